"""``data`` of every service in seed 003 (cloud → gateway on ``services``) and of their replies.

Owns the parameters of authority grabs, DRC enter/exit, take-off and fly-to, camera and gimbal control,
with the seed's ranges, enums and units. Knows nothing about how a device carries them out.

Every reply in the seed is ``{"result": int}`` ("Non-0 means error"): it is ``envelope.ResultReply``, which
adds an optional ``output.reason`` on failure.
"""

from __future__ import annotations

import enum
import re
from typing import Annotated

from pydantic import Field, StringConstraints, field_validator, model_validator

from .base import (
    MAX_SAFE_INT,
    Bool,
    Float,
    InboundModel,
    Int,
    IntEnumField,
    Latitude,
    Longitude,
    OutboundModel,
    PayloadIndex,
    Reason,
    Secret,
    enum_description,
)
from .envelope import EmptyRequest
from .results import ResultValue

# ------------------------------------------------------------------------------------------------- enums


class RcLostAction(enum.IntEnum):
    HOVER = 0
    LAND = 1
    RETURN_HOME = 2


class ExitWaylineWhenRcLost(enum.IntEnum):
    CONTINUE = 0
    EXIT = 1


class RthMode(enum.IntEnum):
    OPTIMAL_HEIGHT = 0
    PRESET_HEIGHT = 1


class CommanderModeLostAction(enum.IntEnum):
    CONTINUE = 0
    EXECUTE_RC_LOST_ACTION = 1


class CommanderFlightMode(enum.IntEnum):
    SMART_HEIGHT = 0
    FIXED_HEIGHT = 1


class SimulateSwitch(enum.IntEnum):
    OFF = 0
    ON = 1


class CameraMode(enum.IntEnum):
    PHOTO = 0
    RECORDING = 1


class CameraType(enum.StrEnum):
    ZOOM = "zoom"
    WIDE = "wide"
    IR = "ir"


class GimbalResetMode(enum.IntEnum):
    RECENTER = 0
    DOWN = 1
    RECENTER_PAN = 2
    PITCH_DOWN = 3


_RC_LOST = enum_description(
    RcLostAction,
    {
        RcLostAction.HOVER: "Hovering",
        RcLostAction.LAND: "Landing",
        RcLostAction.RETURN_HOME: "Returning to home",
    },
)
_EXIT_WAYLINE = enum_description(
    ExitWaylineWhenRcLost,
    {
        ExitWaylineWhenRcLost.CONTINUE: "Continue the wayline task",
        ExitWaylineWhenRcLost.EXIT: "Exit the wayline task and do the RC-lost action",
    },
)
_RTH_MODE = enum_description(
    RthMode,
    {
        RthMode.OPTIMAL_HEIGHT: "Optimal (smart) return-to-home height",
        RthMode.PRESET_HEIGHT: "Preset return-to-home height (rth_altitude)",
    },
)
_COMMANDER_LOST = enum_description(
    CommanderModeLostAction,
    {
        CommanderModeLostAction.CONTINUE: "Continue the flight to the target",
        CommanderModeLostAction.EXECUTE_RC_LOST_ACTION: "Execute the RC-lost action",
    },
)
_COMMANDER_MODE = enum_description(
    CommanderFlightMode,
    {
        CommanderFlightMode.SMART_HEIGHT: "Smart height (the aircraft picks its flight height)",
        CommanderFlightMode.FIXED_HEIGHT: "Fixed height: fly to the target at commander_flight_height",
    },
)
_CAMERA_MODE = enum_description(
    CameraMode, {CameraMode.PHOTO: "Photo taking", CameraMode.RECORDING: "Recording"}
)
_RESET_MODE = enum_description(
    GimbalResetMode,
    {
        GimbalResetMode.RECENTER: "gimbal recenter",
        GimbalResetMode.DOWN: "gimbal down",
        GimbalResetMode.RECENTER_PAN: "recenter gimbal pan",
        GimbalResetMode.PITCH_DOWN: "gimbal pitch down",
    },
)

# ---------------------------------------------------------------------------------------- shared fields

CameraTypeField = Annotated[CameraType, Field(description="zoom, wide or ir (infrared).")]

