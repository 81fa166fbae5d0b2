"""Live flight control (DRC): entering and leaving, sequence order, heartbeats, pushes, and the
failsafe that always stops motion.

Owns the DRC session: the broker link named by ``drc_mode_enter`` (a dedicated paho client, or
the main connection when it is the same broker), the ``drone_control`` set-point and its ``seq``
rules, the heartbeat echo, the emergency-stop hold, and the set-point stream to every device under
live control.

Why this module has its own thread and lock (a deliberate exception to "one event loop owns all
state", DESIGN.md): the stop path must not depend on the loop being idle, on the broker being up or
on a device reply. So:

* ``drc/down`` messages are handled **in paho's network thread** (the bridge's ``inline`` hook):
  heartbeats are echoed at once and sticks update the set-point, even while the loop is flooded;
* a **streaming thread** sends the current set-point to the devices at ``stream_hz`` (the flight
  controller needs a stream; the cloud sends 5–20 Hz) and zeroes it when sticks stop
  (``stick_timeout``), when heartbeats stop (``heartbeat_timeout``, then 514301) or on an
  emergency stop. Device ``drive``/``emergency_stop`` calls only encode a frame and queue it on the
  link's writer thread, so a stalled device cannot hold the thread either;
* everything else (entering, leaving, events, the osd/hsi/delay pushes) runs in the loop.

A flood of ``drone_control`` (a cloud bug, a stuck key repeat) must not starve heartbeats: every
message costs the network thread a parse, a reply and a device frame, so past ``max_stick_rate``
sticks are dropped *before* they are parsed (a byte match on the method, counted as
``drc_rejected_total{reason="rate"}``), which keeps the thread reading far beyond any real stick
rate; heartbeats and emergency stops never count against the budget. The devices see at most that
rate plus the stream. (Past what paho itself can read, the backlog is the broker's: docs/drc.md.)

Sticks are the seed's: ``x`` lateral (+ left), ``y`` longitudinal (+ forward), ``h`` vertical
(+ up), ``w`` yaw rate (+ clockwise); ``x_sign``, ``y_sign`` and ``swap_xy`` adapt clouds that
disagree. Devices receive body-frame forward / right / up velocities and a clockwise yaw rate.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import re
import threading
import time
from collections.abc import Callable
from typing import Any

from pydantic import ValidationError

from adapters.base import Adapter
from gateway.devices import DeviceTable
from gateway.metrics import Metrics
from gateway.mqtt import MqttBridge
from gateway.ratelimit import TokenBucket
from gateway.settings import BrokerSettings, GatewaySettings
from schemas import ResultCode, TopicKind, echo_heart_beat, error_reply_from_validation, reply_for, topic
from schemas.registry import Registry

log = logging.getLogger(__name__)

__all__ = ["DrcController"]

ZERO = (0.0, 0.0, 0.0, 0.0)
#: how a drone_control is recognised before it is parsed (whatever the spacing around the colon)
_STICK = re.compile(rb'"method"\s*:\s*"drone_control"')


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
        now: Callable[[], float] = time.monotonic,
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
        self.now = now
        self.down_topic = topic(TopicKind.DRC_DOWN, self.gw)
        self.up_topic = topic(TopicKind.DRC_UP, self.gw)
        self._lock = threading.Lock()
        # -- state shared with the network and streaming threads (under _lock) --
        self.active = False
        self.drc_state = 0
        self.last_seq: int | None = None
        self.setpoint: tuple[float, float, float, float] = ZERO  # forward, right, up, yaw rate
        self.last_stick = float("-inf")
        self.last_heartbeat = float("-inf")
        self.estop = False
        self.stopped_for_heartbeat = False
        self._stick_received: float | None = None
        self.cmd_delay_ms = 0.0
        # -- network thread only --
        self._stick_budget = self._new_stick_budget()
        # -- loop-owned --
        self._bridge: MqttBridge | None = None  # dedicated DRC connection, None when reusing main
        self._up: MqttBridge = main_bridge
        self._stream_stop = threading.Event()
        self._stream_thread: threading.Thread | None = None
        self._push_task: asyncio.Task[None] | None = None
        self.osd_hz = 10
        self.hsi_hz = 1

    # ------------------------------------------------------------------------------- enter / exit (loop)
    async def enter(self, data: Any) -> tuple[int, dict[str, Any] | None]:
        broker = data.mqtt_broker
        if broker.expire_time and broker.expire_time < time.time():
            return ResultCode.INVALID_PARAMETERS, {"reason": "mqtt_broker credentials already expired"}
        denied = self._authority_problem()
        if denied is not None:
            return denied
        self.osd_hz, self.hsi_hz = int(data.osd_frequency), int(data.hsi_frequency)
        if self.active:
            await self._close_link()
        self._set_state(1, 0)
        host, _, port_text = broker.address.rpartition(":")
        host = host.strip("[]")
        main = self.settings.broker
        same = (host, int(port_text)) == (main.host, main.port) and broker.enable_tls == main.tls
        if same:
            self._bridge, self._up = None, self.main_bridge
        else:
            result = await self._connect(host, int(port_text), broker)
            if result != 0:
                self._set_state(0, result)
                return result, {"reason": "could not connect to the DRC broker"}
        with self._lock:
            now = self.now()
            self.active = True
            self.last_seq = None
            self.setpoint = ZERO
            self.last_stick = float("-inf")
            self.last_heartbeat = now  # the session starts alive: the idle limit counts from here
            self.estop = False
            self.stopped_for_heartbeat = False
            self._stick_budget = self._new_stick_budget()
        self._start_stream()
        self._push_task = self.loop.create_task(self._pushes(), name="drc-pushes")
        self._set_state(2, 0)
        self.metrics.inc("drc_sessions_total")
        log.info("DRC session started (%s broker)", "main" if same else "dedicated")
        return ResultCode.SUCCESS, None

    async def _connect(self, host: str, port: int, broker: Any) -> int:
        main = self.settings.broker
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
            session_expiry=0,
        )
        bridge = MqttBridge(
            settings,
            client_id=broker.client_id,
            subscriptions=[(self.down_topic, 0)],
            loop=self.loop,
            metrics=self.metrics,
            name="drc",
            inline=self._inline_dedicated,
            on_disconnected=self._link_lost,
        )
        bridge.start()
        deadline = self.loop.time() + self.cfg.enter_timeout
        while self.loop.time() < deadline:
            if bridge.subscribed:
                self._bridge, self._up = bridge, bridge
                return 0
            if bridge.last_refusal is not None:
                break
            await asyncio.sleep(0.02)
        refused = bridge.last_refusal is not None
        await asyncio.to_thread(bridge.stop)
        log.warning(
            "DRC broker %s:%d: %s", host, port, "refused the connection" if refused else "unreachable"
        )
        return ResultCode.DRC_LINK_REFUSED if refused else ResultCode.DRC_MQTT_ERROR

    async def exit(self, result: int = 0) -> tuple[int, dict[str, Any] | None]:
        """Leave DRC: motion stopped first, then drc_state 0."""
        if not self.active:
            return ResultCode.SUCCESS, None
        self._stop_motion_now()
        with self._lock:
            self.active = False
        self._stream_stop.set()
        if self._stream_thread is not None:
            await asyncio.to_thread(self._stream_thread.join, 2.0)
            self._stream_thread = None
        if self._push_task is not None:
            self._push_task.cancel()
            self._push_task = None
        await self._close_link()
        self._set_state(0, result)
        log.info("DRC session ended (result %s)", result)
        return ResultCode.SUCCESS, None

    async def _close_link(self) -> None:
        bridge, self._bridge, self._up = self._bridge, None, self.main_bridge
        if bridge is not None:
            await asyncio.to_thread(bridge.stop)

    def _set_state(self, state: int, result: int) -> None:
        self.drc_state = state
        self.publish_event("drc_status_notify", {"result": int(result), "drc_state": state}, True)
        self.publish_gateway_osd({"drc_state": state})

    def main_link_lost(self, reason: str) -> None:
        """The main connection dropped (its network thread). A session riding it has lost its DRC broker just
        as a dedicated one would; a session on a dedicated broker is not concerned."""
        if self.active and self._bridge is None:
            self._link_lost(reason)

    def _link_lost(self, reason: str) -> None:
        """The DRC connection dropped (network thread): stop at once, then end the session."""
        if not self.active:
            return
        self._stop_motion_now()
        self.metrics.inc("drc_failsafe_stops_total", reason="link_lost")
        with contextlib.suppress(RuntimeError):
            self.loop.call_soon_threadsafe(lambda: self.loop.create_task(self.exit(ResultCode.DRC_LINK_LOST)))

    def _authority_problem(self) -> tuple[int, dict[str, Any]] | None:
        movable = [a for a in self.devices if a.info.domain != "1"]
        auth = self.devices.authority
        if movable and not auth.flight:
            return ResultCode.NO_FLIGHT_AUTHORITY, {"reason": "grab flight authority first"}
        if not movable and not auth.payloads:
            return ResultCode.NO_PAYLOAD_AUTHORITY, {"reason": "grab payload authority first"}
        return None

    def _targets(self) -> list[Adapter]:
        auth = self.devices.authority
        return [
            a
            for a in self.devices
            if (a.info.domain != "1" and a.info.sn in auth.flight)
            or (a.info.domain == "1" and a.info.payload_index in auth.payloads)
        ]

    # ------------------------------------------------------------------------ drc/down (network thread)
    def inline_main(self, topic_name: str, payload: bytes) -> bool:
        """The main bridge's hook: consume drc/down while a session uses the main connection."""
        if topic_name != self.down_topic:
            return False
        if not self.active or self._bridge is not None:
            self.metrics.inc("inbound_rejected_total", reason="drc_not_entered")
            return True
        self.handle_down(payload)
        return True

    def _inline_dedicated(self, topic_name: str, payload: bytes) -> bool:
        if topic_name == self.down_topic and self.active:
            self.handle_down(payload)
        return True

    def _publish_up(self, message: Any) -> None:
        self._up.publish(self.up_topic, message.model_dump_json().encode(), qos=0)

    def _new_stick_budget(self) -> TokenBucket:
        rate = self.cfg.max_stick_rate
        return TokenBucket(rate, burst=max(10.0, rate / 5), now=self.now())

    def handle_down(self, payload: bytes) -> None:
        if _STICK.search(payload) is not None and not self._stick_budget.take(self.now()):
            self.metrics.inc("drc_rejected_total", reason="rate")
            return
        try:
            request = self.registry.validate(TopicKind.DRC_DOWN, payload)
        except ValidationError as exc:
            self.metrics.inc("drc_rejected_total", reason="invalid")
            reply = error_reply_from_validation(TopicKind.DRC_DOWN, payload, exc)
            if reply is not None:
                self._publish_up(reply)
            return
        method = request.method
        if method == "heart_beat":
            self._publish_up(echo_heart_beat(request))
            with self._lock:
                self.last_heartbeat = self.now()
                recovered = self.stopped_for_heartbeat
                self.stopped_for_heartbeat = False
            self.metrics.inc("drc_heartbeats_total")
            if recovered:
                self._notify_from_thread(0)
        elif method == "drone_control":
            result, output = self._stick(request.data)
            if result == ResultCode.SUCCESS:
                # on the wire now, not at the next stream tick: stick-to-wire latency is one frame.
                # Never while a failsafe holds the vehicle: the stream thread owns the zero set-point then.
                with self._lock:
                    setpoint = self.setpoint
                    halted = self.estop or self.stopped_for_heartbeat
                for adapter in [] if halted else self._targets():
                    with contextlib.suppress(Exception):
                        adapter.drive(*setpoint)
            if result is not None:
                self._publish_up(reply_for(request, int(result), output))
        elif method == "drone_emergency_stop":
            self._emergency_stop()
            self._publish_up(reply_for(request, ResultCode.SUCCESS))

    def _stick(self, data: Any) -> tuple[int | None, dict[str, Any] | None]:
        """Apply one drone_control; returns the reply (None: a repeat, ignored)."""
        seq = int(data.seq)
        if self._authority_problem() is not None:
            self.metrics.inc("drc_rejected_total", reason="authority")
            return ResultCode.NO_FLIGHT_AUTHORITY, {"seq": seq}
        forward, right, up, yaw = self._to_body(data)
        with self._lock:
            if seq != 0 and self.last_seq is not None:
                if seq < self.last_seq:
                    self.metrics.inc("drc_rejected_total", reason="seq")
                    return ResultCode.DRC_SEQ_TOO_OLD, {"seq": seq}
                if seq == self.last_seq:
                    return None, None  # clouds publish each DRC message several times at QoS 0
            if self.estop and seq != 0:
                return ResultCode.BUSY, {"seq": seq, "reason": "emergency stop holds until seq restarts at 0"}
            self.estop = False
            self.last_seq = seq
            self.setpoint = (forward, right, up, yaw)
            self.last_stick = self.now()
            self._stick_received = self.last_stick
        self.metrics.inc("drc_sticks_total")
        return ResultCode.SUCCESS, {"seq": seq}

    def _to_body(self, data: Any) -> tuple[float, float, float, float]:
        x, y = float(data.x) * self.cfg.x_sign, float(data.y) * self.cfg.y_sign
        if self.cfg.swap_xy:  # x forward, y right
            return (x, y, float(data.h), float(data.w))
        return (y, -x, float(data.h), float(data.w))  # seed: +x left, +y forward

    def _emergency_stop(self) -> None:
        with self._lock:
            self.estop = True
            self.setpoint = ZERO
        self.metrics.inc("drc_failsafe_stops_total", reason="emergency_stop")
        for adapter in self.devices:
            with contextlib.suppress(Exception):
                adapter.emergency_stop()

    def _stop_motion_now(self) -> None:
        """Zero every driven device at once, from whichever thread notices."""
        with self._lock:
            self.setpoint = ZERO
        for adapter in self._targets():
            with contextlib.suppress(Exception):
                adapter.drive(*ZERO)

    def _notify_from_thread(self, result: int) -> None:
        with contextlib.suppress(RuntimeError):
            self.loop.call_soon_threadsafe(
                self.publish_event,
                "drc_status_notify",
                {"result": int(result), "drc_state": self.drc_state},
                True,
            )

    # ------------------------------------------------------------------------------ streaming thread
    def _start_stream(self) -> None:
        self._stream_stop = threading.Event()
        self._stream_thread = threading.Thread(target=self._stream, name="drc-stream", daemon=True)
        self._stream_thread.start()

    def _stream(self) -> None:
        period = 1.0 / self.cfg.stream_hz
        stop = self._stream_stop
        zeroed_for_sticks = True
        while not stop.wait(period):
            now = self.now()
            with self._lock:
                if not self.active:
                    return
                setpoint = self.setpoint
                stick_age = now - self.last_stick
                hb_age = now - self.last_heartbeat
                lost_heartbeat = hb_age > self.cfg.heartbeat_timeout and not self.stopped_for_heartbeat
                if lost_heartbeat:
                    self.stopped_for_heartbeat = True
                halted = self.estop or self.stopped_for_heartbeat
                received, self._stick_received = self._stick_received, None
            if stick_age > self.cfg.stick_timeout or halted:
                if not zeroed_for_sticks and not halted:
                    self.metrics.inc("drc_failsafe_stops_total", reason="sticks")
                zeroed_for_sticks = True
                setpoint = ZERO
            else:
                zeroed_for_sticks = False
            for adapter in self._targets():
                with contextlib.suppress(Exception):
                    adapter.drive(*setpoint)
            if received is not None:
                delay = (self.now() - received) * 1000.0
                self.cmd_delay_ms = delay if self.cmd_delay_ms == 0 else 0.8 * self.cmd_delay_ms + 0.2 * delay
            if lost_heartbeat:
                log.warning("DRC: no heartbeat for %.1fs: motion stopped", hb_age)
                self.metrics.inc("drc_failsafe_stops_total", reason="heartbeat")
                self._notify_from_thread(ResultCode.DRC_HEARTBEAT_TIMEOUT)
            if hb_age > self.cfg.idle_timeout:
                log.warning("DRC: no heartbeat for %.0fs: leaving live control", hb_age)
                with contextlib.suppress(RuntimeError):
                    self.loop.call_soon_threadsafe(
                        lambda: self.loop.create_task(self.exit(ResultCode.DRC_HEARTBEAT_TIMEOUT))
                    )
                return

    # ---------------------------------------------------------------------------------- pushes (loop)
    async def _pushes(self) -> None:
        next_osd = next_hsi = next_delay = 0.0
        while self.active:
            now = self.loop.time()
            try:
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
            await asyncio.sleep(min(1.0 / self.osd_hz, 1.0 / self.hsi_hz, 0.05))

    def _push(self, method: str, data: dict[str, Any] | None) -> None:
        if data is None:
            return
        try:
            msg = self.registry.build(TopicKind.DRC_UP, method, data, timestamp=int(time.time() * 1000))
        except ValidationError as exc:
            self.metrics.inc("outbound_invalid_total", kind="drc_up")
            log.debug("skipped %s: %s", method, exc.errors()[:1])
            return
        self._up.publish(self.up_topic, msg.model_dump_json().encode(), qos=0)

    def _aircraft(self) -> Any:
        for adapter in self.devices:
            telemetry = getattr(adapter, "telemetry", None)
            if adapter.info.domain == "0" and telemetry is not None and telemetry.latitude is not None:
                return adapter
        return None

    def _osd_info(self) -> dict[str, Any] | None:
        aircraft = self._aircraft()
        if aircraft is None:
            return None  # the push's position fields are required: nothing to say without an aircraft
        t = aircraft.telemetry
        north, east, up = t.velocity or (0.0, 0.0, 0.0)
        _, _, yaw = t.attitude or (0.0, 0.0, 0.0)
        g_roll, g_pitch, g_yaw = t.gimbal or (0.0, 0.0, 0.0)
        for adapter in self.devices:  # a gimbal of its own on this gateway reports better angles
            attitude = getattr(adapter, "attitude", None)
            if adapter.info.domain == "1" and attitude is not None:
                g_yaw, g_roll, g_pitch = attitude
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
        }

    def _hsi_info(self) -> dict[str, Any]:
        """Obstacle distances from the flight controller when it reports them; otherwise sensing is
        reported off (distances 0, ``*_enable``/``*_work`` false), never invented."""
        aircraft = self._aircraft()
        obstacles = getattr(aircraft.telemetry, "obstacles", None) if aircraft is not None else None
        if not obstacles:
            return {"up_distance": 0, "down_distance": 0, "around_distances": [], "up_enable": False,
                    "up_work": False, "down_enable": False, "down_work": False}  # fmt: skip

        def mm(side: str) -> int:
            return max(0, round(obstacles[side][0] * 1000))

        return {
            "up_distance": mm("up"),
            "down_distance": mm("down"),
            "around_distances": [mm(s) for s in ("front", "right", "back", "left")],
            "up_enable": True,
            "up_work": obstacles["up"][1],
            "down_enable": True,
            "down_work": obstacles["down"][1],
            "horizontal_enable": True,
            "horizontal_work": all(obstacles[s][1] for s in ("front", "right", "back", "left")),
        }
