"""The RoboMaster robot adapter: referee data → osd/state/events; Cloud API calls → control messages.

Owns one robot on one UART (:class:`~adapters.serial_link.SerialLink`, reopened when it fails):
the 0xA5 stream decoder, the referee values the gateway reports, the silence watchdog, and the
loops that keep motion alive while it is wanted (a board stops by itself ~0.5 s after the last
``chassis_velocity``, so the gateway resends at ``control.rate_hz`` until the set-point's hold
ends, then sends zero). Control messages are fire-and-forget: the board has no acknowledgement,
so a call succeeds once its frame is queued on an open link. Knows nothing of MQTT.

Mapping (the README's table comes from the same decisions):

==============================  =====================================================  ============
Cloud API method                control message(s) on the UART                          failure
==============================  =====================================================  ============
x_robomaster_chassis_velocity   chassis_velocity (vx, vy, wz) resent at rate_hz for     325001 over
                                ``duration`` (default control.hold), then zeros         max speeds
x_robomaster_gimbal_angle       gimbal_angle (yaw, pitch in rad), once                  325001 pitch
x_robomaster_stop               stop, reason 0 (operator)                               325012
x_robomaster_interaction        0x0301 sub-header (data_cmd_id, own id, receiver) +     314000 id
                                user data                                               unknown
camera_screen_drag (payload)    gimbal_angle set-points integrated from the speeds at   325001
                                drag_rate_hz; the drag ends drag_hold after the last
gimbal_reset 0/1/2/3 (payload)  gimbal_angle (0, 0) / (0, pitch_min) / (0, pitch) /     —
                                (yaw, pitch_min)
flight_authority_grab           none: the gateway keeps the robot's motion authority,   325012
                                so live control (DRC) may drive it
drc drone_control (stream)      chassis_velocity: vx = forward, vy = −right, wz =       —
                                −yaw rate (°/s clockwise → rad/s CCW), clamped to the
                                max speeds, one frame per DRC stream period
drc drone_emergency_stop        stop, reason 2 (emergency)                              —
==============================  =====================================================  ============

Every method answers 325012 when the link is down or the robot silent. ``stop_motion`` (failsafe)
sends ``stop`` reason 1 (watchdog) at once; the adapter's own stop sends reason 3 (shutdown); a
robot that goes offline gets ``stop`` reason 1 too, in case only its referee feed stopped.

Referee data in: 0x0001 → state ``x_game_type``/``x_game_progress`` and osd
``x_stage_remain_time``; 0x0201 → state ``x_robot_id``, osd ``x_hp``/``x_max_hp``; 0x0202 → osd
``x_chassis_power`` (2024 only), ``x_buffer_energy``, ``x_shooter_heat`` (the season's barrels in
wire order); 0x0203 → osd ``x_position`` and ``attitude_head`` (the referee's compass bearing,
north 0, folded to -180..180); 0x0104 → event ``x_robomaster_referee_warning`` (need_reply,
once per distinct report: a referee that repeats its last penalty yields one event); 0x0206 → event
``x_robomaster_hurt``. Buffs (0x0204), shots (0x0207) and allowance (0x0208) are kept on the
adapter (``buff``, ``shoot``, ``allowance``); the robot osd contract has no fields for them yet.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
from collections.abc import Mapping
from typing import Any

from adapters.base import CallResult, DeviceInfo, TelemetrySink
from adapters.clock import SYSTEM_CLOCK, Clock
from adapters.errors import CommandError, DeviceNotConnected, DeviceRejected, InvalidParameters, LinkError
from adapters.hold import HeldSetpoint
from adapters.robomaster.commands import REFEREE_TABLE, ControlChannel, decode_message, encode_message
from adapters.robomaster.config import RobomasterDeviceSettings
from adapters.robomaster.extensions import ChassisVelocity, GimbalAngle, Interaction, RobotRequest
from adapters.robomaster.protocol import Decoder, Frame
from adapters.serial_link import SerialLink
from adapters.supervision import SupervisedAdapter
from adapters.wire.table import bind_handlers
from schemas.results import ResultCode
from schemas.services import CameraScreenDrag, FlightAuthorityGrab, GimbalReset

log = logging.getLogger(__name__)

__all__ = [
    "EVENT_HURT",
    "EVENT_WARNING",
    "STOP_EMERGENCY",
    "STOP_OPERATOR",
    "STOP_SHUTDOWN",
    "STOP_WATCHDOG",
    "RobotAdapter",
]

# ``stop`` reasons (control contract, commands.py)
STOP_OPERATOR, STOP_WATCHDOG, STOP_EMERGENCY, STOP_SHUTDOWN = 0, 1, 2, 3

EVENT_WARNING = "x_robomaster_referee_warning"
EVENT_HURT = "x_robomaster_hurt"

_GAME_PROGRESS = range(0, 6)  # schemas.state.GameProgress
_ZERO = {"vx": 0.0, "vy": 0.0, "wz": 0.0}


def _finite(value: Any) -> float | None:
    return float(value) if isinstance(value, int | float) and math.isfinite(value) else None


def _wrap180(deg: float) -> float:
    return (deg + 180.0) % 360.0 - 180.0


class RobotAdapter(SupervisedAdapter):
    noun = "robot"
    _log = log
    _link: SerialLink | None

    def __init__(self, settings: RobomasterDeviceSettings, *, clock: Clock = SYSTEM_CLOCK) -> None:
        self.settings = settings
        super().__init__(
            DeviceInfo.of(settings.sn, settings.product, settings.payload_index), settings, clock
        )
        self._control: ControlChannel = settings.control.channel()
        self._decoder = Decoder(settings.max_data_len)
        self._seq = 0
        # link statistics (tests and metrics read them, with ``link_opens``)
        self.frames_in = 0
        self.bad_frames = 0
        self.undecodable = 0
        # what the referee told us (wire units, except where noted)
        self.robot_id: int | None = None
        self.robot_level: int | None = None
        self.hp: int | None = None
        self.max_hp: int | None = None
        self.game_type: int | None = None
        self.game_progress: int | None = None
        self.stage_remain_time: int | None = None
        self.position: tuple[float, float] | None = None
        self.bearing: float | None = None  # degrees, north 0
        self.chassis_power: float | None = None
        self.buffer_energy: int | None = None
        self.shooter_heat: list[int] | None = None
        self.buff: dict[str, Any] | None = None
        self.shoot: dict[str, Any] | None = None
        self.allowance: dict[str, Any] | None = None
        self._published_state: dict[str, Any] = {}
        self._last_warning: tuple[int, int, int] | None = None
        # motion
        self.velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._velocity = HeldSetpoint(
            f"robomaster-{self.info.sn}-vel",
            period=1.0 / settings.control.rate_hz,
            clock=self._clock,
            refresh=self._velocity_refresh,
            on_end=self._velocity_ended,
        )
        self.gimbal_setpoint: tuple[float, float] = (0.0, 0.0)  # yaw CCW, pitch up (degrees)
        self._drag_speed: tuple[float, float] = (0.0, 0.0)  # yaw CCW, pitch up (°/s)
        self._drag = HeldSetpoint(
            f"robomaster-{self.info.sn}-drag",
            period=1.0 / settings.drag_rate_hz,
            clock=self._clock,
            refresh=self._drag_refresh,
            step_to_deadline=True,
        )
        self._loop: asyncio.AbstractEventLoop | None = None
        self._last_drive = float("-inf")  # when live control (DRC) last drove the chassis
        self.handlers = {
            # the robot has no authority of its own: grabbing "flight" authority lets live control
            # (DRC) drive its chassis, as it would an aircraft (the gateway keeps the authority)
            "flight_authority_grab": self._authority_grab,
            "x_robomaster_chassis_velocity": self._x_chassis_velocity,
            "x_robomaster_gimbal_angle": self._x_gimbal_angle,
            "x_robomaster_stop": self._x_stop,
            "x_robomaster_interaction": self._x_interaction,
        }
        if settings.payload_index is not None:
            self.handlers["camera_screen_drag"] = self._screen_drag
            self.handlers["gimbal_reset"] = self._gimbal_reset

    # -- life cycle -------------------------------------------------------------------------------
    async def start(self, sink: TelemetrySink) -> None:
        self._sink = sink
        loop = self._loop = asyncio.get_running_loop()
        self._link = SerialLink(
            url=self.settings.url,
            baudrate=self.settings.baudrate,
            loop=loop,
            on_bytes=self._on_bytes,
            on_down=self._on_link_down,
        )
        self._tasks.append(loop.create_task(self._supervise(), name=f"robomaster-{self.info.sn}-supervisor"))

    async def stop(self) -> None:
        self._stopping = True
        self._halt(STOP_SHUTDOWN)
        await self._end_supervision()

    async def stop_motion(self, reason: int = STOP_WATCHDOG) -> None:
        """Failsafe: end every motion loop and send ``stop`` at once; nothing is awaited."""
        self._halt(reason)

    def _halt(self, reason: int) -> bool:
        """Cancel the motion loops and send ``stop``; True when the frame was queued."""
        self._cancel_motion()
        try:
            self._send("stop", {"reason": reason})
        except LinkError:
            return False
        return True

    def _cancel_motion(self) -> None:
        self.velocity = (0.0, 0.0, 0.0)
        self._drag_speed = (0.0, 0.0)
        self._velocity.cancel()
        self._drag.cancel()

    # -- link supervision (the loop is SupervisedAdapter's) ----------------------------------------
    def _on_link_opened(self) -> None:
        self._decoder = Decoder(self.settings.max_data_len)

    def _on_online_changed(self, online: bool) -> None:
        if not online:
            # the board may still listen (only the referee feed stopped): ask it to stop, best effort
            self._halt(STOP_WATCHDOG)
            self._published_state = {}  # everything is news again when it comes back

    # -- receive ---------------------------------------------------------------------------------
    def _on_bytes(self, data: bytes) -> None:
        for item in self._decoder.feed(data):
            if isinstance(item, Frame):
                self._on_frame(item)
            else:
                self.bad_frames += 1

    def _on_frame(self, frame: Frame) -> None:
        self.frames_in += 1
        self._last_heard = self._now()
        self._set_online(True)
        try:
            msg = decode_message(frame, self.settings.season, self._control)
        except CommandError as exc:
            self.undecodable += 1
            log.debug("robot %s: %s", self.info.sn, exc)
            return
        handler = _PUSHES.get(msg.name)
        if handler is not None:
            handler(self, msg.fields)

    def _on_game_status(self, f: Mapping[str, Any]) -> None:
        self.game_type = f["game_type"]
        self.game_progress = f["game_progress"]
        self.stage_remain_time = f["stage_remain_time"]
        self._publish_state_changes()

    def _on_robot_status(self, f: Mapping[str, Any]) -> None:
        if f["robot_id"] != self.robot_id:
            self.robot_id = f["robot_id"]
            self._control = self.settings.control.channel(self.robot_id)  # sender id = our own id
        self.robot_level = f["robot_level"]
        self.hp = f["current_HP"]
        self.max_hp = f["maximum_HP"]
        self._publish_state_changes()

    def _on_power_heat_data(self, f: Mapping[str, Any]) -> None:
        if "chassis_power" in f:  # 2024 only; later seasons keep the slot reserved
            self.chassis_power = _finite(f["chassis_power"])
        self.buffer_energy = f["buffer_energy"]
        self.shooter_heat = [v for k, v in f.items() if k.endswith("_barrel_heat")]

    def _on_robot_pos(self, f: Mapping[str, Any]) -> None:
        x, y = _finite(f["x"]), _finite(f["y"])
        self.position = None if x is None or y is None else (x, y)
        self.bearing = _finite(f["angle"])

    def _on_buff(self, f: Mapping[str, Any]) -> None:
        self.buff = dict(f)

    def _on_shoot_data(self, f: Mapping[str, Any]) -> None:
        self.shoot = dict(f)

    def _on_projectile_allowance(self, f: Mapping[str, Any]) -> None:
        self.allowance = dict(f)

    def _on_referee_warning(self, f: Mapping[str, Any]) -> None:
        key = (f["level"], f["offending_robot_id"], f["count"])
        if key == self._last_warning:
            return  # the 1 Hz repeat of the last penalty
        self._last_warning = key
        data = {"level": key[0], "offending_robot_id": key[1], "count": key[2], **self._own_id()}
        if self._sink is not None:
            self._sink.event(self.info.sn, EVENT_WARNING, data, need_reply=True)

    def _on_hurt_data(self, f: Mapping[str, Any]) -> None:
        data = {"armor_id": f["armor_id"], "hp_deduction_reason": f["HP_deduction_reason"], **self._own_id()}
        if self._sink is not None:
            self._sink.event(self.info.sn, EVENT_HURT, data)

    def _own_id(self) -> dict[str, int]:
        return {"robot_id": self.robot_id} if self.robot_id else {}

    # -- telemetry --------------------------------------------------------------------------------
    def state_snapshot(self) -> Mapping[str, Any] | None:
        body: dict[str, Any] = {}
        if self.robot_id:
            body["x_robot_id"] = self.robot_id
        if self.game_type is not None:
            body["x_game_type"] = self.game_type
        if self.game_progress in _GAME_PROGRESS:
            body["x_game_progress"] = self.game_progress
        return body or None

    def _publish_state_changes(self) -> None:
        current = self.state_snapshot() or {}
        changed = {k: v for k, v in current.items() if self._published_state.get(k) != v}
        if changed and self._online and self._sink is not None:
            self._published_state.update(changed)
            self._sink.state(self.info.sn, changed)

    def osd_snapshot(self) -> Mapping[str, Any] | None:
        body: dict[str, Any] = {}
        if self.bearing is not None:
            body["attitude_head"] = _wrap180(self.bearing)
        if self.robot_id:
            body["x_robot_id"] = self.robot_id
        if self.position is not None:
            body["x_position"] = {"x": self.position[0], "y": self.position[1]}
        if self.hp is not None:
            body["x_hp"] = self.hp
        if self.max_hp is not None:
            body["x_max_hp"] = self.max_hp
        if self.chassis_power is not None:
            body["x_chassis_power"] = max(0.0, self.chassis_power)
        if self.buffer_energy is not None:
            body["x_buffer_energy"] = self.buffer_energy
        if self.shooter_heat is not None:
            body["x_shooter_heat"] = list(self.shooter_heat)
        if self.stage_remain_time is not None:
            body["x_stage_remain_time"] = self.stage_remain_time
        return body or None

    # -- send -------------------------------------------------------------------------------------
    def _send(self, name: str, fields: Mapping[str, Any]) -> None:
        """Queue one control (or interaction) frame; LinkError when the port is not open."""
        if self._link is None or not self._link.up:
            raise LinkError(f"robot {self.info.sn}: serial link is down")
        self._seq = (self._seq + 1) & 0xFF
        self._link.write(encode_message(name, fields, self.settings.season, self._seq, self._control))

    def _send_or_raise(self, name: str, fields: Mapping[str, Any]) -> None:
        if not self._online:
            raise DeviceNotConnected(f"robot {self.info.sn} is not connected")
        try:
            self._send(name, fields)
        except LinkError as exc:
            raise DeviceNotConnected(str(exc)) from None

    # -- motion (also the DRC layer's entry point) --------------------------------------------------
    def set_velocity(self, vx: float, vy: float, wz: float, *, hold: float | None = None) -> None:
        """Chassis velocity (m/s forward, m/s left, rad/s CCW) for ``hold`` seconds (default
        ``control.hold``), resent at ``control.rate_hz``; zero velocity when the hold ends. A new
        call replaces the set-point and the hold. Call on the adapter's event loop."""
        s = self.settings
        for name, value, limit in (("vx", vx, s.max_vx), ("vy", vy, s.max_vy), ("wz", wz, s.max_wz)):
            if not math.isfinite(value) or abs(value) > limit:
                raise InvalidParameters(f"{name} {value:g} outside ±{limit:g} for robot {self.info.sn}")
        self._send_or_raise("chassis_velocity", {"vx": vx, "vy": vy, "wz": wz})
        self.velocity = (vx, vy, wz)
        self._velocity.hold(hold if hold is not None else s.control.hold)

    def _velocity_refresh(self, dt: float) -> None:
        vx, vy, wz = self.velocity
        with contextlib.suppress(LinkError):
            self._send("chassis_velocity", {"vx": vx, "vy": vy, "wz": wz})

    def _velocity_ended(self) -> None:
        self.velocity = (0.0, 0.0, 0.0)
        if self._now() - self._last_drive > self.settings.control.hold:  # live control took over
            with contextlib.suppress(LinkError):
                self._send("chassis_velocity", _ZERO)

    # -- live control (DRC): called from the DRC streaming thread -----------------------------------
    def drive(self, forward: float, right: float, up: float, yaw_rate: float) -> bool:
        """One chassis_velocity frame for a live-control set-point (m/s forward and right, °/s
        clockwise; ``up`` has no meaning for a ground robot), clamped to the device's limits.
        Thread-safe: it encodes one frame and queues it; the DRC stream's own rate keeps the board's
        0.5 s hold alive, so no resend loop is involved. False when the robot cannot be driven."""
        if not self._online or self._link is None or not self._link.up:
            return False
        s = self.settings
        vx = max(-s.max_vx, min(s.max_vx, float(forward)))
        vy = max(-s.max_vy, min(s.max_vy, -float(right)))
        wz = max(-s.max_wz, min(s.max_wz, -math.radians(float(yaw_rate))))
        self._last_drive = self._now()
        self._velocity.expire()  # a service's velocity loop ends at its next wake-up
        try:
            self._send("chassis_velocity", {"vx": vx, "vy": vy, "wz": wz})
        except LinkError:
            return False
        return True

    def emergency_stop(self) -> None:
        """``stop`` reason 2 (emergency) now, from any thread; the motion loops end on the loop."""
        self._velocity.expire()
        self._drag.expire()
        with contextlib.suppress(LinkError):
            self._send("stop", {"reason": STOP_EMERGENCY})
        if self._loop is not None:
            with contextlib.suppress(RuntimeError):  # the loop closed during shutdown
                self._loop.call_soon_threadsafe(self._cancel_motion)

    def _gimbal_to(self, yaw_deg: float, pitch_deg: float) -> None:
        """Send an absolute gimbal set-point (degrees, yaw CCW) as the wire's radians."""
        yaw = _wrap180(yaw_deg)
        self._send_or_raise("gimbal_angle", {"yaw": math.radians(yaw), "pitch": math.radians(pitch_deg)})
        self.gimbal_setpoint = (yaw, pitch_deg)

    @property
    def dragging(self) -> bool:
        """True while a camera_screen_drag keeps moving the gimbal set-point."""
        return self._drag.running

    # -- Cloud API methods ------------------------------------------------------------------------
    async def _authority_grab(self, data: FlightAuthorityGrab) -> CallResult:
        if not self._online:
            raise DeviceNotConnected(f"robot {self.info.sn} is not connected")
        return CallResult()

    async def _x_chassis_velocity(self, data: ChassisVelocity) -> CallResult:
        self.set_velocity(float(data.vx), float(data.vy), float(data.wz), hold=data.duration)
        return CallResult()

    async def _x_gimbal_angle(self, data: GimbalAngle) -> CallResult:
        s = self.settings
        pitch = float(data.pitch)
        if not s.pitch_min_deg <= pitch <= s.pitch_max_deg:
            raise InvalidParameters(f"pitch {pitch:g}° outside {s.pitch_min_deg:g}..{s.pitch_max_deg:g}°")
        self._end_drag()
        self._gimbal_to(float(data.yaw), pitch)
        return CallResult()

    async def _x_stop(self, data: RobotRequest) -> CallResult:
        if not self._online:
            raise DeviceNotConnected(f"robot {self.info.sn} is not connected")
        if not self._halt(STOP_OPERATOR):
            raise DeviceNotConnected(f"robot {self.info.sn}: serial link is down")
        return CallResult()

    async def _x_interaction(self, data: Interaction) -> CallResult:
        control = self._control
        if control.wrapped and data.data_cmd_id == control.data_cmd_id:
            raise InvalidParameters(
                f"data_cmd_id 0x{data.data_cmd_id:04X} carries this gateway's control messages"
            )
        sender = self.settings.control.sender_id or self.robot_id
        if not sender:
            raise DeviceRejected(ResultCode.BUSY, "own robot id not known yet (no 0x0201 from the referee)")
        fields = {
            "data_cmd_id": data.data_cmd_id,
            "sender_id": sender,
            "receiver_id": data.receiver_id,
            "user_data": bytes.fromhex(data.data),
        }
        self._send_or_raise("robot_interaction_data", fields)
        return CallResult()

    # -- the gimbal as a payload ------------------------------------------------------------------
    async def _screen_drag(self, data: CameraScreenDrag) -> CallResult:
        s = self.settings
        # Cloud API directions (as for the R SDK gimbal): positive yaw_speed pans right, i.e.
        # clockwise, which is negative on the wire's CCW yaw; positive pitch_speed tilts up.
        yaw = 0.0 if data.locked else -float(data.yaw_speed)
        pitch = float(data.pitch_speed)
        if max(abs(yaw), abs(pitch)) > s.max_gimbal_speed_dps:
            raise InvalidParameters(f"drag speed above {s.max_gimbal_speed_dps:g} °/s")
        if not self._online:
            raise DeviceNotConnected(f"robot {self.info.sn} is not connected")
        self._drag_speed = (yaw, pitch)
        if not self._drag.running:
            self._drag_step(0.0)
        self._drag.hold(s.drag_hold)
        return CallResult()

    def _drag_step(self, dt: float) -> None:
        s = self.settings
        yaw, pitch = self.gimbal_setpoint
        pitch = min(s.pitch_max_deg, max(s.pitch_min_deg, pitch + self._drag_speed[1] * dt))
        self._gimbal_to(yaw + self._drag_speed[0] * dt, pitch)

    def _drag_refresh(self, dt: float) -> None:
        with contextlib.suppress(DeviceNotConnected):
            self._drag_step(dt)

    def _end_drag(self) -> None:
        self._drag.cancel()

    async def _gimbal_reset(self, data: GimbalReset) -> CallResult:
        mode = int(data.reset_mode)
        yaw, pitch = self.gimbal_setpoint
        down = self.settings.pitch_min_deg
        targets = {0: (0.0, 0.0), 1: (0.0, down), 2: (0.0, pitch), 3: (yaw, down)}
        self._end_drag()
        self._gimbal_to(*targets[mode])
        return CallResult()


# referee payload → handler, as the table's entries name them (a missing method fails here, at import)
_PUSHES = bind_handlers(RobotAdapter, REFEREE_TABLE)
