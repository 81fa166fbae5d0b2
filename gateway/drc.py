"""Live flight control (DRC): the I/O around the sans-I/O session in :mod:`gateway.drc_session`.

Owns: the DRC broker link named by ``drc_mode_enter`` (a dedicated paho client, or the main
connection when it is the same broker), turning ``drc/down`` messages into session events and the
session's actions into ``drc/up`` replies, ``drc_status_notify`` events, the gateway osd, metrics
and motion, the pushes (osd/hsi/delay, aircraft state, battery), ``drc_gimbal_reset`` (run as the
``gimbal_reset`` service), and the one thread that writes motion frames to devices.
Must not know: how a decision is made (the session decides: states, seq rules, failsafes, the order
of session changes), bytes on a device link (adapters encode), or Cloud API routing (dispatcher).

Threads (see docs/architecture.md, "Runtime model"):

* **paho's network thread(s)** (the main connection's, and the dedicated DRC link's) parse
  ``drc/down`` and feed the session at once: heartbeats are echoed from there and a stick updates
  the set-point, even while the event loop is flooded;
* the **motion writer** (``drc-writer``, one per gateway, :class:`MotionWriter`) is the only thread
  that sends live-control frames (``drive``/``emergency_stop``) to devices. Every other path only
  changes the set-point it holds and wakes it; it also ticks the session every control period
  (``1/stream_hz``), which applies the stick and heartbeat timeouts;
* the **event loop** feeds ``drc_mode_enter``/``drc_mode_exit``, link outcomes, authority changes and
  shutdown, opens and closes DRC links, publishes events/osd and runs the pushes.

One lock serialises every call into the session; actions are carried out in the order the session
returned them. Whatever must run in the loop (events, link changes, request answers) is scheduled with
``call_soon_threadsafe`` *under that lock*, so the loop sees them in the session's order whichever
thread produced them.

A flood of ``drone_control`` (a cloud bug, a stuck key repeat) must not starve heartbeats: past
``max_stick_rate`` sticks are dropped *before* they are parsed (a byte match on the method, counted as
``drc_rejected_total{reason="rate"}``); heartbeats and emergency stops never count against the
budget. An emergency stop is never refused for a parsing reason: a ``drc/down`` message whose method
reads ``drone_emergency_stop`` stops every device whatever its ``data``.

Sticks are the seed's: ``x`` lateral (+ left), ``y`` longitudinal (+ forward), ``h`` vertical
(+ up), ``w`` yaw rate (+ clockwise); ``x_sign``, ``y_sign`` and ``swap_xy`` adapt clouds that
disagree. ``stick_control`` (DJI's newer docs) sends RC channels instead, mapped by
``drc_session.channels_to_setpoint``. Devices receive body-frame forward / right / up velocities and a
clockwise yaw rate.

Why this module is longer than 500 lines: it is the shell of the live-control session: the one lock, the
motion writer, the DRC broker links, drc/down parsing and drc/up answers and the pushes, which must be read
together to see that every stop reaches the writer without the loop; the decisions live in
drc_session.py.
"""

from __future__ import annotations

import asyncio
import contextlib
import hashlib
import json
import logging
import re
import threading
import time
from collections import deque
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from pydantic import ValidationError

from adapters.base import Adapter, AircraftPose, Domain
from gateway import drc_session as ds
from gateway.audit import audit
from gateway.clock import Clock, SystemClock
from gateway.control_auth import ControlAuth
from gateway.devices import DeviceTable
from gateway.metrics import Metrics
from gateway.mqtt import MqttBridge
from gateway.ratelimit import TokenBucket
from gateway.settings import BrokerSettings, GatewaySettings
from schemas import ResultCode, TopicKind, echo_heart_beat, error_reply_from_validation, reply_for, topic
from schemas.drc import SILENT_WHEN_ACCEPTED, DroneControl
from schemas.registry import Registry
from schemas.services import MAX_PUSH_FREQUENCY, DrcModeEnter

log = logging.getLogger(__name__)

__all__ = ["DrcController", "MotionWriter"]

ZERO = ds.ZERO
#: how a drone_control or stick_control is recognised before it is parsed (whatever the spacing)
_STICK = re.compile(rb'"method"\s*:\s*"(?:drone|stick)_control"')
_ESTOP = re.compile(rb'"method"\s*:\s*"drone_emergency_stop"')


@dataclass(frozen=True, slots=True)
class _Down:
    """A drc/down request as the session sees it: answered on the link it came in on. ``message`` is
    None for an emergency stop that could not be parsed (answered with a reply built by hand)."""

    via: MqttBridge
    message: Any


#: the request token of an emergency stop the gateway itself raised (no drc/up answer)
_LOCAL = object()

#: the failsafe reasons reported in metrics and in the gateway osd (``x_drc_failsafe``)
FAILSAFES = ("sticks", "heartbeat", "emergency_stop", "link_lost", "authority")


