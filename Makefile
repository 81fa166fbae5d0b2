# dji-gateway: the three commands a user and CI need.
#   make run    install the runtime dependencies only, start a local mosquitto (if none is given) and the
#               gateway with simulated devices
#   make test   set up .venv with the dev extras, install mosquitto, chromium and ffmpeg if missing, run ruff, mypy and
#               the whole pytest suite in parallel (TEST_WORKERS, default 10; hadolint comes from PyPI with the
#               dev extras)
#   make bench  print the benchmark tables (codecs, end-to-end round trips)

PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
# two stamps: the runtime install (`make run`) and the dev extras on top of it (`make test`, `make venv`)
# pytest-xdist workers for `make test`: most tests wait on real brokers, devices and timeouts rather than
# the CPU (the suite needs about 3 min of CPU), so more workers than cores overlap the waiting. On 2 cores,
# each beside another run: -n 4 worksteal 369 s, -n 6 loadgroup long-first 337 s (CONTRIBUTING.md); alone,
# after issue #37's real-time return-home table: -n 6 377 s, -n 10 264 s (about 6.5 min of CPU now).
# loadgroup keeps a module with shared fixtures on one worker (tests/conftest.py).
# `make test TEST_WORKERS=0` runs the suite in one process.
TEST_WORKERS ?= 10
RUNTIME := $(VENV)/.installed-runtime
DEV     := $(VENV)/.installed-dev

.PHONY: all run test bench lint venv mosquitto nats chromium ffmpeg clean schema

all: test

$(PY):
	$(PYTHON) -m venv $(VENV)

$(RUNTIME): $(PY) pyproject.toml
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[webrtc]'
	@touch $(RUNTIME)

$(DEV): $(RUNTIME)
	$(PY) -m pip install --quiet -e '.[dev]'
	@touch $(DEV)

venv: $(DEV)

# The tests start their own brokers; they need the binaries, not running services: mosquitto, and
# nats-server for the 3-node cluster tests (Debian's package, 2.9: MQTT 3.1.1, clustering, JetStream).
# iproute2 (ip, tc) for the network-namespace tests (they skip, saying why, where they cannot run).
APT_INSTALL = apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq

mosquitto:
	@if command -v mosquitto >/dev/null 2>&1 || [ -x /usr/sbin/mosquitto ]; then :; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
		echo "installing mosquitto with apt-get"; \
		$(APT_INSTALL) mosquitto >/dev/null; \
	else \
		echo "mosquitto is missing: install it (e.g. 'sudo apt-get install mosquitto') and run again" >&2; exit 1; \
	fi

nats:
	@if command -v nats-server >/dev/null 2>&1 || [ -x /usr/sbin/nats-server ]; then :; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
		echo "installing nats-server with apt-get"; \
		$(APT_INSTALL) nats-server >/dev/null; \
	else \
		echo "nats-server is missing: install it (e.g. 'sudo apt-get install nats-server') and run again" >&2; exit 1; \
	fi
	@if ! command -v ip >/dev/null 2>&1 && [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
		echo "installing iproute2 with apt-get"; $(APT_INSTALL) iproute2 >/dev/null || true; \
	fi

# The console's browser tests drive Debian's Chromium through Playwright's executable_path (never a browser
# that `playwright install` would download); without it they are skipped, saying why.
chromium:
	@if [ -x /usr/bin/chromium ]; then :; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
		echo "installing chromium with apt-get"; \
		$(APT_INSTALL) chromium >/dev/null \
			|| echo "chromium could not be installed: the browser tests will be skipped" >&2; \
	else \
		echo "chromium is missing ('sudo apt-get install chromium'): the browser tests will be skipped" >&2; \
	fi

# Live video (docs/video.md): Debian's ffmpeg (5.1, libx264, drawtext with libfreetype) and a font for the
# test pattern; without them the video tests are skipped, saying why, and live_start_push answers 399015.
ffmpeg:
	@if command -v ffmpeg >/dev/null 2>&1 && command -v ffprobe >/dev/null 2>&1 \
		&& [ -f /usr/share/fonts/truetype/dejavu/DejaVuSans.ttf ]; then :; \
	elif [ "$$(id -u)" = "0" ] && command -v apt-get >/dev/null 2>&1; then \
		echo "installing ffmpeg and fonts-dejavu-core with apt-get"; \
		$(APT_INSTALL) ffmpeg fonts-dejavu-core >/dev/null \
			|| echo "ffmpeg could not be installed: the video tests will be skipped" >&2; \
	else \
		echo "ffmpeg is missing ('sudo apt-get install ffmpeg fonts-dejavu-core'): the video tests will be skipped" >&2; \
	fi

lint: venv
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .
	$(VENV)/bin/mypy schemas adapters gateway

# Python's bytecode cache is on for the run even where the environment turns it off
# (PYTHONDONTWRITEBYTECODE=1, as on our CI machines): without it every worker rewrote and compiled every
# test module (6 s of CPU each, ten workers on two cores) and each of the hundreds of processes the tests
# start compiled the gateway from source. One collection first fills the cache the workers then read
# (262 s -> 217 s of pytest on 2 cores).
test: venv mosquitto nats chromium ffmpeg lint
	PYTHONDONTWRITEBYTECODE= $(PY) -m compileall -q gateway adapters schemas bench >/dev/null
	PYTHONDONTWRITEBYTECODE= $(PY) -m pytest -q --collect-only >/dev/null
	PYTHONDONTWRITEBYTECODE= $(PY) -m pytest -q -n $(TEST_WORKERS) --dist loadgroup --no-loadscope-reorder

bench: venv mosquitto nats ffmpeg
	$(PY) bench/run.py

run: $(RUNTIME) mosquitto ffmpeg
	$(PY) -m gateway.cli.devrun $(ARGS)

schema: $(RUNTIME)
	$(VENV)/bin/dji-gateway schema export

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .mypy_cache .hypothesis build *.egg-info
