"""A gateway killed mid-flight restarts into a safe, truthful state (issue #31), with the flight controller
in a process of its own so the aircraft outlives the gateway: ``dji-gateway simulate osdk --tcp`` (which
holds the last movement set-point without limit, the worst case), ``dji-gateway run --config`` with a
``state_dir``, a real mosquitto, the cloud a paho client.

* SIGKILL mid live control at 4 m/s, restart: the aircraft is stopped (horizontal speed < 0.5 m/s) within
  5 s of the restart, and the cloud is told (``x_osdk_safety_notify`` "stopped", naming the speed found).
* SIGKILL mid-wayline, restart: the task is reported again under the same ``flight_id`` (from the store),
  the osd says ``mode_code`` 5, ``flighttask_pause`` answers 0 and the aircraft holds within 3 s, and
  ``return_home`` ends the task and flies home (``mode_code`` 9).
"""

from __future__ import annotations

import json
import math
import os
import signal
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from adapters.wayline.writer import PointSpec, kmz_bytes, md5_hex, waylines_wpml
from gateway.local_broker import LocalBroker
from tests.support import CloudClient, Proc, wait_until
from tests.test_wayline_e2e import FileStore, ResourceAnswerer

pytestmark = [pytest.mark.broker, pytest.mark.slow]

GW = "GW-TEST-1"  # the ResourceAnswerer's gateway
SN = "OSDK-RESTART-1"
HOME = (22.5431, 113.958)  # the simulator's default home
HOME_ALT = 50.0


def _ne(north: float, east: float) -> tuple[float, float]:
    lat = HOME[0] + math.degrees(north / 6_378_137.0)
    lon = HOME[1] + math.degrees(east / (6_378_137.0 * math.cos(math.radians(HOME[0]))))
    return lat, lon


class Rig:
    """The simulated flight controller's process, the gateway's (restartable), the cloud."""

    def __init__(self, broker: LocalBroker, tmp: Path, hold: str = "inf") -> None:
        self.broker, self.tmp = broker, tmp
        exe = str(Path(sys.executable).parent / "dji-gateway")
        self.exe = exe
        self.env = {k: v for k, v in os.environ.items() if not k.startswith("DJIGW_")} | {
            "PYTHONUNBUFFERED": "1"
        }
        self.sim = Proc("fc", [exe, "simulate", "osdk", "--tcp", "0", "--setpoint-hold", hold], self.env)
        url = self.sim.wait_for_line(r"simulator at (socket://127\.0\.0\.1:\d+)", 20).group(1)
        self.config = tmp / "gateway.toml"
        self.config.write_text(
            f'gateway_sn = "{GW}"\nosd_period = 0.2\nstate_dir = "{tmp / "state"}"\n'
            f'[broker]\nurl = "{broker.url}"\n[metrics]\nenabled = false\n'
            f'[[devices]]\ntype = "osdk"\nsn = "{SN}"\nurl = "{url}"\n'
        )
        self.cloud = CloudClient(broker.host, broker.port, GW)
        self.hold = hold
        self.gateway: Proc | None = None
        self.generation = 0

    def start_gateway(self) -> float:
        """Start the gateway; returns when it was started (monotonic), once its aircraft is online."""
        self.generation += 1
        started = time.monotonic()
        argv = [self.exe, "run", "--config", str(self.config)]
        self.gateway = Proc(f"gateway-{self.generation}", argv, self.env)
        self.gateway.wait_for_line(r"aircraft \S+ activated", 20)
        return started

    def kill_gateway(self) -> None:
        assert self.gateway is not None
        self.gateway.stop(signal.SIGKILL)

    def close(self) -> None:
        if self.gateway is not None:
            self.gateway.stop()
        self.cloud.close()
        self.sim.stop()


@pytest.fixture(params=["inf"])
def rig(request: pytest.FixtureRequest, private_broker: LocalBroker, tmp_path: Path) -> Iterator[Rig]:
    """The simulated FC holds a movement set-point for ``request.param`` seconds (``inf``: forever, the
    worst case; a finite hold: the FC brakes on its own once sticks stop)."""
    r = Rig(private_broker, tmp_path, request.param)
    try:
        yield r
    finally:
        r.close()


def _service(rig: Rig, method: str, data: Any, timeout: float = 10.0) -> dict[str, Any]:
    return rig.cloud.service(method, data, timeout=timeout)


def _last_osd(rig: Rig) -> dict[str, Any]:
    return rig.cloud.find(f"{SN}/osd", lambda b: "latitude" in b["data"])[-1]["data"]


