"""Nothing takes off for a task that cannot be flown, and a task that fails after take-off never strands the
aircraft (issue #33 B): the FC's mission rules (adapters/osdk/limits.py) on their own, then the real adapter
against the real simulated flight controller on one ManualClock (the harness of tests/osdk_world.py)."""

from __future__ import annotations

import logging
import math
from typing import Any

import pytest

from adapters.errors import DeviceError, DeviceRejected
from adapters.osdk import wayline_plan
from adapters.osdk.extensions import SafetyNotify
from adapters.osdk.limits import MissionLimits, after_failure, check_mission, flat_distance
from adapters.osdk.sim import OsdkFcModel
from schemas.results import ResultCode
from schemas.services import FlyToPoint, TakeoffToPoint
from tests import osdk_world

HOME = (22.5431, 113.9580)
LIMITS = MissionLimits()


# -- the rules ---------------------------------------------------------------------------------------------
def test_a_target_a_degree_of_latitude_away_breaks_the_radius_limit_naming_the_distance() -> None:
    target = (HOME[0] + 1.0, HOME[1])
    km = flat_distance(HOME, target) / 1000
    breach = check_mission(
        [(*HOME, 20.0), (*target, 20.0)], aircraft=HOME, home=HOME, limits=LIMITS, names=["up", "target"]
    )
    assert (
        breach is not None and breach.ack == 0xC7 and breach.field == "target" and breach.kind == "distance"
    )
    assert f"{km:.1f} km from the aircraft (its home)" in breach.text and "2.0 km limit" in breach.text


def test_each_rule_in_its_order() -> None:
    north = 1 / 111_320  # one metre of latitude, in degrees (near enough)
    up = (*HOME, 20.0)

    def at(n: float, h: float = 20.0) -> tuple[float, float, float]:
        return (HOME[0] + n * north, HOME[1], h)

    def ack(points: list[tuple[float, float, float]], **kw: Any) -> int | None:
        breach = check_mission(
            points, aircraft=kw.pop("aircraft", HOME), home=HOME, limits=kw.pop("limits", LIMITS)
        )
        return None if breach is None else breach.ack

    assert ack([up, at(1500)]) is None
    assert ack([up, at(100, 501)]) == 0xC0
    assert ack([up, at(100, -201)]) == 0xC1
    assert ack([up, at(2100)]) == 0xC7
    assert ack([at(1900), at(1800)], aircraft=(HOME[0] - 200 * north, HOME[1])) == 0xC9  # 2.1 km away
    assert ack([at(1900), at(-1900)]) == 0xE6  # both inside the radius, 3.8 km apart
    wide = MissionLimits(max_distance=30_000.0)
    zigzag = [at(950 * (-1) ** i) for i in range(35)]  # 34 legs of 1.9 km
    assert ack(zigzag, limits=wide) == 0xE2
    m100 = MissionLimits.for_firmware("m100", max_distance=2000.0, max_height=500.0)
    assert ack(zigzag[:18], limits=m100) == 0xE2 and ack(zigzag[:18]) is None  # 32.3 km: 30 km on others
    far = [at(22_000 + 950 * (-1) ** i) for i in range(31)]  # 57 km out at 22 km: 101 km from home and back
    assert ack(far, limits=wide, aircraft=far[0][:2]) == 0xE3


def test_the_route_limit_codes_are_the_contracts() -> None:
    assert wayline_plan.ALTITUDE_LIMIT == ResultCode.WAYLINE_ALTITUDE_LIMIT == 321513
    assert wayline_plan.DISTANCE_LIMIT == ResultCode.WAYLINE_DISTANCE_LIMIT == 321514


@pytest.mark.parametrize(
    ("in_air", "control", "distance", "action"),
    [
        (True, True, 0.0, "landing"),  # 1.2 m over its take-off point: barely airborne, it lands
        (True, True, 19.9, "landing"),
        (True, True, 20.0, "go_home"),  # DJI's rule: beyond 20 m it climbs and flies home
        (True, True, None, "go_home"),  # home unknown here: the FC knows its own
        (True, False, 500.0, None),  # the RC took it back: the pilot's
        (False, True, 0.0, None),  # on the ground
    ],
)
def test_after_failure_follows_djis_return_home_rule(
    in_air: bool, control: bool, distance: float | None, action: str | None
) -> None:
    assert after_failure(in_air=in_air, has_control=control, home_distance=distance) == action


