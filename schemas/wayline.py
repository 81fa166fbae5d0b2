"""``data`` of the Cloud API wayline (route) methods a dock-like gateway serves: the flighttask_* services,
return_home / return_home_cancel, the flighttask_progress / flighttask_ready / return_home_info events and
the flighttask_resource_get request (device → cloud on ``requests``, answered on ``requests_reply``).

Owns their fields, ranges and enums as DJI's dock pages and reference cloud define them
(/work/shared/WAYLINE-NOTES.md §3–§5; citation keys in brackets). Knows nothing about KMZ files, flight
controllers or when a device emits what.

Tolerance where the notes say clouds differ: ``wayline_type`` is accepted with any integer (dropped from
the docs after v1.7, still sent 0–3 by the Demo, §8.9); services without parameters take ``{}``, ``""``,
``null`` or no ``data`` (``envelope.EmptyRequest``); the fingerprint is compared in lowercase (§6).
"""

from __future__ import annotations

import enum
from typing import Annotated

from pydantic import Field, StringConstraints, model_validator

from .base import Float, InboundModel, Int, IntEnumField, Latitude, Longitude, OutboundModel, Reason, Text
from .envelope import EmptyRequest
from .results import ResultValue
from .services import ExitWaylineWhenRcLost, RthMode  # the same enums as takeoff_to_point's

#: ``flight_id``: the SDK's regex ``^[^<>:"/|?*._\\]+$`` [SDK:FlighttaskPrepareRequest].
FlightId = Annotated[
    str, StringConstraints(strict=True, min_length=1, max_length=128, pattern=r'^[^<>:"/|?*._\\]+$')
]
#: Milliseconds since the epoch, 13 digits (the SDK's ``@Min(123456789012)``).
ExecuteTime = Annotated[int, Field(strict=True, ge=123456789012, le=9_999_999_999_999)]


class TaskType(enum.IntEnum):
    IMMEDIATE = 0
    TIMED = 1
    CONDITIONAL = 2


class OutOfControlAction(enum.IntEnum):
    RETURN_HOME = 0
    HOVER = 1
    LAND = 2


class PrecisionType(enum.IntEnum):
    GPS = 0
    RTK = 1


class BreakPointState(enum.IntEnum):
    ON_SEGMENT = 0
    ON_WAYPOINT = 1


class FlighttaskStatus(enum.StrEnum):
    """``flighttask_progress.status`` [D2]; terminal: ok, rejected, failed, canceled, timeout,
    partially_done."""

    SENT = "sent"
    IN_PROGRESS = "in_progress"
    PAUSED = "paused"
    OK = "ok"
    PARTIALLY_DONE = "partially_done"
    REJECTED = "rejected"
    FAILED = "failed"
    CANCELED = "canceled"
    TIMEOUT = "timeout"


TERMINAL_STATUSES = frozenset(
    {
        FlighttaskStatus.OK,
        FlighttaskStatus.PARTIALLY_DONE,
        FlighttaskStatus.REJECTED,
        FlighttaskStatus.FAILED,
        FlighttaskStatus.CANCELED,
        FlighttaskStatus.TIMEOUT,
    }
)


class WaylineMissionState(enum.IntEnum):
    """``ext.wayline_mission_state`` [D2][SDK:WaylineMissionStateEnum]."""

    DISCONNECTED = 0
    NOT_SUPPORTED = 1
    READY = 2
    UPLOADING = 3
    TRIGGERED = 4
    ENTERING = 5
    EXECUTING = 6
    INTERRUPTED = 7
    RECOVERING = 8
    FINISHED = 9


# ----------------------------------------------------------------------------------------------- services


class WaylineFile(InboundModel):
    """Where the KMZ is and its MD5 (32 hex digits of the file's bytes; compared in lowercase)."""

    url: Annotated[str, StringConstraints(strict=True, min_length=1, max_length=8192)] = Field(
        description="Download URL of the KMZ (usually a pre-signed object-storage URL)."
    )
    fingerprint: Annotated[str, StringConstraints(strict=True, max_length=64)] = Field(
        description="MD5 of the KMZ file's bytes, lowercase hex (empty: 314002 md5 empty)."
    )


