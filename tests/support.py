"""Test helpers: a cloud-side paho client, the gateway in a background thread, waiting with deadlines."""

from __future__ import annotations

import asyncio
import json
import queue
import re
import signal
import subprocess
import threading
import time
import uuid
from collections import Counter
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import can
import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion

from adapters.base import Adapter, CallResult, DeviceInfo, Handler, TelemetrySink
from adapters.rsdk.can import HOST_TX_ID, Reassembler
from adapters.rsdk.commands import decode_message
from adapters.rsdk.protocol import Frame
from gateway.app import GatewayApp
from gateway.clock import Clock
from gateway.mqtt import close_client
from gateway.settings import GatewaySettings, load_settings


def docker_compose() -> list[str] | None:
    """``docker compose`` where the client is installed, else None (``config`` needs no daemon)."""
    import shutil
    import subprocess

    docker = shutil.which("docker")
    if docker is None:
        return None
    probe = subprocess.run([docker, "compose", "version"], capture_output=True, timeout=20)
    return [docker, "compose"] if probe.returncode == 0 else None


def wait_until(
    predicate: Callable[[], Any], timeout: float = 5.0, interval: float = 0.01, what: str = ""
) -> Any:
    """Poll ``predicate`` until it returns something truthy; fail with ``what`` after ``timeout``."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout}s waiting for {what or predicate}")
        time.sleep(interval)


def answer_event(client: paho.Client, topic_name: str, body: Any) -> bool:
    """Answer an event that asks for it (``need_reply``) as a real cloud does; True if it did."""
    if not (topic_name.endswith("/events") and isinstance(body, dict) and body.get("need_reply") == 1):
        return False
    reply = {
        "tid": body.get("tid"),
        "bid": body.get("bid"),
        "timestamp": int(time.time() * 1000),
        "method": body.get("method"),
        "data": {"result": 0},
    }
    client.publish(topic_name + "_reply", json.dumps(reply), qos=1)
    return True


class CloudClient:
    """What a cloud platform does: publish services, read replies, osd, state, events and topology."""

    def __init__(
        self,
        url_host: str,
        port: int,
        gateway_sn: str,
        *,
        client_id: str | None = None,
        answer_events: bool = True,
        username: str | None = None,
        password: str | None = None,
    ) -> None:
        self.gateway_sn = gateway_sn
        self.answer_events = answer_events  # a real cloud answers events that carry need_reply
        self.messages: list[tuple[str, dict[str, Any] | None, bytes]] = []
        self._lock = threading.Lock()
        self._new = threading.Condition(self._lock)
        self.client = paho.Client(
            CallbackAPIVersion.VERSION2, client_id=client_id or f"cloud-{uuid.uuid4().hex[:8]}"
        )
        if username is not None:  # a broker with passwords and ACLs (the compose stack's mosquitto)
            self.client.username_pw_set(username, password)
        self.client.on_message = self._on_message
        self._subscribed = threading.Event()
        self.client.on_subscribe = lambda *a: self._subscribed.set()
        self.client.connect(url_host, port, keepalive=30)
        self.client.loop_start()
        self.client.subscribe([("thing/product/#", 1), ("sys/product/#", 1)])
        if not self._subscribed.wait(5):
            raise AssertionError("cloud client could not subscribe")

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
        close_client(self.client)

    def _on_message(self, client: paho.Client, userdata: Any, msg: paho.MQTTMessage) -> None:
        try:
            body = json.loads(msg.payload)
        except ValueError:
            body = None
        with self._new:
            self.messages.append((msg.topic, body, bytes(msg.payload)))
            self._new.notify_all()
        if self.answer_events:
            answer_event(client, msg.topic, body)

    def publish(self, topic: str, payload: bytes | str | dict[str, Any], qos: int = 1) -> None:
        if isinstance(payload, dict):
            payload = json.dumps(payload)
        self.client.publish(topic, payload, qos=qos).wait_for_publish(5)

    def mark(self) -> int:
        """A point in what has been received: ``find(..., since=mark)`` sees only what came after it
        (unlike :meth:`clear`, which also forgets what other waits still look for). A clear voids marks."""
        with self._lock:
            return len(self.messages)

    def find(
        self, suffix: str, predicate: Callable[[dict[str, Any]], bool] = lambda b: True, since: int = 0
    ) -> list[dict[str, Any]]:
        with self._lock:
            return [
                b
                for t, b, _ in self.messages[since:]
                if t.endswith(suffix) and b is not None and predicate(b)
            ]

    def wait_for(
        self,
        suffix: str,
        predicate: Callable[[dict[str, Any]], bool] = lambda b: True,
        timeout: float = 5.0,
        count: int = 1,
    ) -> list[dict[str, Any]]:
        deadline = time.monotonic() + timeout
        with self._new:
            while True:
                found = [
                    b for t, b, _ in self.messages if t.endswith(suffix) and b is not None and predicate(b)
                ]
                if len(found) >= count:
                    return found
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(
                        f"no {count} message(s) on *{suffix} within {timeout}s; got {len(found)}"
                    )
                self._new.wait(left)

    def service(
        self,
        method: str,
        data: dict[str, Any] | None = None,
        *,
        tid: str | None = None,
        timeout: float = 10.0,
    ) -> dict[str, Any]:
        """Publish one service and return its reply (matched by tid)."""
        tid = tid or str(uuid.uuid4())
        bid = str(uuid.uuid4())
        msg = {
            "tid": tid,
            "bid": bid,
            "timestamp": int(time.time() * 1000),
            "method": method,
            "data": data or {},
        }
        self.publish(f"thing/product/{self.gateway_sn}/services", msg)
        reply = self.wait_for("services_reply", lambda b: b.get("tid") == tid, timeout=timeout)[-1]
        assert reply["bid"] == bid and reply["method"] == method, reply
        return reply

    def clear(self) -> None:
        with self._lock:
            self.messages.clear()


class GatewayThread:
    """The real gateway (GatewayApp) on its own event loop in a background thread."""

    def __init__(
        self, settings: GatewaySettings, adapters: Sequence[Adapter] | None = None, clock: Clock | None = None
    ) -> None:
        self.settings = settings
        self._adapters = adapters
        self._clock = clock
        self.app: GatewayApp | None = None
        self.loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._main, name="gateway", daemon=True)

    def _main(self) -> None:
        try:
            asyncio.run(self._run())
        except BaseException as exc:  # surfaced by start()/stop()
            self._error = exc
            self._ready.set()

    async def _run(self) -> None:
        self.loop = asyncio.get_running_loop()
        self.app = GatewayApp(self.settings, adapters=self._adapters, clock=self._clock)
        task = asyncio.create_task(self.app.run())
        await self.app.started.wait()
        self._ready.set()
        await task

    def start(self, connected: bool = True) -> GatewayThread:
        self._thread.start()
        if not self._ready.wait(10):
            raise AssertionError("gateway did not start")
        if self._error:
            raise self._error
        if connected:
            # subscribed, not just connected: a service published before the broker acknowledged the
            # SUBSCRIBE would reach nobody (seen once in CI: a test's first request got no reply)
            wait_until(
                lambda: self.app and self.app.bridge and self.app.bridge.subscribed,
                10,
                what="broker connection and subscriptions",
            )
        return self

    def call(self, fn: Callable[[], Any], timeout: float = 5.0) -> Any:
        """Run ``fn`` on the gateway's loop and return its result."""
        assert self.loop is not None
        done: queue.Queue[Any] = queue.Queue()
        self.loop.call_soon_threadsafe(lambda: done.put(fn()))
        return done.get(timeout=timeout)

    def stop(self, timeout: float = 10.0) -> None:
        if self.app is not None and self.loop is not None and self._thread.is_alive():
            self.loop.call_soon_threadsafe(self.app.stop)
        self._thread.join(timeout)
        if self._thread.is_alive():
            raise AssertionError("gateway did not stop")
        if self._error:
            raise self._error

    def __enter__(self) -> GatewayThread:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def gateway_settings(broker_port: int, devices: list[dict[str, Any]], **extra: Any) -> GatewaySettings:
    doc: dict[str, Any] = {
        "gateway_sn": extra.pop("gateway_sn", "GW-TEST-1"),
        # a client id of its own: a gateway left over from a failed test must not fight this one
        "broker": {
            "url": f"mqtt://127.0.0.1:{broker_port}",
            "reconnect_min": 0.2,
            "reconnect_max": 1.0,
            "client_id": f"djigw-test-{uuid.uuid4().hex[:8]}",
        },
        "devices": devices,
        "osd_period": extra.pop("osd_period", 0.2),
        # in-process gateways share a machine: no fixed metrics port unless a test asks for one
        "metrics": {"enabled": False},
    }
    for key, value in extra.items():
        doc[key] = (
            {**doc[key], **value} if isinstance(value, dict) and isinstance(doc.get(key), dict) else value
        )
    return load_settings(None, **doc)


