"""The CAN link of one gimbal: binds the R SDK codec to a python-can bus, thinly.

Owns the ``can.Bus`` (any interface python-can opens: socketcan, slcan, pcan, virtual …), its reader and,
where a send may block, a sender thread. How frames come in depends on the interface (:data:`LOOP_READ`):
where the bus has a file descriptor the loop can watch, the loop reads it itself (``add_reader``, then
``bus.recv(0)`` until empty: no thread hand-off); everywhere else python-can's notifier thread reads and
hands frames to the loop with ``call_soon_threadsafe``. How frames go out depends on the interface
(:data:`NONBLOCKING_SEND`): where ``bus.send`` cannot block (python-can's ``virtual`` bus), the caller's
thread (the loop, the motion writer) puts them on the bus itself, under a lock that keeps one command's
frames together: no thread hand-off on the way to the device. Everywhere else they go through a queue to
the sender thread, so a slow or stuck adapter never blocks the loop. python-can exceptions become
:class:`LinkError`, and a bus that fails (unplugged adapter, closed pty, refused socket) is reported once
through ``on_down``.

``observer`` (None by default) sees every CAN frame this link receives on the gimbal's id and every one
it puts on the bus, as ``observer("rx" | "tx", arb_id, data)`` from the notifier thread, the sender
thread or the sending caller's thread: a frame tap (the web console's frame inspector) that must be
thread-safe, bounded and quick, and whose failure never touches the link.

python-can's ``virtual`` bus (the simulators' and the tests'): its fast paths (:func:`virtual_reader`,
:func:`virtual_sender`) rely on how ``can.interfaces.virtual`` lays a bus out, which python-can does not
document: the attributes ``queue``, ``channel`` (the channel's list of queues), ``channel_id``,
``receive_own_messages``, ``preserve_timestamps`` and the module's ``channels_lock``; no underscore
member. Each use checks that layout first and falls back to python-can's own ``send``/notifier when it
differs. It was read in python-can 4.3-4.6 (:data:`VIRTUAL_LAYOUT_CHECKED`; ``pyproject.toml`` pins ``<5``),
and ``tests/test_library_internals.py`` fails when the installed python-can no longer has it, so the
fast path never silently turns off.

Why this module is longer than 500 lines: besides the thin link, it holds the python-can virtual-bus fast
paths (signalled queue, batch sender) that issue #18 measured; they are about how this link reads and writes
the bus and nothing else uses them.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import can

from adapters.errors import LinkError

log = logging.getLogger(__name__)

__all__ = ["NONBLOCKING_SEND", "CanLink", "virtual_batch_sender", "virtual_reader", "virtual_sender"]

#: Interfaces whose ``bus.send(msg, timeout=0)`` returns at once, so frames go on the bus from the
#: sender's own thread with no hand-off. python-can's ``virtual`` bus puts a copy of each frame into every
#: receiver's queue (unbounded unless a receiver was opened with ``rx_queue_size``; a full one fails the
#: send at once with ``timeout=0``, as a full transmit queue fails the link today). Not listed, and so
#: sent by the sender thread: socketcan (a full socket buffer blocks), slcan and serial adapters (a write
#: to a stalled port blocks), vendor drivers (pcan, kvaser …: their calls may wait on the hardware).
NONBLOCKING_SEND = frozenset({"virtual"})


@dataclass(frozen=True, slots=True)
class _LoopReader:
    """A descriptor the loop watches for a bus: ``clear()`` before reading (a signal pipe's bytes),
    ``take()`` for the next frame waiting (None: none; ``bus.recv(0)`` unless the bus's own queue can
    be read directly), ``close()`` when the link closes."""

    fd: int
    clear: Callable[[], None] = lambda: None
    close: Callable[[], None] = lambda: None
    take: Callable[[], can.Message | None] | None = None


#: python-can releases whose ``virtual`` bus layout the fast paths were read against (see the docstring)
VIRTUAL_LAYOUT_CHECKED = ("4.3", "4.4", "4.5", "4.6")
#: the ``VirtualBus`` attributes they read
VIRTUAL_BUS_ATTRIBUTES = ("channel", "queue", "channel_id", "receive_own_messages", "preserve_timestamps")

#: frames the loop takes per wake-up before it lets other callbacks run (then it comes back at once)
READ_BATCH = 256


def _own_fileno(bus: can.BusABC) -> _LoopReader | None:
    """The bus's own descriptor (socketcan: its raw CAN socket; python-can's ``Notifier(loop=)`` watches
    the same one)."""
    return _LoopReader(bus.fileno())


class _SignalledQueue(queue.Queue[Any]):
    """A virtual bus's receive queue that also writes a byte to a pipe (from the sending thread) when a
    frame arrives and none is signalled yet, so a reader can watch the pipe as it watches a socket: a
    command's reply frames put back to back cost one write and one wake-up, not one each. The reader
    empties the pipe, then calls :meth:`rearm`, then reads the queue: a frame put after that signals again.

    Its reader takes frames without blocking (:meth:`take`) and waits on the pipe, never on the queue's
    condition variables; so an unbounded queue (python-can's default) puts and takes on its deque alone
    (``deque.append``/``popleft`` are atomic), without ``queue.Queue``'s two locks and a notify per frame.
    A blocking ``get`` (python-can's ``recv`` with a timeout, which the readers here never call) still
    works: it polls. A bounded queue (``rx_queue_size``) keeps ``queue.Queue``'s own behaviour."""

    def __init__(self, wfd: int, maxsize: int = 0) -> None:
        super().__init__(maxsize)
        self._wfd = wfd
        self._signalled = False
        self._fast = maxsize <= 0

    def put(self, item: Any, block: bool = True, timeout: float | None = None) -> None:
        self.put_quiet(item, block, timeout)
        self.signal()

    def put_quiet(self, item: Any, block: bool = False, timeout: float | None = None) -> None:
        """Put without signalling (the sender of a batch calls :meth:`signal` once after it)."""
        if self._fast:
            self.queue.append(item)
        else:
            super().put(item, block, timeout)

    def signal(self) -> None:
        if not self._signalled:
            self._signalled = True
            try:  # noqa: SIM105 (per frame: contextlib.suppress builds an object per call)
                os.write(self._wfd, b"\0")
            except OSError:  # (a full pipe: the reader is due to read anyway; a closed one: no link)
                pass

    def get(self, block: bool = True, timeout: float | None = None) -> Any:
        if not self._fast:
            return super().get(block, timeout)
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            try:
                return self.queue.popleft()
            except IndexError:
                if not block or (deadline is not None and time.monotonic() >= deadline):
                    raise queue.Empty from None
                time.sleep(0.0005)

    def qsize(self) -> int:
        return len(self.queue) if self._fast else super().qsize()

    def empty(self) -> bool:
        return self.qsize() == 0

    def rearm(self) -> None:
        self._signalled = False

    def take(self) -> can.Message | None:
        if self._fast:
            try:
                msg: can.Message = self.queue.popleft()
            except IndexError:
                return None
            return msg
        try:
            msg = self.get_nowait()
        except queue.Empty:
            return None
        return msg


def _virtual_fileno(bus: can.BusABC) -> _LoopReader | None:
    """python-can's ``virtual`` bus has no descriptor: its frames arrive in a ``queue.Queue`` that every
    sender on the channel puts into (``bus.queue``, listed in ``bus.channel``). Swap it, under the
    module's ``channels_lock``, for a :class:`_SignalledQueue` tied to a pipe; the loop watches the pipe.
    None (the notifier thread reads instead) when a python-can version lays the bus out differently."""
    from can.interfaces import virtual

    old, channel = getattr(bus, "queue", None), getattr(bus, "channel", None)
    lock = getattr(virtual, "channels_lock", None)
    if not isinstance(old, queue.Queue) or not isinstance(channel, list) or lock is None:
        return None
    rfd, wfd = os.pipe()
    os.set_blocking(rfd, False)
    os.set_blocking(wfd, False)
    new = _SignalledQueue(wfd, old.maxsize)
    with lock:
        index = next((i for i, q in enumerate(channel) if q is old), None)
        if index is None:
            os.close(rfd)
            os.close(wfd)
            return None
        channel[index] = new
        bus.queue = new  # type: ignore[attr-defined]  # python-can's VirtualBus attribute
    while True:  # frames that arrived before the swap
        try:
            new.put_nowait(old.get_nowait())
        except queue.Empty:
            break

    def clear() -> None:
        # the pipe emptied first, then re-armed: a frame put after the re-arm writes a byte that stays
        # in the pipe (the loop comes back); one put before it is in the queue the loop reads next
        with contextlib.suppress(BlockingIOError, OSError):
            os.read(rfd, 4096)
        new.rearm()

    def close() -> None:
        for fd in (rfd, wfd):
            with contextlib.suppress(OSError):
                os.close(fd)

    # python-can's recv() adds nothing here but its software filters: read the queue itself without them
    return _LoopReader(rfd, clear, close, take=new.take if bus.filters is None else None)


def virtual_reader(bus: can.BusABC) -> _LoopReader | None:
    """What a reader of python-can's ``virtual`` bus outside the loop watches (the simulated gimbal's
    thread): the bus's queue swapped for a signalled one (see :func:`_virtual_fileno`), so the thread
    waits on a pipe with ``select`` and takes its frames without ``queue.Queue``'s locks. Its ``take`` is
    None when the bus has software filters (then ``bus.recv`` it is). ``close()`` the reader only after
    ``bus.shutdown()``: a sender must not write to a descriptor number that was closed and reused."""
    return _virtual_fileno(bus)


def virtual_sender(bus: can.BusABC) -> Callable[[can.Message], None] | None:
    """A send for python-can's ``virtual`` bus that hands the frame itself to the receiver instead of a
    deep copy: what ``VirtualBus.send(msg, timeout=0)`` does (the same queues, timestamps, ``channel``,
    ``is_rx``, the same ``CanOperationError`` for a full or closed bus), without its ``deepcopy`` per
    receiver, which costs more than the rest of a frame's trip. The returned function *consumes* the
    message: the caller built it for this send and never touches it again (a second receiver, if any,
    gets a plain copy). None when ``bus`` is not a virtual bus laid out as python-can 4 lays it out
    (then ``bus.send`` it is)."""
    send_all = virtual_batch_sender(bus)
    if send_all is None:
        return None

    def send(msg: can.Message) -> None:
        send_all([msg])

    return send


def virtual_batch_sender(bus: can.BusABC) -> Callable[[list[can.Message]], None] | None:
    """:func:`virtual_sender` for frames that go out back to back (one command's): each receiver gets
    them all, in order, and then one signal (a :class:`_SignalledQueue` reader wakes once per batch,
    not once per frame, and never finds half a command). Raises ``CanOperationError`` after the batch
    when a receiver's queue was full or the bus is closed."""
    from can.interfaces import virtual

    if not isinstance(bus, virtual.VirtualBus):
        return None
    if not all(hasattr(bus, a) for a in VIRTUAL_BUS_ATTRIBUTES) or not isinstance(bus.channel, list):
        return None
    vbus: Any = bus  # python-can's VirtualBus attributes, checked above
    channel: list[queue.Queue[can.Message]] = vbus.channel
    channel_id = vbus.channel_id
    own_too = bool(vbus.receive_own_messages)
    keep_time = bool(vbus.preserve_timestamps)
    clock = time.time

    def send_all(msgs: list[can.Message]) -> None:
        own = vbus.queue
        targets: list[queue.Queue[can.Message]] = []
        open_ = False  # a bus that was shut down has taken its queue off the channel
        for q in channel:
            if q is own:
                open_ = True
                if not own_too:
                    continue
            targets.append(q)
        if not open_:
            raise can.CanOperationError("Cannot operate on a closed bus")
        full = False
        for msg in msgs:
            if not keep_time:
                msg.timestamp = clock()
        for i, target in enumerate(targets):
            last = i == len(targets) - 1  # the last one gets the originals
            quiet = target if isinstance(target, _SignalledQueue) else None
            for msg in msgs:
                copy = msg if last else _copied(msg)
                copy.channel, copy.is_rx = channel_id, target is not own
                try:
                    if quiet is not None:
                        quiet.put_quiet(copy)
                    else:
                        target.put(copy, block=True, timeout=0)
                except queue.Full:
                    full = True
                    break
            if quiet is not None:
                quiet.signal()
        if full:
            raise can.CanOperationError("Could not send message to one or more recipients")

    return send_all


def _send_each(bus: can.BusABC, msgs: list[can.Message]) -> None:
    """A batch on a bus without a batch send: frame by frame, stopping at the first that fails."""
    for msg in msgs:
        bus.send(msg, timeout=0)


def _copied(msg: can.Message) -> can.Message:
    return can.Message(
        timestamp=msg.timestamp,
        arbitration_id=msg.arbitration_id,
        is_extended_id=msg.is_extended_id,
        is_remote_frame=msg.is_remote_frame,
        is_error_frame=msg.is_error_frame,
        dlc=msg.dlc,
        data=bytes(msg.data),
        is_fd=msg.is_fd,
        bitrate_switch=msg.bitrate_switch,
        error_state_indicator=msg.error_state_indicator,
    )


#: Interfaces the loop reads itself (``add_reader`` on a descriptor, then ``bus.recv(0)`` until empty),
#: and how to get their descriptor; every other interface is read by python-can's notifier thread
#: (slcan and serial adapters buffer partial lines behind their descriptor; vendor drivers have none).
LOOP_READ: dict[str, Callable[[can.BusABC], _LoopReader | None]] = {
    "socketcan": _own_fileno,
    "virtual": _virtual_fileno,
}


class _Listener(can.Listener):
    def __init__(self, link: CanLink) -> None:
        self._link = link

    def on_message_received(self, msg: can.Message) -> None:
        if self._link._accept(msg):
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
        #: the descriptor the loop watches and what undoes it (None: the notifier thread reads)
        self._reader: _LoopReader | None = None
        self._reader_due = False  # a read is scheduled for the next turn of the loop (a flood)
        self._sendq: queue.SimpleQueue[can.Message | _Sent | None] = queue.SimpleQueue()
        self._sender: threading.Thread | None = None
        self._direct = interface in NONBLOCKING_SEND  # sent by the caller's thread (see NONBLOCKING_SEND)
        self._send_lock = threading.Lock()  # a direct send: one command's frames together, in order
        #: a direct send of one command's frames (virtual_batch_sender) or None
        self._put: Callable[[list[can.Message]], None] | None = None
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
            try:  # noqa: SIM105 (per frame: contextlib.suppress builds an object per call)
                observer(direction, arb_id, bytes(data))
            except Exception:  # a tap must never take the link down
                pass

    async def open(self) -> None:
        """Open the bus (in a worker thread: some interfaces block while they open)."""
        if self._up:
            return
        try:
            bus = await asyncio.to_thread(self._make_bus)
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            raise LinkError(f"cannot open {self.interface} {self.channel}: {exc}") from None
        self._bus = bus
        self._reader, self._reader_due = None, False
        watch = LOOP_READ.get(self.interface)
        try:
            self._reader = watch(bus) if watch is not None else None
        except (NotImplementedError, OSError, ValueError):
            self._reader = None
        if self._reader is not None:
            self._loop.add_reader(self._reader.fd, self._readable, bus)
        else:
            self._notifier = can.Notifier(bus, [_Listener(self)], timeout=0.05)
        self._sendq = queue.SimpleQueue()
        self._put = None
        if self._direct:
            put = virtual_batch_sender(bus) if self.interface == "virtual" else None
            self._put = put or (lambda msgs: _send_each(bus, msgs))
        else:
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
        if self._direct:
            self._send_now(frames, on_sent)
            return
        for arb_id, data in frames:
            self._sendq.put(can.Message(arbitration_id=arb_id, data=data, is_extended_id=False))
        if on_sent is not None:
            self._sendq.put(_Sent(on_sent))

    def close(self) -> None:
        self._up = False
        reader: _LoopReader | None = None
        if self._reader is not None:
            reader, self._reader = self._reader, None
            with contextlib.suppress(Exception):
                self._loop.remove_reader(reader.fd)
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
        if reader is not None:  # after the bus left its channel: no sender writes to its pipe any more
            reader.close()

    def _send_now(self, frames: list[tuple[int, bytes]], on_sent: Callable[[], None] | None) -> None:
        """Put the frames on a bus whose send cannot block, from the calling thread (any thread): all of
        one command's frames in one go (the receiver wakes once for them)."""
        put = self._put
        msgs = [
            can.Message(arbitration_id=arb_id, data=data, is_extended_id=False) for arb_id, data in frames
        ]
        with self._send_lock:
            try:
                if put is None or self._bus is None:
                    raise can.CanOperationError("bus closed")
                put(msgs)
            except (can.CanError, OSError, ValueError) as exc:
                if self._up:  # (a link closed under a sender is not a send error)
                    self.send_errors += 1
                    self._from_thread(self._failed, f"send failed: {type(exc).__name__}: {exc}")
                return
            self.frames_out += len(frames)
            for arb_id, data in frames:
                self._observe("tx", arb_id, data)
        if on_sent is not None:
            self._from_thread(on_sent)

    def _accept(self, msg: can.Message) -> bool:
        """A data frame on the gimbal's id (counted and shown to the tap); anything else is not ours."""
        if (
            msg.is_error_frame
            or msg.is_remote_frame
            or msg.is_extended_id
            or msg.arbitration_id != self.rx_id
        ):
            return False
        self.frames_in += 1
        self._observe("rx", msg.arbitration_id, msg.data)
        return True

    def _readable(self, bus: can.BusABC) -> None:
        """In the loop: the bus's descriptor is readable; take the frames waiting (one wake-up may stand
        for several; at most :data:`READ_BATCH`, then the rest on the next turn of the loop) and hand ours
        to ``on_frame`` directly."""
        reader = self._reader
        if reader is None or self._reader_due:
            return
        reader.clear()  # first: a frame put after this signals again
        take = reader.take or (lambda: bus.recv(0))
        try:
            for _ in range(READ_BATCH):
                if self._reader is not reader or (msg := take()) is None:
                    return
                if self._accept(msg):
                    self.on_frame(msg.arbitration_id, bytes(msg.data))
        except (can.CanError, OSError, ValueError) as exc:
            self._failed(f"receive failed: {type(exc).__name__}: {exc}")
            return
        self._reader_due = True  # a flood: let other callbacks run, then read on

        def again() -> None:
            self._reader_due = False
            if self._reader is reader:  # (not a link closed, or reopened on another bus, meanwhile)
                self._readable(bus)

        self._loop.call_soon(again)

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