class MotionWriter:
    """The one thread that sends live-control frames to devices.

    It holds the set-point (:meth:`set`) and an emergency-stop request (:meth:`emergency`), which any
    thread may change; it sends a changed set-point at once (one thread hand-off: stick-to-wire is one
    frame), and the streamed set-point every ``period``. Before each periodic send it calls ``tick``
    (the session's timeouts), so a loss is acted on within one period. Without a session (the set-point
    is not streamed) it sleeps until woken: a hundred idle gateways in one process cost no wake-ups. A
    device call that raises is counted and logged by ``on_failure``, never swallowed; it cannot stop the
    stream to other devices.
    """

    def __init__(
        self,
        *,
        period: float,
        devices: Callable[[], Sequence[Adapter]],
        targets: Callable[[], Sequence[Adapter]],
        tick: Callable[[float], None],
        now: Callable[[], float],
        on_failure: Callable[[Adapter | None, str, BaseException], None],  # None: the tick failed
        on_sent: Callable[[float], None] | None = None,
    ) -> None:
        self.period = period
        self._devices = devices
        self._targets = targets
        self._tick = tick
        self._now = now
        self._on_failure = on_failure
        self._on_sent = on_sent
        self._cond = threading.Condition(threading.Lock())
        self._setpoint: ds.SetPoint = ZERO
        self._stream = False
        self._dirty = False
        self._since: float | None = None
        self._estop = False
        self._stopping = False
        self._thread: threading.Thread | None = None
        self.frames_sent = 0  # drive() calls that went out (tests, /status)

    # -- any thread ------------------------------------------------------------------------------
    def set(self, setpoint: ds.SetPoint, stream: bool, since: float | None = None) -> None:
        with self._cond:
            self._setpoint, self._stream, self._dirty, self._since = setpoint, stream, True, since
            self._cond.notify()
        if threading.current_thread() is not self._thread:
            # not a timer (no clock): hand the interpreter to the writer, so the frame goes out before the
            # reply
            time.sleep(0)

    def emergency(self) -> None:
        with self._cond:
            self._estop = True
            self._cond.notify()

    @property
    def streaming(self) -> bool:
        return self._stream

    @property
    def setpoint(self) -> ds.SetPoint:
        return self._setpoint

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="drc-writer", daemon=True)
        self._thread.start()

    def stop(self, timeout: float = 2.0) -> None:
        """Send what is pending (the final zero), then end the thread."""
        with self._cond:
            self._stopping = True
            self._cond.notify()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    # -- the writer thread -----------------------------------------------------------------------
    def _run(self) -> None:
        next_tick = self._now() + self.period
        while True:
            with self._cond:
                while not (self._dirty or self._estop or self._stopping):
                    if not self._stream:  # no session: nothing to stream or time out; sleep until woken
                        self._cond.wait()
                        next_tick = self._now() + self.period
                        continue
                    left = next_tick - self._now()
                    if left <= 0:
                        break
                    self._cond.wait(left)
                stopping = self._stopping
            now = self._now()
            periodic = False
            if now >= next_tick and not stopping:
                next_tick = max(next_tick + self.period, now + self.period / 2)
                periodic = True
                try:
                    self._tick(now)
                except Exception as exc:  # the session is pure; a failure here is a bug, not a device
                    log.exception("DRC tick failed")
                    self._on_failure_safe(None, "tick", exc)
            with self._cond:
                setpoint, stream, dirty, since, estop = (
                    self._setpoint, self._stream, self._dirty, self._since, self._estop
                )  # fmt: skip
                self._dirty = self._estop = False
                self._since = None
            if estop:
                for adapter in self._devices():
                    try:
                        adapter.emergency_stop()
                    except Exception as exc:
                        self._on_failure_safe(adapter, "emergency_stop", exc)
            if dirty or (periodic and stream):
                self.write(setpoint)
                if since is not None and self._on_sent is not None:
                    self._on_sent(since)
            if stopping:
                with self._cond:
                    if not (self._dirty or self._estop):
                        return

    def write(self, setpoint: ds.SetPoint) -> None:
        for adapter in self._targets():
            try:
                adapter.drive(*setpoint)
                self.frames_sent += 1
            except Exception as exc:
                self._on_failure_safe(adapter, "stop" if setpoint == ZERO else "drive", exc)

    def _on_failure_safe(self, adapter: Adapter | None, what: str, exc: BaseException) -> None:
        try:
            self._on_failure(adapter, what, exc)
        except Exception:
            log.exception("DRC failure hook failed")