# -- the adapter and the simulated FC ----------------------------------------------------------------------
class World(osdk_world.World):
    """The adapter on the simulated FC (tests/osdk_world.py), activated and in SDK control."""

    def __init__(self, model: OsdkFcModel | None = None, **settings: Any) -> None:
        super().__init__("OSDK-PRE-1", model, **settings)
        self.take_control()


@pytest.fixture
def world() -> Any:
    w = World()
    yield w
    w.close()


def _takeoff(target: tuple[float, float], height: float = 70.0, flight_id: str = "t1") -> TakeoffToPoint:
    return TakeoffToPoint.model_validate(
        {"flight_id": flight_id, "target_latitude": target[0], "target_longitude": target[1],
         "target_height": height, "security_takeoff_height": 20, "rth_altitude": 60, "rc_lost_action": 2,
         "exit_wayline_when_rc_lost": 0, "max_speed": 12}
    )  # fmt: skip


def _north(model: OsdkFcModel, metres: float) -> tuple[float, float]:
    return (math.degrees(model.home_lat) + metres / 6_378_137.0 * 180 / math.pi, math.degrees(model.home_lon))


def test_take_off_to_a_point_111_km_away_is_refused_and_nothing_moves(world: World) -> None:
    typo = (23.5436, 113.9580)  # 23.5436 for 22.5436
    result = world.call(lambda: world.adapter.call("takeoff_to_point", _takeoff(typo)))
    assert isinstance(result, DeviceRejected) and int(result.result) == 336000 + 0xC7
    km = flat_distance(
        (world.adapter.telemetry.latitude or 0.0, world.adapter.telemetry.longitude or 0.0), typo
    )
    assert f"target_latitude/target_longitude: {km / 1000:.1f} km" in str(result) and "2.0 km limit" in str(
        result
    )
    world.run(3.0)
    m = world.model
    assert not m.in_air and not m.motors_on and m.u == 0.0 and m.upload is None
    assert m.actions["flight_task"] == 0 and m.actions["go_home_altitude_write"] == 0  # nothing was sent
    assert world.events("takeoff_to_point_progress") == []  # no task was started


def test_fly_to_beyond_the_radius_is_refused_before_the_upload(world: World) -> None:
    assert not isinstance(world.call(lambda: world.adapter.flight_task("takeoff")), DeviceError)
    world.run(5.0)
    lat, lon = _north(world.model, 2500.0)
    data = FlyToPoint.model_validate(
        {"fly_to_id": "f1", "max_speed": 10, "points": [{"latitude": lat, "longitude": lon, "height": 70}]}
    )
    result = world.call(lambda: world.adapter.call("fly_to_point", data))
    assert isinstance(result, DeviceRejected) and int(result.result) == 336000 + 0xC7
    assert "points[0]: 2.5 km from the aircraft (its home)" in str(
        result
    )  # it hovers over its take-off point
    assert world.model.upload is None and world.model.run is None


def test_a_take_off_whose_mission_the_fc_refuses_after_take_off_lands_again(
    world: World, caplog: pytest.LogCaptureFixture
) -> None:
    """The FC is stricter than the gateway's setting (its radius limit is 50 m): the gateway's check passes,
    the FC takes off and refuses the mission (0xC7); 1.2 m over its take-off point, the aircraft lands."""
    world.model.max_distance_m = 50.0
    with caplog.at_level(logging.ERROR, logger="adapters.osdk.adapter"):
        assert (
            world.call(lambda: world.adapter.call("takeoff_to_point", _takeoff(_north(world.model, 100.0))))
            is not None
        )
        world.run(15.0, until=lambda: not world.model.motors_on and world.model.actions["flight_task"] >= 2)
    m = world.model
    assert not m.in_air and not m.motors_on and m.u < 0.05
    failed = [e for e in world.events("takeoff_to_point_progress") if e["status"] == "wayline_failed"]
    assert len(failed) == 1 and failed[0]["result"] == 336000 + 0xC7
    assert "too far" in failed[0]["x_reason"] and "landing where it is" in failed[0]["x_reason"]
    assert any(
        "failed after take-off" in r.getMessage() and "landing" in r.getMessage() for r in caplog.records
    )
    notes = world.events("x_osdk_safety_notify")
    assert any(n["action"] == "landing" and n["task_id"] == "t1" for n in notes)
    for note in notes:  # what the northbound publishes (it drops what its model refuses)
        SafetyNotify.model_validate(note)