#: A task id (``flight_id``, ``fly_to_id``) as DJI's Java Cloud SDK validates it (TakeoffToPointRequest,
#: FlyToPointRequest: ``^[^<>:"/|?*._\\]+$``): none of ``. _ < > : " / \ | ? *``, at least one character.
TaskId = Annotated[
    str,
    StringConstraints(strict=True, min_length=1, max_length=256, pattern=r'^[^<>:"/|?*._\\]+$'),
]
#: A WGS84 target height (m) as the Java Cloud SDK bounds it (Point.height, targetHeight): 2..10000. What an
#: aircraft can reach is its own limit: an adapter refuses a height above it (325001).
TargetHeight = Annotated[
    float,
    Field(strict=True, allow_inf_nan=False, ge=2, le=10000, json_schema_extra={"x-unit": "m"}),
]


class PayloadRequest(InboundModel):
    """A request that names one payload (camera/gimbal) by its index."""

    payload_index: PayloadIndex


# --------------------------------------------------------------------------------------------- services


class FlightAuthorityGrab(EmptyRequest):
    """Grab flight control authority (seed 003 § Flight control authority grabbing). No parameters."""


class PayloadAuthorityGrab(PayloadRequest):
    """Grab payload control authority for one payload (seed 003 § Payload control authority grabbing)."""


_ADDRESS = re.compile(
    r"^(?:\[[0-9A-Fa-f:.]{2,45}\]|[A-Za-z0-9](?:[A-Za-z0-9.-]{0,251}[A-Za-z0-9])?):([0-9]{1,5})$"
)


class MqttBroker(InboundModel):
    """The DRC broker and its credentials (seed 003 § drc_mode_enter, ``mqtt_broker``).

    ``password`` is a ``SecretStr``: hidden in repr and masked in dumps unless
    ``context={"reveal_secrets": True}``; validation errors under ``mqtt_broker`` never quote a value.
    Credentials may expire without dropping an open connection (PROTOCOL-NOTES), so ``expire_time`` in the
    past is not an error here.
    """

    address: Annotated[str, StringConstraints(strict=True, max_length=260)] = Field(
        description="host:port, e.g. mqtt.dji.com:8883 or 192.0.2.1:8883 ([v6]:port for IPv6).",
        examples=["mqtt.dji.com:8883"],
    )
    client_id: Annotated[str, StringConstraints(strict=True, min_length=1, max_length=256)] = Field(
        description="MQTT client id for the DRC link, e.g. drc-4J4R101."
    )
    username: Annotated[str, StringConstraints(strict=True, max_length=1024)]
    password: Secret
    expire_time: Int = Field(
        ge=1234567890,
        le=9999999999,
        description="Unix time (s) the credentials expire; 1234567890..9999999999 as DJI's Java Cloud SDK.",
        json_schema_extra={"x-unit": "s"},
    )
    enable_tls: Bool

    @field_validator("address")
    @classmethod
    def _host_port(cls, value: str) -> str:
        match = _ADDRESS.fullmatch(value)
        if match is None or not 1 <= int(match.group(1)) <= 65535:
            raise ValueError("address must be host:port with a port in 1..65535")
        return value


#: The highest osd_info_push / hsi_info_push rate (Hz) DJI documents (seed 003, Dock 2/3 pages: 1..30).
MAX_PUSH_FREQUENCY = 30

Frequency = Annotated[
    int,
    Field(
        strict=True,
        ge=1,
        le=MAX_SAFE_INT,
        json_schema_extra={"x-unit": "Hz", "x-used-at-most": MAX_PUSH_FREQUENCY},
    ),
]


class DrcModeEnter(InboundModel):
    """Enter live flight control (DRC) (seed 003 § Enter the live flight controls mode).

    DJI's range for both rates is 1..30 Hz. A higher rate is what a client asks for, not a malformed
    request (an RC-side client, github wudizhr/DJI_Cloud_API_demo, sends ``osd_frequency`` 50): it is
    accepted, the gateway pushes at 30 Hz and says so in the reply's ``output`` (:class:`DrcModeEnterReply`).
    0 and negative rates are refused.
    """

    mqtt_broker: MqttBroker
    osd_frequency: Frequency = Field(
        description=f"osd_info_push rate, 1..{MAX_PUSH_FREQUENCY} Hz; more is pushed at {MAX_PUSH_FREQUENCY}."
    )
    hsi_frequency: Frequency = Field(
        description=f"hsi_info_push rate, 1..{MAX_PUSH_FREQUENCY} Hz; more is pushed at {MAX_PUSH_FREQUENCY}."
    )


