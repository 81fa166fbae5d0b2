"""A real NATS cluster for the tests and the benchmarks: three ``nats-server`` processes on free loopback
ports, clustered, JetStream on (MQTT keeps its sessions, retained messages and QoS 1 deliveries in
JetStream streams replicated across the nodes), each with an MQTT listener.

Owns the processes, their config files and store directories, and the readiness check (an MQTT 3.1.1
client gets a CONNACK and a SUBACK from every node). Never binds anything but 127.0.0.1 and never
uses a server someone else started. Debian's ``nats-server`` (2.9) speaks MQTT 3.1.1 only (an MQTT 5
CONNECT is refused), QoS 0 and 1 (2 from 2.10 on), and no shared subscriptions.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import tempfile
import threading
import time
import uuid
from pathlib import Path

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion, MQTTProtocolVersion

from gateway.local_broker import free_port, port_open
from gateway.mqtt import close_client

__all__ = ["NatsCluster", "find_nats_server"]


def find_nats_server() -> str:
    """Path of the nats-server binary (Debian installs it in /usr/sbin)."""
    found = shutil.which("nats-server") or next(
        (p for p in ("/usr/sbin/nats-server", "/usr/local/bin/nats-server") if os.access(p, os.X_OK)), None
    )
    if not found:
        raise FileNotFoundError("nats-server not found: install it (apt-get install nats-server)")
    return found


def nats_version() -> str:
    out = subprocess.run([find_nats_server(), "--version"], capture_output=True, text=True, timeout=10)
    return out.stdout.strip().removeprefix("nats-server: ")


class NatsCluster:
    """Three clustered nats-server nodes (0, 1, 2), restartable one by one on the same ports."""

    NODES = 3

    def __init__(self, workdir: Path | None = None, *, mqtt_extra: str = "") -> None:
        """``mqtt_extra``: more settings inside each node's ``mqtt { … }`` block (e.g.
        ``consumer_memory_storage: true``; ``bench/failover.py`` compares them)."""
        self.host = "127.0.0.1"
        self.dir = Path(workdir) if workdir else Path(tempfile.mkdtemp(prefix="djigw-nats-"))
        self.client_ports = [free_port() for _ in range(self.NODES)]
        self.cluster_ports = [free_port() for _ in range(self.NODES)]
        self.mqtt_ports = [free_port() for _ in range(self.NODES)]
        self._procs: list[subprocess.Popen[bytes] | None] = [None] * self.NODES
        extra = f", {mqtt_extra}" if mqtt_extra else ""
        routes = ", ".join(f"nats-route://{self.host}:{p}" for p in self.cluster_ports)
        for i in range(self.NODES):
            store = self.dir / f"n{i}"
            store.mkdir(parents=True, exist_ok=True)
            (self.dir / f"n{i}.conf").write_text(
                "\n".join(
                    [
                        f"server_name: djigw-n{i}",
                        f"listen: {self.host}:{self.client_ports[i]}",
                        f"jetstream {{ store_dir: {store}, max_memory_store: 64MB, max_file_store: 512MB }}",
                        f"cluster {{ name: djigw-test, listen: {self.host}:{self.cluster_ports[i]}, "
                        f"routes: [{routes}] }}",
                        f"mqtt {{ listen: {self.host}:{self.mqtt_ports[i]}{extra} }}",
                        "",
                    ]
                )
            )

    def url(self, i: int) -> str:
        return f"mqtt://{self.host}:{self.mqtt_ports[i]}"

    @property
    def urls(self) -> list[str]:
        return [self.url(i) for i in range(self.NODES)]

    def running(self, i: int) -> bool:
        proc = self._procs[i]
        return proc is not None and proc.poll() is None

    def start_node(self, i: int) -> None:
        if self.running(i):
            return
        log = open(self.dir / f"n{i}.log", "ab")  # noqa: SIM115 - owned by the child from here on
        self._procs[i] = subprocess.Popen(
            [find_nats_server(), "-c", str(self.dir / f"n{i}.conf")],
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        log.close()

    def start(self, timeout: float = 60.0) -> NatsCluster:
        """Start the three nodes and wait until each serves MQTT sessions; when one cannot start (a port
        picked free and taken by another process before the node bound it), none is left running."""
        try:
            for i in range(self.NODES):
                self.start_node(i)
            self.wait_ready(range(self.NODES), timeout)
        except BaseException:
            self.stop()
            raise
        return self

    def wait_ready(self, nodes: range | list[int], timeout: float = 60.0) -> None:
        """Every node in ``nodes`` accepts an MQTT session with a QoS 1 subscription (JetStream ready)."""
        deadline = time.monotonic() + timeout
        for i in nodes:
            while not port_open(self.host, self.mqtt_ports[i]):
                self._check_alive(i)
                if time.monotonic() > deadline:
                    raise TimeoutError(f"NATS node {i} did not listen for MQTT: {self.log_tail(i)}")
                time.sleep(0.05)
            while not self._mqtt_works(i):
                self._check_alive(i)
                if time.monotonic() > deadline:
                    raise TimeoutError(f"NATS node {i} did not accept MQTT sessions: {self.log_tail(i)}")
                time.sleep(0.2)

    def _check_alive(self, i: int) -> None:
        proc = self._procs[i]
        if proc is not None and proc.poll() is not None:
            raise RuntimeError(f"nats-server node {i} exited with {proc.returncode}: {self.log_tail(i)}")

    def _mqtt_works(self, i: int) -> bool:
        done = threading.Event()
        ok: list[bool] = []
        client = paho.Client(
            CallbackAPIVersion.VERSION2,
            client_id=f"probe-{uuid.uuid4().hex[:8]}",
            protocol=MQTTProtocolVersion.MQTTv311,
            clean_session=False,  # a persistent session: the JetStream streams must be there
        )

        def on_connect(c: paho.Client, u: object, f: object, reason: object, p: object) -> None:
            if getattr(reason, "is_failure", True):
                done.set()
            else:
                c.subscribe("djigw/probe", qos=1)

        def on_subscribe(c: paho.Client, u: object, mid: int, reasons: list[object], p: object) -> None:
            ok.append(not any(getattr(r, "is_failure", False) for r in reasons))
            done.set()

        client.on_connect = on_connect
        client.on_subscribe = on_subscribe
        try:
            client.connect(self.host, self.mqtt_ports[i], keepalive=10)
            client.loop_start()
            done.wait(5)
        except OSError:
            return False
        finally:
            if client.is_connected():
                # clean up the probe's session so it does not pile up in the streams
                client.disconnect()
            client.loop_stop()
            close_client(client)
        return bool(ok and ok[0])

    def kill(self, i: int) -> None:
        """SIGKILL node ``i`` (a crash: no goodbye to its clients or its peers)."""
        self.stop_node(i, sig=signal.SIGKILL)

    def stop_node(self, i: int, sig: int = signal.SIGTERM) -> None:
        proc = self._procs[i]
        if proc is None:
            return
        if proc.poll() is None:
            proc.send_signal(sig)
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(5)
        self._procs[i] = None

    def stop(self) -> None:
        for i in range(self.NODES):
            self.stop_node(i)

    def log_tail(self, i: int, chars: int = 800) -> str:
        path = self.dir / f"n{i}.log"
        return path.read_text(errors="replace")[-chars:] if path.exists() else ""

    def __enter__(self) -> NatsCluster:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()
