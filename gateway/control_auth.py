"""Cloud-control authorisation: who may fly by live control, decided without I/O.

Owns the decisions behind ``cloud_control_auth_request`` / ``cloud_control_release`` (DJI's RC Plus 2
and RC Pro; docs/cloud-api.md, "Cloud-control authorisation"): the one grant (which cloud user holds
cloud control), the one request waiting for the operator, the allow-list, the operator's deadline, and
what live control asks of them (may this cloud enter DRC, do these sticks belong to the grant holder).
Must not know MQTT, the clock's source, HTTP or the DRC session: time comes in as a value (``now``,
monotonic seconds), results go out as :class:`Notify` values the shell publishes
(gateway/cloud_control.py).

Theory of operation. An RC Plus 2 shows the pilot a pop-up; here the gateway's **allow-list** answers
at once for the user ids it names, and everyone else waits for the **operator** (the web console's
Accept/Deny, ``dji-gateway control-auth accept|deny``) until ``timeout`` passes, which denies:

* a request from the user who holds the grant: granted again (``ok``) at once;
* a request from an allow-listed user while nobody else holds the grant: granted at once;
* any other request waits for the operator (a hand-over from one holder to another is the operator's
  call, allow-listed or not); a request from the user already waiting changes nothing (a cloud's resend),
  a request from another user replaces the waiting one, which ends ``canceled`` (DJI's meaning of it);
* the operator's accept grants (the previous holder, if any, loses it), deny ends the request
  ``failed``, and so does the deadline (:meth:`ControlAuth.tick`);
* ``cloud_control_release`` (or the operator's revoke) ends the grant; a waiting request stays.

Cloud control is **in force** once any cloud has used the flow since the gateway started, or from the
start with ``required``; until then older clouds that never send it use live control as before. In
force, ``drc_mode_enter`` needs a grant, and the session it opens belongs to the holder at that moment
(``owner``): its sticks are refused once the grant ends or passes to another user. ``drc/down``
carries no user id, so "the holder's sticks" means "the sticks of the session the holder entered".
Every refusal is 399003 with a reason a person can act on.
"""

from __future__ import annotations

import enum
import itertools
from dataclasses import dataclass

__all__ = ["NOT_GRANTED", "ControlAuth", "Decision", "Grant", "Notify", "Pending", "Refusal"]

#: the result code of every refusal here (schemas.results.ResultCode.CLOUD_CONTROL_NOT_GRANTED)
NOT_GRANTED = 399003


class Decision(enum.StrEnum):
    ACCEPT = "accept"
    DENY = "deny"


@dataclass(frozen=True, slots=True)
class Grant:
    """Who holds cloud control, since when (monotonic s), and who decided (``allow-list``/``operator``)."""

    user_id: str
    user_callsign: str
    since: float
    by: str


@dataclass(frozen=True, slots=True)
class Pending:
    """A request waiting for the operator; ``number`` tells two requests of one user apart."""

    number: int
    user_id: str
    user_callsign: str
    bid: str
    asked: float
    deadline: float


@dataclass(frozen=True, slots=True)
class Notify:
    """Publish ``cloud_control_auth_notify`` with ``status`` for the request whose ``bid`` this is."""

    status: str  # "ok", "failed", "canceled" (schemas.cloud_control.AuthStatus)
    bid: str
    user_id: str
    why: str  # for the log and the journal: allow-list, holder, operator, timeout, replaced


@dataclass(frozen=True, slots=True)
class Refusal:
    """Why something is refused: the result code and a reason for a person."""

    code: int
    reason: str