class ReadyConditions(InboundModel):
    battery_capacity: Int = Field(ge=0, le=100, description="Battery % must be above this.")
    begin_time: Int = Field(
        ge=0, description="Start no earlier than this (ms).", json_schema_extra={"x-unit": "ms"}
    )
    end_time: Int = Field(
        ge=0, description="Start no later than this (ms).", json_schema_extra={"x-unit": "ms"}
    )


class ExecutableConditions(InboundModel):
    storage_capacity: Int = Field(
        ge=0, description="Minimum free storage (MB).", json_schema_extra={"x-unit": "MB"}
    )


class BreakPoint(InboundModel):
    """Where an interrupted task stopped (from its last progress ``ext.break_point``)."""

    index: Int = Field(ge=0, le=65535, description="Waypoint (state 1) or segment (state 0) index.")
    state: IntEnumField[BreakPointState] = Field(description="0: on a segment, 1: on a waypoint.")
    progress: Float = Field(ge=0, le=1, description="Progress along the segment, 0..1.")
    wayline_id: Int = Field(ge=0, le=65535, description="wpml:waylineId of the Folder.")


class SimulateMission(InboundModel):
    is_enable: Int = Field(ge=0, le=1)
    latitude: Latitude
    longitude: Longitude


class FlighttaskPrepare(InboundModel):
    """Issue a wayline task (WAYLINE-NOTES §3.1). ``ready_conditions`` is required for conditional tasks."""

    flight_id: FlightId = Field(description="Task id (the reference cloud sends bid = flight_id).")
    execute_time: ExecuteTime | None = Field(default=None, description="When to start (ms since the epoch).")
    task_type: IntEnumField[TaskType] = Field(description="0: immediate, 1: timed, 2: conditional.")
    wayline_type: Int | None = Field(
        default=None, description="0 waypoint, 1 mapping2d, 2 mapping3d, 3 strip."
    )
    file: WaylineFile
    ready_conditions: ReadyConditions | None = None
    executable_conditions: ExecutableConditions | None = None
    break_point: BreakPoint | None = None
    rth_altitude: Int | None = Field(
        default=None,
        ge=20,
        le=1500,
        description="Return-to-home height (m).",
        json_schema_extra={"x-unit": "m"},
    )
    rth_mode: IntEnumField[RthMode] | None = Field(
        default=None, description="0 optimal height, 1 preset height."
    )
    out_of_control_action: IntEnumField[OutOfControlAction] | None = Field(
        default=None, description="0: return home, 1: hover, 2: land."
    )
    exit_wayline_when_rc_lost: IntEnumField[ExitWaylineWhenRcLost] | None = Field(
        default=None, description="0: continue the wayline, 1: exit and do the RC-lost action."
    )
    wayline_precision_type: IntEnumField[PrecisionType] | None = Field(
        default=None, description="0 GPS, 1 RTK."
    )
    simulate_mission: SimulateMission | None = None
    flight_safety_advance_check: Int | None = Field(default=None, ge=0, le=1)

    @model_validator(mode="after")
    def _conditions(self) -> FlighttaskPrepare:
        # [D1][D2]: execute_time is required for immediate and timed tasks, ready_conditions for conditional
        if self.task_type in (TaskType.IMMEDIATE, TaskType.TIMED) and self.execute_time is None:
            raise ValueError("execute_time is required when task_type is 0 (immediate) or 1 (timed)")
        if self.task_type == TaskType.CONDITIONAL and self.ready_conditions is None:
            raise ValueError("ready_conditions is required when task_type is 2 (conditional)")
        return self


class FlighttaskExecute(InboundModel):
    """Start a prepared task (§3.2)."""

    flight_id: FlightId


class FlighttaskUndo(InboundModel):
    """Cancel prepared tasks that have not started (§3.3)."""

    flight_ids: list[FlightId] = Field(min_length=1, max_length=64)


class FlighttaskPause(EmptyRequest):
    """Pause the running wayline (§3.4). No parameters (the reference cloud sends ``"data": ""``)."""


class FlighttaskRecovery(EmptyRequest):
    """Resume the paused wayline from its break point (§3.4). No parameters."""


class ReturnHome(EmptyRequest):
    """Return to home (§3.5). No parameters."""


class ReturnHomeCancel(EmptyRequest):
    """Cancel the return to home: the aircraft hovers (§3.5). No parameters."""