class BusSniffer:
    """Listens on the same virtual CAN channel and decodes what the gateway sends to the gimbal."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.rx = Reassembler(rx_id=HOST_TX_ID)
        self.commands: list[tuple[str, dict[str, Any]]] = []
        #: when each command was sent, on time.monotonic()'s scale: the virtual bus stamps a frame with
        #: time.time() as it is sent, so a sniffer thread that runs late (a loaded machine) dates it right
        self.times: list[float] = []
        self.cmd_types: list[int] = []  # each command's CmdType reply type (0: no reply wanted)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self.bus.recv(0.02)
            if msg is None:
                continue
            for item in self.rx.feed(msg.arbitration_id, bytes(msg.data)):
                if isinstance(item, Frame) and not item.is_reply:
                    m = decode_message(item)
                    self.times.append(time.monotonic() - (time.time() - msg.timestamp))
                    self.cmd_types.append(item.cmd_type)
                    self.commands.append((m.name, m.fields))

    def cmd_type_of(self, name: str) -> int:
        """The CmdType of the latest ``name`` command heard."""
        for (n, _), cmd_type in zip(
            reversed(list(self.commands)), reversed(list(self.cmd_types)), strict=False
        ):
            if n == name:
                return cmd_type
        raise AssertionError(f"no {name} heard")

    def names(self) -> Counter[str]:
        return Counter(name for name, _ in list(self.commands))

    def last(self, name: str, predicate: Any = None, timeout: float = 5.0) -> dict[str, Any]:
        """The latest ``name`` command seen on the bus (waiting until one matches ``predicate``): the
        sniffer hears the bus independently of the gimbal, so it may lag the reply by a moment."""

        def find() -> dict[str, Any] | None:
            for n, f in reversed(list(self.commands)):
                if n == name:
                    return f if predicate is None or predicate(f) else None
            return None

        return wait_until(find, timeout, what=f"{name} on the bus")

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)
        self.bus.shutdown()


class FakeAdapter(Adapter):
    """A device with no wire, for tests of the layers above the adapters (dispatcher, service):
    always online, each method answered by the coroutine the test gives. Subclass it for a fake
    that keeps state (calls counted, answers held back)."""

    def __init__(
        self,
        sn: str,
        payload_index: str,
        handlers: Mapping[str, Handler],
        *,
        osd: Mapping[str, Any] | None = None,
    ) -> None:
        self.info = DeviceInfo(sn=sn, domain="1", type=20, sub_type=0, payload_index=payload_index)
        self.handlers = dict(handlers)
        self._osd = osd

    @staticmethod
    async def ok(data: Any) -> CallResult:
        """A method the fake device does at once."""
        return CallResult()

    @property
    def online(self) -> bool:
        return True

    async def start(self, sink: TelemetrySink) -> None:
        sink.online_changed(self.info.sn, True)

    async def stop(self) -> None:
        return None

    async def stop_motion(self) -> None:
        return None

    def osd_snapshot(self) -> Mapping[str, Any] | None:
        return self._osd


def live_drc_session(drc: Any) -> int:
    """Put a (not started) DrcController into a live session on its main link, as a drc_mode_enter
    that succeeded would, without a loop: for harnesses that feed drc/down directly. Returns the
    session id that drc/down messages must name."""
    from gateway import drc_session as ds

    now = drc.now()
    drc.session.handle(ds.Enter(now, None, ds.LinkSpec("main", False)))
    sid = drc.session.session_id
    drc._links[sid] = None
    drc.refresh_targets()
    drc.session.handle(ds.LinkUp(now, sid))
    return int(sid)


class RecordingOutbox:
    """An MQTT bridge stand-in that keeps what is published (topic, payload), for tests of the layers
    above paho that need no broker."""

    def __init__(self) -> None:
        self.sent: list[tuple[str, bytes]] = []

    def publish(self, topic: str, payload: bytes, qos: int = 1, retain: bool = False) -> bool:
        self.sent.append((topic, payload))
        return True

    def payloads(self) -> list[bytes]:
        return [p for _, p in self.sent]


def drc_controller(devices: Any, outbox: RecordingOutbox, loop: Any, gateway_sn: str = "GW-TEST-1") -> Any:
    """A DrcController over ``devices`` whose main link is ``outbox`` (not started: no writer thread
    until the test calls ``start()``; ``live_drc_session`` puts it in a session)."""
    from gateway.app import build_registry
    from gateway.drc import DrcController
    from gateway.metrics import Metrics

    return DrcController(
        settings=gateway_settings(1, [], gateway_sn=gateway_sn),
        registry=build_registry(),
        devices=devices,
        metrics=Metrics(),
        loop=loop,
        main_bridge=outbox,
        publish_event=lambda *a: None,
        publish_gateway_osd=lambda d: None,
    )


class DrcSticks:
    """The cloud's live-control side: sticks at 20 Hz, heartbeats at 5 Hz on ``drc/down``, whatever the
    broker's or the link's state (publishes while it is down are simply lost, as on a real link)."""

    def __init__(self, client: paho.Client, gateway_sn: str, yaw_rate: float) -> None:
        self.client, self.down, self.yaw_rate = client, f"thing/product/{gateway_sn}/drc/down", yaw_rate
        self.seq = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="test-sticks", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        n = 0
        while not self._stop.wait(0.05):
            n += 1
            self.seq += 1
            body = {"method": "drone_control", "data": {"seq": self.seq, "w": self.yaw_rate}}
            self.client.publish(self.down, json.dumps(body), qos=0)
            if n % 4 == 0:
                beat = {"method": "heart_beat", "data": {"seq": self.seq, "timestamp": self.seq}}
                self.client.publish(self.down, json.dumps(beat), qos=0)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2)


class Proc:
    """A child process with its output collected by a thread."""

    def __init__(
        self, name: str, argv: list[str], env: dict[str, str], cwd: str | Path | None = None
    ) -> None:
        self.name = name
        self.lines: list[str] = []
        self.proc = subprocess.Popen(
            argv,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
            start_new_session=True,
            cwd=cwd,
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def wait_for_line(self, pattern: str, timeout: float = 10.0) -> re.Match[str]:
        regex = re.compile(pattern)

        def find() -> re.Match[str] | None:
            if self.proc.poll() is not None and not self._reader.is_alive():
                raise AssertionError(f"{self.name} exited: {self.output()[-1500:]}")
            return next((m for line in list(self.lines) if (m := regex.search(line))), None)

        return wait_until(find, timeout, what=f"{pattern!r} from {self.name}")

    def output(self) -> str:
        return "\n".join(self.lines)

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 15.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self._reader.join(5)
        if self.proc.stdout:
            self.proc.stdout.close()
        return int(self.proc.returncode)


def simulated_gateway(broker_url: str, **env: str) -> tuple[Proc, str]:
    """``dji-gateway run --simulate`` as its own process (``DJIGW_*`` from ``env`` only), its HTTP endpoint
    on any free port: the process, once its three devices run, and the endpoint's URL."""
    import os
    import sys
    from pathlib import Path

    clean = {k: v for k, v in os.environ.items() if not k.startswith("DJIGW_")}
    argv = [
        str(Path(sys.executable).parent / "dji-gateway"),
        "run",
        "--simulate",
        "--broker",
        broker_url,
        "--metrics-port",
        "0",
    ]
    proc = Proc("gateway", argv, {**clean, **env, "PYTHONUNBUFFERED": "1"})
    try:
        port = proc.wait_for_line(r"metrics on http://127\.0\.0\.1:(\d+)/metrics", 20).group(1)
        proc.wait_for_line(r"running with 3 device\(s\)", 20)
    except BaseException:
        proc.stop()
        raise
    return proc, f"http://127.0.0.1:{port}"
