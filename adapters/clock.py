"""Time as a value: the one :class:`Clock` that ``GatewayApp(clock=)`` is given reaches every part that
keeps time on the event loop, so a test can drive each of their timers with a :class:`ManualClock`.

Owns the clock protocol and its two implementations. It lives here, below ``gateway/``, because the
adapters take it too (their request deadlines, drag and hold loops, link supervision and its backoff)
and adapters never import ``gateway/``; ``gateway.clock`` re-exports it.

A clock answers four things: ``monotonic()`` for deadlines and intervals; ``time_ms()`` for the Cloud
API's wall-clock ``timestamp`` fields; ``sleep(seconds)`` and ``wait_for(awaitable, timeout)`` for the
loop's timers. What still takes its own time, and why, is said next to each call: threads whose wait
must be real (paho's, the motion writer's condition variable, a link's writer), simulators (a device
keeps its own time), and the operator CLIs (separate processes that read the system clock).

Must not know: the gateway, any device family, MQTT.
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import itertools
import threading
import time
from collections.abc import Awaitable
from typing import Any, Protocol, TypeVar

__all__ = ["SYSTEM_CLOCK", "Clock", "ManualClock", "SystemClock"]

T = TypeVar("T")


class Clock(Protocol):
    def monotonic(self) -> float:
        """Seconds on a clock that never goes back (deadlines, intervals)."""
        ...

    def time_ms(self) -> int:
        """Wall-clock milliseconds since the Unix epoch (the Cloud API's ``timestamp``)."""
        ...

    async def sleep(self, seconds: float) -> None:
        """Return once ``seconds`` have passed on this clock (in the running loop)."""
        ...

    async def wait_for(self, aw: Awaitable[T], timeout: float) -> T:
        """``aw``'s result, or :class:`TimeoutError` (``aw`` cancelled) once ``timeout`` has passed on
        this clock."""
        ...


class SystemClock:
    """The machine's clocks and the loop's own timers."""

    def monotonic(self) -> float:
        return time.monotonic()

    def time_ms(self) -> int:
        return time.time_ns() // 1_000_000

    async def sleep(self, seconds: float) -> None:
        await asyncio.sleep(seconds)

    async def wait_for(self, aw: Awaitable[T], timeout: float) -> T:
        if timeout <= 0:  # asyncio.wait_for's rule: not even started (asyncio.timeout would start it)
            return await asyncio.wait_for(aw, timeout)
        # in the caller's own task: asyncio.wait_for (Python 3.11) wraps a coroutine in a task of its
        # own and hands its result back through a waiter future, three turns of the loop per wait
        async with asyncio.timeout(timeout):
            return await aw


#: the default of every part that is not handed a clock
SYSTEM_CLOCK = SystemClock()


class ManualClock:
    """A clock that moves only when told: :meth:`advance` (from any thread) wakes the sleepers and
    times out the waits whose time has come. A test advances it, then lets the loop run
    (``await asyncio.sleep(0)``) so the woken tasks take their step."""

    def __init__(self, start: float = 1000.0, epoch_ms: int = 1_700_000_000_000) -> None:
        self.now = start
        self._epoch_ms = epoch_ms - int(start * 1000)
        self._lock = threading.Lock()
        self._order = itertools.count()  # ties in the heap: first come, first woken
        self._sleepers: list[tuple[float, int, asyncio.Future[None]]] = []

    def monotonic(self) -> float:
        return self.now

    def time_ms(self) -> int:
        return self._epoch_ms + int(self.now * 1000)

    @property
    def sleepers(self) -> int:
        """Timers waiting on this clock (tests wait for a task to reach its sleep with it)."""
        with self._lock:
            return sum(1 for _, _, fut in self._sleepers if not fut.done())

    def advance(self, seconds: float) -> None:
        with self._lock:
            self.now += seconds
            due: list[asyncio.Future[None]] = []
            while self._sleepers and self._sleepers[0][0] <= self.now:
                due.append(heapq.heappop(self._sleepers)[2])
        for fut in due:
            _wake(fut)

    def _timer(self, seconds: float) -> asyncio.Future[None]:
        """A future done once the clock has moved ``seconds`` from now (registered at once: a wait's
        time runs from the call, not from when a task first runs)."""
        fut: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        with self._lock:
            if seconds <= 0:
                fut.set_result(None)
            else:
                heapq.heappush(self._sleepers, (self.now + seconds, next(self._order), fut))
        return fut

    async def sleep(self, seconds: float) -> None:
        timer = self._timer(seconds)
        try:
            await timer
        finally:
            timer.cancel()  # a cancelled sleeper leaves no live timer behind

    async def wait_for(self, aw: Awaitable[T], timeout: float) -> T:
        task = asyncio.ensure_future(aw)
        timer = self._timer(timeout)
        try:
            both: set[asyncio.Future[Any]] = {task, timer}
            await asyncio.wait(both, return_when=asyncio.FIRST_COMPLETED)
        finally:
            timer.cancel()
            if not task.done():
                task.cancel()
        if task.done() and not task.cancelled():
            return task.result()
        with contextlib.suppress(asyncio.CancelledError):
            await task  # let the cancelled awaitable run its clean-up, as asyncio.wait_for does
        raise TimeoutError


def _wake(fut: asyncio.Future[None]) -> None:
    loop = fut.get_loop()
    try:
        running = asyncio.get_running_loop()
    except RuntimeError:
        running = None
    if running is loop:
        if not fut.done():
            fut.set_result(None)
    elif not loop.is_closed():
        loop.call_soon_threadsafe(lambda: None if fut.done() else fut.set_result(None))
