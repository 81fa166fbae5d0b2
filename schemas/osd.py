"""OSD bodies (``thing/product/{device_sn}/osd``, periodic) for the gateway, an aircraft, a gimbal payload
and a ground robot.

Owns the telemetry property names and units. Knows nothing about the devices that fill them.

Naming: the Cloud API's own property names wherever one exists (``latitude``, ``height``, ``elevation``,
``attitude_head``, ``horizontal_speed``, ``mode_code``, ``battery.capacity_percent``, ``gimbal_pitch``,
``cameras[].recording_state``, ...); anything the Cloud API has no name for is an extension and starts
with ``x_`` (``base.EXTENSION_PREFIX``) and its description starts with "Extension.". Every field is
optional ("where the device knows it"), but a body must carry at least one. Angles are degrees, distances
metres, speeds m/s, as in the Cloud API (adapters convert from wire units).
"""

from __future__ import annotations

import enum
import re
from typing import Annotated, Literal

from pydantic import ConfigDict, Field, model_validator

from .base import (
    Float,
    Int,
    IntEnumField,
    Latitude,
    Longitude,
    OutboundModel,
    PayloadIndex,
    TimestampMs,
    enum_description,
)
from .state import DrcStateField, DrcStateProperty, require_any


def _ext(description: str) -> str:
    return f"Extension. {description}"


Angle = Annotated[
    float, Field(strict=True, allow_inf_nan=False, ge=-180, le=180, json_schema_extra={"x-unit": "°"})
]
WideAngle = Annotated[
    float, Field(strict=True, allow_inf_nan=False, ge=-360, le=360, json_schema_extra={"x-unit": "°"})
]
Metres = Annotated[float, Field(strict=True, allow_inf_nan=False, json_schema_extra={"x-unit": "m"})]
Speed = Annotated[float, Field(strict=True, allow_inf_nan=False, json_schema_extra={"x-unit": "m/s"})]
Percent = Annotated[int, Field(strict=True, ge=0, le=100, json_schema_extra={"x-unit": "%"})]


class DrcFailsafe(OutboundModel):
    """Extension. The live-control failsafe that fired last and still holds (``none`` once it cleared)."""

    reason: Literal["none", "sticks", "heartbeat", "emergency_stop", "link_lost", "authority"] = Field(
        description="sticks: no drone_control for drc.stick_timeout; heartbeat: no heart_beat for "
        "drc.heartbeat_timeout; emergency_stop; link_lost: the DRC broker connection dropped; authority: "
        "flight/payload authority lost; none: nothing holds."
    )
    since: TimestampMs | None = Field(default=None, description="When it first fired (ms since the epoch).")


class GatewayOsd(DrcStateProperty):
    """The gateway's own osd: the ``drc_state`` property (seed 003 § Property, pushMode 0), and which
    live-control failsafe holds (extension)."""

    x_drc_failsafe: DrcFailsafe | None = Field(
        default=None, description=_ext("The live-control failsafe that holds the devices, if any.")
    )


# ---------------------------------------------------------------------------------------------- aircraft


class ModeCode(enum.IntEnum):
    """Cloud API aircraft ``mode_code``."""

    STANDBY = 0
    TAKEOFF_PREPARATION = 1
    TAKEOFF_READY = 2
    MANUAL = 3
    AUTO_TAKEOFF = 4
    WAYLINE = 5
    PANORAMA = 6
    TRACKING = 7
    ADSB_AVOIDANCE = 8
    RETURN_HOME = 9
    AUTO_LANDING = 10
    FORCED_LANDING = 11
    THREE_BLADE_LANDING = 12
    UPGRADING = 13
    NOT_CONNECTED = 14
    APAS = 15
    VIRTUAL_STICK = 16
    LIVE_FLIGHT_CONTROLS = 17


_MODE_CODE = enum_description(
    ModeCode, {member: member.name.replace("_", " ").lower() for member in ModeCode}
)


