"""The broker connection: owns paho-mqtt, its network thread and the thread that keeps it connected.

Received messages are handed to the asyncio loop with ``call_soon_threadsafe`` and land in a
bounded queue; when it is full the message is dropped, counted and logged, so a flood never
blocks paho's thread (a blocked thread would delay every heartbeat and reply). Subscriptions are
made in the connect callback, so a broker restart that forgot them is healed; when the CONNACK says the
broker kept the session this bridge already subscribed on, they are not made again (on NATS each costs a
JetStream request that blocks the connection while a leader is elected): the liveness probe proves the
kept subscriptions work, and a deaf link resubscribes. The
``on_connected`` hook (``update_topo``, ``state``) runs in the loop after each (re)connect.

Threads: one *supervisor* per bridge (``mqtt-<name>``) finds a broker node and connects (TCP probes
to every ``broker.url``, then paho's ``connect``), starts paho's network thread for that one
connection, watches it (a connection whose data TCP keeps retransmitting is *stalled*: it is dropped
as soon as a probe finds a node answering, or after ``broker.stall_timeout``, and the osd written to it
after its last ACK goes back into the buffer; a connection that does not *receive*, its own probe not
coming back, is *deaf*: resubscribed, then dropped, see :class:`gateway.broker_link.LivenessProbe`) and,
when it ends, asks
:class:`gateway.broker_link.ReconnectPolicy` when and where to go next. paho's own
reconnect is off: the policy decides (failover across nodes, probing, backoff, client-id takeover).
QoS 1 messages published meanwhile wait in paho's queue and go out after the next CONNACK, on
whichever node; osd (the topics ``buffered`` selects, QoS 0) waits in a bounded
:class:`gateway.broker_link.OfflineBuffer` and is delivered in order after ``on_connected``.
Knows topics only as strings; no Cloud API semantics.

Why this module is longer than 500 lines: it owns one broker connection's whole life (probe, connect, watch
for stalls, lose, buffer, fail over) across two threads whose hand-offs must be read together; the decisions
already live in the sans-I/O broker_link.py and the paho internals in pahocompat.py.
"""

from __future__ import annotations

import asyncio
import contextlib
import errno
import logging
import os
import random
import select
import socket
import ssl
import struct
import threading
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion, MQTTProtocolVersion
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties
from paho.mqtt.reasoncodes import ReasonCode

from gateway import pahocompat
from gateway.broker_link import LivenessProbe, Loss, OfflineBuffer, ProbeStep, ReconnectPolicy
from gateway.clock import SYSTEM_CLOCK, Clock
from gateway.metrics import Metrics
from gateway.settings import BrokerEndpoint, BrokerSettings

log = logging.getLogger(__name__)

__all__ = [
    "Inbound",
    "MqttBridge",
    "close_client",
    "probe_topic_for",
    "tcp_last_ack_age",
    "tcp_stalled",
    "tcp_unacked",
]

#: How long sent osd is remembered, to be sent again if its connection turns out to have been dead.
RECENT_WINDOW = 10.0
#: MQTT 5 DISCONNECT reason: another connection with the same client id took the session over.
SESSION_TAKEN_OVER = 0x8E


@dataclass(frozen=True, slots=True)
class Inbound:
    """One received message as the loop sees it. ``oversize`` payloads are truncated to a prefix
    (enough to read a ``tid`` for the error reply) and never parsed."""

    topic: str
    payload: bytes
    oversize: bool = False


def probe_topic_for(client_id: str) -> str:
    """The topic a link's liveness probe travels on: private to the client id (wildcards and levels
    in the id are flattened, so it is one plain topic)."""
    safe = "".join("_" if c in "+#/" else c for c in client_id) or "_"
    return f"djigw/{safe}/probe"


def close_client(client: paho.Client) -> None:
    """Release the sockets paho keeps after ``loop_stop`` (its wake-up socket pair stays open until the
    client object is collected, which a reference cycle can delay: an unclosed-socket warning later)."""
    pahocompat.release_sockets(client)


@contextlib.contextmanager
def _plain_socket(sock: Any) -> Iterator[socket.socket | None]:
    """The TCP connection under ``sock`` (a plain socket, an ``SSLSocket`` or paho's websocket wrapper) as
    a plain ``socket.socket`` on a duplicate of its descriptor, through the public ``fileno()`` only:
    options and ``shutdown`` act on the connection itself, and closing the duplicate leaves it open.
    None where there is no descriptor."""
    try:
        fd = int(sock.fileno())
        dup = socket.socket(fileno=os.dup(fd))
    except (AttributeError, OSError, ValueError, TypeError):
        yield None
        return
    try:
        yield dup
    finally:
        dup.close()


def _tcp_info(sock: Any) -> bytes | None:
    """Linux ``TCP_INFO`` of the connection (``struct tcp_info``), or None where there is none."""
    opt = getattr(socket, "TCP_INFO", None)
    if sock is None or opt is None:
        return None
    with _plain_socket(sock) as raw:
        if raw is None:
            return None
        try:
            info = raw.getsockopt(socket.IPPROTO_TCP, opt, 104)
        except OSError:
            return None
    return info if len(info) >= 60 else None


