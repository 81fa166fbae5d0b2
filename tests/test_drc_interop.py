"""Issue #17, the DRC and progress half, against ``dji-gateway run --simulate`` as its own process
through a real mosquitto, as a cloud built on DJI's reference cloud (every DRC message five times,
``"data": ""``) or written for an RC Plus (``stick_control``, ``drc_gimbal_reset``, the newer pushes)
would drive it.

One gateway for the module: the tests run in order (stops first, then a 250 m fly-to that leaves the
aircraft in the air, then live control of that aircraft and the gimbal).
"""

from __future__ import annotations

import itertools
import json
import math
import time
from collections.abc import Iterator
from typing import Any

import paho.mqtt.client as paho
import pytest

from gateway.cli.run import SIM_GATEWAY_SN, SIM_GIMBAL_PAYLOAD_INDEX
from gateway.local_broker import LocalBroker
from tests.support import CloudClient, simulated_gateway, wait_until

pytestmark = [pytest.mark.broker, pytest.mark.slow]

GW = SIM_GATEWAY_SN
HOME, HOME_ALT = (22.5431, 113.958), 50.0  # the simulated aircraft's take-off point (README)
STATE_HZ, BATTERIES_HZ = 4.0, 2.0  # drc.drone_state_hz / drc.batteries_hz given to the gateway
COPIES = 5  # DJI's Java Cloud SDK publishes each DRC message five times
SPEED = 15  # m/s: the fly-to's max_speed (the simulator's fastest), to keep the 250 m flight short


