# dji-gateway: the gateway and the device simulators in one slim image.
#   docker build -t dji-gateway .
#   docker run --rm dji-gateway --help
#   docker run --rm --add-host host.docker.internal:host-gateway -p 127.0.0.1:9108:9108 dji-gateway
# The gateway is the entry point. The default command runs it with the simulated devices against a broker on
# the Docker host (config/docker/gateway.toml: inside a container 127.0.0.1 is the container, and there is no
# can0 or /dev/ttyUSB0 unless given); for real devices mount a config and run `run --config FILE` (README,
# docker-compose.hardware.yml). The health check asks the gateway's own /healthz (event loop alive, broker
# connected) through `dji-gateway status --check`. tests/test_docker.py lints this file with hadolint and
# runs its default command.

FROM python:3.11-slim AS build
WORKDIR /src
COPY pyproject.toml README.md LICENSE ./
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
COPY config/docker/gateway.toml /etc/dji-gateway/gateway.toml
# numeric, so a runtime can tell it is not root without the image's /etc/passwd (its groups still apply)
USER 10001
WORKDIR /home/djigw
EXPOSE 9108
HEALTHCHECK --interval=15s --timeout=5s --start-period=20s --retries=3 \
    CMD ["dji-gateway", "status", "--check"]
ENTRYPOINT ["dji-gateway"]
CMD ["run", "--simulate", "--config", "/etc/dji-gateway/gateway.toml"]