def tcp_stalled(sock: Any) -> bool:
    """True when TCP has retransmitted the oldest unacknowledged segment at least twice without an
    ACK (``tcpi_retransmits`` ≥ 2 with data in flight, ``tcpi_unacked``): the path is down, or was, and
    the connection now waits out a retransmission timer that doubles each time. False where
    ``TCP_INFO`` does not exist."""
    info = _tcp_info(sock)
    if info is None:
        return False
    (unacked,) = struct.unpack_from("I", info, 24)
    return info[2] >= 2 and unacked > 0


def tcp_unacked(sock: Any) -> bool:
    """True when data written to ``sock`` is not acknowledged by the peer's TCP yet (``tcpi_unacked``);
    False where ``TCP_INFO`` does not exist."""
    info = _tcp_info(sock)
    if info is None:
        return False
    (unacked,) = struct.unpack_from("I", info, 24)
    return bool(unacked > 0)


def tcp_last_ack_age(sock: Any) -> float | None:
    """Seconds since TCP last received an ACK on ``sock`` (``tcpi_last_ack_recv``); None if unknown."""
    info = _tcp_info(sock)
    if info is None:
        return None
    (ms,) = struct.unpack_from("I", info, 56)
    return float(ms) / 1000.0


def _leave_writing_to_the_network_thread(client: paho.Client, userdata: Any, sock: Any) -> None:
    """paho's ``socket_register_write`` hook while no network thread runs: its being set is what matters
    (paho then queues a publish instead of writing it from the caller's thread); the thread, once started,
    writes what is queued."""


class _Prober:
    """Non-blocking TCP connects to broker nodes: a round launches one per node; :meth:`poll` reports
    the nodes whose connect completed. Each probe lives ``timeout`` seconds. Only its own sockets."""

    def __init__(self, endpoints: tuple[BrokerEndpoint, ...], timeout: float) -> None:
        self.endpoints, self.timeout = endpoints, timeout
        self._pending: list[tuple[float, int, socket.socket]] = []
        self.errors: dict[int, str] = {}

    def launch(self, now: float) -> None:
        for index, ep in enumerate(self.endpoints):
            try:
                family, kind, proto, _, addr = socket.getaddrinfo(ep.host, ep.port, type=socket.SOCK_STREAM)[
                    0
                ]
                sock = socket.socket(family, kind, proto)
            except OSError as exc:
                self.errors[index] = f"cannot resolve {ep.host}: {exc.strerror or exc}"
                continue
            sock.setblocking(False)
            err = sock.connect_ex(addr)
            if err in (0, errno.EINPROGRESS, errno.EWOULDBLOCK):
                self._pending.append((now, index, sock))
            else:
                self.errors[index] = os.strerror(err)
                sock.close()

    def poll(self, now: float, timeout: float) -> set[int]:
        """Wait up to ``timeout`` for probes to finish; the nodes that accepted a connection."""
        answered: set[int] = set()
        keep: list[tuple[float, int, socket.socket]] = []
        for started, index, sock in self._pending:
            if now - started > self.timeout:
                self.errors[index] = "no answer (timed out)"
                sock.close()
            else:
                keep.append((started, index, sock))
        self._pending = keep
        if not keep:
            if timeout > 0:
                time.sleep(timeout)  # the supervisor thread's real wait (see the bridge's clock note)
            return answered
        try:
            _, writable, _ = select.select([], [s for _, _, s in keep], [], timeout)
        except (OSError, ValueError):
            writable = []
        rest: list[tuple[float, int, socket.socket]] = []
        for started, index, sock in keep:
            if sock not in writable:
                rest.append((started, index, sock))
                continue
            err = sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)
            if err == 0:
                answered.add(index)
            else:
                self.errors[index] = os.strerror(err)
            sock.close()
        self._pending = rest
        return answered

    def close(self) -> None:
        for _, _, sock in self._pending:
            sock.close()
        self._pending = []