def _fresh_osd(rig: Rig, predicate: Any, timeout: float, what: str) -> dict[str, Any]:
    """Wait for an osd received from now on that satisfies ``predicate`` (what came before is kept: an
    event the gateway sent meanwhile is still there for the test to find)."""
    since = rig.cloud.mark()
    found: dict[str, Any] = wait_until(
        lambda: next(
            (d for d in (b["data"] for b in rig.cloud.find(f"{SN}/osd", since=since)) if predicate(d)), None
        ),
        timeout,
        what=what,
    )
    return found


def _take_off(rig: Rig, above_home: float) -> None:
    target = _ne(10.0, 0.0)
    data = {
        "target_latitude": target[0],
        "target_longitude": target[1],
        "target_height": HOME_ALT + above_home,
        "security_takeoff_height": above_home,
        "rth_altitude": 60,
        "max_speed": 10,
        "flight_id": f"tk-{uuid.uuid4().hex[:8]}",
    }
    r = _service(rig, "takeoff_to_point", data)
    assert r["data"]["result"] == 0, r["data"]
    wait_until(
        lambda: rig.cloud.find(
            "/events",
            lambda b: b.get("method") == "takeoff_to_point_progress" and b["data"]["status"] == "wayline_ok",
        ),
        60,
        what="take-off to point flown",
    )


class Sticks:
    """The cloud's heartbeats (5 Hz) and a forward stick (10 Hz) on drc/down, until stopped."""

    def __init__(self, cloud: CloudClient, forward: float) -> None:
        self.cloud, self.forward = cloud, forward
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        down = f"thing/product/{GW}/drc/down"
        seq = 0
        while not self.stop.is_set():
            seq += 1
            now = int(time.time() * 1000)
            beat = {"method": "heart_beat", "data": {"seq": seq, "timestamp": now}}
            self.cloud.client.publish(down, json.dumps(beat))
            stick = {"seq": seq, "x": 0.0, "y": self.forward, "h": 0.0, "w": 0.0}  # seed: +y forward
            self.cloud.client.publish(down, json.dumps({"method": "drone_control", "data": stick}))
            self.stop.wait(0.1)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(2)


@pytest.mark.parametrize("rig", ["inf", "1"], indirect=True)
def test_killed_mid_live_control_the_restart_stops_the_aircraft(rig: Rig) -> None:
    """Either kind of controller is stopped within 5 s of the restart; the one that holds its set-point
    forever is found moving and stopped by the gateway, and the cloud is told."""
    rig.start_gateway()
    rig.cloud.wait_for(f"{SN}/osd", lambda b: "latitude" in b["data"], timeout=20)
    assert _service(rig, "flight_authority_grab", {})["data"]["result"] == 0
    _take_off(rig, 20.0)
    host, port = rig.broker.host, rig.broker.port
    link = {"address": f"{host}:{port}", "client_id": "drc-restart", "username": "", "password": "",
            "expire_time": int(time.time()) + 600, "enable_tls": False}  # fmt: skip
    r = _service(rig, "drc_mode_enter", {"mqtt_broker": link, "osd_frequency": 5, "hsi_frequency": 1})
    assert r["data"]["result"] == 0, r
    sticks = Sticks(rig.cloud, 4.0)
    try:
        _fresh_osd(rig, lambda d: d.get("horizontal_speed", 0) > 3.5, 15, "flying at 4 m/s by sticks")
        rig.kill_gateway()  # mid live control: nothing stops the set-point the FC holds
    finally:
        sticks.close()
    # inf: the aircraft flies on, ungoverned; 1 s: the FC brakes on its own (4 m/s at 4 m/s^2) and hovers
    time.sleep(1.0 if rig.hold == "inf" else 3.0)
    rig.cloud.clear()
    rig.start_gateway()
    activated = time.monotonic()  # the restarted gateway has just seen its aircraft (its start-up under a
    # loaded machine's scheduling is not what is measured: the safety check runs once it is activated)
    slow = _fresh_osd(rig, lambda d: d.get("horizontal_speed", 99) < 0.5, 10, "stopped after the restart")
    assert slow is not None
    stopped_after = time.monotonic() - activated
    assert stopped_after < 5.0, f"stopped {stopped_after:.1f} s after the restarted gateway activated it"
    assert rig.gateway is not None
    if rig.hold == "inf":  # found moving: the gateway's stop is what stopped it, and it says so
        events = wait_until(
            lambda: rig.cloud.find("/events", lambda b: b.get("method") == "x_osdk_safety_notify"),
            5,
            what="told",
        )
        told = events[0]["data"]
        assert told["action"] == "stopped", told
        found = float(told["reason"].split("horizontal speed ")[1].split(" m/s")[0])
        assert found > 3.0, told
        assert "found in the air under SDK control" in rig.gateway.output()
    else:  # the FC braked on its own 1 s after the last stick: found hovering, nothing to stop or report
        rig.gateway.wait_for_line("hovering: nothing to stop", 5)
        assert not rig.cloud.find("/events", lambda b: b.get("method") == "x_osdk_safety_notify")
    # and it stays stopped: the FC holds the zero set-point
    time.sleep(1.5)
    assert _last_osd(rig)["horizontal_speed"] < 0.5