class ControlAuth:
    def __init__(self, *, allow: frozenset[str], timeout: float, required: bool) -> None:
        self.allow = allow
        self.timeout = timeout
        self.required = required
        self.used = False  # a cloud has sent cloud_control_auth_request since the start
        self.grant: Grant | None = None
        self.pending: Pending | None = None
        self._numbers = itertools.count(1)

    # ----------------------------------------------------------------------------------- observers
    @property
    def in_force(self) -> bool:
        return self.required or self.used

    @property
    def holder(self) -> str | None:
        grant = self.grant
        return grant.user_id if grant is not None else None

    def snapshot(self, now: float) -> dict[str, object]:
        """For /status and the console: in force or not, the holder, the request waiting and its time left."""
        grant, pending = self.grant, self.pending
        holder = None
        if grant is not None:
            holder = {
                "user_id": grant.user_id,
                "user_callsign": grant.user_callsign,
                "by": grant.by,
                "held_s": round(now - grant.since, 1),
            }
        waiting = None
        if pending is not None:
            waiting = {
                "number": pending.number,
                "user_id": pending.user_id,
                "user_callsign": pending.user_callsign,
                "waiting_s": round(now - pending.asked, 1),
                "left_s": round(max(0.0, pending.deadline - now), 1),
            }
        return {"in_force": self.in_force, "required": self.required, "holder": holder, "pending": waiting}

    # -------------------------------------------------------------------------------------- events
    def request(self, now: float, user_id: str, user_callsign: str, bid: str) -> list[Notify]:
        """A ``cloud_control_auth_request`` (validated: ``control_keys`` is ``["flight"]``)."""
        self.used = True
        out = self.tick(now)
        grant, pending = self.grant, self.pending
        if grant is not None and grant.user_id == user_id:
            return [*out, Notify("ok", bid, user_id, "holder")]
        if pending is not None and pending.user_id == user_id:
            return out  # the same user asks again (a resend): the operator's answer will come
        if pending is not None:
            out.append(Notify("canceled", pending.bid, pending.user_id, "replaced"))
            self.pending = None
        if user_id in self.allow and grant is None:
            self.grant = Grant(user_id, user_callsign, now, "allow-list")
            return [*out, Notify("ok", bid, user_id, "allow-list")]
        self.pending = Pending(next(self._numbers), user_id, user_callsign, bid, now, now + self.timeout)
        return out

    def decide(
        self, now: float, decision: Decision, user_id: str | None = None
    ) -> tuple[list[Notify], str | None]:
        """The operator's answer to the waiting request (``user_id``: the one the operator saw, so an
        answer never lands on a request that replaced it). Returns the notifications, or a reason why
        there is nothing to answer."""
        out = self.tick(now)
        pending = self.pending
        if pending is None:
            return out, "no cloud-control request is waiting" + (" (it timed out)" if out else "")
        if user_id is not None and user_id != pending.user_id:
            return out, f"the waiting request is from {pending.user_id!r}, not {user_id!r}"
        self.pending = None
        if decision is Decision.ACCEPT:
            self.grant = Grant(pending.user_id, pending.user_callsign, now, "operator")
            return [*out, Notify("ok", pending.bid, pending.user_id, "operator")], None
        return [*out, Notify("failed", pending.bid, pending.user_id, "operator")], None

    def release(self, now: float) -> Grant | None:
        """``cloud_control_release`` or the operator's revoke: the grant ends (the one ended, if any)."""
        ended, self.grant = self.grant, None
        return ended

    def tick(self, now: float) -> list[Notify]:
        """The operator's deadline: a request not answered in time is denied."""
        pending = self.pending
        if pending is None or now < pending.deadline:
            return []
        self.pending = None
        return [Notify("failed", pending.bid, pending.user_id, "timeout")]

    # ------------------------------------------------------------------------------- live control
    def enter_refusal(self) -> Refusal | None:
        """Why ``drc_mode_enter`` is refused now (None: it may go on, for the holder)."""
        if not self.in_force or self.grant is not None:
            return None
        pending = self.pending
        if pending is not None:
            return Refusal(
                NOT_GRANTED,
                f"cloud control for {pending.user_id!r} waits for the operator: enter live control once "
                "cloud_control_auth_notify says ok",
            )
        return Refusal(NOT_GRANTED, "request cloud control first (cloud_control_auth_request)")

    def stick_refusal(self, owner: str | None) -> Refusal | None:
        """Why sticks of the session entered by ``owner`` (the holder when it was entered; None: entered
        before cloud control was in force) are refused now."""
        if not self.in_force:
            return None
        holder = self.holder
        if holder is None:
            return Refusal(NOT_GRANTED, "cloud control was released: request it again")
        if owner != holder:
            return Refusal(
                NOT_GRANTED, f"cloud control is held by {holder!r}, not by the client of this session"
            )
        return None
