"""Byte-stream endpoints for the device simulators: a pseudo-terminal or a loopback TCP port.

A simulator is a :class:`StreamDevice` (bytes in → bytes out, plus a periodic ``tick``); this
module gives it a real OS byte boundary so the gateway talks to it through pyserial (a pty path or
``socket://127.0.0.1:PORT``) or python-can's ``slcan`` interface exactly as it would to hardware.
Loopback only. One client at a time on TCP (a serial port has one host too); a reconnecting client
replaces the previous one.

Time: a simulator keeps its own, real time (``time.monotonic``), as the device it stands for does; the
gateway's injected clock is not the device's.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import socket
import threading
import time
import tty
from typing import Protocol, Self

log = logging.getLogger(__name__)

__all__ = ["PtyEndpoint", "StreamDevice", "TcpEndpoint", "TcpFarm"]


class StreamDevice(Protocol):
    def on_bytes(self, data: bytes, now: float) -> bytes:
        """Bytes from the host; returns bytes to send back at once."""
        ...

    def tick(self, now: float) -> bytes:
        """Called every ``tick_interval``; returns unsolicited bytes (pushes, telemetry)."""
        ...


class _Endpoint:
    def __init__(self, device: StreamDevice, tick_interval: float = 0.01) -> None:
        self.device = device
        self.tick_interval = tick_interval
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self.paused = False  # when True the device neither reads nor answers (a "silent" device)

    def start(self) -> Self:
        self._thread = threading.Thread(target=self._run, name=type(self).__name__, daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        self._close()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        next_tick = time.monotonic()
        while not self._stop.is_set():
            fd = self._fd()
            timeout = max(0.0, next_tick - time.monotonic())
            readable: list[int] = []
            if fd is not None:
                try:
                    readable, _, _ = select.select([fd], [], [], timeout)
                except (OSError, ValueError):
                    self._drop_client()
                    continue
            else:
                self._accept(timeout)
            now = time.monotonic()
            if readable:
                data = self._read()
                if data is None:
                    self._drop_client()
                elif data and not self.paused:
                    out = self.device.on_bytes(data, now)
                    if out:
                        self._write(out)
            if now >= next_tick:
                next_tick = now + self.tick_interval
                if not self.paused:
                    out = self.device.tick(now)
                    if out and self._fd() is not None:
                        self._write(out)

    # subclass hooks
    def _fd(self) -> int | None:
        raise NotImplementedError

    def _read(self) -> bytes | None:
        raise NotImplementedError

    def _write(self, data: bytes) -> None:
        raise NotImplementedError

    def _accept(self, timeout: float) -> None:
        time.sleep(timeout)

    def _drop_client(self) -> None:
        pass

    def _close(self) -> None:
        pass


class PtyEndpoint(_Endpoint):
    """The device holds the master side; the host opens :attr:`path` (the slave) with pyserial.

    Like a UART without flow control, the device never waits for its host for long: when nobody reads
    (the host program exited) a write waits at most ``write_timeout`` for room in the pty's buffer, then
    the bytes are dropped (counted in :attr:`dropped`) and later writes are dropped at once until the
    host reads again, so the device keeps ticking (a simulated aircraft keeps flying its mission)."""

    def __init__(self, device: StreamDevice, tick_interval: float = 0.01, write_timeout: float = 1.0) -> None:
        super().__init__(device, tick_interval)
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)  # no echo, no CR/LF translation: a clean 8-bit line
        tty.setraw(self._master)
        os.set_blocking(self._master, False)
        self.path = os.ttyname(self._slave)
        self.write_timeout = write_timeout
        self.dropped = 0  # bytes nobody read in time
        self._stalled = False

    def _fd(self) -> int | None:
        return self._master

    def _read(self) -> bytes | None:
        try:
            return os.read(self._master, 4096)
        except BlockingIOError:
            return b""
        except OSError:
            return b""  # EIO when no host has the slave open: keep waiting

    def _write(self, data: bytes) -> None:
        with self._lock:
            view = memoryview(data)
            deadline = time.monotonic() + (0.0 if self._stalled else self.write_timeout)
            while view:
                try:
                    view = view[os.write(self._master, view) :]
                    continue
                except BlockingIOError:
                    pass
                except OSError as exc:
                    log.debug("pty write failed: %s", exc)
                    return
                left = deadline - time.monotonic()
                if left <= 0 or not select.select([], [self._master], [], left)[1]:
                    self._stalled = True  # nobody reads: drop, and do not wait again until they do
                    self.dropped += len(view)
                    return
            self._stalled = False

    def _close(self) -> None:
        for fd in (self._master, self._slave):
            with contextlib.suppress(OSError):
                os.close(fd)


class TcpEndpoint(_Endpoint):
    """Listens on 127.0.0.1:``port`` (0 = any free port); the host opens :attr:`url`.

    ``host`` defaults to ``$DJIGW_SIM_HOST`` or loopback: a simulator in its own container (the
    compose stack) listens on ``0.0.0.0`` so the gateway's container can reach it by service name."""

    def __init__(
        self, device: StreamDevice, port: int = 0, tick_interval: float = 0.01, host: str | None = None
    ) -> None:
        super().__init__(device, tick_interval)
        host = host or os.environ.get("DJIGW_SIM_HOST") or "127.0.0.1"
        self._server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self._server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self._server.bind((host, port))
        self._server.listen(1)
        self.port = int(self._server.getsockname()[1])
        self.url = f"socket://{'127.0.0.1' if host == '0.0.0.0' else host}:{self.port}"
        self._client: socket.socket | None = None

    def _fd(self) -> int | None:
        return self._client.fileno() if self._client is not None else None

    def _accept(self, timeout: float) -> None:
        ready, _, _ = select.select([self._server], [], [], timeout)
        if ready:
            client, _ = self._server.accept()
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self._client = client

    def _read(self) -> bytes | None:
        assert self._client is not None
        try:
            data = self._client.recv(4096)
        except OSError:
            return None
        return data or None

    def _write(self, data: bytes) -> None:
        with self._lock:
            if self._client is None:
                return
            try:
                self._client.sendall(data)
            except OSError:
                self._drop_client()

    def _drop_client(self) -> None:
        if self._client is not None:
            with contextlib.suppress(OSError):
                self._client.close()
            self._client = None

    def _close(self) -> None:
        self._drop_client()
        with contextlib.suppress(OSError):
            self._server.close()


