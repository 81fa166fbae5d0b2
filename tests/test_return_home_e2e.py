"""Return home from every state the aircraft can be in (issue #37), end to end: a cloud (a paho client on a
real mosquitto) drives the gateway, which flies the simulated Onboard SDK flight controller over a real pty.

One parametrized case per starting state (xdist spreads them): each ends with the aircraft landed within
2 m of home, ``mode_code`` 9 (return home) and then 10 (landing) seen in the osd, a ``return_home_info``
event (DJI's dock wayline page) naming the task it interrupted, and that task ended with its terminal
progress. On the ground the return is refused naming why, and nothing moves. ``return_home_cancel`` from
each phase of the return leaves the aircraft hovering.
"""

from __future__ import annotations

import json
import math
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

import pytest

from gateway.local_broker import LocalBroker
from tests.support import CloudClient, wait_until
from tests.test_wayline_e2e import (
    GW,
    HOME,
    HOME_ALT,
    SN,
    _distance,
    _flying_leg_one,
    _ne,
    _prepare_and_execute,
    _rig,
    _status,
)

pytestmark = pytest.mark.broker

RTH_ALT = 20  # m: the lowest go-home altitude an Onboard SDK FC takes (0x01 0x42), the quickest descent


@pytest.fixture
def rig(broker: LocalBroker) -> Iterator[dict[str, Any]]:
    with _rig(broker, grab=True) as made:
        yield made


def _events(cloud: CloudClient, method: str) -> list[dict[str, Any]]:
    return [b["data"] for b in cloud.find("/events", lambda b: b.get("method") == method)]


def _takeoff(cloud: CloudClient, north: float, height: float, flight_id: str = "to-1") -> None:
    lat, lon = _ne(north, 0.0)
    data = {"target_latitude": lat, "target_longitude": lon, "target_height": HOME_ALT + height,
            "security_takeoff_height": 20.0, "rth_altitude": RTH_ALT, "flight_id": flight_id,
            "max_speed": 15}  # fmt: skip
    reply = cloud.service("takeoff_to_point", data)["data"]
    assert reply["result"] == 0, reply


def _takeoff_done(cloud: CloudClient, flight_id: str = "to-1", timeout: float = 40.0) -> None:
    wait_until(
        lambda: any(
            e["status"] == "task_finish" and e["flight_id"] == flight_id
            for e in _events(cloud, "takeoff_to_point_progress")
        ),
        timeout,
        what="take-off finished",
    )


def _hover(fc: Any) -> None:
    wait_until(lambda: fc.inspect(lambda m: m.in_air and m.speed < 0.3), 20, what="hovering")


def _above_home(rig: dict[str, Any]) -> str | None:
    _takeoff(rig["cloud"], 0.0, 20.0)
    _takeoff_done(rig["cloud"])
    _hover(rig["fc"])
    return None


def _far_away(rig: dict[str, Any]) -> str | None:
    _takeoff(rig["cloud"], 200.0, 20.0)
    _takeoff_done(rig["cloud"], timeout=60)
    _hover(rig["fc"])
    assert rig["fc"].inspect(lambda m: math.hypot(m.n, m.e)) > 190.0
    return None


def _mid_wayline(rig: dict[str, Any]) -> str | None:
    flight = _prepare_and_execute(rig, rth_altitude=RTH_ALT)  # the lowest: the quickest descent
    _flying_leg_one(rig, flight)
    return flight


def _mid_wayline_paused(rig: dict[str, Any]) -> str | None:
    flight = _mid_wayline(rig)
    assert rig["cloud"].service("flighttask_pause", None)["data"]["result"] == 0
    wait_until(lambda: _status(rig["cloud"], flight)[-1:] == ["paused"], 5, what="paused")
    return flight


def _mid_takeoff(rig: dict[str, Any]) -> str | None:
    _takeoff(rig["cloud"], 60.0, 20.0)
    wait_until(lambda: rig["fc"].inspect(lambda m: m.u > 5.0), 20, what="climbing")
    return None


