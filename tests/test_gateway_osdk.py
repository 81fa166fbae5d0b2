"""The Onboard SDK aircraft end to end: a cloud-side paho client → mosquitto → the gateway → the
open protocol on a real pseudo-terminal → the simulated flight controller, and back as replies,
progress events and osd."""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections.abc import Iterator
from typing import Any

import pytest
import serial

from adapters.osdk.protocol import encode_command
from adapters.osdk.sim import OsdkFcDevice, OsdkFcModel
from adapters.simio import PtyEndpoint
from gateway.local_broker import LocalBroker
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker

GW = "GW-TEST-1"
SN = "OSDK-T-1"
HOME = (22.5431, 113.958)
HOME_ALT = 50.0  # the simulator's WGS84 altitude of the take-off point


def _north_east(lat: float, lon: float, north: float, east: float) -> tuple[float, float]:
    dlat = math.degrees(north / 6_378_137.0)
    dlon = math.degrees(east / (6_378_137.0 * math.cos(math.radians(lat))))
    return lat + dlat, lon + dlon


def _distance(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    n = math.radians(lat2 - lat1) * 6_378_137.0
    e = math.radians(lon2 - lon1) * 6_378_137.0 * math.cos(math.radians(lat1))
    return math.hypot(n, e)


@pytest.fixture
def rig(broker: LocalBroker) -> Iterator[dict[str, Any]]:
    device = OsdkFcDevice(OsdkFcModel(home=HOME, home_altitude=HOME_ALT))
    pty = PtyEndpoint(device).start()
    settings = gateway_settings(broker.port, [{"type": "osdk", "sn": SN, "url": pty.path, "app_id": 1234}])
    cloud = CloudClient(broker.host, broker.port, GW)
    gw = GatewayThread(settings).start()
    try:
        cloud.wait_for("status", lambda b: [d["sn"] for d in b["data"]["sub_devices"]] == [SN], timeout=10)
        yield {"fc": device, "cloud": cloud, "gw": gw, "adapter": gw.app.devices.by_sn(SN), "pty": pty}
    finally:
        gw.stop()
        cloud.close()
        pty.stop()


def _events(cloud: CloudClient, method: str) -> list[dict[str, Any]]:
    return [b["data"] for b in cloud.find("/events", lambda b: b.get("method") == method)]


def _takeoff_data(north: float = 30.0, height: float = 20.0, **extra: Any) -> dict[str, Any]:
    """A takeoff_to_point request to ``north`` m north of home, ``height`` m above it."""
    target = _north_east(*HOME, north, 0.0)
    return {
        "target_latitude": target[0],
        "target_longitude": target[1],
        "target_height": HOME_ALT + height,
        "security_takeoff_height": 20.0,
        "rth_altitude": 30,
        "flight_id": "flight-1",
        "max_speed": 12,
        **extra,
    }


def _assert_refused(cloud: CloudClient, base: dict[str, Any], cases: Any) -> None:
    """Each (extra fields, field) case of takeoff_to_point is answered 325001 with a reason naming field."""
    for extra, field in cases:
        reply = cloud.service("takeoff_to_point", {**base, **extra})["data"]
        assert reply["result"] == 325001 and reply["output"]["reason"].startswith(field), (extra, reply)


def _take_off(
    cloud: CloudClient, north: float = 30.0, height: float = 20.0, **extra: Any
) -> tuple[float, float]:
    data = _takeoff_data(north, height, **extra)
    assert cloud.service("takeoff_to_point", data)["data"]["result"] == 0
    return data["target_latitude"], data["target_longitude"]


def test_a_take_off_target_111_km_away_is_refused_and_the_aircraft_stays_on_the_ground(
    rig: dict[str, Any],
) -> None:
    """Issue #33 B: a typo (23.5436 for 22.5436) is refused in the reply, naming the field and the distance
    (the FC would refuse the mission with 0xC7 after taking off); nothing is sent, nothing moves."""
    fc, cloud = rig["fc"], rig["cloud"]
    assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
    cloud.wait_for(f"{SN}/osd", lambda b: "latitude" in b["data"])
    typo = {**_takeoff_data(flight_id="typo"), "target_latitude": HOME[0] + 1.0}
    reply = cloud.service("takeoff_to_point", typo)["data"]
    assert reply["result"] == 336000 + 0xC7, reply
    reason = reply["output"]["reason"]
    assert reason.startswith("target_latitude/target_longitude: 111.3 km from the aircraft"), reason
    assert "2.0 km limit" in reason
    time.sleep(1.0)  # where the take-off would have been
    assert fc.inspect(lambda m: (m.in_air, m.motors_on, m.u, m.actions["flight_task"])) == (
        False,
        False,
        0.0,
        0,
    )
    assert _events(cloud, "takeoff_to_point_progress") == []


def test_takeoff_fields_the_flight_controller_cannot_honour_are_refused(rig: dict[str, Any]) -> None:
    """Nothing accepted is ignored (issue #16 item 4): an RC-loss action other than the FC's configured
    failsafe, a go-home altitude outside the FC's 20..500 m, a target over its height limit are refused
    with 325001 naming the field, before anything is sent; a matching request goes through."""
    fc, cloud = rig["fc"], rig["cloud"]
    assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
    base = _takeoff_data(flight_id="f")
    cases = (
        ({"rc_lost_action": 1}, "rc_lost_action"),  # land; the FC's failsafe is return_home
        ({"rc_lost_action": 0}, "rc_lost_action"),
        ({"rth_altitude": 10}, "rth_altitude"),
        ({"rth_altitude": 501}, "rth_altitude"),
        ({"target_height": HOME_ALT + 600.0}, "target_height"),
    )
    _assert_refused(cloud, base, cases)
    assert fc.inspect(lambda m: (m.actions["flight_task"], m.actions["go_home_altitude_write"])) == (0, 0)
    assert fc.inspect(lambda m: m.go_home_altitude_m) == 20.0
    reply = cloud.service("takeoff_to_point", {**base, "rc_lost_action": 2, "rth_altitude": 45})["data"]
    assert reply["result"] == 0, reply
    assert fc.inspect(lambda m: (m.actions["flight_task"], m.go_home_altitude_m)) == (1, 45.0)


@pytest.mark.slow
def test_java_sdk_takeoff_fields_are_honoured_or_refused(rig: dict[str, Any]) -> None:
    """Issue #17: the Cloud API 1.x fields DJI's Java Cloud SDK sends with takeoff_to_point. What the FC can
    do is done (fixed-height commander mode flies the route at commander_flight_height; the commander
    RC-loss action drives action_on_rc_lost), the rest is refused with 325001 naming the field."""
    fc, cloud = rig["fc"], rig["cloud"]
    assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
    base = _takeoff_data(40.0, 25.0, rth_altitude=60.0, flight_id="java-1", max_speed=12.0)
    cases = (
        ({"rth_mode": 0}, "rth_mode"),
        ({"commander_flight_mode": 0}, "commander_flight_mode"),
        ({"commander_flight_mode": 1}, "commander_flight_height"),
        ({"commander_flight_height": 50.0}, "commander_flight_height"),
        (
            {"simulate_mission": {"is_enable": 1, "latitude": HOME[0], "longitude": HOME[1]}},
            "simulate_mission",
        ),
    )
    _assert_refused(cloud, base, cases)
    assert fc.inspect(lambda m: m.actions["flight_task"]) == 0
    java = {"rth_mode": 1, "commander_mode_lost_action": 1, "commander_flight_mode": 1,
            "commander_flight_height": 35.0, "simulate_mission": {"is_enable": 0, "latitude": HOME[0],
                                                                 "longitude": HOME[1]}}  # fmt: skip
    assert cloud.service("takeoff_to_point", {**base, **java})["data"]["result"] == 0
    wait_until(
        lambda: any(e["status"] == "task_finish" for e in _events(cloud, "takeoff_to_point_progress")),
        40,
        what="take-off task finished",
    )
    # the route: up to 20 m, up to 35 m, across at 35 m, down to the target (25 m above take-off)
    heights = fc.inspect(lambda m: [round(p["altitude"], 1) for p in m.upload.points if p is not None])
    assert heights == [20.0, 35.0, 35.0, 25.0], heights
    assert fc.inspect(lambda m: (m.upload.info["action_on_rc_lost"], m.go_home_altitude_m)) == (0, 60.0)
    statuses = [(e["status"], e["way_point_index"]) for e in _events(cloud, "takeoff_to_point_progress")]
    assert statuses[-2:] == [("wayline_ok", 3), ("task_finish", 3)], statuses


@pytest.mark.slow
def test_the_demo_webs_default_takeoff_flies_each_phase_with_its_rc_loss_action(rig: dict[str, Any]) -> None:
    """Issue #33: DJI's Cloud-API-Demo-Web take-off form as it opens (rc_lost_action 2,
    exit_wayline_when_rc_lost 1, rth_mode 1, commander_mode_lost_action 0, commander_flight_mode 1,
    rth_altitude 100) was refused (325001: "disagrees"). The two fields govern different phases
    (docs/cloud-api.md): the climb to the safe take-off height is flown as a mission that exits on RC loss
    (action_on_rc_lost 0), the flight to the point as one that continues (1); the aircraft reaches the
    target and the events read as one flight."""
    fc, cloud = rig["fc"], rig["cloud"]
    assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
    demo_web = {"rc_lost_action": 2, "exit_wayline_when_rc_lost": 1, "rth_mode": 1,
                "commander_mode_lost_action": 0, "commander_flight_mode": 1, "commander_flight_height": 22.0,
                "rth_altitude": 100, "max_speed": 15}  # fmt: skip
    data = _takeoff_data(10.0, 22.0, flight_id="demo-web-1", **demo_web)  # short: a few seconds
    reply = cloud.service("takeoff_to_point", data)["data"]
    assert reply == {"result": 0}, reply
    missions: list[tuple[int, int]] = []  # (waypoints, action_on_rc_lost) of each upload, in order

    def watch() -> bool:
        up = fc.inspect(
            lambda m: (
                None if m.upload is None else (m.upload.info["length"], m.upload.info["action_on_rc_lost"])
            )
        )
        if up is not None and (not missions or missions[-1] != up):
            missions.append(up)
        return any(e["status"] == "task_finish" for e in _events(cloud, "takeoff_to_point_progress"))

    wait_until(watch, 60, what="take-off task finished", interval=0.05)
    # the climb exits on RC loss, the flight to the point (up to 22 m, across at it) continues
    assert missions == [(2, 0), (3, 1)], missions
    n, e, up = fc.inspect(lambda m: (m.n, m.e, m.u))
    assert math.dist((n, e, up), (10.0, 0.0, 22.0)) < 3.0, (n, e, up)  # at the target, 22 m above home
    assert fc.inspect(lambda m: m.go_home_altitude_m) == 100.0
    statuses = [(e["status"], e["way_point_index"]) for e in _events(cloud, "takeoff_to_point_progress")]
    assert statuses[0] == ("task_ready", 0) and statuses[-2:] == [("wayline_ok", 2), ("task_finish", 2)]
    assert all(s in ("task_ready", "wayline_progress", "wayline_ok", "task_finish") for s, _ in statuses)


def test_activation_topology_and_osd(rig: dict[str, Any]) -> None:
    fc, cloud = rig["fc"], rig["cloud"]
    assert fc.inspect(lambda m: m.activated) and fc.inspect(lambda m: m.actions["activate"]) >= 1
    osd = cloud.wait_for(f"{SN}/osd", lambda b: "latitude" in b["data"])[-1]["data"]
    assert _distance(osd["latitude"], osd["longitude"], *HOME) < 1.0
    assert abs(osd["height"] - HOME_ALT) < 0.5 and osd["mode_code"] == 0
    assert osd["battery"]["capacity_percent"] > 0


@pytest.mark.slow
def test_takeoff_fly_to_and_stop(rig: dict[str, Any]) -> None:
    fc, cloud = rig["fc"], rig["cloud"]
    # without flight authority the cloud may not fly
    here = [{"latitude": HOME[0], "longitude": HOME[1], "height": 60.0}]
    refused = cloud.service("fly_to_point", {"fly_to_id": "x", "max_speed": 5, "points": here})
    assert refused["data"]["result"] == 319030
    assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
    cloud.wait_for(f"{SN}/state", lambda b: b["data"].get("control_source") == "A")

    target = _take_off(cloud, exit_wayline_when_rc_lost=1)
    takeoff = lambda: _events(cloud, "takeoff_to_point_progress")  # noqa: E731
    wait_until(
        lambda: any(e["status"] == "task_finish" for e in takeoff()), 40, what="take-off task finished"
    )
    # the periodic wayline_progress between the points (issue #38) repeat the last one: collapsed here
    progress = [(e["status"], e["way_point_index"]) for e in takeoff()]
    progress = [p for i, p in enumerate(progress) if i == 0 or p != progress[i - 1]]
    expected = [("task_ready", 0), ("wayline_progress", 0), ("wayline_progress", 1), ("wayline_ok", 1)]
    assert progress == [*expected, ("task_finish", 1)], progress
    assert all(e["flight_id"] == "flight-1" and e["result"] == 0 for e in takeoff())
    # exit_wayline_when_rc_lost 1 reached the mission init: action_on_rc_lost 0 (exit, the FC's failsafe)
    assert fc.inspect(lambda m: m.upload.info["action_on_rc_lost"]) == 0
    # rth_altitude reached the wire (0x01 0x42): the simulated FC's go-home altitude was 20 m
    assert fc.inspect(lambda m: (m.actions["go_home_altitude_write"], m.go_home_altitude_m)) == (1, 30.0)
    osd = cloud.wait_for(
        f"{SN}/osd", lambda b: _distance(b["data"]["latitude"], b["data"]["longitude"], *target) < 2.0
    )
    assert abs(osd[-1]["data"]["elevation"] - 20.0) < 1.5

    # fly to two points; progress in order, then wayline_ok, and the aircraft ends at the last point
    p1 = _north_east(*HOME, 30.0, 40.0)
    p2 = _north_east(*HOME, -10.0, 40.0)
    points = [{"latitude": p[0], "longitude": p[1], "height": HOME_ALT + 25.0} for p in (p1, p2)]
    assert (
        cloud.service("fly_to_point", {"fly_to_id": "fly-1", "max_speed": 12, "points": points})["data"][
            "result"
        ]
        == 0
    )
    wait_until(lambda: any(e["status"] == "wayline_ok" for e in _events(cloud, "fly_to_point_progress")), 40,
               what="fly-to finished")  # fmt: skip
    events = [(e["status"], e["way_point_index"]) for e in _events(cloud, "fly_to_point_progress")]
    # periodic progress repeats the point being flown between the waypoint events: in order, no other
    steps = [step for i, step in enumerate(events) if i == 0 or step != events[i - 1]]
    assert steps == [("wayline_progress", 0), ("wayline_progress", 1), ("wayline_ok", 1)], events
    assert all(
        e["fly_to_id"] == "fly-1" and e["result"] == 0 for e in _events(cloud, "fly_to_point_progress")
    )
    osd = cloud.wait_for(
        f"{SN}/osd", lambda b: _distance(b["data"]["latitude"], b["data"]["longitude"], *p2) < 1.5
    )
    assert abs(osd[-1]["data"]["height"] - (HOME_ALT + 25.0)) < 1.5
    # events asked for a reply: the cloud answers, and the gateway stops re-sending
    assert rig["gw"].app.metrics.count("events_published_total", method="fly_to_point_progress") >= 3

    # a far point is refused by the flight controller: 336000 + 0xC7 ("too far"), text in output
    far = _north_east(*HOME, 5000.0, 0.0)
    far_points = [{"latitude": far[0], "longitude": far[1], "height": HOME_ALT + 30}]
    r = cloud.service("fly_to_point", {"fly_to_id": "far", "max_speed": 10, "points": far_points})
    assert r["data"]["result"] == 336000 + 0xC7 and "too far" in r["data"]["output"]["reason"]

    # stop mid-flight: wayline_cancel, and the aircraft stops short of the point
    back = [{"latitude": HOME[0], "longitude": HOME[1], "height": HOME_ALT + 25.0}]
    assert (
        cloud.service("fly_to_point", {"fly_to_id": "fly-2", "max_speed": 5, "points": back})["data"][
            "result"
        ]
        == 0
    )
    time.sleep(1.0)
    assert cloud.service("fly_to_point_stop", {})["data"]["result"] == 0
    cancel = {"fly_to_id": "fly-2", "status": "wayline_cancel"}
    cloud.wait_for(
        "events", lambda b: b.get("method") == "fly_to_point_progress" and cancel.items() <= b["data"].items()
    )
    wait_until(lambda: fc.inspect(lambda m: m.speed) < 0.2, 10, what="hovering after the stop")
    assert fc.inspect(lambda m: math.hypot(m.n, m.e)) > 5.0  # stopped short of home


def test_rc_takeover_drops_authority(rig: dict[str, Any], caplog: pytest.LogCaptureFixture) -> None:
    fc, cloud = rig["fc"], rig["cloud"]
    caplog.set_level(logging.INFO, logger="gateway.northbound")
    assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
    cloud.wait_for(f"{SN}/state", lambda b: b["data"].get("control_source") == "A")
    fc.rc_takeover()
    event = cloud.wait_for("events", lambda b: b.get("method") == "joystick_invalid_notify")[0]
    assert event["data"] == {"reason": 4} and event["need_reply"] == 1
    cloud.wait_for(f"{SN}/state", lambda b: b["data"].get("control_source") == "")
    # an RC take-over keeps its wording (a WARNING: someone else now flies the aircraft)
    lost = [r for r in caplog.records if r.name == "gateway.northbound" and "authority" in r.getMessage()]
    assert [(r.levelno, r.getMessage()) for r in lost] == [
        (logging.WARNING, f"device {SN} took flight authority back")
    ]
    # with the RC in P mode the flight controller refuses to hand control back
    r = cloud.service("flight_authority_grab", {})
    assert r["data"]["result"] == 319030 and "RC" in r["data"]["output"]["reason"]


def test_after_a_release_no_control_frame_is_sent_and_the_log_says_released(
    rig: dict[str, Any], caplog: pytest.LogCaptureFixture
) -> None:
    """Issue #31: on shutdown after the cloud released authority the gateway still sent two zero-velocity
    ``01 03`` frames (the app's stop and the adapter's own) to an aircraft it no longer controlled, and
    the release was logged as the device having "took flight authority back"."""
    fc, cloud, gw, adapter = rig["fc"], rig["cloud"], rig["gw"], rig["adapter"]
    caplog.set_level(logging.INFO, logger="gateway.northbound")
    moves = lambda: fc.inspect(lambda m: m.actions["movement_control"])  # noqa: E731 (every 01 03 frame decoded)
    assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
    before = moves()
    asyncio.run_coroutine_threadsafe(adapter.stop_motion(), gw.loop).result(5)  # while in control: sent
    wait_until(lambda: moves() == before + 1, 5, what="the stop's zero-velocity frame while in control")
    assert cloud.service("x_osdk_authority_release", {})["data"]["result"] == 0
    assert not fc.inspect(lambda m: m.sdk_control)
    cloud.wait_for(f"{SN}/state", lambda b: b["data"].get("control_source") == "")
    released = moves()
    gw.stop()  # the shutdown: the app's stop_motion, then the adapter's stop
    # a marker after the gateway's last byte on the same pty: once the FC has read it, it has read all
    seen = fc.inspect(lambda m: m.actions["get_version"])  # before the write: the FC may read it at once
    with serial.serial_for_url(rig["pty"].path, baudrate=230400, timeout=0.1) as port:
        port.write(encode_command(0x00, 0x00, b"\x00", 2, 4242))
        wait_until(lambda: fc.inspect(lambda m: m.actions["get_version"]) > seen, 5, what="the marker")
    assert moves() == released  # no 01 03 after the release, none at shutdown
    logged = [(r.levelno, r.getMessage()) for r in caplog.records if r.name == "gateway.northbound"]
    assert (logging.INFO, f"device {SN}: flight authority released, as the cloud asked") in logged
    assert not any("took flight authority back" in text for _, text in logged)


def test_ack_loss_is_retransmitted_and_acted_on_once(rig: dict[str, Any]) -> None:
    fc, cloud = rig["fc"], rig["cloud"]
    before = fc.inspect(lambda m: m.actions["obtain_control"])
    dups = fc.inspect(lambda m: m.duplicates)
    fc.drop_acks(1)  # the FC acts, but its ACK is lost: the gateway resends the same frame (session, seq)
    assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
    assert fc.inspect(lambda m: m.actions["obtain_control"]) == before + 1  # acted on once
    assert fc.inspect(lambda m: m.duplicates) == dups + 1  # the resend was recognised and re-ACKed


def test_a_late_ack_is_an_error_and_matches_nothing_later(rig: dict[str, Any]) -> None:
    fc, cloud, adapter = rig["fc"], rig["cloud"], rig["adapter"]
    fc.inspect(lambda m: setattr(m, "ack_delay", 3.0))  # later than every retry and the deadline
    t0 = time.monotonic()
    r = cloud.service("flight_authority_grab", {})
    assert r["data"]["result"] == 325004 and time.monotonic() - t0 < 3.0
    fc.inspect(lambda m: setattr(m, "ack_delay", 0.0))
    wait_until(lambda: adapter.unmatched_replies >= 1, 6, what="the late ACK arrived and was dropped")
    assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