class TcpFarm:
    """Many simulated devices, each on its own loopback TCP port, served by one thread and one select loop.

    A thread per device (:class:`TcpEndpoint`) is fine for a handful; for hundreds (the scale benchmark,
    a fleet demo) the threads' wake-ups cost more than the devices themselves. Same contract per device:
    one client at a time, a reconnecting client replaces the previous one, ticks every ``tick_interval``.
    """

    _SLOTS = 10  # devices tick in this many phases spread over ``tick_interval``

    def __init__(
        self, devices: list[StreamDevice], tick_interval: float = 0.05, host: str = "127.0.0.1"
    ) -> None:
        self.devices = devices
        self.tick_interval = tick_interval
        self._servers: list[socket.socket] = []
        self._clients: list[socket.socket | None] = [None] * len(devices)
        for _ in devices:
            server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            server.bind((host, 0))
            server.listen(1)
            server.setblocking(False)
            self._servers.append(server)
        self.urls = [f"socket://{host}:{s.getsockname()[1]}" for s in self._servers]
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> TcpFarm:
        self._thread = threading.Thread(target=self._run, name="TcpFarm", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        for i in range(len(self.devices)):
            self._drop(i)
        for server in self._servers:
            with contextlib.suppress(OSError):
                server.close()

    def _drop(self, i: int) -> None:
        client, self._clients[i] = self._clients[i], None
        if client is not None:
            with contextlib.suppress(OSError):
                client.close()

    def _send(self, i: int, data: bytes) -> None:
        client = self._clients[i]
        if client is None:
            return
        try:
            client.sendall(data)
        except OSError:
            self._drop(i)

    def _run(self) -> None:
        server_index = {s.fileno(): i for i, s in enumerate(self._servers)}
        next_tick = time.monotonic()
        slot = 0
        while not self._stop.is_set():
            client_index = {c.fileno(): i for i, c in enumerate(self._clients) if c is not None}
            timeout = max(0.0, next_tick - time.monotonic())
            try:
                readable, _, _ = select.select([*server_index, *client_index], [], [], timeout)
            except (OSError, ValueError):
                continue  # a client closed under us: the next pass rebuilds the fd set
            now = time.monotonic()
            for fd in readable:
                if fd in server_index:
                    i = server_index[fd]
                    with contextlib.suppress(BlockingIOError):
                        accepted, _ = self._servers[i].accept()
                        accepted.setblocking(True)
                        accepted.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                        self._drop(i)
                        self._clients[i] = accepted
                    continue
                i = client_index[fd]
                client = self._clients[i]
                if client is None:
                    continue
                try:
                    data = client.recv(4096)
                except OSError:
                    data = b""
                if not data:
                    self._drop(i)
                    continue
                out = self.devices[i].on_bytes(data, now)
                if out:
                    self._send(i, out)
            if now >= next_tick:
                # one slot of devices per pass: real devices are not synchronised, and a farm that ticked
                # them all at one instant would hand the host one big burst per period
                slot_interval = self.tick_interval / self._SLOTS
                next_tick += slot_interval
                if next_tick < now:  # fell behind (a slow pass): skip, do not burst
                    next_tick = now + slot_interval
                for i in range(slot, len(self.devices), self._SLOTS):
                    if self._clients[i] is not None:
                        out = self.devices[i].tick(now)
                        if out:
                            self._send(i, out)
                slot = (slot + 1) % self._SLOTS