class PrepareOutput(OutboundModel):
    """``output`` of the flighttask_prepare reply: a failure's ``reason``, or (accepted) the route's actions
    the aircraft cannot carry out and will skip (extension; ``wayline.strict_actions`` refuses them)."""

    reason: Reason | None = Field(default=None, description="Why the request failed, for a human.")
    x_skipped_actions: list[Reason] | None = Field(
        default=None, description="Extension. The route's WPML actions the aircraft will skip, each named."
    )


class FlighttaskPrepareReply(OutboundModel):
    """``data`` of the flighttask_prepare reply (the services reply's ``result`` and ``output``)."""

    result: ResultValue
    output: PrepareOutput | None = None


# ------------------------------------------------------------------------------------------------- events


class ProgressBreakPoint(OutboundModel):
    index: Int = Field(ge=0, le=65535)
    state: IntEnumField[BreakPointState]
    progress: Float = Field(ge=0, le=1)
    wayline_id: Int = Field(ge=0, le=65535)
    break_reason: Int = Field(ge=0, le=65535, description="Why the task stopped (WAYLINE-NOTES §4.1).")
    latitude: Latitude
    longitude: Longitude
    height: Float = Field(description="Ellipsoid height (m).", json_schema_extra={"x-unit": "m"})
    attitude_head: Float = Field(ge=-180, le=180, description="Yaw vs true north (°).")


class ProgressExt(OutboundModel):
    flight_id: Text
    wayline_id: Int = Field(ge=0, le=65535, description="Folder waylineId; 65535 before a wayline starts.")
    current_waypoint_index: Int = Field(ge=0, description="Waypoints of the wayline executed so far.")
    wayline_mission_state: IntEnumField[WaylineMissionState]
    media_count: Int = Field(ge=0, description="Media files this task produced.")
    track_id: Text = ""
    break_point: ProgressBreakPoint | None = None
    x_reason: Reason | None = Field(
        default=None, description="Extension. Why the task failed, for a human (`result` has the code)."
    )
    x_skipped_actions: list[Reason] | None = Field(
        default=None,
        description="Extension. The route's WPML actions the aircraft cannot carry out (skipped).",
    )


class ProgressSteps(OutboundModel):
    current_step: Int = Field(ge=0, le=65535, description="Execution step (Dock 2 numbering).")
    percent: Int = Field(ge=0, le=100)


class ProgressOutput(OutboundModel):
    ext: ProgressExt
    progress: ProgressSteps
    status: FlighttaskStatus


class FlighttaskProgress(OutboundModel):
    """Task progress (§4.1): sent with ``bid = flight_id`` and ``need_reply: 1``."""

    result: ResultValue
    output: ProgressOutput


class FlighttaskReady(OutboundModel):
    """Conditional tasks whose ready_conditions are met (§4.2)."""

    flight_ids: list[Text] = Field(min_length=1)


class PathPoint(OutboundModel):
    latitude: Latitude
    longitude: Longitude
    height: Float = Field(description="Ellipsoid height (m).", json_schema_extra={"x-unit": "m"})


class ReturnHomeInfo(OutboundModel):
    """The planned way home, a full replacement each time (§4.3)."""

    planned_path_points: list[PathPoint]
    last_point_type: Int = Field(ge=0, le=1, description="0: the last point is above home, 1: it is not.")
    flight_id: Text


# ----------------------------------------------------------------------------------------------- requests


class FlighttaskResourceGet(OutboundModel):
    """Ask the cloud for a fresh KMZ URL of a task (§5.1)."""

    flight_id: Text


class ResourceOutput(InboundModel):
    file: WaylineFile | None = None  # absent when the cloud answers with an error


class FlighttaskResourceGetReply(InboundModel):
    """The cloud's answer: ``{"result": 0, "output": {"file": {"url", "fingerprint"}}}``."""

    result: Int
    output: ResourceOutput | None = None


__all__ = [
    "TERMINAL_STATUSES",
    "BreakPoint",
    "FlighttaskExecute",
    "FlighttaskPause",
    "FlighttaskPrepare",
    "FlighttaskPrepareReply",
    "FlighttaskProgress",
    "FlighttaskReady",
    "FlighttaskRecovery",
    "FlighttaskResourceGet",
    "FlighttaskResourceGetReply",
    "FlighttaskStatus",
    "FlighttaskUndo",
    "PrepareOutput",
    "ReturnHome",
    "ReturnHomeCancel",
    "ReturnHomeInfo",
    "WaylineFile",
    "WaylineMissionState",
]
