"""Issue #35, truthful addresses: a gateway never prints an address another process answers.

* ``dji-gateway run`` with its HTTP port taken stops before anything starts (exit 2), naming the address
  and the setting that moves it;
* ``make run`` (``gateway.cli.devrun``) with its default console port taken serves on a free one and
  prints that one, and every address it prints (the console, ``status --url``, ``monitor --status-url``,
  the broker in the live-control line) is the one this run answers on;
* the gateway's own bind (the race after the check) stops it the same way;
* two gateways with one serial number on one broker are reported (``/status``, ``status``, the console's
  state), not silently merged.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import aiohttp
import pytest

from gateway.local_broker import LocalBroker
from tests.support import GatewayThread, Proc, gateway_settings, wait_until

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


def test_the_twin_watch_tells_its_own_osd_from_another_publishers() -> None:
    from gateway.twins import TwinWatch

    watch = TwinWatch(keep=2, recent=5.0)
    for tid in ("a", "b", "c"):
        watch.sent(f'{{"tid": "{tid}", "data": {{}}}}'.encode())
    assert not watch.heard(b'{"tid": "c"}', 1.0) and not watch.heard(b'{"tid": "b"}', 1.0)  # echoes
    assert not watch.heard(b"not json", 1.0) and watch.count == 0
    assert watch.heard(b'{"tid": "a"}', 2.0)  # forgotten (keep 2) or another's: counted
    assert watch.heard(b'{"tid": "zz"}', 3.0) and watch.count == 2
    assert watch.snapshot(4.0) == {"active": True, "count": 2, "last_age_s": 1.0}
    assert watch.snapshot(9.0)["active"] is False


@pytest.mark.broker
def test_two_gateways_with_one_serial_number_are_reported_not_merged(tmp_path: Path) -> None:
    """Issue #35: a second gateway configured with the same gateway_sn on the same broker is seen by the
    first (its osd under that serial number were not sent by it): ``/status``, ``dji-gateway status`` and
    the console's state say so; alone, a gateway never takes its own osd for another's."""
    from gateway.cli.status import fetch

    broker = LocalBroker(0).start()
    first = GatewayThread(gateway_settings(broker.port, [], gateway_sn="GW-TWIN", osd_period=0.2,
                                           metrics={"enabled": True, "port": 0})).start()  # fmt: skip
    second: GatewayThread | None = None
    try:
        assert first.app.observability is not None
        url = f"http://127.0.0.1:{first.app.observability.port}"
        wait_until(lambda: fetch(url, "/status")[1]["broker"]["connected"], 10, what="connected")
        time.sleep(1.0)  # five of its own osd periods: echoes only
        assert first.app.twins.count == 0
        assert fetch(url, "/status")[1]["broker"]["gateway_sn_conflict"]["count"] == 0
        second = GatewayThread(
            gateway_settings(broker.port, [], gateway_sn="GW-TWIN", osd_period=0.2)
        ).start()
        wait_until(lambda: first.app.twins.count >= 2, 10, what="the twin seen")
        status = fetch(url, "/status")[1]
        assert status["broker"]["gateway_sn_conflict"]["active"] is True, status["broker"]
        assert second.app.twins.count >= 1  # and the second sees the first
        done = subprocess.run([BIN, "status", "--url", url], capture_output=True, text=True, timeout=30,
                              env=_env(COLUMNS="200"))  # fmt: skip
        assert "ANOTHER GATEWAY publishes as GW-TWIN on this broker" in done.stdout, done.stdout
        with urllib.request.urlopen(url + "/metrics", timeout=5) as resp:
            assert "djigw_gateway_sn_conflicts" in resp.read().decode()
        assert json.dumps(first.app.observability.status()["broker"]["gateway_sn_conflict"])

        async def console_state() -> dict[str, Any]:  # what the page is pushed (it draws a red pill from it)
            async with (
                aiohttp.ClientSession() as session,
                session.ws_connect(url + "/api/ws", headers={"Origin": url}) as ws,
            ):
                while True:
                    msg = json.loads((await ws.receive(timeout=5)).data)
                    if msg["type"] == "state":
                        return dict(msg)

        conflict = asyncio.run(console_state())["gateway"]["sn_conflict"]
        assert conflict["active"] is True and conflict["count"] >= 2, conflict
    finally:
        if second is not None:
            second.stop()
        first.stop()
        broker.stop()
