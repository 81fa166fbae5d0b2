"""Extension services and events for a RoboMaster robot, which the Cloud API cannot name.

Services (``x_robomaster_<name>``, cloud → gateway) drive the robot through the gateway's control
messages (``adapters.robomaster.commands``) and relay 0x0301 robot interaction data; events
(gateway → cloud) carry the referee's warnings (0x0104) and hurt reports (0x0206). Every model is
registered into the gateway's registry at start-up, so it is validated, exported to JSON Schema and
AsyncAPI, and routed like a seed method: by ``sn`` when given, else to the first robot.

Units are the cloud's (degrees, m/s, rad/s, seconds); the adapter converts degrees to the wire's
radians. Directions follow the control wire contract (REP-103): vx forward, vy left, wz and the
gimbal yaw counter-clockwise seen from above, pitch up positive.
"""

from __future__ import annotations

import enum
from typing import Annotated

from pydantic import Field, StringConstraints

from schemas.base import Float, InboundModel, Int, OutboundModel, SerialNumber, enum_description
from schemas.envelope import InboundResult, ResultReply

__all__ = [
    "EVENT_EXTENSIONS",
    "EXTENSIONS",
    "ChassisVelocity",
    "GimbalAngle",
    "HurtEvent",
    "Interaction",
    "RefereeWarningEvent",
    "RobotRequest",
]


class RobotRequest(InboundModel):
    """A request for one robot: ``sn`` picks it (the dispatcher routes by ``data.sn``)."""

    sn: SerialNumber | None = Field(default=None, description="The robot's sn; default: the first robot.")


class ChassisVelocity(RobotRequest):
    """Chassis velocity set-point in the body frame, kept for ``duration`` seconds, then zero."""

    vx: Float = Field(ge=-10, le=10, description="Forward speed (m/s).", json_schema_extra={"x-unit": "m/s"})
    vy: Float = Field(
        default=0.0, ge=-10, le=10, description="Leftward speed (m/s).", json_schema_extra={"x-unit": "m/s"}
    )
    wz: Float = Field(
        default=0.0,
        ge=-30,
        le=30,
        description="Yaw rate, counter-clockwise seen from above (rad/s).",
        json_schema_extra={"x-unit": "rad/s"},
    )
    duration: Float | None = Field(
        default=None,
        gt=0,
        le=10,
        description="Seconds the set-point lasts (the gateway resends it); default: the device's hold. "
        "A new request replaces it.",
        json_schema_extra={"x-unit": "s"},
    )


class GimbalAngle(RobotRequest):
    """Absolute gimbal set-point, degrees from the gimbal's calibrated zero."""

    yaw: Float = Field(
        ge=-180,
        le=180,
        description="Yaw (°), counter-clockwise seen from above.",
        json_schema_extra={"x-unit": "°"},
    )
    pitch: Float = Field(
        ge=-90, le=90, description="Pitch (°), positive raises the barrel.", json_schema_extra={"x-unit": "°"}
    )


#: 0x0301 sub-commands: DJI's (client UI, sentry/radar decisions) from 0x0100, students' 0x0200-0x02FF.
DataCmdId = Annotated[int, Field(strict=True, ge=0x0100, le=0x02FF)]
HexBytes = Annotated[
    str, StringConstraints(strict=True, pattern=r"^(?:[0-9A-Fa-f]{2}){0,112}$", max_length=224)
]


class Interaction(RobotRequest):
    """Send 0x0301 robot interaction data; the sender id is the robot's own (the referee requires it)."""

    data_cmd_id: DataCmdId = Field(
        description="0x0301 sub-command: 0x0100-0x01FF DJI's (client UI, decisions), 0x0200-0x02FF students'."
    )
    receiver_id: Int = Field(
        ge=1, le=0xFFFF, description="Robot id (1-11, 101-111), client id (0x0101-0x016A) or 0x8080 server."
    )
    data: HexBytes = Field(description="User data as hex, at most 112 bytes.")


class WarningLevel(enum.IntEnum):
    BOTH_YELLOW = 1
    YELLOW = 2
    RED = 3
    FORFEIT = 4


_LEVEL = enum_description(
    WarningLevel,
    {
        WarningLevel.BOTH_YELLOW: "yellow card to both sides",
        WarningLevel.YELLOW: "yellow card",
        WarningLevel.RED: "red card",
        WarningLevel.FORFEIT: "forfeit",
    },
)

U8 = Annotated[int, Field(strict=True, ge=0, le=255)]


class RefereeWarningEvent(OutboundModel):
    """A referee penalty against the robot's side (0x0104), once per distinct report."""

    level: U8 = Field(description=_LEVEL + " (other values passed through).")
    offending_robot_id: U8 = Field(description="The penalised robot (0 when the penalty names none).")
    count: U8 = Field(description="That robot's violations at this level.")
    robot_id: U8 | None = Field(default=None, description="Our robot's referee id, when known.")


class HurtEvent(OutboundModel):
    """The robot lost HP (0x0206), one event per referee report."""

    armor_id: Annotated[int, Field(strict=True, ge=0, le=15)] = Field(
        description="Armour or module id that took the damage."
    )
    hp_deduction_reason: Annotated[int, Field(strict=True, ge=0, le=15)] = Field(
        description="The referee's HP_deduction_reason (V1.6.1: 0 projectile, 1 module offline, "
        "2 over-speed, 3 over-heat, 4 over-power, 5 collision); later appendices define their own values."
    )
    robot_id: U8 | None = Field(default=None, description="Our robot's referee id, when known.")


#: (method, request model, reply model, summary) — registered on ``services`` by the composition root.
EXTENSIONS: tuple[tuple[str, type[InboundModel], type[OutboundModel], str], ...] = (
    (
        "x_robomaster_chassis_velocity",
        ChassisVelocity,
        ResultReply,
        "RoboMaster: chassis velocity set-point for a duration",
    ),
    ("x_robomaster_gimbal_angle", GimbalAngle, ResultReply, "RoboMaster: absolute gimbal yaw/pitch"),
    ("x_robomaster_stop", RobotRequest, ResultReply, "RoboMaster: stop the chassis, hold the gimbal"),
    ("x_robomaster_interaction", Interaction, ResultReply, "RoboMaster: send 0x0301 robot interaction data"),
)

#: (method, event data model, events_reply model, summary) — registered on ``events``.
EVENT_EXTENSIONS: tuple[tuple[str, type[OutboundModel], type[InboundModel], str], ...] = (
    ("x_robomaster_referee_warning", RefereeWarningEvent, InboundResult, "RoboMaster: referee penalty"),
    ("x_robomaster_hurt", HurtEvent, InboundResult, "RoboMaster: the robot lost HP"),
)
