"""The Onboard SDK aircraft adapter: Cloud API flight methods → open-protocol commands on the UART;
flight-data, mission-status and mission-event pushes → osd, state and progress events.

Owns one flight controller: its :class:`~adapters.serial_link.SerialLink` (reopened when it fails),
the session layer (sessions 2–31 with retransmission of the *same* frame and ACKs matched by
session and seq, session 0 for movement control, ACKs for the FC's own frames and duplicate
suppression on receive), activation at start-up, the telemetry state, the fly-to / take-off tasks
that turn ground-station events into ``*_progress`` events, and the movement-control set-point the
DRC layer streams. Knows nothing of MQTT; reports through a :class:`~adapters.base.TelemetrySink`.

Mapping (see the README's table):

===========================  ======================================================================
Cloud API method             Onboard SDK commands
===========================  ======================================================================
flight_authority_grab        0x01 0x00 obtain (re-sent with a new seq while the FC says "in progress")
fly_to_point                 0x03 0x10 init (degrees → radians, WGS84 height → height above take-off,
                             ``max_speed`` → idle velocity), one 0x03 0x11 per point, 0x03 0x12 start;
                             then ``fly_to_point_progress`` from the 0x02 0x04 events and
                             every 0.5 s in between (remaining distance and time)
fly_to_point_stop            0x03 0x12 cancel → ``wayline_cancel``
takeoff_to_point             0x01 0x01 take-off; once airborne a 2-point mission (straight up to
                             ``security_takeoff_height``, then the target) with
                             ``takeoff_to_point_progress`` events; the climb is a mission of its
                             own when its RC-loss action differs from the flight to the point's
x_osdk_*                     the rest of seed 004 (extensions.py)
===========================  ======================================================================

Ground-station ACK codes map to 336000 + code (``schemas.results.ground_station_ack``) with the
seed's text in ``output.reason``; control ACKs that mean "the RC owns the aircraft" map to 319030.
Heights: the Cloud API's are WGS84 (``height``, ``target_height``); waypoints are relative to the
take-off point, so the adapter subtracts the home altitude (telemetry ``altitude − height``).

Why this module is longer than 500 lines: it is one flight controller's session: the link, the
session layer (sessions, resends, ACKs), activation, the telemetry it decodes, the truth it holds the
gateway's intent against, and the Cloud API methods, which all share one command path and one view of the
FC. What can stand alone already does: the codec (commands.py, protocol.py, telemetry.py), the mission
record, mode table and reconciliation (mission.py), the route planner (wayline_plan.py) and the runner
(wayline.py).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import secrets
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from adapters.base import AircraftPose, CallResult, DeviceInfo, Handler, TelemetrySink
from adapters.clock import SYSTEM_CLOCK, Clock
from adapters.errors import (
    DeviceNotConnected,
    DeviceRejected,
    DeviceTimeout,
    InvalidParameters,
    LinkError,
    SessionsExhausted,
    UnknownCommandError,
)
from adapters.osdk import commands as cmds
from adapters.osdk.config import DEFAULT_FREQUENCIES, OsdkDeviceSettings
from adapters.osdk.extensions import (
    FollowMeStart,
    FollowMeTarget,
    HotpointStart,
    IdleVelocity,
    Pause,
)
from adapters.osdk.limits import LimitBreach, MissionLimits, after_failure, check_mission, flat_distance
from adapters.osdk.mission import (
    AUTOMATIC,
    DM_AUTO_LANDING,
    DM_AUTO_TAKEOFF,
    DM_GO_HOME,
    DM_SDK_CONTROL,
    KIND_WORDS,
    STATUS_STALE,
    FcMissionState,
    Task,
    reconcile,
)
from adapters.osdk.mission import mode_code as compute_mode_code
from adapters.osdk.protocol import Decoder, DuplicateFilter, Frame, SessionMode, SessionTable
from adapters.osdk.telemetry import ITEMS as _TELEMETRY_ITEMS
from adapters.osdk.wayline import OsdkWayline
from adapters.serial_link import SerialLink
from adapters.supervision import SupervisedAdapter
from adapters.wire.layout import LayoutError
from adapters.wire.stream import BadFrame
from adapters.wire.table import bind_handlers
from schemas.envelope import EmptyRequest
from schemas.results import GROUND_STATION_ACK_BASE, ResultCode, ground_station_ack, meaning
from schemas.services import FlightAuthorityGrab, FlyToPoint, FlyToPointStop, TakeoffToPoint

log = logging.getLogger(__name__)

__all__ = ["AircraftAdapter", "Task"]

EARTH_RADIUS_M = 6_378_137.0
OBTAIN_RETRIES = 5  # "in progress" answers before giving up
CONTROL_OBTAINED, CONTROL_RELEASED = 0x0002, 0x0001
CONTROL_IN_PROGRESS = (0x0003, 0x0004)
CONTROL_RC_OWNS = (0x0000, 0x0005, 0x0006)
MISSION_NOT_RUNNING = 0xD4  # ground-station ACK: no mission is running
STILL_SPEED = 0.3  # m/s: slower than this (3-D), an aircraft found after a restart is hovering
CONTROL_DEVICE_SDK = 2  # the control-device item's device_status: 0 RC, 1 mobile app, 2 onboard (SDK)
AUTO_TAKEOFF = 11  # display mode while the FC's own take-off runs: missions are refused until it ends
#: fly_to_point_progress while flying between points: twice a second, so the cloud hears from the flight
#: at least once a second (DJI's devices report it continuously; the seed's waypoint events alone leave a
#: 250 m leg silent for its whole 24 s)
PROGRESS_INTERVAL = 0.5
EARTH_RADIUS = 6_378_137.0  # m (WGS84 equatorial): the local flat-earth distances of progress events
MAX_MISSION_POINTS = 255  # the mission init's u8 length (seed 004 0x03 0x10)
MIN_WAYPOINT_SPACING = 0.5  # m between neighbouring waypoints (the FC refuses closer ones: 0xE5)
#: takeoff_to_point's rc_lost_action (Cloud API enum) as the ``rc_lost_action`` setting names it
_RC_LOST_ACTIONS = {0: "hover", 1: "land", 2: "return_home"}
#: an M100's flight status (1 standby, 2 taking off, 3 in air, 4 landing, 5 landed) as a display mode
_M100_DISPLAY = {2: DM_AUTO_TAKEOFF, 4: DM_AUTO_LANDING}


@dataclass
class Telemetry:
    """What the FC last told us, in Cloud API units (degrees, metres, m/s)."""

    latitude: float | None = None
    longitude: float | None = None
    altitude: float | None = None  # WGS84 (m)
    height: float | None = None  # above take-off (m)
    velocity: tuple[float, float, float] | None = None  # north, east, up
    attitude: tuple[float, float, float] | None = None  # roll, pitch, yaw (°)
    gimbal: tuple[float, float, float] | None = None
    flight: int | None = None  # 0 stopped, 1 on ground, 2 in air
    display_mode: int | None = None
    battery_percent: int | None = None
    battery_voltage: int | None = None
    battery_current: int | None = None
    #: obstacle distances (m) and sensor health by direction, new firmware only (position item)
    obstacles: dict[str, tuple[float, bool]] | None = None

    @property
    def home_altitude(self) -> float | None:
        if self.altitude is None or self.height is None:
            return None
        return self.altitude - self.height


def _leg(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    """Straight-line distance (m) between two (lat, lon, height) points, flat-earth (legs of a fly-to are
    at most a few km: the error is far below a metre)."""
    north = math.radians(b[0] - a[0]) * EARTH_RADIUS
    east = math.radians(b[1] - a[1]) * EARTH_RADIUS * math.cos(math.radians((a[0] + b[0]) / 2))
    return math.sqrt(north * north + east * east + (b[2] - a[2]) ** 2)


def _distance_3d(a: tuple[float, float, float], b: tuple[float, float, float]) -> float:
    """Metres between two (lat°, lon°, height m) points, flat earth (waypoints are close together)."""
    north = math.radians(b[0] - a[0]) * EARTH_RADIUS_M
    east = math.radians(b[1] - a[1]) * EARTH_RADIUS_M * math.cos(math.radians(a[0]))
    return math.sqrt(north * north + east * east + (b[2] - a[2]) ** 2)


def _quat_to_euler(w: float, x: float, y: float, z: float) -> tuple[float, float, float]:
    """Roll, pitch, yaw in degrees from the FC's body-to-ground quaternion."""
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return (math.degrees(roll), math.degrees(pitch), math.degrees(yaw))