class BatteryItem(OutboundModel):
    """One battery of ``battery.batteries[]`` (Cloud API names; ``x_current`` is an extension)."""

    index: Int = Field(ge=0, le=7, description="Battery slot.")
    capacity_percent: Percent | None = None
    voltage: Int | None = Field(default=None, ge=0, description="mV.", json_schema_extra={"x-unit": "mV"})
    temperature: Float | None = Field(
        default=None, ge=-100, le=200, description="°C.", json_schema_extra={"x-unit": "°C"}
    )
    x_current: Int | None = Field(
        default=None,
        description=_ext("Current (mA); negative is discharge."),
        json_schema_extra={"x-unit": "mA"},
    )


class Battery(OutboundModel):
    """Aircraft ``battery`` (Cloud API names)."""

    capacity_percent: Percent = Field(description="Remaining charge of the whole aircraft (%).")
    remain_flight_time: Int | None = Field(
        default=None, ge=0, description="Seconds of flight left.", json_schema_extra={"x-unit": "s"}
    )
    batteries: list[BatteryItem] | None = Field(default=None, max_length=8)


class PayloadOsd(OutboundModel):
    """A gimbal payload's angles in an aircraft osd, under the key ``{payload_index}`` (Cloud API shape)."""

    payload_index: PayloadIndex
    gimbal_pitch: WideAngle | None = None
    gimbal_roll: WideAngle | None = None
    gimbal_yaw: WideAngle | None = None
    zoom_factor: Float | None = Field(default=None, ge=1, le=200)


_PAYLOAD_KEY = re.compile(r"^[0-9]{1,5}-[0-9]{1,5}-[0-9]{1,5}$")


class AircraftOsd(OutboundModel):
    """Aircraft osd (Onboard SDK flight controller), Cloud API names.

    Besides the named fields, keys of the form ``{payload_index}`` (e.g. ``"39-0-7"``) carry a
    ``PayloadOsd`` whose ``payload_index`` equals the key: that is how the Cloud API reports a gimbal on an
    aircraft. Any other unknown key is rejected.
    """

    model_config = ConfigDict(extra="allow")
    __pydantic_extra__: dict[str, PayloadOsd] = Field(init=False)

    latitude: Latitude | None = None
    longitude: Longitude | None = None
    height: Metres | None = Field(default=None, description="Ellipsoid (WGS84) height (m).")
    elevation: Metres | None = Field(default=None, description="Height above the take-off point (m).")
    attitude_pitch: Angle | None = Field(default=None, description="Pitch (°).")
    attitude_roll: Angle | None = Field(default=None, description="Roll (°).")
    attitude_head: Angle | None = Field(default=None, description="Heading (°), 0 north, clockwise positive.")
    horizontal_speed: Speed | None = Field(default=None, ge=0, description="Ground speed (m/s).")
    vertical_speed: Speed | None = Field(default=None, description="Vertical speed (m/s); positive is up.")
    mode_code: IntEnumField[ModeCode] | None = Field(default=None, description=_MODE_CODE)
    battery: Battery | None = None
    drc_state: DrcStateField | None = Field(
        default=None, description="0 disconnected, 1 connecting, 2 connected."
    )

    @model_validator(mode="after")
    def _payload_keys(self) -> AircraftOsd:
        for key, value in (self.model_extra or {}).items():
            if (
                not _PAYLOAD_KEY.fullmatch(key)
                or not isinstance(value, PayloadOsd)
                or value.payload_index != key
            ):
                raise ValueError(f"unknown property {key[:40]!r} (only {{payload_index}} keys may be added)")
        require_any(self)
        return self


# ------------------------------------------------------------------------------------------------ gimbal


class CameraOsdMode(enum.IntEnum):
    """Cloud API ``cameras[].camera_mode`` in osd."""

    PHOTO = 0
    VIDEO = 1
    LOW_LIGHT = 2
    PANORAMA = 3


class RecordingState(enum.IntEnum):
    IDLE = 0
    RECORDING = 1


