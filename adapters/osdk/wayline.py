"""Flying a planned wayline route on an Onboard SDK aircraft: take-off when on the ground (like a dock),
upload and start each chained ground-station mission, follow its reached / finished / error pushes,
change the cruise speed per segment, pause / resume / cancel, and return home (the FC's own go home).

Owns the I/O half of a wayline on this family (the plan, sans-I/O, is ``wayline_plan.py``); uses the
aircraft only through :class:`adapters.osdk.mission.MissionHost` (the command path ``ground_station``,
``obtain_control``, ``flight_task``; ``begin_mission``/``mission_started`` for the :class:`Task` its
pushes go to). Knows nothing of MQTT, downloads or Cloud API task states: it reports through the
callbacks it is given.

The FC decides when a mission is over: a task the FC stopped flying (an emergency brake, the RC taking
over, a mission it dropped) ends the run with :class:`MissionStopped` (an emergency stop the operator
asked for) or :class:`DeviceRejected` (anything else), with the FC's reason; a waypoint mission found
flying after a restart is handed to the wayline service by :meth:`OsdkWayline.claim` and followed by
:meth:`OsdkWayline.follow`.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable

from adapters.errors import DeviceNotConnected, DeviceRejected, DeviceTimeout, MissionStopped
from adapters.osdk.commands import GO_HOME_ALTITUDE_RANGE, GS_ACK_TEXT
from adapters.osdk.mission import DM_GO_HOME, MissionHost, Task
from adapters.osdk.wayline_plan import MISSION_MAX, FcMission, Plan, PlanOptions, plan_route
from adapters.wayline.kmz import Route
from adapters.wayline.runner import Reached
from schemas.results import GROUND_STATION_ACK_BASE, ResultCode

log = logging.getLogger(__name__)

__all__ = ["MissionStopped", "OsdkWayline", "Reached"]

AUTO_TAKEOFF = 11
POLL = 0.05


class OsdkWayline:
    """The wayline runner (:class:`adapters.wayline.runner.WaylineRunner`) of one
    :class:`~adapters.osdk.adapter.AircraftAdapter` (one route at a time)."""

    def __init__(self, adapter: MissionHost) -> None:
        self.adapter = adapter
        self.paused = False
        self._task: Task | None = None
        self._speed_changes: set[asyncio.Task[None]] = set()  # held until done (the loop keeps weak refs)
        #: waypoints per ground-station mission (the u8 length allows 255; a firmware that takes fewer
        #: sets less, and longer routes are chained)
        self.mission_max = MISSION_MAX

    # -- planning --------------------------------------------------------------------------------
    def plan(
        self,
        route: Route,
        *,
        rth_altitude: float | None = None,
        exit_wayline_when_rc_lost: int | None = None,
        break_point: tuple[int, int, int] | None = None,
    ) -> Plan:
        t = self.adapter.telemetry
        if t.latitude is None or t.longitude is None:
            raise DeviceRejected(ResultCode.BUSY, "no position from the aircraft yet")
        home = self.home()
        options = PlanOptions(
            here=(t.latitude, t.longitude, t.height or 0.0),
            in_air=self.adapter.in_air,
            home=home,
            home_altitude=t.home_altitude,
            rth_altitude=rth_altitude,
            exit_wayline_when_rc_lost=exit_wayline_when_rc_lost,
            break_point=break_point,
            vel_cmd_range=self.adapter.settings.mission_vel_cmd_range,
            mission_max=self.mission_max,
            limits=self.adapter.limits,
        )
        return plan_route(route, options)

    def home(self) -> tuple[float, float]:
        """Where the aircraft took off (its position when last on the ground)."""
        t = self.adapter.telemetry
        if self.adapter.home_position is not None:
            return self.adapter.home_position
        return (t.latitude or 0.0, t.longitude or 0.0)

    # -- flying ----------------------------------------------------------------------------------
    async def ensure_control(self) -> None:
        """SDK control of the FC (``01 00`` obtain), as ``flight_authority_grab`` takes it, when not held:
        the FC refuses take-off and missions without it."""
        if not self.adapter.has_control:
            await self.adapter.obtain_control(1)

    async def take_off(self, timeout: float) -> None:
        """On the ground: the FC's take-off, then wait until airborne and the take-off has ended."""
        a = self.adapter
        if a.in_air:
            return
        await a.flight_task("takeoff")
        deadline = a.clock.monotonic() + timeout
        while not self._took_off():
            if a.clock.monotonic() > deadline:
                raise DeviceTimeout("the aircraft did not take off in time")
            await a.clock.sleep(POLL)

    def _took_off(self) -> bool:
        """Airborne, at least 1 m up, and the FC's own take-off over (display mode no longer 11)."""
        a, t = self.adapter, self.adapter.telemetry
        return a.in_air and (t.height or 0.0) >= 1.0 and t.display_mode != AUTO_TAKEOFF

    async def fly(
        self,
        plan: Plan,
        flight_id: str,
        on_reached: Callable[[Reached], None],
        on_entered: Callable[[], None],
    ) -> None:
        """Fly every mission of ``plan`` in order; returns when the last one finished. Raises
        DeviceRejected (FC refused or reported a mission error, ``result``), DeviceTimeout, or
        MissionStopped."""
        for k, mission in enumerate(plan.missions):
            self.adapter.require_no_mission()  # before the upload replaces what the FC holds
            await self._upload(mission)
            task = Task("wayline", flight_id, len(mission.waypoints))
            self._task = task
            self.adapter.begin_mission(task)
            speed = [float(mission.init["idle_vel"])]

            def reached(index: int, mission: FcMission = mission, speed: list[float] = speed) -> None:
                if index >= len(mission.points):
                    return
                ref = mission.points[index]
                if ref is not None:
                    on_reached(Reached(ref, mission.photos[index]))
                want = mission.speeds[index]
                if index + 1 < len(mission.points) and abs(want - speed[0]) > 1e-3:
                    speed[0] = want
                    change = asyncio.get_running_loop().create_task(self._set_speed(want))
                    self._speed_changes.add(change)
                    change.add_done_callback(self._speed_changes.discard)

            task.on_reached = reached
            await self.adapter.start_mission(task)
            if k == 0:
                on_entered()
            await self._until_over(task)
            if task.reached < len(mission.waypoints) - 1:
                raise MissionStopped("the mission was stopped")

    async def _until_over(self, task: Task) -> None:
        """Wait until the FC has finished ``task``'s mission; raise how it ended otherwise."""
        while task.live:
            if not self.adapter.online:
                # the FC flies its uploaded mission on its own (a ground-station mission needs no
                # host), but nothing it does can be reported or changed any more: the task fails
                raise DeviceNotConnected(f"aircraft {self.adapter.info.sn} lost during the mission")
            await self.adapter.clock.sleep(POLL)
        if task.failed is not None:
            ack = task.failed - GROUND_STATION_ACK_BASE
            text = f": {GS_ACK_TEXT[ack]} (0x{ack:02X})" if ack in GS_ACK_TEXT else ""
            raise DeviceRejected(task.failed, f"the flight controller reported a mission error{text}")
        if task.canceled:
            raise MissionStopped("the mission was stopped")
        if task.dropped is not None:
            if task.dropped == "emergency stop":
                raise MissionStopped("emergency stop: the flight controller braked and dropped the mission")
            raise DeviceRejected(ResultCode.BUSY, f"the flight controller ended the mission: {task.dropped}")

    # -- a mission found flying (after a restart) -------------------------------------------------
    def claim(self) -> Task | None:
        """The waypoint mission the FC flies that no run follows (the adapter adopted it), once."""
        task = self.adapter.current_mission
        if task is None or task.kind != "adopted" or not task.live or task is self._task:
            return None  # a continued fly-to or take-off reports itself (the adapter)
        self._task = task
        return task

    async def follow(self, task: Task, on_reached: Callable[[int], None]) -> None:
        """Follow an adopted mission to its end: ``on_reached`` with each waypoint index the FC reports;
        returns when the FC finished it, raises like :meth:`fly` otherwise."""
        task.on_reached = on_reached
        await self._until_over(task)

    async def _set_speed(self, speed: float) -> None:
        try:
            await self.adapter.ground_station("wp_set_idle_velocity", {"idle_velocity": speed})
        except Exception as exc:  # a missed speed change is logged; the mission goes on
            log.warning("aircraft %s: segment speed %.1f m/s not set: %s", self.adapter.info.sn, speed, exc)

    async def _upload(self, mission: FcMission) -> None:
        a = self.adapter
        await a.ground_station("wp_init", mission.init)
        for wp in mission.waypoints:
            ack = await a.ground_station("wp_upload", wp)
            if int(ack.fields.get("index", wp["index"])) != wp["index"]:
                raise DeviceRejected(
                    ResultCode.BUSY, f"waypoint {wp['index']} acknowledged as {ack.fields.get('index')}"
                )

    async def pause(self) -> None:
        await self.adapter.ground_station("wp_pause_resume", {"pause": 0})
        self.paused = True

    async def resume(self) -> None:
        await self.adapter.ground_station("wp_pause_resume", {"pause": 1})
        self.paused = False

    async def cancel(self) -> bool:
        """Stop the mission: the FC brakes and hovers where it is (the adapter's
        :meth:`stop_current_mission`; a FC that flies none has nothing left to stop). Returns whether the
        FC was flying it. The FC's own go home that no task of this process stands for (one started
        before a restart: the display mode says it flies) is exited all the same: the device is the truth."""
        current = self.adapter.current_mission
        if (current is None or not current.live) and self.fc_going_home:
            await self.adapter.exit_go_home()
            return True
        return await self.adapter.stop_current_mission()

    @property
    def fc_going_home(self) -> bool:
        """The FC flies its go home (display mode 15), whoever started it."""
        return self.adapter.display_mode == DM_GO_HOME

    async def go_home_altitude(self, rth_altitude: float | None) -> float | None:
        """The height the FC's go home will climb to (m above take-off), set first where the firmware can.
        New firmware: ``rth_altitude`` (clamped to the FC's 20..500 m) is written with ``01 42``; without
        one, the FC's own value is read (``01 41``: what the last take-off to point or task set). M100: the
        protocol has neither (DJI Assistant 2 sets it): the ``go_home_altitude`` setting, or None."""
        a = self.adapter
        if a.fw != "new":
            configured = a.settings.go_home_altitude
            return None if configured is None else float(configured)
        if rth_altitude is not None:
            lo, hi = GO_HOME_ALTITUDE_RANGE
            altitude = int(min(max(round(rth_altitude), lo), hi))
            await a.set_go_home_altitude(altitude)
            return float(altitude)
        return await a.read_go_home_altitude()

    def go_home_path(self, altitude: float | None) -> list[tuple[float, float, float]]:
        """The way the FC's go home flies (what ``return_home_info`` plans): up to ``altitude`` over the
        aircraft when it is lower, then over home at that height, where it lands: (latitude, longitude,
        height above take-off). Empty when the gateway does not know home (a restarted gateway that has
        not seen this aircraft on the ground): the FC knows it, the gateway cannot draw it."""
        t = self.adapter.telemetry
        home = self.adapter.home_position
        if home is None or t.latitude is None or t.longitude is None:
            return []
        h = max(altitude or 0.0, t.height or 0.0)
        return [(t.latitude, t.longitude, h), (home[0], home[1], h)]

    async def go_home(self, flight_id: str) -> None:
        """The FC's own go home (``01 01`` task 6: it climbs to its go-home altitude, flies home and
        lands; within 20 m of home DJI's FCs land where they are), followed as a task of kind ``go_home``
        (the FC's display mode says it runs). Whatever task flies is stopped first (its end reported):
        return home is the abort path of every task."""
        current = self.adapter.current_mission
        if current is not None and current.kind == "go_home" and current.live:
            return  # asked again while it goes home: the same go home (clouds resend)
        if current is not None and current.live:
            await self.adapter.stop_current_mission()
        await self.adapter.flight_task("go_home")
        task = Task("go_home", flight_id, 0)
        self._task = task
        self.adapter.begin_mission(task)
        self.adapter.mission_started(task)

    async def secure(self, flight_id: str, reason: str) -> str | None:
        """The wayline failed after the aircraft took off for it (or while it flew it): never leave it where
        it failed (the adapter's rule: land within 20 m of home, else the FC's go home). Returns what was
        done, in words (None: nothing: on the ground, or the RC has it)."""
        return await self.adapter.secure("wayline", flight_id, reason)

    @property
    def mission_running(self) -> bool:
        task = self._task
        return task is not None and task.live
