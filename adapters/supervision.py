"""Link supervision shared by the device adapters: keep the link open and the online flag honest.

Every family has one link (a CAN bus, a serial port) that fails and comes back, and a device that
may fall silent while its link stays up. The rules are the same for all of them: reopen a closed
link every ``reopen_interval`` (absent hardware is not an error: said once, then backing off, see
``adapters/absence.py``), call the device offline after
``silence_timeout`` without a valid frame, and report each change of the online flag once through
:meth:`~adapters.base.TelemetrySink.online_changed`. :class:`SupervisedAdapter` owns that loop
and that flag, so they cannot drift apart between families; a family says only what differs
through the hooks (``_on_link_opened``, ``_supervise_tick``, ``_on_went_silent``,
``_on_online_changed``). It also answers, once for every family, what the gateway may read of a
link (:meth:`SupervisedAdapter.link_stats`, :meth:`~SupervisedAdapter.observe_link`,
:attr:`~SupervisedAdapter.last_heard`): a family only says where its stream decoder's counters are
(:meth:`SupervisedAdapter._decoder_stats`). Knows nothing of any wire protocol, codec or Cloud API method.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from typing import Any, ClassVar, Protocol

from adapters.absence import Absence
from adapters.base import Adapter, DeviceInfo, FrameObserver, LinkStats, TelemetrySink
from adapters.clock import Clock
from adapters.errors import LinkError
from adapters.wire.stream import DecoderStats, StreamDecoder

__all__ = ["SupervisedAdapter", "SupervisedLink", "SupervisionTiming"]


class SupervisedLink(Protocol):
    """What supervision needs of a link (``CanLink``, ``SerialLink``), and what its statistics read."""

    observer: FrameObserver | None  # the console's frame tap (None: none)

    @property
    def up(self) -> bool: ...

    async def open(self) -> None: ...

    def close(self) -> None: ...

    @property
    def kind(self) -> str:
        """ "can" or "serial"."""
        ...

    @property
    def where(self) -> str:
        """The CAN channel or the serial URL (neither carries credentials)."""
        ...

    @property
    def opens(self) -> int: ...

    @property
    def frames_in(self) -> int | None:
        """Frames received by the link itself; None: the adapter's stream decoder counts them."""
        ...

    @property
    def frames_out(self) -> int: ...

    @property
    def bytes_in(self) -> int | None:
        """None: the link does not count bytes (CAN)."""
        ...

    @property
    def bytes_out(self) -> int | None: ...

    @property
    def send_errors(self) -> int: ...


class SupervisionTiming(Protocol):
    """The two timing settings every family's device settings carry (seconds)."""

    @property
    def reopen_interval(self) -> float: ...

    @property
    def silence_timeout(self) -> float: ...