def _route(rig: Rig, flight_id: str, store: FileStore, files: dict[str, tuple[Any, str]]) -> dict[str, Any]:
    coords = [_ne(0.0, 0.0), _ne(300.0, 0.0), _ne(300.0, 300.0)]
    pts = [PointSpec(lat, lon, 20.0) for lat, lon in coords]
    kmz = kmz_bytes(waylines_wpml(pts, speed=8.0, transitional_speed=8.0, take_off_security_height=8.0))
    name = f"{flight_id}.kmz"
    store.put(name, kmz)
    files[flight_id] = (name, md5_hex(kmz))
    return {
        "flight_id": flight_id,
        "execute_time": int(time.time() * 1000),
        "task_type": 0,
        "wayline_type": 0,
        "file": {"url": store.url(name), "fingerprint": md5_hex(kmz)},
        "rth_altitude": 40,
        "rth_mode": 1,
        "out_of_control_action": 0,
        "exit_wayline_when_rc_lost": 1,
    }


def _progress(rig: Rig, flight_id: str) -> list[dict[str, Any]]:
    return [
        b["data"]
        for b in rig.cloud.find("/events", lambda b: b.get("method") == "flighttask_progress")
        if b["data"]["output"]["ext"]["flight_id"] == flight_id
    ]


def test_killed_mid_wayline_the_restart_reports_the_task_and_acts_on_it(rig: Rig) -> None:
    store = FileStore()
    files: dict[str, tuple[Any, str]] = {}
    answerer = ResourceAnswerer(rig.broker, files, store)
    try:
        rig.start_gateway()
        rig.cloud.wait_for(f"{SN}/osd", lambda b: "latitude" in b["data"], timeout=20)
        assert _service(rig, "flight_authority_grab", {})["data"]["result"] == 0
        flight = f"restart-{uuid.uuid4().hex[:8]}"
        assert _service(rig, "flighttask_prepare", _route(rig, flight, store, files))["data"]["result"] == 0
        assert _service(rig, "flighttask_execute", {"flight_id": flight})["data"]["result"] == 0
        wait_until(
            lambda: any(
                p["output"]["ext"]["current_waypoint_index"] >= 1 and p["output"]["status"] == "in_progress"
                for p in _progress(rig, flight)
            ),
            60,
            what="flying the first leg",
        )
        _fresh_osd(rig, lambda d: d.get("horizontal_speed", 0) > 6.0, 15, "at cruise speed")
        rig.kill_gateway()
        time.sleep(1.0)  # the FC flies its mission on, with nobody reporting it
        rig.cloud.clear()
        rig.start_gateway()
        # the same task, reported again, from the store; the aircraft still flies the route
        again = wait_until(
            lambda: [p for p in _progress(rig, flight) if p["output"]["status"] == "in_progress"] or None,
            10,
            what="the task reported after the restart",
        )
        assert again[0]["output"]["ext"]["current_waypoint_index"] >= 1, again[0]
        _fresh_osd(rig, lambda d: d.get("mode_code") == 5 and d.get("horizontal_speed", 0) > 4.0, 5, "mode 5")
        # pause acts on the FC's mission: answered 0, the aircraft holds within 3 s
        r = _service(rig, "flighttask_pause", None)
        assert r["data"]["result"] == 0, r["data"]
        paused = time.monotonic()
        _fresh_osd(rig, lambda d: d.get("horizontal_speed", 99) < 0.5, 5, "holding")
        assert time.monotonic() - paused < 3.0
        wait_until(lambda: _progress(rig, flight)[-1]["output"]["status"] == "paused", 5, what="paused")
        # return home works: the task ends canceled and the aircraft heads home (mode_code 9)
        assert _service(rig, "flight_authority_grab", {})["data"]["result"] == 0  # a new process's authority
        r = _service(rig, "return_home", None)
        assert r["data"]["result"] == 0, r["data"]
        wait_until(lambda: _progress(rig, flight)[-1]["output"]["status"] == "canceled", 5, what="canceled")
        home = _fresh_osd(rig, lambda d: d.get("mode_code") == 9, 10, "returning home")
        far = math.dist(_ne(0, 0), (home["latitude"], home["longitude"]))
        wait_until(
            lambda: (
                math.dist(_ne(0, 0), (_last_osd(rig)["latitude"], _last_osd(rig)["longitude"])) < far * 0.8
            ),
            30,
            what="closer to home",
        )
    finally:
        answerer.close()
        store.close()


