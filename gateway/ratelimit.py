"""A token bucket: the one rate limit the gateway applies to a flood it cannot refuse at the broker.

Clock-free (the caller passes ``now``) so tests drive it with a fake clock and the DRC network
thread pays one subtraction and one comparison per message.
"""

from __future__ import annotations

__all__ = ["TokenBucket"]


class TokenBucket:
    """At most ``rate`` events per second on average and ``burst`` at once."""

    __slots__ = ("_last", "_tokens", "burst", "rate")

    def __init__(self, rate: float, burst: float, now: float) -> None:
        if rate <= 0 or burst < 1:
            raise ValueError("a token bucket needs rate > 0 and burst >= 1")
        self.rate, self.burst = rate, burst
        self._tokens, self._last = burst, now

    def take(self, now: float) -> bool:
        """Spend one token if there is one; False means: over the rate, drop this event."""
        elapsed = now - self._last
        if elapsed > 0:
            self._tokens = min(self.burst, self._tokens + elapsed * self.rate)
            self._last = now
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return True
        return False
