"""The service under failure: adapter exceptions, broker restarts, a simulator in another process over
SLCAN, and SIGTERM on the real ``dji-gateway run`` process."""

from __future__ import annotations

import gc
import json
import os
import re
import signal
import subprocess
import sys
import time
from typing import Any

import pytest

from adapters.base import CallResult
from adapters.rsdk.sim import GimbalCanSim, SlcanGimbal
from adapters.simio import TcpEndpoint
from gateway.local_broker import LocalBroker
from tests.support import CloudClient, FakeAdapter, GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker

GW = "GW-TEST-1"


class FlakyAdapter(FakeAdapter):
    """A device whose adapter has a bug: the first photo raises, later ones work."""

    def __init__(self) -> None:
        osd = {"payload_index": "2001-0-0", "gimbal_pitch": 0.0}
        super().__init__("FLAKY-1", "2001-0-0", {"camera_photo_take": self._photo}, osd=osd)
        self.calls = 0

    async def _photo(self, data: Any) -> CallResult:
        self.calls += 1
        if self.calls == 1:
            raise RuntimeError("adapter bug")
        return CallResult()


def test_an_adapter_exception_does_not_stop_the_next_request(broker: LocalBroker) -> None:
    flaky = FlakyAdapter()
    settings = gateway_settings(broker.port, [], dispatcher={"require_authority": False})
    cloud = CloudClient(broker.host, broker.port, GW)
    with GatewayThread(settings, adapters=[flaky]) as gw:
        first = cloud.service("camera_photo_take", {"payload_index": "2001-0-0"})
        assert first["data"] == {
            "result": 599001,
            "output": {"reason": "internal error in the device adapter"},
        }
        for _ in range(3):
            assert cloud.service("camera_photo_take", {"payload_index": "2001-0-0"})["data"]["result"] == 0
        assert gw.app.metrics.count("handler_exceptions_total", where="adapter:FLAKY-1") == 1
    cloud.close()


def test_broker_killed_and_restarted(private_broker: LocalBroker, can_channel: str) -> None:
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {"type": "rsdk", "sn": "RSDK-T-2", "interface": "virtual", "channel": can_channel}
    settings = gateway_settings(private_broker.port, [device], dispatcher={"require_authority": False})
    with GatewayThread(settings) as gw:
        cloud = CloudClient(private_broker.host, private_broker.port, GW)
        wait_until(lambda: gw.app.devices.by_sn("RSDK-T-2").online, 5, what="gimbal online")
        assert cloud.service("camera_photo_take", {"payload_index": "20-0-0"})["data"]["result"] == 0
        cloud.close()
        private_broker.stop(kill=True)
        wait_until(lambda: not gw.app.bridge.connected, 5, what="gateway notices the broker is gone")
        published = gw.app.metrics.count("topology_published_total")
        private_broker.start()
        cloud = CloudClient(private_broker.host, private_broker.port, GW)  # returns once subscribed
        # reconnected: topology republished (with the gimbal), subscriptions restored, services work
        if not gw.app.bridge.connected:  # the gateway's CONNACK, hence its update_topo, came after ours
            cloud.wait_for(
                "status", lambda b: [d["sn"] for d in b["data"]["sub_devices"]] == ["RSDK-T-2"], timeout=10
            )
        else:  # it reconnected first (its probe won the race on a loaded machine): the status went to
            # a broker on which nobody was subscribed yet; the gateway published it all the same
            wait_until(lambda: gw.app.metrics.count("topology_published_total") > published, 10,
                       what="update_topo republished")  # fmt: skip
            assert gw.app.northbound is not None
            topo = json.loads(gw.app.northbound.topology())
            assert [d["sn"] for d in topo["data"]["sub_devices"]] == ["RSDK-T-2"]
        assert cloud.service("camera_photo_take", {"payload_index": "20-0-0"})["data"]["result"] == 0
        assert sim.model.photos == 2
        assert gw.app.metrics.count("mqtt_connects_total") >= 2
        cloud.close()
    sim.stop()


