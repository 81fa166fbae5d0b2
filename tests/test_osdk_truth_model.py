"""A model-based test of the aircraft's truth (issue #31): the real Onboard SDK adapter and its wayline
runner against the real simulated flight controller (``OsdkFcModel``), joined by an in-memory serial line,
every timer on one ``ManualClock`` the test moves (no sleeping: a step of simulated seconds costs
milliseconds; the harness is tests/osdk_world.py).

Hypothesis interleaves what a cloud asks (a fly-to, its stop, an emergency stop, live-control sticks and
their end, return home and its cancel, taking control back) with what happens to the aircraft (the RC takes
over and gives it back, the FC drops its mission, the serial line drops, the gateway process dies and a
new one starts on the same FC). After each step that leaves 2 s of quiet, the invariants:

* the adapter's ``mode_code`` and task state are the FC's (a task is live exactly while the FC flies it);
* no motion without a live command source: with no sticks streaming and nothing automatic flying, the
  aircraft is not moving under an SDK set-point;
* some service can always act: with no task live and the aircraft in the air under SDK control, a new
  fly-to is accepted.
"""

from __future__ import annotations

import math
from collections.abc import Awaitable, Callable
from typing import TypeVar

from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from adapters.errors import DeviceError
from adapters.osdk.mission import mode_code
from schemas.services import FlyToPoint
from tests.osdk_world import MemoryAircraft, World

T = TypeVar("T")
SN = "OSDK-MODEL-1"


