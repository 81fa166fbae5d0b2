"""Cloud-control authorisation: the I/O around the sans-I/O decisions in :mod:`gateway.control_auth`.

Owns answering ``cloud_control_auth_request`` and ``cloud_control_release`` (for the dispatcher),
publishing ``cloud_control_auth_notify`` (after the request's reply, ``bid`` the request's), the
operator's deadline as a timer on the injected clock, the operator's answers (the web console, the
``dji-gateway control-auth`` CLI through it), their audit lines, and telling live control when the grant
changed. Runs on the event loop only. Must not know HTTP, MQTT topics (it publishes through the
northbound's ``event``) or how live control refuses (gateway/drc.py asks :attr:`CloudControl.auth`).
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable
from typing import Any

from gateway.audit import audit
from gateway.clock import Clock
from gateway.control_auth import ControlAuth, Decision, Notify
from gateway.metrics import Metrics
from gateway.settings import CloudControlSettings
from schemas import ResultCode
from schemas.cloud_control import CloudControlAuthRequest

log = logging.getLogger(__name__)

__all__ = ["CloudControl"]

#: publish one event: (method, data, need_reply, bid)
PublishEvent = Callable[[str, dict[str, Any], bool, str], None]


class CloudControl:
    methods = frozenset({"cloud_control_auth_request", "cloud_control_release"})

    def __init__(
        self,
        *,
        settings: CloudControlSettings,
        clock: Clock,
        publish_event: PublishEvent,
        metrics: Metrics,
        on_change: Callable[[], None] | None = None,
    ) -> None:
        self.auth = ControlAuth(
            allow=frozenset(settings.allow), timeout=settings.timeout, required=settings.required
        )
        self.clock = clock
        self.publish_event = publish_event
        self.metrics = metrics
        #: told after the grant changed hands or ended (live control re-checks its session's sticks)
        self.on_change = on_change
        self._timer: asyncio.Task[None] | None = None

    def snapshot(self) -> dict[str, object]:
        return self.auth.snapshot(self.clock.monotonic())

    # ------------------------------------------------------------------------ the cloud (dispatcher)
    async def call(self, method: str, data: Any, bid: str) -> tuple[int, dict[str, Any] | None]:
        """Answer one of :attr:`methods` (``data`` validated by the contract)."""
        before = self.auth.holder
        now = self.clock.monotonic()
        if method == "cloud_control_auth_request":
            assert isinstance(data, CloudControlAuthRequest)
            notes = self.auth.request(now, data.user_id, data.user_callsign, bid)
            waiting = self.auth.pending
            if waiting is not None and waiting.bid == bid:
                log.warning(
                    "cloud control asked by %r (%s): accept or deny it in the console or with "
                    "`dji-gateway control-auth accept|deny` within %.0f s",
                    data.user_id, data.user_callsign, self.auth.timeout,
                )  # fmt: skip
                audit("cloud_control_request", user_id=data.user_id, bid=bid, result="waiting")
        else:
            ended = self.auth.release(now)
            notes = []
            audit("cloud_control_release", user_id=ended.user_id if ended else None, source="mqtt")
        self._after(notes, before)
        return ResultCode.SUCCESS, {"status": "ok"}

    # ---------------------------------------------------------------------- the operator (console, CLI)
    def decide(self, decision: str, user_id: str | None = None, who: str = "operator") -> dict[str, Any]:
        """Accept or deny the waiting request (``user_id``: the one the operator saw), or ``revoke`` the
        grant. ``{"ok": bool, "reason"?: str, "cloud_control": snapshot}``."""
        before = self.auth.holder
        now = self.clock.monotonic()
        if decision == "revoke":
            ended = self.auth.release(now)
            audit("cloud_control_revoke", who=who, user_id=ended.user_id if ended else None)
            self._after([], before)
            if ended is None:
                return {"ok": False, "reason": "nobody holds cloud control", "cloud_control": self.snapshot()}
            return {"ok": True, "cloud_control": self.snapshot()}
        notes, problem = self.auth.decide(now, Decision(decision), user_id)
        self._after(notes, before)
        if problem is not None:
            return {"ok": False, "reason": problem, "cloud_control": self.snapshot()}
        audit("cloud_control_decision", who=who, decision=decision, user_id=notes[-1].user_id)
        return {"ok": True, "cloud_control": self.snapshot()}

    # ------------------------------------------------------------------------------------- the rest
    def _after(self, notes: list[Notify], holder_before: str | None) -> None:
        """Publish the notifications (after the request's reply: scheduled, not sent now), re-arm the
        deadline, and tell live control when the grant changed."""
        loop = asyncio.get_running_loop()
        for note in notes:
            loop.call_soon(self._notify, note)
        self._arm()
        if self.auth.holder != holder_before and self.on_change is not None:
            self.on_change()

    def _notify(self, note: Notify) -> None:
        log.info("cloud control for %r: %s (%s)", note.user_id, note.status, note.why)
        self.metrics.inc("cloud_control_decisions_total", status=note.status, why=note.why)
        if note.why == "timeout":
            audit("cloud_control_decision", who="timeout", decision="deny", user_id=note.user_id)
        self.publish_event(
            "cloud_control_auth_notify", {"result": 0, "output": {"status": note.status}}, False, note.bid
        )

    def _arm(self) -> None:
        """One timer for the waiting request's deadline (none when nothing waits)."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        pending = self.auth.pending
        if pending is not None:
            delay = pending.deadline - self.clock.monotonic()
            self._timer = asyncio.get_running_loop().create_task(
                self._expire(delay), name="cloud-control-timeout"
            )

    async def _expire(self, delay: float) -> None:
        await self.clock.sleep(delay)
        self._timer = None
        before = self.auth.holder
        self._after(self.auth.tick(self.clock.monotonic()), before)

    def stop(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
