"""Time as a value: the dispatcher, live control and the northbound ask the :class:`Clock` that
``GatewayApp(clock=)`` is given, so tests can drive them.

``monotonic()`` for deadlines and intervals; ``time_ms()`` for the Cloud API's wall-clock
``timestamp`` fields. Not yet everything: the adapters, the broker connection and the web console take a
``now`` callable of their own (``time.monotonic`` by default), and the operator CLIs (``monitor``,
``fly``) read the system clock; one clock passed from ``GatewayApp`` down is open work (issue #18).
"""

from __future__ import annotations

import time
from typing import Protocol

__all__ = ["Clock", "ManualClock", "SystemClock"]


class Clock(Protocol):
    def monotonic(self) -> float: ...

    def time_ms(self) -> int: ...


class SystemClock:
    def monotonic(self) -> float:
        return time.monotonic()

    def time_ms(self) -> int:
        return time.time_ns() // 1_000_000


class ManualClock:
    """A clock that moves only when told (unit tests of timing logic)."""

    def __init__(self, start: float = 1000.0, epoch_ms: int = 1_700_000_000_000) -> None:
        self.now = start
        self._epoch_ms = epoch_ms - int(start * 1000)

    def monotonic(self) -> float:
        return self.now

    def time_ms(self) -> int:
        return self._epoch_ms + int(self.now * 1000)

    def advance(self, seconds: float) -> None:
        self.now += seconds
