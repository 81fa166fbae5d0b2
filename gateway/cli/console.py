"""``dji-gateway send`` and ``dji-gateway monitor``: the cloud side of the Cloud API, for people.

``send`` publishes one service (or one ``drc/down`` message) through the broker, waits for the reply
that matches its ``tid`` and ``bid`` (``drc/up``: its method and ``seq``), prints it and exits 0 on
result 0, 1 on an error result, 3 when nothing came back in time, 2 when the broker could not be used
(``stick_control``, not answered when accepted: 0 when no refusal comes and the gateway's live-control
pushes arrive on that drc/up, proof its session rides this broker; 3 when they do not: nothing moved).
``monitor`` subscribes to one gateway's topics and shows topology, osd, state, events, replies and the
live-control (DRC) session: heartbeat round trip as seen on the broker, the last sticks, failsafes.
It draws a ``rich`` view on a terminal and prints one line per message otherwise (``--plain``, or
stdout not a TTY), so it works in pipes, logs and tests.

Owns only the console: message shapes come from the Cloud API envelope (tid, bid, method, data), the
broker link is a plain paho client. :class:`MonitorState` is pure (topic, payload, time in; lines
out; :func:`render` draws it), so both modes show the same facts. Knows nothing of devices or bytes.
Passwords are read from the environment (``DJIGW_CONSOLE_PASSWORD``), never from the command line,
where ``ps`` would show them.

Time: reads the system clock itself (a separate process; the gateway's injected clock is the service's).

Why this module is longer than 500 lines: ``send`` and ``monitor`` share the broker client, the request checks
and the monitor's state model with its rich and plain views; ``fly``, ``status`` and the contract checks
already live in modules of their own.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import sys
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from gateway.cli.codec import is_assignment
from gateway.mqtt import close_client

if TYPE_CHECKING:
    import paho.mqtt.client as paho
    from paho.mqtt.properties import Properties
    from paho.mqtt.reasoncodes import ReasonCode
    from rich.console import RenderableType

__all__ = [
    "DEFAULT_BROKER",
    "MonitorState",
    "add_parsers",
    "build_message",
    "cmd_monitor",
    "cmd_send",
    "parse_fields",
    "render",
]

DEFAULT_BROKER = "mqtt://127.0.0.1:1883"
BROKER_ENV = "DJIGW_CONSOLE_BROKER"
USERNAME_ENV = "DJIGW_CONSOLE_USERNAME"
PASSWORD_ENV = "DJIGW_CONSOLE_PASSWORD"
GATEWAY_ENV = "DJIGW_GATEWAY_SN"

EXIT_OK, EXIT_ERROR_RESULT, EXIT_USAGE, EXIT_TIMEOUT = 0, 1, 2, 3
#: how long ``send --drc`` waits for the refusal of a method that is not answered when accepted (s)
SILENT_WAIT = 1.0
#: and, longer, for the gateway's live-control pushes on the same drc/up (the proof that a session rides
#: this broker, so the accepted message reached it): ``delay_info_push`` comes once a second at least
DRC_PROOF_WAIT = 2.5
#: what a gateway in live control publishes on drc/up by itself, unasked
DRC_PUSHES = frozenset({"osd_info_push", "hsi_info_push", "delay_info_push", "drc_drone_state_push"})

#: osd fields shown first (and always, when present) in a device's one-line summary.
_OSD_FIRST = (
    "gimbal_yaw", "gimbal_pitch", "gimbal_roll", "mode_code", "latitude", "longitude", "elevation", "height",
    "attitude_head", "horizontal_speed", "vertical_speed", "drc_state", "x_robot_id", "x_hp", "x_position",
)  # fmt: skip
_DRC_PUSHES = frozenset({"osd_info_push", "hsi_info_push", "delay_info_push"})


# ------------------------------------------------------------------------------------------ arguments
def add_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    send = sub.add_parser(
        "send",
        help="publish one Cloud API service and print its reply",
        description="Check the method and every field against the contract (dji-gateway methods METHOD lists "
        "them), publish one service to thing/product/SN/services, wait for the services_reply with the same "
        "tid and bid, print it. Exit 0 on result 0, 1 on an error result (its reason on stderr), 2 when "
        "nothing was sent (a bad method or field, or the broker unusable), 3 when no reply came in time "
        "(the gateway serial numbers seen on the broker on stderr).",
    )
    send.add_argument("method", help="Cloud API method, e.g. camera_aim (dji-gateway methods lists them)")
    send.add_argument(
        "fields",
        nargs="*",
        metavar="field=value",
        help="data fields; values are JSON when they parse (0.5, true, {...}), text otherwise; a.b=1 nests",
    )
    send.add_argument("--data", help="the whole data object as JSON (field=value pairs are merged over it)")
    send.add_argument(
        "--drc",
        action="store_true",
        help="publish on drc/down instead (heart_beat, drone_control, stick_control, drone_emergency_stop, "
        "drc_gimbal_reset) and wait for the drc/up answer with the same method and seq (stick_control: "
        "1 s for a refusal, accepted ones are not answered: exit 0 when the gateway's live-control pushes "
        "arrive on this broker's drc/up, 3 when none does: nothing moved)",
    )
    send.add_argument("--timeout", type=float, default=10.0, help="seconds to wait for the reply (10)")
    send.add_argument(
        "--no-check",
        action="store_true",
        help="publish without checking the method and fields against the contract (values JSON when "
        "they parse): to see how a gateway answers a bad request",
    )
    send.add_argument("--tid", help="the request's tid (default: a fresh UUID)")
    _connection_args(send)
    send.set_defaults(handler=cmd_send, trailing=("fields", is_assignment))

    mon = sub.add_parser(
        "monitor",
        help="watch a gateway's topology, osd, state, events and DRC session live",
        description="Subscribe to one gateway's topics and show them live: a rich view on a terminal, "
        "one line per message otherwise.",
    )
    mon.add_argument("--plain", action="store_true", help="one line per message, even on a terminal")
    mon.add_argument("--once", action="store_true", help="listen for --duration, draw the view once, exit")
    mon.add_argument("--duration", type=float, help="stop after this many seconds (--once: default 3)")
    replies = mon.add_mutually_exclusive_group()
    replies.add_argument(
        "--reply-events",
        dest="reply_events",
        action="store_const",
        const="always",
        default="auto",
        help="answer every event that asks for an events_reply at once (act as the cloud). Default: "
        f"answer one only when no other cloud has within {AUTO_REPLY_GRACE:g}s (the monitor is the only "
        "cloud), so the gateway does not re-send it",
    )
    replies.add_argument(
        "--no-reply-events",
        dest="reply_events",
        action="store_const",
        const="never",
        help="never answer events (another cloud does; unanswered ones are re-sent, shown once)",
    )
    mon.add_argument(
        "--status-url",
        default=None,
        help="the gateway's HTTP endpoint, asked once for the topology when the monitor starts after the "
        "gateway's update_topo (default http://127.0.0.1:$DJIGW_METRICS__PORT, 9108; '' turns it off)",
    )
    mon.add_argument("--verbose", "-v", action="store_true", help="plain mode: also the DRC pushes")
    _connection_args(mon)
    mon.set_defaults(handler=cmd_monitor)


def _connection_args(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--gateway-sn",
        default=os.environ.get(GATEWAY_ENV),
        help=f"the gateway's serial number (default ${GATEWAY_ENV})",
    )
    p.add_argument(
        "--broker",
        default=os.environ.get(BROKER_ENV, DEFAULT_BROKER),
        help=f"mqtt://host:port, mqtts://, ws://, wss:// (default ${BROKER_ENV} or {DEFAULT_BROKER})",
    )
    p.add_argument(
        "--username",
        default=os.environ.get(USERNAME_ENV),
        help=f"broker user (default ${USERNAME_ENV}); the password comes from ${PASSWORD_ENV}",
    )
    p.add_argument("--ca-file", help="CA certificate for mqtts:// and wss://")


# ------------------------------------------------------------------------------------------ messages
def parse_fields(pairs: list[str]) -> dict[str, Any]:
    """``["x=0.5", "camera_type=wide", "a.b=1"]`` → ``{"x": 0.5, "camera_type": "wide", "a": {"b": 1}}``."""
    out: dict[str, Any] = {}
    for pair in pairs:
        key, sep, text = pair.partition("=")
        if not sep or not key:
            raise ValueError(f"expected field=value, got {pair!r}")
        try:
            value: Any = json.loads(text)
        except ValueError:
            value = text
        node = out
        *parents, leaf = key.split(".")
        for name in parents:
            child = node.setdefault(name, {})
            if not isinstance(child, dict):
                raise ValueError(f"{key}: {name} is already a value")
            node = child
        node[leaf] = value
    return out


def _progress_text(data: dict[str, Any]) -> str:
    """A wayline task's progress in one line: flight_id status step percent waypoint media (result)."""

    def part(parent: dict[str, Any], name: str) -> dict[str, Any]:
        value = parent.get(name)
        return value if isinstance(value, dict) else {}

    out = part(data, "output")
    ext, prog = part(out, "ext"), part(out, "progress")
    text = (
        f"{ext.get('flight_id', '?')} status={out.get('status', '?')} step={prog.get('current_step', '?')} "
        f"percent={prog.get('percent', '?')} waypoint={ext.get('current_waypoint_index', '?')} "
        f"media={ext.get('media_count', '?')}"
    )
    result = data.get("result")
    return text + (f" result={result}" if result else "")