class SupervisedAdapter(Adapter):
    """An adapter whose device sits behind one link that fails and comes back.

    A subclass sets :attr:`noun` and :attr:`_log`, builds ``self._link`` in
    ``start()`` (with :meth:`_on_link_down` as its ``on_down``), starts :meth:`_supervise` as a task
    in ``self._tasks``, stamps ``self._last_heard`` and calls ``_set_online(True)`` when a frame
    arrives, and ends with :meth:`_end_supervision` in ``stop()``.
    """

    #: how log lines name the device ("gimbal", "aircraft", "robot")
    noun: ClassVar[str]
    #: the family module's logger, so supervision's log lines keep the family's logger name
    _log: ClassVar[logging.Logger]

    _link: SupervisedLink | None
    #: the stream decoder the link's bytes go through (its counters feed :meth:`link_stats`); a family
    #: that keeps it elsewhere (rsdk: in its CAN reassembler) overrides :meth:`_decoder_stats` instead
    _decoder: StreamDecoder[Any]
    #: replies or ACKs that matched no request in flight (late, duplicated, wrong seq); families count them
    unmatched_replies: int = 0

    def __init__(self, info: DeviceInfo, timing: SupervisionTiming, clock: Clock) -> None:
        self.info = info
        self._timing = timing
        #: the gateway's clock: every deadline, interval and sleep of the adapter runs on it
        self._clock = clock
        self._now = clock.monotonic
        self._link = None
        self._sink: TelemetrySink | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._online = False
        self._stopping = False
        self._last_heard = float("-inf")  # when the device last sent a valid frame (``now`` clock)
        self._absence = Absence(timing.reopen_interval)

    @property
    def online(self) -> bool:
        return self._online

    # -- the loop ---------------------------------------------------------------------------------
    async def _supervise(self) -> None:
        """Keep the link open (a failed open is retried every ``reopen_interval``, the device
        offline meanwhile) and, every 0.1 s while it is up, run :meth:`_supervise_tick`."""
        while not self._stopping:
            link = self._link
            assert link is not None
            if not link.up:
                what = f"{self.noun} {self.info.sn}"
                try:
                    await link.open()
                except LinkError as exc:
                    # absent hardware: said once with a hint, then quiet and backing off (adapters/absence.py)
                    decision = self._absence.failed(self._now(), str(exc), what)
                    self._log.log(decision.level, "%s", decision.message)
                    self._set_online(False)
                    await self._clock.sleep(decision.delay)
                    continue
                if (back := self._absence.opened(self._now(), what)) is not None:
                    self._log.info("%s", back)
                self._on_link_opened()
            await self._supervise_tick(self._now())
            await self._clock.sleep(0.1)

    async def _supervise_tick(self, now: float) -> None:
        """One pass of the loop with the link up. A family that does more on each pass overrides
        this and calls :meth:`_check_silence` where its order of effects wants it."""
        self._check_silence(now)

    def _check_silence(self, now: float) -> None:
        """Offline once the device has said nothing for ``silence_timeout``: the link can stay up
        while the device behind it has restarted, lost power or stopped its feed."""
        silent = now - self._last_heard
        if self._online and silent > self._timing.silence_timeout:
            self._log.warning("%s %s silent for %.1fs: offline", self.noun, self.info.sn, silent)
            self._set_online(False)
            self._on_went_silent(now)

    def _on_link_down(self, reason: str) -> None:
        """The link's ``on_down``: offline at once; the loop reopens it. Subclasses extend it
        (calling this first) to fail what waited on the link."""
        self._set_online(False)

    def _set_online(self, online: bool) -> None:
        """Change the flag and tell the sink, once per change (after :meth:`_on_online_changed`)."""
        if online == self._online:
            return
        self._online = online
        self._on_online_changed(online)
        if self._sink is not None:
            self._sink.online_changed(self.info.sn, online)

    # -- what the gateway reads (adapters.base.Adapter's contract) ---------------------------------
    def link_stats(self) -> LinkStats | None:
        """The link's counters and the stream decoder's (frames in on a serial link, CRC and framing
        errors); None before ``start()`` built the link. Counters restart when a family replaces its
        decoder on a reopen; the exporter keeps what it exports monotonic."""
        link = self._link
        if link is None:
            return None
        stats = self._decoder_stats()
        bad = stats.bad_frames if stats is not None else 0
        crc = stats.crc_errors if stats is not None else 0
        frames_in = link.frames_in
        if frames_in is None:
            frames_in = stats.frames if stats is not None else 0
        return LinkStats(
            kind=link.kind,
            where=link.where,
            up=link.up,
            opens=link.opens,
            frames_in=frames_in,
            frames_out=link.frames_out,
            bytes_in=link.bytes_in,
            bytes_out=link.bytes_out,
            crc_errors=crc,
            framing_errors=max(0, bad - crc),
            send_errors=link.send_errors,
            unmatched_replies=self.unmatched_replies,
        )

    def observe_link(self, observer: FrameObserver) -> bool:
        link = self._link
        if link is None or link.observer is not None:
            return False
        link.observer = observer
        return True

    @property
    def last_heard(self) -> float | None:
        heard = self._last_heard
        return None if heard == float("-inf") else heard

    def _decoder_stats(self) -> DecoderStats | None:
        """The counters of the stream decoder the link's bytes go through: ``self._decoder``'s by default;
        a family that keeps its decoder elsewhere overrides this."""
        decoder: StreamDecoder[Any] | None = getattr(self, "_decoder", None)  # set by the family's __init__
        return decoder.stats if decoder is not None else None

    # -- hooks ------------------------------------------------------------------------------------
    def _on_link_opened(self) -> None:
        """The link has just (re)opened: drop what a decoder half-read from the old one."""

    def _on_went_silent(self, now: float) -> None:
        """The device has just been marked offline for silence (after the sink heard of it)."""

    def _on_online_changed(self, online: bool) -> None:
        """The flag has just changed; runs before the sink is told, so a device going offline is
        stopped before the cloud hears of it."""

    # -- shutdown ---------------------------------------------------------------------------------
    async def _end_supervision(self, *others: asyncio.Task[None] | None) -> None:
        """Cancel the adapter's tasks and ``others`` (motion loops, cancelled but not awaited),
        then close the link once its sender thread has had a moment to put the last frames (the
        stop the caller just queued) on the wire."""
        for task in [*self._tasks, *others]:
            if task is not None:
                task.cancel()
        for task in self._tasks:
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await task
        await asyncio.sleep(0.05)  # real time, not the clock's: a link's writer thread keeps real time
        if self._link is not None:
            self._link.close()