class AircraftTruth(RuleBasedStateMachine):
    def __init__(self) -> None:
        super().__init__()
        self.world = World(SN, on_stop="hover")
        self.clock, self.model, self.line = self.world.clock, self.world.model, self.world.line
        self.sticks = False  # live control streams a set-point
        self.fly_tos = 0

    # -- the harness (tests/osdk_world.py) -------------------------------------------------------------
    @property
    def adapter(self) -> MemoryAircraft:
        return self.world.adapter  # a new one after a gateway restart

    def _world(self, seconds: float) -> None:
        """Let ``seconds`` of simulated time pass: the FC flies and pushes, the adapter's timers run, and
        live control (when streaming) sends its set-point every tick, as the motion writer does."""
        self.world.run(seconds, each=self._sticks)

    def _sticks(self) -> None:
        if self.sticks:
            self.adapter.drive(4.0, 0.0, 0.0, 0.0)

    def _call(self, make: Callable[[], Awaitable[T]], limit: float = 10.0) -> T | DeviceError:
        """Run one of the adapter's coroutines to its end while the world turns (its ACKs take time)."""
        return self.world.call(make, limit)

    def teardown(self) -> None:
        self.world.close()

    # -- start: the aircraft in the air under SDK control ----------------------------------------------
    @initialize()
    def airborne(self) -> None:
        self.world.take_control()  # activation, telemetry
        assert not isinstance(self._call(lambda: self.adapter.flight_task("takeoff")), DeviceError)
        self._world(4.0)
        assert self.model.in_air

    # -- what a cloud asks -----------------------------------------------------------------------------
    @rule(north=st.sampled_from([40.0, 120.0]))
    def fly_to(self, north: float) -> None:
        lat = math.degrees(self.model.home_lat + (self.model.n + north) / 6_378_137.0)
        lon = math.degrees(self.model.home_lon)
        self.fly_tos += 1
        data = FlyToPoint.model_validate(
            {"fly_to_id": f"f{self.fly_tos}", "max_speed": 8,
             "points": [{"latitude": lat, "longitude": lon, "height": self.model.home_altitude + 20}]}
        )  # fmt: skip
        self._call(lambda: self.adapter.call("fly_to_point", data))

    @rule()
    def fly_to_stop(self) -> None:
        self._call(lambda: self.adapter.call("fly_to_point_stop", None))

    @rule()
    def emergency_stop(self) -> None:
        self.sticks = False  # DRC's e-stop holds the zero set-point
        self.adapter.emergency_stop()

    @rule()
    def sticks_start(self) -> None:
        self.sticks = True

    @rule()
    def sticks_stop(self) -> None:
        # the session's stick failsafe: zero once, then nothing streams
        self.sticks = False
        self.adapter.drive(0.0, 0.0, 0.0, 0.0)

    @rule()
    def return_home(self) -> None:
        self._call(lambda: self.adapter.wayline.go_home("rth"))

    @rule()
    def return_home_cancel(self) -> None:
        if self.adapter.wayline.mission_running:
            self._call(self.adapter.wayline.cancel)

    @rule()
    def grab(self) -> None:
        self._call(lambda: self.adapter.obtain_control(1))

    # -- what happens to the aircraft --------------------------------------------------------------------
    @rule()
    def rc_takes_over(self) -> None:
        self.sticks = False
        self.model.rc_takeover(self.clock.monotonic())

    @rule()
    def rc_back_to_f(self) -> None:
        self.model.rc_mode = "F"

    @rule()
    def fc_drops_its_mission(self) -> None:
        if self.model.run is not None:
            self.model._abort_missions()
            self.model._enter_hover(None)

    @rule(seconds=st.sampled_from([0.5, 2.5]))
    def cable_out(self, seconds: float) -> None:
        self.line.cut = True
        self._world(seconds)
        self.line.cut = False

    @rule()
    def gateway_crash_and_restart(self) -> None:
        self.adapter.crash()
        self.sticks = False  # a new process has no live-control session
        self._world(0.5)
        self.world.start_adapter()

    @precondition(lambda self: self.model.in_air)
    @rule(seconds=st.sampled_from([0.2, 1.0, 3.0]))
    def time_passes(self, seconds: float) -> None:
        self._world(seconds)

    # -- after 2 s of quiet --------------------------------------------------------------------------------
    @rule()
    def quiet(self) -> None:
        self._world(2.5)
        a, m = self.adapter, self.model
        if not (a.online and m.in_air):
            return  # landed at home (return home) or the line still settling: nothing to compare
        task = a.mission
        fc_mission = m.run is not None
        fc_go_home = m.task in ("go_home", "landing")
        live = task is not None and task.live
        if live and task is not None:
            # the gateway's way home lands at its end: the FC's landing is that task's last phase
            flying = (
                fc_go_home
                if task.kind == "go_home"
                else fc_mission or (task.kind == "return_home" and m.task == "landing")
            )
            assert flying, f"task {task.kind} live, the FC flies {m.task!r}"
        else:
            assert not fc_mission or (task is not None and task.adopted), (
                "the FC flies a mission nobody follows"
            )
        expected = mode_code(
            connected=True,
            in_air=m.in_air,
            display_mode=m.display_mode,
            mission_running=fc_mission,
            mission_kind=task.kind if live and task is not None else None,
        )
        assert a.mode_code() == expected, (a.mode_code(), expected, m.task)
        # no motion without a live command source
        if not self.sticks and m.task in ("sdk", "hover"):
            assert m.speed < 0.5, f"moving at {m.speed:.1f} m/s under SDK control with nothing driving it"
        # some service can act: with nothing live, in the air under SDK control, a new task is accepted
        if not live and not fc_mission and not fc_go_home and m.sdk_control and m.rc_mode == "F":
            self.sticks = False
            before = self.fly_tos
            self.fly_to(120.0)
            assert self.fly_tos == before + 1
            assert a.mission is not None and a.mission.kind == "fly_to" and a.mission.live, "fly-to refused"

    @invariant()
    def never_two_live_tasks_on_the_fc(self) -> None:
        task = self.adapter.mission
        if task is not None and task.live and task.kind == "go_home":
            assert self.model.run is None or not task.started


AircraftTruth.TestCase.settings = settings(max_examples=60, stateful_step_count=15, deadline=None)
test_the_aircraft_truth_state_machine = AircraftTruth.TestCase
