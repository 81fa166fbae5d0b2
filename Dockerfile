# dji-gateway: the gateway and the device simulators in one slim image.
#   docker build -t dji-gateway .
#   docker run --rm dji-gateway --help
# The gateway is the entry point; `run` with the example config is the default command. The health check
# asks the gateway's own /healthz (event loop alive, broker connected) through `dji-gateway status --check`.

FROM python:3.11-slim AS build
WORKDIR /src
COPY pyproject.toml README.md ./
COPY schemas ./schemas
COPY adapters ./adapters
COPY gateway ./gateway
RUN pip wheel --no-cache-dir --disable-pip-version-check --wheel-dir /wheels .

FROM python:3.11-slim
ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1
COPY --from=build /wheels /wheels
# a non-root user; dialout opens USB serial adapters (/dev/ttyUSB*, /dev/ttyACM*) passed with --device
RUN pip install /wheels/*.whl \
    && rm -rf /wheels \
    && useradd --system --uid 10001 --user-group --groups dialout --no-create-home \
       --shell /usr/sbin/nologin djigw
COPY config/gateway.example.toml /etc/dji-gateway/gateway.toml
USER djigw
WORKDIR /home/djigw
EXPOSE 9108
HEALTHCHECK --interval=15s --timeout=5s --start-period=20s --retries=3 \
    CMD ["dji-gateway", "status", "--check"]
ENTRYPOINT ["dji-gateway"]
CMD ["run", "--config", "/etc/dji-gateway/gateway.toml"]