def build_message(method: str, data: dict[str, Any], *, tid: str | None = None) -> dict[str, Any]:
    """A services envelope: fresh tid and bid, the time in ms."""
    return {
        "tid": tid or str(uuid.uuid4()),
        "bid": str(uuid.uuid4()),
        "timestamp": int(time.time() * 1000),
        "method": method,
        "data": data,
    }


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = value
    return out


# ------------------------------------------------------------------------------------------ broker link
class BrokerError(Exception):
    """The broker could not be reached or refused us; the message says which."""


class _Link:
    """One paho client: connect, subscribe (waiting for SUBACK), hand messages to ``on_message``."""

    def __init__(self, ns: argparse.Namespace, on_message: Callable[[str, bytes], None]) -> None:
        import paho.mqtt.client as paho
        from paho.mqtt.enums import CallbackAPIVersion, MQTTProtocolVersion
        from pydantic import ValidationError

        from gateway.settings import BrokerSettings

        try:
            self.settings = BrokerSettings(url=ns.broker)
        except ValidationError as exc:
            raise BrokerError(f"bad --broker {ns.broker!r}: {exc.errors()[0]['msg']}") from None
        s = self.settings
        self._on_message = on_message
        self._connected = threading.Event()
        self._subscribed = threading.Event()
        self.refusal: str | None = None
        self.client = paho.Client(
            CallbackAPIVersion.VERSION2,
            client_id=f"djigw-console-{uuid.uuid4().hex[:8]}",
            protocol=MQTTProtocolVersion.MQTTv5,
            transport=s.transport,
        )
        if s.transport == "websockets":
            self.client.ws_set_options(path=s.ws_path)
        if ns.username:
            self.client.username_pw_set(ns.username, os.environ.get(PASSWORD_ENV))
        if s.tls:
            self.client.tls_set(ca_certs=ns.ca_file)
        self.client.on_connect = self._connect_cb
        self.client.on_message = lambda c, u, msg: self._on_message(msg.topic, bytes(msg.payload))
        self.client.on_subscribe = lambda *a: self._subscribed.set()

    def _connect_cb(
        self,
        client: paho.Client,
        userdata: Any,
        flags: paho.ConnectFlags,
        reason: ReasonCode,
        props: Properties | None,
    ) -> None:
        if reason.is_failure:
            self.refusal = str(reason)
        self._connected.set()

    def open(self, topics: list[str], timeout: float = 5.0) -> _Link:
        s = self.settings
        try:
            self.client.connect(s.host, s.port, keepalive=30)
        except OSError as exc:
            raise BrokerError(
                f"cannot reach the broker at {s.host}:{s.port}: {exc.strerror or exc}"
            ) from None
        self.client.loop_start()
        if not self._connected.wait(timeout):
            self.close()
            raise BrokerError(f"no answer from the broker at {s.host}:{s.port} within {timeout:g}s")
        if self.refusal is not None:
            self.close()
            raise BrokerError(f"the broker at {s.host}:{s.port} refused the connection: {self.refusal}")
        if topics:
            self.client.subscribe([(t, 1) for t in topics])
            if not self._subscribed.wait(timeout):
                self.close()
                raise BrokerError("the broker did not acknowledge the subscriptions")
        return self

    def publish(self, topic: str, body: dict[str, Any], qos: int = 1) -> None:
        info = self.client.publish(topic, json.dumps(body, separators=(",", ":")), qos=qos)
        if qos:
            info.wait_for_publish(5)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
        close_client(self.client)


