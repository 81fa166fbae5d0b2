"""Issue #35, truthful addresses: a gateway never prints an address another process answers.

* ``dji-gateway run`` with its HTTP port taken stops before anything starts (exit 2), naming the address
  and the setting that moves it;
* ``make run`` (``gateway.cli.devrun``) with its default console port taken serves on a free one and
  prints that one, and every address it prints (the console, ``status --url``, ``monitor --status-url``,
  the broker in the live-control line) is the one this run answers on;
* the gateway's own bind (the race after the check) stops it the same way.
"""

from __future__ import annotations

import asyncio
import os
import re
import signal
import socket
import subprocess
import sys
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest

from gateway.local_broker import LocalBroker
from tests.support import Proc, gateway_settings

pytestmark = [pytest.mark.timeout(90)]

BIN = str(Path(sys.executable).parent / "dji-gateway")


@pytest.fixture
def held() -> Iterator[int]:
    """A loopback port something listens on (as another gateway's console would)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        sock.listen(1)
        yield int(sock.getsockname()[1])


def _env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("DJIGW_")}
    return {**env, "PYTHONUNBUFFERED": "1", **extra}


def test_run_refuses_a_taken_http_port_naming_it_and_the_setting(held: int, tmp_path: Path) -> None:
    done = subprocess.run(
        [BIN, "run", "--simulate", "--metrics-port", str(held), "--broker", "mqtt://127.0.0.1:9"],
        cwd=tmp_path, env=_env(), capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert done.returncode == 2, (done.stdout, done.stderr)
    assert f"cannot listen on 127.0.0.1:{held}" in done.stderr
    assert "--metrics-port, DJIGW_METRICS__PORT or [metrics] port" in done.stderr
    assert "running with" not in done.stderr + done.stdout  # nothing started


def test_the_gateways_own_bind_failure_stops_it_with_exit_code_2(
    held: int, caplog: pytest.LogCaptureFixture
) -> None:
    """The race after ``run``'s check: the server cannot bind when the gateway starts it."""
    from gateway.app import GatewayApp

    settings = gateway_settings(9, [], metrics={"enabled": True, "port": held})
    app = GatewayApp(settings)

    async def run() -> None:
        await asyncio.wait_for(app.run(), 30)

    asyncio.run(run())
    assert app.exit_code == 2
    assert any(f"cannot listen on 127.0.0.1:{held}" in r.getMessage() for r in caplog.records)


@pytest.mark.broker
def test_make_run_with_its_console_port_taken_prints_the_one_it_serves(held: int, tmp_path: Path) -> None:
    broker = LocalBroker(0).start()
    # make run's recipe, with the default console port set to one that is taken here (9108 may be free or
    # be another engineer's gateway on this machine: neither would test anything)
    code = (
        f"import sys, gateway.cli.devrun as d; d.DEFAULT_HTTP_PORT = {held}; sys.exit(d.main(sys.argv[1:]))"
    )
    proc = Proc("make run", [sys.executable, "-c", code], _env(BROKER=broker.url), cwd=tmp_path)
    try:
        proc.wait_for_line(r"running with 3 device\(s\)", 30)
        out = proc.output()
        assert f"port {held} is taken" in out
        web = re.search(r"web console:\s+(http://127\.0\.0\.1:(\d+))/", out)
        assert web is not None, out
        url, port = web.group(1), int(web.group(2))
        assert port != held
        assert f"dji-gateway status --url {url}" in out
        assert f"--status-url {url}" in out
        assert f"mqtt_broker.address=127.0.0.1:{broker.port}" in out
        with urllib.request.urlopen(url + "/", timeout=5) as resp:
            assert b"dji-gateway console" in resp.read()
        with urllib.request.urlopen(url + "/status", timeout=5) as resp:
            assert b"DJIGW-SIM-0001" in resp.read()
        token = tmp_path / f".console-token-{port}"
        assert token.is_file() and oct(token.stat().st_mode & 0o777) == "0o600"
        assert not (tmp_path / ".console-token").exists()  # the first instance's file is not touched
    finally:
        proc.proc.send_signal(signal.SIGINT)
        assert proc.stop(timeout=20) == 0, proc.output()[-2000:]
        broker.stop()
    assert not any(tmp_path.glob(".console-token*"))  # removed when the run ended