class CameraOsd(OutboundModel):
    """One camera of ``cameras[]`` (Cloud API names)."""

    payload_index: PayloadIndex
    camera_mode: IntEnumField[CameraOsdMode] | None = Field(default=None, description="0 photo, 1 video, ...")
    recording_state: IntEnumField[RecordingState] | None = Field(
        default=None, description="0 idle, 1 recording."
    )
    zoom_factor: Float | None = Field(default=None, ge=1, le=200)


class Axes(OutboundModel):
    """Per-axis values (pitch, roll, yaw)."""

    pitch: Float | None = None
    roll: Float | None = None
    yaw: Float | None = None


class AngleLimits(OutboundModel):
    """Mechanical/soft angle limits (°) per axis."""

    pitch_min: Float | None = None
    pitch_max: Float | None = None
    roll_min: Float | None = None
    roll_max: Float | None = None
    yaw_min: Float | None = None
    yaw_max: Float | None = None


class Stiffness(OutboundModel):
    """Motor stiffness per axis (0..100)."""

    pitch: Percent | None = None
    roll: Percent | None = None
    yaw: Percent | None = None


class GimbalOsd(OutboundModel):
    """Gimbal payload osd (R SDK gimbal as its own device), Cloud API payload names plus ``x_`` extensions."""

    payload_index: PayloadIndex | None = None
    gimbal_pitch: WideAngle | None = Field(default=None, description="Attitude pitch (°).")
    gimbal_roll: WideAngle | None = Field(default=None, description="Attitude roll (°).")
    gimbal_yaw: WideAngle | None = Field(default=None, description="Attitude yaw (°).")
    cameras: list[CameraOsd] | None = Field(default=None, max_length=4)
    x_joint_angles: Axes | None = Field(default=None, description=_ext("Joint (motor) angles (°)."))
    x_angle_limits: AngleLimits | None = Field(default=None, description=_ext("Angle limits (°)."))
    x_motor_stiffness: Stiffness | None = Field(default=None, description=_ext("Motor stiffness (0..100)."))

    @model_validator(mode="after")
    def _not_empty(self) -> GimbalOsd:
        require_any(self)
        return self


# ------------------------------------------------------------------------------------------------- robot


class FieldPosition(OutboundModel):
    """Position on the competition field (m, field frame) from the referee system."""

    x: Float
    y: Float


class RobotOsd(OutboundModel):
    """Ground robot osd (RoboMaster referee data). Only ``attitude_head`` has a Cloud API name."""

    attitude_head: Angle | None = Field(default=None, description="Heading (°), -180..180.")
    x_robot_id: Int | None = Field(
        default=None, ge=1, le=255, description=_ext("Referee robot id: red 1-11, blue 101-111.")
    )
    x_position: FieldPosition | None = Field(default=None, description=_ext("Field position x, y (m)."))
    x_hp: Int | None = Field(default=None, ge=0, le=65535, description=_ext("Current HP."))
    x_max_hp: Int | None = Field(default=None, ge=0, le=65535, description=_ext("Maximum HP."))
    x_chassis_power: Float | None = Field(
        default=None, ge=0, description=_ext("Chassis power (W)."), json_schema_extra={"x-unit": "W"}
    )
    x_buffer_energy: Int | None = Field(
        default=None,
        ge=0,
        le=65535,
        description=_ext("Buffer energy (J)."),
        json_schema_extra={"x-unit": "J"},
    )
    x_shooter_heat: list[Annotated[int, Field(strict=True, ge=0, le=65535)]] | None = Field(
        default=None, max_length=4, description=_ext("Barrel heat, in the referee's barrel order.")
    )
    x_stage_remain_time: Int | None = Field(
        default=None,
        ge=0,
        le=65535,
        description=_ext("Seconds left in the game stage."),
        json_schema_extra={"x-unit": "s"},
    )

    @model_validator(mode="after")
    def _not_empty(self) -> RobotOsd:
        require_any(self)
        return self
