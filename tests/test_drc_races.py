"""Live flight control against a racing, repeating cloud, end to end: ``dji-gateway run --simulate`` as
its own process, a real mosquitto, the simulated aircraft in the air.

* 20 ``drc_mode_exit``/``drc_mode_enter`` pairs published back to back, then one final exit: after it no
  stick moves the aircraft, no ``drone_control`` is answered 0, and every drc_state published is 0;
* ``drone_emergency_stop`` with ``"data": ""`` published five times (DJI's reference cloud sends each
  DRC message five times, with an empty-string data): a climbing aircraft stops, each copy answered 0.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from gateway.cli.run import SIM_AIRCRAFT_SN, SIM_GATEWAY_SN
from gateway.local_broker import LocalBroker
from tests.support import CloudClient, wait_until

pytestmark = pytest.mark.broker

GW = SIM_GATEWAY_SN
HOME = (22.5431, 113.9580)  # the simulated aircraft's home (adapters.osdk.sim.DEFAULT_HOME)
HOME_ALTITUDE = 50.0  # target_height is an ellipsoid height, as in the Cloud API


DRC_USER, DRC_PASSWORD = "drc-pilot", "race-drc-secret-77"


@pytest.fixture
def drc_link() -> Iterator[tuple[LocalBroker, CloudClient]]:
    """The DRC broker that drc_mode_enter names (with a password, as DJI's reference cloud hands out),
    and the cloud's client on it (drc/down, drc/up)."""
    broker = LocalBroker(users={DRC_USER: DRC_PASSWORD}).start()
    client = CloudClient(broker.host, broker.port, GW, username=DRC_USER, password=DRC_PASSWORD)
    try:
        yield broker, client
    finally:
        client.close()
        broker.stop()


@pytest.fixture
def simulated(private_broker: LocalBroker, tmp_path: Path) -> Iterator[CloudClient]:
    """``dji-gateway run --simulate`` on a private broker, the aircraft online with flight authority."""
    cfg = tmp_path / "gateway.toml"
    cfg.write_text(
        f'gateway_sn = "{GW}"\nosd_period = 0.1\n[broker]\nurl = "{private_broker.url}"\n'
        "[metrics]\nenabled = false\n"
    )
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    log = (tmp_path / "gateway.log").open("w")
    proc = subprocess.Popen(
        [sys.executable, "-m", "gateway.cli", "run", "--simulate", "--config", str(cfg)],
        stdout=log,
        stderr=subprocess.STDOUT,
        env=env,
    )
    cloud = CloudClient(private_broker.host, private_broker.port, GW)
    try:
        cloud.wait_for(
            "status",
            lambda b: any(d.get("sn") == SIM_AIRCRAFT_SN for d in b["data"].get("sub_devices", [])),
            timeout=20,
        )
        reply = _raw_service(cloud, "flight_authority_grab", "")  # the reference cloud's shape
        assert reply["data"]["result"] == 0, reply
        yield cloud
    finally:
        cloud.close()
        proc.terminate()
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(5)
        log.close()


def _raw_service(cloud: CloudClient, method: str, data: Any, timeout: float = 10.0) -> dict[str, Any]:
    tid = str(uuid.uuid4())
    _publish_service(cloud, method, data, tid)
    return cloud.wait_for("services_reply", lambda b: b.get("tid") == tid, timeout=timeout)[-1]


def _publish_service(cloud: CloudClient, method: str, data: Any, tid: str) -> None:
    msg = {"tid": tid, "bid": str(uuid.uuid4()), "timestamp": int(time.time() * 1000), "method": method}
    msg["data"] = data
    cloud.client.publish(f"thing/product/{GW}/services", json.dumps(msg), qos=1)


def _down(cloud: CloudClient, method: str, data: Any) -> None:
    cloud.client.publish(f"thing/product/{GW}/drc/down", json.dumps({"method": method, "data": data}), qos=0)


def _osd(cloud: CloudClient) -> dict[str, Any]:
    return cloud.find(f"{SIM_AIRCRAFT_SN}/osd")[-1]["data"]


def _metres(a: dict[str, Any], b: dict[str, Any]) -> float:
    north = math.radians(b["latitude"] - a["latitude"]) * 6378137.0
    east = math.radians(b["longitude"] - a["longitude"]) * 6378137.0 * math.cos(math.radians(a["latitude"]))
    return math.sqrt(north**2 + east**2 + (b["height"] - a["height"]) ** 2)


def _take_off(cloud: CloudClient, above_home: float, security_height: float = 20) -> None:
    data = {
        "target_latitude": HOME[0] + 0.0001,  # 11 m north
        "target_longitude": HOME[1],
        "target_height": HOME_ALTITUDE + above_home,
        "security_takeoff_height": security_height,
        "rth_altitude": 60,
        "max_speed": 10,
        "flight_id": f"race-{uuid.uuid4().hex[:8]}",
    }
    assert _raw_service(cloud, "takeoff_to_point", data)["data"]["result"] == 0


def _enter(cloud: CloudClient, drc_broker: LocalBroker, tid: str | None = None) -> None:
    broker = {"address": f"127.0.0.1:{drc_broker.port}", "client_id": "drc-race", "username": DRC_USER,
              "password": DRC_PASSWORD, "expire_time": int(time.time()) + 600,
              "enable_tls": False}  # fmt: skip
    data = {"mqtt_broker": broker, "osd_frequency": 5, "hsi_frequency": 1}
    _publish_service(cloud, "drc_mode_enter", data, tid or str(uuid.uuid4()))


class Heartbeats:
    """The cloud's 1 Hz (here 5 Hz) heart_beat while the test runs."""

    def __init__(self, cloud: CloudClient) -> None:
        self.cloud, self.stop = cloud, threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        seq = 0
        while not self.stop.is_set():
            seq += 1
            _down(self.cloud, "heart_beat", {"seq": seq, "timestamp": int(time.time() * 1000)})
            self.stop.wait(0.2)

    def __enter__(self) -> Heartbeats:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop.set()
        self.thread.join(2)


def test_raced_exit_enter_burst_ends_with_live_control_off(
    simulated: CloudClient, drc_link: tuple[LocalBroker, CloudClient]
) -> None:
    cloud, (drc_broker, drc) = simulated, drc_link
    _take_off(cloud, 25)

    def finished() -> bool:
        return bool(cloud.find("events", lambda b: (b.get("data") or {}).get("status") == "task_finish"))

    wait_until(finished, 40, what="task_finish")
    with Heartbeats(drc):
        first = str(uuid.uuid4())
        _enter(cloud, drc_broker, first)
        assert cloud.wait_for("services_reply", lambda b: b.get("tid") == first)[-1]["data"]["result"] == 0
        _down(drc, "drone_control", {"seq": 1, "y": 2.0})  # live control works before the burst
        wait_until(lambda: _osd(cloud).get("horizontal_speed", 0) > 1.0, 5, what="sticks fly the aircraft")
        final = str(uuid.uuid4())
        for _ in range(20):  # back to back: each one its own dispatcher task
            _publish_service(cloud, "drc_mode_exit", "", str(uuid.uuid4()))
            _enter(cloud, drc_broker)
        _publish_service(cloud, "drc_mode_exit", "", final)
        reply = cloud.wait_for("services_reply", lambda b: b.get("tid") == final, timeout=20)[-1]
        assert reply["data"]["result"] == 0, reply
        mark, drc_mark = len(cloud.messages), len(drc.messages)
        wait_until(lambda: _osd(cloud).get("horizontal_speed", 9) < 0.3, 5, what="stopped after the exit")
        before = _osd(cloud)
        seq = 1000
        end = time.monotonic() + 3.0
        while time.monotonic() < end:  # 3 s of 5 m/s sticks, none of which may move it
            seq += 1
            _down(drc, "drone_control", {"seq": seq, "y": 5.0, "h": 1.0})
            time.sleep(0.1)
        after = _osd(cloud)
    assert _metres(before, after) < 1.0, (before, after)
    later = cloud.messages[mark:]
    answered = [b for t, b, _ in drc.messages[drc_mark:]
                if t.endswith("drc/up") and b and b.get("method") == "drone_control"]  # fmt: skip
    assert not [b for b in answered if b["data"].get("result") == 0], answered[:3]
    states = [b["data"]["drc_state"] for t, b, _ in later
              if t.endswith("/events") and b and b.get("method") == "drc_status_notify"]  # fmt: skip
    states += [b["data"]["drc_state"] for t, b, _ in later
               if t.endswith(f"{GW}/osd") and b and "drc_state" in b["data"]]  # fmt: skip
    assert states and set(states) == {0}, states


def test_five_fold_emergency_stop_with_empty_data_stops_a_climbing_aircraft(
    simulated: CloudClient, drc_link: tuple[LocalBroker, CloudClient]
) -> None:
    cloud, (drc_broker, drc) = simulated, drc_link
    entered = str(uuid.uuid4())
    _enter(cloud, drc_broker, entered)
    assert cloud.wait_for("services_reply", lambda b: b.get("tid") == entered)[-1]["data"]["result"] == 0
    with Heartbeats(drc):
        _take_off(cloud, 120, security_height=100)  # straight up to 100 m first: a vertical climb
        wait_until(
            lambda: _osd(cloud).get("vertical_speed", 0) > 3.0 and _osd(cloud).get("elevation", 0) > 15,
            40,
            what="climbing",
        )
        mark = len(cloud.messages)
        for _ in range(5):
            drc.client.publish(
                f"thing/product/{GW}/drc/down", b'{"method":"drone_emergency_stop","data":""}', qos=0
            )
        stopped_at = time.monotonic()
        wait_until(
            lambda: (
                abs(_osd(cloud).get("vertical_speed", 9)) < 0.2
                and _osd(cloud).get("horizontal_speed", 9) < 0.2
            ),
            5,
            what="the aircraft stopped",
        )
        took = time.monotonic() - stopped_at
        replies = drc.wait_for(
            "drc/up", lambda b: b.get("method") == "drone_emergency_stop", count=5, timeout=5
        )
    assert [r["data"]["result"] for r in replies[-5:]] == [0] * 5
    # climbing at 4 m/s, the simulated aircraft brakes at 4 m/s^2: 1.0 s, plus one 0.1 s osd period and
    # the test's own polling (measured here: 1.1 s)
    assert took < 1.5, f"stopped {took:.2f}s after the emergency stop"
    notices = [b for t, b, _ in cloud.messages[mark:]
               if t.endswith("/events") and b and b.get("method") == "drc_status_notify"]  # fmt: skip
    assert all(n["data"]["drc_state"] == 2 for n in notices)  # stopped and held, still in live control