# ------------------------------------------------------------------------------------------ send
def _checked_data(ns: argparse.Namespace) -> dict[str, Any] | None:
    """The request's ``data``, typed and checked against the contract (None: refused, and said why on
    stderr). ``--no-check`` sends what was typed, JSON where it parses (to try a gateway's own checks).
    Raises ValueError for words that are not ``field=value`` or a ``--data`` that is not an object."""
    base: dict[str, Any] = {}
    if ns.data:
        loaded = json.loads(ns.data)
        if not isinstance(loaded, dict):
            raise ValueError("--data must be a JSON object")
        base = loaded
    if ns.no_check:
        return _merge(base, parse_fields(list(ns.fields or [])))
    from gateway.cli.contract import check_request

    check = check_request(ns.method, list(ns.fields or []), base, drc=ns.drc)
    if check.ok:
        return check.data
    print(f"dji-gateway send: {ns.method} not sent:", file=sys.stderr)
    for problem in check.problems:
        print(f"  {problem}", file=sys.stderr)
    if check.hint:
        print(f"  ({check.hint})", file=sys.stderr)
    return None


class GatewaysSeen:
    """The gateway serial numbers heard on the broker (their osd and status), so a wrong
    ``--gateway-sn`` can be answered with the right ones."""

    TOPICS = ("thing/product/+/osd", "sys/product/+/status")

    def __init__(self) -> None:
        self.serials: set[str] = set()

    def feed(self, topic: str, payload: bytes) -> None:
        parts = topic.split("/")
        if len(parts) != 4 or parts[3] not in ("osd", "status"):
            return
        if parts[0] == "sys":
            self.serials.add(parts[2])
            return
        try:
            body = json.loads(payload)
        except ValueError:
            return
        if isinstance(body, dict) and isinstance(body.get("gateway"), str):
            self.serials.add(body["gateway"])

    def advice(self, wanted: str, drc: str | None = None) -> str:
        """One sentence: which gateways are there, or that none is. ``drc``: the broker a ``--drc`` message
        went to (a gateway that is here and does not answer it has no live-control session on it)."""
        if wanted in self.serials and drc is not None:
            return (
                f"gateway {wanted} is on this broker but its live control does not ride it: enter it with "
                f"drc_mode_enter mqtt_broker.address naming this broker ({drc}), or send to the broker that "
                "drc_mode_enter named"
            )
        if wanted in self.serials:
            return f"gateway {wanted} is on this broker but did not answer (is the method slow? --timeout)"
        if not self.serials:
            return "no gateway published on this broker meanwhile (is one running and connected to it?)"
        return "gateways seen on this broker: " + ", ".join(sorted(self.serials))


def cmd_send(ns: argparse.Namespace) -> int:
    if not ns.gateway_sn:
        print(f"dji-gateway send: --gateway-sn is required (or set ${GATEWAY_ENV})", file=sys.stderr)
        return EXIT_USAGE
    served = None
    if ns.method == "flighttask_prepare" and not ns.drc:  # file=route.kmz: served here, fingerprinted
        from gateway.wayline.console_files import serve_prepare_fields

        try:
            ns.fields, served = serve_prepare_fields(list(ns.fields or []))
        except OSError as exc:
            print(f"dji-gateway send: cannot read the KMZ: {exc.strerror or exc}", file=sys.stderr)
            return EXIT_USAGE
    try:
        return _send(ns)
    finally:
        if served is not None:
            served.close()


