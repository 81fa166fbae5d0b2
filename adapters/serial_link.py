"""A serial link for the UART device families (Onboard SDK, RoboMaster), thin over pyserial.

Owns one port opened by URL (``/dev/ttyUSB0``, ``/dev/serial/by-id/…``, a pty path,
``socket://127.0.0.1:PORT``, ``rfc2217://…``) and a writer thread, so a stuck port never blocks the
loop. Reading: a port with a file descriptor (a tty, a pty, ``socket://``) is watched by the asyncio
loop itself (``add_reader``; pyserial reads it without blocking once its timeout is 0): no thread and
no cross-thread hand-off per burst, which is what lets one gateway serve hundreds of ports. A port
without one (``rfc2217://``, ``loop://``) gets a reader thread that hands bytes over with
``call_soon_threadsafe``. A tty is opened with ``exclusive=True`` (an advisory ``flock``): a port another
process holds locked is reported as "in use by another process" with the command that finds it.
pyserial exceptions become :class:`LinkError`; a port that fails (cable
unplugged, pty closed, socket dropped) is closed and reported once through ``on_down``; the adapter
reopens it.

``observer`` (None by default) sees the bytes as they cross the port: ``observer("rx", None, chunk)``
for every read, ``observer("tx", None, frame)`` for every write once it is on the port, from the loop
or the link's threads: a frame tap (the web console's frame inspector) that must be thread-safe,
bounded and quick, and whose failure never touches the link.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import queue
import threading
from collections.abc import Callable
from typing import Any

import serial

from adapters.errors import LinkError

log = logging.getLogger(__name__)

__all__ = ["SerialLink"]


_READ_ERRORS = (serial.SerialException, OSError, TypeError, AttributeError, ValueError)


def _selectable_fd(port: serial.Serial) -> int | None:
    """The port's descriptor, with pyserial's timeout set to 0 so a read takes what is there and returns;
    None for ports that have none (their reads stay in a thread)."""
    try:
        fd = port.fileno()
        port.timeout = 0
    except (AttributeError, OSError, ValueError, serial.SerialException):
        return None
    return fd if isinstance(fd, int) and fd >= 0 else None


class SerialLink:
    def __init__(
        self,
        *,
        url: str,
        baudrate: int,
        loop: asyncio.AbstractEventLoop,
        on_bytes: Callable[[bytes], None],
        on_down: Callable[[str], None],
        options: dict[str, Any] | None = None,
    ) -> None:
        self.url, self.baudrate = url, baudrate
        self.on_bytes, self.on_down = on_bytes, on_down
        self._options = dict(options or {})
        self._loop = loop
        self._writeq: queue.SimpleQueue[bytes | None] = queue.SimpleQueue()
        self._threads: list[threading.Thread] = []
        self._fd: int | None = None
        self._up = False
        self._generation = 0
        self.bytes_in = 0
        self.bytes_out = 0
        self.frames_out = 0  # write() calls: every adapter here writes one whole frame per call
        self.send_errors = 0  # writes that failed (and closed the link)
        self.opens = 0  # successful opens (the first one and every reopen), for the reconnect metric
        #: frame tap: ``observer(direction, None, data)`` (see the module doc)
        self.observer: Callable[[str, int | None, bytes], None] | None = None

    #: what the link statistics call it (adapters.supervision.SupervisedLink); frames received are
    #: protocol frames, counted by the adapter's stream decoder, not here
    kind = "serial"
    frames_in: int | None = None

    @property
    def where(self) -> str:
        return self.url

    @property
    def up(self) -> bool:
        return self._up

    def _observe(self, direction: str, data: bytes) -> None:
        observer = self.observer
        if observer is not None:
            with contextlib.suppress(Exception):  # a tap must never take the link down
                observer(direction, None, data)

    async def open(self) -> None:
        if self._up:
            return
        try:
            port = await asyncio.to_thread(self._make_port)
        except (serial.SerialException, OSError, ValueError) as exc:
            if getattr(exc, "errno", None) in (errno.EWOULDBLOCK, errno.EAGAIN) and "lock" in str(exc):
                raise LinkError(
                    f"cannot open {self.url}: in use by another process (find it with "
                    f"'fuser -v {self.url}' or 'lsof {self.url}')"
                ) from None
            raise LinkError(f"cannot open {self.url}: {exc}") from None
        self._generation += 1
        gen = self._generation
        self._writeq = queue.SimpleQueue()
        self._threads = [
            threading.Thread(
                target=self._write_loop,
                args=(port, self._writeq, gen),
                daemon=True,
                name=f"serial-tx {self.url}",
            )
        ]
        self._fd = _selectable_fd(port)
        if self._fd is not None:
            self._loop.add_reader(self._fd, self._readable, port, gen)
        else:
            self._threads.append(
                threading.Thread(
                    target=self._read_loop, args=(port, gen), daemon=True, name=f"serial-rx {self.url}"
                )
            )
        for t in self._threads:
            t.start()
        self._up = True
        self.opens += 1
        log.info("serial link open: %s @ %d", self.url, self.baudrate)

    def _make_port(self) -> serial.Serial:
        kwargs: dict[str, Any] = {
            "baudrate": self.baudrate,
            "timeout": 0.05,
            "write_timeout": 1.0,
            # flock(LOCK_EX) on a tty: a second gateway (or any program that locks) cannot share the UART;
            # URL ports (socket://) ignore it
            "exclusive": True,
            **self._options,
        }
        return serial.serial_for_url(self.url, **kwargs)

    def write(self, data: bytes) -> None:
        """Queue bytes for the port, in order; raises LinkError when the link is down."""
        if not self._up:
            raise LinkError(f"serial link {self.url} is down")
        self._writeq.put(bytes(data))
        self.frames_out += 1

    def close(self) -> None:
        """Stop reading and hand the port to the writer thread, which sends what is queued and closes it;
        returns at once (hundreds of links close in parallel, and the loop never waits on a port). Call
        it from the loop's thread (the adapters do): the loop stops watching the descriptor first, so a
        reused descriptor number is never mistaken for this port."""
        self._up = False
        self._generation += 1
        self._writeq.put(None)
        fd, self._fd = self._fd, None
        if fd is not None:
            with contextlib.suppress(Exception):
                self._loop.remove_reader(fd)
        self._threads = []

    # -- reading ----------------------------------------------------------------------------------
    def _readable(self, port: serial.Serial, gen: int) -> None:
        """The loop saw the descriptor readable: take everything there in one read (the timeout is 0)."""
        if gen != self._generation:
            return
        try:
            data = port.read(65536)
            if not data:  # readable but empty: the other end went away
                raise serial.SerialException("port closed by the device side")
        except _READ_ERRORS as exc:
            self._failed(gen, f"read failed: {type(exc).__name__}: {exc}")
            return
        self.bytes_in += len(data)
        self._observe("rx", data)
        self.on_bytes(data)

    def _read_loop(self, port: serial.Serial, gen: int) -> None:
        """Ports without a descriptor: pyserial's own blocking read, in a thread."""
        while gen == self._generation:
            try:
                data = port.read(max(1, port.in_waiting or 1))
            except _READ_ERRORS as exc:
                self._from_thread(self._failed, gen, f"read failed: {type(exc).__name__}: {exc}")
                return
            if data:
                self.bytes_in += len(data)
                self._observe("rx", data)
                self._from_thread(self._deliver, gen, data)

    def _write_loop(self, port: serial.Serial, q: queue.SimpleQueue[bytes | None], gen: int) -> None:
        """Write what is queued, in order, until :meth:`close` (its sentinel comes after every frame queued
        before it, so a last stop frame still goes out); then close the port here, off the loop: pyserial's
        socket:// close sleeps 0.3 s, and a tty's may wait for its output to drain."""
        try:
            while True:
                data = q.get()
                if data is None:
                    return
                try:
                    port.write(data)
                    self.bytes_out += len(data)
                    self._observe("tx", data)
                except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                    self.send_errors += 1
                    self._from_thread(self._failed, gen, f"write failed: {type(exc).__name__}: {exc}")
                    return
        finally:
            with contextlib.suppress(Exception):
                port.close()

    def _from_thread(self, fn: Callable[..., None], *args: Any) -> None:
        with contextlib.suppress(RuntimeError):  # the loop closed during shutdown
            self._loop.call_soon_threadsafe(fn, *args)

    def _deliver(self, gen: int, data: bytes) -> None:
        if gen == self._generation:
            self.on_bytes(data)

    def _failed(self, gen: int, reason: str) -> None:
        if gen != self._generation or not self._up:
            return
        log.warning("serial link %s failed: %s", self.url, reason)
        self.close()
        self.on_down(reason)
