"""``dji-gateway fly``: live flight control (DRC) from the keyboard, for a person at a terminal.

It grabs flight authority, enters DRC on the broker it is connected to (the gateway then reuses its own
connection), streams ``drone_control`` at 10 Hz and ``heart_beat`` at 1 Hz on ``drc/down``, and draws the
monitor's view (the DRC panel: heartbeat round trip, sticks, failsafes, ``osd_info_push``) under a line
of keys. It stops the aircraft (zero sticks) and leaves DRC on Esc, Ctrl-C, or when the terminal loses
focus (focus reporting, ``ESC[?1004h``: the terminal sends ``ESC[O`` on focus out) — a window left
behind must not keep flying. A terminal sends no key-up, so a key moves the aircraft while it is
held: auto-repeat refreshes it, and it lapses ``--hold`` (0.6 s, longer than the usual auto-repeat
delay) after the last repeat; Space zeroes every axis at once, ``x`` is an emergency stop.

:class:`KeyDecoder` (bytes and time in, key names out) and :class:`Sticks` (keys and time in, stick
values out) are sans-I/O and tested alone; :func:`cmd_fly` is the thin loop around them (termios, the
broker link of :mod:`gateway.cli.console`, rich). Knows nothing of devices: what the sticks do is the
gateway's business (``drc.*`` settings, docs/drc.md).

Time: reads the system clock itself (a separate process; the gateway's injected clock is the service's).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import select
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from gateway.cli.console import (
    EXIT_ERROR_RESULT,
    EXIT_OK,
    EXIT_USAGE,
    GATEWAY_ENV,
    PASSWORD_ENV,
    BrokerError,
    EventAnswerer,
    MonitorState,
    _connection_args,
    _Link,
    build_message,
    render,
)

__all__ = ["KEYS", "KeyDecoder", "Sticks", "add_parsers", "cmd_fly"]

STICK_HZ = 10.0
HEARTBEAT_PERIOD = 1.0
ESC_WAIT = 0.05  # a lone ESC byte is the Esc key once nothing follows it for this long
FOCUS_ON, FOCUS_OFF = "\x1b[?1004h", "\x1b[?1004l"

#: key → (axis, direction): x left +, y forward +, h up +, w clockwise + (the seed's stick axes)
KEYS: dict[str, tuple[str, int]] = {
    "w": ("y", 1), "up": ("y", 1), "s": ("y", -1), "down": ("y", -1),
    "a": ("x", 1), "left": ("x", 1), "d": ("x", -1), "right": ("x", -1),
    "r": ("h", 1), "f": ("h", -1),
    "q": ("w", -1), "e": ("w", 1),
}  # fmt: skip
QUIT_KEYS = frozenset({"esc", "ctrl-c", "focus_out"})
HELP = (
    "w/s ↑/↓ forward/back · a/d ←/→ left/right · r/f up/down · q/e yaw · space stop · x emergency stop · "
    "Esc, Ctrl-C or leaving the window: stop and exit"
)

_CSI_KEYS = {"A": "up", "B": "down", "C": "right", "D": "left", "O": "focus_out", "I": "focus_in"}


class KeyDecoder:
    """Terminal bytes → key names: letters as themselves, ``space``, ``esc``, ``ctrl-c``, arrows
    (``ESC [ A`` and ``ESC O A``), ``focus_in``/``focus_out`` (``ESC [ I``/``ESC [ O``); other
    escape sequences are swallowed whole. A lone ESC waits :data:`ESC_WAIT` for a sequence."""

    def __init__(self) -> None:
        self._pending = ""
        self._since = 0.0

    def feed(self, data: bytes, now: float) -> list[str]:
        text = self._pending + data.decode("utf-8", "replace")
        if data:
            self._since = now
        keys: list[str] = []
        i = 0
        while i < len(text):
            ch = text[i]
            if ch != "\x1b":
                keys.append({" ": "space", "\x03": "ctrl-c"}.get(ch, ch.lower()))
                i += 1
                continue
            if i + 1 >= len(text):
                break  # maybe the start of a sequence: wait
            intro = text[i + 1]
            if intro not in "[O":
                keys.append("esc")  # ESC then an ordinary key
                i += 1
                continue
            j = i + 2
            while j < len(text) and not ("@" <= text[j] <= "~"):
                j += 1
            if j >= len(text):
                break  # incomplete: wait for the rest
            final = text[j]
            name = _CSI_KEYS.get(final) if j == i + 2 else None
            if intro == "O" and final == "O":  # ESC O O is not a key; ESC [ O is focus out
                name = None
            if name is not None:
                keys.append(name)
            i = j + 1
        self._pending = text[i:]
        return keys

    def flush(self, now: float) -> list[str]:
        """A lone ESC that nothing followed in time is the Esc key."""
        if self._pending == "\x1b" and now - self._since >= ESC_WAIT:
            self._pending = ""
            return ["esc"]
        return []


@dataclass
class Sticks:
    """Held keys → stick values. A key holds its axis for ``hold`` seconds after its last press (key
    repeat renews it); the opposite key takes over at once; Space releases everything."""

    speed: float = 2.0  # m/s, forward/back and sideways
    climb: float = 1.0  # m/s, up/down
    yaw_rate: float = 30.0  # °/s
    hold: float = 0.6
    pressed: dict[str, tuple[int, float]] = field(default_factory=dict)  # axis → (direction, when)

    def press(self, key: str, now: float) -> None:
        if key == "space":
            self.pressed.clear()
        elif key in KEYS:
            axis, sign = KEYS[key]
            self.pressed[axis] = (sign, now)

    def values(self, now: float) -> dict[str, float]:
        scale = {"x": self.speed, "y": self.speed, "h": self.climb, "w": self.yaw_rate}
        out = {axis: 0.0 for axis in ("x", "y", "h", "w")}
        for axis, (sign, when) in list(self.pressed.items()):
            if now - when > self.hold:
                del self.pressed[axis]
            else:
                out[axis] = sign * scale[axis]
        return out


def add_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "fly",
        help="live flight control (DRC) from the keyboard",
        description="Grab flight authority, enter DRC, stream sticks at 10 Hz and heartbeats at 1 Hz from "
        "the keyboard and show the DRC panel. " + HELP + ". Exit 0 after leaving DRC, 1 when DRC could not "
        "be entered, 2 without a broker or a terminal.",
    )
    p.add_argument(
        "--speed", type=float, default=2.0, help="forward/back/sideways speed while a key is held (2 m/s)"
    )
    p.add_argument("--climb", type=float, default=1.0, help="up/down speed (1 m/s)")
    p.add_argument("--yaw-rate", type=float, default=30.0, help="yaw rate (30 °/s)")
    p.add_argument(
        "--hold",
        type=float,
        default=0.6,
        help="a key moves the aircraft this long after its last repeat (0.6 s)",
    )
    _connection_args(p)
    p.set_defaults(handler=cmd_fly)


# ------------------------------------------------------------------------------------------ the loop
class _Session:
    """The broker side of one fly session: requests with replies, drc/down messages, the view's state."""

    def __init__(self, ns: argparse.Namespace) -> None:
        self.gw = ns.gateway_sn
        self.state = MonitorState(self.gw)
        self.lock = threading.Lock()
        self._replies: dict[str, dict[str, Any]] = {}
        self._arrived = threading.Condition()
        self.link = _Link(ns, self._on_message)
        self.answerer = EventAnswerer(self.link, self.state, self.lock, "auto")
        self.stick_seq = 0
        self.heartbeat_seq = 0

    def _on_message(self, topic: str, payload: bytes) -> None:
        with self.lock:
            self.state.feed(topic, payload, time.monotonic())
        if topic.endswith("/services_reply"):
            with contextlib.suppress(ValueError):
                body = json.loads(payload)
                if isinstance(body, dict) and isinstance(body.get("tid"), str):
                    with self._arrived:
                        self._replies[body["tid"]] = body
                        self._arrived.notify_all()
        elif topic.endswith("/events"):
            self.answerer.event(payload)

    def open(self) -> None:
        self.link.open([*self.state.topics(), f"thing/product/{self.gw}/services_reply"])

    def request(self, method: str, data: dict[str, Any], timeout: float = 10.0) -> tuple[int, str]:
        """One service and its result code and reason; -1 when no reply came within ``timeout``."""
        body = build_message(method, data)
        self.link.publish(f"thing/product/{self.gw}/services", body)
        deadline = time.monotonic() + timeout
        with self._arrived:
            while body["tid"] not in self._replies:
                left = deadline - time.monotonic()
                if left <= 0:
                    return -1, "no reply (is the gateway running and connected to this broker?)"
                self._arrived.wait(left)
            reply = self._replies.pop(body["tid"])
        rdata = reply.get("data") or {}
        output: dict[str, Any] = rdata["output"] if isinstance(rdata.get("output"), dict) else {}
        return int(rdata.get("result", 0) or 0), str(output.get("reason", ""))

    def drc(self, method: str, data: dict[str, Any]) -> None:
        body = {"method": method, "data": data}
        self.link.client.publish(
            f"thing/product/{self.gw}/drc/down", json.dumps(body, separators=(",", ":")), qos=0
        )

    def sticks(self, values: dict[str, float]) -> None:
        self.drc("drone_control", {"seq": self.stick_seq, **values})
        self.stick_seq += 1

    def heartbeat(self) -> None:
        self.drc("heart_beat", {"seq": self.heartbeat_seq, "timestamp": int(time.time() * 1000)})
        self.heartbeat_seq += 1


@contextlib.contextmanager
def _keyboard(fd: int) -> Iterator[None]:
    """cbreak (keys one by one, no echo; Ctrl-C still a signal), focus reporting on; both undone."""
    import termios
    import tty

    saved = termios.tcgetattr(fd)
    tty.setcbreak(fd)
    sys.stdout.write(FOCUS_ON)
    sys.stdout.flush()
    try:
        yield
    finally:
        sys.stdout.write(FOCUS_OFF)
        sys.stdout.flush()
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)


def _enter_data(ns: argparse.Namespace, session: _Session) -> dict[str, Any]:
    s = session.link.settings
    return {
        "mqtt_broker": {
            "address": f"{s.host}:{s.port}",
            "client_id": f"djigw-fly-{uuid.uuid4().hex[:8]}",
            "username": ns.username or "fly",
            "password": os.environ.get(PASSWORD_ENV) or "-",
            "expire_time": int(time.time()) + 3600,
            "enable_tls": s.tls,
        },
        "osd_frequency": 10,
        "hsi_frequency": 1,
    }


def cmd_fly(ns: argparse.Namespace) -> int:
    if not ns.gateway_sn:
        print(f"dji-gateway fly: --gateway-sn is required (or set ${GATEWAY_ENV})", file=sys.stderr)
        return EXIT_USAGE
    fd = sys.stdin.fileno()
    if not os.isatty(fd):
        print("dji-gateway fly: needs a terminal (keys are read one by one)", file=sys.stderr)
        return EXIT_USAGE
    try:
        session = _Session(ns)
        session.open()
    except BrokerError as exc:
        print(f"dji-gateway fly: {exc}", file=sys.stderr)
        return EXIT_USAGE
    try:
        for method, data in (("flight_authority_grab", {}), ("drc_mode_enter", _enter_data(ns, session))):
            result, reason = session.request(method, data)
            if result != 0:
                print(f"dji-gateway fly: {method} failed: {result} {reason}".rstrip(), file=sys.stderr)
                return EXIT_ERROR_RESULT
        print(f"in live control of {ns.gateway_sn}: {HELP}", flush=True)
        why = _fly(ns, session, fd)
        session.sticks({"x": 0.0, "y": 0.0, "h": 0.0, "w": 0.0})  # stop first, then leave
        result, reason = session.request("drc_mode_exit", {}, timeout=5.0)
        left = "left DRC" if result == 0 else f"drc_mode_exit answered {result} {reason}".rstrip()
        print(f"\n{why}: sticks zeroed (the aircraft hovers), {left}", flush=True)
        return EXIT_OK
    finally:
        session.link.close()


def _fly(ns: argparse.Namespace, session: _Session, fd: int) -> str:
    """The 10 Hz loop until a quit key; returns why it ended."""
    from rich.console import Console, Group
    from rich.live import Live
    from rich.text import Text

    keys, sticks = KeyDecoder(), Sticks(ns.speed, ns.climb, ns.yaw_rate, ns.hold)
    console = Console()
    period = 1.0 / STICK_HZ
    next_stick = time.monotonic()
    next_heartbeat = next_stick
    next_draw = next_stick

    def view() -> Any:
        size = console.size
        with session.lock:
            body = render(
                session.state, time.monotonic(), ns.broker, height=size.height - 2, width=size.width
            )
        return Group(Text(HELP, style="bold"), body)

    try:
        with _keyboard(fd), Live(view(), console=console, auto_refresh=False, screen=False) as live:
            while True:
                now = time.monotonic()
                wait = max(0.0, min(next_stick, next_heartbeat) - now)
                ready, _, _ = select.select([fd], [], [], min(wait, ESC_WAIT))
                now = time.monotonic()
                pressed = keys.feed(os.read(fd, 64), now) if ready else []
                pressed += keys.flush(now)
                for key in pressed:
                    if key in QUIT_KEYS:
                        return {"esc": "Esc", "ctrl-c": "Ctrl-C", "focus_out": "the terminal lost focus"}[key]
                    if key == "x":
                        session.drc("drone_emergency_stop", {})
                        sticks.pressed.clear()
                        session.stick_seq = 0  # an emergency stop holds until sticks restart at seq 0
                    else:
                        sticks.press(key, now)
                if now >= next_heartbeat:
                    session.heartbeat()
                    next_heartbeat += HEARTBEAT_PERIOD
                if now >= next_stick:
                    session.sticks(sticks.values(now))
                    next_stick = max(next_stick + period, now)  # never a burst to catch up
                if now >= next_draw:
                    live.update(view(), refresh=True)
                    next_draw = now + 0.25
    except KeyboardInterrupt:
        return "Ctrl-C"
