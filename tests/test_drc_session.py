"""The DRC session state machine (gateway/drc_session.py), model-based: a hypothesis
``RuleBasedStateMachine`` plays a cloud and a shell that race in every order (enters and exits while
links open and close, sticks, heartbeats, emergency stops, broker and authority losses, shutdown,
messages from stale links) on a manual clock, and checks after every step:

* no motion after exit, emergency stop, heartbeat loss (3 s), stick loss (0.5 s), broker loss,
  authority loss or shutdown: the set-point the writer holds is zero whenever any of them applies;
* a non-zero set-point only ever comes with a stick that was answered 0;
* at most one session, and at most one DRC link open or opening or closing at any time;
* the drc_state last reported equals the real state;
* every enter/exit is answered exactly once (checked again after all links settle), every stick,
  heartbeat and stop at most once, and an exit answered 0 leaves drc_state 0 and no motion;
* ``stick_control`` (RC channels, each message five times, as DJI's reference cloud sends) obeys the
  same rules as ``drone_control``; a payload command (``drc_gimbal_reset``) is carried out only while
  the session drives freely (no emergency stop, heartbeats fresh).

Plus example tests for the orders that broke the old controller.
"""

from __future__ import annotations

import itertools
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.stateful import RuleBasedStateMachine, initialize, invariant, precondition, rule

from gateway import drc_session as ds
from schemas.drc import STICK_MAX, STICK_MIN, STICK_NEUTRAL

CFG = ds.SessionConfig(stick_timeout=0.5, heartbeat_timeout=3.0, idle_timeout=60.0)
MOVE = (1.0, -2.0, 0.5, 10.0)
LIMITS = ds.StickLimits()
CHANNEL = st.sampled_from([364, 700, 1024, 1024, 1024, 1354, 1684])


class _Req:
    """A request token: which kind, in which order it was fed."""

    _ids = itertools.count()

    def __init__(self, kind: str) -> None:
        self.kind = kind
        self.n = next(self._ids)

    def __repr__(self) -> str:
        return f"{self.kind}#{self.n}"


