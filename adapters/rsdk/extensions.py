"""Extension services for what an R SDK gimbal can do and the Cloud API cannot name.

Method names are ``x_rsdk_<name>`` (the contract's extension prefix); each has a request model and
a reply model here, registered into the gateway's registry at start-up so they are validated,
exported to JSON Schema/AsyncAPI and routed like any seed method (by ``payload_index``). Units are
the Cloud API's (degrees, seconds), not the wire's; the adapter converts.
"""

from __future__ import annotations

import enum
from typing import Annotated

from pydantic import Field

from schemas.base import Bool, Float, Int, IntEnumField, OutboundModel
from schemas.envelope import ErrorOutput, ResultReply
from schemas.results import ResultValue
from schemas.services import PayloadRequest

__all__ = ["EXTENSIONS"]

U8Angle = Annotated[int, Field(strict=True, ge=0)]


class LimitAngles(PayloadRequest):
    """Set the user limit angles (seed 000 §2.3.4.4), degrees from centre per direction."""

    pitch_max: U8Angle = Field(le=145)
    pitch_min: U8Angle = Field(le=55)
    yaw_max: U8Angle = Field(le=179)
    yaw_min: U8Angle = Field(le=179)
    roll_max: U8Angle = Field(le=30)
    roll_min: U8Angle = Field(le=30)


class LimitAnglesOut(OutboundModel):
    pitch_max: Int
    pitch_min: Int
    yaw_max: Int
    yaw_min: Int
    roll_max: Int
    roll_min: Int


class LimitAnglesReply(OutboundModel):
    result: ResultValue
    output: LimitAnglesOut | ErrorOutput | None = None


Pct = Annotated[int, Field(strict=True, ge=0, le=100)]


class Stiffness(PayloadRequest):
    """Set the motor stiffness per axis, 0..100 (seed 000 §2.3.4.6)."""

    pitch: Pct
    roll: Pct
    yaw: Pct


class StiffnessOut(OutboundModel):
    pitch: Int
    roll: Int
    yaw: Int


class StiffnessReply(OutboundModel):
    result: ResultValue
    output: StiffnessOut | ErrorOutput | None = None


class FollowMode(enum.IntEnum):
    """Seed 000 §2.3.4.15 (Figure 28): 0 lock, 2 yaw follow, 3 sport."""

    LOCK = 0
    YAW_FOLLOW = 2
    SPORT = 3


class FollowModeSet(PayloadRequest):
    mode: IntEnumField[FollowMode] = Field(description="0 lock, 2 yaw follow, 3 sport")


class GimbalPosition(PayloadRequest):
    """Move to (or by) angles in degrees over ``duration`` seconds (seed 000 §2.3.4.1)."""

    yaw: Float | None = Field(default=None, ge=-180, le=180)
    roll: Float | None = Field(default=None, ge=-30, le=30)
    pitch: Float | None = Field(default=None, ge=-56, le=146)
    absolute: Bool = True
    duration: Float = Field(default=1.0, ge=0.1, le=25.5, description="seconds (0.1 s steps)")


class FocusPosition(PayloadRequest):
    """Focus motor absolute position 0..4095 (seed 000 §2.3.4.19, sub-command 0x01; no reply frame)."""

    position: Annotated[int, Field(strict=True, ge=0, le=4095)]


class AutoCalibration(PayloadRequest):
    """Start or stop the gimbal's control-parameter self-tuning (seed 000 §2.3.4.16)."""

    start: Bool


class AngleGet(PayloadRequest):
    """Read the gimbal's angles with 0x0E 0x02 (seed 000 §2.3.4.3): attitude (default) or joint angles."""

    joint: Bool = Field(default=False, description="false: attitude angles (0x01); true: joint angles (0x02)")


class AngleOut(OutboundModel):
    kind: str = Field(description="attitude or joint (the reply's data_type)")
    yaw: Float
    roll: Float
    pitch: Float


class AngleReply(OutboundModel):
    result: ResultValue
    output: AngleOut | ErrorOutput | None = None


class VersionOut(OutboundModel):
    device_id: Int
    version: str


class VersionReply(OutboundModel):
    result: ResultValue
    output: VersionOut | ErrorOutput | None = None


#: (method, request model, reply model, summary) — registered on ``services`` by the composition root.
EXTENSIONS: tuple[tuple[str, type[PayloadRequest], type[OutboundModel], str], ...] = (
    ("x_rsdk_limit_angle_set", LimitAngles, ResultReply, "R SDK: set the gimbal's user limit angles"),
    ("x_rsdk_limit_angle_get", PayloadRequest, LimitAnglesReply, "R SDK: read the user limit angles"),
    ("x_rsdk_stiffness_set", Stiffness, ResultReply, "R SDK: set motor stiffness per axis"),
    ("x_rsdk_stiffness_get", PayloadRequest, StiffnessReply, "R SDK: read motor stiffness"),
    ("x_rsdk_follow_mode_set", FollowModeSet, ResultReply, "R SDK: lock / yaw follow / sport mode"),
    ("x_rsdk_position_set", GimbalPosition, ResultReply, "R SDK: move to or by angles over a duration"),
    ("x_rsdk_selfie", PayloadRequest, ResultReply, "R SDK: turn the gimbal around for a selfie"),
    ("x_rsdk_active_track_toggle", PayloadRequest, ResultReply, "R SDK: start or stop ActiveTrack"),
    ("x_rsdk_focus_set", FocusPosition, ResultReply, "R SDK: focus motor absolute position"),
    ("x_rsdk_auto_calibration", AutoCalibration, ResultReply, "R SDK: start or stop self-tuning"),
    ("x_rsdk_version_get", PayloadRequest, VersionReply, "R SDK: gimbal firmware version"),
    ("x_rsdk_angle_get", AngleGet, AngleReply, "R SDK: read attitude or joint angles (0x0E 0x02)"),
)
