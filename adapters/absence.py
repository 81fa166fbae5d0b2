"""What to say, and how long to wait, about a device link that cannot open: absent hardware is normal
(a gimbal not plugged in yet, a flight controller powered off), so it must not fill the log.

Owns one link's absence as a small sans-I/O state machine (time in, decisions out): the first failure,
and each *different* error after it, is one WARNING with a hint (the dialout group, ``/dev/serial/by-id``,
``ip link set can0 up type can bitrate 1000000``); repeats of the same error are DEBUG, with a reminder
at INFO after 1 min, then 2, 4 … up to every hour; the link opening again is one INFO line saying how
long it was absent. The retry interval is the family's ``reopen_interval`` for the first
:data:`BACKOFF_AFTER` seconds, then doubles up to :data:`MAX_RETRY` (or ``reopen_interval`` when that is
longer). Error texts are made concise (pyserial repeats the port path three times). Knows nothing of
asyncio, links or devices; :class:`~adapters.supervision.SupervisedAdapter` logs what it decides.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass

__all__ = ["BACKOFF_AFTER", "MAX_RETRY", "Absence", "Decision", "concise", "hint_for"]

BACKOFF_AFTER = 30.0  # seconds of failures at the configured interval before backing off
MAX_RETRY = 10.0  # the longest wait between two opens (unless reopen_interval is longer)
FIRST_REMINDER = 60.0
MAX_REMINDER = 3600.0


@dataclass(frozen=True, slots=True)
class Decision:
    level: int  # logging level of the line (DEBUG for a repeat)
    message: str
    delay: float  # seconds until the next open


def concise(error: str) -> str:
    """``cannot open /dev/x: [Errno 2] could not open port /dev/x: [Errno 2] No such file or directory:
    '/dev/x'`` → ``cannot open /dev/x: No such file or directory``."""
    text = re.sub(r"\[Errno \d+\]\s*", "", error)
    text = re.sub(r"could not open port \S+: ", "", text)
    return re.sub(r": '[^']*'$", "", text).strip()


def hint_for(error: str) -> str:
    """The likeliest fix for an open error, in a few words (docs/serial.md has the whole guide)."""
    low = error.lower()
    if "permission denied" in low:
        return "add the gateway's user to the dialout group (sudo usermod -aG dialout USER) and log in again"
    if "address family not supported" in low:
        return "this kernel has no SocketCAN (a container needs network_mode: host for can0)"
    if "socketcan" in low or "network is down" in low or "no such device" in low:
        return "bring the CAN interface up: sudo ip link set can0 up type can bitrate 1000000"
    if "no such file" in low or "could not open" in low:
        return (
            "is it plugged in? ls -l /dev/serial/by-id; python -m serial.tools.list_ports -v (docs/serial.md)"
        )
    if "busy" in low or "resource temporarily unavailable" in low or "in use by another process" in low:
        return "another program holds the port (ModemManager? see docs/serial.md)"
    return "see docs/serial.md"


class Absence:
    """One link's absence. ``failed`` after each open that failed, ``opened`` after one that worked."""

    def __init__(self, reopen_interval: float) -> None:
        self.interval = reopen_interval
        self.since: float | None = None  # when the link was first found absent (None: it is open)
        self.attempts = 0
        self._error = ""
        self._delay = reopen_interval
        self._remind_at = 0.0
        self._remind_every = FIRST_REMINDER

    def failed(self, now: float, error: str, what: str) -> Decision:
        text = concise(error)
        if self.since is None:
            self.since = now
        self.attempts += 1
        absent = now - self.since
        if absent >= BACKOFF_AFTER:
            self._delay = min(max(self.interval, MAX_RETRY), self._delay * 2)
        if text != self._error:
            self._error = text
            self._remind_at, self._remind_every = now + FIRST_REMINDER, FIRST_REMINDER
            message = (
                f"{what}: {text}; retrying every {self.interval:g}s, backing off to "
                f"{max(self.interval, MAX_RETRY):g}s after {BACKOFF_AFTER:g}s (hint: {hint_for(text)})"
            )
            return Decision(logging.WARNING, message, self._delay)
        if now >= self._remind_at:
            self._remind_every = min(MAX_REMINDER, self._remind_every * 2)
            self._remind_at = now + self._remind_every
            message = (
                f"{what}: still {text} ({absent:.0f}s, {self.attempts} attempts; next in {self._delay:g}s)"
            )
            return Decision(logging.INFO, message, self._delay)
        return Decision(logging.DEBUG, f"{what}: {text}", self._delay)

    def opened(self, now: float, what: str) -> str | None:
        """The line for a link that opened (None the first time: nothing was missing)."""
        if self.since is None:
            return None
        message = f"{what}: link open after {now - self.since:.0f}s absent ({self.attempts} attempts)"
        self.since, self.attempts, self._error, self._delay = None, 0, "", self.interval
        return message