def _mid_fly_to(rig: dict[str, Any]) -> str | None:
    cloud = rig["cloud"]
    _takeoff(cloud, 0.0, 20.0)
    _takeoff_done(cloud)
    lat, lon = _ne(80.0, 0.0)
    points = [{"latitude": lat, "longitude": lon, "height": HOME_ALT + 20.0}]
    r = cloud.service("fly_to_point", {"fly_to_id": "fly-1", "max_speed": 10, "points": points})["data"]
    assert r["result"] == 0, r
    wait_until(lambda: rig["fc"].inspect(lambda m: m.n > 10.0), 20, what="flying to the point")
    return None


def _mid_drc(rig: dict[str, Any]) -> str | None:
    cloud = rig["cloud"]
    _takeoff(cloud, 0.0, 20.0)
    _takeoff_done(cloud)
    host_port = rig["gw"].app.settings.broker.url.split("//", 1)[1]
    link = {"address": host_port, "client_id": "drc-rth", "username": "", "password": "",
            "expire_time": int(time.time()) + 600, "enable_tls": False}  # fmt: skip
    r = cloud.service("drc_mode_enter", {"mqtt_broker": link, "osd_frequency": 5, "hsi_frequency": 1})
    assert r["data"]["result"] == 0, r
    stop = threading.Event()
    down = f"thing/product/{GW}/drc/down"

    def stream() -> None:  # 10 Hz sticks until the test ends (a pilot's stick held forward)
        seq = 0
        while not stop.is_set():
            seq += 1
            cloud.publish(down, json.dumps({"method": "heart_beat", "data": {"seq": seq, "timestamp": 1}}), 0)
            stick = {"seq": seq, "x": 0.0, "y": 3.0, "h": 0.0, "w": 0.0}
            cloud.publish(down, json.dumps({"method": "drone_control", "data": stick}), 0)
            time.sleep(0.1)

    streamer = threading.Thread(target=stream, daemon=True)
    streamer.start()
    rig["streamer"] = (stop, streamer)
    wait_until(
        lambda: rig["fc"].inspect(lambda m: math.hypot(m.n, m.e)) > 5.0, 10, what="moved by the sticks"
    )
    return None


def _after_emergency_stop(rig: dict[str, Any]) -> str | None:
    cloud = rig["cloud"]
    _takeoff(cloud, 80.0, 20.0)
    wait_until(lambda: rig["fc"].inspect(lambda m: m.n > 15.0), 30, what="flying north")
    stop = json.dumps({"method": "drone_emergency_stop", "data": {}})
    cloud.publish(f"thing/product/{GW}/drc/down", stop, 0)
    _hover(rig["fc"])
    return None


STATES: dict[str, Callable[[dict[str, Any]], str | None]] = {
    "above_home": _above_home,
    "200m_away": _far_away,
    "mid_wayline": _mid_wayline,
    "mid_wayline_paused": _mid_wayline_paused,
    "mid_takeoff_to_point": _mid_takeoff,
    "mid_fly_to_point": _mid_fly_to,
    "mid_drc_sticks": _mid_drc,
    "after_emergency_stop": _after_emergency_stop,
}


def _modes(cloud: CloudClient) -> list[int]:
    return [int(b["data"]["mode_code"]) for b in cloud.find(f"{SN}/osd", lambda b: "mode_code" in b["data"])]


