"""The flight controller's truth against the gateway's intent (adapters/osdk/mission.py): the mode_code
table, the reading of mission status pushes, and the reconciliation verdicts, including a model-based
test: random interleavings of what the gateway asks and what the FC does, on a clock the test moves."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, invariant, precondition, rule

from adapters.osdk.mission import (
    DISPLAY_MODE_CODES,
    GRACE,
    STATUS_STALE,
    FcMissionState,
    Task,
    mode_code,
    reconcile,
)


@pytest.mark.parametrize(
    ("connected", "in_air", "display", "running", "kind", "expected"),
    [
        (False, False, None, False, None, 14),  # nothing reported on this link
        (True, False, 6, False, None, 0),  # on the ground
        (True, False, 11, False, None, 4),  # the FC's take-off from its first moment, on the ground too
        (True, True, 11, False, None, 4),
        (True, True, 6, False, None, 3),  # P-GPS in the air: manual flight
        (True, True, 14, True, "wayline", 5),
        (True, True, 14, True, "return_home", 9),  # the gateway's way home is a mission the FC flies
        (True, True, 15, False, "go_home", 9),  # the FC's own go home
        (True, True, 15, True, "wayline", 9),  # a go home wins over a stale mission push
        (True, True, 12, False, None, 10),
        (True, True, 33, False, None, 11),
        (True, True, 17, False, None, 16),  # virtual stick
        (True, True, 25, False, None, 7),  # follow-me: intelligent tracking
        (True, True, 9, False, None, 3),  # hotpoint: no mode of its own in the contract's enum
        (True, True, None, False, None, 3),
    ],
)
def test_mode_code_table(
    connected: bool, in_air: bool, display: int | None, running: bool, kind: str | None, expected: int
) -> None:
    got = mode_code(
        connected=connected, in_air=in_air, display_mode=display, mission_running=running, mission_kind=kind
    )
    assert got == expected


def test_every_mapped_display_mode_is_a_cloud_api_mode() -> None:
    from schemas.osd import ModeCode

    assert set(DISPLAY_MODE_CODES.values()) <= {int(m) for m in ModeCode}


def test_status_pushes_say_a_mission_runs_until_they_stop() -> None:
    fc = FcMissionState()
    assert not fc.running(6, 0.0)
    fc.on_status({"mission_type": 1, "target_waypoint": 3, "current_status": 1}, 10.0)
    assert fc.running(6, 10.0) and fc.target == 3
    assert fc.running(6, 10.0 + STATUS_STALE)
    assert not fc.running(6, 10.0 + STATUS_STALE + 0.01)
    assert fc.running(14, 100.0)  # the display mode alone says so too
    # a default status push naming a broken waypoint mission ends it at once
    fc.on_status({"mission_type": 1, "target_waypoint": 1}, 20.0)
    fc.on_status({"mission_type": 0, "last_mission_type": 1, "is_broken": 1, "reason": 0}, 20.5)
    assert fc.broken_at == 20.5 and not fc.running(6, 20.6)
    # a hotpoint push says nothing of waypoints
    fc.on_status({"mission_type": 2, "mission_status": 1}, 30.0)
    assert not fc.running(6, 30.0)


def _task(started: bool = True) -> Task:
    return Task("wayline", "f1", 3, started=started)


def test_reconcile_gives_the_fc_a_grace_then_ends_the_task() -> None:
    task = _task()
    verdict, since = reconcile(task, True, disagree_since=None, now=0.0)
    assert verdict is None and since is None  # they agree
    verdict, since = reconcile(task, False, disagree_since=None, now=1.0)
    assert verdict is None and since == 1.0
    verdict, since = reconcile(task, False, disagree_since=since, now=1.0 + GRACE / 2)
    assert verdict is None and since == 1.0
    verdict, since = reconcile(task, True, disagree_since=since, now=1.0 + GRACE / 2 + 0.01)
    assert verdict is None and since is None  # agreeing again clears the grace
    verdict, since = reconcile(task, False, disagree_since=1.0, now=1.0 + GRACE)
    assert verdict is not None and "no longer flying" in verdict.reason


def test_reconcile_knows_the_stops_the_gateway_asked_for_and_ignores_what_has_not_started() -> None:
    verdict, _ = reconcile(_task(), False, disagree_since=None, now=0.0, stop_requested="emergency stop")
    assert verdict is not None and verdict.reason == "emergency stop"  # no grace: the gateway knows why
    verdict, _ = reconcile(_task(), True, disagree_since=None, now=0.0, stop_requested="emergency stop")
    assert verdict is None  # the FC still flies it: not ended by a wish
    verdict, _ = reconcile(_task(), True, disagree_since=None, now=0.0, broken=True)
    assert verdict is not None and "broke" in verdict.reason
    verdict, _ = reconcile(_task(started=False), False, disagree_since=None, now=99.0)
    assert verdict is None  # an upload or a take-off before the start: nothing to disagree with
    done = _task()
    done.finished = True
    assert reconcile(done, False, disagree_since=None, now=99.0) == (None, None)


class Truth(RuleBasedStateMachine):
    """The gateway's task and a flight controller that may drop its mission at any time (a brake, the
    RC, a dropped mission), push status about once a second while it flies, finish it, or pause it. The
    adapter's reconciliation runs every 0.1 s. Invariants: after :data:`STATUS_STALE` + :data:`GRACE` s
    of the FC flying nothing, no live started task remains; a task the FC still flies is never ended by
    the reconciliation; mode_code is 5 exactly while the FC says a mission runs (in the air)."""

    def __init__(self) -> None:
        super().__init__()
        self.now = 0.0
        self.fc = FcMissionState()
        self.fc_flying = False  # the world: does the FC fly a mission?
        self.display = 6
        self.task: Task | None = None
        self.since: float | None = None
        self.stop_requested: str | None = None
        self.quiet_since = 0.0  # when the FC last flew a mission
        self.ended_by_reconcile: list[str] = []

    def _land(self) -> None:
        """The FC stops flying its mission now (whatever the reason)."""
        if self.fc_flying:
            self.quiet_since = self.now
        self.fc_flying, self.display = False, 6

    def _advance(self, seconds: float) -> None:
        end = self.now + seconds
        while self.now < end - 1e-9:
            self.now = round(self.now + 0.1, 6)
            if self.fc_flying:
                self.quiet_since = self.now
                if round(self.now * 10) % 10 == 0:  # the FC's ~1 Hz status push
                    self.fc.on_status({"mission_type": 1, "target_waypoint": 1}, self.now)
            running = self.fc.running(self.display, self.now)
            verdict, self.since = reconcile(
                self.task,
                running,
                disagree_since=self.since,
                now=self.now,
                stop_requested=self.stop_requested,
            )
            if verdict is not None and self.task is not None:
                assert not self.fc_flying or not running, "ended a task the FC still flies"
                self.task.dropped = verdict.reason
                self.ended_by_reconcile.append(verdict.reason)
                self.stop_requested = None

    # -- the gateway --------------------------------------------------------------------------------
    @precondition(lambda self: self.task is None or not self.task.live)
    @rule()
    def start_mission(self) -> None:
        self.task = Task("wayline", "f", 3)
        self.stop_requested, self.since = None, None
        self.fc_flying, self.display = True, 14  # the FC accepted the start
        self.quiet_since = self.now
        self.task.started = True
        self.fc.on_status({"mission_type": 1, "target_waypoint": 0}, self.now)

    @rule()
    def emergency_stop(self) -> None:
        self.stop_requested = "emergency stop"
        self._land()

    @precondition(lambda self: self.task is not None and self.task.live)
    @rule()
    def cancel(self) -> None:
        assert self.task is not None
        self.task.finished = True
        self._land()
        self.fc.status_at = float("-inf")  # the FC acknowledged the stop

    # -- the world ----------------------------------------------------------------------------------
    @rule()
    def fc_drops_the_mission(self) -> None:  # a brake from elsewhere, the RC, a failed mission
        self._land()

    @precondition(lambda self: self.fc_flying)
    @rule()
    def fc_finishes(self) -> None:
        self._land()
        if self.task is not None and self.task.live:
            self.task.finished = True

    @rule(seconds=st.sampled_from([0.1, 0.3, 0.5, 1.0, 2.0, 3.0]))
    def time_passes(self, seconds: float) -> None:
        self._advance(seconds)

    # -- invariants ---------------------------------------------------------------------------------
    @invariant()
    def quiet_fc_means_no_live_task(self) -> None:
        if self.fc_flying or self.task is None or not self.task.live:
            return
        assert self.now - self.quiet_since <= STATUS_STALE + GRACE + 0.2, (
            f"task live {self.now - self.quiet_since:.1f} s after the FC stopped flying it"
        )

    @invariant()
    def mode_code_follows_the_fc(self) -> None:
        running = self.fc.running(self.display, self.now)
        kind = self.task.kind if self.task is not None and self.task.live else None
        code = mode_code(
            connected=True, in_air=True, display_mode=self.display, mission_running=running, mission_kind=kind
        )
        if self.fc_flying:
            assert code == 5
        elif self.now - self.quiet_since > STATUS_STALE + 0.1:
            assert code == 3


Truth.TestCase.settings = settings(max_examples=300, stateful_step_count=40, deadline=None)
test_truth_state_machine = Truth.TestCase


@given(pushes=st.lists(st.tuples(st.floats(0, 100), st.integers(0, 4), st.integers(0, 1)), max_size=30))
def test_any_status_push_sequence_is_read_without_error(pushes: list[tuple[float, int, int]]) -> None:
    fc = FcMissionState()
    for at, kind, broken in sorted(pushes):
        fields: dict[str, Any] = {"mission_type": kind, "target_waypoint": 2, "last_mission_type": 1}
        fields["is_broken"] = broken
        fc.on_status(fields, at)
        assert isinstance(fc.running(None, at), bool)
