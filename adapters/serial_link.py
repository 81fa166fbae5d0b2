"""A serial link for the UART device families (Onboard SDK, RoboMaster), thin over pyserial.

Owns one port opened by URL (``/dev/ttyUSB0``, ``/dev/serial/by-id/…``, a pty path,
``socket://127.0.0.1:PORT``, ``rfc2217://…``), a reader thread that hands received bytes to the
asyncio loop with ``call_soon_threadsafe``, and a writer thread so a stuck port never blocks the
loop. pyserial exceptions become :class:`LinkError`; a port that fails (cable unplugged, pty
closed, socket dropped) is closed and reported once through ``on_down``; the adapter reopens it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import queue
import select
import threading
from collections.abc import Callable
from typing import Any

import serial

log = logging.getLogger(__name__)

__all__ = ["LinkError", "SerialLink"]


class LinkError(Exception):
    """The serial link could not be opened or failed while in use."""


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
        self._port: serial.SerialBase | None = None
        self._writeq: queue.SimpleQueue[bytes | None] = queue.SimpleQueue()
        self._threads: list[threading.Thread] = []
        self._up = False
        self._generation = 0
        self.bytes_in = 0
        self.bytes_out = 0
        self.frames_out = 0  # write() calls: every adapter here writes one whole frame per call
        self.opens = 0  # successful opens (the first one and every reopen), for the reconnect metric

    @property
    def up(self) -> bool:
        return self._up

    async def open(self) -> None:
        if self._up:
            return
        try:
            port = await asyncio.to_thread(self._make_port)
        except (serial.SerialException, OSError, ValueError) as exc:
            raise LinkError(f"cannot open {self.url}: {exc}") from None
        self._port = port
        self._generation += 1
        gen = self._generation
        self._writeq = queue.SimpleQueue()
        self._threads = [
            threading.Thread(
                target=self._read_loop, args=(port, gen), daemon=True, name=f"serial-rx {self.url}"
            ),
            threading.Thread(
                target=self._write_loop,
                args=(port, self._writeq, gen),
                daemon=True,
                name=f"serial-tx {self.url}",
            ),
        ]
        for t in self._threads:
            t.start()
        self._up = True
        self.opens += 1
        log.info("serial link open: %s @ %d", self.url, self.baudrate)

    def _make_port(self) -> serial.SerialBase:
        kwargs: dict[str, Any] = {
            "baudrate": self.baudrate,
            "timeout": 0.05,
            "write_timeout": 1.0,
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
        self._up = False
        self._generation += 1
        self._writeq.put(None)
        port, self._port = self._port, None
        if port is not None:
            with contextlib.suppress(Exception):
                port.close()
        for t in self._threads:
            if t is not threading.current_thread():
                t.join(timeout=1.0)
        self._threads = []

    # -- threads ----------------------------------------------------------------------------------
    def _read_loop(self, port: serial.SerialBase, gen: int) -> None:
        # Wait for the port to be readable, then take everything there in one read: one hand-off to
        # the loop per burst, not per byte (pyserial's socket:// reports in_waiting as 0 or 1, so
        # read(in_waiting) crawls byte by byte). Ports without a file descriptor read as before.
        try:
            fd: int | None = port.fileno()
        except (AttributeError, OSError, ValueError, serial.SerialException):
            fd = None
        if fd is not None:
            try:
                port.timeout = 0  # once: select() does the waiting, read() takes what is there
            except (serial.SerialException, OSError, ValueError):
                fd = None
        while gen == self._generation:
            try:
                if fd is not None:
                    ready, _, _ = select.select([fd], [], [], 0.1)
                    if not ready:
                        continue
                    data = port.read(65536)
                    if not data:  # readable but empty: the other end went away
                        raise serial.SerialException("port closed by the device side")
                else:
                    data = port.read(max(1, port.in_waiting or 1))
            except (serial.SerialException, OSError, TypeError, AttributeError, ValueError) as exc:
                self._from_thread(self._failed, gen, f"read failed: {type(exc).__name__}: {exc}")
                return
            if data:
                self.bytes_in += len(data)
                self._from_thread(self._deliver, gen, data)

    def _write_loop(self, port: serial.SerialBase, q: queue.SimpleQueue[bytes | None], gen: int) -> None:
        while True:
            data = q.get()
            if data is None or gen != self._generation:
                return
            try:
                port.write(data)
                self.bytes_out += len(data)
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                self._from_thread(self._failed, gen, f"write failed: {type(exc).__name__}: {exc}")
                return

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
