"""Cloud-control authorisation without I/O (gateway/control_auth.py): the allow-list, the operator's
accept and deny, the deadline, a replaced request, the release, and what live control is told; then the
shell (gateway/cloud_control.py) on a ManualClock: the notify after the reply, the timer."""

from __future__ import annotations

import asyncio
import sys
from pathlib import Path
from typing import Any

import pytest

from gateway.clock import ManualClock
from gateway.cloud_control import CloudControl
from gateway.control_auth import NOT_GRANTED, ControlAuth, Decision, Notify
from gateway.metrics import Metrics
from gateway.settings import CloudControlSettings
from schemas import ResultCode
from schemas.cloud_control import CloudControlAuthRequest, CloudControlRelease
from tests.test_sans_io import FORBIDDEN_STDLIB, _imports

T0 = 100.0


def book(allow: tuple[str, ...] = ("ops-1",), timeout: float = 60.0, required: bool = False) -> ControlAuth:
    return ControlAuth(allow=frozenset(allow), timeout=timeout, required=required)


def test_the_decisions_import_no_io() -> None:
    path = Path(__file__).resolve().parent.parent / "gateway" / "control_auth.py"
    found = {name.split(".")[0] for name in _imports(path)}
    assert found <= (set(sys.stdlib_module_names) - FORBIDDEN_STDLIB) | {"__future__"}, found


def test_not_in_force_until_a_cloud_uses_the_flow_or_it_is_required() -> None:
    auth = book()
    assert not auth.in_force
    assert auth.enter_refusal() is None and auth.stick_refusal(None) is None  # older clouds as before
    strict = book(required=True)
    refusal = strict.enter_refusal()
    assert refusal is not None and refusal.code == NOT_GRANTED == ResultCode.CLOUD_CONTROL_NOT_GRANTED
    assert "cloud_control_auth_request" in refusal.reason


def test_an_allow_listed_user_is_granted_at_once() -> None:
    auth = book()
    assert auth.request(T0, "ops-1", "Ops", "bid-1") == [Notify("ok", "bid-1", "ops-1", "allow-list")]
    assert auth.holder == "ops-1" and auth.pending is None and auth.in_force
    assert auth.enter_refusal() is None
    assert auth.stick_refusal("ops-1") is None
    # asking again while holding it: ok again, nothing waits
    assert auth.request(T0 + 1, "ops-1", "Ops", "bid-2") == [Notify("ok", "bid-2", "ops-1", "holder")]


def test_anyone_else_waits_for_the_operator_who_accepts() -> None:
    auth = book()
    assert auth.request(T0, "guest", "Guest", "bid-g") == []
    assert auth.pending is not None and auth.pending.deadline == T0 + 60
    refusal = auth.enter_refusal()
    assert refusal is not None and "waits for the operator" in refusal.reason
    # an answer meant for another request does not land on this one
    notes, problem = auth.decide(T0 + 5, Decision.ACCEPT, "somebody")
    assert notes == [] and problem is not None and "'guest'" in problem and auth.pending is not None
    notes, problem = auth.decide(T0 + 5, Decision.ACCEPT, "guest")
    assert problem is None and notes == [Notify("ok", "bid-g", "guest", "operator")]
    assert auth.holder == "guest" and auth.grant is not None and auth.grant.by == "operator"
    assert auth.enter_refusal() is None
    snap = auth.snapshot(T0 + 7)
    assert snap["holder"] == {"user_id": "guest", "user_callsign": "Guest", "by": "operator", "held_s": 2.0}
    assert snap["pending"] is None and snap["in_force"] is True


def test_the_operator_denies_and_nothing_is_granted() -> None:
    auth = book()
    auth.request(T0, "guest", "Guest", "bid-g")
    notes, problem = auth.decide(T0 + 1, Decision.DENY)
    assert problem is None and notes == [Notify("failed", "bid-g", "guest", "operator")]
    assert auth.holder is None and auth.pending is None
    assert auth.enter_refusal() is not None  # in force now: live control needs a grant
    notes, problem = auth.decide(T0 + 2, Decision.ACCEPT)
    assert notes == [] and problem == "no cloud-control request is waiting"


def test_no_answer_in_time_denies() -> None:
    auth = book(timeout=2.0)
    auth.request(T0, "guest", "Guest", "bid-g")
    assert auth.tick(T0 + 1.999) == [] and auth.pending is not None
    assert auth.snapshot(T0 + 1.5)["pending"]["left_s"] == 0.5  # type: ignore[index]
    assert auth.tick(T0 + 2.0) == [Notify("failed", "bid-g", "guest", "timeout")]
    assert auth.pending is None and auth.holder is None
    # a late accept finds nothing (and says why)
    notes, problem = auth.decide(T0 + 3, Decision.ACCEPT)
    assert notes == [] and problem is not None


def test_a_late_answer_after_the_deadline_reports_the_timeout_not_a_grant() -> None:
    auth = book(timeout=2.0)
    auth.request(T0, "guest", "Guest", "bid-g")
    notes, problem = auth.decide(T0 + 5, Decision.ACCEPT)  # nobody ticked in between: decide ticks first
    assert notes == [Notify("failed", "bid-g", "guest", "timeout")]
    assert problem == "no cloud-control request is waiting (it timed out)" and auth.holder is None


def test_a_resend_keeps_the_request_another_user_replaces_it() -> None:
    auth = book(timeout=10.0)
    auth.request(T0, "guest", "Guest", "bid-1")
    assert auth.request(T0 + 3, "guest", "Guest", "bid-1b") == []  # a cloud's resend: same request
    assert auth.pending is not None and auth.pending.bid == "bid-1" and auth.pending.deadline == T0 + 10
    first = auth.pending.number
    assert auth.request(T0 + 4, "other", "Other", "bid-2") == [
        Notify("canceled", "bid-1", "guest", "replaced")
    ]
    assert auth.pending is not None and auth.pending.user_id == "other" and auth.pending.number > first
    assert auth.pending.deadline == T0 + 14


