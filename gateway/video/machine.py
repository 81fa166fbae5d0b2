"""The life of one live video: start, first frame, failure, restart with backoff, reconfigure, stop.

Owns the decisions about one ``video_id``'s stream, sans-I/O: events come in as method calls carrying the
time (``now``, from the injected clock), decisions come out as actions (:class:`Spawn`, :class:`Kill`) the
transport (:mod:`gateway.video.service`) carries out, and the ``live_status`` entry is derived from the
machine's snapshot. Knows nothing about processes, ffmpeg, MQTT or the event loop.

Theory of operation::

                start ─▶ STARTING ──first frames──▶ LIVE
                            ▲  │                     │
             backoff over ──┘  └── exited/stalled ───┴──▶ RETRYING (error_status = 399015)
                  (tick)                                     │
     stop / device offline from any phase ──▶ STOPPING (Kill) ──exited──▶ IDLE

- Each process the machine asks for has a *generation*; an event about an older generation is ignored, so a
  late exit of a killed pipeline cannot fail its successor.
- A start that never produced a frame and whose process exited is a *start failure*: when ``fail_fast`` is
  set (the caller is still waiting to answer ``live_start_push``), the machine goes IDLE and reports it, so
  the cloud hears the failure in the reply instead of a retry loop it never asked for. Once a stream has
  been live, a failure is retried for ever, with a backoff of ``initial``·2ⁿ capped at ``maximum``; the
  backoff resets when a stream has stayed live for ``stable_after`` seconds.
- A stall (no new frame for ``stall_timeout`` while LIVE, or no first frame for ``start_timeout`` after a
  process starts) is a failure too: the machine kills the process and the exit that follows schedules the
  retry.
- ``reconfigure`` (quality, lens) replaces a running pipeline at once: kill the old generation, spawn the
  new one; the stream is not reported as failed.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, replace

__all__ = ["Backoff", "Kill", "Phase", "Spawn", "StreamMachine", "Target"]

#: ``live_status.error_status`` while a stream is failing (schemas.results.ResultCode.LIVE_START_FAILED).
FAILED = 399015


class Phase(enum.StrEnum):
    IDLE = "idle"
    STARTING = "starting"
    LIVE = "live"
    RETRYING = "retrying"
    STOPPING = "stopping"


@dataclass(frozen=True, slots=True)
class Target:
    """What the cloud asked for: where to (``url_type``, ``url``), how good, which lens."""

    url_type: int
    url: str
    quality: int
    lens: str


@dataclass(frozen=True, slots=True)
class Spawn:
    generation: int
    target: Target


@dataclass(frozen=True, slots=True)
class Kill:
    generation: int


Action = Spawn | Kill


@dataclass(frozen=True, slots=True)
class Backoff:
    initial: float = 0.5
    maximum: float = 10.0
    stable_after: float = 10.0

    def delay(self, failures: int) -> float:
        """The wait before retry number ``failures`` (1-based)."""
        return float(min(self.maximum, self.initial * 2 ** max(0, failures - 1)))


class StreamMachine:
    def __init__(
        self,
        video_id: str,
        *,
        backoff: Backoff,
        stall_timeout: float = 5.0,
        start_timeout: float | None = None,
    ) -> None:
        self.video_id = video_id
        self.backoff = backoff
        self.stall_timeout = stall_timeout
        #: how long a process may take to its first frame (None: ``stall_timeout``): a WHIP publisher
        #: starts Python and aiortc, POSTs its offer and connects ICE and DTLS before its first frame
        self.start_timeout = stall_timeout if start_timeout is None else max(start_timeout, stall_timeout)
        self.phase = Phase.IDLE
        self.target: Target | None = None
        self.generation = 0
        self.running: int | None = None  # the generation whose process is alive (None: none)
        self.error = 0  # live_status.error_status
        self.failures = 0  # consecutive failures (the backoff's exponent)
        self.restarts = 0  # every retry spawned (metrics, tests)
        self.retry_at: float | None = None
        self.live_since: float | None = None
        self.first_frame_at: float | None = None
        self.frames = 0  # frames of the running generation
        self.last_frame_at: float | None = None
        self.last_reason = ""
        self.fail_fast = False

    # -- snapshot ---------------------------------------------------------------------------------
    @property
    def active(self) -> bool:
        """The cloud wants this video streaming (not IDLE, not STOPPING)."""
        return self.phase in (Phase.STARTING, Phase.LIVE, Phase.RETRYING)

    def status(self) -> tuple[int, int]:
        """``(status, error_status)`` of the ``live_status`` entry: 1 only while frames flow."""
        return (1 if self.phase is Phase.LIVE else 0), self.error

    # -- commands ---------------------------------------------------------------------------------
    def start(self, target: Target, now: float, *, fail_fast: bool = True) -> list[Action]:
        """A ``live_start_push`` the service accepted (it checked the phase first)."""
        actions: list[Action] = []
        if self.running is not None:  # a stop still under way: that process goes, a new one comes
            actions.append(Kill(self.running))
            self.running = None
        self.target = target
        self.failures = 0
        self.error = 0
        self.fail_fast = fail_fast
        self.first_frame_at = None
        return [*actions, self._spawn(now)]

    def reconfigure(self, now: float, *, quality: int | None = None, lens: str | None = None) -> list[Action]:
        """New quality or lens for an active stream: the pipeline is replaced at once."""
        assert self.target is not None
        if quality is not None:
            self.target = replace(self.target, quality=quality)
        if lens is not None:
            self.target = replace(self.target, lens=lens)
        actions: list[Action] = []
        if self.running is not None:
            actions.append(Kill(self.running))
            self.running = None
        if self.phase is Phase.RETRYING:  # waiting out a backoff: the next try uses the new settings
            return actions
        return [*actions, self._spawn(now)]

    def stop(self, now: float, reason: str = "stopped") -> list[Action]:
        """``live_stop_push``, the device went offline, or shutdown. Never an error when idle."""
        self.target = None
        self.retry_at = None
        self.error = 0
        self.live_since = None
        self.last_reason = reason
        if self.running is not None:
            self.phase = Phase.STOPPING
            return [Kill(self.running)]
        self.phase = Phase.IDLE
        return []

    # -- what the transport reports ---------------------------------------------------------------
    def progress(self, generation: int, frames: int, now: float) -> None:
        """The process of ``generation`` has sent ``frames`` frames so far."""
        if generation != self.running or frames <= self.frames:
            return
        self.frames = frames
        self.last_frame_at = now
        if self.phase is Phase.STARTING:
            self.phase = Phase.LIVE
            self.live_since = now
            self.error = 0
            self.fail_fast = False
            if self.first_frame_at is None:
                self.first_frame_at = now

    def exited(self, generation: int, now: float, reason: str) -> list[Action]:
        """The process of ``generation`` ended (by itself, or after a Kill)."""
        if generation != self.running:
            return []
        self.running = None
        stalled = self._stall_killed == generation
        self.last_reason = f"{self.last_reason} ({reason})" if stalled else reason
        if self.phase is Phase.STOPPING:
            self.phase = Phase.IDLE
            return []
        if self.phase not in (Phase.STARTING, Phase.LIVE):
            return []
        if (
            self.phase is Phase.LIVE
            and self.live_since is not None
            and now - self.live_since >= self.backoff.stable_after
        ):
            self.failures = 0
        self.live_since = None
        self.error = FAILED
        if self.fail_fast and self.phase is Phase.STARTING:
            self.phase = Phase.IDLE  # the start is answered with the failure; nothing retries it
            self.target = None
            return []
        self.failures += 1
        self.phase = Phase.RETRYING
        self.retry_at = now + self.backoff.delay(self.failures)
        return []

    def tick(self, now: float) -> list[Action]:
        """Time passed: retry when the backoff is over; kill a pipeline that stalled."""
        if self.phase is Phase.RETRYING and self.retry_at is not None and now >= self.retry_at:
            self.restarts += 1
            return [self._spawn(now)]
        if self.phase in (Phase.STARTING, Phase.LIVE) and self.running is not None:
            first = self.last_frame_at is None  # this process has sent nothing yet
            since = self._spawned_at if first else self.last_frame_at
            limit = self.start_timeout if first else self.stall_timeout
            assert since is not None
            if now - since >= limit and self._stall_killed != self.running:
                self.last_reason = f"no frame for {limit:g} s" + (" after its start" if first else "")
                # the exit that follows the kill is this generation's failure: it stays "running" until then
                self._stall_killed = self.running
                return [Kill(self.running)]
        return []

    def _spawn(self, now: float) -> Spawn:
        assert self.target is not None
        self.generation += 1
        self.running = self.generation
        self.phase = Phase.STARTING
        self.retry_at = None
        self.frames = 0
        self.last_frame_at = None
        self._spawned_at = now
        return Spawn(self.generation, self.target)

    _spawned_at: float = 0.0
    _stall_killed: int | None = None
