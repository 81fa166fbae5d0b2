"""What a cloud reads during a ``takeoff_to_point`` (issue #38): ``mode_code`` 4 "auto take-off" for the
whole take-off phase (the FC's take-off and the climb to the safe height), 5 for the flight to the point,
and the full ``takeoff_to_point_progress`` sequence ending with ``task_finish`` in every path, on the real
adapter against the simulated FC on one ManualClock (the harness of test_osdk_preflight)."""

from __future__ import annotations

from typing import Any

import pytest

from adapters.errors import DeviceError
from adapters.osdk.mission import AUTO_TAKEOFF, WAYLINE, mode_code
from adapters.osdk.wayline import OsdkWayline
from schemas import TopicKind, default_registry
from tests.test_osdk_preflight import World, _north, _takeoff


@pytest.fixture
def world() -> Any:
    w = World()
    yield w
    w.close()


def _finished(world: World) -> bool:
    return any(e["status"] == "task_finish" for e in world.events("takeoff_to_point_progress"))


def test_the_take_off_phase_reads_4_before_the_fc_mission_mode_would_say_5() -> None:
    kw: dict[str, Any] = {"connected": True, "in_air": True, "display_mode": 14, "mission_running": True}
    assert mode_code(mission_kind="takeoff", taking_off=True, **kw) == AUTO_TAKEOFF
    assert mode_code(mission_kind="takeoff", taking_off=False, **kw) == WAYLINE
    # the FC's own go home or landing wins over the take-off phase
    assert mode_code(**{**kw, "display_mode": 15}, mission_kind="takeoff", taking_off=True) == 9


def test_take_off_to_point_reads_4_while_climbing_then_5_and_ends_with_task_finish(world: World) -> None:
    target = _north(world.model, 60.0)
    result = world.call(lambda: world.adapter.call("takeoff_to_point", _takeoff(target, height=75.0)))
    assert not isinstance(result, DeviceError), result
    seen: list[tuple[float, int]] = []  # (height above take-off, mode_code) through the flight

    def sample() -> bool:
        if world.model.in_air:
            seen.append((world.model.u, world.adapter.mode_code()))
        return _finished(world)

    world.run(90.0, until=sample)
    assert _finished(world)
    climbing = [code for height, code in seen if 2.0 < height < 18.0]
    assert climbing and set(climbing) == {AUTO_TAKEOFF}, sorted(set(climbing))
    above = [code for height, code in seen if height > 21.0]
    assert above and WAYLINE in above and AUTO_TAKEOFF not in above, sorted(set(above))

    events = world.events("takeoff_to_point_progress")
    statuses = [e["status"] for e in events]
    assert statuses[0] == "task_ready" and "wayline_progress" in statuses, statuses
    assert statuses[-2:] == ["wayline_ok", "task_finish"], statuses
    assert statuses.count("task_finish") == 1 and statuses.count("wayline_ok") == 1
    assert all(e["flight_id"] == "t1" for e in events)
    # remaining distance: the whole way at the start, shrinking, 0 at the end
    assert events[0]["remaining_distance"] > 60.0, events[0]
    moving = [e["remaining_distance"] for e in events if e["status"] == "wayline_progress"]
    assert moving == sorted(moving, reverse=True) and moving[0] > moving[-1], moving
    assert events[-1]["remaining_distance"] == 0.0 and events[-1]["remaining_time"] == 0.0
    for e in events:  # each is what the contract says a takeoff_to_point_progress is
        body = {"tid": "t", "bid": "b", "timestamp": 1, "gateway": "G", "method": "takeoff_to_point_progress",
                "need_reply": 1, "data": e}  # fmt: skip
        default_registry().validate(TopicKind.EVENTS, body)


def test_a_take_off_interrupted_by_a_stop_ends_with_cancel_and_task_finish(world: World) -> None:
    """An emergency stop (DRC's or the console's) in the climb: a terminal status, never silence."""
    target = _north(world.model, 60.0)
    result = world.call(lambda: world.adapter.call("takeoff_to_point", _takeoff(target, height=75.0)))
    assert not isinstance(result, DeviceError), result
    world.run(60.0, until=lambda: world.model.u > 8.0)
    assert world.adapter.mode_code() == AUTO_TAKEOFF
    world.call(world.adapter.stop_motion)
    world.run(1.0)
    statuses = [e["status"] for e in world.events("takeoff_to_point_progress")]
    assert statuses[-2:] == ["wayline_cancel", "task_finish"], statuses
    assert statuses.count("task_finish") == 1
    world.run(5.0)  # nothing after task_finish
    assert [e["status"] for e in world.events("takeoff_to_point_progress")] == statuses
    assert world.adapter.mode_code() != AUTO_TAKEOFF


def _fly_to(target: tuple[float, float], height: float, fly_to_id: str = "f1") -> Any:
    from schemas.services import FlyToPoint

    return FlyToPoint.model_validate(
        {"fly_to_id": fly_to_id, "max_speed": 10, "points": [{"latitude": target[0], "longitude": target[1],
                                                               "height": height}]}
    )  # fmt: skip


def _airborne(world: World) -> float:
    """Take off to 40 m above a point 5 m north and wait for the task's end: the home's WGS84 height."""
    target = _north(world.model, 5.0)
    home = world.adapter.telemetry.home_altitude
    assert home is not None
    result = world.call(lambda: world.adapter.call("takeoff_to_point", _takeoff(target, height=home + 40.0)))
    assert not isinstance(result, DeviceError), result
    world.run(90.0, until=lambda: _finished(world))
    assert _finished(world)
    return float(home)


@pytest.mark.parametrize("interruption", ["stop", "go_home"])
def test_a_fly_to_interrupted_ends_with_one_terminal_status(world: World, interruption: str) -> None:
    """Issue #38: fly_to_point_progress in every path: stopped by an emergency stop (DRC's, the console's) or
    by the FC's go home (return_home) mid-flight, it ends with one terminal status, then silence."""
    home = _airborne(world)
    target = _north(world.model, 300.0)
    result = world.call(lambda: world.adapter.call("fly_to_point", _fly_to(target, home + 40.0)))
    assert not isinstance(result, DeviceError), result
    world.run(20.0, until=lambda: world.model.speed > 5.0)
    if interruption == "stop":
        world.call(world.adapter.stop_motion)
    else:
        assert world.call(lambda: OsdkWayline(world.adapter).go_home("rth-1")) is None  # return_home's path
    world.run(3.0)
    statuses = [e["status"] for e in world.events("fly_to_point_progress")]
    terminal = [s for s in statuses if s in ("wayline_ok", "wayline_failed", "wayline_cancel")]
    assert terminal == ["wayline_cancel"], statuses
    world.run(5.0)
    assert [e["status"] for e in world.events("fly_to_point_progress")] == statuses  # nothing after it


def test_a_take_off_interrupted_by_return_home_ends_with_cancel_and_task_finish(world: World) -> None:
    """return_home mid-climb (the wayline service's path: the task stopped, then the FC's go home)."""
    target = _north(world.model, 60.0)
    result = world.call(lambda: world.adapter.call("takeoff_to_point", _takeoff(target, height=75.0)))
    assert not isinstance(result, DeviceError), result
    world.run(60.0, until=lambda: world.model.u > 8.0)
    assert world.call(lambda: OsdkWayline(world.adapter).go_home("rth-1")) is None  # return_home's path
    world.run(3.0)
    statuses = [e["status"] for e in world.events("takeoff_to_point_progress")]
    assert statuses[-2:] == ["wayline_cancel", "task_finish"], statuses
    assert statuses.count("task_finish") == 1
