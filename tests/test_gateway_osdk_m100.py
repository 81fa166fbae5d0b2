"""The M100 on legacy firmware, end to end: ``dji-gateway simulate osdk --firmware m100`` as its own process
(and the same simulator in-process, to watch its flight tasks), a gateway configured with
``firmware = "m100"``, a real mosquitto. The M100's codes differ from the new firmware's for the same
intent (flight tasks 1 go home, 4 take off, 6 landing; ACK 0x0002 started; flight status 3 in air):
a gateway that sent new-firmware codes would send the M100 home when asked to take off."""

from __future__ import annotations

import re
import subprocess
import sys
from collections.abc import Iterator
from typing import Any

import pytest

from adapters.osdk.sim import OsdkFcDevice, OsdkFcModel
from adapters.simio import TcpEndpoint
from gateway.local_broker import LocalBroker
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until
from tests.test_gateway_osdk import HOME, HOME_ALT, _distance, _events, _north_east, _takeoff_data

pytestmark = pytest.mark.broker

GW = "GW-TEST-1"
SN = "OSDK-M100-1"


class Recording(OsdkFcModel):
    """The simulated M100, remembering every task it entered."""

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.tasks_seen: list[str] = []

    def _step(self, h: float) -> None:
        super()._step(h)
        if not self.tasks_seen or self.tasks_seen[-1] != self.task:
            self.tasks_seen.append(self.task)


@pytest.fixture
def m100(broker: LocalBroker) -> Iterator[dict[str, Any]]:
    model = Recording(home=HOME, home_altitude=HOME_ALT, firmware="m100")
    device = OsdkFcDevice(model)
    endpoint = TcpEndpoint(device).start()
    device_settings = {
        "type": "osdk",
        "sn": SN,
        "url": endpoint.url,
        "firmware": "m100",
        "go_home_altitude": 30,
    }
    cloud = CloudClient(broker.host, broker.port, GW)
    gw = GatewayThread(gateway_settings(broker.port, [device_settings])).start()
    try:
        cloud.wait_for("status", lambda b: [d["sn"] for d in b["data"]["sub_devices"]] == [SN], timeout=10)
        yield {"fc": device, "cloud": cloud, "gw": gw}
    finally:
        gw.stop()
        cloud.close()
        endpoint.stop()


@pytest.mark.slow
def test_an_m100_takes_off_flies_to_a_point_and_never_goes_home(m100: dict[str, Any]) -> None:
    fc, cloud = m100["fc"], m100["cloud"]
    state = cloud.wait_for(f"{SN}/state", lambda b: "x_hardware" in b["data"], timeout=5)[-1]["data"]
    assert state["x_hardware"] == "M100"  # the CRC layout of the version reply, read
    assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
    target = _north_east(*HOME, 30.0, 0.0)
    data = {
        "target_latitude": target[0],
        "target_longitude": target[1],
        "target_height": HOME_ALT + 20.0,
        "security_takeoff_height": 20.0,
        "rth_altitude": 30,
        "flight_id": "m100-1",
        "max_speed": 12,
    }
    assert cloud.service("takeoff_to_point", data)["data"]["result"] == 0  # ACK 0x0002 = started
    finished = lambda: any(e["status"] == "task_finish" for e in _events(cloud, "takeoff_to_point_progress"))  # noqa: E731
    wait_until(finished, 40, what="take-off task finished")
    statuses = [e["status"] for e in _events(cloud, "takeoff_to_point_progress")]
    assert statuses[0] == "task_ready" and statuses[-2:] == ["wayline_ok", "task_finish"], statuses
    osd = cloud.wait_for(
        f"{SN}/osd", lambda b: _distance(b["data"]["latitude"], b["data"]["longitude"], *target) < 5.0
    )[-1]["data"]
    assert abs(osd["elevation"] - 20.0) < 5.0
    # fly_to_point on a flying M100 (status 3 = in air, which the new firmware's "2" would miss)
    p1 = _north_east(*HOME, -20.0, 30.0)
    points = [{"latitude": p1[0], "longitude": p1[1], "height": HOME_ALT + 25.0}]
    assert (
        cloud.service("fly_to_point", {"fly_to_id": "m100-f", "max_speed": 10, "points": points})["data"][
            "result"
        ]
        == 0
    )
    wait_until(lambda: any(e["status"] == "wayline_ok" for e in _events(cloud, "fly_to_point_progress")), 40,
               what="fly-to finished")  # fmt: skip
    cloud.wait_for(f"{SN}/osd", lambda b: _distance(b["data"]["latitude"], b["data"]["longitude"], *p1) < 5.0)
    seen = fc.inspect(lambda m: list(m.tasks_seen))
    assert "go_home" not in seen and "landing" not in seen, seen
    assert "takeoff" in seen and "waypoint" in seen


def test_an_m100_refuses_a_go_home_altitude_it_cannot_be_given(m100: dict[str, Any]) -> None:
    """Legacy firmware has no command for the go-home altitude: rth_altitude must be the configured one."""
    fc, cloud = m100["fc"], m100["cloud"]
    assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
    data = _takeoff_data(rth_altitude=60, flight_id="m100-2")
    reply = cloud.service("takeoff_to_point", data)["data"]
    assert reply["result"] == 325001 and "go_home_altitude setting (30 m)" in reply["output"]["reason"]
    assert fc.inspect(lambda m: m.actions["flight_task"]) == 0


def test_the_m100_simulator_as_its_own_process_prints_its_port(broker: LocalBroker) -> None:
    proc = subprocess.Popen(
        [sys.executable, "-m", "gateway.cli", "simulate", "osdk", "--firmware", "m100", "--tcp", "0"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        url = re.search(r"socket://127\.0\.0\.1:\d+", line)
        assert url, line
        device_settings = {"type": "osdk", "sn": SN, "url": url.group(0), "firmware": "m100"}
        cloud = CloudClient(broker.host, broker.port, GW)
        with GatewayThread(gateway_settings(broker.port, [device_settings])):
            cloud.wait_for(
                "status", lambda b: [d["sn"] for d in b["data"]["sub_devices"]] == [SN], timeout=10
            )
            assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
            state = cloud.wait_for(f"{SN}/state", lambda b: "x_hardware" in b["data"], timeout=5)[-1]["data"]
            assert state["x_hardware"] == "M100"
        cloud.close()
    finally:
        proc.terminate()
        proc.wait(10)
        if proc.stdout is not None:
            proc.stdout.close()
