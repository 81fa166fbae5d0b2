"""The R SDK gimbal adapter: Cloud API payload methods → R SDK commands on CAN; pushes → osd.

Owns one gimbal: its :class:`~adapters.rsdk.link.CanLink` (reopened when it fails), the SEQ-keyed
table of commands waiting for a reply (SEQ is the only safe key, PROTOCOL-NOTES), the parameter
push that feeds ``osd``, the silence watchdog that marks the gimbal offline, and the drag loop that
keeps speed control alive (a speed command lasts 0.5 s, seed §2.3.4.2) while the cloud keeps
dragging. Knows nothing of MQTT: it reports through a :class:`~adapters.base.TelemetrySink`.

Mapping (the README's table is generated from the same decisions):

=========================  =====================================================  ==============
Cloud API method           R SDK command(s)                                        failure result
=========================  =====================================================  ==============
camera_screen_drag         0E 01 speed control, ctrl 0x88, resent at ≥10 Hz;       327004
                           zero speeds + release 0.5 s after the last drag
camera_aim                 0E 00 incremental position from (x, y) and the FOV     327005
gimbal_reset 0/1/2/3       0E 0E recenter / 0E 00 yaw 0 + pitch down /             314000
                           0E 00 yaw 0 / 0E 00 pitch down
camera_photo_take          0D 00 command 0x0001 (shutter)                          327006
camera_recording_start     0D 00 command 0x0003                                    327007
camera_recording_stop      0D 00 command 0x0004                                    327008
camera_mode_switch         none: seed 000 has no camera-mode command               399001
camera_focal_length_set    none: R SDK gimbals cannot zoom                         399001
x_rsdk_*                   0E 03/04/05/06/0E/00/11/12/0F, 0E 09                    314000
=========================  =====================================================  ==============

A reply's return code 0x01 (parse error) maps to 325001; 0x02 (execution failed) and 0xFF to the
method's failure result above.

Directions (chosen, since neither the seed nor the Cloud API says): a positive Cloud API
``pitch_speed`` tilts up (R SDK pitch angle increases), a positive ``yaw_speed`` pans right
(R SDK yaw angle increases); "down" is pitch −90° clamped to the gimbal's range (−56° on an RS).

Why this module is longer than 500 lines: one Cloud API method → R SDK command mapping per service the gimbal
offers, plus its pushes; the link, the codec and the supervision already live in their own modules.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from adapters.base import CallResult, DeviceInfo, GimbalAttitude, TelemetrySink
from adapters.clock import SYSTEM_CLOCK, Clock
from adapters.errors import (
    CommandError,
    DeviceNotConnected,
    DeviceRejected,
    DeviceTimeout,
    InvalidParameters,
    LinkError,
    MethodNotSupported,
)
from adapters.hold import HeldSetpoint
from adapters.rsdk.can import Reassembler, segment
from adapters.rsdk.commands import (
    COMMAND_TABLE,
    TABLE,
    Message,
    build_frame,
    decode_message,
    decode_reply,
    lookup,
    wants_reply,
)
from adapters.rsdk.config import RsdkDeviceSettings
from adapters.rsdk.extensions import (
    AngleGet,
    AutoCalibration,
    FocusPosition,
    FollowModeSet,
    GimbalPosition,
    LimitAngles,
    Stiffness,
)
from adapters.rsdk.link import CanLink
from adapters.rsdk.protocol import Frame, encode
from adapters.supervision import SupervisedAdapter
from adapters.wire.stream import DecoderStats
from adapters.wire.table import bind_handlers
from schemas.results import ResultCode
from schemas.services import (
    CameraAim,
    CameraFocalLengthSet,
    CameraModeSwitch,
    CameraPhotoTake,
    CameraRecordingStart,
    CameraRecordingStop,
    CameraScreenDrag,
    GimbalReset,
    PayloadRequest,
)

log = logging.getLogger(__name__)

__all__ = ["GimbalAdapter"]

PITCH_RANGE = (-56.0, 146.0)  # seed §2.3.4.1 pitch range −560 … +1460 (0.1°)
SPEED_TAKE_OVER = 0x88  # bit 7 take over, bit 3 ignore focal length (PROTOCOL-NOTES)
SPEED_RELEASE = 0x08
RC_PARSE_ERROR = 0x01
SDK_DEVICE_ID = 0x00000001  # seed §2.3.3: "DJI R SDK"
#: Gimbal auto calibration (0x0E 0x0F) self-tuning type, bits 7:1 of the control value: seed Figure 29's
#: note "Self-tuning type selects 1" (single attitude mode).
SELF_TUNING_TYPE = 1


@dataclass
class _Pending:
    future: asyncio.Future[Message]
    cmd_set: int
    cmd_id: int
    name: str


_CMD_SETS = frozenset(cmd_set for cmd_set, _ in TABLE)


def _answers_another_command(frame: Frame, cmd_set: int, cmd_id: int) -> bool:
    """A reply carrying another command's CmdSet/CmdID (a stale reply on a reused seq). A legacy reply
    (firmware before 2.2.0.5) has no CmdSet/CmdID: its data starts with a return code, never with a
    command set, so its first two bytes say nothing about which command it answers."""
    key = frame.key
    return key is not None and key[0] in _CMD_SETS and key != (cmd_set, cmd_id)


class GimbalAdapter(SupervisedAdapter):
    noun = "gimbal"
    _log = log
    _link: CanLink | None

    def __init__(self, settings: RsdkDeviceSettings, *, clock: Clock = SYSTEM_CLOCK) -> None:
        self.settings = settings
        super().__init__(
            DeviceInfo.of(settings.sn, settings.product, settings.payload_index, settings.carried_by),
            settings,
            clock,
        )
        self._rx = Reassembler(rx_id=settings.rx_id)
        self._seq = 0
        self._pending: dict[int, _Pending] = {}
        self.unmatched_replies = 0  # replies matching no request in flight (metrics)
        self._next_poll = 0.0  # when an offline gimbal is next asked to (re-)enable its push
        # what the gimbal told us (wire units converted to degrees)
        self.attitude: tuple[float, float, float] | None = None  # yaw, roll, pitch
        self.joints: tuple[float, float, float] | None = None
        self.limits: dict[str, int] | None = None
        self.stiffness: dict[str, int] | None = None
        self.version: str | None = None
        self.camera_mode = 0  # R SDK gimbals have no mode command: reported as photo (0)
        self.calibration: tuple[int, int] | None = None  # auto calibration (status, progress %), pushed
        self.recording = False
        # drag state
        self._drag_speed: tuple[float, float] = (0.0, 0.0)  # yaw, pitch °/s
        self._drag = HeldSetpoint(
            f"rsdk-{settings.sn}-drag",
            period=1.0 / settings.drag_rate_hz,
            clock=self._clock,
            refresh=self._drag_refresh,
            on_end=self._zero_and_release,
            end_when_cancelled=True,
        )
        self.handlers = {
            "camera_screen_drag": self._screen_drag,
            "camera_aim": self._aim,
            "gimbal_reset": self._gimbal_reset,
            "camera_photo_take": self._photo,
            "camera_recording_start": self._recording_start,
            "camera_recording_stop": self._recording_stop,
            "camera_mode_switch": self._mode_switch,
            "camera_focal_length_set": self._zoom,
            "x_rsdk_limit_angle_set": self._x_limit_set,
            "x_rsdk_limit_angle_get": self._x_limit_get,
            "x_rsdk_stiffness_set": self._x_stiffness_set,
            "x_rsdk_stiffness_get": self._x_stiffness_get,
            "x_rsdk_follow_mode_set": self._x_follow_mode,
            "x_rsdk_position_set": self._x_position,
            "x_rsdk_selfie": self._x_selfie,
            "x_rsdk_active_track_toggle": self._x_active_track,
            "x_rsdk_focus_set": self._x_focus,
            "x_rsdk_auto_calibration": self._x_calibration,
            "x_rsdk_version_get": self._x_version,
            "x_rsdk_angle_get": self._x_angle,
        }

    # -- life cycle -------------------------------------------------------------------------------
    async def start(self, sink: TelemetrySink) -> None:
        self._sink = sink
        loop = asyncio.get_running_loop()
        s = self.settings
        self._link = CanLink(
            interface=s.interface,
            channel=s.channel,
            bitrate=s.bitrate,
            rx_id=s.rx_id,
            loop=loop,
            on_frame=self._on_can,
            on_down=self._on_link_down,
            bus_options=s.bus_options,
        )
        self._tasks.append(loop.create_task(self._supervise(), name=f"rsdk-{s.sn}-supervisor"))

    async def stop(self) -> None:
        self._stopping = True
        with contextlib.suppress(Exception):
            await self.stop_motion()
        await self._end_supervision(self._drag.task)
        self._fail_pending(DeviceNotConnected(f"gimbal {self.info.sn} adapter stopped"))

    async def stop_motion(self) -> None:
        """Zero speed and release speed control. Fire-and-forget: no reply is awaited, so a stalled
        gimbal or a busy loop cannot delay it."""
        self._drag_speed = (0.0, 0.0)
        self._drag.cancel()
        self._zero_and_release()

    def drive(self, forward: float, right: float, up: float, yaw_rate: float) -> bool:
        """Live control of the gimbal (when ``drc_drive``): yaw rate → yaw speed, vertical stick → pitch
        speed. Thread-safe: encodes one speed-control frame and queues it (cmd type 0, no reply)."""
        s = self.settings
        if not s.drc_drive or not self._online:
            return False
        limit = s.max_speed_dps
        yaw = max(-limit, min(limit, yaw_rate))
        pitch = max(-limit, min(limit, up * s.drc_pitch_gain))
        with contextlib.suppress(LinkError, CommandError):
            self._send_no_reply("speed_control", self._speed_fields(yaw, pitch))
        return True

    def emergency_stop(self) -> None:
        for ctrl in (SPEED_TAKE_OVER, SPEED_RELEASE):
            with contextlib.suppress(LinkError, CommandError):
                self._send_no_reply(
                    "speed_control", {"yaw_speed": 0, "roll_speed": 0, "pitch_speed": 0, "ctrl_byte": ctrl}
                )

    def gimbal_attitude(self) -> GimbalAttitude | None:
        if self.attitude is None:
            return None
        yaw, roll, pitch = self.attitude
        return GimbalAttitude(yaw=yaw, roll=roll, pitch=pitch)

    # -- link supervision (the loop is SupervisedAdapter's) ----------------------------------------
    def _decoder_stats(self) -> DecoderStats:
        return self._rx.decoder.stats

    def _on_link_opened(self) -> None:
        self._rx.reset()
        self._next_poll = 0.0

    async def _supervise_tick(self, now: float) -> None:
        """Silence first, so a gimbal found silent is asked for its push in the same pass."""
        self._check_silence(now)
        if not self._online and now >= self._next_poll:
            # (re-)enable the push: a gimbal that restarted has it off; its reply brings us online
            self._next_poll = now + min(1.0, self.settings.silence_timeout / 2)
            with contextlib.suppress(LinkError, CommandError):
                self._send_no_reply("push_settings", {"ctrl_byte": 0x01}, want_reply=True)
                self._send_no_reply("get_version", {"device_id": SDK_DEVICE_ID}, want_reply=True)

    def _on_went_silent(self, now: float) -> None:
        self._fail_pending(DeviceNotConnected(f"gimbal {self.info.sn} went silent"))

    def _on_link_down(self, reason: str) -> None:
        super()._on_link_down(reason)
        self._fail_pending(DeviceNotConnected(f"gimbal {self.info.sn} CAN link down"))

    def _on_online_changed(self, online: bool) -> None:
        if not online:
            self._drag.expire()  # a drag in progress stops and releases at its next wake-up

    def _fail_pending(self, exc: Exception) -> None:
        pending, self._pending = self._pending, {}
        for p in pending.values():
            if not p.future.done():
                p.future.set_exception(exc)

    # -- receive ---------------------------------------------------------------------------------
    def _on_can(self, arb_id: int, data: bytes) -> None:
        for item in self._rx.feed(arb_id, data):
            if isinstance(item, Frame):
                self._on_frame(item)

    def _on_frame(self, frame: Frame) -> None:
        self._last_heard = self._now()
        self._set_online(True)
        if frame.is_reply:
            p = self._pending.get(frame.seq)
            if p is None or _answers_another_command(frame, p.cmd_set, p.cmd_id):
                # late, duplicated or carrying another request's seq: never misapplied to a request
                self._on_unsolicited_reply(frame)
                return
            del self._pending[frame.seq]
            try:
                msg = decode_reply(
                    frame, p.cmd_set, p.cmd_id, p.name, angle_order=self.settings.legacy_angle_order
                )
            except CommandError as exc:
                if not p.future.done():
                    p.future.set_exception(DeviceRejected(ResultCode.BUSY, f"unreadable reply: {exc}"))
                return
            if not p.future.done():
                p.future.set_result(msg)
            return
        try:
            msg = decode_message(frame)
        except CommandError:
            return
        handler = _PUSHES.get(msg.name)
        if handler is not None:
            handler(self, msg.fields)

    def _on_unsolicited_reply(self, frame: Frame) -> None:
        """Replies to fire-and-forget commands (the start-up version query) still carry news; any
        other reply without its request in flight is counted and dropped."""
        if frame.key == (0x0E, 0x09):
            with contextlib.suppress(CommandError):
                msg = decode_reply(frame, 0x0E, 0x09, "get_version")
                self._version_from(msg.fields)
            return
        self.unmatched_replies += 1

    def _version_from(self, f: Mapping[str, Any]) -> None:
        v = int(f.get("version", 0))
        self.version = ".".join(f"{(v >> s) & 0xFF:02X}" for s in (24, 16, 8, 0))

    def _on_calibration(self, f: Mapping[str, Any]) -> None:
        """Auto calibration progress (0x0E 0x10): kept in ``calibration``, each status change logged."""
        for item in f.get("tlv_buffer", ()):
            value = item.get("value")
            if item.get("id") != 0x00 or not isinstance(value, dict):
                continue  # an unknown or malformed item: the decoder kept it raw
            status, progress = int(value.get("status", 0)), int(value.get("progress", 0))
            before = self.calibration
            self.calibration = (status, progress)
            if before is None or before[0] != status:
                text = {0: "idle", 1: "running", 2: "completed", 3: "failed"}.get(status, str(status))
                log.info("gimbal %s auto calibration %s (%d %%)", self.info.sn, text, progress)

    def _on_push(self, f: Mapping[str, Any]) -> None:
        ctrl = f["ctrl_byte"]
        if ctrl & 0x01:
            self.attitude = (f["yaw_angle"] / 10, f["roll_angle"] / 10, f["pitch_angle"] / 10)
            self.joints = (f["yaw_joint_angle"] / 10, f["roll_joint_angle"] / 10, f["pitch_joint_angle"] / 10)
        if ctrl & 0x02:
            self.limits = {
                k: f[k] for k in ("pitch_max", "pitch_min", "yaw_max", "yaw_min", "roll_max", "roll_min")
            }
        if ctrl & 0x04:
            self.stiffness = {
                "pitch": f["pitch_stiffness"],
                "roll": f["roll_stiffness"],
                "yaw": f["yaw_stiffness"],
            }

    # -- send -------------------------------------------------------------------------------------
    def _next_seq(self) -> int:
        self._seq = (self._seq + 1) & 0xFFFF
        while self._seq in self._pending:
            self._seq = (self._seq + 1) & 0xFFFF
        return self._seq

    def _send_no_reply(self, name: str, fields: Mapping[str, Any], *, want_reply: bool = False) -> None:
        if self._link is None:
            raise LinkError("not started")
        frame = build_frame(name, self._next_seq(), fields, cmd_type=None if want_reply else 0x00)
        self._link.send(segment(encode(frame), self.settings.tx_id))

    async def request(self, name: str, fields: Mapping[str, Any]) -> Message:
        """Send one command and wait for its reply (matched by SEQ) within the adapter's timeout."""
        if not self._online or self._link is None or not self._link.up:
            raise DeviceNotConnected(f"gimbal {self.info.sn} is not connected")
        spec = lookup(name)
        try:
            frame = build_frame(name, self._next_seq(), fields)
        except CommandError as exc:
            raise InvalidParameters(str(exc)) from None
        fut: asyncio.Future[Message] = asyncio.get_running_loop().create_future()
        self._pending[frame.seq] = _Pending(fut, *spec.set_and_id, name)
        try:
            self._link.send(segment(encode(frame), self.settings.tx_id))
            return await self._clock.wait_for(fut, self.settings.request_timeout)
        except LinkError as exc:
            raise DeviceNotConnected(str(exc)) from None
        except TimeoutError:
            raise DeviceTimeout(f"gimbal {self.info.sn} did not answer {name}") from None
        finally:
            self._pending.pop(frame.seq, None)

    async def send_confirmed(self, name: str, fields: Mapping[str, Any]) -> None:
        """Send a command that gets no reply frame (seed: "This command has no reply frame"; CmdType 0)
        and return once its frames are on the bus: that is all a gimbal will ever say about it."""
        if not self._online or self._link is None or not self._link.up:
            raise DeviceNotConnected(f"gimbal {self.info.sn} is not connected")
        try:
            frame = build_frame(name, self._next_seq(), fields)
        except CommandError as exc:
            raise InvalidParameters(str(exc)) from None
        if frame.needs_reply:  # pragma: no cover - a table entry with a reply goes through request()
            raise ValueError(f"{name} gets a reply frame: use request()")
        done: asyncio.Future[None] = asyncio.get_running_loop().create_future()

        def sent() -> None:
            if not done.done():
                done.set_result(None)

        try:
            self._link.send(segment(encode(frame), self.settings.tx_id), on_sent=sent)
            await self._clock.wait_for(done, self.settings.request_timeout)
        except LinkError as exc:
            raise DeviceNotConnected(str(exc)) from None
        except TimeoutError:
            raise DeviceTimeout(f"gimbal {self.info.sn}: {name} could not be put on the bus") from None

    async def _command(self, name: str, fields: Mapping[str, Any], failure: int) -> Message | None:
        """One command: its reply checked (return code 0, else the result ``failure``), or for a command
        without a reply frame, its frames on the bus (None)."""
        spec = lookup(name)
        if not wants_reply(spec, {**spec.fixed, **fields}):
            await self.send_confirmed(name, fields)
            return None
        msg = await self.request(name, fields)
        code = msg.fields.get("return_code", 0)
        if code == 0:
            return msg
        if code == RC_PARSE_ERROR:
            raise DeviceRejected(ResultCode.INVALID_PARAMETERS, f"gimbal could not parse {name}")
        raise DeviceRejected(failure, f"gimbal refused {name} (return code 0x{code:02X})")

    # -- telemetry --------------------------------------------------------------------------------
    def osd_snapshot(self) -> Mapping[str, Any] | None:
        if self.attitude is None:
            return None
        yaw, roll, pitch = self.attitude
        body: dict[str, Any] = {
            "payload_index": self.info.payload_index,
            "gimbal_yaw": yaw,
            "gimbal_roll": roll,
            "gimbal_pitch": pitch,
            "cameras": [
                {
                    "payload_index": self.info.payload_index,
                    "camera_mode": self.camera_mode,
                    "recording_state": 1 if self.recording else 0,
                }
            ],
        }
        if self.joints is not None:
            body["x_joint_angles"] = {"yaw": self.joints[0], "roll": self.joints[1], "pitch": self.joints[2]}
        if self.limits is not None:
            lim = self.limits
            body["x_angle_limits"] = {
                "pitch_max": float(lim["pitch_max"]),
                "pitch_min": -float(lim["pitch_min"]),
                "yaw_max": float(lim["yaw_max"]),
                "yaw_min": -float(lim["yaw_min"]),
                "roll_max": float(lim["roll_max"]),
                "roll_min": -float(lim["roll_min"]),
            }
        if self.stiffness is not None:
            body["x_motor_stiffness"] = dict(self.stiffness)
        return body

    # -- Cloud API methods ------------------------------------------------------------------------
    async def _screen_drag(self, data: CameraScreenDrag) -> CallResult:
        s = self.settings
        yaw = 0.0 if data.locked else float(data.yaw_speed)
        pitch = float(data.pitch_speed)
        if max(abs(yaw), abs(pitch)) > s.max_speed_dps:
            raise InvalidParameters(f"drag speed above {s.max_speed_dps:g} °/s")
        self._drag_speed = (yaw, pitch)
        self._drag.until = self._now() + s.drag_hold
        await self._command("speed_control", self._speed_fields(yaw, pitch), ResultCode.SCREEN_DRAG_FAILED)
        self._drag.start()
        return CallResult()

    @staticmethod
    def _speed_fields(yaw: float, pitch: float) -> dict[str, int]:
        return {
            "yaw_speed": round(yaw * 10),
            "roll_speed": 0,
            "pitch_speed": round(pitch * 10),
            "ctrl_byte": SPEED_TAKE_OVER,
        }

    def _drag_refresh(self, dt: float) -> None:
        """Refresh speed control while the drag lasts."""
        with contextlib.suppress(LinkError, CommandError):
            self._send_no_reply("speed_control", self._speed_fields(*self._drag_speed))

    def _zero_and_release(self) -> None:
        """After the drag: zero speed, then release speed control."""
        for ctrl in (SPEED_TAKE_OVER, SPEED_RELEASE):
            with contextlib.suppress(LinkError, CommandError):
                self._send_no_reply(
                    "speed_control",
                    {"yaw_speed": 0, "roll_speed": 0, "pitch_speed": 0, "ctrl_byte": ctrl},
                )

    async def _aim(self, data: CameraAim) -> CallResult:
        s = self.settings
        d_yaw = (float(data.x) - 0.5) * s.fov_h_deg
        d_pitch = (0.5 - float(data.y)) * s.fov_v_deg
        fields = {
            "yaw_angle": round(d_yaw * 10),
            "roll_angle": 0,
            "pitch_angle": round(d_pitch * 10),
            "ctrl_byte": 0x04,  # incremental, roll invalid
            "time_for_action": max(1, round(s.aim_time_s * 10)),
        }
        await self._command("position_control", fields, ResultCode.AIM_FAILED)
        return CallResult()

    def _pitch_down(self) -> int:
        return round(max(PITCH_RANGE[0], -90.0) * 10)

    async def _gimbal_reset(self, data: GimbalReset) -> CallResult:
        mode = int(data.reset_mode)
        if mode == 0:
            await self._command("recenter_selfie", {"recenter_and_selfie_command": 0x01}, ResultCode.BUSY)
            return CallResult()
        yaw_valid = mode in (1, 2)
        pitch_valid = mode in (1, 3)
        ctrl = (
            0x01 | 0x04 | (0 if yaw_valid else 0x02) | (0 if pitch_valid else 0x08)
        )  # absolute, roll invalid
        fields = {
            "yaw_angle": 0,
            "roll_angle": 0,
            "pitch_angle": self._pitch_down() if pitch_valid else 0,
            "ctrl_byte": ctrl,
            "time_for_action": 10,
        }
        await self._command("position_control", fields, ResultCode.BUSY)
        return CallResult()

    async def _camera(self, command: int, failure: int) -> None:
        await self._command("camera_control", {"camera_control_command": command}, failure)

    async def _photo(self, data: CameraPhotoTake) -> CallResult:
        await self._camera(0x0001, ResultCode.PHOTO_FAILED)
        return CallResult()

    async def _recording_start(self, data: CameraRecordingStart) -> CallResult:
        await self._camera(0x0003, ResultCode.RECORDING_START_FAILED)
        self.recording = True
        return CallResult()

    async def _recording_stop(self, data: CameraRecordingStop) -> CallResult:
        await self._camera(0x0004, ResultCode.RECORDING_STOP_FAILED)
        self.recording = False
        return CallResult()

    async def _mode_switch(self, data: CameraModeSwitch) -> CallResult:
        # Seed 000 has no camera-mode command (0x0D 0x00 takes a photo or starts/stops recording in any
        # mode), and an answer of 0 without a frame on the wire would be a fake result.
        raise MethodNotSupported(
            "R SDK gimbals have no camera mode command: camera_photo_take and camera_recording_start "
            "work in any mode"
        )

    async def _zoom(self, data: CameraFocalLengthSet) -> CallResult:
        raise MethodNotSupported("R SDK gimbals have no zoom command (camera_focal_length_set)")

    # -- extension methods ------------------------------------------------------------------------
    async def _x_limit_set(self, data: LimitAngles) -> CallResult:
        names = ("pitch_max", "pitch_min", "yaw_max", "yaw_min", "roll_max", "roll_min")
        await self._command(
            "set_limit_angle", {"ctrl_byte": 0x01, **{n: getattr(data, n) for n in names}}, ResultCode.BUSY
        )
        return CallResult()

    async def _x_limit_get(self, data: PayloadRequest) -> CallResult:
        msg = await self._command("get_limit_angle", {"ctrl_byte": 0x01}, ResultCode.BUSY)
        assert msg is not None  # get_limit_angle has a reply frame
        names = ("pitch_max", "pitch_min", "yaw_max", "yaw_min", "roll_max", "roll_min")
        return CallResult(0, {n: msg.fields[n] for n in names})

    async def _x_stiffness_set(self, data: Stiffness) -> CallResult:
        fields = {
            "ctrl_byte": 0x01,
            "pitch_stiffness": data.pitch,
            "roll_stiffness": data.roll,
            "yaw_stiffness": data.yaw,
        }
        await self._command("set_stiffness", fields, ResultCode.BUSY)
        return CallResult()

    async def _x_stiffness_get(self, data: PayloadRequest) -> CallResult:
        msg = await self._command("get_stiffness", {"ctrl_byte": 0x01}, ResultCode.BUSY)
        assert msg is not None  # get_stiffness has a reply frame
        f = msg.fields
        return CallResult(
            0, {"pitch": f["pitch_stiffness"], "roll": f["roll_stiffness"], "yaw": f["yaw_stiffness"]}
        )

    async def _x_follow_mode(self, data: FollowModeSet) -> CallResult:
        fields = {"operating_mode": int(data.mode), "recenter_and_selfie_command": 0x00}
        await self._command("follow_mode", fields, ResultCode.BUSY)
        return CallResult()

    async def _x_position(self, data: GimbalPosition) -> CallResult:
        ctrl = 0x01 if data.absolute else 0x00
        values = {}
        for bit, axis in ((0x02, "yaw"), (0x04, "roll"), (0x08, "pitch")):
            value = getattr(data, axis)
            if value is None:
                ctrl |= bit
            values[f"{axis}_angle"] = round((value or 0.0) * 10)
        fields = {**values, "ctrl_byte": ctrl, "time_for_action": round(data.duration * 10)}
        await self._command("position_control", fields, ResultCode.BUSY)
        return CallResult()

    async def _x_selfie(self, data: PayloadRequest) -> CallResult:
        await self._command("recenter_selfie", {"recenter_and_selfie_command": 0x02}, ResultCode.BUSY)
        return CallResult()

    async def _x_active_track(self, data: PayloadRequest) -> CallResult:
        await self._command("active_track", {"enable_active_track": 0x03}, ResultCode.BUSY)
        return CallResult()

    async def _x_focus(self, data: FocusPosition) -> CallResult:
        # sub-command 0x01 has no reply frame (seed Figure 32): answered once it is on the bus
        fields = {
            "command_sub_id": 0x01,
            "control_type": 0x00,
            "data_length": 0x02,
            "absolute_position": data.position,
        }
        await self._command("focus_motor", fields, ResultCode.BUSY)
        return CallResult()

    async def _x_calibration(self, data: AutoCalibration) -> CallResult:
        # seed Figure 29: bit 0 start/stop, bits 7:1 the self-tuning type, and "Self-tuning type selects
        # 1" (single attitude mode): start 0x03, stop 0x02. No reply frame: answered once on the bus.
        item = {"id": 0x00, "value": (SELF_TUNING_TYPE << 1) | (0x01 if data.start else 0x00)}
        await self._command("auto_calibration", {"tlv_buffer": [item]}, ResultCode.BUSY)
        return CallResult()

    async def _x_angle(self, data: AngleGet) -> CallResult:
        """0x0E 0x02; a legacy-firmware reply is read in this gimbal's ``legacy_angle_order``."""
        msg = await self._command("get_angle", {"ctrl_byte": 0x02 if data.joint else 0x01}, ResultCode.BUSY)
        assert msg is not None  # get_angle has a reply frame
        f = msg.fields
        if f["data_type"] == 0x00:
            raise DeviceRejected(ResultCode.BUSY, "the gimbal's angle data is not ready")
        kind = "joint" if f["data_type"] == 0x02 else "attitude"
        return CallResult(0, {"kind": kind, **{axis: f[axis] / 10 for axis in ("yaw", "roll", "pitch")}})

    async def _x_version(self, data: PayloadRequest) -> CallResult:
        msg = await self._command("get_version", {"device_id": SDK_DEVICE_ID}, ResultCode.BUSY)
        assert msg is not None  # get_version has a reply frame
        self._version_from(msg.fields)
        return CallResult(0, {"device_id": msg.fields["device_id"], "version": self.version})


# push → handler, as the table's entries name them (a missing method fails here, at import)
_PUSHES = bind_handlers(GimbalAdapter, COMMAND_TABLE)
