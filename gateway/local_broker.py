"""Start a private mosquitto on a free loopback port: for ``make run`` and for the test suite.

Owns the mosquitto process, its config file and its readiness check. Knows nothing of the Cloud
API. Never binds anything but loopback, and never reuses a broker someone else started. The temporary
directory it makes (config, log, database) is removed when the object goes away (a test suite made some
150 per run and left them in /tmp); a ``workdir`` given to it is left alone.

Time: real (``time.monotonic``/``time.sleep``): it waits for an operating-system process, not a timer of
the gateway's.
"""

from __future__ import annotations

import contextlib
import getpass
import os
import random
import shutil
import signal
import socket
import subprocess
import tempfile
import time
import weakref
from pathlib import Path

__all__ = ["LocalBroker", "find_mosquitto", "free_port", "port_open"]


def find_mosquitto() -> str:
    """Path of the mosquitto binary (Debian installs it in /usr/sbin, often not on PATH)."""
    found = shutil.which("mosquitto") or next(
        (p for p in ("/usr/sbin/mosquitto", "/usr/local/sbin/mosquitto") if os.access(p, os.X_OK)), None
    )
    if not found:
        raise FileNotFoundError("mosquitto binary not found: install it (apt-get install mosquitto)")
    return found


def _mosquitto_passwd() -> str:
    found = shutil.which("mosquitto_passwd") or (
        "/usr/bin/mosquitto_passwd" if os.access("/usr/bin/mosquitto_passwd", os.X_OK) else None
    )
    if not found:
        raise FileNotFoundError("mosquitto_passwd not found (it ships with the mosquitto package)")
    return found


#: where :func:`free_port` looks first: below Linux's default ephemeral range (32768-60999)
_STABLE_PORTS = (20000, 32767)


def _ephemeral_low() -> int:
    """The lowest port the kernel hands to connections as their local end (32768 where unreadable)."""
    try:
        return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nothing listens on or holds now, chosen outside the kernel's ephemeral range where it
    can: a broker restarted on the same port (the outage and failover tests kill nodes and start them
    again) must not find it taken meanwhile by some connection's local end, which the kernel picks from
    that range (seen: a NATS node that could not listen again on its port). Falls back to a port the
    kernel picks when none below the range is free."""
    low, high = _STABLE_PORTS[0], min(_STABLE_PORTS[1], _ephemeral_low() - 1)
    pick = random.SystemRandom()
    for _ in range(100 if high > low else 0):
        port = pick.randint(low, high)
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind((host, port))
            except OSError:
                continue
            return port
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def port_open(host: str, port: int, timeout: float = 0.2) -> bool:
    with contextlib.suppress(OSError), socket.create_connection((host, port), timeout=timeout):
        return True
    return False


class LocalBroker:
    """A mosquitto child process on 127.0.0.1:port, restartable on the same port (for outage tests).

    ``extra_config`` lines are appended to the generated config (password_file, acl_file, TLS …);
    ``listener_lines`` replace the default plain listener."""

    def __init__(
        self,
        port: int | None = None,
        *,
        extra_config: str = "",
        listener_lines: str | None = None,
        allow_anonymous: bool = True,
        workdir: Path | None = None,
        users: dict[str, str] | None = None,
        persistence: bool = False,
    ) -> None:
        self.host = "127.0.0.1"
        self.port = port or free_port()
        self._dir = Path(workdir) if workdir else Path(tempfile.mkdtemp(prefix="djigw-mosq-"))
        self._dir.mkdir(parents=True, exist_ok=True)
        if workdir is None:  # a directory of our own (config, log, database): gone with this object
            weakref.finalize(self, shutil.rmtree, str(self._dir), ignore_errors=True)
        listener = listener_lines or f"listener {self.port} {self.host}"
        if users:
            password_file = self._dir / "passwords"
            password_file.write_text("")
            for user, password in users.items():
                subprocess.run(
                    [_mosquitto_passwd(), "-b", str(password_file), user, password],
                    check=True,
                    capture_output=True,
                    timeout=30,
                )
            password_file.chmod(0o600)
            extra_config = f"password_file {password_file}\n{extra_config}"
            allow_anonymous = False
        self.config_path = self._dir / "mosquitto.conf"
        self.log_path = self._dir / "mosquitto.log"
        self.config_path.write_text(
            "\n".join(
                [
                    "per_listener_settings false",
                    # run as whoever started us: as root, mosquitto would switch to a 'mosquitto' user
                    # that cannot read this private directory
                    f"user {getpass.getuser()}",
                    listener,
                    f"allow_anonymous {'true' if allow_anonymous else 'false'}",
                    f"persistence {'true' if persistence else 'false'}",
                    f"persistence_location {self._dir}/",
                    "autosave_interval 1",
                    "set_tcp_nodelay true",
                    "max_queued_messages 10000",
                    f"log_dest file {self.log_path}",
                    "log_type error",
                    "log_type warning",
                    "log_type notice",
                    extra_config,
                    "",
                ]
            )
        )
        self._proc: subprocess.Popen[bytes] | None = None

    @property
    def url(self) -> str:
        return f"mqtt://{self.host}:{self.port}"

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    def start(self, timeout: float = 10.0) -> LocalBroker:
        if self.running:
            return self
        self._proc = subprocess.Popen(
            [find_mosquitto(), "-c", str(self.config_path)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            start_new_session=True,
        )
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if self._proc.poll() is not None:
                err = self._proc.stderr.read().decode(errors="replace") if self._proc.stderr else ""
                log = self.log_path.read_text() if self.log_path.exists() else ""
                raise RuntimeError(
                    f"mosquitto exited with {self._proc.returncode}: {err.strip()} {log[-500:]}"
                )
            if port_open(self.host, self.port):
                return self
            time.sleep(0.02)
        self.stop()
        raise TimeoutError(f"mosquitto did not listen on {self.host}:{self.port} within {timeout}s")

    def save(self, timeout: float = 5.0) -> None:
        """Have mosquitto write its persistence database now (SIGUSR1) and wait until the file changed: what a
        test's crash (``stop(kill=True)``) must not lose, whatever the autosave's timing under load."""
        db = self._dir / "mosquitto.db"
        if self._proc is None or self._proc.poll() is not None:
            return
        before = db.stat().st_mtime_ns if db.exists() else 0
        self._proc.send_signal(signal.SIGUSR1)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if db.exists() and db.stat().st_mtime_ns != before:
                time.sleep(0.05)  # written, not half-written
                return
            time.sleep(0.02)
        raise TimeoutError(f"mosquitto did not write {db} within {timeout}s (persistence off?)")

    def stop(self, *, kill: bool = False) -> None:
        """Stop the broker; ``kill`` sends SIGKILL (a crash) instead of SIGTERM."""
        if self._proc is None:
            return
        if self._proc.poll() is None:
            self._proc.send_signal(signal.SIGKILL if kill else signal.SIGTERM)
            try:
                self._proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait(timeout=5)
        if self._proc.stderr:
            self._proc.stderr.close()
        self._proc = None
        # wait until the port is free again so a restart can bind it
        deadline = time.monotonic() + 5
        while port_open(self.host, self.port) and time.monotonic() < deadline:
            time.sleep(0.02)

    def restart(self) -> LocalBroker:
        self.stop()
        return self.start()

    def __enter__(self) -> LocalBroker:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