class TimedCloud(CloudClient):
    """A cloud that also notes when each message arrived (monotonic s), for rates and gaps."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.arrivals: list[tuple[float, str, dict[str, Any] | None]] = []
        super().__init__(*args, **kwargs)

    def _on_message(self, client: paho.Client, userdata: Any, msg: paho.MQTTMessage) -> None:
        try:
            body = json.loads(msg.payload)
        except ValueError:
            body = None
        self.arrivals.append((time.monotonic(), msg.topic, body))
        super()._on_message(client, userdata, msg)

    def times(self, suffix: str, method: str, since: float = 0.0) -> list[float]:
        return [
            t
            for t, topic, b in list(self.arrivals)
            if t >= since and topic.endswith(suffix) and b is not None and b.get("method") == method
        ]

    def raw(self, suffix: str, body: dict[str, Any], copies: int = 1, qos: int = 1) -> None:
        for _ in range(copies):
            self.publish(f"thing/product/{GW}/{suffix}", json.dumps(body), qos=qos)


@pytest.fixture(scope="module")
def sim() -> Iterator[dict[str, Any]]:
    broker = LocalBroker().start()
    env = {"DJIGW_DRC__DRONE_STATE_HZ": str(STATE_HZ), "DJIGW_DRC__BATTERIES_HZ": str(BATTERIES_HZ)}
    # the cloud subscribes first: a gateway's update_topo published before anyone listens is not seen
    cloud = TimedCloud(broker.host, broker.port, GW)
    proc, _ = simulated_gateway(broker.url, **env)
    try:
        # the dock lists the aircraft and the gimbal; the robot announces itself (docs/cloud-api.md)
        cloud.wait_for(f"{GW}/status", lambda b: len(b["data"]["sub_devices"]) == 2, timeout=15)
        yield {"cloud": cloud, "broker": broker, "proc": proc}
    finally:
        cloud.close()
        proc.stop()
        broker.stop()


def _service_raw(cloud: TimedCloud, method: str, data: Any, tid: str) -> dict[str, Any]:
    body = {
        "tid": tid,
        "bid": f"b-{tid}",
        "timestamp": int(time.time() * 1000),
        "method": method,
        "data": data,
    }
    cloud.raw("services", body)
    return cloud.wait_for("services_reply", lambda b: b.get("tid") == tid, timeout=10)[-1]


def _north(north_m: float) -> tuple[float, float]:
    return HOME[0] + math.degrees(north_m / 6_378_137.0), HOME[1]


def _down(cloud: TimedCloud, method: str, data: dict[str, Any], seq: int | None = None) -> None:
    body: dict[str, Any] = {"method": method, "data": data}
    if seq is not None:
        body["seq"] = seq
    cloud.raw("drc/down", body, copies=COPIES, qos=0)


def test_stops_with_empty_string_data_are_answered_without_a_parse_error(sim: dict[str, Any]) -> None:
    cloud = sim["cloud"]
    for method in ("fly_to_point_stop", "drc_mode_exit"):
        reply = _service_raw(cloud, method, "", tid=f"empty-{method}")
        assert reply["method"] == method and reply["data"]["result"] != 325001, reply
    # nothing to stop: both are plain successes
    assert _service_raw(cloud, "drc_mode_exit", "", tid="empty-again")["data"]["result"] == 0


def test_a_250_m_fly_to_reports_progress_at_least_once_a_second(sim: dict[str, Any]) -> None:
    cloud = sim["cloud"]
    assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
    target = _north(10.0)
    takeoff = {"target_latitude": target[0], "target_longitude": target[1], "target_height": HOME_ALT + 20,
               "security_takeoff_height": 20.0, "rth_altitude": 30, "flight_id": "up",
               "max_speed": 10}  # fmt: skip
    assert cloud.service("takeoff_to_point", takeoff)["data"]["result"] == 0
    cloud.wait_for("events", lambda b: b["method"] == "takeoff_to_point_progress"
                   and b["data"]["status"] == "task_finish", timeout=60)  # fmt: skip

    far = _north(260.0)  # 250 m from where the take-off left it
    points = [{"latitude": far[0], "longitude": far[1], "height": HOME_ALT + 20}]
    start = time.monotonic()
    reply = cloud.service("fly_to_point", {"fly_to_id": "far-250", "max_speed": SPEED, "points": points})
    assert reply["data"]["result"] == 0
    replied = time.monotonic()
    done = cloud.wait_for("events", lambda b: b["method"] == "fly_to_point_progress"
                          and b["data"]["status"] == "wayline_ok", timeout=60)[-1]  # fmt: skip
    assert done["data"]["fly_to_id"] == "far-250" and done["data"]["remaining_distance"] == 0
    arrived = max(cloud.times("/events", "fly_to_point_progress"))
    seen = cloud.times("/events", "fly_to_point_progress", since=start)
    flight = arrived - replied
    assert flight > 250 / SPEED, f"a 250 m flight at {SPEED} m/s took {flight:.1f} s"
    gaps = [b - a for a, b in zip([replied, *seen], seen, strict=False)]
    assert len(seen) >= flight, (len(seen), flight)  # at least once a second over the flight
    # sent every 0.5 s by design: a silence over 1.5 s is a stalled report, not a loaded machine's jitter
    assert max(gaps) <= 1.5, f"longest silence {max(gaps):.2f} s"
    progress = [b["data"] for b in cloud.find("/events", lambda b: b.get("method") == "fly_to_point_progress")
                if b["data"]["fly_to_id"] == "far-250"]  # fmt: skip
    remaining = [p["remaining_distance"] for p in progress if p["status"] == "wayline_progress"]
    assert 200 < remaining[0] <= 260 and remaining[-1] < 30, remaining
    assert _mostly_falling(remaining), remaining
    assert all(p["planned_path_points"] == points for p in progress)
    assert all(
        p["remaining_time"] == pytest.approx(p["remaining_distance"] / SPEED, abs=0.11) for p in progress
    )


def _mostly_falling(values: list[float]) -> bool:
    """The aircraft converges on the point: no reading more than a metre above an earlier one."""
    return all(b <= a + 1.0 for a, b in itertools.pairwise(values))


def test_drc_driven_only_by_stick_control_moves_the_aircraft_and_the_gimbal(sim: dict[str, Any]) -> None:
    cloud, broker = sim["cloud"], sim["broker"]
    pi = SIM_GIMBAL_PAYLOAD_INDEX
    assert cloud.service("payload_authority_grab", {"payload_index": pi})["data"]["result"] == 0
    assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0  # sticks fly the aircraft too
    link = {"address": f"{broker.host}:{broker.port}", "client_id": "drc-interop", "username": "u",
            "password": "p", "expire_time": int(time.time()) + 600, "enable_tls": False}  # fmt: skip
    enter = {"tid": "enter-1", "bid": "b-enter", "timestamp": int(time.time() * 1000),
             "method": "drc_mode_enter",
             "data": {"mqtt_broker": link, "osd_frequency": 10, "hsi_frequency": 1}}  # fmt: skip
    cloud.raw("services", enter, copies=COPIES)  # the reference cloud's five copies: one session
    replies = cloud.wait_for("services_reply", lambda b: b.get("tid") == "enter-1", count=COPIES, timeout=10)
    assert [r["data"]["result"] for r in replies] == [0] * COPIES
    entered = lambda b: b["method"] == "drc_status_notify" and b["data"]["drc_state"] == 2  # noqa: E731
    cloud.wait_for("events", entered)

    hb = 0

    def heartbeat() -> None:
        nonlocal hb
        hb += 1
        _down(cloud, "heart_beat", {"timestamp": 1_700_000_000_000 + hb}, seq=hb)

    heartbeat()
    cloud.wait_for("drc/up", lambda b: b["method"] == "heart_beat" and b["data"]["seq"] == 1, count=COPIES)

    def osd() -> dict[str, Any]:
        return cloud.wait_for("drc/up", lambda b: b["method"] == "osd_info_push")[-1]["data"]

    before = osd()
    window_start = time.monotonic()
    # half pitch (forward) and half yaw (clockwise), 10 Hz, every message five times
    seq = 0
    for i in range(30):
        seq += 1
        _down(cloud, "stick_control", {"roll": 1024, "pitch": 1354, "throttle": 1024, "yaw": 1354}, seq=seq)
        if i % 10 == 0:
            heartbeat()
        time.sleep(0.1)
    window = time.monotonic() - window_start
    after = osd()
    speed = math.hypot(after["speed_x"], after["speed_y"])
    assert speed > 3.0, after  # 5 m/s asked for at half pitch
    # 45 °/s for the window (3 s, longer when a loaded machine stretches the sleeps)
    most = min(359.0, 45.0 * window + 45.0)
    turned = (after["attitude_head"] - before["attitude_head"]) % 360
    assert 20 < turned < most, (before["attitude_head"], after["attitude_head"], window)
    gimbal = (after["gimbal_yaw"] - before["gimbal_yaw"]) % 360
    assert 20 < gimbal <= most, (before["gimbal_yaw"], after["gimbal_yaw"], window)  # the gimbal yaws too
    assert "elevation" in after and abs(after["elevation"] - 20.0) < 3.0, after
    # accepted stick_control is not answered (DJI: "this protocol has no reply")
    assert not cloud.find("drc/up", lambda b: b["method"] == "stick_control")

    # the newer pushes at their configured rates (counted over the window, ±40 %)
    for method, hz in (("drc_drone_state_push", STATE_HZ), ("drc_batteries_info_push", BATTERIES_HZ)):
        n = len(cloud.times("drc/up", method, since=window_start))
        assert 0.6 * hz * window <= n <= 1.4 * hz * window + 1, (method, n, window)
    state = cloud.wait_for("drc/up", lambda b: b["method"] == "drc_drone_state_push")[-1]["data"]
    assert state == {"mode_code": 16}  # virtual stick: the sticks fly it (as the aircraft osd says)
    battery = cloud.wait_for("drc/up", lambda b: b["method"] == "drc_batteries_info_push")[-1]["data"]
    assert 0 < battery["capacity_percent"] <= 100

    # drc_gimbal_reset: the gimbal_reset service over drc/down, answered on drc/up
    _down(cloud, "drc_gimbal_reset", {"payload_index": pi, "reset_mode": 0}, seq=1)
    resets = cloud.wait_for("drc/up", lambda b: b["method"] == "drc_gimbal_reset", count=COPIES, timeout=10)
    assert [r["data"]["result"] for r in resets] == [0] * COPIES

    # five emergency stops: every copy answered 0; sticks are then refused (answered) until seq 0
    _down(cloud, "drone_emergency_stop", {}, seq=1)
    stops = cloud.wait_for("drc/up", lambda b: b["method"] == "drone_emergency_stop", count=COPIES)
    assert [s["data"]["result"] for s in stops] == [0] * COPIES
    seq += 1
    _down(cloud, "stick_control", {"pitch": 1684}, seq=seq)
    refused = cloud.wait_for("drc/up", lambda b: b["method"] == "stick_control")
    assert refused[0]["data"]["result"] == 314000 and refused[0]["data"]["output"]["seq"] == seq
    time.sleep(0.3)
    refused = cloud.find("drc/up", lambda b: b["method"] == "stick_control")
    assert 1 <= len(refused) <= COPIES and all(r == refused[0] for r in refused)  # each copy: one refusal
    wait_until(lambda: math.hypot(osd()["speed_x"], osd()["speed_y"]) < 0.5, 10, what="braked")

    # issue #33: a fresh drc_mode_enter, as an RC-side client sends it (github wudizhr/DJI_Cloud_API_demo:
    # "enable_tls": "false", osd_frequency 50), is the same session: answered 0 with the rates used, and it
    # ends the stop's hold, so sticks whose seq only increases drive again (no seq 0 needed)
    rc_link = {**link, "enable_tls": "false"}
    again = {"tid": "enter-2", "bid": "b-enter-2", "timestamp": int(time.time() * 1000),
             "method": "drc_mode_enter", "data": {"mqtt_broker": rc_link, "osd_frequency": 50,
                                                  "hsi_frequency": 1}}  # fmt: skip
    cloud.raw("services", again)
    reply = cloud.wait_for("services_reply", lambda b: b.get("tid") == "enter-2", timeout=10)[-1]["data"]
    assert reply == {"result": 0, "output": {"osd_frequency": 30, "hsi_frequency": 1}}, reply
    heartbeat()
    pushed_from = time.monotonic()
    for _ in range(10):
        seq += 1
        _down(cloud, "stick_control", {"roll": 1024, "pitch": 1354, "throttle": 1024, "yaw": 1024}, seq=seq)
        time.sleep(0.1)
    assert cloud.find("drc/up", lambda b: b["method"] == "stick_control") == refused  # none refused now
    assert math.hypot(osd()["speed_x"], osd()["speed_y"]) > 2.0  # driving again, 5 m/s asked for
    pushes = len(cloud.times("drc/up", "osd_info_push", since=pushed_from))
    assert pushes >= 15, pushes  # 30 Hz asked of the pushes (10 Hz before): at least 15 a second seen

    # five drc_mode_exit copies (one tid): all answered 0, the session ends once
    exit_ = {"tid": "exit-1", "bid": "b-exit", "timestamp": int(time.time() * 1000),
             "method": "drc_mode_exit", "data": ""}  # fmt: skip
    cloud.raw("services", exit_, copies=COPIES)
    replies = cloud.wait_for("services_reply", lambda b: b.get("tid") == "exit-1", count=COPIES, timeout=10)
    assert [r["data"]["result"] for r in replies] == [0] * COPIES
    left = lambda b: b["method"] == "drc_status_notify" and b["data"]["drc_state"] == 0  # noqa: E731
    cloud.wait_for("events", left)
    time.sleep(0.5)
    assert len(cloud.find("events", entered)) == 1 and len(cloud.find("events", left)) == 1