class AircraftAdapter(SupervisedAdapter):
    noun = "aircraft"
    _log = log
    _link: SerialLink | None

    def __init__(self, settings: OsdkDeviceSettings, *, clock: Clock = SYSTEM_CLOCK) -> None:
        self.settings = settings
        self.fw = settings.firmware
        self.codes = cmds.FIRMWARE_CODES[self.fw]  # task codes, ACKs and status values of this firmware
        self._task_seq = 0  # M100 flight tasks carry a command sequence number
        super().__init__(DeviceInfo.of(settings.sn, settings.product), settings, clock)
        self.deadline = settings.deadline
        self._decoder = Decoder()
        # each command waiting for its ACK is tagged with its waiter: the future and the command's name
        # The first seq is random: the FC remembers the last seq per session and answers a repeat with the
        # stored ACK instead of acting, and it does not know that this is a new process. A restarted
        # gateway that counted from 0 again would have its first commands taken for resends of the old
        # process's (seen with the simulator in its own process: a pause got an activation's ACK).
        self._sessions: SessionTable[tuple[asyncio.Future[cmds.Message], str]] = SessionTable(
            first_seq=secrets.randbelow(0x10000)
        )
        self._dups = DuplicateFilter()
        self.activated = False
        self._next_activation = 0.0  # when an unactivated FC is next asked (version, activation, rates)
        self.version: str | None = None  # the version name, e.g. "SDK-v1.1 BETA A3-03.03.100.00"
        self.hardware: str | None = None  # e.g. "A3", from the version name
        self.firmware_version: str | None = None  # e.g. "03.03.100.00", from the version name
        self.activation_error: str | None = None
        self.telemetry = Telemetry()
        self.has_control = False
        #: the mission task the FC flies (intent; :mod:`adapters.osdk.mission` reconciles it with the FC)
        self.mission: Task | None = None
        #: the FC's waypoint mission as its pushes say (the truth the task is held against)
        self.fc = FcMissionState()
        self._disagree_since: float | None = None
        #: a stop the gateway asked of the FC itself (an emergency brake, the RC taking over): the reason
        #: a mission the FC then drops ended with. Written from the DRC writer thread (a str assignment)
        self._stop_requested: str | None = None
        self._mission_ended_at = float("-inf")  # when the last task ended (its status pushes fade after)
        self._ended_task: Task | None = None
        #: who the FC says controls it (the control-device item: 0 RC, 1 mobile app, 2 onboard/SDK), None
        #: until it said so on this link
        self.control_device: int | None = None
        self._safety_check_due = False  # after each (re)activation, once the FC's state is known
        #: when live control last drove the aircraft (drive(); the DRC writer thread)
        self.driven_at = float("-inf")
        self.safety_stops = 0  # restarts or reconnects that found the aircraft moving with nobody driving
        #: where the aircraft last stood on the ground (latitude, longitude): the home of a wayline's RTH
        self.home_position: tuple[float, float] | None = None
        self.wayline = OsdkWayline(self)
        self._mission_task: asyncio.Task[None] | None = None
        self.unmatched_replies = 0  # ACKs after their deadline or for no request (metrics)
        self.handlers = {
            "flight_authority_grab": self._grab,
            "fly_to_point": self._fly_to_point,
            "fly_to_point_stop": self._fly_to_point_stop,
            "takeoff_to_point": self._takeoff_to_point,
            **{method: self._online_only(call) for method, call in self._extension_calls().items()},
        }

    # -- life cycle -------------------------------------------------------------------------------
    async def start(self, sink: TelemetrySink) -> None:
        self._sink = sink
        loop = asyncio.get_running_loop()
        s = self.settings
        self._link = SerialLink(
            url=s.url,
            baudrate=s.baudrate,
            loop=loop,
            on_bytes=self._on_bytes,
            on_down=self._on_link_down,
            options=s.serial_options,
        )
        self._tasks += [
            loop.create_task(self._supervise(), name=f"osdk-{s.sn}-supervisor"),
            loop.create_task(self._retransmit(), name=f"osdk-{s.sn}-sessions"),
        ]

    async def stop(self) -> None:
        self._stopping = True
        with contextlib.suppress(Exception):
            await self.stop_motion()
        if self.settings.release_on_stop and self.has_control and self._link is not None and self._link.up:
            with contextlib.suppress(Exception):
                # real time: a stopping gateway stops even when nobody advances a test's clock
                await asyncio.wait_for(self.command("obtain_control", {"control": 0}), 1.0)
        await self._end_supervision(self._mission_task)
        self._fail_pending(DeviceNotConnected(f"aircraft {self.info.sn} adapter stopped"))

    async def stop_motion(self) -> None:
        """Failsafe: zero velocity with the stable bit (brake and hover), sent at once on session 0,
        without waiting for anything; then what ``on_stop`` says (a mission in flight is cancelled)."""
        self.send_movement(0.0, 0.0, 0.0, 0.0)
        task = self.mission
        if task is not None and task.live:
            with contextlib.suppress(Exception):
                self._fire("wp_start_stop", {"start": 1})
            # the cloud hears the task's end (its final progress event), as after fly_to_point_stop
            task.finished = task.canceled = True
            if self._mission_task is not None:
                self._mission_task.cancel()
            self._progress(task, "wayline_cancel", task.reached - task.offset)
        if self.settings.on_stop == "land" and self.in_air:
            with contextlib.suppress(Exception):
                self._fire("flight_task", self._task_fields("landing"))
        elif self.settings.on_stop == "go_home" and self.in_air:
            with contextlib.suppress(Exception):
                self._fire("flight_task", self._task_fields("go_home"))

    def _broadcast_codes(self) -> list[int]:
        """The 0x00 0x10 rate codes: one per flight-data item, in this firmware's item order. The default
        rates are written in the new firmware's order; an M100 gets the same rate per item *name* (its
        status is item 9, not 11). A list from the configuration is sent as written."""
        codes = list(self.settings.frequencies)
        if self.fw == "new" or codes != DEFAULT_FREQUENCIES:
            return codes
        rate = dict(zip((it.name for it in _TELEMETRY_ITEMS["new"]), codes, strict=False))
        legacy = [rate.get(it.name, 0) for it in _TELEMETRY_ITEMS[self.fw]]
        return legacy + [0] * (len(codes) - len(legacy))

    @property
    def in_air(self) -> bool:
        return self.telemetry.flight in self.codes.in_air

    def _task_fields(self, task: str) -> dict[str, Any]:
        code = self.codes.tasks.get(task)
        if code is None:  # e.g. exit go home on an M100: its legacy flight tasks have none
            raise DeviceRejected(ResultCode.BUSY, f"flight task {task} does not exist on {self.fw} firmware")
        fields: dict[str, Any] = {"command": code}
        if self.fw == "m100":
            self._task_seq = (self._task_seq + 1) & 0xFF
            fields["cmd_sequence"] = self._task_seq
        return fields

    # -- movement control (used by DRC) ------------------------------------------------------------
    def send_movement(self, forward: float, right: float, up: float, yaw_rate: float) -> None:
        """One 0x01 0x03 frame: body-frame velocities (m/s) and yaw rate (°/s), stable bit set, on
        session 0 (no ACK); nothing while the adapter does not hold control (never obtained, released,
        or taken back by the RC): the aircraft is no longer ours to steer, so a shutdown after a
        release sends no zero-velocity frames. A link that is down drops the frame."""
        if not self.has_control:
            return
        flag = cmds.control_flag(
            cmds.HORIZONTAL_VELOCITY, cmds.VERTICAL_VELOCITY, cmds.YAW_RATE, cmds.FRAME_BODY, stable=True
        )
        fields = {"flag": flag, "x": forward, "y": right, "z": up, "yaw": yaw_rate}
        with contextlib.suppress(LinkError):
            self._fire("movement_control", fields)

    def emergency_brake(self) -> None:
        if not self.has_control:  # as send_movement: no control frame to an aircraft we do not control
            return
        with contextlib.suppress(LinkError):
            self._fire("emergency_brake", {})

    def drive(self, forward: float, right: float, up: float, yaw_rate: float) -> bool:
        """Live control: one movement-control frame. Thread-safe: it only encodes and queues (session 0
        takes no ACK; two threads drawing the global seq at once can at worst repeat a seq on session 0,
        which the FC does not check)."""
        if not self.has_control or self._link is None or not self._link.up:
            return False
        self.driven_at = self._now()
        self.send_movement(forward, right, up, yaw_rate)
        return True

    def emergency_stop(self) -> None:
        """Brake now (the 26-byte emergency brake, firmware >= 3.2.36.6; an M100 has none) and zero
        velocity with the stable bit after it. A mission the FC drops for it ends as stopped by it."""
        self._stop_requested = "emergency stop"
        if self.codes.emergency_brake:
            self.emergency_brake()
        self.send_movement(0.0, 0.0, 0.0, 0.0)

    # -- link supervision (the loop is SupervisedAdapter's) ----------------------------------------
    def _on_link_opened(self) -> None:
        self._decoder.reset()
        self._dups.reset()  # a frame on the new link is no resend of one on the old, whatever its seq
        self.activated = False
        self._next_activation = 0.0
        # what the FC said on the old link no longer holds: read it again before acting on it
        self.control_device = None
        self.telemetry.flight = None
        self.fc.reset()

    async def _supervise_tick(self, now: float) -> None:
        """Activate first (the FC stays offline until activated, and answers nothing else before),
        retrying every 3 s; then the silence check."""
        if not self.activated and now >= self._next_activation:
            self._next_activation = now + 3.0
            await self._activate()
        if self.activated:
            self._truth(now)
        self._check_silence(now)

    # -- the FC is the source of truth (adapters/osdk/mission.py) -----------------------------------
    @property
    def clock(self) -> Clock:
        return self._clock

    @property
    def display_mode(self) -> int | None:
        return self.telemetry.display_mode

    @property
    def current_mission(self) -> Task | None:
        return self.mission

    def begin_mission(self, task: Task) -> None:
        """``task`` is the mission the FC flies from now on: its pushes go to it. Refused while another
        task is live (the FC would refuse the start, 0xD5, after the upload had replaced what it holds):
        whoever means to replace one stops it first (:meth:`stop_current_mission`)."""
        self.require_no_mission()
        self.mission = task
        self._stop_requested = None
        self._disagree_since = None

    def require_no_mission(self) -> None:
        """Raise (314000, naming it) while a task is live: checked before anything is uploaded."""
        old = self.mission
        if old is not None and old.live:
            what = KIND_WORDS.get(old.kind, old.kind)
            name = f" {old.task_id}" if old.task_id else ""
            raise DeviceRejected(
                ResultCode.BUSY, f"{what}{name} is flying: stop it first (or return home, which does)"
            )

    async def stop_current_mission(self) -> bool:
        """Stop whatever task the FC flies for the gateway (a mission: ``03 12`` cancel; the FC's go home:
        exit go home) and end it canceled, told to whoever follows it. A FC that flies no mission (0xD4)
        has nothing left to stop: the task ends all the same. Returns whether the FC was flying one."""
        task = self.mission
        flying = True
        if task is not None and task.kind == "go_home" and task.live:
            await self.exit_go_home()  # the FC hovers where it is
        else:
            try:
                await self.ground_station("wp_start_stop", {"start": 1})
            except DeviceRejected as exc:
                # 0xD4 "mission not running": the FC flies nothing (the device is the truth); any other
                # refusal is the answer
                if exc.detail.get("ack") != MISSION_NOT_RUNNING:
                    raise
                flying = False
            self.mission_stopped()
        if task is not None and task.live:
            task.finished = task.canceled = True  # no wayline_ok for a cancelled task
            task.done.set()
            if task.kind in ("fly_to", "takeoff"):
                if self._mission_task is not None:
                    self._mission_task.cancel()
                self._progress(task, "wayline_cancel", task.reached - task.offset)
        return flying

    async def exit_go_home(self) -> None:
        """End the FC's go home in whichever phase it is: flying home (exit go home) or landing at home
        (exit landing; the new firmware's task 14). The display mode says which; it lags the FC by up to
        one push, so the other is tried when the first is refused."""
        landing = self.telemetry.display_mode == DM_AUTO_LANDING
        order = ["exit_landing", "exit_go_home"] if landing else ["exit_go_home", "exit_landing"]
        order = [name for name in order if name in self.codes.tasks] or ["exit_go_home"]  # M100: refused
        for k, name in enumerate(order):
            try:
                await self.flight_task(name)
                return
            except DeviceRejected:
                if k == len(order) - 1:
                    raise

    def mission_started(self, task: Task) -> None:
        """The FC acknowledged the start of ``task``'s mission: from now on it may disagree."""
        task.started = True

    async def start_mission(self, task: Task) -> None:
        """``03 12`` start for the uploaded mission ``task`` stands for; a start the FC refuses (or does not
        answer) ends the task with that result, so no task is left waiting for a mission that never ran."""
        try:
            await self.ground_station("wp_start_stop", {"start": 0})
        except DeviceRejected as exc:
            task.failed = int(exc.result)
            task.done.set()
            raise
        except (DeviceTimeout, DeviceNotConnected):
            task.failed = int(ResultCode.DEVICE_TIMEOUT)
            task.done.set()
            raise
        self.mission_started(task)

    def mission_stopped(self) -> None:
        """The FC acknowledged a stop (or said no mission runs): its last status push no longer holds."""
        self.fc.status_at = float("-inf")

    def fc_mission_running(self) -> bool:
        """Does the FC fly (or hold, paused) a waypoint mission, by its own pushes?"""
        return self.fc.running(self.telemetry.display_mode, self._now())

    def autonomous_task(self) -> str | None:
        """What flies the aircraft on its own now (take-off, landing, go home, a mission), in words; None
        when nothing does. Live control's sticks are refused while one does: the FC ignores movement
        control then, and a stick answered 0 would be a lie."""
        t = self.telemetry
        if t.flight is None:
            return None
        dm = t.display_mode
        if dm is not None and dm in AUTOMATIC and (self.in_air or dm == DM_AUTO_TAKEOFF):
            return AUTOMATIC[dm]
        if self.in_air and self.fc_mission_running():
            task = self.mission
            return KIND_WORDS.get(task.kind, "waypoint mission") if task is not None else "waypoint mission"
        task = self.mission
        if task is not None and task.live and task.started:
            return KIND_WORDS.get(task.kind, "mission")
        return None

    def _truth(self, now: float) -> None:
        """Hold the gateway's intent against what the FC reports, every supervision pass (0.1 s)."""
        t = self.telemetry
        if t.flight is None:
            return  # nothing reported on this link yet
        if self._safety_check_due and self.control_device is not None:
            self._safety_check_due = False
            self._safety_check(now)
        task = self.mission
        if task is not None and task.kind == "go_home" and task.live and task.started and not self.in_air:
            task.finished = True  # the FC's go home ends on the ground at home
            task.done.set()
        mission_running = running = self.fc.running(t.display_mode, now)
        if task is not None and task.kind == "go_home":
            running = t.display_mode in (DM_GO_HOME, DM_AUTO_LANDING)  # the FC's own, not a mission
        broken = self.fc.broken_at >= now - 1.0 and self.fc.broken_at > self._mission_ended_at
        verdict, self._disagree_since = reconcile(
            task,
            running,
            disagree_since=self._disagree_since,
            now=now,
            stop_requested=self._stop_requested,
            broken=broken,
        )
        if verdict is not None and task is not None:
            self._drop(task, verdict.reason, now)
            return
        if task is not None and not task.live and task is not self._ended_task:
            self._ended_task = task  # ended here (finished, stopped, failed): its status pushes fade
            self._mission_ended_at = now
            self._forget(task)
        if (
            mission_running
            and self.in_air
            and (task is None or not task.live)
            and now - self._mission_ended_at > STATUS_STALE + 0.5
        ):
            self._adopt(now)

    def _drop(self, task: Task, reason: str, now: float) -> None:
        """The FC no longer flies ``task``: it ends, with the reason, and whoever follows it is told."""
        task.dropped = reason
        task.done.set()
        self._mission_ended_at = now
        self._ended_task = task
        self._forget(task)
        self._stop_requested = None
        log.warning(
            "aircraft %s: %s %s ended by the flight controller: %s",
            self.info.sn,
            KIND_WORDS.get(task.kind, task.kind),
            task.task_id or "(adopted)",
            reason,
        )
        self._notify("mission_ended", reason, task.task_id)

    # -- the task journal: a fly-to or take-off continues under its id after a restart -----------------
    def _remember(self, task: Task) -> None:
        if self.journal is None:
            return
        data = {"points": task.points, "offset": task.offset, "path": task.path, "speed": task.speed,
                "planned": task.planned}  # fmt: skip
        try:
            self.journal.remember(self.info.sn, task.kind, task.task_id, data)
        except Exception:  # a full disk must not stop a flight
            log.exception("aircraft %s: could not keep task %s", self.info.sn, task.task_id)

    def _forget(self, task: Task) -> None:
        if self.journal is not None and task.kind in ("fly_to", "takeoff"):
            with contextlib.suppress(Exception):
                self.journal.forget(self.info.sn, task.task_id)

    def _continued(self) -> Task | None:
        """The fly-to or take-off this device started before a restart, as the journal kept it."""
        kept = None
        if self.journal is not None:
            with contextlib.suppress(Exception):
                kept = self.journal.recall(self.info.sn)
        if kept is None or kept[0] not in ("fly_to", "takeoff"):
            return None
        kind, task_id, d = kept
        path = [(float(a), float(b), float(c)) for a, b, c in d.get("path", [])]
        task = Task(kind, task_id, int(d.get("points", 0)), offset=int(d.get("offset", 0)), path=path,
                    started=True, adopted=True)  # fmt: skip
        task.speed = float(d.get("speed", 0.0))
        task.planned = list(d.get("planned", []))
        return task

    def _adopt(self, now: float) -> None:
        """A waypoint mission the FC flies that no task knows of (the gateway restarted mid-mission, or
        another host started it): a task follows it, so its progress is reported and pause, recovery,
        return home and stop act on it. A fly-to or take-off to point the journal kept continues under its
        id, reported here; any other is claimed by the wayline runner (:meth:`OsdkWayline.claim`)."""
        continued = self._continued()
        if continued is not None:
            continued.reached = (self.fc.target or 0) - 1
            self.mission = continued
            self._disagree_since = None
            log.warning(
                "aircraft %s: the flight controller is flying %s %s (started before a restart): following it",
                self.info.sn,
                KIND_WORDS[continued.kind],
                continued.task_id,
            )
            self._notify("mission_adopted", f"{KIND_WORDS[continued.kind]} continued", continued.task_id)
            self._start_watch(continued)
            return
        task = Task("adopted", "", points=0, started=True, adopted=True)
        task.reached = (self.fc.target or 0) - 1
        self.mission = task
        self._disagree_since = None
        log.warning(
            "aircraft %s: the flight controller is flying a waypoint mission the gateway did not start "
            "in this process (target waypoint %s): following it",
            self.info.sn,
            self.fc.target,
        )
        self._notify("mission_adopted", "a waypoint mission was running on the flight controller", "")

    def _safety_check(self, now: float) -> None:
        """After every (re)activation: an aircraft in the air under SDK control that nothing here drives
        (the gateway restarted, or the link came back, mid live control) is stopped: zero velocity with the
        stable bit, the emergency brake where the firmware has it, zero again. The FC may hold the last
        set-point without limit (what a real A3/N3 does is not documented), so nothing else would stop it.
        A mission or the FC's own automatic task is left to fly (it is adopted and reported instead)."""
        t = self.telemetry
        sdk = self.control_device == CONTROL_DEVICE_SDK
        if sdk:
            self.has_control = True  # the FC says so, whatever this process believed
        if not (self.in_air and sdk):
            return
        if now - self.driven_at < 1.0:
            return  # live control streams set-points: it governs the motion
        if self.fc.running(t.display_mode, now) or (t.display_mode in AUTOMATIC):
            return
        speed = math.hypot(*t.velocity[:2]) if t.velocity is not None else float("nan")
        moving = t.velocity is None or math.hypot(*t.velocity) > STILL_SPEED
        if not moving and t.display_mode != DM_SDK_CONTROL:
            # hovering on its own (the FC's hold expired, or nothing was ever set): nothing to stop
            log.info("aircraft %s: in the air under SDK control, hovering: nothing to stop", self.info.sn)
            return
        self.safety_stops += 1
        self.send_movement(0.0, 0.0, 0.0, 0.0)
        self.emergency_stop()
        self._stop_requested = None  # no task to end: the stop is the whole story
        log.warning(
            "aircraft %s: found in the air under SDK control with nothing driving it (horizontal speed "
            "%.1f m/s, display mode %s): stopped it (zero velocity, brake)",
            self.info.sn,
            speed,
            t.display_mode,
        )
        self._notify(
            "stopped",
            f"in the air under SDK control with nothing driving it (horizontal speed {speed:.1f} m/s)",
            "",
        )

    def _notify(self, action: str, reason: str, task_id: str) -> None:
        if self._sink is not None:
            data = {"action": action, "reason": reason[:300], "task_id": task_id}
            self._sink.event(self.info.sn, "x_osdk_safety_notify", data, need_reply=False)

    def _on_went_silent(self, now: float) -> None:
        # a silent FC may have restarted, which forgets the activation: redo it on the next pass
        self.activated = False
        self._next_activation = now

    async def _activate(self) -> None:
        """Version, activation, broadcast rates: the FC ignores other command sets until activated."""
        s = self.settings
        try:
            ver = await self.command("get_version", {"arbitrary": 0})
            try:
                info = cmds.parse_version_reply(int(ver.fields["ack"]), bytes(ver.fields["version_data"]))
            except ValueError as exc:
                log.warning("aircraft %s: unreadable version reply: %s", self.info.sn, exc)
            else:
                changed = (info.hardware, info.firmware) != (self.hardware, self.firmware_version)
                self.version, self.hardware, self.firmware_version = info.name, info.hardware, info.firmware
                if changed and self._sink is not None and self.online:
                    self._sink.state(self.info.sn, self.state_snapshot() or {})
            ack = await self.command(
                "activate",
                {"app_id": s.app_id, "api_level": s.api_level, "fw_version": s.activation_version},
            )
            code = ack.fields["ack"]
            if code != 0:
                text = cmds.ACTIVATION_ACK.get(code, "unknown code")
                if self.activation_error != text:
                    log.error("aircraft %s refused activation: %s (code %d)", self.info.sn, text, code)
                self.activation_error = text
                return
            self.activation_error = None
            await self.command("set_broadcast_frequency", {"frequency": self._broadcast_codes()})
            self.activated = True
            self._safety_check_due = True
            log.info("aircraft %s activated (firmware %s)", self.info.sn, self.version or "?")
        except (DeviceTimeout, DeviceNotConnected) as exc:
            log.info("aircraft %s: activation pending: %s", self.info.sn, exc)
        except DeviceRejected as exc:
            log.warning("aircraft %s: activation step failed: %s", self.info.sn, exc)

    async def _retransmit(self) -> None:
        """Resend unanswered frames (same session, same seq) and fail those out of retries."""
        while not self._stopping:
            res = self._sessions.poll(self._now())
            for frame in res.resend:
                with contextlib.suppress(LinkError):
                    self._write(frame)
            for p in res.expired:
                if p.tag is None:
                    continue  # nothing waits for it
                fut, name = p.tag
                if not fut.done():
                    fut.set_exception(DeviceTimeout(f"aircraft {self.info.sn} did not acknowledge {name}"))
            await self._clock.sleep(0.02)

    def _on_link_down(self, reason: str) -> None:
        super()._on_link_down(reason)
        self.activated = False
        self._fail_pending(DeviceNotConnected(f"aircraft {self.info.sn} serial link down"))

    def _fail_pending(self, exc: Exception) -> None:
        for p in self._sessions.clear():
            if p.tag is None:
                continue  # nothing waits for it
            fut, _ = p.tag
            if not fut.done():
                fut.set_exception(exc)

    # -- send -------------------------------------------------------------------------------------
    def _write(self, frame: bytes) -> None:
        if self._link is None:
            raise LinkError("not started")
        self._link.write(frame)

    def _fire(self, name: str, fields: Mapping[str, Any]) -> None:
        """Send a command without waiting for its ACK (session 0 commands, failsafe paths)."""
        spec = cmds.spec_for(name, self.fw)
        payload = cmds.encode_request(name, fields, self.fw)
        sent = self._sessions.send(*spec.set_and_id, payload, now=self._now(), mode=SessionMode.NO_ACK)
        self._write(sent.frame)

    async def command(self, name: str, fields: Mapping[str, Any] | None = None) -> cmds.Message:
        """Send one command and wait for its ACK (retransmitted per the command's session rules)."""
        if self._link is None or not self._link.up:
            raise DeviceNotConnected(f"aircraft {self.info.sn} is not connected")
        spec = cmds.spec_for(name, self.fw)
        try:
            payload = cmds.encode_request(name, fields, self.fw)
        except LayoutError as exc:
            raise InvalidParameters(f"{name}: {exc}") from None
        if spec.delivery.session == SessionMode.NO_ACK or not spec.reply:
            self._fire(name, fields or {})
            return cmds.Message(name, spec.cmd_set, spec.cmd_id, {}, is_reply=True)
        fut: asyncio.Future[cmds.Message] = asyncio.get_running_loop().create_future()
        try:
            sent = self._sessions.send(
                *spec.set_and_id,
                payload,
                now=self._now(),
                mode=SessionMode(spec.delivery.session),
                timeout=spec.delivery.timeout,
                retries=spec.delivery.retries,
                tag=(fut, name),
            )
        except SessionsExhausted:
            raise DeviceRejected(ResultCode.BUSY, "all Onboard SDK sessions are busy") from None
        try:
            self._write(sent.frame)
        except LinkError as exc:
            raise DeviceNotConnected(str(exc)) from None
        return await fut

    # -- receive ---------------------------------------------------------------------------------
    def _on_bytes(self, data: bytes) -> None:
        for item in self._decoder.feed(data):
            if isinstance(item, BadFrame):
                continue
            try:
                self._on_frame(item)
            except Exception:  # one bad frame must not stop the link
                log.exception("aircraft %s: failed to handle a frame", self.info.sn)

    def _on_frame(self, frame: Frame) -> None:
        if frame.is_ack:
            p = self._sessions.on_ack(frame)
            if p is None:
                self.unmatched_replies += 1  # late (after its deadline) or unknown: never matched to anything
                return
            if p.tag is None:
                return  # nothing waits for it
            fut, name = p.tag
            if fut.done():
                return
            try:
                fut.set_result(cmds.decode_ack(name, frame.data, self.fw))
            except LayoutError as exc:
                fut.set_exception(DeviceRejected(ResultCode.BUSY, f"unreadable {name} ACK: {exc}"))
            return
        verdict = self._dups.check(frame)
        if verdict.duplicate:
            if verdict.resend is not None:
                with contextlib.suppress(LinkError):
                    self._write(verdict.resend)
            return
        if frame.cmd_set is None or frame.cmd_id is None:
            return
        try:
            msg = cmds.decode_request(frame.cmd_set, frame.cmd_id, frame.payload, self.fw)
        except (UnknownCommandError, LayoutError):
            msg = None
        if frame.session >= 1:
            with contextlib.suppress(LinkError, LayoutError):
                ack_name = msg.name if msg is not None else "lost_authority_push"
                self._write(self._dups.ack(frame, cmds.encode_ack_payload(ack_name, {"ack": 0}, self.fw)))
        if msg is None:
            return
        handler = _PUSHES.get(msg.name)
        if handler is not None:
            handler(self, msg.fields)

    def _on_flight_data(self, f: Mapping[str, Any]) -> None:
        t = self.telemetry
        pos = f.get("position")
        if pos is not None:
            t.latitude, t.longitude = math.degrees(pos["latitude"]), math.degrees(pos["longitude"])
            t.altitude, t.height = float(pos["altitude"]), float(pos["height"])
            if "obstacle_front" in pos:
                t.obstacles = {
                    side: (float(pos[f"obstacle_{side}"]), bool(pos.get(f"{side}_health", 0)))
                    for side in ("front", "right", "back", "left", "up", "down")
                }
        vel = f.get("velocity")
        if vel is not None:
            t.velocity = (float(vel["x"]), float(vel["y"]), float(vel["z"]))
        q = f.get("quaternion")
        if q is not None:
            t.attitude = _quat_to_euler(q["w"], q["x"], q["y"], q["z"])
        gimbal = f.get("gimbal")
        if gimbal is not None:
            t.gimbal = (float(gimbal["roll"]), float(gimbal["pitch"]), float(gimbal["yaw"]))
        status = f.get("status")
        if status is not None:
            t.flight = int(status["flight"])
            if "display_mode" in status:
                t.display_mode = int(status["display_mode"])
            else:  # an M100 reports no display mode: its flight status names take-off (2) and landing (4)
                t.display_mode = _M100_DISPLAY.get(t.flight)
        device = f.get("control_device")
        if device is not None:
            controller = int(device.get("device_status", 0))
            if controller != self.control_device:
                # who controls the FC comes from the FC; read on every change (an obtain's ACK sets it
                # between the 1 Hz reports, and an unchanged report does not undo that)
                self.control_device = controller
                self.has_control = controller == CONTROL_DEVICE_SDK
        if t.flight is not None and not self.in_air and t.latitude is not None and t.longitude is not None:
            self.home_position = (t.latitude, t.longitude)
        battery = f.get("battery")
        if battery is not None:
            t.battery_percent = int(battery["percentage"])
            t.battery_voltage = int(battery.get("voltage", 0))
            t.battery_current = int(battery.get("current", 0))
        self._last_heard = self._now()
        if self.activated:
            self._set_online(True)

    def _on_status(self, f: Mapping[str, Any]) -> None:
        self.fc.on_status(f, self._now())
        task = self.mission
        if task is None or f.get("mission_type") != 1:
            return
        err = int(f.get("error_notification", 0))
        if err and not task.finished:
            task.failed = ground_station_ack(err) if err < 1000 else ResultCode.BUSY
            task.done.set()

    def _on_event(self, f: Mapping[str, Any]) -> None:
        task = self.mission
        if task is None:
            return
        incident = f.get("incident_type")
        if incident == 2:  # waypoint reached
            index = int(f["waypoint_index"])
            if index > task.reached:
                task.reached = index
                if task.on_reached is not None:
                    task.on_reached(index)
                if index >= task.offset:
                    self._progress(task, "wayline_progress", index - task.offset)
        elif incident == 1:  # mission finished: the FC flies none from now on
            self.mission_stopped()
            task.finished = True
            task.done.set()

    def _on_lost_authority(self, f: Mapping[str, Any]) -> None:
        log.warning("aircraft %s: the RC took control back (reason %s)", self.info.sn, f.get("reason"))
        self.has_control = False
        self._stop_requested = "the RC took control back"  # the FC drops its mission and hovers
        if self._sink is not None:
            self._sink.authority_lost(self.info.sn)
            self._sink.event(self.info.sn, "joystick_invalid_notify", {"reason": 4}, need_reply=True)

    # -- telemetry out ----------------------------------------------------------------------------
    def mode_code(self) -> int:
        """The Cloud API mode_code from what the FC reports (adapters/osdk/mission.py's table)."""
        t = self.telemetry
        task = self.mission
        return compute_mode_code(
            connected=t.flight is not None,
            in_air=self.in_air,
            display_mode=t.display_mode,
            mission_running=self.fc_mission_running(),
            mission_kind=task.kind if task is not None and task.live else None,
            taking_off=task is not None and task.kind == "takeoff" and task.taking_off(t.height),
        )

    def aircraft_pose(self) -> AircraftPose | None:
        t = self.telemetry
        if t.latitude is None:
            return None
        return AircraftPose(
            latitude=t.latitude,
            longitude=t.longitude,
            altitude=t.altitude,
            height=t.height,
            mode_code=self.mode_code(),
            velocity=t.velocity,
            attitude=t.attitude,
            gimbal=t.gimbal,
            obstacles=t.obstacles,
        )

    def osd_snapshot(self) -> Mapping[str, Any] | None:
        t = self.telemetry
        if t.latitude is None:
            return None
        body: dict[str, Any] = {
            "latitude": max(-90.0, min(90.0, t.latitude)),
            "longitude": max(-180.0, min(180.0, t.longitude or 0.0)),
            "height": t.altitude,
            "elevation": t.height,
            "mode_code": self.mode_code(),
        }
        if t.attitude is not None:
            roll, pitch, yaw = t.attitude
            body.update(attitude_roll=roll, attitude_pitch=pitch, attitude_head=yaw)
        if t.velocity is not None:
            north, east, up = t.velocity
            body.update(horizontal_speed=math.hypot(north, east), vertical_speed=up)
        if t.battery_percent is not None:
            item: dict[str, Any] = {"index": 0, "capacity_percent": max(0, min(100, t.battery_percent))}
            if t.battery_voltage:
                item["voltage"] = max(0, t.battery_voltage)
                item["x_current"] = t.battery_current
            body["battery"] = {"capacity_percent": item["capacity_percent"], "batteries": [item]}
        return body

    def state_snapshot(self) -> Mapping[str, Any] | None:
        state: dict[str, Any] = {"locked": False}
        if self.firmware_version is not None:
            state["firmware_version"] = self.firmware_version
        if self.hardware is not None:
            state["x_hardware"] = self.hardware
        return state

    # -- Cloud API methods ------------------------------------------------------------------------
    def _require_online(self) -> None:
        if not self._online:
            raise DeviceNotConnected(f"aircraft {self.info.sn} is not connected")

    async def ground_station(self, name: str, fields: Mapping[str, Any] | None = None) -> cmds.Message:
        """A ground-station command whose ACK code 0 is success; others raise with the seed's text."""
        msg = await self.command(name, fields)
        code = int(msg.fields.get("ack", 0))
        if code != 0:
            text = cmds.GS_ACK_TEXT.get(code, "unknown ground-station ACK")
            raise DeviceRejected(ground_station_ack(code), f"{name}: {text} (0x{code:02X})", {"ack": code})
        return msg

    async def obtain_control(self, control: int) -> None:
        """Obtain (1) or release (0) control of the flight controller, asking again while the FC says it
        is still switching; refused by the FC: :class:`DeviceRejected` (RC in charge: 319030, no flight
        authority)."""
        for _ in range(OBTAIN_RETRIES):
            msg = await self.command("obtain_control", {"control": control})
            code = int(msg.fields["ack"])
            if code in CONTROL_IN_PROGRESS:
                await self._clock.sleep(0.1)
                continue  # the FC wants the request again, with a new seq
            if code == (CONTROL_OBTAINED if control else CONTROL_RELEASED):
                self.has_control = bool(control)
                return
            text = cmds.CONTROL_ACK.get(code, "unknown control ACK")
            result = ResultCode.NO_FLIGHT_AUTHORITY if code in CONTROL_RC_OWNS else ResultCode.BUSY
            raise DeviceRejected(result, f"flight controller refused: {text} (0x{code:04X})")
        raise DeviceRejected(ResultCode.BUSY, "flight controller still busy obtaining control")

    async def _grab(self, data: FlightAuthorityGrab) -> CallResult:
        self._require_online()
        await self.obtain_control(1)
        return CallResult()

    async def flight_task(self, task: str) -> None:
        """``task``: takeoff, landing or go_home, in this firmware's codes (cmds.FIRMWARE_CODES)."""
        fields = self._task_fields(task)
        msg = await self.command("flight_task", fields)
        code = int(msg.fields["ack"])
        if code != self.codes.task_ok:
            text = self.codes.task_ack.get(code, "unknown flight task ACK")
            raise DeviceRejected(ResultCode.BUSY, f"flight task {task} refused: {text} ({code})")

    def _relative(self, wgs84_height: float) -> float:
        home = self.telemetry.home_altitude
        if home is None:
            raise DeviceRejected(ResultCode.BUSY, "no position from the aircraft yet")
        return wgs84_height - home

    async def _upload(
        self, points: list[tuple[float, float, float]], speed: float, *, exit_on_rc_lost: bool = False
    ) -> None:
        """init + one waypoint per point (lat/lon degrees, height above take-off). ``exit_on_rc_lost``:
        the mission init's ``action_on_rc_lost`` 0 (exit the mission, the FC's own RC-loss failsafe)
        instead of 1 (continue)."""
        s = self.settings
        idle = max(1.0, min(float(speed), s.mission_vel_cmd_range))
        init = {
            "length": len(points),
            "vel_cmd_range": s.mission_vel_cmd_range,
            "idle_vel": idle,
            "action_on_finish": 0,  # hover at the target: the Cloud API's default action
            "mission_exec_num": 1,
            "yaw_mode": 0,
            "trace_mode": 0,
            "action_on_rc_lost": 0 if exit_on_rc_lost else 1,
            "gimbal_pitch_mode": 0,
        }
        await self.ground_station("wp_init", init)
        for index, (lat, lon, alt) in enumerate(points):
            wp = {
                "index": index,
                "latitude": math.radians(lat),
                "longitude": math.radians(lon),
                "altitude": alt,
                "action_time_limit": 100,
            }
            ack = await self.ground_station("wp_upload", wp)
            if int(ack.fields.get("index", index)) != index:
                raise DeviceRejected(
                    ResultCode.BUSY, f"waypoint {index} acknowledged as {ack.fields.get('index')}"
                )

    def _remaining_all(self, task: Task) -> float:
        """Metres of ``task``'s whole path from where the aircraft stands (before it started)."""
        t = self.telemetry
        if not task.path or t.latitude is None:
            return 0.0
        here = (t.latitude, t.longitude or 0.0, t.height or 0.0)
        return sum(_leg(a, b) for a, b in zip([here, *task.path], task.path, strict=False))

    def _remaining(self, task: Task, status: str) -> float:
        """Metres left to fly: from where the aircraft is to the next point not yet reached, then along
        the remaining legs; 0 once arrived."""
        t = self.telemetry
        if status == "wayline_ok" or not task.path or t.latitude is None:
            return 0.0
        here = (t.latitude, t.longitude or 0.0, t.height or 0.0)
        ahead = task.path[min(len(task.path) - 1, max(task.reached + 1, task.offset)) :]
        return sum(_leg(a, b) for a, b in zip([here, *ahead], ahead, strict=False))

    def _progress(
        self,
        task: Task,
        status: str,
        index: int,
        result: int = 0,
        *,
        need_reply: bool = True,
        reason: str | None = None,
    ) -> None:
        """One ``fly_to_point_progress`` / ``takeoff_to_point_progress``; a failure carries ``reason`` in the
        extension field ``x_reason`` (the Cloud API's events have only the ``result`` code)."""
        if self._sink is None or task.kind not in ("fly_to", "takeoff"):
            return  # waylines, the way home and adopted missions report through gateway/wayline
        index = max(0, index)
        if task.kind == "fly_to":
            left = self._remaining(task, status)
            data = {"fly_to_id": task.task_id, "status": status, "result": result, "way_point_index": index,
                    "remaining_distance": round(left, 1),
                    "remaining_time": round(left / task.speed, 1) if task.speed > 0 else 0.0,
                    "planned_path_points": task.planned}  # fmt: skip
            if reason:
                data["x_reason"] = reason[:300]
            self._sink.event(self.info.sn, "fly_to_point_progress", data, need_reply=need_reply)
        else:
            terminal = status in ("wayline_ok", "wayline_failed", "wayline_cancel")
            if task.end_told or status == "task_finish":
                return  # one terminal status, then task_finish (below); nothing after it
            left = self._remaining(task, status) if status != "task_ready" else self._remaining_all(task)
            data = {"flight_id": task.task_id, "track_id": "", "status": status, "result": result,
                    "way_point_index": index, "remaining_distance": round(left, 1),
                    "remaining_time": round(left / task.speed, 1) if task.speed > 0 else 0.0}  # fmt: skip
            if reason:
                data["x_reason"] = reason[:300]
            self._sink.event(self.info.sn, "takeoff_to_point_progress", data, need_reply=need_reply)
            if terminal:  # every path ends with task_finish (DJI's last status), carrying the result
                task.end_told = True
                self._sink.event(
                    self.info.sn,
                    "takeoff_to_point_progress",
                    {**data, "status": "task_finish"},
                    need_reply=True,
                )

    def _start_watch(self, task: Task) -> None:
        if self._mission_task is not None and not self._mission_task.done():
            self._mission_task.cancel()
        self._mission_task = asyncio.get_running_loop().create_task(self._watch(task))

    async def _watch(self, task: Task) -> None:
        while task.kind in ("fly_to", "takeoff") and not task.done.is_set():
            # between the waypoint events the flight reports itself periodically: a progress superseded
            # within the interval is not re-sent (need_reply 0); the events of a point, the end, a
            # cancel or a failure still ask for a reply
            with contextlib.suppress(TimeoutError):
                await self._clock.wait_for(task.done.wait(), PROGRESS_INTERVAL)
            if not task.done.is_set() and not task.finished:
                self._progress(task, "wayline_progress", task.reached - task.offset, need_reply=False)
        await task.done.wait()
        last = task.points - 1 - task.offset
        if task.failed is not None:
            ack = task.failed - GROUND_STATION_ACK_BASE
            text = cmds.GS_ACK_TEXT.get(ack, "") if 0 < ack < 256 else meaning(task.failed)
            reason = f"the flight controller reported a mission error: {text or meaning(task.failed)}"
            if 0 < ack < 256:
                reason += f" (0x{ack:02X})"
            await self._failed(task, task.failed, reason)
        elif task.dropped is not None:
            # the FC ended it: an emergency stop the operator asked for is a cancel; anything else failed
            if task.dropped == "emergency stop":
                self._progress(task, "wayline_cancel", task.reached - task.offset, 0)
            else:
                await self._failed(task, ResultCode.BUSY, f"the flight controller ended it: {task.dropped}")
        elif task.finished:
            self._progress(task, "wayline_ok", last)  # a take-off's task_finish follows (_progress)

    async def _fly_to_point(self, data: FlyToPoint) -> CallResult:
        self._require_online()
        if data.max_speed <= 0:
            raise InvalidParameters("max_speed must be at least 1 m/s to fly")
        t = self.telemetry
        if t.flight not in self.codes.in_air:
            raise DeviceRejected(
                ResultCode.BUSY, "fly_to_point needs the aircraft in the air (use takeoff_to_point)"
            )
        # A ground-station mission needs at least two waypoints (DJI's minimum): the first is where the
        # aircraft is now, so the cloud's points keep their indexes shifted by one (undone in events).
        if len(data.points) > MAX_MISSION_POINTS - 1:
            raise InvalidParameters(
                f"points: a ground-station mission holds {MAX_MISSION_POINTS} waypoints, one of them where "
                f"the aircraft is now: at most {MAX_MISSION_POINTS - 1} points"
            )
        self.require_no_mission()  # before anything is uploaded over the mission the FC holds
        here = (t.latitude or 0.0, t.longitude or 0.0, t.height or 0.0)
        points = [here, *((p.latitude, p.longitude, self._relative(p.height)) for p in data.points)]
        for index, (_, _, height) in enumerate(points[1:]):
            self._check_height(f"points[{index}].height", height)
        names = ["the aircraft", *(f"points[{i}]" for i in range(len(data.points)))]
        self._preflight(points, names)
        await self._upload(points, data.max_speed)
        task = Task("fly_to", data.fly_to_id, len(points), offset=1, path=points)
        task.speed = max(1.0, min(float(data.max_speed), self.settings.mission_vel_cmd_range))
        task.planned = [
            {"latitude": p.latitude, "longitude": p.longitude, "height": p.height} for p in data.points
        ]
        self.begin_mission(task)
        await self.start_mission(task)
        self._remember(task)
        self._start_watch(task)
        return CallResult()

    async def _fly_to_point_stop(self, data: FlyToPointStop) -> CallResult:
        self._require_online()
        await self.stop_current_mission()
        return CallResult()

    @property
    def limits(self) -> MissionLimits:
        """What this flight controller accepts in a waypoint mission (adapters/osdk/limits.py)."""
        s = self.settings
        return MissionLimits.for_firmware(self.fw, max_distance=s.max_distance, max_height=s.max_height)

    def _home(self) -> tuple[float, float]:
        """Where the aircraft took off (its position when last on the ground), else where it is."""
        t = self.telemetry
        if self.home_position is not None and self.in_air:
            return self.home_position
        return (t.latitude or 0.0, t.longitude or 0.0)

    def mission_breach(
        self, points: list[tuple[float, float, float]], names: list[str]
    ) -> LimitBreach | None:
        """The FC's mission rule ``points`` break (from where the aircraft is now), or None."""
        t = self.telemetry
        here = (t.latitude or 0.0, t.longitude or 0.0)
        return check_mission(points, aircraft=here, home=self._home(), limits=self.limits, names=names)

    def _preflight(self, points: list[tuple[float, float, float]], names: list[str]) -> None:
        """Refuse, before anything is sent, a mission the FC would refuse (it would answer the ACK named,
        after a take-off for a take-off to point): 336000 + that ACK, the field and the numbers in the
        reason."""
        breach = self.mission_breach(points, names)
        if breach is not None:
            log.warning("aircraft %s: refused before take-off or upload: %s", self.info.sn, breach.text)
            text = cmds.GS_ACK_TEXT.get(breach.ack, "")
            raise DeviceRejected(
                ground_station_ack(breach.ack),
                f"{breach.text} (the flight controller would refuse the mission: 0x{breach.ack:02X} {text})",
                {"ack": breach.ack},
            )

    def _check_height(self, name: str, height: float) -> None:
        """A height above take-off the FC can fly to (``max_height``, its configured limit)."""
        if height > self.settings.max_height:
            raise InvalidParameters(
                f"{name}: {height:.1f} m above take-off is over this aircraft's limit of "
                f"{self.settings.max_height:g} m"
            )

    def _check_takeoff(self, data: TakeoffToPoint) -> None:
        """Refuse (325001, naming the field) what this flight controller cannot honour, before anything
        is sent: an RC-loss action other than its configured failsafe (the protocol cannot set it), a
        go-home altitude outside 20..500 m (OSDK's own check) or one an M100 cannot be given, a height
        over its limit."""
        s = self.settings
        wanted = getattr(data, "rc_lost_action", None)
        if wanted is not None and _RC_LOST_ACTIONS[int(wanted)] != s.rc_lost_action:
            raise InvalidParameters(
                f"rc_lost_action: this flight controller's RC-loss failsafe is {s.rc_lost_action} (set in "
                f"DJI Assistant 2; the Onboard SDK cannot change it), not {_RC_LOST_ACTIONS[int(wanted)]}"
            )
        lo, hi = cmds.GO_HOME_ALTITUDE_RANGE
        if not lo <= data.rth_altitude <= hi:
            raise InvalidParameters(f"rth_altitude: the flight controller takes {lo}..{hi} m")
        if self.fw == "m100" and data.rth_altitude != s.go_home_altitude:
            configured = "not configured" if s.go_home_altitude is None else f"{s.go_home_altitude} m"
            raise InvalidParameters(
                "rth_altitude: an M100 cannot be sent a go-home altitude; it must equal the device's "
                f"go_home_altitude setting ({configured})"
            )
        self._check_height("security_takeoff_height", float(data.security_takeoff_height))
        self._check_height("target_height", self._relative(data.target_height))
        # DJI's Java Cloud SDK (Cloud API 1.x) fields: what this FC can do is honoured, the rest refused
        if getattr(data, "rth_mode", None) == 0:
            raise InvalidParameters(
                "rth_mode: an Onboard SDK flight controller returns home at its preset altitude "
                "(rth_mode 1, rth_altitude); optimal-height return is not available"
            )
        mode = getattr(data, "commander_flight_mode", None)
        height = getattr(data, "commander_flight_height", None)
        if mode == 0:
            raise InvalidParameters(
                "commander_flight_mode: smart height is not available on an Onboard SDK flight controller; "
                "use 1 (fixed height) with commander_flight_height"
            )
        if mode == 1 and height is None:
            raise InvalidParameters("commander_flight_height: required with commander_flight_mode 1")
        if mode is None and height is not None:
            raise InvalidParameters("commander_flight_height: applies with commander_flight_mode 1 only")
        if height is not None:
            self._check_height("commander_flight_height", float(height))
        simulate = getattr(data, "simulate_mission", None)
        if simulate is not None and simulate.is_enable == 1:
            raise InvalidParameters(
                "simulate_mission: an Onboard SDK flight controller's simulator is started from DJI "
                "Assistant 2, not by a command (dji-gateway run --simulate simulates the whole aircraft)"
            )

    @staticmethod
    def _exit_on_rc_lost(data: TakeoffToPoint) -> tuple[bool, bool]:
        """Exit the mission when the RC is lost, (in the climb to ``security_takeoff_height``, in the flight
        to the point)? 1 exit (the FC's RC-loss failsafe), 0 continue. DJI's current take-off page (Dock
        2/3) requires ``commander_mode_lost_action``, the to-point flight's action; the Dock 1 page keeps
        ``exit_wayline_when_rc_lost`` as deprecated, the wayline (take-off) phase's. So the commander field
        governs the flight to the point and the deprecated one yields to it there (before Cloud API 1.x it
        governed the whole flight: alone, it still does); the deprecated one governs the climb, which the
        commander field does not speak of (absent, the climb does as the flight to the point). Neither:
        continue, the seed's default."""
        old = getattr(data, "exit_wayline_when_rc_lost", None)
        new = getattr(data, "commander_mode_lost_action", None)
        to_point = (new if new is not None else old) == 1
        climb = to_point if old is None else old == 1
        return climb, to_point

    def _takeoff_route(self, data: TakeoffToPoint) -> list[tuple[float, float, float]]:
        """The mission after the take-off (lat/lon degrees, height above take-off): straight up to
        ``security_takeoff_height``; in fixed-height commander mode up (or down) to
        ``commander_flight_height``, across at that height and down (or up) to the target; else straight
        to the target. Points closer than 0.5 m to the previous one are left out (the FC refuses them)."""
        t = self.telemetry
        here = (t.latitude or 0.0, t.longitude or 0.0)
        target = (data.target_latitude, data.target_longitude)
        route = [(*here, float(data.security_takeoff_height))]
        cruise = getattr(data, "commander_flight_height", None)
        if getattr(data, "commander_flight_mode", None) == 1 and cruise is not None:
            route += [(*here, float(cruise)), (*target, float(cruise))]
        route.append((*target, self._relative(data.target_height)))
        kept = route[:1]
        for point in route[1:]:
            if _distance_3d(kept[-1], point) >= MIN_WAYPOINT_SPACING:
                kept.append(point)
        if len(kept) == 1:
            # a target straight above the take-off point at the safe height: a mission has at least two
            # waypoints (one is "invalid mission data", 0xE0), so it starts where the aircraft hovers
            kept.insert(0, (*here, min(float(t.height or 0.0), kept[0][2] - MIN_WAYPOINT_SPACING)))
        return kept

    async def read_go_home_altitude(self) -> float:
        """0x01 0x41 GO_HOME_ALTITUDE (new firmware): the height the FC's go home climbs to."""
        msg = await self.command("go_home_altitude_read", {})
        f = msg.fields
        if int(f["ack"]) != 0 or f["hash"] != cmds.GO_HOME_ALTITUDE_HASH:
            raise DeviceRejected(ResultCode.BUSY, f"go-home altitude not read (ret code {f['ack']})")
        return float(f["altitude"])

    async def set_go_home_altitude(self, altitude: int) -> None:
        await self._set_go_home_altitude(altitude)

    async def _set_go_home_altitude(self, altitude: int) -> None:
        """0x01 0x42 GO_HOME_ALTITUDE (new firmware): written, and the FC's echo must hold it."""
        msg = await self.command("go_home_altitude_write", {"altitude": altitude})
        f = msg.fields
        if int(f["ack"]) != 0 or f["hash"] != cmds.GO_HOME_ALTITUDE_HASH or int(f["altitude"]) != altitude:
            raise DeviceRejected(
                ResultCode.INVALID_PARAMETERS,
                f"rth_altitude: the flight controller kept a go-home altitude of {f['altitude']} m "
                f"(ret code {f['ack']})",
            )

    async def _takeoff_to_point(self, data: TakeoffToPoint) -> CallResult:
        self._require_online()
        if self.in_air:
            raise DeviceRejected(ResultCode.BUSY, "the aircraft is already in the air")
        self._check_takeoff(data)
        self.require_no_mission()
        route = self._takeoff_route(data)
        names = ["security_takeoff_height", *["commander_flight_height"] * (len(route) - 2)]
        self._preflight(route, [*names, "target_latitude/target_longitude"])  # nothing moves for a refusal
        if self.fw == "new":
            await self._set_go_home_altitude(int(data.rth_altitude))
        await self.flight_task("takeoff")
        task = Task("takeoff", data.flight_id, 2, path=route, climb_to=float(data.security_takeoff_height))
        task.speed = max(1.0, min(float(data.max_speed), self.settings.mission_vel_cmd_range))
        self.begin_mission(task)
        self._progress(task, "task_ready", 0)
        if self._mission_task is not None and not self._mission_task.done():
            self._mission_task.cancel()
        self._mission_task = asyncio.get_running_loop().create_task(self._takeoff_then_fly(task, data))
        return CallResult()

    async def _takeoff_then_fly(self, task: Task, data: TakeoffToPoint) -> None:
        """After the take-off ACK: wait until airborne, then fly up and over to the target."""
        deadline = self._now() + self.settings.takeoff_timeout
        t = self.telemetry
        while not (self.in_air and (t.height or 0.0) >= 1.0 and t.display_mode != AUTO_TAKEOFF):
            if self._now() > deadline:
                await self._failed(task, ResultCode.DEVICE_TIMEOUT, "the take-off did not end in time")
                return
            await self._clock.sleep(0.1)
        try:
            points = self._takeoff_route(data)
            task.points, task.path = len(points), points
            # exit_wayline_when_rc_lost / commander_mode_lost_action: 1 exit → init action_on_rc_lost 0;
            # 0 or absent → 1 continue (the seed's default); one per phase (_exit_on_rc_lost)
            climb_exit, to_point_exit = self._exit_on_rc_lost(data)
            # a mission has one RC-loss action: when the phases differ the climb is a mission of its own
            split = climb_exit != to_point_exit and len(points) > 1
            if points[0][2] < float(data.security_takeoff_height):  # the target is the safe height above
                split, to_point_exit = False, climb_exit  # the take-off point: it is all climb
            if split and not await self._climb(task, points[0], data.max_speed, exit_on_rc_lost=climb_exit):
                return
            await self._upload(points, data.max_speed, exit_on_rc_lost=to_point_exit)
            await self.start_mission(task)
            self._remember(task)
        except DeviceRejected as exc:
            task.failed = int(exc.result)
            task.done.set()
            await self._failed(task, exc.result, f"the mission after the take-off was refused: {exc}")
            return
        except (DeviceTimeout, DeviceNotConnected) as exc:
            task.failed = int(ResultCode.DEVICE_TIMEOUT)
            task.done.set()
            await self._failed(
                task, ResultCode.DEVICE_TIMEOUT, f"the mission after the take-off failed: {exc}"
            )
            return
        await self._watch(task)

    async def _failed(self, task: Task, result: int, reason: str) -> None:
        """``task`` failed: a take-off to point is never left where it failed (:meth:`secure`), the reason
        is logged at ERROR and told in the failure event (``x_reason``) and ``x_osdk_safety_notify``."""
        index = task.reached - task.offset
        if task.kind == "takeoff":
            done = await self.secure(KIND_WORDS[task.kind], task.task_id, reason)
            if done is not None:
                reason = f"{reason}; {done}"
        else:
            log.error(
                "aircraft %s: %s %s failed: %s", self.info.sn, KIND_WORDS[task.kind], task.task_id, reason
            )
        self._progress(task, "wayline_failed", index, int(result), reason=reason)

    async def secure(self, what: str, task_id: str, reason: str) -> str | None:
        """A task failed after the aircraft took off for it: never leave it hovering where it failed.
        DJI's return-home rule (adapters/osdk/limits.py :func:`after_failure`): within 20 m of home it lands,
        farther it flies the FC's go home (climb to the go-home altitude, home, land). Nothing when it is on
        the ground or not the gateway's to command (the RC took it back). Logged at ERROR with the reason,
        told by ``x_osdk_safety_notify``; returns what was done, in words (None: nothing)."""
        t = self.telemetry
        here = (t.latitude, t.longitude) if t.latitude is not None and t.longitude is not None else None
        home = self.home_position
        distance = flat_distance(here, home) if here is not None and home is not None else None
        action = after_failure(in_air=self.in_air, has_control=self.has_control, home_distance=distance)
        where = f"{t.height or 0.0:.1f} m above take-off, " + (
            f"{distance:.0f} m from home" if distance is not None else "home unknown"
        )
        if action is None:
            left = "on the ground" if not self.in_air else "the RC controls it"
            log.error("aircraft %s: %s %s failed: %s (%s)", self.info.sn, what, task_id, reason, left)
            return None
        words = "landing where it is" if action == "landing" else "returning home (the FC's go home)"
        sn = self.info.sn
        log.error(
            "aircraft %s: %s %s failed after take-off: %s; %s (%s)", sn, what, task_id, reason, words, where
        )
        try:
            if action == "landing":
                await self.flight_task("landing")
            else:
                await self.wayline.go_home(task_id)
        except (DeviceRejected, DeviceTimeout, DeviceNotConnected) as exc:
            log.error("aircraft %s: could not start %s after the failure: %s", self.info.sn, words, exc)
            self._notify("mission_ended", f"{reason}; {words} refused: {exc}", task_id)
            return None
        self._notify("landing" if action == "landing" else "returning_home", f"{reason} ({where})", task_id)
        return words

    async def _climb(
        self, task: Task, top: tuple[float, float, float], speed: float, *, exit_on_rc_lost: bool
    ) -> bool:
        """The take-off phase as a mission of its own (straight up from where the aircraft hovers to
        ``top``, with its own RC-loss action), flown for ``task``: True once it is up there; False when it
        ended otherwise (reported as the take-off's end; a stop cancels the caller's coroutine)."""
        t = self.telemetry
        here = (t.latitude or 0.0, t.longitude or 0.0, t.height or 0.0)
        # its waypoints are none of the cloud's; the same take-off phase and speed
        climb = Task("takeoff", task.task_id, 2, offset=2, speed=task.speed, climb_to=task.climb_to)
        await self._upload([here, top], speed, exit_on_rc_lost=exit_on_rc_lost)
        self.mission = climb  # the same take-off, its first phase: the FC's pushes go to it
        self._stop_requested, self._disagree_since = None, None
        await self.start_mission(climb)
        await climb.done.wait()
        if climb.finished and not climb.canceled and climb.failed is None and climb.dropped is None:
            self.begin_mission(task)  # the flight to the point
            return True
        self.mission = task
        task.failed, task.dropped, task.finished = climb.failed, climb.dropped, climb.finished
        task.done.set()
        await self._watch(task)
        return False

    def _online_only(self, call: Handler) -> Handler:
        async def checked(data: Any) -> CallResult:
            self._require_online()
            return await call(data)

        return checked

    # -- extension services: method → coroutine(data) ------------------------------------------------

    def _extension_calls(self) -> dict[str, Handler]:
        """Extension method → its coroutine on this adapter (each behind :meth:`_online_only`). The
        request model each takes is the one its method is registered with (extensions.EXTENSIONS),
        validated by the dispatcher before the call."""
        return {
            "x_osdk_waypoint_pause": lambda d: self._ext_pause("wp_pause_resume", d),
            "x_osdk_waypoint_idle_velocity_set": self._ext_idle_set,
            "x_osdk_waypoint_idle_velocity_get": self._ext_idle_get,
            "x_osdk_mission_download": self._ext_download,
            "x_osdk_hotpoint_start": self._ext_hotpoint,
            "x_osdk_hotpoint_stop": lambda d: self._ext_plain("hp_stop"),
            "x_osdk_hotpoint_pause": lambda d: self._ext_pause("hp_pause_resume", d),
            "x_osdk_hotpoint_velocity_set": lambda d: self._ext_plain(
                "hp_set_idle_velocity", {"is_clockwise": 1 if d.clockwise else 0, "idle_velocity": d.velocity}
            ),
            "x_osdk_hotpoint_radius_set": lambda d: self._ext_plain("hp_set_radius", {"radius": d.radius}),
            "x_osdk_hotpoint_reset_yaw": lambda d: self._ext_plain("hp_reset_yaw"),
            "x_osdk_hotpoint_download": self._ext_hotpoint_download,
            "x_osdk_hotpoint_auto_radius": lambda d: self._ext_plain(
                "hp_auto_radius", {"on_off": 1 if d.enable else 0, "rate": d.rate}
            ),
            "x_osdk_followme_start": self._ext_followme,
            "x_osdk_followme_stop": lambda d: self._ext_plain("fm_stop"),
            "x_osdk_followme_pause": lambda d: self._ext_pause("fm_pause_resume", d),
            "x_osdk_followme_target": self._ext_followme_target,
            "x_osdk_land": lambda d: self._ext_task("landing"),
            "x_osdk_go_home": lambda d: self._ext_task("go_home"),
            "x_osdk_authority_release": self._ext_release,
        }

    async def _ext_pause(self, name: str, data: Pause) -> CallResult:
        await self.ground_station(name, {"pause": 0 if data.pause else 1})
        return CallResult()

    async def _ext_plain(self, name: str, fields: Mapping[str, Any] | None = None) -> CallResult:
        await self.ground_station(name, fields or {"arbitrary": 0})
        return CallResult()

    async def _ext_idle_set(self, data: IdleVelocity) -> CallResult:
        msg = await self.ground_station("wp_set_idle_velocity", {"idle_velocity": data.velocity})
        return CallResult(0, {"idle_velocity": float(msg.fields["idle_velocity"])})

    async def _ext_idle_get(self, data: EmptyRequest) -> CallResult:
        msg = await self.ground_station("wp_get_idle_velocity", {"arbitrary": 0})
        return CallResult(0, {"idle_velocity": float(msg.fields["idle_velocity"])})

    async def _ext_download(self, data: EmptyRequest) -> CallResult:
        init = await self.ground_station("wp_download_init", {"arbitrary": 0})
        points = []
        for index in range(int(init.fields["length"])):
            wp = await self.ground_station("wp_download_point", {"index": index})
            f = wp.fields
            points.append(
                {
                    "index": int(f["index"]),
                    "latitude": math.degrees(f["latitude"]),
                    "longitude": math.degrees(f["longitude"]),
                    "altitude": float(f["altitude"]),
                }
            )
        out = {
            "length": int(init.fields["length"]),
            "idle_velocity": float(init.fields["idle_vel"]),
            "action_on_finish": int(init.fields["action_on_finish"]),
            "points": points,
        }
        return CallResult(0, out)

    async def _ext_hotpoint(self, data: HotpointStart) -> CallResult:
        fields = {
            "version": 0,
            "hp_latitude": math.radians(data.latitude),
            "hp_longitude": math.radians(data.longitude),
            "hp_altitude": data.altitude,
            "hp_radius": data.radius,
            "angle_rate": data.angle_rate,
            "is_clockwise": 1 if data.clockwise else 0,
            "start_point_position": data.start_point,
            "yaw_mode": data.yaw_mode,
        }
        msg = await self.ground_station("hp_upload_start", fields)
        return CallResult(0, {"max_radius": float(msg.fields.get("max_radius", 0.0))})

    async def _ext_hotpoint_download(self, data: EmptyRequest) -> CallResult:
        f = (await self.ground_station("hp_download", {"arbitrary": 0})).fields
        out = {
            "latitude": math.degrees(f["hp_latitude"]),
            "longitude": math.degrees(f["hp_longitude"]),
            "altitude": float(f["hp_altitude"]),
            "radius": float(f["hp_radius"]),
            "angle_rate": float(f["angle_rate"]),
            "clockwise": bool(f["is_clockwise"]),
        }
        return CallResult(0, out)

    async def _ext_followme(self, data: FollowMeStart) -> CallResult:
        fields = {
            "follow_mode": 0,
            "yaw_mode": 1 if data.point_to_target else 0,
            "init_latitude": math.radians(data.latitude),
            "init_longitude": math.radians(data.longitude),
            "init_alti": data.altitude,
        }
        await self.ground_station("fm_upload_start", fields)
        return CallResult()

    async def _ext_followme_target(self, data: FollowMeTarget) -> CallResult:
        fields = {"latitude": math.radians(data.latitude), "longitude": math.radians(data.longitude),
                  "altitude": data.altitude}  # fmt: skip
        await self.command("fm_update_target", fields)  # no ACK: the send is the result
        return CallResult()

    async def _ext_task(self, task: str) -> CallResult:
        await self.flight_task(task)
        return CallResult()

    async def _ext_release(self, data: EmptyRequest) -> CallResult:
        await self.obtain_control(0)
        if self._sink is not None:
            self._sink.authority_lost(self.info.sn, requested=True)  # the cloud's release, no take-over
        return CallResult()


# push → handler, as the table's entries name them (a missing method fails here, at import)
_PUSHES = bind_handlers(AircraftAdapter, cmds.COMMAND_TABLE)
