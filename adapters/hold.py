"""Held set-points: a command a device must hear again and again until its hold runs out.

Owns: the one loop behind the R SDK gimbal's screen drag (speed control resent at ``drag_rate_hz``,
then zero and release) and the robot's chassis velocity and gimbal drag (resent or integrated at their
rates until the hold ends). The owner says what a refresh sends and what ending does; this module
owns the timing, on the adapter's injected :class:`~adapters.clock.Clock`: the deadline, the wake-ups,
the last step up to the deadline, and who may end it.
Must not know frames, links or the Cloud API. Runs on the adapter's event loop;
:meth:`HeldSetpoint.expire` is the one call safe from another thread (it writes one float: the loop
ends at its next wake-up).
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable

from adapters.clock import Clock

__all__ = ["HeldSetpoint"]


class HeldSetpoint:
    """A set-point refreshed every ``period`` seconds until :attr:`until`.

    ``refresh(dt)`` runs at each wake-up before the deadline (``dt``: seconds since the last one, for
    set-points integrated from speeds). With ``step_to_deadline`` the wake-up that reaches the deadline
    refreshes once more with ``dt`` up to the deadline (a drag integrates its whole hold), unless the
    hold was ended early with :meth:`expire` or :meth:`cancel`. ``on_end()`` runs when the hold runs
    out; with ``end_when_cancelled`` also when the task is cancelled (the gimbal must be released
    whatever ended the drag)."""

    __slots__ = (
        "_clock",
        "_end_when_cancelled",
        "_name",
        "_now",
        "_on_end",
        "_refresh",
        "_step",
        "period",
        "task",
        "until",
    )

    def __init__(
        self,
        name: str,
        *,
        period: float,
        clock: Clock,
        refresh: Callable[[float], None],
        on_end: Callable[[], None] | None = None,
        step_to_deadline: bool = False,
        end_when_cancelled: bool = False,
    ) -> None:
        self._name = name
        self.period = period
        self._clock = clock
        self._now = clock.monotonic
        self._refresh = refresh
        self._on_end = on_end
        self._step = step_to_deadline
        self._end_when_cancelled = end_when_cancelled
        self.until = -math.inf
        self.task: asyncio.Task[None] | None = None

    @property
    def running(self) -> bool:
        return self.task is not None

    def hold(self, seconds: float) -> bool:
        """Hold for ``seconds`` from now (replacing any earlier deadline); start the loop unless it
        runs. True when it started one. Call on the event loop."""
        self.until = self._now() + seconds
        return self.start()

    def start(self) -> bool:
        """Start the loop for the current :attr:`until` unless it runs; True when it started one."""
        if self.task is not None and not self.task.done():
            return False
        self.task = asyncio.get_running_loop().create_task(self._run(), name=self._name)
        return True

    def expire(self) -> None:
        """End the hold at the loop's next wake-up (without a last step). Safe from any thread."""
        self.until = -math.inf

    def cancel(self) -> None:
        """End the hold now: expire it and cancel the loop (unless the loop itself is calling: it
        then ends at its next check). Call on the event loop."""
        self.until = -math.inf
        if self.task is not None and self.task is not asyncio.current_task():
            self.task.cancel()
        self.task = None

    async def _run(self) -> None:
        last = self._now()
        ran_out = False
        try:
            while True:
                left = self.until - self._now()
                if left <= 0:
                    break
                await self._clock.sleep(min(self.period, left))
                now = self._now()
                if now >= self.until and not (self._step and self.until >= last):
                    break
                self._refresh(min(now, self.until) - last)
                last = now
            ran_out = True
        finally:
            if self.task is asyncio.current_task():
                self.task = None
            if self._on_end is not None and (ran_out or self._end_when_cancelled):
                self._on_end()