def _spawn(args: list[str]) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen(
        [sys.executable, "-m", "gateway.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )


def test_gimbal_simulator_in_another_process_over_slcan_tcp(broker: LocalBroker) -> None:
    sim = _spawn(["simulate", "rsdk", "--tcp", "0"])
    try:
        assert sim.stdout is not None
        line = sim.stdout.readline()
        url = re.search(r"socket://127\.0\.0\.1:\d+", line)
        assert url, line
        device = {
            "type": "rsdk",
            "sn": "RSDK-SLCAN-1",
            "interface": "slcan",
            "channel": url.group(0),
            "bus_options": {"sleep_after_open": 0},
        }
        settings = gateway_settings(broker.port, [device], dispatcher={"require_authority": False})
        cloud = CloudClient(broker.host, broker.port, GW)
        with GatewayThread(settings):
            cloud.wait_for("RSDK-SLCAN-1/osd", lambda b: "gimbal_yaw" in b["data"], timeout=10)
            aim = {"payload_index": "20-0-0", "camera_type": "wide", "locked": False, "x": 0.5, "y": 0.0}
            r = cloud.service("camera_aim", aim)
            assert r["data"]["result"] == 0
            # the aim tilts up by half the vertical field of view (45° → 22.5°)
            cloud.wait_for(
                "RSDK-SLCAN-1/osd", lambda b: abs(b["data"]["gimbal_pitch"] - 22.5) < 0.5, timeout=5
            )
        cloud.close()
    finally:
        sim.terminate()
        sim.wait(5)
        if sim.stdout:
            sim.stdout.close()


def _config(tmp_path: Any, broker: LocalBroker, url: str, sn: str) -> str:
    cfg = tmp_path / "gateway.toml"
    cfg.write_text(
        f'''gateway_sn = "{GW}"
[broker]
url = "{broker.url}"
[dispatcher]
require_authority = false
[metrics]
enabled = false  # not 9108: another gateway on this machine may hold it, and a taken port stops the start
[[devices]]
type = "rsdk"
sn = "{sn}"
interface = "slcan"
channel = "{url}"
bus_options = {{ sleep_after_open = 0 }}
'''
    )
    return str(cfg)


def test_sigterm_stops_motion_publishes_offline_and_exits_0(broker: LocalBroker, tmp_path: Any) -> None:
    gimbal = SlcanGimbal()
    endpoint = TcpEndpoint(gimbal).start()
    cloud = CloudClient(broker.host, broker.port, GW)
    proc = _spawn(["run", "--config", _config(tmp_path, broker, endpoint.url, "RSDK-TERM-1")])
    try:
        cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == 1, timeout=15)
        drag = {"payload_index": "20-0-0", "locked": False, "pitch_speed": 10.0, "yaw_speed": 10.0}
        assert cloud.service("camera_screen_drag", drag)["data"]["result"] == 0
        assert gimbal.model.pitch.speed == 10.0
        cloud.clear()
        stopped_at = int(time.time() * 1000)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
        # motion stopped before the exit: zero speed, speed control released
        assert gimbal.model.pitch.speed == 0.0 and gimbal.model.speed_until == 0.0
        offline = cloud.wait_for("status", timeout=5)[-1]
        assert offline["data"]["sub_devices"] == []
        # a fresh goodbye, not the will fixed at connect: stamped when it went offline (issue #38)
        assert offline["timestamp"] >= stopped_at, (offline["timestamp"], stopped_at)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
        out = proc.stdout.read() if proc.stdout else ""
        if proc.stdout:
            proc.stdout.close()
        cloud.close()
        endpoint.stop()
    assert "Traceback" not in out, out


def test_a_vanished_gateway_is_announced_offline_by_its_will(broker: LocalBroker, tmp_path: Any) -> None:
    endpoint = TcpEndpoint(SlcanGimbal()).start()
    cloud = CloudClient(broker.host, broker.port, GW)
    proc = _spawn(["run", "--config", _config(tmp_path, broker, endpoint.url, "RSDK-WILL-1")])
    try:
        cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == 1, timeout=15)
        cloud.clear()
        proc.kill()  # no goodbye: the broker publishes the will
        proc.wait(5)
        proc.wait(5)
        will = cloud.wait_for("status", timeout=10)[-1]
        assert will["method"] == "update_topo" and will["data"]["sub_devices"] == []
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
        if proc.stdout:
            proc.stdout.close()
        cloud.close()
        endpoint.stop()


