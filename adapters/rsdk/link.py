"""The CAN link of one gimbal: binds the R SDK codec to a python-can bus, thinly.

Owns the ``can.Bus`` (any interface python-can opens: socketcan, slcan, pcan, virtual …), its
notifier thread and a sender thread. Received CAN frames on the gimbal's id are handed to the
asyncio loop with ``call_soon_threadsafe``; sends go through a queue so a slow or stuck adapter
never blocks the loop. python-can exceptions become :class:`LinkError`, and a bus that fails
(unplugged adapter, closed pty, refused socket) is reported once through ``on_down``.

``observer`` (None by default) sees every CAN frame this link receives on the gimbal's id and every one
it puts on the bus, as ``observer("rx" | "tx", arb_id, data)`` from the notifier or sender thread: a
frame tap (the web console's frame inspector) that must be thread-safe, bounded and quick, and whose
failure never touches the link.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import queue
import threading
from collections.abc import Callable
from typing import Any

import can

log = logging.getLogger(__name__)

__all__ = ["CanLink", "LinkError"]


class LinkError(Exception):
    """The CAN link could not be opened or failed while in use."""


class _Listener(can.Listener):
    def __init__(self, link: CanLink) -> None:
        self._link = link

    def on_message_received(self, msg: can.Message) -> None:
        if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id:
            return
        if msg.arbitration_id != self._link.rx_id:
            return
        self._link.frames_in += 1
        self._link._observe("rx", msg.arbitration_id, msg.data)
        self._link._from_thread(self._link.on_frame, msg.arbitration_id, bytes(msg.data))

    def on_error(self, exc: Exception) -> None:
        self._link._from_thread(self._link._failed, f"receive failed: {type(exc).__name__}: {exc}")


class _Sent:
    """A marker queued after a command's CAN frames: the sender calls ``done`` in the loop once they
    are on the bus (commands that get no reply frame are complete then)."""

    __slots__ = ("done",)

    def __init__(self, done: Callable[[], None]) -> None:
        self.done = done


class CanLink:
    def __init__(
        self,
        *,
        interface: str,
        channel: str,
        bitrate: int,
        rx_id: int,
        loop: asyncio.AbstractEventLoop,
        on_frame: Callable[[int, bytes], None],
        on_down: Callable[[str], None],
        bus_options: dict[str, Any] | None = None,
    ) -> None:
        self.interface, self.channel, self.bitrate, self.rx_id = interface, channel, bitrate, rx_id
        self.on_frame = on_frame
        self.on_down = on_down
        self._options = dict(bus_options or {})
        self._loop = loop
        self._bus: can.BusABC | None = None
        self._notifier: can.Notifier | None = None
        self._sendq: queue.SimpleQueue[can.Message | _Sent | None] = queue.SimpleQueue()
        self._sender: threading.Thread | None = None
        self._up = False
        self.frames_in = 0  # CAN frames on rx_id
        self.frames_out = 0
        self.send_errors = 0
        self.opens = 0  # successful opens (the first one and every reopen), for the reconnect metric
        #: frame tap: ``observer(direction, arb_id, data)`` from the link's threads (see the module doc)
        self.observer: Callable[[str, int | None, bytes], None] | None = None

    #: what the link statistics call it (adapters.supervision.SupervisedLink); a CAN link counts no bytes
    kind = "can"
    bytes_in: int | None = None
    bytes_out: int | None = None

    @property
    def where(self) -> str:
        return self.channel

    @property
    def up(self) -> bool:
        return self._up

    def _observe(self, direction: str, arb_id: int, data: bytes | bytearray) -> None:
        observer = self.observer
        if observer is not None:
            with contextlib.suppress(Exception):  # a tap must never take the link down
                observer(direction, arb_id, bytes(data))

    async def open(self) -> None:
        """Open the bus (in a worker thread: some interfaces block while they open)."""
        if self._up:
            return
        try:
            bus = await asyncio.to_thread(self._make_bus)
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            raise LinkError(f"cannot open {self.interface} {self.channel}: {exc}") from None
        self._bus = bus
        self._notifier = can.Notifier(bus, [_Listener(self)], timeout=0.05)
        self._sendq = queue.SimpleQueue()
        self._sender = threading.Thread(target=self._send_loop, args=(bus, self._sendq), daemon=True)
        self._sender.start()
        self._up = True
        self.opens += 1
        log.info("CAN link open: %s %s", self.interface, self.channel)

    def _make_bus(self) -> can.BusABC:
        kwargs: dict[str, Any] = {"interface": self.interface, "channel": self.channel, **self._options}
        if self.interface != "virtual":
            kwargs.setdefault("bitrate", self.bitrate)
        kwargs.setdefault("receive_own_messages", False)
        return can.Bus(**kwargs)

    def send(self, frames: list[tuple[int, bytes]], on_sent: Callable[[], None] | None = None) -> None:
        """Queue CAN frames in order; raises LinkError when the link is down. ``on_sent`` runs in the
        loop once the last of them is on the bus (never, if the bus fails first)."""
        if not self._up:
            raise LinkError("CAN link is down")
        for arb_id, data in frames:
            self._sendq.put(can.Message(arbitration_id=arb_id, data=data, is_extended_id=False))
        if on_sent is not None:
            self._sendq.put(_Sent(on_sent))

    def close(self) -> None:
        self._up = False
        if self._notifier is not None:
            with contextlib.suppress(Exception):
                self._notifier.stop(timeout=1.0)
            self._notifier = None
        self._sendq.put(None)
        if self._sender is not None:
            self._sender.join(timeout=2.0)
            self._sender = None
        if self._bus is not None:
            with contextlib.suppress(Exception):
                self._bus.shutdown()
            # python-can's slcan shutdown writes "C" first and, on a dead port, raises before it closes
            # the port: close the serial/socket underneath ourselves so it does not leak
            port = getattr(self._bus, "serialPortOrig", None)
            if port is not None:
                with contextlib.suppress(Exception):
                    port.close()
            self._bus = None

    # -- threads ----------------------------------------------------------------------------------
    def _send_loop(self, bus: can.BusABC, q: queue.SimpleQueue[can.Message | _Sent | None]) -> None:
        while True:
            msg = q.get()
            if msg is None:
                return
            if isinstance(msg, _Sent):
                self._from_thread(msg.done)
                continue
            try:
                bus.send(msg, timeout=0.2)
                self.frames_out += 1
                self._observe("tx", msg.arbitration_id, msg.data)
            except (can.CanError, OSError, ValueError) as exc:
                self.send_errors += 1
                self._from_thread(self._failed, f"send failed: {type(exc).__name__}: {exc}")
                return

    def _from_thread(self, fn: Callable[..., None], *args: Any) -> None:
        with contextlib.suppress(RuntimeError):  # loop closed during shutdown
            self._loop.call_soon_threadsafe(fn, *args)

    def _failed(self, reason: str) -> None:
        if not self._up:
            return
        log.warning("CAN link %s %s failed: %s", self.interface, self.channel, reason)
        self.close()
        self.on_down(reason)