def test_a_hand_over_is_the_operators_call_even_for_the_allow_list() -> None:
    auth = book(allow=("ops-1", "ops-2"))
    auth.request(T0, "ops-1", "Ops 1", "bid-1")
    assert auth.request(T0 + 1, "ops-2", "Ops 2", "bid-2") == []  # ops-1 holds it: the operator decides
    assert auth.holder == "ops-1" and auth.pending is not None
    # while waiting, ops-1's session still flies
    assert auth.stick_refusal("ops-1") is None
    notes, _ = auth.decide(T0 + 2, Decision.ACCEPT)
    assert notes == [Notify("ok", "bid-2", "ops-2", "operator")] and auth.holder == "ops-2"
    refusal = auth.stick_refusal("ops-1")  # the session ops-1 entered no longer flies
    assert refusal is not None and refusal.code == NOT_GRANTED and "'ops-2'" in refusal.reason
    assert auth.stick_refusal("ops-2") is None


def test_release_ends_the_grant_and_the_sessions_sticks() -> None:
    auth = book()
    auth.request(T0, "ops-1", "Ops", "bid-1")
    ended = auth.release(T0 + 1)
    assert ended is not None and ended.user_id == "ops-1" and auth.holder is None
    refusal = auth.stick_refusal("ops-1")
    assert refusal is not None and "released" in refusal.reason
    assert auth.release(T0 + 2) is None  # nothing held: nothing ended
    # a session entered before the flow was in force does not fly once it is
    fresh = book()
    assert fresh.stick_refusal(None) is None
    fresh.request(T0, "ops-1", "Ops", "b")
    assert fresh.stick_refusal(None) is not None


# ------------------------------------------------------------------------------------ the shell
class _Events:
    def __init__(self) -> None:
        self.sent: list[tuple[str, dict[str, Any], bool, str]] = []

    def __call__(self, method: str, data: dict[str, Any], need_reply: bool, bid: str) -> None:
        self.sent.append((method, data, need_reply, bid))

    def statuses(self) -> list[tuple[str, str]]:
        return [(data["output"]["status"], bid) for _, data, _, bid in self.sent]


def _shell(clock: ManualClock, **settings: Any) -> tuple[CloudControl, _Events, list[str]]:
    events, changes = _Events(), []
    cc = CloudControl(
        settings=CloudControlSettings(**settings),
        clock=clock,
        publish_event=events,
        metrics=Metrics(),
        on_change=lambda: changes.append(str(cc.auth.holder)),
    )
    return cc, events, changes


def _ask(user: str) -> CloudControlAuthRequest:
    return CloudControlAuthRequest(user_id=user, user_callsign=user.upper(), control_keys=["flight"])


async def _settle() -> None:
    for _ in range(5):
        await asyncio.sleep(0)


def test_the_shell_notifies_after_the_reply_and_denies_on_its_clock() -> None:
    async def scenario() -> None:
        clock = ManualClock()
        cc, events, changes = _shell(clock, allow=("ops-1",), timeout=30.0)
        result, output = await cc.call("cloud_control_auth_request", _ask("ops-1"), "bid-a")
        assert (result, output) == (0, {"status": "ok"})
        assert events.sent == []  # the notify follows the request's reply, never precedes it
        await _settle()
        assert events.sent == [
            ("cloud_control_auth_notify", {"result": 0, "output": {"status": "ok"}}, False, "bid-a")
        ]
        assert changes == ["ops-1"]
        assert await cc.call(
            "cloud_control_release", CloudControlRelease(control_keys=["flight"]), "bid-r"
        ) == (
            0,
            {"status": "ok"},
        )
        assert changes == ["ops-1", "None"]

        # a user not on the list waits; 29.9 s later still waiting, at 30 s denied
        await cc.call("cloud_control_auth_request", _ask("guest"), "bid-g")
        await _settle()
        assert len(events.sent) == 1 and cc.snapshot()["pending"] is not None
        clock.advance(29.9)
        await _settle()
        assert len(events.sent) == 1
        clock.advance(0.1)
        await _settle()
        assert events.statuses()[-1] == ("failed", "bid-g") and cc.snapshot()["pending"] is None

        # the operator accepts the next one before its deadline: no timer fires later
        await cc.call("cloud_control_auth_request", _ask("guest"), "bid-g2")
        outcome = cc.decide("accept", "guest", who="test")
        assert outcome["ok"] is True and outcome["cloud_control"]["holder"]["user_id"] == "guest"
        await _settle()
        assert events.statuses()[-1] == ("ok", "bid-g2") and changes[-1] == "guest"
        clock.advance(60)
        await _settle()
        assert events.statuses()[-1] == ("ok", "bid-g2") and len(events.sent) == 3
        assert clock.sleepers == 0
        assert cc.decide("deny")["ok"] is False  # nothing waits
        revoked = cc.decide("revoke", who="test")
        assert revoked["ok"] is True and changes[-1] == "None"
        assert cc.decide("revoke")["reason"] == "nobody holds cloud control"

    asyncio.run(scenario())


@pytest.mark.parametrize("keys", [["payload"], ["flight", "flight"], [], "flight"])
def test_only_the_flight_key_is_accepted(keys: Any) -> None:
    with pytest.raises(ValueError):
        CloudControlAuthRequest.model_validate({"user_id": "u", "user_callsign": "U", "control_keys": keys})
    with pytest.raises(ValueError):
        CloudControlRelease.model_validate({"control_keys": keys})