def test_a_bad_config_fails_with_one_clear_line(tmp_path: Any) -> None:
    cfg = tmp_path / "gw.toml"
    cfg.write_text('gateway_sn = "GW-1"\n[[devices]]\ntype = "rsdk"\nsn = "G1"\nbitrate = "fast"\n')
    proc = subprocess.run(
        [sys.executable, "-m", "gateway.cli", "run", "--config", str(cfg)],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "devices.0.rsdk.bitrate" in lines[0], proc.stderr


# python-can's slcan bus leaves its socket open when its own start-up handshake fails (as it may while the
# adapter is going away); the leak is collected inside this test and not blamed on a later one
@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
@pytest.mark.filterwarnings("ignore::ResourceWarning")
def test_a_can_adapter_that_disappears_and_comes_back(broker: LocalBroker) -> None:
    """The USB-CAN adapter (an SLCAN simulator process on a TCP port) vanishes: the gimbal goes offline
    and its methods answer 325012; the adapter is back on the same port: the link reopens by itself."""
    from gateway.local_broker import free_port

    port = free_port()
    sim = _spawn(["simulate", "rsdk", "--tcp", str(port)])
    assert sim.stdout is not None
    sim.stdout.readline()
    device = {"type": "rsdk", "sn": "RSDK-GONE-1", "interface": "slcan", "channel": f"socket://127.0.0.1:{port}",
              "bus_options": {"sleep_after_open": 0}, "reopen_interval": 0.5}  # fmt: skip
    settings = gateway_settings(broker.port, [device], dispatcher={"require_authority": False})
    cloud = CloudClient(broker.host, broker.port, GW)
    try:
        with GatewayThread(settings) as gw:
            wait_until(lambda: gw.app.devices.by_sn("RSDK-GONE-1").online, 10, what="gimbal online")
            cloud.clear()
            sim.kill()
            sim.wait(5)
            sim.wait(5)
            cloud.wait_for("status", lambda b: b["data"]["sub_devices"] == [], timeout=10)
            assert cloud.service("camera_photo_take", {"payload_index": "20-0-0"})["data"]["result"] == 325012
            sim.stdout.close()
            sim = _spawn(["simulate", "rsdk", "--tcp", str(port)])
            assert sim.stdout is not None
            sim.stdout.readline()
            wait_until(lambda: gw.app.devices.by_sn("RSDK-GONE-1").online, 15, what="gimbal back")
            assert cloud.service("camera_photo_take", {"payload_index": "20-0-0"})["data"]["result"] == 0
    finally:
        cloud.close()
        sim.terminate()
        sim.wait(5)
        if sim.stdout:
            sim.stdout.close()
        gc.collect()


def test_many_devices_one_topology_unique_channels_and_a_prompt_stop(broker: LocalBroker) -> None:
    """70 robots on real loopback serial ports (more than the 26 letters and the old 64-entry cap): all come
    online in one topology with a distinct channel index each, and the gateway stops within its 10 s bound
    (each pyserial socket:// close sleeps 0.3 s: 21 s if the links were closed one after another)."""
    from adapters.robomaster.sim import RefereeMatch, RobomasterSim
    from adapters.simio import TcpFarm
    from gateway.northbound import channel_index

    assert [channel_index(i) for i in (0, 25, 26, 27, 51, 52, 701, 702)] == [
        "A", "Z", "AA", "AB", "AZ", "BA", "ZZ", "AAA"
    ]  # fmt: skip
    n = 70
    farm = TcpFarm([RobomasterSim(RefereeMatch(hit_period=0.0)) for _ in range(n)], tick_interval=0.2).start()
    # listed by the gateway (announce = sub_device), not each its own gateway: one topology of 70
    listed = {"announce": "sub_device"}
    devices = [
        {"type": "robomaster", "sn": f"RM-{i:03d}", "url": url, "product": listed}
        for i, url in enumerate(farm.urls)
    ]
    cloud = CloudClient(broker.host, broker.port, "GW-MANY-1")
    gw = GatewayThread(gateway_settings(broker.port, devices, gateway_sn="GW-MANY-1")).start()
    try:
        topo = cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == n, timeout=30)[-1]
        subs = topo["data"]["sub_devices"]
        assert sorted(s["sn"] for s in subs) == sorted(d["sn"] for d in devices)
        assert len({s["index"] for s in subs}) == n
        assert gw.app.metrics.count("outbound_invalid_total") == 0
    finally:
        gw.stop()  # raises when the gateway has not stopped within 10 s
        cloud.close()
        farm.stop()
