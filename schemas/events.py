"""``data`` of the events in seed 003 (gateway → cloud on ``events``); the cloud answers on events_reply
with ``envelope.InboundResult``.

Owns fly-to / take-off progress, DRC link state and the joystick-invalid reason. Knows nothing about when
a device emits them.
"""

from __future__ import annotations

import enum
from typing import Annotated

from pydantic import Field

from .base import Float, Int, IntEnumField, Latitude, Longitude, OutboundModel, Reason, Text, enum_description
from .results import ResultValue
from .state import DrcState, DrcStateField


class FlyToStatus(enum.StrEnum):
    PROGRESS = "wayline_progress"
    FAILED = "wayline_failed"
    OK = "wayline_ok"
    CANCEL = "wayline_cancel"


class TakeoffStatus(enum.StrEnum):
    TASK_READY = "task_ready"
    PROGRESS = "wayline_progress"
    FAILED = "wayline_failed"
    OK = "wayline_ok"
    CANCEL = "wayline_cancel"
    TASK_FINISH = "task_finish"


class JoystickInvalidReason(enum.IntEnum):
    RC_DISCONNECTED = 0
    LOW_POWER_RETURN_HOME = 1
    LOW_POWER_LANDING = 2
    NEAR_GEO_ZONE = 3
    AUTHORITY_GRABBED = 4


_FLY_TO_STATUS = (
    "wayline_progress: executing, wayline_failed: failed, wayline_ok: arrived at the target point, "
    "wayline_cancel: cancelled"
)
_TAKEOFF_STATUS = "task_ready: ready to take off, " + _FLY_TO_STATUS + ", task_finish: take-off task finished"
_JOYSTICK = enum_description(
    JoystickInvalidReason,
    {
        JoystickInvalidReason.RC_DISCONNECTED: "Remote controller is disconnected",
        JoystickInvalidReason.LOW_POWER_RETURN_HOME: "Low-power return-to-home",
        JoystickInvalidReason.LOW_POWER_LANDING: "Low-power landing",
        JoystickInvalidReason.NEAR_GEO_ZONE: "Approach GEO zone",
        JoystickInvalidReason.AUTHORITY_GRABBED: "Authority grabbed by the remote controller",
    },
)


Remaining = Annotated[float, Field(strict=True, allow_inf_nan=False, ge=0)]


class PathPoint(OutboundModel):
    """One point of ``planned_path_points`` (DJI Cloud API docs, Dock 3 § flyto result event)."""

    latitude: Latitude
    longitude: Longitude
    height: Float = Field(description="Ellipsoid (WGS84) height (m).", json_schema_extra={"x-unit": "m"})


class FlyToPointProgress(OutboundModel):
    """Fly-to progress (seed 003 § Event notification of flyto result; ``remaining_distance``,
    ``remaining_time`` and ``planned_path_points`` from DJI's newer docs, Dock 3 § flyto result event,
    docs/cloud-api.md). Sent at each point, at the end, and periodically (at least once a second) while
    the aircraft flies."""

    fly_to_id: Text = Field(min_length=1, description="The fly_to_id of the fly_to_point request.")
    status: FlyToStatus = Field(description=_FLY_TO_STATUS)
    result: ResultValue
    way_point_index: Int = Field(ge=0, description="Index of the point being flown.")
    remaining_distance: Remaining | None = Field(
        default=None, description="Distance left to fly (m).", json_schema_extra={"x-unit": "m"}
    )
    remaining_time: Remaining | None = Field(
        default=None, description="Time left at the planned speed (s).", json_schema_extra={"x-unit": "s"}
    )
    planned_path_points: list[PathPoint] | None = Field(
        default=None, description="The points being flown to, as requested (DJI: no size limit)."
    )
    x_reason: Reason | None = Field(
        default=None,
        description="Extension. Why the task failed, for a human (failure events; `result` is the code).",
    )


class TakeoffToPointProgress(OutboundModel):
    """One-key take-off progress (seed 003 § Event notification of one-key taking off result;
    ``remaining_distance`` and ``remaining_time`` as DJI's newer docs define them for the flyto event, Dock
    2/3 § DRC, docs/cloud-api.md). The gateway sends ``task_ready``, ``wayline_progress`` (at each point and
    periodically), one terminal status (``wayline_ok``, ``wayline_failed`` or ``wayline_cancel``) and then
    ``task_finish`` with the same ``result``, in every path."""

    status: TakeoffStatus = Field(description=_TAKEOFF_STATUS)
    result: ResultValue
    flight_id: Text = Field(min_length=1, description="The flight_id of the takeoff_to_point request.")
    track_id: Text = Field(description="Wayline track id (may be empty).")
    way_point_index: Int = Field(ge=0, description="Index of the point being flown.")
    remaining_distance: Remaining | None = Field(
        default=None, description="Distance left to fly (m).", json_schema_extra={"x-unit": "m"}
    )
    remaining_time: Remaining | None = Field(
        default=None, description="Time left at the planned speed (s).", json_schema_extra={"x-unit": "s"}
    )
    x_reason: Reason | None = Field(
        default=None,
        description="Extension. Why the task failed, for a human (failure events; `result` is the code).",
    )


class DrcStatusNotify(OutboundModel):
    """DRC link state (seed 003 § Notification of DRC link state); result 5143xx on link errors."""

    result: ResultValue
    drc_state: DrcStateField


class JoystickInvalidNotify(OutboundModel):
    """Why stick control stopped working (seed 003 § Reason notification of invalid Joystick control)."""

    reason: IntEnumField[JoystickInvalidReason] = Field(description=_JOYSTICK)


__all__ = [
    "DrcState",
    "DrcStatusNotify",
    "FlyToPointProgress",
    "FlyToStatus",
    "JoystickInvalidNotify",
    "JoystickInvalidReason",
    "PathPoint",
    "TakeoffStatus",
    "TakeoffToPointProgress",
]