def test_killed_mid_fly_to_the_restart_continues_it_under_its_id(rig: Rig) -> None:
    """The fly-to the gateway started is kept in the store: after a SIGKILL and a restart its progress goes
    on under the same fly_to_id, to wayline_ok at the target."""
    rig.start_gateway()
    rig.cloud.wait_for(f"{SN}/osd", lambda b: "latitude" in b["data"], timeout=20)
    assert _service(rig, "flight_authority_grab", {})["data"]["result"] == 0
    _take_off(rig, 20.0)
    target = _ne(150.0, 0.0)
    points = [{"latitude": target[0], "longitude": target[1], "height": HOME_ALT + 20}]
    r = _service(rig, "fly_to_point", {"fly_to_id": "far-150", "max_speed": 8, "points": points})
    assert r["data"]["result"] == 0, r["data"]

    def progress() -> list[dict[str, Any]]:
        return [
            b["data"]
            for b in rig.cloud.find("/events", lambda b: b.get("method") == "fly_to_point_progress")
            if b["data"]["fly_to_id"] == "far-150"
        ]

    _fresh_osd(rig, lambda d: d.get("horizontal_speed", 0) > 6.0, 15, "at cruise speed")
    rig.kill_gateway()
    time.sleep(1.0)
    rig.cloud.clear()
    rig.start_gateway()
    going = wait_until(
        lambda: [p for p in progress() if p["status"] == "wayline_progress"] or None, 10, what="continued"
    )
    assert 0 < going[0]["remaining_distance"] < 140, going[0]
    assert going[0]["planned_path_points"] == points
    done = wait_until(lambda: [p for p in progress() if p["status"] == "wayline_ok"] or None, 40, what="ok")
    assert done[-1]["remaining_distance"] == 0
    last = _last_osd(rig)
    assert math.dist(target, (last["latitude"], last["longitude"])) < 1e-4  # ~10 m: at the target


@pytest.mark.slow
def test_killed_mid_return_home_the_restart_reports_it_and_can_cancel_it(rig: Rig) -> None:
    """Issue #37's fault variant: the gateway dies while the FC flies its go home; the FC keeps returning,
    and the restarted gateway reports it (mode_code 9 from the FC, not from a memory of its own), cancels
    it on request (the aircraft hovers) and starts it again, down to a landing at home."""
    rig.start_gateway()
    rig.cloud.wait_for(f"{SN}/osd", lambda b: "latitude" in b["data"], timeout=20)
    assert _service(rig, "flight_authority_grab", {})["data"]["result"] == 0
    # 200 m out at 15 m/s, so the FC's flight home (10 m/s) lasts 20 s: the restart must find it flying
    # even on a loaded machine (a cancel once it lands is rightly refused, 314000: nothing returns then)
    target = _ne(200.0, 0.0)
    data = {"target_latitude": target[0], "target_longitude": target[1], "target_height": HOME_ALT + 20.0,
            "security_takeoff_height": 20.0, "rth_altitude": 20, "max_speed": 15,
            "flight_id": f"tk-{uuid.uuid4().hex[:8]}"}  # fmt: skip
    assert _service(rig, "takeoff_to_point", data)["data"]["result"] == 0
    wait_until(
        lambda: rig.cloud.find("/events", lambda b: b.get("method") == "takeoff_to_point_progress"
                               and b["data"]["status"] == "task_finish"),
        60,
        what="out at 200 m",
    )  # fmt: skip
    assert _service(rig, "return_home", None)["data"]["result"] == 0
    _fresh_osd(rig, lambda d: d.get("mode_code") == 9 and d.get("horizontal_speed", 0) > 3.0, 15, "returning")
    rig.kill_gateway()
    time.sleep(1.0)  # nobody reports it; the FC flies home on its own
    rig.cloud.clear()
    rig.start_gateway()
    # the FC's go home, reported from what the FC says (this process never started it)
    _fresh_osd(rig, lambda d: d.get("mode_code") == 9, 15, "the restarted gateway reports the return")
    assert _service(rig, "flight_authority_grab", {})["data"]["result"] == 0  # a new process's authority
    r = _service(rig, "return_home_cancel", None)
    assert r["data"]["result"] == 0, r["data"]
    hover = _fresh_osd(rig, lambda d: d.get("mode_code") != 9 and d.get("horizontal_speed", 99) < 0.5, 10,
                       "hovering")  # fmt: skip
    assert hover["mode_code"] != 10, hover  # it hovers away from home, not landing
    assert _service(rig, "return_home", None)["data"]["result"] == 0
    _fresh_osd(rig, lambda d: d.get("mode_code") == 10, 40, "landing at home")
    landed = _fresh_osd(
        rig, lambda d: d.get("elevation", 99.0) < 0.2 and d.get("mode_code") == 0, 40, "landed"
    )
    assert math.dist(_ne(0, 0), (landed["latitude"], landed["longitude"])) * 111_000 < 2.0, landed