class DrcModeEnterOutput(OutboundModel):
    """``output`` of the ``drc_mode_enter`` reply: ``reason`` on failure; on success the push rates actually
    used when the request asked for more than the device can do (absent when used as asked)."""

    reason: Reason | None = None
    osd_frequency: Annotated[int, Field(strict=True, ge=1, le=MAX_PUSH_FREQUENCY)] | None = None
    hsi_frequency: Annotated[int, Field(strict=True, ge=1, le=MAX_PUSH_FREQUENCY)] | None = None


class DrcModeEnterReply(OutboundModel):
    """``data`` of the ``drc_mode_enter`` reply: ``result``, and ``output`` (rates used, or why not)."""

    result: ResultValue
    output: DrcModeEnterOutput | None = None


class DrcModeExit(EmptyRequest):
    """Leave live flight control (seed 003 § Exit the live flight controls mode). No parameters."""


class SimulateMission(InboundModel):
    """DJI's simulated flight (Java Cloud SDK ``SimulateMission``): fly in the simulator at lat/lon."""

    is_enable: IntEnumField[SimulateSwitch] = Field(description="0: off, 1: on")
    latitude: Latitude
    longitude: Longitude


class TakeoffToPoint(InboundModel):
    """One-key take-off to a target point (seed 003 § One-key taking off).

    ``rc_lost_action`` and ``exit_wayline_when_rc_lost`` are in the table but not in the seed's example, so
    they are optional (absent: the device keeps its configured behaviour). The other seed fields are
    required. Ranges and the ``flight_id`` pattern are DJI's Java Cloud SDK's (TakeoffToPointRequest), which
    also sends ``rth_mode``, ``commander_mode_lost_action``, ``commander_flight_mode``,
    ``commander_flight_height`` and ``simulate_mission`` (Cloud API 1.x): accepted here, optional; what a
    device does with each (or refuses) is its adapter's business and is documented per family.
    """

    target_latitude: Latitude
    target_longitude: Longitude
    target_height: TargetHeight = Field(description="WGS84 altitude of the target (m). Hover on arrival.")
    security_takeoff_height: Float = Field(
        ge=20,
        le=1500,
        description="Climb to this height above the take-off point first (m).",
        json_schema_extra={"x-unit": "m"},
    )
    rth_altitude: Int = Field(
        ge=2,
        le=1500,
        description="Return-to-home height above the take-off point (m).",
        json_schema_extra={"x-unit": "m"},
    )
    rc_lost_action: IntEnumField[RcLostAction] | None = Field(default=None, description=_RC_LOST)
    exit_wayline_when_rc_lost: IntEnumField[ExitWaylineWhenRcLost] | None = Field(
        default=None, description=_EXIT_WAYLINE
    )
    flight_id: TaskId = Field(description='Task UUID of this take-off (no . _ < > : " / \\ | ? *).')
    max_speed: Int = Field(
        ge=1, le=15, description="Maximum speed (m/s).", json_schema_extra={"x-unit": "m/s"}
    )
    rth_mode: IntEnumField[RthMode] | None = Field(default=None, description=_RTH_MODE)
    commander_mode_lost_action: IntEnumField[CommanderModeLostAction] | None = Field(
        default=None, description=_COMMANDER_LOST
    )
    commander_flight_mode: IntEnumField[CommanderFlightMode] | None = Field(
        default=None, description=_COMMANDER_MODE
    )
    commander_flight_height: Float | None = Field(
        default=None,
        ge=2,
        le=3000,
        description="Flight height above the take-off point in fixed-height commander mode (m).",
        json_schema_extra={"x-unit": "m"},
    )
    simulate_mission: SimulateMission | None = Field(default=None, description="DJI's simulated flight.")


class FlyToPointTarget(InboundModel):
    """One fly-to target: WGS84 degrees and altitude (m).

    Heights here and in take-off: 2..10000 m as DJI's Java Cloud SDK validates them (Point.height; the
    aircraft's own limit is checked by its adapter); the seed's step 0.1 is display precision and is not
    enforced (binary floats are not multiples of 0.1).
    """

    latitude: Latitude
    longitude: Longitude
    height: TargetHeight = Field(description="WGS84 altitude (m).")