class MqttBridge:
    """One paho client, kept connected to one of the configured broker nodes, feeding an asyncio queue."""

    def __init__(
        self,
        settings: BrokerSettings,
        *,
        client_id: str,
        subscriptions: list[tuple[str, int]],
        loop: asyncio.AbstractEventLoop,
        metrics: Metrics,
        on_connected: Callable[[], None] | None = None,
        name: str = "main",
        inline: Callable[[str, bytes], bool] | None = None,
        on_disconnected: Callable[[str], None] | None = None,
        buffered: Callable[[str], bool] | None = None,
        clock: Clock = SYSTEM_CLOCK,
        rng: random.Random | None = None,
        probe_topic: str | None = None,
    ) -> None:
        self.settings = settings
        self.client_id = client_id
        self.subscriptions = list(subscriptions)
        self.queue: asyncio.Queue[Inbound] = asyncio.Queue(maxsize=settings.inbound_queue)
        self.endpoints = settings.endpoints
        self._loop = loop
        self._metrics = metrics
        # The callbacks, given here or assigned before :meth:`start` (as paho's are), once the objects
        # they call exist. ``on_connected`` runs in the loop after each (re)connect. ``inline`` sees every
        # message in the network thread first and may consume it (returns True): DRC heartbeats and
        # sticks are answered there, so a busy event loop cannot delay them. ``on_disconnected`` runs in
        # the network thread when an established connection is lost.
        self.on_connected: Callable[[], None] | None = on_connected
        self.inline: Callable[[str, bytes], bool] | None = inline
        self.on_disconnected: Callable[[str], None] | None = on_disconnected
        self._buffered = buffered  # QoS 0 topics kept in the offline buffer (osd); None: none
        self._name = name
        # the gateway's clock, read by this bridge's threads; their waits are real (Event.wait): a
        # supervisor on a ManualClock polls every 0.5 s until the clock is advanced
        self._clock = clock.monotonic
        self.clock = clock
        self.policy = ReconnectPolicy(
            len(self.endpoints),
            reconnect_min=settings.reconnect_min,
            reconnect_max=settings.reconnect_max,
            probe_interval=settings.probe_interval,
            takeover_backoff_max=settings.takeover_backoff_max,
            rng=rng,
        )
        self._buffer = OfflineBuffer(settings.telemetry_buffer, settings.telemetry_buffer_age)
        # the end-to-end receive check: the probe rides the subscriptions' own QoS (a QoS 1 probe crosses
        # the broker's persistent-session path, e.g. JetStream on NATS, as requests do); no subscriptions:
        # nothing to be deaf to
        self.probe_topic = probe_topic or probe_topic_for(client_id)
        self._probe_qos = max((q for _, q in self.subscriptions), default=0)
        self.liveness = LivenessProbe(
            interval=settings.liveness_interval if self.subscriptions else 0.0,
            timeout=settings.liveness_timeout,
            rng=rng,
        )
        self._probe_lock = threading.Lock()  # the supervisor steps it, the network thread answers it
        self._traffic_at: float | None = None  # when the broker last delivered a message (not a probe)
        self._buffer_lock = threading.Lock()
        # paho writes a byte to its wake-up socket pair on every publish and disconnect, from the caller's
        # thread; the supervisor closes that pair after each connection (pahocompat.release_sockets). This
        # lock keeps the two apart: unguarded, a publish racing the close raised EBADF out of publish()
        self._wake_lock = threading.Lock()
        # buffered-topic messages recently handed to the socket: when a stalled connection is given up,
        # those sent after its last ACK never arrived, and go back into the buffer (oldest first)
        self._recent: deque[tuple[float, str, bytes]] = deque(maxlen=max(1, settings.telemetry_buffer))
        self._drops_counted = (0, 0)
        self._subscribed = threading.Event()  # set once the broker acknowledged every subscription
        self._subscribed_once = False  # this bridge's subscriptions were acknowledged on its session once
        self._sub_mid: int | None = None
        self._dropped_logged = 0
        self.last_refusal: str | None = None  # the broker's reason for refusing the last CONNECT
        self.last_error: str | None = None  # why the last connection attempt failed (TCP/TLS), if known
        self.current: BrokerEndpoint | None = None  # the node of the current (or last) connection
        self.stalled = False  # connected, but TCP keeps retransmitting: telemetry goes to the buffer
        self._stop = threading.Event()
        self._done = threading.Event()  # the current connection ended (paho's on_disconnect)
        self._connack = threading.Event()
        self._refused = False
        self._refused_busy = False
        self._aborting = False
        self._loss = Loss.CLOSED
        self._session_live = False  # CONNACK accepted on the current connection
        self._had_session = False  # a CONNACK was ever accepted: later connections resume the session
        self._failing_since: float | None = None  # first failed attempt of the current streak
        self._supervisor: threading.Thread | None = None
        self._ssl: ssl.SSLContext | None = None
        self._client = self._build_client()

    # -- set-up ---------------------------------------------------------------------------------
    def _build_client(self) -> paho.Client:
        s = self.settings
        v5 = s.protocol == "5"
        client = paho.Client(
            CallbackAPIVersion.VERSION2,
            client_id=self.client_id,
            protocol=MQTTProtocolVersion.MQTTv5 if v5 else MQTTProtocolVersion.MQTTv311,
            transport=s.transport,
            clean_session=None if v5 else False,
            reconnect_on_failure=False,  # the supervisor decides when and where (failover, takeover)
        )
        if s.transport == "websockets":
            client.ws_set_options(path=s.ws_path)
        if s.username is not None:
            client.username_pw_set(s.username, s.password.get_secret_value() if s.password else None)
        if s.tls:
            self._ssl = self._ssl_context()
            client.tls_set_context(self._ssl)
        client.max_queued_messages_set(10000)
        client.connect_timeout = s.connect_timeout
        client.on_connect = self._on_connect
        client.on_disconnect = self._on_disconnect
        client.on_message = self._on_message
        client.on_subscribe = self._on_subscribe
        client.on_socket_open = self._on_socket_open
        return client

    def _ssl_context(self) -> ssl.SSLContext:
        """The broker's certificate is always verified (the system's CAs or ``ca_file``); the hostname
        check can be turned off for brokers addressed by an IP their certificate does not name."""
        s = self.settings
        try:
            ctx = ssl.create_default_context(cafile=str(s.ca_file) if s.ca_file else None)
            if s.cert_file is not None:
                ctx.load_cert_chain(str(s.cert_file), str(s.key_file) if s.key_file else None)
        except (OSError, ssl.SSLError) as exc:
            raise ValueError(f"broker TLS files: {exc}") from None
        ctx.check_hostname = s.tls_hostname_check
        return ctx

    def set_will(self, topic: str, payload: bytes) -> None:
        """The message the broker publishes if the gateway vanishes (must precede :meth:`start`)."""
        self._client.will_set(topic, payload, qos=1, retain=False)

    def start(self) -> None:
        self._stop.clear()
        self._supervisor = threading.Thread(target=self._supervise, name=f"mqtt-{self._name}", daemon=True)
        self._supervisor.start()

    @property
    def connected(self) -> bool:
        return self._client.is_connected()

    @property
    def deaf(self) -> bool:
        """A liveness probe missed its deadline and none has come back since (on this node or another)."""
        return self.liveness.deaf

    @property
    def takeover_suspected(self) -> bool:
        """Another client seems to use our client id (see :class:`gateway.broker_link.ReconnectPolicy`)."""
        return self.policy.takeover_suspected

    @property
    def buffered(self) -> int:
        """Telemetry messages waiting in the offline buffer."""
        return len(self._buffer)

    def publish(self, topic: str, payload: bytes, qos: int = 1, retain: bool = False) -> bool:
        """Queue a message; paho writes it from this thread at once when connected. QoS 1 messages
        published while disconnected wait in paho's queue and go out after the reconnect; osd (the
        ``buffered`` topics) waits in the offline buffer while the link is down or stalled."""
        if qos == 0 and self._buffered is not None and self._buffered(topic):
            with self._buffer_lock:
                if self.stalled or not self.connected or len(self._buffer):
                    self._buffer.add(self._clock(), topic, payload)
                    self._count_buffer()
                    if not self.stalled and self.connected:
                        self._flush_locked()
                    return True
                self._remember(topic, payload)
        return self._send(topic, payload, qos, retain)

    def _remember(self, topic: str, payload: bytes) -> None:
        now = self._clock()
        recent = self._recent
        while recent and now - recent[0][0] > RECENT_WINDOW:
            recent.popleft()
        recent.append((now, topic, payload))

    def _paho_publish(
        self, topic: str, payload: bytes, qos: int, retain: bool = False
    ) -> paho.MQTTMessageInfo:
        with self._wake_lock:
            return self._client.publish(topic, payload, qos=qos, retain=retain)

    def _paho_disconnect(self) -> None:
        with self._wake_lock:
            self._client.disconnect()

    def _release_sockets(self, *, sockpair_only: bool) -> None:
        with self._wake_lock:
            pahocompat.release_sockets(self._client, sockpair_only=sockpair_only)

    def _send(self, topic: str, payload: bytes, qos: int, retain: bool) -> bool:
        info = self._paho_publish(topic, payload, qos, retain)
        ok = info.rc == paho.MQTT_ERR_SUCCESS or (qos > 0 and info.rc == paho.MQTT_ERR_NO_CONN)
        if not ok:
            self._metrics.inc("mqtt_publish_errors_total", link=self._name)
        else:
            self._metrics.inc("mqtt_messages_out_total", link=self._name)
        return ok

    def flush(self) -> int:
        """Send what the offline buffer holds, oldest first (after a reconnect); the number sent."""
        with self._buffer_lock:
            return self._flush_locked()

    def _flush_locked(self) -> int:
        if self.stalled or not self.connected:
            return 0
        items = self._buffer.take(self._clock())
        for n, (_, topic, payload) in enumerate(items):
            info = self._paho_publish(topic, payload, 0)
            if info.rc != paho.MQTT_ERR_SUCCESS:  # the link dropped again: keep the rest, in order
                self._buffer.put_back(items[n:])
                if n:
                    self._metrics.inc("telemetry_delivered_late_total", n, link=self._name)
                self._count_buffer()
                return n
            self._remember(topic, payload)
            self._metrics.inc("mqtt_messages_out_total", link=self._name)
        if items:
            self._metrics.inc("telemetry_delivered_late_total", len(items), link=self._name)
        self._count_buffer()
        return len(items)

    def _count_buffer(self) -> None:
        overflow, age = self._buffer.dropped_overflow, self._buffer.dropped_age
        before_overflow, before_age = self._drops_counted
        if overflow > before_overflow:
            self._metrics.inc("telemetry_dropped_total", overflow - before_overflow, reason="overflow")
        if age > before_age:
            self._metrics.inc("telemetry_dropped_total", age - before_age, reason="age")
        self._drops_counted = (overflow, age)
        self._metrics.set("telemetry_buffered", len(self._buffer), link=self._name)

    def stop(self, last: tuple[str, bytes] | None = None, timeout: float = 2.0) -> None:
        """Publish ``last`` (the clean offline message), wait for it briefly, disconnect."""
        self._stop.set()
        if last is not None and self._client.is_connected():
            info = self._paho_publish(last[0], last[1], 1)
            try:
                info.wait_for_publish(timeout)
            except (RuntimeError, ValueError):
                log.warning("offline message not delivered before shutdown")
        self._paho_disconnect()
        if self._supervisor is not None:
            self._supervisor.join(timeout + self.settings.connect_timeout + 2)
            self._supervisor = None
        self._client.loop_stop()
        self._release_sockets(sockpair_only=False)

    # -- the supervisor thread ------------------------------------------------------------------
    def _supervise(self) -> None:
        at = self._clock()
        while not self._stop.is_set():
            try:
                index = self._find_broker(at)
                if index is None:
                    return
                at = self._session(index)
            except Exception:  # never let the thread die: the gateway would stay offline for good
                self._metrics.inc("handler_exceptions_total", where=f"mqtt-supervisor:{self._name}")
                log.exception("broker supervisor (%s) failed; retrying", self._name)
                at = self._clock() + self.settings.reconnect_max

    def _sleep_until(self, at: float) -> bool:
        """Wait until ``at`` on the bridge's clock; False when stopping."""
        while not self._stop.is_set():
            left = at - self._clock()
            if left <= 0:
                return True
            self._stop.wait(min(left, 0.5))
        return False

    def _find_broker(self, start_at: float) -> int | None:
        """Probe every node from ``start_at`` until one accepts a TCP connection; its index."""
        if not self._sleep_until(start_at):
            return None
        prober = _Prober(self.endpoints, self.settings.connect_timeout)
        next_round = self._clock()
        rounds = 0
        try:
            while not self._stop.is_set():
                now = self._clock()
                if now >= next_round:
                    if rounds:  # the last round found nobody
                        self.policy.unreachable(now)
                    if rounds == 1 or (rounds and rounds % 600 == 0):
                        self._report_unreachable(prober.errors)
                    prober.launch(now)
                    rounds += 1
                    next_round = self.policy.next_round(now)
                answered = prober.poll(now, max(0.0, min(0.1, next_round - now)))
                if answered:
                    return self.policy.choose(answered)
            return None
        finally:
            prober.close()

    def _report_unreachable(self, errors: dict[int, str]) -> None:
        if self._failing_since is None:
            self._failing_since = self._clock()
        parts = [f"{self.endpoints[i].where()}: {why}" for i, why in sorted(errors.items())]
        reason = "cannot connect: " + ("; ".join(parts) if parts else "no answer")
        self.last_error = reason
        self._metrics.inc("mqtt_connect_failures_total", link=self._name)
        log.error(
            "broker (%s): %s; probing every %.2g s",
            self._name,
            reason,
            self.settings.probe_interval,
        )

    def _connect_kwargs(self) -> dict[str, Any]:
        s = self.settings
        kwargs: dict[str, Any] = {"keepalive": s.keepalive}
        if s.protocol == "5":
            props = Properties(PacketTypes.CONNECT)  # type: ignore[no-untyped-call]  # paho: no annotations
            props.SessionExpiryInterval = s.session_expiry
            kwargs["properties"] = props
            # a fresh session when the process starts, the same session on every later connection (any
            # node): requests the broker queued meanwhile are delivered (paho's FIRST_ONLY would count
            # every connect() call as a first one)
            kwargs["clean_start"] = not self._had_session
        return kwargs

    def _session(self, index: int) -> float:
        """Connect to node ``index``, keep the connection until it ends; when to look for a broker next."""
        ep = self.endpoints[index]
        client = self._client
        self.current = ep
        self._done.clear()
        self._connack.clear()
        self._refused = False
        self._aborting = False
        self._loss = Loss.CLOSED
        self._session_live = False
        # while connect() runs in this thread and until paho's network thread runs, publishers elsewhere
        # only queue their packets: paho writes directly from the caller when it has no network thread (it
        # could write before the CONNECT) unless a socket_register_write callback is set (public API)
        client.on_socket_register_write = _leave_writing_to_the_network_thread
        started = False
        self.policy.attempt(index)
        try:
            client.connect(ep.host, ep.port, **self._connect_kwargs())
            started = True
        except ssl.SSLCertVerificationError as exc:
            return self._attempt_failed(
                ep, f"TLS: the broker's certificate was refused: {exc.verify_message}"
            )
        except ssl.SSLError as exc:
            return self._attempt_failed(ep, f"TLS handshake failed: {exc.reason or exc}")
        except OSError as exc:  # the node went away between the probe and the connect
            self.last_error = f"cannot connect: {exc.strerror or exc}"
            self._metrics.inc("mqtt_connect_failures_total", link=self._name)
            self.policy.unreachable(self._clock())
            return self.policy.next_round(self._clock())
        finally:
            if not started:
                client.on_socket_register_write = None
        client.loop_start()
        client.on_socket_register_write = None  # the network thread writes from now on
        try:
            return self._run_connection(ep)
        finally:
            client.loop_stop()
            self._release_sockets(sockpair_only=True)  # loop_start makes a new pair each time
            self.stalled = False

    def _attempt_failed(self, ep: BrokerEndpoint, reason: str, *, busy: bool = False) -> float:
        """The broker answered TCP but the connection failed (TLS, CONNACK): the next node, or back off
        (``busy``: the way a cluster that is not ready fails; see :meth:`ReconnectPolicy.refused`)."""
        self._metrics.inc("mqtt_connect_failures_total", link=self._name)
        if reason != self.last_error:
            log.error("broker %s (%s): %s", ep.where(), self._name, reason)
        self.last_error = reason
        pahocompat.close_network_socket(self._client)
        return self.policy.refused(self._clock(), busy=busy)

    def _run_connection(self, ep: BrokerEndpoint) -> float:
        started = self._clock()
        quick = self.policy.connack_timeout(self.settings.connect_timeout)
        while not (self._connack.is_set() or self._done.is_set() or self._stop.is_set()):
            waited = self._clock() - started
            # past the quick deadline, wait on only while TCP has not delivered the CONNECT (a slow link):
            # a broker that has it and does not answer is left for the next node
            if waited > self.settings.connect_timeout or (
                waited > quick and not tcp_unacked(self._client.socket())
            ):
                self._abort()
                return self._attempt_failed(ep, f"no CONNACK within {waited:.2g} s", busy=True)
            self._connack.wait(0.02)
        if self._stop.is_set():
            self._close_for_stop()
            return self._clock()
        if self._refused or not self._connack.is_set():
            self._wait_done()
            if not self._refused:  # closed without a CONNACK (NATS while JetStream elects a leader): say so
                reason = "the broker closed the connection before its CONNACK"
                return self._attempt_failed(ep, reason, busy=True)
            return self.policy.refused(self._clock(), busy=self._refused_busy)
        connected_at = self._clock()
        self.policy.connected(connected_at, self.endpoints.index(ep))
        self._watch(ep)
        if self._stop.is_set():
            return self._clock()
        now = self._clock()
        was_suspected = self.policy.takeover_suspected
        at = self.policy.lost(now, lasted=now - connected_at, how=self._loss)
        if self.policy.takeover_suspected and not was_suspected:
            self._report_takeover()
        elif self.policy.takeover_suspected:
            self._metrics.inc("mqtt_takeovers_total", link=self._name)
        return at

    def _report_takeover(self) -> None:
        self._metrics.inc("mqtt_takeovers_total", link=self._name)
        self._metrics.set("mqtt_client_id_conflict", 1, link=self._name)
        how = (
            "the broker said the session was taken over (0x8E)"
            if self._loss is Loss.TAKEN_OVER
            else "the broker keeps closing the connection right after accepting it"
        )
        log.error(
            "broker (%s): another client with client id %r took over the connection: %s. Likely cause: "
            "two gateways with the same gateway_sn or broker.client_id (or a second copy of this one). "
            "Backing off (up to %.0f s); fix the duplicate",
            self._name,
            self.client_id,
            how,
            self.settings.takeover_backoff_max,
        )

    def _watch(self, ep: BrokerEndpoint) -> None:
        """Until the connection ends: every 50 ms look for a stall; while stalled, probe the nodes and
        drop the connection when one answers (the network is back, TCP's timer is not)."""
        prober: _Prober | None = None
        next_round = stalled_at = 0.0
        try:
            while not self._done.wait(0.05):
                if self._stop.is_set():
                    self._close_for_stop()
                    return
                stuck = tcp_stalled(self._client.socket())
                now = self._clock()
                if stuck and not self.stalled:
                    self.stalled = True
                    self._metrics.inc("mqtt_stalls_total", link=self._name)
                    log.warning("broker %s (%s): connection stalled; probing", ep.where(), self._name)
                    prober = _Prober(self.endpoints, self.settings.connect_timeout)
                    next_round = stalled_at = now
                elif not stuck and self.stalled:
                    self.stalled = False
                    log.info("broker %s (%s): the stalled connection recovered", ep.where(), self._name)
                    if prober is not None:
                        prober.close()
                        prober = None
                    self._in_loop(self.flush)
                if self.stalled and now - stalled_at > self.settings.stall_timeout:
                    log.warning("broker %s (%s): stalled for %.1f s: the link is lost; reconnecting",
                                ep.where(), self._name, now - stalled_at)  # fmt: skip
                    self._loss = Loss.STALLED
                    self._requeue_unacked()
                    self._abort()
                    self._wait_done()
                    return
                if self._probe_step(ep, now):
                    return
                if prober is not None:
                    if now >= next_round:
                        prober.launch(now)
                        next_round = self.policy.next_round(now)
                    if prober.poll(now, 0.0):
                        log.warning("broker (%s): a node answers again: dropping the stalled connection",
                                    self._name)  # fmt: skip
                        self._loss = Loss.STALLED
                        self._requeue_unacked()
                        self._abort()
                        self._wait_done()
                        return
        finally:
            if prober is not None:
                prober.close()

    # -- liveness (supervisor thread steps it, network thread answers it) --------------------------
    def _subscription_list(self) -> list[tuple[str, int]]:
        subs = list(self.subscriptions)
        if self.liveness.enabled:
            subs.append((self.probe_topic, self._probe_qos))
        return subs

    def _probe_step(self, ep: BrokerEndpoint, now: float) -> bool:
        """Advance the liveness probe; True when it gave the connection up (deaf twice)."""
        with self._probe_lock:
            was_deaf = self.liveness.deaf
            step = self.liveness.step(now, self._traffic_at)
            nonce = self.liveness.nonce
        if step is ProbeStep.NONE:
            return False
        if step is ProbeStep.SEND:
            self._paho_publish(self.probe_topic, nonce.encode(), self._probe_qos)
            return False
        if not was_deaf:
            self._metrics.inc("mqtt_deaf_total", link=self._name)
            self._metrics.set("mqtt_deaf", 1, link=self._name)
        if step is ProbeStep.RESUBSCRIBE:
            log.warning("broker %s (%s): deaf: our probe did not come back within %.2g s; resubscribing",
                        ep.where(), self._name, self.liveness.last_deadline)  # fmt: skip
            self._metrics.inc("mqtt_resubscribes_total", link=self._name)
            with self._wake_lock:
                _, self._sub_mid = self._client.subscribe(self._subscription_list())
            return False
        log.warning("broker %s (%s): still deaf after resubscribing; reconnecting (next node first)",
                    ep.where(), self._name)  # fmt: skip
        self._loss = Loss.DEAF
        self._abort()
        self._wait_done()
        return True

    def _probe_back(self, payload: bytes) -> None:
        with self._probe_lock:
            was_deaf = self.liveness.deaf
            ours = self.liveness.received(self._clock(), payload)
        if ours and was_deaf:
            self._metrics.set("mqtt_deaf", 0, link=self._name)
            log.info("broker %s (%s): receives again (probe back)", self._where(), self._name)

    def _requeue_unacked(self) -> None:
        """The stalled connection is given up: the buffered-topic messages written to it after its last
        ACK (50 ms of margin) did not arrive; they go back into the buffer ahead of what came later."""
        age = tcp_last_ack_age(self._client.socket())
        if age is None or self._buffered is None:
            return
        cut = self._clock() - age - 0.05
        with self._buffer_lock:
            lost = [(at, topic, payload) for at, topic, payload in self._recent if at >= cut]
            self._recent.clear()
            if lost:
                self._buffer.put_back(lost)
                self._count_buffer()
        if lost:
            self._metrics.inc("telemetry_requeued_total", len(lost), link=self._name)

    def _abort(self) -> None:
        """Drop the connection without a DISCONNECT (it is stuck or never answered): paho's thread sees
        the socket end and reports the loss."""
        self._aborting = True
        with _plain_socket(self._client.socket()) as raw, contextlib.suppress(OSError):
            if raw is not None:
                raw.shutdown(socket.SHUT_RDWR)  # the TCP connection's, also under TLS

    def _close_for_stop(self) -> None:
        """Stopping: end the connection with a DISCONNECT (:meth:`stop` may have sent it already)."""
        self._paho_disconnect()
        self._wait_done()

    def _wait_done(self) -> None:
        if not self._done.wait(self.settings.connect_timeout):
            log.warning("broker (%s): the network thread did not end the connection in time", self._name)

    def _in_loop(self, fn: Callable[[], Any]) -> None:
        with contextlib.suppress(RuntimeError):  # the loop closed during shutdown
            self._loop.call_soon_threadsafe(fn)

    # -- paho callbacks (network thread) --------------------------------------------------------
    def _on_socket_open(self, client: paho.Client, userdata: Any, sock: paho.SocketLike) -> None:
        with _plain_socket(sock) as raw:
            try:
                if raw is None:
                    raise AttributeError("no socket")
                raw.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            except (OSError, AttributeError):
                log.debug("could not set TCP_NODELAY on %r", type(sock).__name__)

    def _on_connect(
        self,
        client: paho.Client,
        userdata: Any,
        flags: paho.ConnectFlags,
        reason: ReasonCode,
        props: Properties | None,
    ) -> None:
        if reason.is_failure:
            self.last_refusal = str(reason)
            self._refused = True
            # "server unavailable" (3.1.1: 3; 5: 0x88) and "server busy" (5: 0x89): the cluster is not
            # ready; credentials, protocol and the rest are refusals
            self._refused_busy = getattr(reason, "value", None) in (3, 0x88, 0x89)
            self._metrics.inc("mqtt_connect_refused_total", link=self._name)
            log.error("broker %s refused the connection: %s", self._where(), reason)
            self._connack.set()
            return
        self._session_live = True
        self._had_session = True
        self.last_error = None
        self.last_refusal = None
        if self._failing_since is not None:
            log.info("broker reachable again after %.1f s", self._clock() - self._failing_since)
            self._failing_since = None
        self._subscribed.clear()
        # the broker kept this session and we subscribed on it before (this process, these topics): its
        # subscriptions are there, and subscribing again only costs (NATS creates, or looks up, a JetStream
        # consumer per topic through its metadata leader, and holds the connection up to 4 s per topic
        # while that leader is being elected). The liveness probe proves it; deaf → resubscribe
        present = bool(getattr(flags, "session_present", False))
        kept = present and self._subscribed_once and self.liveness.enabled
        if self.subscriptions and not kept:
            _, self._sub_mid = client.subscribe(self._subscription_list())
        self._metrics.inc("mqtt_connects_total", link=self._name)
        self._metrics.set("mqtt_connected", 1, link=self._name)
        if not self.policy.takeover_suspected:
            self._metrics.set("mqtt_client_id_conflict", 0, link=self._name)
        log.info(
            "connected to %s (%s), %s %d topics",
            self._where(),
            self._name,
            "its session kept (no resubscribe):" if kept else "subscribed to",
            len(self.subscriptions),
        )
        if kept:
            with self._probe_lock:
                if self.liveness.enabled:
                    self.liveness.subscribed(self._clock())
            self._subscribed.set()
        self._connack.set()
        with contextlib.suppress(RuntimeError):  # the loop closed during shutdown
            self._loop.call_soon_threadsafe(self._after_connect)

    def _on_subscribe(
        self,
        client: paho.Client,
        userdata: Any,
        mid: int,
        reasons: list[ReasonCode],
        props: Properties | None,
    ) -> None:
        if mid != self._sub_mid:
            return
        refused = [r for r in reasons if getattr(r, "is_failure", False)]
        if refused:
            self._metrics.inc("mqtt_subscribe_refused_total", link=self._name)
            log.error("broker %s refused %d subscription(s): %s", self._where(), len(refused), refused[0])
        with self._probe_lock:
            if self.liveness.enabled and len(reasons) > len(self.subscriptions):
                if getattr(reasons[-1], "is_failure", False):  # the probe topic: no proof possible here
                    self.liveness.enabled = False
                    log.warning(
                        "broker %s (%s) refused the probe topic %s: liveness checks off for this link "
                        "(allow it in the ACL)",
                        self._where(),
                        self._name,
                        self.probe_topic,
                    )
                else:
                    self.liveness.subscribed(self._clock())
        self._subscribed_once = not refused  # a refused topic is asked for again on every connect
        self._subscribed.set()

    @property
    def subscribed(self) -> bool:
        """Connected, and the broker has acknowledged the subscriptions (ready to receive requests)."""
        return self.connected and self._subscribed.is_set()

    def _on_disconnect(
        self,
        client: paho.Client,
        userdata: Any,
        flags: paho.DisconnectFlags,
        reason: ReasonCode,
        props: Properties | None,
    ) -> None:
        self._subscribed.clear()
        with self._probe_lock:
            self.liveness.lost()
        self._metrics.set("mqtt_connected", 0, link=self._name)
        if getattr(reason, "value", None) == SESSION_TAKEN_OVER:
            self._loss = Loss.TAKEN_OVER
        elif self._aborting and self._loss not in (Loss.STALLED, Loss.DEAF):
            self._loss = Loss.CLOSED
        if reason.is_failure and self._session_live:
            self._metrics.inc("mqtt_disconnects_total", link=self._name)
            log.warning("lost broker %s (%s): %s", self._where(), self._name, reason)
            if self.on_disconnected is not None:
                try:
                    self.on_disconnected(str(reason))
                except Exception:
                    log.exception("disconnect hook failed")
        self._session_live = False
        self._done.set()

    def _on_message(self, client: paho.Client, userdata: Any, msg: paho.MQTTMessage) -> None:
        if msg.topic == self.probe_topic:
            self._probe_back(bytes(msg.payload))
            return
        if msg.qos >= self._probe_qos:  # the link receives on the probe's path (LivenessProbe.step): on
            # NATS a QoS 0 subscription is plain NATS while QoS 1 ones are JetStream consumers, so a QoS 0
            # message (the gateway's own osd, heard back for twin detection) proves nothing about requests
            self._traffic_at = self._clock()  # a float store, no lock
        if self.inline is not None:
            try:
                if self.inline(msg.topic, bytes(msg.payload)):  # paho's payload is bytes: not copied
                    self._metrics.inc("mqtt_messages_in_total", link=self._name)
                    return
            except Exception:  # never let a handler kill paho's thread
                self._metrics.inc("handler_exceptions_total", where=f"inline:{self._name}")
                log.exception("inline handler failed on %s", msg.topic[:200])
                return
        payload = msg.payload
        oversize = len(payload) > self.settings.max_payload
        if oversize:
            payload = payload[:512]
        item = Inbound(msg.topic, bytes(payload), oversize)
        with contextlib.suppress(RuntimeError):  # the loop closed during shutdown
            self._loop.call_soon_threadsafe(self._enqueue, item)

    # -- loop side ------------------------------------------------------------------------------
    def _after_connect(self) -> None:
        if self.on_connected is not None:
            try:
                self.on_connected()
            except Exception:
                self._metrics.inc("handler_exceptions_total", where="on_connected")
                log.exception("on_connected hook failed")
        self.flush()  # after update_topo and state: the cloud registers the gateway before its osd

    def _enqueue(self, item: Inbound) -> None:
        self._metrics.inc("mqtt_messages_in_total", link=self._name)
        try:
            self.queue.put_nowait(item)
        except asyncio.QueueFull:
            self._metrics.inc("mqtt_inbound_dropped_total", link=self._name)
            self._dropped_logged += 1
            if self._dropped_logged in (1, 10, 100) or self._dropped_logged % 1000 == 0:
                log.warning("inbound queue full: dropped %d message(s) so far", self._dropped_logged)

    def _where(self) -> str:
        ep = self.current or self.endpoints[0]
        return ep.where()
