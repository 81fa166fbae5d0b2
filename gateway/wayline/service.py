"""The wayline service: the Cloud API's flighttask_* and return_home* services for the gateway's aircraft,
their progress events, and the I/O around the sans-I/O :class:`~gateway.wayline.task.TaskBook`.

Owns, on the event loop: the KMZ downloads (``fetch.py``), the ``flighttask_resource_get`` request before
each run (a fresh URL, as docks ask; ``gateway/cloud_requests.py``), the check and parse
(``adapters.wayline.kmz``), one run per executed task (the aircraft family's runner: an adapter with a
``wayline`` attribute, :class:`adapters.wayline.runner.WaylineRunner`), ``flighttask_progress``
(bid = flight_id, need_reply 1) on every change and each second while a task runs,
``flighttask_ready`` for conditional tasks, ``return_home_info`` while returning, and the task
time-outs. Knows nothing of paho or of bytes on a link.

Choices where WAYLINE-NOTES is silent (a DJI dock's behaviour where known):

* ``flighttask_prepare`` downloads and checks the file at once and waits for it up to
  :data:`PREPARE_WAIT` s: a wrong fingerprint, a bad file or a route the aircraft cannot fly is the
  prepare's non-zero result (nothing is uploaded, nothing moves); a slower download goes on and a failure
  then fails the execute. A file that cannot be obtained (an expired pre-signed URL, a host not reachable)
  does not fail the prepare: the execute asks for a fresh URL, as a dock does (314013 if that fails too).
  ``flighttask_execute`` answers at once and the run reports by progress events.
* Before each run the gateway asks ``flighttask_resource_get``; an answer with a file is downloaded
  unless it has the fingerprint already verified; no answer (or an error) falls back to the prepared file.
* **Dock semantics.** None of these services needs a ``flight_authority_grab`` first: a dock owns its
  aircraft, and DJI's reference cloud (DJI-Cloud-API-Demo) runs its wayline jobs and return home without
  one. Whatever moves the aircraft (execute, pause, recovery, return home and its cancel) obtains SDK
  control of the FC itself (``01 00``, the runner's ``ensure_control``). That gives the cloud no stick
  authority: live control (DRC) keeps its own rule (a grab first; docs/cloud-api.md). A pilot's RC that
  owns the aircraft refuses the obtain: the run fails with 319030 (return home answers 314000 with the
  FC's reason); a DRC session's sticks are refused (314000, naming the task) while the task flies.
* ``return_home`` is the abort path from every state in the air (issue #37): a running or paused task
  ends ``canceled`` (break reason 1283 "user RTH"), a take-off or fly-to the adapter flies ends
  ``wayline_cancel``, and the flight controller's own go home flies the aircraft home and lands it
  (docs/osdk.md: why not a mission built by the gateway). Its height is set first where the firmware
  can (``01 42``): the last task's ``rth_altitude``, else its KMZ's ``globalRTHHeight``, else the FC keeps
  its own (what the last take-off to point set). ``return_home_info`` draws that way: up to the height
  over the aircraft, over home (``last_point_type`` 0). On the ground it is refused (314000, "on the
  ground") and nothing moves. ``return_home_cancel`` exits the go home (or its landing): the aircraft
  hovers (as a dock's aircraft does, §3.5).
* ``out_of_control_action`` 1 (hover) and 2 (land) are refused (325001): an Onboard SDK FC's lost-link
  failsafe is set in DJI Assistant 2, not by the open protocol; 0 (return home) is its default.
* ``ready_conditions`` of a conditional task (``task_type`` 2) are checked every second: battery above
  ``battery_capacity`` and now within [begin_time, end_time]; the first time they all hold,
  ``flighttask_ready`` names the task. ``executable_conditions.storage_capacity`` cannot be checked on an
  Onboard SDK FC (it reports no storage): accepted and logged as not checked.
* A lost cloud does not stop a flying task (a dock's aircraft flies on without its cloud); a lost
  flight controller fails it (325012: the FC flies its uploaded mission on its own, nothing can be
  reported or changed); a take-off that does not end within :data:`TAKEOFF_TIMEOUT` s fails it with
  314008 "preparation timed out".
* ``wayline_precision_type``, ``rth_mode``, ``flight_safety_advance_check`` and ``simulate_mission`` have no
  counterpart on the FC: accepted and logged as ignored (``rth_mode`` 1 preset height is what is flown).
* **The aircraft is the truth.** A run ends when the FC says its mission ended: an emergency stop the
  operator asked for ends it ``canceled``, any other end the FC decides (the RC taking over, a mission it
  dropped) ``failed`` with the FC's reason, each with a break point; a new prepare and execute are then
  accepted. Each running task is kept in the crash-safe store (``gateway/store.py``): a gateway restarted
  while the aircraft flies the mission finds it flying (the adapter adopts it), reports it again under the
  same ``flight_id`` with its progress, and pause, recovery, return home and its end act on it. A mission
  the store does not know is reported as a task of its own (``flight_id`` ``adopted-<sn>-<ms>``). After
  a restart the waypoint indexes are the FC mission's (the plan that mapped them is not kept).

Why this module is longer than 500 lines: it is the I/O of one task life cycle (prepare, download,
execute, the run or the follow of an adopted mission, pause, recovery, return home, progress, the store),
whose steps share the task book, the runs in flight and the files; the decisions live in task.py.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

from adapters.errors import (
    DeviceNotConnected,
    DeviceRejected,
    DeviceTimeout,
    KmzError,
    MissionStopped,
    RouteRefused,
)
from adapters.wayline.kmz import FILE_FORMAT, Route, check_fingerprint, parse_wpml, unpack_wpml
from adapters.wayline.runner import Reached
from gateway.clock import Clock
from gateway.cloud_requests import CloudRequestError, CloudRequests
from gateway.devices import DeviceTable
from gateway.metrics import Metrics
from gateway.store import StateStore
from gateway.wayline.fetch import FetchError, fetch_kmz
from gateway.wayline.task import (
    NO_WAYLINE,
    ON_WAYPOINT,
    STEP_DOWNLOAD,
    STEP_TAKEOFF,
    STEP_TRIGGER,
    STEP_UPLOAD,
    STEP_URL,
    Phase,
    TaskBook,
    Verdict,
    WaylineTask,
    break_point_at,
)
from schemas import TopicKind
from schemas.base import InboundModel
from schemas.registry import WAYLINE_METHODS
from schemas.results import ResultCode
from schemas.wayline import (
    FlighttaskExecute,
    FlighttaskPause,
    FlighttaskPrepare,
    FlighttaskRecovery,
    FlighttaskUndo,
    ReturnHome,
    ReturnHomeCancel,
)

log = logging.getLogger(__name__)

__all__ = ["PREPARE_WAIT", "WaylineService"]

PREPARE_WAIT = 2.0
#: An immediate task is executed within 30 s of its execute_time (WAYLINE-NOTES §2 [FEAT]).
IMMEDIATE_WINDOW_MS = 30_000
TAKEOFF_TIMEOUT = 30.0
PROGRESS_PERIOD = 1.0
_UNOBTAINABLE = int(ResultCode.WAYLINE_FILE_UNOBTAINABLE)
METHODS = frozenset(spec.method for spec in WAYLINE_METHODS if spec.kind is TopicKind.SERVICES)

Result = tuple[int, dict[str, Any] | None]


@dataclass
class _File:
    fingerprint: str
    route: Route
    skipped: tuple[str, ...] = ()  # the trial plan's actions the aircraft cannot carry out


class WaylineService:
    methods = METHODS

    def __init__(
        self,
        *,
        gateway_sn: str,
        devices: DeviceTable,
        event: Callable[..., None],
        requests: CloudRequests,
        clock: Clock,
        metrics: Metrics,
        fetch: Callable[[str], Awaitable[bytes]] = fetch_kmz,
        store: StateStore | None = None,
        strict_actions: bool = False,
    ) -> None:
        self.gateway_sn = gateway_sn
        self.devices = devices
        self._event = event  # Northbound.event
        self.requests = requests
        self.clock = clock
        self.metrics = metrics
        self.fetch = fetch
        self.book = TaskBook()
        self._files: dict[str, asyncio.Task[_File]] = {}
        self._runs: dict[str, asyncio.Task[None]] = {}
        self._ready_sent: set[str] = set()
        self._stops: set[asyncio.Task[None]] = set()  # time-out stops in flight
        self._rth: dict[str, Any] | None = None  # the way home being flown: path, flight_id
        self._flown: dict[str, _File] = {}  # the file each run flies (a fresh URL may replace the prepared)
        self._rth_altitude: float | None = None  # the last task's, else the FC's own
        self.store = store if store is not None else StateStore(None)
        self._persisted: dict[str, tuple[Any, ...]] = {}  # flight_id -> what the store holds of it
        #: refuse a route with actions the aircraft cannot carry out (else they are skipped and listed)
        self.strict_actions = strict_actions
        self._moved: set[str] = set()  # runs that took off or entered their route: a failure secures them

    # -- the aircraft ----------------------------------------------------------------------------
    def _aircraft(self) -> Any:
        """The aircraft that flies waylines (an adapter with a ``wayline`` runner), or None."""
        for adapter in self.devices:
            if getattr(adapter, "wayline", None) is not None:
                return adapter
        return None

    def aircraft_sn(self) -> str | None:
        aircraft = self._aircraft()
        return aircraft.info.sn if aircraft is not None else None

    def route_of(self, flight_id: str) -> tuple[str, Route] | None:
        """The task's route and its fingerprint (the one flown, else the prepared one once downloaded),
        for the web console; None while it is being fetched or when it could not be."""
        file = self._flown.get(flight_id)
        if file is None:
            prepared = self._files.get(flight_id)
            if prepared is None or not prepared.done() or prepared.cancelled() or prepared.exception():
                return None
            file = prepared.result()
        return file.fingerprint, file.route

    # -- services --------------------------------------------------------------------------------
    async def call(self, method: str, data: InboundModel) -> Result:
        aircraft = self._aircraft()
        if aircraft is None:
            return ResultCode.METHOD_NOT_SUPPORTED, {"reason": "no aircraft here flies waylines"}
        # dock semantics: no flight_authority_grab first; whatever moves the aircraft takes SDK control
        # itself (runner.ensure_control), as a dock does for its own aircraft (module docstring)
        handler = getattr(self, "_" + method)
        result: Result = await handler(aircraft, data)
        return result

    async def _flighttask_prepare(self, aircraft: Any, data: FlighttaskPrepare) -> Result:
        if data.out_of_control_action is not None and data.out_of_control_action != 0:
            return ResultCode.INVALID_PARAMETERS, {
                "reason": "out_of_control_action: only 0 (return home), the FC's own failsafe"
            }
        task, new = self.book.prepare(data, self.clock.monotonic())
        if new:
            self._log_ignored(data)
            self._files[task.flight_id] = asyncio.get_running_loop().create_task(
                self._load(aircraft, data.file.url, data.file.fingerprint, data), name=f"kmz-{task.flight_id}"
            )
        if task.phase is Phase.DONE and task.started_at is None and task.status == "failed":
            return task.result, {"reason": task.reason}
        file = self._files.get(task.flight_id)
        if file is not None:
            await asyncio.wait({file}, timeout=PREPARE_WAIT)
            failure = _file_failure(file)
            if failure is not None and failure[0] == _UNOBTAINABLE:
                # an expired or unreachable URL: the execute asks flighttask_resource_get for a fresh one
                log.warning(
                    "wayline task %s: %s; a fresh URL is asked for at execute", task.flight_id, failure[1]
                )
            elif failure is not None:
                self.book.failed(task, *failure, None)
                return failure[0], {"reason": failure[1]}
            if file.done() and failure is None and file.result().skipped:
                return ResultCode.SUCCESS, {"x_skipped_actions": list(file.result().skipped)}
        return ResultCode.SUCCESS, None

    async def _load(self, aircraft: Any, url: str, fingerprint: str, prepare: FlighttaskPrepare) -> _File:
        """Download, check and parse; a trial plan from where the aircraft is now refuses what it cannot
        fly before anything is uploaded."""
        if not fingerprint.strip():
            raise KmzError(int(ResultCode.WAYLINE_MD5_EMPTY), "the task's fingerprint (MD5) is empty")
        try:
            kmz = await self.fetch(url)
        except FetchError as exc:
            raise KmzError(_UNOBTAINABLE, str(exc)) from None
        digest = check_fingerprint(kmz, fingerprint)
        route = parse_wpml(unpack_wpml(kmz))
        skipped: tuple[str, ...] = ()
        if aircraft.telemetry.latitude is not None:
            skipped = tuple(self._plan(aircraft, route, prepare).skipped)
        return _File(digest, route, skipped)

    def _plan(self, aircraft: Any, route: Route, prepare: FlighttaskPrepare) -> Any:
        """The runner's plan from where the aircraft is now (RouteRefused for what it cannot fly, the FC's
        limits included); under ``strict_actions`` a route with actions it would skip is refused too."""
        bp = prepare.break_point
        plan = aircraft.wayline.plan(
            route,
            rth_altitude=prepare.rth_altitude,
            exit_wayline_when_rc_lost=prepare.exit_wayline_when_rc_lost,
            break_point=(bp.wayline_id, bp.index, int(bp.state)) if bp is not None else None,
        )
        skipped = list(getattr(plan, "skipped", ()))
        if self.strict_actions and skipped:
            more = f" and {len(skipped) - 1} more" if len(skipped) > 1 else ""
            raise RouteRefused(
                1634, f"wayline.strict_actions: the aircraft cannot carry out {skipped[0]}{more}", FILE_FORMAT
            )
        return plan

    def _log_ignored(self, data: FlighttaskPrepare) -> None:
        ignored = [
            name
            for name in (
                "wayline_precision_type",
                "rth_mode",
                "flight_safety_advance_check",
                "simulate_mission",
            )
            if getattr(data, name) is not None
        ]
        if ignored:
            log.info("wayline task %s: %s have no counterpart on this FC (ignored)", data.flight_id, ignored)
        if data.executable_conditions is not None:
            log.info("wayline task %s: storage_capacity cannot be checked on this FC", data.flight_id)

    async def _flighttask_execute(self, aircraft: Any, data: FlighttaskExecute) -> Result:
        task = self.book.get(data.flight_id)
        if task is not None and task.phase is Phase.PREPARED and task.request.task_type == 0:
            skew = abs(self.clock.time_ms() - (task.request.execute_time or self.clock.time_ms()))
            if skew > IMMEDIATE_WINDOW_MS:
                # [FEAT]: an immediate task more than 30 s from its execute_time is an error (a dock
                # without time sync gets 319008; which code a dock sends for this one is not documented)
                return ResultCode.WAYLINE_TASK_EXPIRED, {
                    "reason": f"immediate task {skew / 1000:.0f} s from its execute_time (30 s allowed)"
                }
        if task is not None and task.phase is Phase.PREPARED:
            prepared = self._files.get(task.flight_id)
            failure = _file_failure(prepared)
            if failure is not None and failure[0] != _UNOBTAINABLE:
                self.book.failed(task, *failure, None)
            elif prepared is not None and prepared.done() and failure is None and self.book.active is None:
                refused = self._recheck(aircraft, task, prepared.result())
                if refused is not None:
                    return refused
        verdict, start = self.book.execute(data.flight_id, self.clock.monotonic())
        if start:
            assert task is not None
            self._emit(task)
            self._runs[task.flight_id] = asyncio.get_running_loop().create_task(
                self._run(aircraft, task), name=f"wayline-{task.flight_id}"
            )
        return verdict.result, ({"reason": verdict.reason} if verdict.reason else None)

    def _recheck(self, aircraft: Any, task: WaylineTask, file: _File) -> Result | None:
        """The execute plans the prepared route again from where the aircraft is now (it may have moved
        since the prepare): a route it cannot fly from here is refused before anything moves; the task stays
        prepared (executable from where it can be flown)."""
        if aircraft.telemetry.latitude is None:
            return None
        try:
            self._plan(aircraft, file.route, task.request)
        except RouteRefused as exc:
            code, reason = _failure(exc)
            log.warning("wayline task %s: execute refused before take-off: %s", task.flight_id, reason)
            return code, {"reason": reason[:300]}
        return None

    async def _flighttask_undo(self, aircraft: Any, data: FlighttaskUndo) -> Result:
        verdict = self.book.undo(list(data.flight_ids))
        if verdict.ok:
            for f in data.flight_ids:
                if self.book.get(f) is None:
                    file = self._files.pop(f, None)
                    if file is not None:
                        file.cancel()
        return verdict.result, ({"reason": verdict.reason} if verdict.reason else None)

    async def _flighttask_pause(self, aircraft: Any, data: FlighttaskPause) -> Result:
        return await self._hold_or_go(aircraft, self.book.pause(), aircraft.wayline.pause, self.book.paused,
                                      ResultCode.WAYLINE_PAUSE_FAILED)  # fmt: skip

    async def _flighttask_recovery(self, aircraft: Any, data: FlighttaskRecovery) -> Result:
        return await self._hold_or_go(aircraft, self.book.recovery(), aircraft.wayline.resume,
                                      self.book.resumed, ResultCode.WAYLINE_RESUME_FAILED)  # fmt: skip

    async def _hold_or_go(
        self,
        aircraft: Any,
        decided: tuple[Verdict, WaylineTask | None],
        act: Callable[[], Awaitable[None]],
        done: Callable[[WaylineTask], None],
        failed: int,
    ) -> Result:
        """Pause or recovery: the book's verdict, then the aircraft (SDK control first, as a dock takes it
        for its own aircraft), then the book and a progress event."""
        verdict, task = decided
        if task is None:  # refused, or already so (a second pause, a recovery of a running task): 0
            return verdict.result, ({"reason": verdict.reason} if verdict.reason else None)
        try:
            await aircraft.wayline.ensure_control()
            await act()
        except (DeviceRejected, DeviceTimeout, DeviceNotConnected) as exc:
            return failed, {"reason": str(exc)[:300]}
        done(task)
        self._emit(task)
        return ResultCode.SUCCESS, None

    async def _return_home(self, aircraft: Any, data: ReturnHome) -> Result:
        if not aircraft.in_air:
            return ResultCode.BUSY, {"reason": "return home refused: the aircraft is on the ground"}
        task = self.book.active
        flight_id = ""
        if task is not None:
            flight_id = task.flight_id
            await self._stop_task(aircraft, task, "canceled", break_reason=1283)
        runner = aircraft.wayline
        try:
            await runner.ensure_control()  # a dock's own aircraft: no grab from the cloud first
            altitude = await runner.go_home_altitude(self._rth_altitude)
            await runner.go_home(flight_id)  # the FC's own: it ends whatever task flies first
        except (DeviceRejected, DeviceTimeout, DeviceNotConnected) as exc:
            return ResultCode.BUSY, {"reason": f"return home refused: {str(exc)[:200]}"}
        path = runner.go_home_path(altitude)
        self._rth = {"path": path, "flight_id": flight_id, "home_altitude": aircraft.telemetry.home_altitude}
        self._emit_rth()
        return ResultCode.SUCCESS, None

    async def _return_home_cancel(self, aircraft: Any, data: ReturnHomeCancel) -> Result:
        runner = aircraft.wayline
        # the FC's word, not this process's memory: a go home started before a restart is cancelled too
        if not (runner.mission_running or runner.fc_going_home):
            self._rth = None
            return ResultCode.BUSY, {"reason": "the aircraft is not returning home"}
        try:
            await aircraft.wayline.ensure_control()
            flying = await aircraft.wayline.cancel()
        except (DeviceRejected, DeviceTimeout, DeviceNotConnected) as exc:
            return ResultCode.BUSY, {"reason": str(exc)[:300]}
        self._rth = None
        if not flying:  # the FC says no return is flying (it ended: over home, landing)
            return ResultCode.BUSY, {
                "reason": "the aircraft is not returning home (the flight controller flies none)"
            }
        return ResultCode.SUCCESS, None

    # -- a run -----------------------------------------------------------------------------------
    async def _run(self, aircraft: Any, task: WaylineTask) -> None:
        req = task.request
        if req.rth_altitude is not None:
            self._rth_altitude = float(req.rth_altitude)
        self.store.task_started(
            task.flight_id, aircraft.info.sn, req.model_dump(mode="json"), self.clock.time_ms()
        )
        await self._guarded(aircraft, task, self._fly(aircraft, task))

    async def _follow(self, aircraft: Any, task: WaylineTask, mission: Any) -> None:
        """An adopted mission, followed to its end (the FC flies it; the runner reports it)."""

        def reached(index: int) -> None:
            if task.phase is Phase.DONE:
                return
            wayline_id = 0 if task.wayline_id == NO_WAYLINE else task.wayline_id
            self.book.reached(task, wayline_id, index, 0)
            self._emit(task)

        async def follow() -> None:
            await aircraft.wayline.follow(mission, reached)
            if task.phase is not Phase.DONE:
                self.book.finished(task)

        await self._guarded(aircraft, task, follow())

    async def _fly(self, aircraft: Any, task: WaylineTask) -> None:
        """A run: URL, download, plan, upload, take-off, the missions; its ends are :meth:`_guarded`'s."""
        book, runner, req = self.book, aircraft.wayline, task.request
        book.step(task, STEP_URL, 2)
        self._emit(task)
        file = self._flown[task.flight_id] = await self._fresh_file(aircraft, task)
        if file.route.config.global_rth_height and req.rth_altitude is None:
            self._rth_altitude = file.route.config.global_rth_height
        plan = self._plan(aircraft, file.route, req)
        for note in plan.skipped:
            log.warning("wayline task %s: skipped %s", task.flight_id, note)
        book.planned(task, plan.route_points, list(plan.skipped))
        book.step(task, STEP_UPLOAD, 8)
        self._emit(task)
        await runner.ensure_control()
        if not aircraft.in_air:
            book.step(task, STEP_TAKEOFF, 9)
            self._emit(task)
            self._moved.add(task.flight_id)  # from here a failure must not leave it in the air
            try:
                await runner.take_off(TAKEOFF_TIMEOUT)
            except DeviceTimeout as exc:  # a dock's "preparation timed out"
                raise DeviceRejected(ResultCode.WAYLINE_PREPARE_TIMEOUT, str(exc)) from None
        book.step(task, STEP_TRIGGER, 10)
        self._emit(task)

        def reached(r: Reached) -> None:
            if task.phase is Phase.DONE:
                return
            book.reached(task, r.ref[0], r.ref[1], r.photos)
            self._emit(task)

        def entered() -> None:
            self._moved.add(task.flight_id)
            book.entered(task)
            self._emit(task)

        await runner.fly(plan, task.flight_id, reached, entered)
        if task.phase is not Phase.DONE:
            book.finished(task)

    async def _guarded(self, aircraft: Any, task: WaylineTask, body: Awaitable[None]) -> None:
        """Run ``body`` (a run or a follow) and end the task the way it ended, reported and stored."""
        book = self.book
        try:
            await body
        except (KmzError, RouteRefused) as exc:
            code, reason = _failure(exc)
            br = getattr(exc, "break_reason", 0)
            book.failed(task, code, await self._secure(aircraft, task, reason),
                        self._break_point(aircraft, task, br) if br else None)  # fmt: skip
        except DeviceRejected as exc:
            reason = await self._secure(aircraft, task, str(exc))
            book.failed(task, int(exc.result), reason[:300], self._break_point(aircraft, task, 1564))
        except (DeviceTimeout, DeviceNotConnected) as exc:
            code = (
                ResultCode.DEVICE_NOT_CONNECTED
                if isinstance(exc, DeviceNotConnected)
                else ResultCode.DEVICE_TIMEOUT
            )
            reason = await self._secure(aircraft, task, str(exc))
            book.failed(task, int(code), reason[:300], self._break_point(aircraft, task, 2))
        except MissionStopped:
            if task.phase is not Phase.DONE:
                book.stopped(task, "canceled", self._break_point(aircraft, task, 1281))
        except asyncio.CancelledError:
            if task.phase is not Phase.DONE:
                book.stopped(task, "canceled", self._break_point(aircraft, task, 1281))
        except Exception:
            log.exception("wayline task %s failed", task.flight_id)
            book.failed(task, int(ResultCode.INTERNAL_ERROR), "internal error in the gateway", None)
        finally:
            self._runs.pop(task.flight_id, None)
            self._moved.discard(task.flight_id)
            self.metrics.inc("wayline_tasks_total", status=task.status)
            log.info("wayline task %s ended %s (%s)", task.flight_id, task.status, task.result)
            self._emit(task)

    async def _secure(self, aircraft: Any, task: WaylineTask, reason: str) -> str:
        """A run that took off (or entered its route) failed: the runner never leaves the aircraft where it
        failed (the Onboard SDK runner: land within 20 m of home, else the FC's go home; logged at ERROR).
        Returns the reason the task reports (``ext.x_reason``), with what was done. A run that failed
        before anything moved is only logged."""
        secure = getattr(aircraft.wayline, "secure", None)
        if secure is None or task.flight_id not in self._moved:
            log.error("wayline task %s failed before anything moved: %s", task.flight_id, reason)
            return reason
        done = await secure(task.flight_id, reason)
        return f"{reason}; {done}" if done else reason

    async def _fresh_file(self, aircraft: Any, task: WaylineTask) -> _File:
        """The route to fly: a fresh URL from the cloud (flighttask_resource_get) when it gives one,
        downloaded unless that fingerprint is already verified; else the prepared file."""
        req = task.request
        url, fingerprint = req.file.url, req.file.fingerprint
        try:
            answer = await self.requests.request(
                "flighttask_resource_get", {"flight_id": task.flight_id}, bid=task.flight_id
            )
        except CloudRequestError as exc:
            log.warning("wayline task %s: %s; using the prepared file URL", task.flight_id, exc)
        else:
            if answer.result == 0 and answer.output is not None and answer.output.file is not None:
                url, fingerprint = answer.output.file.url, answer.output.file.fingerprint
            else:
                log.warning(
                    "wayline task %s: flighttask_resource_get answered %s", task.flight_id, answer.result
                )
        self.book.step(task, STEP_DOWNLOAD, 5)
        self._emit(task)
        prepared = self._files.get(task.flight_id)
        if prepared is not None:
            with contextlib.suppress(Exception):
                known = await asyncio.shield(prepared)
                if known.fingerprint == fingerprint.strip().lower():
                    return known
        file = await self._load(aircraft, url, fingerprint, req)
        return file

    async def _stop_task(self, aircraft: Any, task: WaylineTask, status: str, *, break_reason: int) -> None:
        self.book.stopped(task, status, self._break_point(aircraft, task, break_reason))
        if aircraft.wayline.mission_running:
            with contextlib.suppress(DeviceRejected, DeviceTimeout, DeviceNotConnected):
                await aircraft.wayline.cancel()
        run = self._runs.get(task.flight_id)
        if run is not None and not run.done():
            run.cancel()
        self._emit(task)

    def _break_point(self, aircraft: Any, task: WaylineTask, reason: int) -> dict[str, Any] | None:
        t = aircraft.telemetry
        if t.latitude is None or t.longitude is None:
            return None
        yaw = t.attitude[2] if t.attitude is not None else 0.0
        wayline_id = 0 if task.wayline_id == NO_WAYLINE else task.wayline_id
        start = 0
        resumed = getattr(task.request, "break_point", None)  # this run resumed an earlier one's
        not_yet = task.waypoint_index == 0
        if resumed is not None and not_yet and task.wayline_id in (NO_WAYLINE, resumed.wayline_id):
            wayline_id = resumed.wayline_id
            start = resumed.index if int(resumed.state) == ON_WAYPOINT else resumed.index + 1
        index, state, progress = break_point_at(
            task.waypoint_index, self._waypoints(task.flight_id, wayline_id), (t.latitude, t.longitude), start
        )
        return {
            "index": index,
            "state": state,
            "progress": round(progress, 4),
            "wayline_id": wayline_id,
            "break_reason": reason,
            "latitude": max(-90.0, min(90.0, t.latitude)),
            "longitude": max(-180.0, min(180.0, t.longitude)),
            "height": float(t.altitude or 0.0),
            "attitude_head": max(-180.0, min(180.0, yaw)),
        }

    def _waypoints(self, flight_id: str, wayline_id: int) -> list[tuple[float, float]] | None:
        """The latitude and longitude of the flown wayline's waypoints, in index order (None: unknown)."""
        flown = self.route_of(flight_id)
        if flown is None:
            return None
        for wayline in flown[1].waylines:
            if wayline.wayline_id == wayline_id:
                ordered = sorted(wayline.placemarks, key=lambda pm: pm.index)
                return [(pm.latitude, pm.longitude) for pm in ordered]
        return None

    # -- a mission found flying (a restart mid-flight) ---------------------------------------------
    def _adopt(self, aircraft: Any, mission: Any) -> None:
        """The aircraft flies a waypoint mission no run follows (its adapter adopted it): report it as the
        task the store says was running (same ``flight_id``, its progress so far), else as a task of its
        own, and follow it to its end."""
        sn = aircraft.info.sn
        stored = self.store.live_task(sn)
        request: Any = None
        if stored is not None:
            flight_id = stored.flight_id
            try:
                request = FlighttaskPrepare.model_validate(stored.request)
            except ValueError:
                log.warning("wayline task %s: its stored request no longer validates", flight_id)
        else:
            flight_id = f"adopted-{sn}-{self.clock.time_ms()}"
        mission.task_id = flight_id
        task = self.book.adopt(
            flight_id,
            request,
            self.clock.monotonic(),
            paused=stored is not None and stored.status == "paused",
            total_points=stored.total_points if stored is not None else 0,
            done_points=stored.done_points if stored is not None else 0,
            wayline_id=stored.wayline_id if stored is not None else 0,
            waypoint_index=stored.waypoint_index if stored is not None else 0,
        )
        if stored is None:
            self.store.task_started(flight_id, sn, {}, self.clock.time_ms())
        log.warning(
            "wayline task %s: aircraft %s is flying it (found after a restart): reporting and following it",
            flight_id,
            sn,
        )
        self._emit(task)
        self._moved.add(flight_id)  # it flies: a failure must not leave it in the air
        self._runs[flight_id] = asyncio.get_running_loop().create_task(
            self._follow(aircraft, task, mission), name=f"wayline-follow-{flight_id}"
        )

    # -- reports ---------------------------------------------------------------------------------
    def _emit(self, task: WaylineTask) -> None:
        self._event(
            self.gateway_sn, "flighttask_progress", self.book.progress(task), True, bid=task.flight_id
        )
        self._persist(task)

    def _persist(self, task: WaylineTask) -> None:
        """Keep what a restarted gateway needs of a started task (written when it changes)."""
        if task.started_at is None:
            return
        live = task.phase in (Phase.RUNNING, Phase.PAUSED)
        row = (task.status, task.total_points, task.done_points, task.wayline_id, task.waypoint_index, live)
        if self._persisted.get(task.flight_id) == row:
            return
        try:
            self.store.task_progress(
                task.flight_id,
                status=task.status,
                total_points=task.total_points,
                done_points=task.done_points,
                wayline_id=task.wayline_id,
                waypoint_index=task.waypoint_index,
                live=live,
                now_ms=self.clock.time_ms(),
            )
        except Exception:  # a full disk must not stop a flight's reports
            self.metrics.inc("handler_exceptions_total", where="state_store")
            log.exception("wayline task %s: could not keep its state", task.flight_id)
            return
        if live:
            self._persisted[task.flight_id] = row
        else:
            self._persisted.pop(task.flight_id, None)

    def _emit_rth(self) -> None:
        rth = self._rth
        if rth is None or not rth["path"]:
            return  # the FC's own go home: its path is the FC's
        base = rth["home_altitude"] or 0.0
        points = [
            {"latitude": lat, "longitude": lon, "height": round(base + h, 1)} for lat, lon, h in rth["path"]
        ]
        data = {"planned_path_points": points, "last_point_type": 0, "flight_id": rth["flight_id"]}
        self._event(self.gateway_sn, "return_home_info", data, False)

    def tick(self) -> None:
        """Once a second: progress of the running task, the way home, time-outs, conditional tasks."""
        now = self.clock.monotonic()
        aircraft = self._aircraft()
        claim = getattr(getattr(aircraft, "wayline", None), "claim", None)
        if claim is not None:
            mission = claim()
            if mission is not None:
                self._adopt(aircraft, mission)
        task = self.book.active
        if task is not None:
            self._emit(task)
        if self._rth is not None:
            if aircraft is not None and aircraft.wayline.mission_running:
                self._emit_rth()
            else:
                self._rth = None
        for late in self.book.expired(now):
            if aircraft is not None:
                stop = asyncio.get_running_loop().create_task(
                    self._stop_task(aircraft, late, "timeout", break_reason=2)
                )
                self._stops.add(stop)
                stop.add_done_callback(self._stops.discard)
        for gone in [f for f in self._flown if f not in self.book.tasks]:
            del self._flown[gone]  # forgotten by the book (PREPARE_TTL): the console no longer shows it
        ready = [f for f, t in self.book.tasks.items() if self._ready(aircraft, t)]
        if ready:
            self._ready_sent.update(ready)
            self._event(self.gateway_sn, "flighttask_ready", {"flight_ids": ready}, True)

    def _ready(self, aircraft: Any, task: WaylineTask) -> bool:
        req = task.request
        if task.phase is not Phase.PREPARED or req.task_type != 2 or task.flight_id in self._ready_sent:
            return False
        cond = req.ready_conditions
        if cond is None or aircraft is None:
            return False
        battery = aircraft.telemetry.battery_percent
        now_ms = self.clock.time_ms()
        return (
            battery is not None
            and battery > cond.battery_capacity
            and cond.begin_time <= now_ms <= cond.end_time
        )

    async def run(self, stop: asyncio.Event) -> None:
        while not stop.is_set():
            try:
                self.tick()
            except Exception:
                self.metrics.inc("handler_exceptions_total", where="wayline")
                log.exception("wayline tick failed")
            with contextlib.suppress(TimeoutError):
                await self.clock.wait_for(stop.wait(), PROGRESS_PERIOD)

    async def stop(self) -> None:
        for run in list(self._runs.values()):
            run.cancel()
        for file in self._files.values():
            file.cancel()


def _file_failure(file: asyncio.Task[_File] | None) -> tuple[int, str] | None:
    """Why a finished download/check failed (code, reason), or None (not done, or fine)."""
    if file is None or not file.done():
        return None
    if file.cancelled():
        return _UNOBTAINABLE, "the download was cancelled"
    exc = file.exception()
    return None if exc is None else _failure(exc)


def _failure(exc: BaseException | None) -> tuple[int, str]:
    if isinstance(exc, RouteRefused):
        return exc.code, f"{exc.reason} (break reason {exc.break_reason})"
    if isinstance(exc, KmzError):
        return exc.code, exc.reason
    if isinstance(exc, DeviceRejected):
        return int(exc.result), str(exc)[:300]
    if isinstance(exc, asyncio.CancelledError):
        return _UNOBTAINABLE, "the download was cancelled"
    return FILE_FORMAT, f"the file could not be checked: {type(exc).__name__}"
