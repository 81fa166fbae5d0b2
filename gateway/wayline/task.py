"""The wayline task state machine: every Cloud API wayline task by ``flight_id``, what each service does
to it, and the ``flighttask_progress`` body it reports.

Sans-I/O (like ``gateway/drc_session.py``): events in (a service, a step of the run, a waypoint reached,
the end, a clock value), values out (a :class:`Verdict` for the reply, whether a run must start or stop,
the progress body). No sockets, threads, clocks or asyncio; ``gateway/wayline/service.py`` does the I/O.
Knows nothing of MQTT, KMZ bytes or flight controllers.

Theory of operation. A task is *prepared* (``flighttask_prepare``; repeating it with the same flight_id
is answered like the first: the reference cloud resends with a new tid, WAYLINE-NOTES §1), then
*executed* (``flighttask_execute``, idempotent the same way), runs through its steps and ends in one
terminal status. Transitions (``status`` of flighttask_progress in brackets):

==================  =====================  ===============================================================
state               event                  next
==================  =====================  ===============================================================
PREPARED            execute                RUNNING (sent), the run starts; another task running: 319016
PREPARED            undo                   removed (canceled); a running task: 319006
PREPARED            expiry (PREPARE_TTL)   removed
RUNNING             step / reached         RUNNING (sent until the aircraft enters the wayline, then
                                           in_progress)
RUNNING             pause                  PAUSED (paused), only once flying: before that 319046
PAUSED              pause                  PAUSED: 0, nothing sent (idempotent)
PAUSED              recovery               RUNNING (in_progress)
RUNNING             recovery               RUNNING: 0, nothing sent (idempotent)
RUNNING/PAUSED      finished               ok
RUNNING/PAUSED      failed(code)           failed, with the code as ``result`` and a break point
RUNNING/PAUSED      stopped (RTH, stop)    canceled, with a break point
RUNNING/PAUSED      RUN_TIMEOUT            timeout (the service stops the aircraft)
==================  =====================  ===============================================================

Reporting (WAYLINE-NOTES §4.1, where the notes are silent the choice is written here):
``current_step`` follows the Dock 2 numbering: 16 get the KMZ URL, 17 download, 18 upload to the
aircraft, 20 take-off, 24 trigger the wayline, 25 executing (the step between Dock 2's 24 "trigger" and
26 "RTH pre-check", as Dock 1's 23 follows its 22), 35 notify the result. ``percent`` is 0–10 during
preparation and 10 + 90 × waypoints done / waypoints, 100 on ``ok``. ``current_waypoint_index`` counts
the waypoints of the current wayline done (0 before the first). ``wayline_id`` is 65535 until the aircraft
enters a wayline (observed on real docks, §8.7).

The break point of a task that ends early (:func:`break_point_at`) follows DJI's numbering, where a
*segment* is named by the waypoint it starts from (DJI MSDK 5 ``BreakPointInfo``: 25 % of the way from
waypoint 1 to waypoint 2 is waypoint 1 with progress 0.25): after waypoint *k* the aircraft is on segment
*k* (state 0) with the fraction of it flown as ``progress``; before the first waypoint it is at waypoint 0
(state 1: nothing of the route flown); after the last, at the last (state 1). A resume from it
(``flighttask_prepare`` with ``break_point``) flies on from waypoint *k* + 1, or from the waypoint of a
state 1 break point.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

__all__ = ["PREPARE_TTL", "RUN_TIMEOUT", "Phase", "TaskBook", "Verdict", "WaylineTask"]

#: A prepared task not executed within this (s) is forgotten (the Demo prepares at most 24 h ahead).
PREPARE_TTL = 2 * 86_400.0
#: A run longer than this (s) is stopped and reported ``timeout``.
RUN_TIMEOUT = 3 * 3600.0
NO_WAYLINE = 65535

# result codes (schemas.results.ResultCode values; this module imports nothing of the contract)
OK = 0
TASK_UNKNOWN, TASK_RUNNING, OTHER_TASK_RUNNING = 319003, 319006, 319016
PAUSE_FAILED, RESUME_FAILED, COMPLETED, NOT_RUNNING = 319020, 319042, 319044, 319046


class Phase(enum.Enum):
    PREPARED = "prepared"
    RUNNING = "running"
    PAUSED = "paused"
    DONE = "done"


STEP_URL, STEP_DOWNLOAD, STEP_UPLOAD, STEP_TAKEOFF, STEP_TRIGGER, STEP_EXECUTING, STEP_RESULT = (
    16, 17, 18, 20, 24, 25, 35,
)  # fmt: skip
_STATE_FOR_STEP = {STEP_URL: 2, STEP_DOWNLOAD: 2, STEP_UPLOAD: 3, STEP_TAKEOFF: 4, STEP_TRIGGER: 4}


@dataclass(frozen=True, slots=True)
class Verdict:
    """The answer to one service: ``result`` (0 or a code), ``reason`` for a failure."""

    result: int = OK
    reason: str = ""

    @property
    def ok(self) -> bool:
        return self.result == OK


@dataclass
class WaylineTask:
    flight_id: str
    prepared_at: float
    request: Any  # the validated flighttask_prepare data
    phase: Phase = Phase.PREPARED
    status: str = "sent"
    result: int = OK
    step: int = 0
    percent: int = 0
    mission_state: int = 2
    wayline_id: int = NO_WAYLINE
    waypoint_index: int = 0  # waypoints of the current wayline done
    done_points: int = 0
    total_points: int = 0
    media_count: int = 0
    started_at: float | None = None
    entered: bool = False
    break_point: dict[str, Any] | None = None
    reason: str = ""
    history: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)  # the route's actions the aircraft cannot carry out


class TaskBook:
    """Every wayline task of one gateway (one aircraft flies at most one at a time)."""

    def __init__(self) -> None:
        self.tasks: dict[str, WaylineTask] = {}

    # -- queries ---------------------------------------------------------------------------------
    @property
    def active(self) -> WaylineTask | None:
        for t in self.tasks.values():
            if t.phase in (Phase.RUNNING, Phase.PAUSED):
                return t
        return None

    def get(self, flight_id: str) -> WaylineTask | None:
        return self.tasks.get(flight_id)

    # -- services --------------------------------------------------------------------------------
    def prepare(self, request: Any, now: float) -> tuple[WaylineTask, bool]:
        """The task of a prepare, and whether it is new (a repeat changes nothing)."""
        known = self.tasks.get(request.flight_id)
        if known is not None:
            return known, False
        task = WaylineTask(request.flight_id, now, request)
        self.tasks[request.flight_id] = task
        return task, True

    def execute(self, flight_id: str, now: float) -> tuple[Verdict, bool]:
        """The verdict, and whether the run must start now."""
        task = self.tasks.get(flight_id)
        if task is None:
            return Verdict(TASK_UNKNOWN, "no prepared task with this flight_id"), False
        if task.phase in (Phase.RUNNING, Phase.PAUSED):
            return Verdict(), False  # a resend of the execute that started it
        if task.phase is Phase.DONE:
            if task.status == "failed" and task.started_at is None:
                return Verdict(task.result, task.reason or "the task failed"), False
            return Verdict(), False  # ran already: its final progress said how it ended
        other = self.active
        if other is not None:
            return Verdict(OTHER_TASK_RUNNING, f"task {other.flight_id} is running"), False
        task.phase = Phase.RUNNING
        task.started_at = now
        task.status = "sent"
        task.step = STEP_URL
        return Verdict(), True

    def adopt(
        self,
        flight_id: str,
        request: Any,
        now: float,
        *,
        paused: bool = False,
        total_points: int = 0,
        done_points: int = 0,
        wayline_id: int = NO_WAYLINE,
        waypoint_index: int = 0,
    ) -> WaylineTask:
        """A task the aircraft is found flying (a restarted gateway): running (or paused) and entered, with
        the progress known of it; ``request`` may be None (a mission nobody here started)."""
        task = self.tasks.get(flight_id) or WaylineTask(flight_id, now, request)
        self.tasks[flight_id] = task
        task.started_at = now if task.started_at is None else task.started_at
        task.total_points, task.done_points = total_points, done_points
        task.wayline_id, task.waypoint_index = wayline_id, waypoint_index
        task.phase = Phase.RUNNING
        self.entered(task)
        if total_points:
            task.percent = min(99, 10 + 90 * done_points // total_points)
        if paused:
            self.paused(task)
        return task

    def undo(self, flight_ids: list[str]) -> Verdict:
        live = (Phase.RUNNING, Phase.PAUSED)
        running = [f for f in flight_ids if (t := self.tasks.get(f)) is not None and t.phase in live]
        if running:
            return Verdict(TASK_RUNNING, "a running task cannot be undone (pause it, or return home)")
        for f in flight_ids:
            task = self.tasks.get(f)
            if task is not None and task.phase is Phase.PREPARED:
                del self.tasks[f]
        return Verdict()

    def pause(self) -> tuple[Verdict, WaylineTask | None]:
        """The verdict, and the task to pause (None: nothing to do on the aircraft). Pausing a paused task is
        done already: 0, nothing sent (a cloud that resends, or a second operator, gets no error)."""
        task = self.active
        if task is not None and task.phase is Phase.PAUSED:
            return Verdict(), None
        if task is None or not task.entered:
            return Verdict(NOT_RUNNING, "no wayline is flying"), None
        return Verdict(), task

    def paused(self, task: WaylineTask) -> None:
        task.phase = Phase.PAUSED
        task.status = "paused"
        task.mission_state = 7

    def recovery(self) -> tuple[Verdict, WaylineTask | None]:
        """The verdict, and the task to resume (None: nothing to do on the aircraft). Recovering a running
        task is done already: 0, nothing sent (the same rule as a second pause)."""
        task = self.active
        if task is None:
            done = [t for t in self.tasks.values() if t.phase is Phase.DONE and t.started_at is not None]
            if done:
                return Verdict(COMPLETED, "the task has ended"), None
            return Verdict(RESUME_FAILED, "no paused wayline"), None
        if task.phase is not Phase.PAUSED:
            return Verdict(), None  # running: what a recovery asks for already holds
        return Verdict(), task

    def resumed(self, task: WaylineTask) -> None:
        task.phase = Phase.RUNNING
        task.status = "in_progress"
        task.mission_state = 6

    # -- the run ---------------------------------------------------------------------------------
    def step(self, task: WaylineTask, step: int, percent: int | None = None) -> None:
        task.step = step
        task.mission_state = _STATE_FOR_STEP.get(step, task.mission_state)
        if percent is not None:
            task.percent = percent

    def planned(self, task: WaylineTask, total_points: int, skipped: list[str] | None = None) -> None:
        task.total_points = max(1, total_points)
        task.skipped = list(skipped or [])

    def entered(self, task: WaylineTask) -> None:
        """The aircraft is on its way to the first waypoint."""
        task.entered = True
        task.step = STEP_EXECUTING
        task.status = "in_progress" if task.phase is Phase.RUNNING else task.status
        task.mission_state = 5
        task.percent = max(task.percent, 10)

    def reached(self, task: WaylineTask, wayline_id: int, index: int, photos: int) -> None:
        if wayline_id != task.wayline_id:
            task.waypoint_index = 0
        task.wayline_id = wayline_id
        task.waypoint_index = index + 1
        task.done_points += 1
        task.media_count += photos
        task.mission_state = 6 if task.phase is Phase.RUNNING else task.mission_state
        task.percent = min(99, 10 + 90 * task.done_points // task.total_points) if task.total_points else 10

    def finished(self, task: WaylineTask) -> None:
        self._end(task, "ok", OK)
        task.percent = 100

    def failed(self, task: WaylineTask, result: int, reason: str, break_point: dict[str, Any] | None) -> None:
        task.break_point = break_point
        self._end(task, "failed", result, reason)

    def stopped(self, task: WaylineTask, status: str, break_point: dict[str, Any] | None) -> None:
        """Ended from outside: ``canceled`` (return home, a stop) or ``timeout``."""
        task.break_point = break_point
        self._end(task, status, OK)

    def _end(self, task: WaylineTask, status: str, result: int, reason: str = "") -> None:
        task.phase = Phase.DONE
        task.status = status
        task.result = result
        task.reason = reason
        task.step = STEP_RESULT
        task.mission_state = 9

    def expired(self, now: float) -> list[WaylineTask]:
        """Running tasks past RUN_TIMEOUT (to be stopped); forgets prepared tasks past PREPARE_TTL."""
        for f, t in list(self.tasks.items()):
            if t.phase in (Phase.PREPARED, Phase.DONE) and now - t.prepared_at > PREPARE_TTL:
                del self.tasks[f]
        live = (Phase.RUNNING, Phase.PAUSED)
        return [
            t
            for t in self.tasks.values()
            if t.started_at is not None and t.phase in live and now - t.started_at > RUN_TIMEOUT
        ]

    # -- reporting -------------------------------------------------------------------------------
    @staticmethod
    def progress(task: WaylineTask) -> dict[str, Any]:
        """The ``data`` of flighttask_progress (schemas.wayline.FlighttaskProgress)."""
        ext: dict[str, Any] = {
            "flight_id": task.flight_id,
            "wayline_id": task.wayline_id,
            "current_waypoint_index": task.waypoint_index,
            "wayline_mission_state": task.mission_state,
            "media_count": task.media_count,
            "track_id": "",
        }
        if task.break_point is not None:
            ext["break_point"] = task.break_point
        if task.status == "failed" and task.reason:
            ext["x_reason"] = task.reason[:300]  # extension: the Cloud API has only the result code
        if task.skipped:
            ext["x_skipped_actions"] = [s[:300] for s in task.skipped]
        return {
            "result": task.result,
            "output": {
                "ext": ext,
                "progress": {"current_step": task.step, "percent": task.percent},
                "status": task.status,
            },
        }


#: state of a break point: on a segment (named by the waypoint it starts from) or on a waypoint
ON_SEGMENT, ON_WAYPOINT = 0, 1


def break_point_at(
    done: int,
    waypoints: Sequence[tuple[float, float]] | None,
    position: tuple[float, float],
    start: int = 0,
) -> tuple[int, int, float]:
    """``(index, state, progress)`` of the aircraft at ``position`` (latitude, longitude) when waypoints
    up to index ``done`` - 1 of the current wayline (``waypoints``, their latitude and longitude in index
    order, None if unknown) have been reached; ``start`` is the first waypoint the run flies (a resumed
    task's). ``progress`` is the aircraft's position projected on the segment, 0..1 (0 when the route is
    unknown: a resume then flies the whole segment again)."""
    if done <= start:
        return start, ON_WAYPOINT, 0.0
    if waypoints is not None and done >= len(waypoints):
        return len(waypoints) - 1, ON_WAYPOINT, 0.0
    index = done - 1
    if waypoints is None:
        return index, ON_SEGMENT, 0.0
    (lat0, lon0), (lat1, lon1) = waypoints[index], waypoints[index + 1]
    east = math.cos(math.radians(lat0))  # a local flat map: metres per degree of longitude shrink
    sx, sy = (lon1 - lon0) * east, lat1 - lat0
    px, py = (position[1] - lon0) * east, position[0] - lat0
    length2 = sx * sx + sy * sy
    if length2 <= 0.0:
        return index, ON_SEGMENT, 0.0
    return index, ON_SEGMENT, min(1.0, max(0.0, (px * sx + py * sy) / length2))