@pytest.mark.slow
@pytest.mark.parametrize("state", list(STATES))
def test_return_home_lands_at_home_from(rig: dict[str, Any], state: str) -> None:
    cloud, fc = rig["cloud"], rig["fc"]
    try:
        flight = STATES[state](rig)
        cloud.clear()
        reply = cloud.service("return_home", None)["data"]
        assert reply["result"] == 0, reply
        if flight is not None:  # the wayline it interrupted ends canceled, "user RTH", with a break point
            wait_until(lambda: _status(cloud, flight)[-1:] == ["canceled"], 5, what="task canceled")
        info = cloud.wait_for("/events", lambda b: b.get("method") == "return_home_info")[-1]["data"]
        assert info["flight_id"] == (flight or ""), info
        assert info["last_point_type"] == 0 and info["planned_path_points"], info
        last = info["planned_path_points"][-1]
        assert _distance(last["latitude"], last["longitude"], *HOME) < 1.0, info
        # over home the FC's go home is its landing at once (DJI: within 20 m it lands where it is): 10;
        # elsewhere 9 while it returns, then 10 while it lands
        first = 10 if state == "above_home" else 9
        wait_until(lambda: first in _modes(cloud), 5, what=f"mode_code {first} in osd")
        wait_until(lambda: not fc.inspect(lambda m: m.in_air), 90, what="landed")
        assert fc.inspect(lambda m: math.hypot(m.n, m.e)) < 2.0
        modes = _modes(cloud)
        assert 10 in modes[modes.index(first) :], modes  # landing after the return
        assert 5 not in modes[modes.index(first) :], modes  # never a "wayline" on the way home
        if "streamer" in rig:  # the sticks during the return were refused, naming what flies it
            answers = cloud.find("drc/up", lambda b: b.get("method") == "drone_control")
            refused = [a for a in answers if a["data"]["result"] != 0]
            reasons = {a["data"]["output"]["reason"].split(" flies")[0] for a in refused}
            assert "return home" in reasons and reasons <= {"return home", "landing"}, reasons
    finally:
        if "streamer" in rig:
            stop, streamer = rig["streamer"]
            stop.set()
            streamer.join(5)


def test_return_home_on_the_ground_is_refused_naming_why_and_nothing_moves(rig: dict[str, Any]) -> None:
    cloud, fc = rig["cloud"], rig["fc"]
    reply = cloud.service("return_home", None)["data"]
    assert reply["result"] != 0 and "ground" in reply["output"]["reason"], reply
    time.sleep(0.5)
    assert fc.inspect(lambda m: (m.in_air, m.motors_on, m.task)) == (False, False, "ground")
    assert fc.inspect(lambda m: m.actions["flight_task"]) == 0


@pytest.mark.parametrize("phase", ["returning", "landing"])
def test_return_home_cancel_from_each_phase_leaves_it_hovering(rig: dict[str, Any], phase: str) -> None:
    """return_home_cancel while it flies home (the FC's exit go home) and while it lands at home (its
    exit landing): 0, the aircraft hovers in the air where it was, and the osd leaves 9 / 10."""
    cloud, fc = rig["cloud"], rig["fc"]
    _takeoff(cloud, 0.0 if phase == "landing" else 60.0, 20.0)
    _takeoff_done(cloud)
    _hover(fc)
    assert cloud.service("return_home", None)["data"]["result"] == 0
    task = "landing" if phase == "landing" else "go_home"
    wait_until(lambda: fc.inspect(lambda m: m.task) == task, 10, what=task)
    if phase == "returning":
        wait_until(lambda: fc.inspect(lambda m: m.speed) > 3.0, 10, what="flying home")
    else:
        wait_until(lambda: fc.inspect(lambda m: m.u) < 19.0, 10, what="descending")
    reply = cloud.service("return_home_cancel", None)["data"]
    assert reply["result"] == 0, reply
    _hover(fc)
    assert fc.inspect(lambda m: (m.in_air, m.task)) == (True, "hover")
    cloud.clear()
    wait_until(lambda: len(_modes(cloud)) >= 2, 5, what="fresh osd")
    assert not {9, 10} & set(_modes(cloud)[1:]), _modes(cloud)
    # nothing returns any more: a second cancel says so
    assert cloud.service("return_home_cancel", None)["data"]["result"] == 314000