def test_a_take_off_to_point_broken_off_on_the_way_returns_home(
    world: World, caplog: pytest.LogCaptureFixture
) -> None:
    """The FC breaks the mission off 300 m out (a low-battery error): the FC's go home brings it back."""
    with caplog.at_level(logging.ERROR, logger="adapters.osdk.adapter"):
        world.call(lambda: world.adapter.call("takeoff_to_point", _takeoff(_north(world.model, 600.0))))
        world.run(60.0, until=lambda: world.model.n > 250.0)
        assert world.model.run is not None and world.model.n > 250.0
        assert world.model.break_mission(0xD9, world.clock.monotonic())
        world.run(3.0, until=lambda: world.model.task == "go_home")
    assert world.model.task == "go_home"
    failed = [e for e in world.events("takeoff_to_point_progress") if e["status"] == "wayline_failed"]
    assert len(failed) == 1 and failed[0]["result"] == 336000 + 0xD9
    assert "low battery" in failed[0]["x_reason"] and "returning home" in failed[0]["x_reason"]
    assert any("returning home" in r.getMessage() and r.levelno == logging.ERROR for r in caplog.records)
    world.run(1.0)  # the next flight-data push says so
    assert world.adapter.mode_code() == 9  # return home
    world.run(120.0, until=lambda: not world.model.in_air)
    assert not world.model.in_air and math.hypot(world.model.n, world.model.e) < 2.0  # landed at home


def test_the_progress_ext_carries_the_failure_reason_and_the_skipped_actions() -> None:
    """flighttask_progress: ``ext.x_reason`` on a failure, ``ext.x_skipped_actions`` once planned; both
    validate against the contract."""
    from gateway.wayline.task import TaskBook
    from schemas.wayline import FlighttaskProgress

    book = TaskBook()
    request = type("Req", (), {"flight_id": "f1"})()
    task, _ = book.prepare(request, 0.0)
    book.execute("f1", 0.0)
    book.planned(
        task, 3, ["wayline 0 waypoint 1: zoom (a camera setting the flight controller cannot reach)"]
    )
    ext = book.progress(task)["output"]["ext"]
    assert (
        ext["x_skipped_actions"]
        == ["wayline 0 waypoint 1: zoom (a camera setting the flight controller cannot reach)"]
        and "x_reason" not in ext
    )
    book.failed(task, 336217, "the flight controller reported a mission error: low battery (0xD9)", None)
    body = book.progress(task)
    assert body["output"]["ext"]["x_reason"].endswith("low battery (0xD9)") and body["result"] == 336217
    FlighttaskProgress.model_validate(body)


def test_a_take_off_to_the_safe_height_straight_above_flies_a_two_waypoint_climb(world: World) -> None:
    """A target straight above the take-off point at the safe height (an RC-side client's "go up"): the
    route after the take-off is one point, which the FC refuses (0xE0: a mission needs two); the mission
    starts where the aircraft hovers instead, and the take-off ends at the target."""
    here = _north(world.model, 0.0)
    result = world.call(lambda: world.adapter.call("takeoff_to_point", _takeoff(here, height=70.0)))
    assert not isinstance(result, DeviceError), result
    world.run(
        60.0,
        until=lambda: any(e["status"] == "task_finish" for e in world.events("takeoff_to_point_progress")),
    )
    statuses = [e["status"] for e in world.events("takeoff_to_point_progress")]
    assert statuses[-2:] == ["wayline_ok", "task_finish"] and "wayline_failed" not in statuses, statuses
    m = world.model
    assert m.in_air and abs(m.u - 20.0) < 1.0 and math.hypot(m.n, m.e) < 1.0, (m.u, m.n, m.e)