def _send(ns: argparse.Namespace) -> int:
    try:
        data = _checked_data(ns)
    except ValueError as exc:
        print(f"dji-gateway send: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if data is None:
        return EXIT_USAGE
    gw = ns.gateway_sn
    if ns.drc:
        body: dict[str, Any] = {"method": ns.method, "data": data}
        seq = data.get("seq")
        request_topic, reply_topic = f"thing/product/{gw}/drc/down", f"thing/product/{gw}/drc/up"

        def matches(reply: dict[str, Any]) -> bool:
            if reply.get("method") != ns.method:
                return False
            rdata = reply.get("data") or {}
            got = rdata.get("seq", (rdata.get("output") or {}).get("seq", reply.get("seq")))
            return seq is None or got == seq

    else:
        body = build_message(ns.method, data, tid=ns.tid)
        request_topic, reply_topic = f"thing/product/{gw}/services", f"thing/product/{gw}/services_reply"

        def matches(reply: dict[str, Any]) -> bool:
            return bool(reply.get("tid") == body["tid"] and reply.get("bid") == body["bid"])

    found: list[dict[str, Any]] = []
    arrived = threading.Event()
    pushing = threading.Event()  # the gateway's live-control pushes seen on this drc/up
    seen = GatewaysSeen()

    def on_message(topic: str, payload: bytes) -> None:
        if topic != reply_topic:
            seen.feed(topic, payload)
            return
        try:
            reply = json.loads(payload)
        except ValueError:
            return
        if isinstance(reply, dict) and reply.get("method") in DRC_PUSHES:
            pushing.set()
        if isinstance(reply, dict) and matches(reply) and not arrived.is_set():
            found.append(reply)
            arrived.set()

    try:
        link = _Link(ns, on_message).open([reply_topic, *GatewaysSeen.TOPICS])
    except BrokerError as exc:
        print(f"dji-gateway send: {exc}", file=sys.stderr)
        return EXIT_USAGE
    from schemas.drc import SILENT_WHEN_ACCEPTED

    silent = ns.drc and ns.method in SILENT_WHEN_ACCEPTED
    try:
        link.publish(request_topic, body, qos=0 if ns.drc else 1)
        wait = min(ns.timeout, SILENT_WAIT)
        if silent and not arrived.wait(wait):
            # no refusal: accepted, if the gateway's live-control session rides this broker at all (else
            # nobody read it); its unasked pushes on this drc/up say so
            deadline = time.monotonic() + max(0.0, min(ns.timeout, DRC_PROOF_WAIT) - wait)
            while not (pushing.is_set() or arrived.is_set()) and time.monotonic() < deadline:
                pushing.wait(0.05)
            if not arrived.is_set():
                if pushing.is_set():
                    print(
                        f"sent {ns.method}: not refused within {wait:g}s, and {gw}'s live-control session "
                        "rides this broker (its drc/up pushes arrive): accepted (an accepted one is not "
                        "answered)"
                    )
                    return EXIT_OK
                print(
                    f"dji-gateway send: {ns.method} reached no live-control session: {gw} publishes nothing "
                    f"on drc/up of {link.settings.host}:{link.settings.port} (within "
                    f"{min(ns.timeout, DRC_PROOF_WAIT):g}s), so nothing moved; enter live control with "
                    "drc_mode_enter naming this broker (mqtt_broker.address), or send to the broker it named",
                    file=sys.stderr,
                )
                return EXIT_TIMEOUT
        if not arrived.wait(ns.timeout):
            print(
                f"dji-gateway send: no reply to {ns.method} from {gw} within {ns.timeout:g}s; "
                + seen.advice(gw, drc=f"{link.settings.host}:{link.settings.port}" if ns.drc else None),
                file=sys.stderr,
            )
            return EXIT_TIMEOUT
    finally:
        link.close()
    reply = found[0]
    print(json.dumps(reply, indent=2, ensure_ascii=False))
    rdata = reply.get("data") or {}
    result = rdata.get("result", 0)
    if result:
        from schemas.results import meaning

        reason = (rdata.get("output") or {}).get("reason") if isinstance(rdata.get("output"), dict) else None
        print(
            f"dji-gateway send: {ns.method} failed with {result} ({meaning(int(result)).rstrip('.')})"
            + (f": {reason}" if reason else ""),
            file=sys.stderr,
        )
        return EXIT_ERROR_RESULT
    return EXIT_OK


# ------------------------------------------------------------------------------------------ monitor state
@dataclass
class DeviceView:
    sn: str
    domain: str = "?"
    online: bool = False
    own: bool = False  # announced as its own gateway (its own update_topo), not in the gateway's list
    osd: dict[str, Any] = field(default_factory=dict)
    osd_at: float | None = None
    osd_count: int = 0
    state: dict[str, Any] = field(default_factory=dict)
    state_at: float | None = None


@dataclass
class DrcView:
    state: int = 0
    heartbeats: int = 0
    pending_heartbeats: dict[Any, float] = field(default_factory=dict)  # seq -> when it went down
    rtt_ms: float | None = None  # last heartbeat round trip as seen on this broker
    rtt_avg_ms: float | None = None
    heartbeat_at: float | None = None
    stick: dict[str, Any] = field(default_factory=dict)  # the last drone_control data
    stick_at: float | None = None
    stick_result: int | None = None
    failsafe: str | None = None  # the failsafe that holds (heartbeat lost, stick timeout, emergency stop, …)
    failsafe_reason: str | None = None  # its kind (sticks, heartbeat, emergency_stop, link_lost, authority)
    failsafe_at: float | None = None  # when it first fired
    delay_ms: float | None = None  # the gateway's delay_info_push sdr_cmd_delay
    push: dict[str, Any] = field(default_factory=dict)  # the last osd_info_push


class MonitorState:
    """What one gateway has said so far; :meth:`feed` returns the plain-mode lines for a message."""

    def __init__(self, gateway_sn: str, *, verbose: bool = False, history: int = 200) -> None:
        self.gateway_sn = gateway_sn
        self.verbose = verbose
        self.devices: dict[str, DeviceView] = {}
        self.gateway_online: bool | None = None
        self.topology_at: float | None = None
        self.topology_source = ""  # "" (update_topo on the broker) or "/status" (asked the gateway)
        self.events: deque[tuple[float, str]] = deque(maxlen=history)
        self.drc = DrcView()
        self.messages = 0
        self.last_at: float | None = None
        self.resent = 0  # event copies the gateway re-sent (shown once, counted here)
        self._event_tids: dict[str, bool] = {}  # tid → needs a reply; bounded, oldest forgotten
        self.answered: set[str] = set()  # event tids some cloud answered on events_reply

    def topics(self) -> list[str]:
        gw = self.gateway_sn
        return [
            "sys/product/+/status",  # the gateway's, and those of devices announced as gateways of their own
            f"thing/product/{gw}/events",
            f"thing/product/{gw}/events_reply",
            f"thing/product/{gw}/services",
            f"thing/product/{gw}/services_reply",
            f"thing/product/{gw}/drc/up",
            f"thing/product/{gw}/drc/down",
            f"thing/product/{gw}/requests",
            "thing/product/+/osd",  # sub-devices publish under their own serial numbers
            "thing/product/+/state",
        ]

    def feed(self, topic: str, payload: bytes, now: float) -> list[str]:
        try:
            body = json.loads(payload)
        except ValueError:
            return [f"{_clock()} ?      {topic}: not JSON ({len(payload)} bytes)"]
        if not isinstance(body, dict):
            return []
        parts = topic.split("/")
        if len(parts) < 4:
            return []
        sn, kind = parts[2], "/".join(parts[3:])
        data = body.get("data") if isinstance(body.get("data"), dict) else {}
        if kind in ("osd", "state") and not self._ours(sn, body):
            return []
        if kind == "status" and sn != self.gateway_sn and sn not in self.devices:
            return []  # another gateway's, or one of ours whose osd has not been seen yet
        self.messages += 1
        self.last_at = now
        handler = getattr(self, "_" + kind.replace("/", "_"), None)
        return handler(sn, body, data, now) if handler is not None else []

    def learn_status(self, doc: dict[str, Any], now: float) -> list[str]:
        """The topology from the gateway's ``/status`` (a monitor started after the gateway's last
        ``update_topo``); ignored when it is another gateway's, or an ``update_topo`` came first."""
        if doc.get("gateway_sn") != self.gateway_sn or self.topology_at is not None:
            return []
        self.topology_at, self.topology_source, self.gateway_online = now, "/status", True
        online = []
        for d in doc.get("devices") or []:
            sn = str(d.get("sn"))
            view = self.devices.setdefault(sn, DeviceView(sn))
            view.domain, view.online = str(d.get("domain", "?")), bool(d.get("online"))
            if view.online:
                online.append(f"{sn}(domain {view.domain})")
        names = " ".join(online) or "no devices online"
        return [f"{_clock()} topo   {self.gateway_sn}: {names} (from the gateway's /status)"]

    def wants_answer(self, tid: str) -> bool:
        """An event with ``need_reply`` that nobody has answered yet (the monitor's auto reply)."""
        return bool(self._event_tids.get(tid)) and tid not in self.answered

    def _ours(self, sn: str, body: dict[str, Any]) -> bool:
        return sn == self.gateway_sn or sn in self.devices or body.get("gateway") == self.gateway_sn

    # -- per kind ---------------------------------------------------------------------------------
    def _status(self, sn: str, body: dict[str, Any], data: dict[str, Any], now: float) -> list[str]:
        if body.get("method") != "update_topo":
            return []
        subs = data.get("sub_devices") or []
        listed = {d.get("sn") for d in subs}
        if sn != self.gateway_sn:  # a device that is its own gateway: it lists itself while it is online
            view = self.devices.setdefault(sn, DeviceView(sn))
            view.own, view.online = True, sn in listed
            view.domain = str(data.get("domain", view.domain))
            return [f"{_clock()} topo   {sn}: {'online' if view.online else 'offline'} (its own gateway)"]
        self.topology_at, self.topology_source = now, ""
        self.gateway_online = True
        for view in self.devices.values():
            if not view.own:
                view.online = view.sn in listed
        for d in subs:
            view = self.devices.setdefault(str(d.get("sn")), DeviceView(str(d.get("sn"))))
            view.domain, view.online = str(d.get("domain", "?")), True
        names = " ".join(f"{d.get('sn')}(domain {d.get('domain')})" for d in subs) or "no devices online"
        return [f"{_clock()} topo   {sn}: {names}"]

    def _osd(self, sn: str, body: dict[str, Any], data: dict[str, Any], now: float) -> list[str]:
        if sn == self.gateway_sn:
            before = (self.drc.failsafe, self.drc.failsafe_reason)
            if "drc_state" in data:
                self.drc.state = int(data["drc_state"])
            failsafe = data.get("x_drc_failsafe")
            if isinstance(failsafe, dict):  # the gateway says which failsafe holds, and since when
                reason = str(failsafe.get("reason", "none"))
                if reason == "none":
                    self.drc.failsafe = self.drc.failsafe_reason = None
                else:
                    since = failsafe.get("since")
                    at = now - max(0.0, time.time() - since / 1000) if isinstance(since, int | float) else now
                    self._failsafe(_FAILSAFE_TEXT.get(reason, reason), at, reason)
            shown = [f"{_clock()} osd    {sn} drc_state={data.get('drc_state')}"] if self.verbose else []
            return [*shown, *self._failsafe_change(before, now)]
        view = self.devices.setdefault(sn, DeviceView(sn))
        view.osd.update(data)
        view.osd_at, view.osd_count = now, view.osd_count + 1
        view.online = True  # only online devices publish osd (the topology may predate this monitor)
        return [f"{_clock()} osd    {sn} {osd_summary(data)}"]

    def _state(self, sn: str, body: dict[str, Any], data: dict[str, Any], now: float) -> list[str]:
        view = self.devices.setdefault(sn, DeviceView(sn))
        view.state.update(data)
        view.state_at = now
        return [f"{_clock()} state  {sn} {_compact(data)}"]

    def _events_reply(self, sn: str, body: dict[str, Any], data: dict[str, Any], now: float) -> list[str]:
        tid = body.get("tid")
        if isinstance(tid, str):
            self.answered.add(tid)
            while len(self.answered) > 1024:
                self.answered.pop()
        return []

    def _events(self, sn: str, body: dict[str, Any], data: dict[str, Any], now: float) -> list[str]:
        method = str(body.get("method"))
        tid = body.get("tid")
        if isinstance(tid, str):
            if tid in self._event_tids:  # the gateway re-sent it (nobody answered yet): shown once
                self.resent += 1
                return []
            self._event_tids[tid] = body.get("need_reply") == 1
            while len(self._event_tids) > 1024:
                self._event_tids.pop(next(iter(self._event_tids)))
        text = f"{method} {_progress_text(data) if method == 'flighttask_progress' else _compact(data)}"
        before = (self.drc.failsafe, self.drc.failsafe_reason)
        if method == "drc_status_notify":
            self.drc.state = int(data.get("drc_state", self.drc.state))
            result = int(data.get("result", 0) or 0)
            if result == 514301:
                self._failsafe(f"{result} {_meaning(result)}", now, "heartbeat")
            elif result:
                self._failsafe(f"{result} {_meaning(result)}", now, f"result {result}")
            elif self.drc.failsafe_reason == "heartbeat":  # heartbeats resumed: that failsafe is over
                self.drc.failsafe = self.drc.failsafe_reason = None
        elif method == "joystick_invalid_notify":
            self._failsafe(f"joystick invalid (reason {data.get('reason')})", now, "authority")
        self.events.append((now, f"event {text}"))
        return [f"{_clock()} event  {text}", *self._failsafe_change(before, now)]

    def _failsafe_change(self, before: tuple[str | None, str | None], now: float) -> list[str]:
        """A line (and an entry in the event list) when the failsafe that holds changes: failsafes are
        shown as they happen, not only in the DRC panel."""
        drc = self.drc
        if (drc.failsafe, drc.failsafe_reason) == before or drc.failsafe == before[0]:
            return []
        text = f"FAILSAFE {drc.failsafe}" if drc.failsafe is not None else f"failsafe cleared ({before[0]})"
        self.events.append((now, text))
        return [f"{_clock()} drc    {text}"]

    def _services(self, sn: str, body: dict[str, Any], data: dict[str, Any], now: float) -> list[str]:
        text = f"{body.get('method')} {_compact(data)}"
        self.events.append((now, f"→ {text}"))
        return [f"{_clock()} call   {text} tid={body.get('tid')}"]

    def _services_reply(self, sn: str, body: dict[str, Any], data: dict[str, Any], now: float) -> list[str]:
        result = data.get("result")
        extra = f" {_compact(data['output'])}" if data.get("output") else ""
        text = f"{body.get('method')} result={result}{extra}"
        self.events.append((now, f"← {text}"))
        return [f"{_clock()} reply  {text} tid={body.get('tid')}"]

    def _requests(self, sn: str, body: dict[str, Any], data: dict[str, Any], now: float) -> list[str]:
        self.events.append((now, f"request {body.get('method')}"))
        return [f"{_clock()} req    {body.get('method')} {_compact(data)}"]

    def _drc_down(self, sn: str, body: dict[str, Any], data: dict[str, Any], now: float) -> list[str]:
        method = body.get("method")
        seq = data.get("seq", body.get("seq"))
        drc = self.drc
        if method == "heart_beat":
            drc.pending_heartbeats[seq] = now
            while len(drc.pending_heartbeats) > 64:
                drc.pending_heartbeats.pop(next(iter(drc.pending_heartbeats)))
            return []
        if method in ("drone_control", "stick_control"):
            drc.stick, drc.stick_at = dict(data), now
            return [f"{_clock()} drc    sticks {_compact(data)}"]
        if method == "drone_emergency_stop":
            before = (drc.failsafe, drc.failsafe_reason)
            self._failsafe(_FAILSAFE_TEXT["emergency_stop"], now, "emergency_stop")
            return [f"{_clock()} drc    EMERGENCY STOP", *self._failsafe_change(before, now)]
        return []

    def _drc_up(self, sn: str, body: dict[str, Any], data: dict[str, Any], now: float) -> list[str]:
        method = body.get("method")
        drc = self.drc
        if method == "heart_beat":
            seq = data.get("seq", body.get("seq"))
            sent = drc.pending_heartbeats.pop(seq, None)
            drc.heartbeats += 1
            drc.heartbeat_at = now
            if sent is None:
                return [f"{_clock()} drc    heart_beat seq={seq}"]
            rtt = (now - sent) * 1000.0
            drc.rtt_ms = rtt
            drc.rtt_avg_ms = rtt if drc.rtt_avg_ms is None else 0.8 * drc.rtt_avg_ms + 0.2 * rtt
            return [f"{_clock()} drc    heart_beat seq={seq} rtt={rtt:.1f}ms"]
        if method == "drone_control":
            drc.stick_result = int(data.get("result", 0) or 0)
            if drc.stick_result:
                return [f"{_clock()} drc    sticks refused {_compact(data)}"]
            return []
        if method == "delay_info_push":
            drc.delay_ms = data.get("sdr_cmd_delay")
        elif method == "osd_info_push":
            drc.push = dict(data)
        if method in _DRC_PUSHES:
            return [f"{_clock()} drc    {method} {_compact(data)}"] if self.verbose else []
        return [f"{_clock()} drc    {method} {_compact(data)}"]

    def _failsafe(self, text: str, now: float, reason: str) -> None:
        """Show ``text``; the same failsafe seen again keeps the time it first fired."""
        drc = self.drc
        if drc.failsafe is None or drc.failsafe_reason != reason or drc.failsafe_at is None:
            drc.failsafe_at = now
        else:  # still the same one (the osd repeats it, the event and the osd both tell it)
            drc.failsafe_at = min(drc.failsafe_at, now)
        drc.failsafe, drc.failsafe_reason = text, reason


#: How the monitor names each failsafe the gateway reports in its osd (``x_drc_failsafe.reason``).
_FAILSAFE_TEXT = {
    "sticks": "stick timeout: no drone_control for drc.stick_timeout, holding zero",
    "heartbeat": "514301 DRC link: heartbeat timed out",
    "emergency_stop": "emergency stop: held until sticks restart at seq 0",
    "link_lost": "514303 DRC link lost",
    "authority": "flight/payload authority lost",
}


def osd_summary(data: dict[str, Any], limit: int = 8) -> str:
    """The scalar fields that say most about a device, ``name=value`` (angles to 0.1)."""
    keys = [k for k in _OSD_FIRST if k in data] + sorted(k for k in data if k not in _OSD_FIRST)
    shown = []
    for key in keys:
        value = data[key]
        if isinstance(value, dict):
            if set(value) <= {"x", "y"} and value:
                shown.append(f"{key}=({_num(value.get('x'))},{_num(value.get('y'))})")
            continue
        if isinstance(value, list):
            continue
        shown.append(f"{key}={_num(value)}" + (_mode_label(value) if key == "mode_code" else ""))
        if len(shown) >= limit:
            break
    return " ".join(shown)


def _mode_label(code: Any) -> str:
    """``mode_code`` in words, as the contract names it: ``(wayline)``, ``(manual)`` …"""
    from schemas.osd import ModeCode

    try:
        return f"({ModeCode(int(code)).name.replace('_', ' ').lower()})"
    except (TypeError, ValueError):
        return ""


def _num(value: Any) -> str:
    """Floats without noise: 28.0 → 28, 0.1234567 → 0.123457, 22.54310012 → 22.5431."""
    if isinstance(value, float):
        return f"{value:.6f}".rstrip("0").rstrip(".") or "0"
    return str(value)


def _compact(data: Any, limit: int = 160) -> str:
    text = json.dumps(data, separators=(",", ":"), ensure_ascii=False)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def _meaning(code: int) -> str:
    from schemas.results import meaning

    return meaning(code).rstrip(".")


def _clock() -> str:
    now = time.time()
    return time.strftime("%H:%M:%S", time.localtime(now)) + f".{int(now * 1000) % 1000:03d}"


# ------------------------------------------------------------------------------------------ rich view
def _age(now: float, then: float | None) -> str:
    return "—" if then is None else f"{max(0.0, now - then):.1f}s"


def render(
    state: MonitorState, now: float, broker: str = "", height: int | None = None, width: int = 120
) -> RenderableType:
    """The live view: devices (online, osd), the DRC session, the latest events and replies: as many as
    fit in ``height`` rows of ``width`` columns (the terminal's), or 12 when no height is given.

    It always fits (issue #35: 80×24 shows the DRC panel and the newest events): when the full view does
    not, the devices collapse to one line each and the DRC panel to two lines without a frame; when that
    is still too tall, the devices that do not fit are counted ("… 2 more device(s)") and the events keep
    at least two rows."""
    if height is None:
        return _view(state, now, broker, 12)
    from rich.console import Console

    console = Console(width=width, file=io.StringIO())

    def lines(view: RenderableType) -> int:
        return len(console.render_lines(view, console.options, pad=False))

    # measure the view without events at this width (lines wrap), and give the events what is left
    bare = lines(_view(state, now, broker, 0))
    if height - bare - 1 >= 3:
        return _view(state, now, broker, height - bare - 1)
    shown = len(state.devices)
    while True:
        bare = lines(_view(state, now, broker, 0, compact=True, devices=shown))
        if height - bare - 1 >= 2 or shown == 0:
            return _view(state, now, broker, max(1, height - bare - 1), compact=True, devices=shown)
        shown -= 1


def _view(
    state: MonitorState,
    now: float,
    broker: str,
    rows: int,
    *,
    compact: bool = False,
    devices: int | None = None,
) -> RenderableType:
    from rich import box
    from rich.console import Group
    from rich.panel import Panel
    from rich.table import Table
    from rich.text import Text

    gw = state.gateway_sn
    title = f"dji-gateway monitor · gateway {gw}" + (f" · {broker}" if broker else "")
    if state.topology_at is not None:
        where = " (from the gateway's /status)" if state.topology_source else ""
        head = f"topology {_age(now, state.topology_at)} ago{where} · messages {state.messages}"
        if state.resent:
            head += f" · {state.resent} event re-sends (unanswered events)"
    elif state.messages:
        head = (
            f"messages {state.messages} · no update_topo yet (sent on connect and when devices come or go; "
            "--status-url lets the monitor ask the gateway)"
        )
    else:
        head = "waiting for the gateway (is it running and connected to this broker?)"
    frame = None if compact else box.HEAVY_HEAD  # rich's default table box, or none when collapsed
    table = Table(title=None if compact else "devices", expand=True, title_justify="left",
                  show_header=not compact, box=frame)  # fmt: skip
    columns = ("sn", "online", "osd age", "osd") if compact else ("sn", "domain", "online", "osd age", "osd")
    for name in columns:
        table.add_column(
            name,
            overflow="ellipsis" if compact else "fold",
            no_wrap=compact,
            ratio=4 if name == "osd" else None,
        )
    views = list(state.devices.values())
    shown = views if devices is None else views[:devices]
    for view in shown:
        cells = [
            view.sn,
            view.domain if view.domain != "?" else "—",
            "[green]online[/]" if view.online else "[red]offline[/]",
            _age(now, view.osd_at),
            osd_summary(view.osd, limit=10),
        ]
        if compact:
            del cells[1]
        table.add_row(*cells)
    drc = state.drc
    names = {0: "idle", 1: "connecting", 2: "in live control"}
    rtt = "—" if drc.rtt_ms is None else f"{drc.rtt_ms:.1f} ms (avg {drc.rtt_avg_ms:.1f} ms)"
    sticks = (
        " ".join(f"{k}={_num(drc.stick[k])}" for k in ("seq", "x", "y", "h", "w") if k in drc.stick) or "—"
    )
    refused = f" (refused {drc.stick_result})" if drc.stick_result else ""
    failsafe = "none" if drc.failsafe is None else f"[red]{drc.failsafe}[/] {_age(now, drc.failsafe_at)} ago"
    events = Table(title=None if compact else "events and replies", expand=True, title_justify="left",
                   show_header=False, box=frame)  # fmt: skip
    events.add_column("age", width=7, no_wrap=True)
    events.add_column("what", overflow="ellipsis", no_wrap=True, ratio=1)
    for at, text in list(state.events)[::-1][:rows]:
        events.add_row(_age(now, at), text)
    if compact:
        drc_lines = Table.grid(expand=True)
        drc_lines.add_column(overflow="ellipsis", no_wrap=True)
        drc_lines.add_row(
            f"[bold]DRC {drc.state} ({names.get(drc.state, '?')})[/] · failsafe {failsafe} · "
            f"heartbeat {drc.heartbeats}, {_age(now, drc.heartbeat_at)} ago, rtt {rtt}"
        )
        drc_lines.add_row(f"[bold]sticks[/] {sticks}, {_age(now, drc.stick_at)} ago{refused}")
        hidden = len(views) - len(shown)
        more = (
            [Text(f"… {hidden} more device(s): a taller terminal shows them", style="dim")] if hidden else []
        )
        parts: list[RenderableType] = [Text(head, overflow="ellipsis", no_wrap=True), table, *more, drc_lines]
        return Panel(Group(*parts, Text("events and replies", style="bold"), events), title=title,
                     title_align="left")  # fmt: skip
    drc_table = Table.grid(padding=(0, 2))
    drc_table.add_column(style="bold")
    drc_table.add_column()
    drc_table.add_row("drc_state", f"{drc.state} ({names.get(drc.state, '?')})")
    drc_table.add_row(
        "heartbeat", f"{drc.heartbeats} echoed, last {_age(now, drc.heartbeat_at)} ago, rtt {rtt}"
    )
    drc_table.add_row("sticks", f"{sticks}, {_age(now, drc.stick_at)} ago{refused}")
    drc_table.add_row("failsafe", failsafe)
    if drc.delay_ms is not None:
        drc_table.add_row("command delay", f"{drc.delay_ms} ms")
    if drc.push:
        drc_table.add_row("osd_info_push", osd_summary(drc.push, limit=8))
    return Panel(
        Group(head, table, Panel(drc_table, title="live control (DRC)", title_align="left"), events),
        title=title,
        title_align="left",
    )


# ------------------------------------------------------------------------------------------ monitor
#: How long the monitor waits for another cloud to answer an event before it answers it itself
#: (``--reply-events auto``); the gateway re-sends after ``dispatcher.event_retry_interval`` (3 s).
AUTO_REPLY_GRACE = 1.0


class EventAnswerer:
    """Answers events that carry ``need_reply`` as a cloud would (an ``events_reply`` with result 0), so
    the gateway stops re-sending them. ``always`` answers at once; ``auto`` only when no other cloud
    has answered within :data:`AUTO_REPLY_GRACE` (the monitor is then the only cloud); ``never`` not."""

    def __init__(self, link: _Link, state: MonitorState, lock: threading.Lock, mode: str) -> None:
        self.link, self.state, self.lock, self.mode = link, state, lock, mode
        self.sent = 0

    def event(self, payload: bytes) -> None:
        if self.mode == "never":
            return
        try:
            body = json.loads(payload)
        except ValueError:
            return
        if not isinstance(body, dict) or body.get("need_reply") != 1 or not isinstance(body.get("tid"), str):
            return
        if self.mode == "always":
            self._answer(body)
            return
        timer = threading.Timer(AUTO_REPLY_GRACE, self._answer, args=(body,))
        timer.daemon = True
        timer.start()

    def _answer(self, body: dict[str, Any]) -> None:
        tid = body["tid"]
        with self.lock:
            if not self.state.wants_answer(tid):
                return
            self.state.answered.add(tid)
        reply = {
            "tid": tid,
            "bid": body.get("bid"),
            "timestamp": int(time.time() * 1000),
            "method": body.get("method"),
            "data": {"result": 0},
        }
        # from paho's thread (always) or a timer: publish without waiting for the broker's PUBACK
        topic = f"thing/product/{self.state.gateway_sn}/events_reply"
        self.link.client.publish(topic, json.dumps(reply), qos=1)
        self.sent += 1


def _ask_status(url: str, state: MonitorState, lock: threading.Lock, plain: bool) -> None:
    """Learn the topology from the gateway's ``/status`` (its ``update_topo`` went out before this
    monitor subscribed). Nobody there, or another gateway: nothing learnt, nothing said."""
    from gateway.cli.status import fetch

    try:
        code, doc = fetch(url, "/status", 2.0)
    except (OSError, ValueError):
        return
    if code != 200 and "gateway_sn" not in doc:
        return
    with lock:
        lines = state.learn_status(doc, time.monotonic())
    if plain:
        for line in lines:
            print(line, flush=True)


def cmd_monitor(ns: argparse.Namespace) -> int:
    if not ns.gateway_sn:
        print(f"dji-gateway monitor: --gateway-sn is required (or set ${GATEWAY_ENV})", file=sys.stderr)
        return EXIT_USAGE
    state = MonitorState(ns.gateway_sn, verbose=ns.verbose)
    plain = ns.plain or (not ns.once and not sys.stdout.isatty())
    lock = threading.Lock()
    answerer: list[EventAnswerer] = []

    def on_message(topic: str, payload: bytes) -> None:
        with lock:
            lines = state.feed(topic, payload, time.monotonic())
        if plain:
            for line in lines:
                print(line, flush=True)
        if topic.endswith("/events") and answerer:
            answerer[0].event(payload)

    try:
        link = _Link(ns, on_message)
        answerer.append(EventAnswerer(link, state, lock, ns.reply_events))
        link.open(state.topics())
    except BrokerError as exc:
        print(f"dji-gateway monitor: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if plain:
        print(f"monitoring gateway {ns.gateway_sn} on {ns.broker} (Ctrl-C stops)", flush=True)
    from gateway.cli.status import default_url

    status_url = default_url() if ns.status_url is None else ns.status_url
    if status_url:
        threading.Thread(target=_ask_status, args=(status_url, state, lock, plain), daemon=True).start()
    duration = ns.duration if ns.duration is not None else (3.0 if ns.once else None)
    deadline = None if duration is None else time.monotonic() + duration
    try:
        if ns.once:
            _sleep_until(deadline)
            from rich.console import Console

            with lock:
                Console(width=max(100, _terminal_width())).print(render(state, time.monotonic(), ns.broker))
            return EXIT_OK if state.messages else EXIT_ERROR_RESULT
        if plain:
            _sleep_until(deadline)
            return EXIT_OK
        from rich.console import Console
        from rich.live import Live

        console = Console()

        def view() -> RenderableType:
            with lock:
                size = console.size
                return render(state, time.monotonic(), ns.broker, height=size.height, width=size.width)

        with Live(view(), console=console, refresh_per_second=4, screen=False) as live:
            while deadline is None or time.monotonic() < deadline:
                time.sleep(0.25)
                live.update(view())
        return EXIT_OK
    except KeyboardInterrupt:
        return EXIT_OK
    finally:
        link.close()


def _sleep_until(deadline: float | None) -> None:
    while deadline is None or time.monotonic() < deadline:
        time.sleep(0.1 if deadline is None else max(0.0, min(0.1, deadline - time.monotonic())))
        if deadline is not None and time.monotonic() >= deadline:
            return


def _terminal_width() -> int:
    try:
        return os.get_terminal_size().columns
    except OSError:
        return 120