class Harness:
    """The shell's side: carries out actions the way gateway.drc does, records what the world saw."""

    def __init__(self) -> None:
        self.m = ds.DrcSession(CFG)
        self.now = 1000.0
        self.setpoint: ds.SetPoint = ds.ZERO  # what the writer holds
        self.reported = 0
        self.opening: set[int] = set()
        self.open: set[int] = set()
        self.closing: set[int] = set()
        self.answers: dict[_Req, list[int]] = {}
        self.requests: list[_Req] = []
        self.hb_at = float("-inf")  # last heartbeat echoed in the current session (or its start)
        self.stick_at = float("-inf")  # last stick answered 0
        self.observed_at = float("-inf")  # the last time the machine was told the time by a tick or stick
        self.stopped_after_stick = True  # estop / losses / exit since the last accepted stick
        self.estops = 0
        self.estop_hold = False  # an emergency stop holds until a stick with seq 0
        self.last_seq: int | None = None  # the last seq answered 0 in the current session

    def feed(self, event: ds.Event) -> list[ds.Action]:
        # the shell's bookkeeping of links: an outcome is reported only for a link it was working on
        if isinstance(event, ds.LinkUp) and event.session in self.opening:
            self.opening.discard(event.session)
            self.open.add(event.session)
        elif isinstance(event, ds.LinkFailed) and event.session in self.opening:
            self.opening.discard(event.session)
        elif isinstance(event, ds.LinkClosed) and event.session in self.closing:
            self.closing.discard(event.session)
        # the machine is told the time by every tick, and by every stick on the current session's link
        told = isinstance(event, ds.Stick | ds.PayloadCommand) and event.session == self.m.session_id
        if isinstance(event, ds.Tick) or told:
            self.observed_at = event.at
        repeat = (
            isinstance(event, ds.Stick)
            and event.session == self.m.session_id
            and event.seq != 0
            and event.seq == self.last_seq
        )
        actions = self.m.handle(event)
        if repeat:  # the same seq again (clouds repeat DRC messages): one effect, one answer
            acted = [
                a
                for a in actions
                if isinstance(a, ds.StickReply) or getattr(a, "setpoint", ds.ZERO) != ds.ZERO
            ]
            assert not acted, f"a repeat acted: {acted}"
        accepted_stick = False
        for a in actions:
            if isinstance(a, ds.StickReply) and isinstance(event, ds.Stick) and a.result == 0:
                accepted_stick = True
        for a in actions:
            if isinstance(a, ds.Motion):
                if a.setpoint != ds.ZERO:
                    assert isinstance(event, ds.Stick) and accepted_stick, f"motion from {event}"
                self.setpoint = a.setpoint
            elif isinstance(a, ds.EmergencyStop):
                self.estops += 1
            elif isinstance(a, ds.Report):
                self.reported = a.drc_state
            elif isinstance(a, ds.OpenLink):
                assert not (self.opening or self.open or self.closing), "a second DRC link"
                self.opening.add(a.session)
            elif isinstance(a, ds.CloseLink):
                assert a.session in self.opening | self.open, f"close of a link that is not there: {a}"
                self.opening.discard(a.session)
                self.open.discard(a.session)
                self.closing.add(a.session)
            elif isinstance(a, ds.Forward):
                assert isinstance(event, ds.PayloadCommand) and a.request is event.request
                assert self.m.state is ds.State.ACTIVE, f"payload command carried out in {self.m.state}"
                assert not self.estop_hold, "payload command carried out through an emergency stop"
                assert event.at - self.hb_at <= CFG.heartbeat_timeout, "payload command without heartbeats"
                self.answers.setdefault(a.request, []).append(0)
                assert len(self.answers[a.request]) == 1, f"{a.request} forwarded twice"
            elif isinstance(a, ds.Reply | ds.StickReply):
                req = a.request
                if isinstance(req, _Req):
                    self.answers.setdefault(req, []).append(a.result)
                    assert len(self.answers[req]) == 1, f"{req} answered twice"
                    if isinstance(a, ds.StickReply) and req.kind == "heartbeat":
                        self.hb_at = event.at
                    if req.kind == "stick" and a.result == 0:
                        assert isinstance(event, ds.Stick)
                        assert not (self.estop_hold and event.seq != 0), "drove through an emergency stop"
                        self.estop_hold = False
                        self.last_seq = event.seq
                        self.stick_at = event.at
                        self.stopped_after_stick = False
        if isinstance(event, ds.LinkUp) and self.m.state is ds.State.ACTIVE:
            self.hb_at = event.at
            self.estop_hold = False
            self.last_seq = None
        renewed = isinstance(event, ds.Enter) and ds.Reply(event.request, 0) in actions
        if renewed and self.m.state in (ds.State.ACTIVE, ds.State.HOLDING):
            # a fresh enter of the live session (answered at once) ends the emergency stop's hold: the
            # set-point stays zero until a stick (issue #33); the seq sequence goes on
            moved = [a for a in actions if isinstance(a, ds.Motion) and a.setpoint != ds.ZERO]
            assert not moved, f"an enter moved a device: {moved}"
            self.estop_hold = False
        if isinstance(event, ds.EStop) and self.m.state is ds.State.HOLDING:
            self.estop_hold = True
        stop = (ds.EStop, ds.BrokerLost, ds.AuthorityLost, ds.Exit, ds.Shutdown)
        if isinstance(event, stop) and any(isinstance(a, ds.Motion) for a in actions):
            self.stopped_after_stick = True
        if self.m.state not in (ds.State.ACTIVE, ds.State.HOLDING):
            self.stopped_after_stick = True
        self._check_exit_answers(actions)
        return actions

    def _check_exit_answers(self, actions: list[ds.Action]) -> None:
        for a in actions:
            if isinstance(a, ds.Reply) and isinstance(a.request, _Req) and a.request.kind == "exit":
                later_enter = any(r.kind == "enter" and r.n > a.request.n for r in self.requests)
                if not later_enter:
                    assert self.m.drc_state == 0 and self.setpoint == ds.ZERO, "exit answered, still live"

    def request(self, kind: str) -> _Req:
        req = _Req(kind)
        if kind in ("enter", "exit"):
            self.requests.append(req)
        return req

    # -- the invariants ---------------------------------------------------------------------------
    def check(self) -> None:
        m = self.m
        assert self.reported == m.drc_state, f"reported {self.reported}, real {m.drc_state} ({m.state})"
        assert (m.session_id is None) == (m.state is ds.State.IDLE)
        assert len(self.opening) + len(self.open) + len(self.closing) <= 1
        assert self.setpoint == m.setpoint
        assert (m.failsafe is None) == (m.failsafe_since is None), "a failsafe without its incident's start"
        if m.state is ds.State.HOLDING:
            assert m.failsafe is not None, "holding with no failsafe to show"
        if m.state in (ds.State.ACTIVE, ds.State.HOLDING):
            assert self.observed_at - self.hb_at <= CFG.idle_timeout, "a silent session was not ended"
        if self.setpoint != ds.ZERO:
            assert m.state is ds.State.ACTIVE, f"moving in {m.state}"
            assert not self.stopped_after_stick, "moving after a stop"
            assert not m.closed
            assert self.observed_at - self.hb_at <= CFG.heartbeat_timeout, "moving without heartbeats"
            assert self.observed_at - self.stick_at <= CFG.stick_timeout, "moving on a stale stick"

    def settle(self) -> None:
        """Let every link operation finish (the shell always does, in the end)."""
        for _ in range(50):
            if self.opening:
                self.feed(ds.LinkUp(self.now, min(self.opening)))
            elif self.closing:
                self.feed(ds.LinkClosed(self.now, min(self.closing)))
            else:
                return