class DrcController:
    def __init__(
        self,
        *,
        settings: GatewaySettings,
        registry: Registry,
        devices: DeviceTable,
        metrics: Metrics,
        loop: asyncio.AbstractEventLoop,
        main_bridge: MqttBridge,
        publish_event: Callable[[str, dict[str, Any], bool], None],
        publish_gateway_osd: Callable[[dict[str, Any]], None],
        clock: Clock | None = None,
        link_factory: Callable[..., MqttBridge] = MqttBridge,
    ) -> None:
        self.settings = settings
        self.cfg = settings.drc
        self.gw = settings.gateway_sn
        self.registry = registry
        self.devices = devices
        self.metrics = metrics
        self.loop = loop
        self.main_bridge = main_bridge
        self.publish_event = publish_event
        self.publish_gateway_osd = publish_gateway_osd
        self.clock = clock or SystemClock()
        self.now = self.clock.monotonic
        self._link_factory = link_factory
        self.down_topic = topic(TopicKind.DRC_DOWN, self.gw)
        self.up_topic = topic(TopicKind.DRC_UP, self.gw)
        self.session = ds.DrcSession(
            ds.SessionConfig(
                stick_timeout=self.cfg.stick_timeout,
                heartbeat_timeout=self.cfg.heartbeat_timeout,
                idle_timeout=self.cfg.idle_timeout,
            )
        )
        self._lock = threading.Lock()  # every call into the session, and the actions it returns
        self._stick_budget = self._new_stick_budget()  # network threads only
        #: full stick_control deflection (drc.stick_*): docs/drc.md
        self._stick_limits = ds.StickLimits(
            self.cfg.stick_horizontal, self.cfg.stick_up, self.cfg.stick_down, self.cfg.stick_yaw_rate
        )
        self._up: MqttBridge = main_bridge  # where the current session answers
        self._links: dict[int, MqttBridge | None] = {}  # session id -> its dedicated link (None: main)
        self._opening: dict[int, asyncio.Task[None]] = {}
        self._closing: set[asyncio.Task[None]] = set()
        self._targets: tuple[Adapter, ...] = ()
        #: an aircraft or robot is here (flight authority governs sticks), else payloads only
        self._has_movable = any(a.info.domain != Domain.PAYLOAD for a in devices)
        self._push_task: asyncio.Task[None] | None = None
        self._pending_broker: dict[Any, Any] = {}  # link key -> drc_mode_enter's mqtt_broker, until opened
        self._failure_logged: dict[tuple[str, str], float] = {}
        #: runs a services request (bytes) as the cloud's would be and returns its reply: the dispatcher's
        #: ``call_local``, set by the app (drc_gimbal_reset is the gimbal_reset service over drc/down)
        self.call_service: Callable[[bytes], Awaitable[bytes]] | None = None
        #: cloud-control authorisation (set by the app): in force, enter needs a grant and the session's
        #: sticks belong to the user who held it when entering (``_owner``); gateway/control_auth.py
        self.cloud_control: ControlAuth | None = None
        self._owner: str | None = None
        self._forwarding: set[asyncio.Task[None]] = set()
        self._forwarded = 0  # drc_gimbal_reset carried out (a tid for one without a seq)
        self.cmd_delay_ms = 0.0
        self.osd_hz = 10
        self.hsi_hz = 1
        #: the last heartbeats as (received, the cloud's send time), wall clock ms: the web console's chart
        self.heartbeats: deque[tuple[int, int]] = deque(maxlen=120)
        self.writer = MotionWriter(
            period=1.0 / self.cfg.stream_hz,
            devices=lambda: list(self.devices),
            targets=lambda: self._targets,
            tick=self._tick,
            now=self.now,
            on_failure=self._device_failure,
            on_sent=self._measured,
        )

    def start(self) -> None:
        """Start the motion writer (the app does, once; a controller that is never started drives nothing)."""
        self.writer.start()

    # ------------------------------------------------------------------------------- observers
    @property
    def drc_state(self) -> int:
        return self.session.drc_state

    @property
    def active(self) -> bool:
        return self.session.state in (ds.State.ACTIVE, ds.State.HOLDING)

    @property
    def dedicated_link(self) -> MqttBridge | None:
        """The current session's own DRC broker connection; None when it rides the main one (or none)."""
        sid = self.session.session_id
        return self._links.get(sid) if sid is not None else None

    def snapshot(self) -> dict[str, Any]:
        """Live control for ``/status``."""
        with self._lock:
            view = self.session.snapshot(self.now())
        forward, right, up, yaw = self.writer.setpoint
        return {
            "state": self.session.drc_state,
            "active": self.active,
            "broker": "dedicated" if self.dedicated_link is not None else "main",
            **view,
            "setpoint": {"forward": forward, "right": right, "up": up, "yaw_rate": yaw},
            "streaming": self.writer.streaming,
            "emergency_stop": "emergency_stop" in str(view["hold"]),
            "stopped_for_heartbeat": "heartbeat" in str(view["hold"]),
            "command_delay_ms": round(float(self.cmd_delay_ms), 1),
        }

    # ------------------------------------------------------------------- the one way in (any thread)
    def _feed(self, event: ds.Event) -> list[ds.Action]:
        with self._lock:
            actions = self.session.handle(event)
            for action in actions:
                try:
                    self._carry_out(action)
                except Exception:
                    self.metrics.inc("handler_exceptions_total", where="drc_action")
                    log.exception("DRC: could not carry out %s", type(action).__name__)
            return actions

    def _carry_out(self, action: ds.Action) -> None:
        if isinstance(action, ds.Motion):
            self.writer.set(action.setpoint, action.stream, action.since if action.setpoint != ZERO else None)
        elif isinstance(action, ds.EmergencyStop):
            self.writer.emergency()
        elif isinstance(action, ds.StickReply):
            self._answer_down(action)
        elif isinstance(action, ds.Report):
            if action.drc_state == 2:
                self.metrics.inc("drc_sessions_total")
            self._in_loop(self._report, action.drc_state, action.result)
        elif isinstance(action, ds.Notify):
            self._in_loop(self._notify, action.drc_state, action.result)
        elif isinstance(action, ds.Reply):
            self._in_loop(self._resolve, action.request, action.result, action.reason)
        elif isinstance(action, ds.OpenLink):
            self._in_loop(self._spawn_open, action.session, action.link)
        elif isinstance(action, ds.CloseLink):
            self._in_loop(self._spawn_close, action.session)
        elif isinstance(action, ds.Forward):
            self._in_loop(self._spawn_forward, action.request)
        elif isinstance(action, ds.Failsafe):
            self._failsafe(action)
        elif isinstance(action, ds.Count):
            if action.reason == "not_entered":
                self.metrics.inc("inbound_rejected_total", reason="drc_not_entered")
            else:
                self.metrics.inc("drc_rejected_total", reason=action.reason)

    def _in_loop(self, fn: Callable[..., Any], *args: Any) -> None:
        with contextlib.suppress(RuntimeError):  # the loop closed during shutdown: nobody to tell
            self.loop.call_soon_threadsafe(fn, *args)

    # ------------------------------------------------------------------- enter / exit (the loop)
    async def enter(self, data: DrcModeEnter) -> tuple[int, dict[str, Any] | None]:
        broker = data.mqtt_broker
        if broker.expire_time and broker.expire_time < self.clock.time_ms() / 1000:
            return ResultCode.INVALID_PARAMETERS, {"reason": "mqtt_broker credentials already expired"}
        owner = self.cloud_control.holder if self.cloud_control is not None else None
        refused = self.cloud_control.enter_refusal() if self.cloud_control is not None else None
        if refused is not None:
            return refused.code, {"reason": refused.reason}
        # during an automatic task the session is entered all the same (payloads, pushes, the stop on
        # drc/down); its sticks are refused until the task is paused or ends (docs/drc.md)
        denied = self._authority_problem(sticks=False)
        if denied is not None:
            return denied
        host, _, port_text = broker.address.rpartition(":")
        host = host.strip("[]")
        main = self.settings.broker
        dedicated = not main.is_node(host, int(port_text), bool(broker.enable_tls))  # any node of the list
        secret = hashlib.sha256(broker.password.get_secret_value().encode()).hexdigest()
        key = (host, int(port_text), bool(broker.enable_tls), broker.client_id, broker.username, secret)
        link = ds.LinkSpec(key=key, dedicated=dedicated)
        self._pending_broker[key] = broker
        future: asyncio.Future[tuple[int, str | None]] = self.loop.create_future()
        self.refresh_targets()
        self._feed(ds.Enter(self.now(), future, link))
        result, reason = await future
        if result == 0:
            self._owner = owner
            # more than DJI's 30 Hz: pushed at 30, and the reply says so (a client asks for the most it can
            # get; refusing would leave it without live control for a number it cannot act on)
            osd, hsi = (min(int(hz), MAX_PUSH_FREQUENCY) for hz in (data.osd_frequency, data.hsi_frequency))
            self.osd_hz, self.hsi_hz = osd, hsi
            if (osd, hsi) == (data.osd_frequency, data.hsi_frequency):
                return ResultCode.SUCCESS, None
            log.info(
                "drc_mode_enter asked for osd %s Hz, hsi %s Hz: pushing at %s Hz and %s Hz (at most %s Hz)",
                data.osd_frequency, data.hsi_frequency, osd, hsi, MAX_PUSH_FREQUENCY,
            )  # fmt: skip
            return ResultCode.SUCCESS, {"osd_frequency": osd, "hsi_frequency": hsi}
        return result, {"reason": reason or "could not enter live flight control"}

    async def exit(self) -> tuple[int, dict[str, Any] | None]:
        """Leave DRC: motion stopped first, then drc_state 0; answered once the link is closed."""
        future: asyncio.Future[tuple[int, str | None]] = self.loop.create_future()
        self._feed(ds.Exit(self.now(), future))
        result, reason = await future
        return result, ({"reason": reason} if reason else None)

    async def shutdown(self) -> None:
        """Gateway stop: motion zeroed, session ended, every link closed, the writer's last frame out."""
        self._feed(ds.Shutdown(self.now()))
        for _ in range(3):  # closes may be scheduled by the actions just carried out
            await asyncio.sleep(0)  # a yield, not a timer
            pending = [*self._opening.values(), *self._closing]
            if pending:
                await asyncio.gather(*pending, return_exceptions=True)
        if self._push_task is not None:
            self._push_task.cancel()
            self._push_task = None
        for task in list(self._forwarding):  # a drc_gimbal_reset still waiting for its device
            task.cancel()
        await asyncio.to_thread(self.writer.stop)

    def _resolve(self, future: Any, result: int, reason: str | None) -> None:
        if isinstance(future, asyncio.Future) and not future.done():
            future.set_result((result, reason))

    # -- links (the loop) -----------------------------------------------------------------------
    def _spawn_open(self, session: int, link: ds.LinkSpec) -> None:
        self._opening[session] = self.loop.create_task(self._open(session, link), name=f"drc-open-{session}")

    async def _open(self, session: int, link: ds.LinkSpec) -> None:
        try:
            if self._closing:  # the session guarantees the order; this only makes sure the sockets are gone
                await asyncio.gather(*list(self._closing), return_exceptions=True)
            if not link.dedicated:
                self._links[session] = None
                self._up = self.main_bridge
                self.refresh_targets()
                self._feed(ds.LinkUp(self.now(), session))
                return
            broker = self._pending_broker.pop(link.key, None)
            if broker is None:  # pragma: no cover - every dedicated OpenLink follows an enter that stored it
                self._feed(ds.LinkFailed(self.now(), session, int(ResultCode.DRC_MQTT_ERROR)))
                return
            bridge, result = await self._connect(session, broker)
            if bridge is None:
                self._feed(ds.LinkFailed(self.now(), session, result))
                return
            self._links[session] = bridge
            self._up = bridge
            self.refresh_targets()
            self._feed(ds.LinkUp(self.now(), session))
        finally:
            self._opening.pop(session, None)

    async def _connect(self, session: int, broker: Any) -> tuple[MqttBridge | None, int]:
        main = self.settings.broker
        host, _, port_text = broker.address.rpartition(":")
        host, port = host.strip("[]"), int(port_text)
        scheme = "mqtts" if broker.enable_tls else "mqtt"
        settings = BrokerSettings(
            url=f"{scheme}://{host}:{port}",
            username=broker.username,
            password=broker.password.get_secret_value(),
            client_id=broker.client_id,
            protocol=main.protocol,
            ca_file=main.ca_file,
            tls_hostname_check=main.tls_hostname_check,
            reconnect_min=main.reconnect_min,
            reconnect_max=main.reconnect_max,
            stall_timeout=main.for_live_control(self.settings.drc.heartbeat_timeout).stall_timeout,
            session_expiry=0,
            liveness_interval=main.liveness_interval,
            liveness_timeout=main.liveness_timeout,
        )
        bridge = self._link_factory(
            settings,
            client_id=broker.client_id,
            subscriptions=[(self.down_topic, 0)],
            loop=self.loop,
            metrics=self.metrics,
            name="drc",
            clock=self.clock,
            inline=lambda topic_name, payload: self._inline_dedicated(session, topic_name, payload),
            on_disconnected=lambda reason: self._link_lost(session, reason),
        )
        bridge.start()
        deadline = self.now() + self.cfg.enter_timeout
        try:
            while self.now() < deadline:
                if bridge.subscribed:
                    return bridge, 0
                if bridge.last_refusal is not None:
                    break
                await self.clock.sleep(0.02)
        except asyncio.CancelledError:
            await asyncio.to_thread(bridge.stop)
            raise
        refused = bridge.last_refusal is not None
        await asyncio.to_thread(bridge.stop)
        why = "refused the connection" if refused else "unreachable"
        log.warning("DRC broker %s:%d: %s", host, port, why)
        return None, int(ResultCode.DRC_LINK_REFUSED if refused else ResultCode.DRC_MQTT_ERROR)

    def _spawn_close(self, session: int) -> None:
        task = self.loop.create_task(self._close(session), name=f"drc-close-{session}")
        self._closing.add(task)
        task.add_done_callback(self._closing.discard)

    async def _close(self, session: int) -> None:
        opening = self._opening.get(session)
        if opening is not None:  # shut down while connecting: stop trying
            opening.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await opening
        bridge = self._links.pop(session, None)
        if self._up is bridge or bridge is None:
            self._up = self.main_bridge
        if bridge is not None:
            try:
                await asyncio.to_thread(bridge.stop)
            except Exception:
                log.exception("DRC: closing the link of session %d failed", session)
        self._feed(ds.LinkClosed(self.now(), session))

    def main_link_lost(self, reason: str) -> None:
        """The main connection dropped (its network thread): a session riding it lost its DRC broker."""
        sid = self.session.session_id
        if sid is not None and self._links.get(sid, 0) is None:
            self._link_lost(sid, reason)

    def _link_lost(self, session: int, reason: str) -> None:
        """A DRC connection dropped (its network thread): the session stops at once and ends."""
        log.warning("DRC link of session %d lost: %s", session, reason)
        self._feed(ds.BrokerLost(self.now(), session))

    # -- authority (the loop) -------------------------------------------------------------------
    def _authority_problem(self, *, sticks: bool = True) -> tuple[int, dict[str, Any]] | None:
        """Called for every stick: reads two set sizes and what each driven device says flies it, builds
        nothing unless it refuses (the device table is fixed). A device an automatic task flies (a
        wayline, a take-off, the FC's go home) ignores sticks: they are refused (314000) with what flies
        it, never answered 0."""
        auth = self.devices.authority
        if self._has_movable and not auth.flight:
            return ResultCode.NO_FLIGHT_AUTHORITY, {"reason": "grab flight authority first"}
        if not self._has_movable and not auth.payloads:
            return ResultCode.NO_PAYLOAD_AUTHORITY, {"reason": "grab payload authority first"}
        if not sticks:
            return None
        for adapter in self._targets:
            busy = adapter.autonomous_task()
            if busy is not None:
                reason = f"{busy} flies {adapter.info.sn}: stop it (or wait for its end) to fly by sticks"
                return ResultCode.BUSY, {"reason": reason}
        return None

    def refresh_targets(self) -> None:
        """Recompute which devices live control drives (after any authority change). A device that
        lost its authority during a session is a failsafe: the set-point is zeroed."""
        auth = self.devices.authority
        targets = tuple(
            a
            for a in self.devices
            if (a.info.domain != Domain.PAYLOAD and a.info.sn in auth.flight)
            or (a.info.domain == Domain.PAYLOAD and a.info.payload_index in auth.payloads)
        )
        lost = [a for a in self._targets if a not in targets]
        self._targets = targets
        if lost:
            self._feed(ds.AuthorityLost(self.now()))

    def cloud_control_changed(self) -> None:
        """The cloud-control grant ended or changed hands (the loop): a session whose sticks it no longer
        covers is a failsafe (set-point zeroed); its sticks are refused from now on (399003)."""
        cc = self.cloud_control
        if cc is not None and self.active and cc.stick_refusal(self._owner) is not None:
            self._feed(ds.AuthorityLost(self.now()))

    # --------------------------------------------------------------- drc/down (network threads)
    def inline_main(self, topic_name: str, payload: bytes) -> bool:
        """The main bridge's hook: consume drc/down (answered here while a session rides the main link)."""
        if topic_name != self.down_topic:
            return False
        sid = self.session.session_id
        riding = sid is not None and self._links.get(sid, 0) is None
        self.handle_down(payload, sid if riding else None, self.main_bridge)
        return True

    def _inline_dedicated(self, session: int, topic_name: str, payload: bytes) -> bool:
        if topic_name == self.down_topic:
            bridge = self._links.get(session)
            self.handle_down(payload, session, bridge if bridge is not None else self._up)
        return True

    def _new_stick_budget(self) -> TokenBucket:
        rate = self.cfg.max_stick_rate
        return TokenBucket(rate, burst=max(10.0, rate / 5), now=self.now())

    def handle_down(self, payload: bytes, session: int | None, via: MqttBridge) -> None:
        """One drc/down message from the link ``via``; ``session``: the session that link belongs to
        (None: no current session rides it)."""
        now = self.now()
        if _STICK.search(payload) is not None and not self._stick_budget.take(now):
            self.metrics.inc("drc_rejected_total", reason="rate")
            return
        try:
            request = self.registry.validate(TopicKind.DRC_DOWN, payload)
        except ValidationError as exc:
            if _ESTOP.search(payload) is not None:  # a stop is never refused for a parsing reason
                self.metrics.inc("drc_rejected_total", reason="invalid_stop_obeyed")
                audit("emergency_stop", method="drone_emergency_stop", source="drc", unparseable=True)
                self._feed(ds.EStop(now, session, _Down(via, None)))
                return
            self.metrics.inc("drc_rejected_total", reason="invalid")
            if session is not None and session == self.session.session_id:
                reply = error_reply_from_validation(TopicKind.DRC_DOWN, payload, exc)
                if reply is not None:
                    via.publish(self.up_topic, reply.model_dump_json().encode(), qos=0)
            return
        method = request.method
        if method == "heart_beat":
            self.heartbeats.append((self.clock.time_ms(), int(request.data.timestamp)))
            self._feed(ds.Heartbeat(now, session, _Down(via, request)))
        elif method == "drone_control":
            self._stick(now, session, _Down(via, request), self._to_body(request.data))
        elif method == "stick_control":
            d = request.data
            setpoint = ds.channels_to_setpoint(d.roll, d.pitch, d.throttle, d.yaw, self._stick_limits)
            self._stick(now, session, _Down(via, request), setpoint)
        elif method == "drone_emergency_stop":
            audit("emergency_stop", method=method, source="drc", seq=getattr(request.data, "seq", None))
            self._feed(ds.EStop(now, session, _Down(via, request)))
        elif method == "drc_gimbal_reset":
            self._feed(ds.PayloadCommand(now, session, _Down(via, request)))

    def _stick(self, now: float, session: int | None, token: _Down, setpoint: ds.SetPoint) -> None:
        """A ``drone_control`` or ``stick_control`` (already in the body frame) into the session, with the
        control authority as it stands now."""
        problem = self._authority_problem()
        cc = self.cloud_control
        refused = cc.stick_refusal(self._owner) if cc is not None and problem is None else None
        if refused is not None:
            problem = refused.code, {"reason": refused.reason}
        self._feed(
            ds.Stick(
                now,
                session,
                token,
                int(token.message.data.seq),
                setpoint,
                authorized=problem is None,
                denied_result=int(problem[0]) if problem is not None else 0,
                denied_reason=str(problem[1].get("reason", "")) if problem is not None else "",
            )
        )

    def emergency_stop(self) -> None:
        """An emergency stop from the gateway itself (the web console): the session event a drc/down
        ``drone_emergency_stop`` makes (every device stopped by the motion writer; a session holds until
        new sticks), answered to nobody. Any thread."""
        self._feed(ds.EStop(self.now(), self.session.session_id, _LOCAL))

    def _to_body(self, data: DroneControl) -> ds.SetPoint:
        x, y = float(data.x) * self.cfg.x_sign, float(data.y) * self.cfg.y_sign
        if self.cfg.swap_xy:  # x forward, y right
            return (x, y, float(data.h), float(data.w))
        return (y, -x, float(data.h), float(data.w))  # seed: +x left, +y forward

    def _answer_down(self, action: ds.StickReply) -> None:
        token = action.request
        if token is _LOCAL:  # the gateway's own stop: nobody waits for an answer
            return
        assert isinstance(token, _Down)
        request = token.message
        if request is None:  # an emergency stop that could not be parsed, obeyed all the same
            reply = self.registry.build(TopicKind.DRC_UP, "drone_emergency_stop", {"result": action.result})
            token.via.publish(self.up_topic, reply.model_dump_json().encode(), qos=0)
            return
        method = request.method
        if method == "heart_beat":
            self.metrics.inc("drc_heartbeats_total")
            reply = echo_heart_beat(request)
        else:
            output: dict[str, Any] | None = None
            if method in ("drone_control", "stick_control"):
                output = {"seq": action.seq}
                if action.reason:
                    output["reason"] = action.reason
                if action.result == 0:
                    self.metrics.inc("drc_sticks_total")
                    if method in SILENT_WHEN_ACCEPTED:  # DJI: "this protocol has no reply"; refusals are told
                        return
            elif action.reason:
                output = {"reason": action.reason}
            reply = reply_for(request, int(action.result), output)
        token.via.publish(self.up_topic, reply.model_dump_json().encode(), qos=0)

    # ------------------------------------------------------------ payload commands (the loop)
    def _spawn_forward(self, token: _Down) -> None:
        task = self.loop.create_task(self._forward(token), name="drc-payload-command")
        self._forwarding.add(task)
        task.add_done_callback(self._forwarding.discard)

    async def _forward(self, token: _Down) -> None:
        """``drc_gimbal_reset`` → the ``gimbal_reset`` service through the dispatcher (validation, routing by
        ``payload_index``, payload authority, deadline, metrics, audit), answered on drc/up. Copies with
        the same ``seq`` in one session (clouds repeat DRC messages) share one tid: the dispatcher's
        duplicate-tid cache gives them one effect and the same answer."""
        request = token.message
        data = request.data.model_dump(mode="json", include={"payload_index", "reset_mode"})
        seq = request.data.seq
        self._forwarded += 1
        tid = f"drc-{request.method}-{self.session.session_id}-" + (
            f"seq-{seq}" if seq is not None else f"n-{self._forwarded}"
        )
        result = int(ResultCode.INTERNAL_ERROR)
        output: object = {"reason": "no dispatcher to carry it out"}  # else the reply's output, parsed JSON
        if self.call_service is not None:
            body = {
                "tid": tid,
                "bid": "drc",
                "timestamp": self.clock.time_ms(),
                "gateway": self.gw,
                "method": "gimbal_reset",
                "data": data,
            }
            raw = await self.call_service(json.dumps(body).encode())
            answer = json.loads(raw)["data"] if raw else {"result": int(ResultCode.INTERNAL_ERROR)}
            result, output = int(answer["result"]), answer.get("output")
        reason = output.get("reason") if isinstance(output, dict) else None
        reply = reply_for(request, result, {"reason": reason} if reason else None)
        token.via.publish(self.up_topic, reply.model_dump_json().encode(), qos=0)

    # ------------------------------------------------------------------------- writer thread
    def _tick(self, now: float) -> None:
        self._feed(ds.Tick(now))

    def _measured(self, since: float) -> None:
        delay = (self.now() - since) * 1000.0
        self.cmd_delay_ms = delay if self.cmd_delay_ms == 0 else 0.8 * self.cmd_delay_ms + 0.2 * delay

    def _device_failure(self, adapter: Adapter | None, what: str, exc: BaseException) -> None:
        device = adapter.info.sn if adapter is not None else "-"
        reason = f"{what}:{type(exc).__name__}"
        if what in ("stop", "emergency_stop", "tick"):
            self.metrics.inc("drc_stop_failures_total", reason=reason, device=device)
        else:
            self.metrics.inc("drc_drive_failures_total", reason=reason, device=device)
        key = (device, reason)
        now = self.now()
        # every failure is counted; the log says it once per device and reason every 5 s
        if now - self._failure_logged.get(key, float("-inf")) >= 5.0:
            self._failure_logged[key] = now
            log.error("DRC: %s failed on device %s: %s: %s", what, device, type(exc).__name__, exc)

    # -------------------------------------------------------------- events and osd (the loop)
    @property
    def failsafe(self) -> tuple[str, int] | None:
        """The failsafe that holds or fired last in this session and when its incident began (wall clock,
        ms); None: none. Read from the session, its one owner (cleared when the session ends)."""
        session = self.session
        reason, since = session.failsafe, session.failsafe_since
        if reason is None or since is None:
            return None
        return reason, self.clock.time_ms() - round((self.now() - since) * 1000.0)

    def _failsafe(self, action: ds.Failsafe) -> None:
        if action.reason is not None and action.fired:
            self.metrics.inc("drc_failsafe_stops_total", reason=action.reason)
            # sticks stopping is how an operator lets go: routine; every other failsafe is news
            level = logging.INFO if action.reason == "sticks" else logging.WARNING
            log.log(level, "DRC failsafe: %s: motion stopped", action.reason)
        self._in_loop(self._publish_osd, self.session.drc_state)

    def _report(self, state: int, result: int) -> None:
        self.publish_event("drc_status_notify", {"result": int(result), "drc_state": state}, True)
        self._publish_osd(state)
        if state == 2 and self._push_task is None:
            self._push_task = self.loop.create_task(self._pushes(), name="drc-pushes")
        elif state != 2 and self._push_task is not None:
            self._push_task.cancel()
            self._push_task = None
        if state == 2:
            log.info("DRC session started (%s broker)", "dedicated" if self.dedicated_link else "main")
            audit("drc_enter", broker="dedicated" if self.dedicated_link else "main", result=int(result))
        elif state == 0:
            log.info("DRC session ended (result %d)", result)
            audit("drc_exit", result=int(result))

    def _notify(self, state: int, result: int) -> None:
        self.publish_event("drc_status_notify", {"result": int(result), "drc_state": state}, True)

    def osd_data(self, state: int | None = None) -> dict[str, Any]:
        """The gateway's osd body: ``drc_state`` and the failsafe that holds (``x_drc_failsafe``)."""
        failsafe = self.failsafe
        return {
            "drc_state": self.session.drc_state if state is None else state,
            "x_drc_failsafe": (
                {"reason": failsafe[0], "since": failsafe[1]} if failsafe is not None else {"reason": "none"}
            ),
        }

    def _publish_osd(self, state: int) -> None:
        self.publish_gateway_osd(self.osd_data(state))

    # ------------------------------------------------------------------------- pushes (the loop)
    async def _pushes(self) -> None:
        next_osd = next_hsi = next_delay = next_state = next_batteries = 0.0
        state_hz, batteries_hz = self.cfg.drone_state_hz, self.cfg.batteries_hz
        while True:
            now = self.now()
            try:
                if state_hz > 0 and now >= next_state:
                    next_state = max(next_state + 1.0 / state_hz, now)
                    self._push("drc_drone_state_push", self._drone_state())
                if batteries_hz > 0 and now >= next_batteries:
                    next_batteries = max(next_batteries + 1.0 / batteries_hz, now)
                    self._push("drc_batteries_info_push", self._batteries())
                if now >= next_osd:
                    next_osd = now + 1.0 / self.osd_hz
                    self._push("osd_info_push", self._osd_info())
                if now >= next_hsi:
                    next_hsi = now + 1.0 / self.hsi_hz
                    self._push("hsi_info_push", self._hsi_info())
                if now >= next_delay:
                    next_delay = now + 1.0
                    self._push(
                        "delay_info_push",
                        {"sdr_cmd_delay": round(self.cmd_delay_ms), "liveview_delay_list": []},
                    )
            except Exception:
                self.metrics.inc("handler_exceptions_total", where="drc_pushes")
                log.exception("DRC push failed")
            await self.clock.sleep(min(1.0 / self.osd_hz, 1.0 / self.hsi_hz, 0.05))

    def _push(self, method: str, data: dict[str, Any] | None) -> None:
        if data is None:
            return
        try:
            msg = self.registry.build(TopicKind.DRC_UP, method, data, timestamp=self.clock.time_ms())
        except ValidationError as exc:
            self.metrics.inc("outbound_invalid_total", kind="drc_up")
            log.debug("skipped %s: %s", method, exc.errors()[:1])
            return
        self._up.publish(self.up_topic, msg.model_dump_json().encode(), qos=0)

    def _aircraft(self) -> tuple[Adapter, AircraftPose] | None:
        """The first aircraft whose position is known, and its pose."""
        for adapter in self.devices:
            if adapter.info.domain == Domain.AIRCRAFT and (pose := adapter.aircraft_pose()) is not None:
                return adapter, pose
        return None

    def _osd_info(self) -> dict[str, Any] | None:
        aircraft = self._aircraft()
        if aircraft is None:
            return None  # the push's position fields are required: nothing to say without an aircraft
        _, t = aircraft
        north, east, up = t.velocity or (0.0, 0.0, 0.0)
        _, _, yaw = t.attitude or (0.0, 0.0, 0.0)
        g_roll, g_pitch, g_yaw = t.gimbal or (0.0, 0.0, 0.0)
        for adapter in self.devices:  # a gimbal of its own on this gateway reports better angles
            attitude = adapter.gimbal_attitude()
            if adapter.info.domain == Domain.PAYLOAD and attitude is not None:
                g_yaw, g_roll, g_pitch = attitude.yaw, attitude.roll, attitude.pitch
                break
        return {
            "attitude_head": yaw,
            "latitude": t.latitude,
            "longitude": t.longitude,
            "height": t.altitude if t.altitude is not None else 0.0,
            "speed_x": north,
            "speed_y": east,
            "speed_z": up,
            "gimbal_pitch": g_pitch,
            "gimbal_roll": g_roll,
            "gimbal_yaw": g_yaw,
            "elevation": t.height,
        }

    def _drone_state(self) -> dict[str, Any] | None:
        """``drc_drone_state_push``: the aircraft's ``mode_code`` (what its osd says); nothing without one."""
        aircraft = self._aircraft()
        return {"mode_code": aircraft[1].mode_code} if aircraft is not None else None

    def _batteries(self) -> dict[str, Any] | None:
        """``drc_batteries_info_push``: the aircraft osd's ``battery`` struct; nothing before it is known."""
        aircraft = self._aircraft()
        snapshot = aircraft[0].osd_snapshot() if aircraft is not None else None
        battery = snapshot.get("battery") if snapshot else None
        return dict(battery) if battery else None

    def _hsi_info(self) -> dict[str, Any]:
        """Obstacle distances from the flight controller when it reports them (resampled onto the seed's
        360 one-degree bins: :func:`around_distances`); otherwise sensing is reported off (distances 0,
        ``*_enable``/``*_work`` false), never invented."""
        aircraft = self._aircraft()
        obstacles = aircraft[1].obstacles if aircraft is not None else None
        if not obstacles:
            return {"up_distance": 0, "down_distance": 0, "around_distances": [], "up_enable": False,
                    "up_work": False, "down_enable": False, "down_work": False}  # fmt: skip
        body: dict[str, Any] = {
            "up_distance": _mm(obstacles["up"]),
            "down_distance": _mm(obstacles["down"]),
            "around_distances": around_distances(obstacles),
            "up_enable": True,
            "up_work": obstacles["up"][1],
            "down_enable": True,
            "down_work": obstacles["down"][1],
            "horizontal_enable": True,
            "horizontal_work": any(obstacles[s][1] for s in _SECTORS),
        }
        for side in _SECTORS:
            body[f"{side}_enable"] = True
            body[f"{side}_work"] = obstacles[side][1]
        return body


#: The flight controller's horizontal sensors, clockwise from the nose (0x02 0x00 position item).
_SECTORS = ("front", "right", "back", "left")


def _mm(reading: tuple[float, bool]) -> int:
    """A distance in metres (the flight controller's unit) as the Cloud API's integer millimetres; 0 when
    the sensor does not work (its ``*_work`` flag says so)."""
    distance, working = reading
    return max(0, round(distance * 1000)) if working and distance == distance else 0


def around_distances(obstacles: Mapping[str, tuple[float, bool]]) -> list[int]:
    """The seed's ``around_distances``: 360 one-degree bins clockwise from the nose, in mm.

    The flight controller measures four sectors (front, right, back, left), each centred on its axis
    (0°, 90°, 180°, 270°). Each bin takes the reading of the sector it lies in: bins 315°..44° the
    front, 45°..134° the right, 135°..224° the back, 225°..314° the left (nearest-sector resampling;
    the FC gives one distance per sector, so nothing finer can be said). A sector whose sensor does not
    work gives 0 in its bins, and its ``*_work`` flag is false."""
    values = [_mm(obstacles[side]) for side in _SECTORS]
    return [values[((degree + 45) // 90) % 4] for degree in range(360)]