class FlyToPoint(InboundModel):
    """Fly to a target point (seed 003 § flyto target point).

    Seed contradiction: the table says "Only one target point is supported" but the example sends two
    (identical) points. Decision, as DJI's Java Cloud SDK (FlyToPointRequest: ``@Size(min = 1)``, "the M30
    series only support one point"): at least one point, no maximum in the contract; the device flies them
    in order and the last one is the target, and a device refuses more than it can fly (325001, the Onboard
    SDK aircraft above 254). ``max_speed`` 1..15 and the ``fly_to_id`` pattern are the Java SDK's (the seed's
    minimum 0 cannot fly).
    """

    fly_to_id: TaskId = Field(description='Target point (task) id (no . _ < > : " / \\ | ? *).')
    max_speed: Int = Field(
        ge=1, le=15, description="Maximum speed (m/s).", json_schema_extra={"x-unit": "m/s"}
    )
    points: list[FlyToPointTarget] = Field(min_length=1)


class FlyToPointStop(EmptyRequest):
    """End the fly-to task (seed 003 § End the task of flying to target point). No parameters."""


class CameraModeSwitch(PayloadRequest):
    """Switch the camera mode (seed 003 § switch the camera mode)."""

    camera_mode: IntEnumField[CameraMode] = Field(description=_CAMERA_MODE)


class CameraPhotoTake(PayloadRequest):
    """Take one photo (seed 003 § take single photo)."""


class CameraRecordingStart(PayloadRequest):
    """Start recording (seed 003 § start recording)."""


class CameraRecordingStop(PayloadRequest):
    """Stop recording (seed 003 § stop recording)."""


class CameraScreenDrag(PayloadRequest):
    """Drag the camera view: gimbal speeds (seed 003 § drag screen). ``yaw_speed`` only acts when not locked.

    The seed gives a unit (°/s) but no range; ±360 °/s is the R SDK gimbal's own maximum, so a garbage value
    is refused instead of slewing a gimbal at full speed.
    """

    locked: Bool = Field(description="true: the aircraft body turns with the gimbal; false: only the gimbal.")
    pitch_speed: Float = Field(
        ge=-360, le=360, description="Gimbal pitch speed (°/s).", json_schema_extra={"x-unit": "°/s"}
    )
    yaw_speed: Float = Field(
        ge=-360,
        le=360,
        description="Gimbal yaw speed (°/s); only when not locked.",
        json_schema_extra={"x-unit": "°/s"},
    )


class CameraAim(PayloadRequest):
    """Double-tap to aim: the point (x, y) of the view becomes its centre (seed 003 § double tab to AIM).

    x and y are fractions of the view from its upper-left corner, 0..1.
    """

    camera_type: CameraTypeField
    locked: Bool = Field(description="true: the aircraft body turns with the gimbal; false: only the gimbal.")
    x: Float = Field(ge=0, le=1, description="Horizontal position, 0 (left) .. 1 (right).")
    y: Float = Field(ge=0, le=1, description="Vertical position, 0 (top) .. 1 (bottom).")


#: The seed's zoom limits: visible light 2..200, infrared 2..20.
MAX_IR_ZOOM = 20


class CameraFocalLengthSet(PayloadRequest):
    """Set the zoom factor (seed 003 § zoom). 2..200 for visible light; 2..20 when ``camera_type`` is ir."""

    camera_type: CameraTypeField
    zoom_factor: Float = Field(ge=2, le=200, description="Zoom factor: 2..200 (visible), 2..20 (infrared).")

    @model_validator(mode="after")
    def _ir_limit(self) -> CameraFocalLengthSet:
        if self.camera_type is CameraType.IR and self.zoom_factor > MAX_IR_ZOOM:
            raise ValueError(f"zoom_factor for an ir camera must be at most {MAX_IR_ZOOM}")
        return self


class GimbalReset(PayloadRequest):
    """Reset the gimbal (seed 003 § reset the gimbal)."""

    reset_mode: IntEnumField[GimbalResetMode] = Field(description=_RESET_MODE)