class DrcSessionMachine(RuleBasedStateMachine):
    """Rules weighted towards what a live session sees (sticks, heartbeats, time), with every other
    event interleaved; rare events (shutdown) are gated so most runs stay live long enough to race."""

    h: Harness

    @initialize(live=st.sampled_from(["main", "drc-a", None]))
    def start(self, live: str | None) -> None:
        self.h = Harness()
        self.seq = 0
        if live is not None:
            h = self.h
            h.feed(ds.Enter(h.now, h.request("enter"), ds.LinkSpec(live, live != "main")))
            h.feed(ds.LinkUp(h.now, min(h.opening)))

    def _settle_one(self) -> None:
        h = self.h
        if h.opening:
            h.feed(ds.LinkUp(h.now, min(h.opening)))
        elif h.closing:
            h.feed(ds.LinkClosed(h.now, min(h.closing)))

    # -- the cloud's services -----------------------------------------------------------------------
    @rule(key=st.sampled_from(["main", "drc-a", "drc-b"]), settle=st.booleans())
    def enter(self, key: str, settle: bool) -> None:
        h = self.h
        h.feed(ds.Enter(h.now, h.request("enter"), ds.LinkSpec(key, key != "main")))
        if settle:  # the link comes up before anything else happens
            self._settle_one()

    @rule(settle=st.booleans())
    def exit(self, settle: bool) -> None:
        h = self.h
        h.feed(ds.Exit(h.now, h.request("exit")))
        if settle:
            self._settle_one()

    # -- the shell's link outcomes --------------------------------------------------------------------
    @precondition(lambda self: bool(self.h.opening))
    @rule(ok=st.sampled_from([True, True, False]))
    def link_opened(self, ok: bool) -> None:
        h = self.h
        sid = min(h.opening)
        h.feed(ds.LinkUp(h.now, sid) if ok else ds.LinkFailed(h.now, sid, 514300))

    @precondition(lambda self: bool(self.h.closing))
    @rule()
    def link_closed(self) -> None:
        h = self.h
        h.feed(ds.LinkClosed(h.now, min(h.closing)))

    @rule(sid=st.integers(0, 6), which=st.sampled_from(["up", "failed", "closed", "lost"]))
    def stale_link_event(self, sid: int, which: str) -> None:
        """Link news about a session that is not waiting for it: ignored."""
        h = self.h
        if sid in h.opening | h.open | h.closing or sid == h.m.session_id:
            return
        event: ds.Event = {
            "up": ds.LinkUp(h.now, sid),
            "failed": ds.LinkFailed(h.now, sid, 514300),
            "closed": ds.LinkClosed(h.now, sid),
            "lost": ds.BrokerLost(h.now, sid),
        }[which]
        assert h.feed(event) == []

    @rule(gate=st.integers(0, 2))
    def broker_lost(self, gate: int) -> None:
        h = self.h
        sid = h.m.session_id
        if gate or sid is None:
            return
        live = h.m.state in (ds.State.ACTIVE, ds.State.HOLDING)
        h.feed(ds.BrokerLost(h.now, sid))
        if live:
            assert h.m.state is ds.State.EXITING and h.reported == 0, "the session outlived its link"

    # -- drc/down -------------------------------------------------------------------------------------
    @rule(
        step=st.sampled_from([1, 1, 1, 2, 0, -1, "restart"]),
        setpoint=st.sampled_from([MOVE, MOVE, ds.ZERO, (0.0, 0.0, 3.0, 0.0)]),
        authorized=st.sampled_from([True, True, True, False]),
        stale=st.sampled_from([False, False, False, True]),
    )
    def stick(self, step: int | str, setpoint: ds.SetPoint, authorized: bool, stale: bool) -> None:
        h = self.h
        self.seq = 0 if step == "restart" else max(0, self.seq + int(step))
        sid = h.m.session_id
        session = None if stale or sid is None else sid
        h.feed(ds.Stick(h.now, session, h.request("stick"), self.seq, setpoint, authorized))

    @rule(
        step=st.sampled_from([1, 1, 1, 2, 0, -1, "restart"]),
        channels=st.tuples(CHANNEL, CHANNEL, CHANNEL, CHANNEL),
        authorized=st.sampled_from([True, True, True, False]),
        copies=st.sampled_from([1, 5, 5]),
    )
    def stick_control(
        self, step: int | str, channels: tuple[int, int, int, int], authorized: bool, copies: int
    ) -> None:
        """``stick_control``: RC channels mapped as the shell maps them, each message ``copies`` times."""
        h = self.h
        self.seq = 0 if step == "restart" else max(0, self.seq + int(step))
        setpoint = ds.channels_to_setpoint(*channels, LIMITS)
        for _ in range(copies):
            h.feed(ds.Stick(h.now, h.m.session_id, h.request("stick"), self.seq, setpoint, authorized))

    @rule(stale=st.sampled_from([False, False, False, True]), copies=st.sampled_from([1, 5]))
    def payload_command(self, stale: bool, copies: int) -> None:
        h = self.h
        for _ in range(copies):
            sid = None if stale else h.m.session_id
            h.feed(ds.PayloadCommand(h.now, sid, h.request("payload")))

    @rule(stale=st.sampled_from([False, False, False, True]))
    def heartbeat(self, stale: bool) -> None:
        h = self.h
        sid = None if stale else h.m.session_id
        h.feed(ds.Heartbeat(h.now, sid, h.request("heartbeat")))

    @rule(times=st.sampled_from([1, 5]), gate=st.integers(0, 2))
    def emergency_stop(self, times: int, gate: int) -> None:
        if gate:
            return
        h = self.h
        before = h.estops
        for _ in range(times):  # DJI's reference cloud publishes each DRC message five times
            req = h.request("estop")
            h.feed(ds.EStop(h.now, h.m.session_id, req))
            assert h.answers[req] == [0], "a stop is always answered 0"
        if h.m.state in (ds.State.ACTIVE, ds.State.HOLDING):
            assert h.estops - before <= 1, "a repeated stop stopped again"
        assert h.setpoint == ds.ZERO

    @rule(gate=st.integers(0, 3))
    def authority_lost(self, gate: int) -> None:
        if gate:
            return
        h = self.h
        h.feed(ds.AuthorityLost(h.now))
        assert h.setpoint == ds.ZERO

    # -- time and the end ----------------------------------------------------------------------------
    @rule(dt=st.sampled_from([0.04, 0.04, 0.3, 0.6, 2.0, 3.5, 61.0]))
    def tick(self, dt: float) -> None:
        h = self.h
        h.now += dt
        h.feed(ds.Tick(h.now))

    @rule(dt=st.sampled_from([0.02, 0.3, 0.6, 3.5]))
    def wait(self, dt: float) -> None:
        """Time passes and a message may come before the writer's next tick."""
        self.h.now += dt

    @rule(gate=st.integers(0, 9))
    def shutdown(self, gate: int) -> None:
        h = self.h
        if gate or h.m.closed:
            return
        h.feed(ds.Shutdown(h.now))
        assert h.setpoint == ds.ZERO

    @invariant()
    def invariants(self) -> None:
        if hasattr(self, "h"):
            self.h.check()

    def teardown(self) -> None:
        if not hasattr(self, "h"):
            return
        h = self.h
        h.feed(ds.Shutdown(h.now))
        h.settle()
        assert h.m.state is ds.State.IDLE, h.m.state
        assert h.m.queued == 0
        assert h.setpoint == ds.ZERO and h.reported == 0
        for req in h.requests:
            assert len(h.answers.get(req, [])) == 1, f"{req} answered {h.answers.get(req)}"


