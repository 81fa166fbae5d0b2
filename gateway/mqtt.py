"""The broker connection: owns paho-mqtt and its network thread, nothing else.

Received messages are handed to the asyncio loop with ``call_soon_threadsafe`` and land in a
bounded queue; when it is full the message is dropped, counted and logged, so a flood never
blocks paho's thread (a blocked thread would delay every heartbeat and reply). Subscriptions are
made in the connect callback every time, so a broker restart that forgot them is healed. The
``on_connected`` hook (``update_topo``, ``state``) runs in the loop after each (re)connect.
Reconnects use capped exponential backoff with full jitter, so a fleet does not stampede a
restarted broker. Knows topics only as strings; no Cloud API semantics.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import socket
import ssl
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion, MQTTProtocolVersion
from paho.mqtt.packettypes import PacketTypes
from paho.mqtt.properties import Properties

from gateway.metrics import Metrics
from gateway.settings import BrokerSettings

log = logging.getLogger(__name__)

__all__ = ["Backoff", "Inbound", "MqttBridge", "close_client"]


@dataclass(frozen=True, slots=True)
class Inbound:
    """One received message as the loop sees it. ``oversize`` payloads are truncated to a prefix
    (enough to read a ``tid`` for the error reply) and never parsed."""

    topic: str
    payload: bytes
    oversize: bool = False


def close_client(client: paho.Client) -> None:
    """Release the sockets paho keeps after ``loop_stop`` (its wake-up socket pair stays open until the
    client object is collected, which a reference cycle can delay: an unclosed-socket warning later)."""
    with contextlib.suppress(Exception):
        client._reset_sockets()  # private, but the only way; harmless when already closed


class Backoff:
    """Capped exponential backoff with full jitter (delay drawn from [0.5·d, d])."""

    def __init__(self, minimum: float, maximum: float, rng: random.Random | None = None) -> None:
        self.minimum, self.maximum = minimum, max(minimum, maximum)
        self._attempt = 0
        self._rng = rng or random.Random()

    def next(self) -> float:
        ceiling = min(self.maximum, self.minimum * (2**self._attempt))
        self._attempt = min(self._attempt + 1, 32)
        return self._rng.uniform(ceiling / 2, ceiling)

    def reset(self) -> None:
        self._attempt = 0


class MqttBridge:
    """One paho client in its own thread, feeding an asyncio queue."""

    def __init__(
        self,
        settings: BrokerSettings,
        *,
        client_id: str,
        subscriptions: list[tuple[str, int]],
        loop: asyncio.AbstractEventLoop,
        metrics: Metrics,
        will: tuple[str, bytes] | None = None,
        on_connected: Callable[[], None] | None = None,
        name: str = "main",
        inline: Callable[[str, bytes], bool] | None = None,
        on_disconnected: Callable[[str], None] | None = None,
    ) -> None:
        self.settings = settings
        self.client_id = client_id
        self.subscriptions = list(subscriptions)
        self.queue: asyncio.Queue[Inbound] = asyncio.Queue(maxsize=settings.inbound_queue)
        self._loop = loop
        self._metrics = metrics
        self._on_connected = on_connected
        # ``inline`` sees every message in the network thread first and may consume it (returns True):
        # DRC heartbeats and sticks are answered there, so a busy event loop cannot delay them.
        self._inline = inline
        self._on_disconnected = on_disconnected
        self._name = name
        self._backoff = Backoff(settings.reconnect_min, settings.reconnect_max)
        self._connected = asyncio.Event()
        self._subscribed = threading.Event()  # set once the broker acknowledged every subscription
        self._sub_mid: int | None = None
        self._dropped_logged = 0
        self.last_refusal: str | None = None  # the broker's reason for refusing the last CONNECT
        self.last_error: str | None = None  # why the last connection attempt failed (TCP/TLS), if known
        self._diagnosed = False
        self._ssl: ssl.SSLContext | None = None
        self._client = self._build_client(will)

    # -- set-up ---------------------------------------------------------------------------------
    def _build_client(self, will: tuple[str, bytes] | None) -> paho.Client:
        s = self.settings
        v5 = s.protocol == "5"
        client = paho.Client(
            CallbackAPIVersion.VERSION2,
            client_id=self.client_id,
            protocol=MQTTProtocolVersion.MQTTv5 if v5 else MQTTProtocolVersion.MQTTv311,
            transport=s.transport,
            clean_session=None if v5 else False,
            reconnect_on_failure=True,
        )
        if s.transport == "websockets":
            client.ws_set_options(path=s.ws_path)
        if s.username is not None:
            client.username_pw_set(s.username, s.password.get_secret_value() if s.password else None)
        if s.tls:
            self._ssl = self._ssl_context()
            client.tls_set_context(self._ssl)
        if will is not None:
            client.will_set(will[0], will[1], qos=1, retain=False)
        client.max_queued_messages_set(10000)
        client.reconnect_delay_set(s.reconnect_min, s.reconnect_min)
        client.on_connect = self._on_connect
        client.on_disconnect = self._on_disconnect
        client.on_connect_fail = self._on_connect_fail
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

    def _diagnose(self) -> None:
        """paho reports a failed connect without its cause; find it with one probe (TCP, then TLS) and
        log one clear line per streak of failures. Runs in its own short-lived thread."""
        s = self.settings
        try:
            with socket.create_connection((s.host, s.port), timeout=3) as sock:
                if self._ssl is not None:
                    with self._ssl.wrap_socket(sock, server_hostname=s.host):
                        pass
            reason = "TCP/TLS works, but the MQTT connection failed"
        except ssl.SSLCertVerificationError as exc:
            reason = f"TLS: the broker's certificate was refused: {exc.verify_message}"
        except ssl.SSLError as exc:
            reason = f"TLS handshake failed: {exc.reason or exc}"
        except OSError as exc:
            reason = f"cannot connect: {exc.strerror or exc}"
        self.last_error = reason
        log.error("broker %s (%s): %s", self._where(), self._name, reason)

    def set_will(self, topic: str, payload: bytes) -> None:
        """The message the broker publishes if the gateway vanishes (must precede :meth:`start`)."""
        self._client.will_set(topic, payload, qos=1, retain=False)

    def start(self) -> None:
        s = self.settings
        props = None
        kwargs: dict[str, Any] = {}
        if s.protocol == "5":
            props = Properties(PacketTypes.CONNECT)
            props.SessionExpiryInterval = s.session_expiry
            kwargs["clean_start"] = paho.MQTT_CLEAN_START_FIRST_ONLY
        self._client.connect_async(s.host, s.port, keepalive=s.keepalive, properties=props, **kwargs)
        self._client.loop_start()

    async def wait_connected(self, timeout: float | None = None) -> bool:
        try:
            await asyncio.wait_for(self._connected.wait(), timeout)
        except TimeoutError:
            return False
        return True

    @property
    def connected(self) -> bool:
        return self._client.is_connected()

    def publish(self, topic: str, payload: bytes, qos: int = 1, retain: bool = False) -> bool:
        """Queue a message; paho writes it from this thread at once when connected. QoS 1 messages
        published while disconnected wait in paho's queue and go out after the reconnect."""
        info = self._client.publish(topic, payload, qos=qos, retain=retain)
        ok = info.rc == paho.MQTT_ERR_SUCCESS or (qos > 0 and info.rc == paho.MQTT_ERR_NO_CONN)
        if not ok:
            self._metrics.inc("mqtt_publish_errors_total", link=self._name)
        else:
            self._metrics.inc("mqtt_messages_out_total", link=self._name)
        return ok

    def stop(self, last: tuple[str, bytes] | None = None, timeout: float = 2.0) -> None:
        """Publish ``last`` (the clean offline message), wait for it briefly, disconnect."""
        if last is not None and self._client.is_connected():
            info = self._client.publish(last[0], last[1], qos=1)
            try:
                info.wait_for_publish(timeout)
            except (RuntimeError, ValueError):
                log.warning("offline message not delivered before shutdown")
        self._client.disconnect()
        self._client.loop_stop()
        close_client(self._client)

    # -- paho callbacks (network thread) --------------------------------------------------------
    def _on_socket_open(self, client: paho.Client, userdata: Any, sock: Any) -> None:
        raw = getattr(sock, "_socket", sock)  # websockets wrap the socket
        try:
            raw.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        except (OSError, AttributeError):
            log.debug("could not set TCP_NODELAY on %r", type(raw).__name__)

    def _on_connect(self, client: paho.Client, userdata: Any, flags: Any, reason: Any, props: Any) -> None:
        if reason.is_failure:
            self.last_refusal = str(reason)
            self._metrics.inc("mqtt_connect_refused_total", link=self._name)
            log.error("broker %s refused the connection: %s", self._where(), reason)
            self._schedule_retry()
            return
        self._backoff.reset()
        self._diagnosed = False
        self.last_error = None
        client.reconnect_delay_set(self.settings.reconnect_min, self.settings.reconnect_min)
        self._subscribed.clear()
        if self.subscriptions:
            _, self._sub_mid = client.subscribe(list(self.subscriptions))
        self._metrics.inc("mqtt_connects_total", link=self._name)
        self._metrics.set("mqtt_connected", 1, link=self._name)
        log.info(
            "connected to %s (%s), subscribed to %d topics",
            self._where(),
            self._name,
            len(self.subscriptions),
        )
        self._loop.call_soon_threadsafe(self._after_connect)

    def _on_subscribe(self, client: paho.Client, userdata: Any, mid: int, reasons: Any, props: Any) -> None:
        if mid != self._sub_mid:
            return
        refused = [r for r in reasons if getattr(r, "is_failure", False)]
        if refused:
            self._metrics.inc("mqtt_subscribe_refused_total", link=self._name)
            log.error("broker %s refused %d subscription(s): %s", self._where(), len(refused), refused[0])
        self._subscribed.set()

    @property
    def subscribed(self) -> bool:
        """Connected, and the broker has acknowledged the subscriptions (ready to receive requests)."""
        return self.connected and self._subscribed.is_set()

    def _on_disconnect(self, client: paho.Client, userdata: Any, flags: Any, reason: Any, props: Any) -> None:
        self._subscribed.clear()
        self._metrics.set("mqtt_connected", 0, link=self._name)
        self._loop.call_soon_threadsafe(self._connected.clear)
        if reason.is_failure:
            self._metrics.inc("mqtt_disconnects_total", link=self._name)
            log.warning("lost broker %s: %s; reconnecting", self._where(), reason)
            if self._on_disconnected is not None:
                try:
                    self._on_disconnected(str(reason))
                except Exception:
                    log.exception("disconnect hook failed")
        self._schedule_retry()

    def _on_connect_fail(self, client: paho.Client, userdata: Any) -> None:
        self._metrics.inc("mqtt_connect_failures_total", link=self._name)
        if not self._diagnosed:
            self._diagnosed = True
            threading.Thread(target=self._diagnose, name=f"mqtt-diagnose-{self._name}", daemon=True).start()
        self._schedule_retry()

    def _schedule_retry(self) -> None:
        delay = self._backoff.next()
        self._client.reconnect_delay_set(delay, delay)

    def _on_message(self, client: paho.Client, userdata: Any, msg: paho.MQTTMessage) -> None:
        if self._inline is not None:
            try:
                if self._inline(msg.topic, msg.payload):
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
        self._connected.set()
        if self._on_connected is not None:
            try:
                self._on_connected()
            except Exception:
                self._metrics.inc("handler_exceptions_total", where="on_connected")
                log.exception("on_connected hook failed")

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
        s = self.settings
        return f"{s.host}:{s.port}"
