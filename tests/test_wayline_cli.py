"""The README's "fly a route" walkthrough, as a reader runs it against ``dji-gateway run --simulate``:
``route-demo`` writes the KMZ, ``send flighttask_prepare file=route.kmz`` serves it and fingerprints it,
``send flighttask_execute`` flies it, and ``monitor`` shows the task's progress to ``status=ok``."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from gateway.local_broker import LocalBroker
from tests.support import CloudClient, Proc, simulated_gateway, wait_until

pytestmark = pytest.mark.broker

GW = "DJIGW-SIM-0001"
BIN = str(Path(sys.executable).parent / "dji-gateway")
ENV = {**{k: v for k, v in os.environ.items() if not k.startswith("DJIGW_")}, "PYTHONUNBUFFERED": "1"}


def _cli(*args: str, broker: LocalBroker, cwd: Path) -> subprocess.CompletedProcess[str]:
    argv = [BIN, *args]
    if args[0] == "send":
        argv += ["--gateway-sn", GW, "--broker", broker.url]
    return subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=60, env=ENV)


@pytest.mark.slow
def test_fly_a_route_from_the_console(broker: LocalBroker, tmp_path: Path) -> None:
    gateway, _ = simulated_gateway(broker.url)
    cloud = CloudClient(broker.host, broker.port, GW)
    monitor = Proc("monitor", [BIN, "monitor", "--plain", "--gateway-sn", GW, "--broker", broker.url,
                               "--status-url", ""], ENV)  # fmt: skip
    try:
        monitor.wait_for_line("monitoring gateway", 20)
        done = _cli("route-demo", "route.kmz", broker=broker, cwd=tmp_path)
        assert done.returncode == 0 and "md5" in done.stdout, done.stderr
        assert _cli("send", "flight_authority_grab", broker=broker, cwd=tmp_path).returncode == 0
        prep = _cli("send", "flighttask_prepare", "file=route.kmz", "flight_id=route-1",
                    broker=broker, cwd=tmp_path)  # fmt: skip
        assert prep.returncode == 0 and '"result": 0' in prep.stdout, (prep.stdout, prep.stderr)
        # the request carried the served URL and the lowercase MD5 of the file
        (sent,) = cloud.find("/services", lambda b: b.get("method") == "flighttask_prepare")
        md5 = hashlib.md5((tmp_path / "route.kmz").read_bytes(), usedforsecurity=False).hexdigest()
        assert sent["data"]["file"]["fingerprint"] == md5
        assert sent["data"]["file"]["url"].startswith("http://127.0.0.1:")
        ex = _cli("send", "flighttask_execute", "flight_id=route-1", broker=broker, cwd=tmp_path)
        assert ex.returncode == 0, (ex.stdout, ex.stderr)
        line = monitor.wait_for_line(r"flighttask_progress route-1 status=ok .*media=1", 120)
        assert "percent=100" in line.group(0)
        wait_until(
            lambda: any("status=in_progress" in ln for ln in monitor.lines), 1, what="in_progress shown"
        )
    finally:
        monitor.stop()
        gateway.stop()
        cloud.close()