DrcSessionMachine.TestCase.settings = settings(
    max_examples=2000,
    stateful_step_count=30,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
# CPU-bound (2,000 examples): beside parallel workers on 2 cores it needs more than the suite's 120 s default
TestDrcSession = pytest.mark.timeout(600)(pytest.mark.slow(DrcSessionMachine.TestCase))


# ------------------------------------------------------------------------------------------ examples
def _live(h: Harness, key: str = "main") -> int:
    h.feed(ds.Enter(h.now, h.request("enter"), ds.LinkSpec(key, key != "main")))
    sid = h.m.session_id
    assert sid is not None and h.m.state is ds.State.CONNECTING
    h.feed(ds.LinkUp(h.now, sid))
    assert h.m.state is ds.State.ACTIVE
    return sid


def _kinds(actions: list[ds.Action]) -> list[Any]:
    return [type(a).__name__ for a in actions]


def test_exit_then_enter_is_one_exit_then_one_new_session() -> None:
    """The race that broke the old controller: exit and enter back to back, before the link closed."""
    h = Harness()
    _live(h, "drc-a")
    exit_req = h.request("exit")
    h.feed(ds.Exit(h.now, exit_req))
    enter_req = h.request("enter")
    h.feed(ds.Enter(h.now, enter_req, ds.LinkSpec("drc-a", True)))
    assert h.m.state is ds.State.EXITING and h.reported == 0
    assert enter_req not in h.answers and exit_req not in h.answers  # the enter waits for the close
    actions = h.feed(ds.LinkClosed(h.now, min(h.closing)))
    assert _kinds(actions) == ["Reply", "Report", "OpenLink"]
    assert h.answers[exit_req] == [0] and h.reported == 1


def test_twenty_exit_enter_pairs_then_exit_ends_at_zero() -> None:
    h = Harness()
    _live(h, "drc-a")
    for _ in range(20):
        h.feed(ds.Exit(h.now, h.request("exit")))
        h.feed(ds.Enter(h.now, h.request("enter"), ds.LinkSpec("drc-a", True)))
    h.feed(ds.Exit(h.now, h.request("exit")))
    reports: list[int] = []
    for _ in range(100):  # the shell settles links one at a time, in order
        if h.opening:
            actions = h.feed(ds.LinkUp(h.now, min(h.opening)))
        elif h.closing:
            actions = h.feed(ds.LinkClosed(h.now, min(h.closing)))
        else:
            break
        reports += [a.drc_state for a in actions if isinstance(a, ds.Report)]
    assert h.m.state is ds.State.IDLE and h.reported == 0 and reports[-1] == 0
    assert all(len(h.answers[r]) == 1 for r in h.requests)
    sid_stale = 1
    replies = h.feed(ds.Stick(h.now, sid_stale, h.request("stick"), 50, MOVE))
    assert h.setpoint == ds.ZERO and not any(isinstance(a, ds.StickReply) for a in replies)


def test_estop_five_times_stops_once_and_answers_each() -> None:
    h = Harness()
    sid = _live(h)
    h.feed(ds.Heartbeat(h.now, sid, h.request("heartbeat")))
    h.feed(ds.Stick(h.now, sid, h.request("stick"), 1, MOVE))
    assert h.setpoint == MOVE
    reqs = [h.request("estop") for _ in range(5)]
    for r in reqs:
        h.feed(ds.EStop(h.now, sid, r))
    assert h.estops == 1 and h.setpoint == ds.ZERO
    assert [h.answers[r] for r in reqs] == [[0]] * 5
    held = h.request("stick")
    h.feed(ds.Stick(h.now, sid, held, 2, MOVE))
    assert h.answers[held] == [314000] and h.setpoint == ds.ZERO
    h.feed(ds.Stick(h.now, sid, h.request("stick"), 0, MOVE))  # seq restarts at 0: drive again
    assert h.setpoint == MOVE


def test_heartbeat_loss_holds_and_a_heartbeat_releases() -> None:
    h = Harness()
    sid = _live(h)
    h.feed(ds.Stick(h.now, sid, h.request("stick"), 1, MOVE))
    for _ in range(8):  # sticks keep coming, heartbeats do not
        h.now += 0.4
        h.feed(ds.Tick(h.now))
        h.feed(ds.Stick(h.now, sid, h.request("stick"), int(h.now * 10), MOVE))
    assert h.m.state is ds.State.HOLDING and h.setpoint == ds.ZERO and h.m.failsafe == "heartbeat"
    late = h.request("stick")
    h.feed(ds.Stick(h.now, sid, late, 100_000, MOVE))
    assert h.answers[late] == [514301]
    actions = h.feed(ds.Heartbeat(h.now, sid, h.request("heartbeat")))
    assert ds.Notify(2, 0) in actions and h.m.state is ds.State.ACTIVE and h.setpoint == ds.ZERO
    h.feed(ds.Stick(h.now, sid, h.request("stick"), 100_001, MOVE))
    assert h.setpoint == MOVE


def test_a_stick_never_drives_past_an_unnoticed_heartbeat_deadline() -> None:
    """No tick between the deadline and the stick: the stick itself applies the deadline."""
    h = Harness()
    sid = _live(h)
    h.now += 3.5
    req = h.request("stick")
    h.feed(ds.Stick(h.now, sid, req, 1, MOVE))
    assert h.setpoint == ds.ZERO and h.answers[req] == [514301]


def test_stick_loss_zeroes_within_one_tick() -> None:
    h = Harness()
    sid = _live(h)
    h.feed(ds.Stick(h.now, sid, h.request("stick"), 1, MOVE))
    h.now += 0.48
    h.feed(ds.Tick(h.now))
    assert h.setpoint == MOVE
    h.now += 0.04
    actions = h.feed(ds.Tick(h.now))
    assert h.setpoint == ds.ZERO and ds.Failsafe("sticks", h.now) in actions
    assert h.m.state is ds.State.ACTIVE  # the session goes on: the next stick drives again


def test_repeated_enter_with_the_same_link_keeps_the_session() -> None:
    h = Harness()
    sid = _live(h, "drc-a")
    again = h.request("enter")
    assert h.feed(ds.Enter(h.now, again, ds.LinkSpec("drc-a", True))) == [ds.Reply(again, 0)]
    assert h.m.session_id == sid
    other = h.request("enter")
    h.feed(ds.Enter(h.now, other, ds.LinkSpec("drc-b", True)))  # another broker: a new session
    assert h.m.state is ds.State.EXITING and h.reported == 0 and other not in h.answers


def test_shutdown_while_connecting_answers_the_enter() -> None:
    h = Harness()
    req = h.request("enter")
    h.feed(ds.Enter(h.now, req, ds.LinkSpec("drc-a", True)))
    queued = h.request("exit")
    h.feed(ds.Exit(h.now, queued))
    h.feed(ds.Shutdown(h.now))
    assert h.m.state is ds.State.EXITING
    h.feed(ds.LinkClosed(h.now, min(h.closing)))
    assert h.answers[req] == [314000] and h.answers[queued] == [0] and h.m.state is ds.State.IDLE


def test_a_payload_command_is_forwarded_only_while_driving_freely() -> None:
    h = Harness()
    sid = _live(h)
    assert _kinds(h.feed(ds.PayloadCommand(h.now, sid, h.request("payload")))) == ["Forward"]
    assert _kinds(h.feed(ds.PayloadCommand(h.now, None, h.request("payload")))) == ["Count"]  # no session
    h.feed(ds.EStop(h.now, sid, h.request("estop")))
    refused = h.feed(ds.PayloadCommand(h.now, sid, h.request("payload")))
    assert [(type(a).__name__, getattr(a, "result", None)) for a in refused] == [
        ("Count", None),
        ("StickReply", ds.BUSY),
    ]
    h.feed(ds.Stick(h.now, sid, h.request("stick"), 0, ds.ZERO))  # seq 0 releases the stop
    h.now += CFG.heartbeat_timeout + 0.1  # heartbeats overdue: held, refused with 514301
    held = h.feed(ds.PayloadCommand(h.now, sid, h.request("payload")))
    assert [a.result for a in held if isinstance(a, ds.StickReply)] == [ds.DRC_HEARTBEAT_TIMEOUT]
    assert not any(isinstance(a, ds.Forward) for a in held)


@given(roll=st.integers(364, 1684), pitch=st.integers(364, 1684), throttle=st.integers(364, 1684),
       yaw=st.integers(364, 1684))  # fmt: skip
def test_stick_channels_map_linearly_within_the_limits(
    roll: int, pitch: int, throttle: int, yaw: int
) -> None:
    forward, right, up, yaw_rate = ds.channels_to_setpoint(roll, pitch, throttle, yaw, LIMITS)
    assert abs(forward) <= LIMITS.horizontal and abs(right) <= LIMITS.horizontal
    assert -LIMITS.down <= up <= LIMITS.up and abs(yaw_rate) <= LIMITS.yaw_rate
    # DJI's directions: larger roll right, pitch forward, throttle up, yaw clockwise; 1024 still
    for value, axis in ((roll, right), (pitch, forward), (throttle, up), (yaw, yaw_rate)):
        assert (axis > 0) == (value > ds.STICK_NEUTRAL) and (axis < 0) == (value < ds.STICK_NEUTRAL)
    assert ds.channels_to_setpoint(1024, 1024, 1024, 1024, LIMITS) == ds.ZERO
    assert ds.channels_to_setpoint(1684, 1684, 1684, 1684, LIMITS) == (10.0, 10.0, 5.0, 90.0)
    assert ds.channels_to_setpoint(364, 364, 364, 364, LIMITS) == (-10.0, -10.0, -4.0, -90.0)


def test_the_session_and_the_contract_agree_on_the_stick_channels() -> None:
    assert (ds.STICK_NEUTRAL, ds.STICK_NEUTRAL + ds.STICK_SPAN, ds.STICK_NEUTRAL - ds.STICK_SPAN) == (
        STICK_NEUTRAL,
        STICK_MAX,
        STICK_MIN,
    )


def test_five_copies_of_enter_and_of_exit_make_one_session_and_one_exit() -> None:
    """DJI's reference cloud sends each message five times (a new tid each, at worst), the copies
    racing the link: one link opened, one closed, every copy answered 0, drc_state reported once each."""
    h = Harness()
    link = ds.LinkSpec("drc-a", True)
    reports: list[int] = []

    def feed(event: ds.Event) -> None:
        reports.extend(a.drc_state for a in h.feed(event) if isinstance(a, ds.Report))

    enters = [h.request("enter") for _ in range(5)]
    for req in enters:
        feed(ds.Enter(h.now, req, link))
    assert len(h.opening) == 1 and not h.answers  # one link being opened; the copies wait their turn
    feed(ds.LinkUp(h.now, min(h.opening)))
    assert [h.answers[r] for r in enters] == [[0]] * 5 and reports == [1, 2]
    exits = [h.request("exit") for _ in range(5)]
    for req in exits:
        feed(ds.Exit(h.now, req))
    assert len(h.closing) == 1 and reports == [1, 2, 0]
    feed(ds.LinkClosed(h.now, min(h.closing)))
    assert [h.answers[r] for r in exits] == [[0]] * 5 and reports == [1, 2, 0]
    assert h.m.state is ds.State.IDLE and not (h.opening or h.open or h.closing)


def test_the_failsafe_is_one_incident_owned_by_the_session_and_ends_with_it() -> None:
    """Issue #31: an emergency stop, exit and enter again: the new session shows no failsafe (its osd said
    emergency_stop while sticks flew the aircraft); a failsafe firing again keeps its incident's start,
    another reason starts a new one."""
    h = Harness()
    sid = _live(h, "drc-a")
    h.feed(ds.EStop(h.now, sid, h.request("estop")))
    assert (h.m.failsafe, h.m.failsafe_since) == ("emergency_stop", h.now)
    first = h.now
    h.now += 5.0
    h.feed(ds.EStop(h.now, sid, h.request("estop")))  # the same incident, repeated
    assert h.m.failsafe_since == first
    h.feed(ds.Exit(h.now, h.request("exit")))
    h.feed(ds.LinkClosed(h.now, min(h.closing)))
    assert (h.m.failsafe, h.m.failsafe_since) == (None, None)  # the session ended: so did its failsafe
    h.now += 30.0
    sid = _live(h, "drc-b")
    assert h.m.failsafe is None
    h.feed(ds.Stick(h.now, sid, h.request("stick"), 1, MOVE))
    assert h.setpoint == MOVE and h.m.failsafe is None
    h.now += 1.0
    h.feed(ds.Tick(h.now))  # the sticks stop: a new incident, now
    assert (h.m.failsafe, h.m.failsafe_since) == ("sticks", h.now)
    h.feed(ds.BrokerLost(h.now + 0.1, sid))  # another reason: another incident
    assert (h.m.failsafe, h.m.failsafe_since) == ("link_lost", h.now + 0.1)


def test_a_stick_refused_for_an_automatic_task_says_why() -> None:
    h = Harness()
    sid = _live(h)
    req = h.request("stick")
    reason = "waypoint mission flies OSDK-1: stop it (or wait for its end) to fly by sticks"
    actions = h.feed(
        ds.Stick(h.now, sid, req, 1, MOVE, authorized=False, denied_result=314000, denied_reason=reason)
    )
    assert h.answers[req] == [314000] and h.setpoint == ds.ZERO
    replies = [a for a in actions if isinstance(a, ds.StickReply)]
    assert replies[0].reason == reason


def test_a_fresh_enter_ends_the_emergency_stop_and_increasing_seqs_drive_again() -> None:
    """Issue #33: after drone_emergency_stop, a client whose seq only increases was locked out until it
    restarted (only a seq 0 released the stop). A fresh drc_mode_enter of the same session releases it:
    nothing moves until the next stick, which drives with the next seq; the old seq rule still holds."""
    h = Harness()
    sid = _live(h, "drc-a")
    fwd = (1.0, 0.0, 0.0, 0.0)
    h.feed(ds.Heartbeat(h.now, sid, h.request("heartbeat")))
    h.feed(ds.Stick(h.now, sid, h.request("stick"), 7, fwd))
    assert h.setpoint == fwd
    h.feed(ds.EStop(h.now, sid, h.request("estop")))
    held = h.request("stick")
    h.feed(ds.Stick(h.now, sid, held, 8, fwd))
    assert h.answers[held] == [ds.BUSY] and h.setpoint == ds.ZERO and h.m.failsafe == "emergency_stop"
    again = h.request("enter")
    actions = h.feed(ds.Enter(h.now, again, ds.LinkSpec("drc-a", True)))
    assert h.answers[again] == [0] and h.m.session_id == sid  # the same session, not a new link
    assert h.m.state is ds.State.ACTIVE and h.m.failsafe is None and h.setpoint == ds.ZERO
    assert ds.Failsafe(None, h.now) in actions
    old = h.request("stick")
    h.feed(ds.Stick(h.now, sid, old, 6, fwd))
    assert h.answers[old] == [ds.DRC_SEQ_TOO_OLD] and h.setpoint == ds.ZERO  # seq rules unchanged
    driven = h.request("stick")
    h.feed(ds.Stick(h.now, sid, driven, 9, fwd))
    assert h.answers[driven] == [0] and h.setpoint == fwd


def test_a_fresh_enter_does_not_end_a_heartbeat_hold() -> None:
    h = Harness()
    sid = _live(h, "drc-a")
    h.now += CFG.heartbeat_timeout + 0.1
    h.feed(ds.Tick(h.now))
    assert h.m.failsafe == "heartbeat"
    h.feed(ds.Enter(h.now, h.request("enter"), ds.LinkSpec("drc-a", True)))
    held = h.request("stick")
    h.feed(ds.Stick(h.now, sid, held, 1, (1.0, 0.0, 0.0, 0.0)))
    assert h.answers[held] == [ds.DRC_HEARTBEAT_TIMEOUT] and h.setpoint == ds.ZERO
