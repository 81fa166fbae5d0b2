"""What an Onboard SDK flight controller says it is doing, set against what the gateway asked of it.

Owns: the record of a mission task (:class:`Task`: a fly-to, take-off, wayline or return home that the
gateway started, or one it found the flight controller flying and adopted), the Cloud API ``mode_code``
of every phase computed from telemetry (:func:`mode_code`, :data:`DISPLAY_MODE_CODES`), the reading of
the FC's mission state from its pushes (:class:`FcMissionState`), and the verdict when the gateway's
intent and the FC disagree (:func:`reconcile`). No I/O: values and a clock value in, values out. Must not
know MQTT, Cloud API services, the wayline task book or the serial link; ``adapters/osdk/adapter.py``
feeds it and acts on its verdicts, ``adapters/osdk/wayline.py`` reads tasks through the
:class:`MissionHost` protocol.

The device is the source of truth. The gateway's :class:`Task` is *intent*: a task the FC no longer flies
(an emergency brake, an RC take-over, a mission the FC dropped, a gateway restart that missed the end) is
ended by :func:`reconcile` within :data:`GRACE` s of the FC saying so, with the reason it found; a
waypoint mission the FC flies that no task knows of is adopted (the adapter asks :func:`orphan`).

How the FC says a waypoint mission runs (seed 004 and DJI's Onboard-SDK 3.x source; the simulator
behaves the same): the ``0x02 0x03`` mission status push with ``mission_type`` 1 (waypoint) arrives
about once a second while a mission is loaded and running or paused, and the flight-data status item's
display mode reads 14 (the Mobile SDK's ``GPS_WAYPOINT``) while it flies. Either one, fresh, is "a
mission runs"; neither for :data:`STATUS_STALE` s is "none runs". A default status push
(``mission_type`` 0) with ``is_broken`` set says the last mission was broken off: that ends it at once.
"""

from __future__ import annotations

import asyncio
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from adapters.clock import Clock
    from adapters.osdk import commands as cmds
    from adapters.osdk.config import OsdkDeviceSettings
    from adapters.osdk.limits import MissionLimits

__all__ = [
    "DISPLAY_MODE_CODES",
    "GRACE",
    "STATUS_STALE",
    "FcMissionState",
    "MissionHost",
    "Task",
    "Verdict",
    "mode_code",
    "reconcile",
]

#: A waypoint status push older than this (s) no longer says a mission runs (the FC pushes ~1 Hz).
STATUS_STALE = 1.6
#: How long (s) the gateway's intent may disagree with the FC before the FC wins.
GRACE = 0.5

# FC display modes (OSDK ``DisplayMode``; 14 and 25 as in the Mobile SDK's ``FlightMode`` list)
DM_ASSISTED_TAKEOFF, DM_AUTO_TAKEOFF, DM_AUTO_LANDING, DM_GO_HOME = 10, 11, 12, 15
DM_HOTPOINT, DM_WAYPOINT, DM_SDK_CONTROL, DM_FOLLOW_ME, DM_FORCED_LANDING = 9, 14, 17, 25, 33

#: Cloud API ``mode_code`` (schemas.osd.ModeCode) of an aircraft in the air, by the FC's display mode.
#: Any display mode not listed (manual 0, attitude 1, P-GPS 6, …) is 3 "manual flight". Hotpoint has no
#: Cloud API mode of its own in this contract's enum (0..17): it reads 3 too.
DISPLAY_MODE_CODES: Mapping[int, int] = {
    DM_ASSISTED_TAKEOFF: 4,  # auto take-off
    DM_AUTO_TAKEOFF: 4,
    DM_AUTO_LANDING: 10,  # automatic landing
    DM_GO_HOME: 9,  # return to home
    DM_FORCED_LANDING: 11,  # forced landing
    DM_SDK_CONTROL: 16,  # virtual stick
    DM_WAYPOINT: 5,  # wayline
    DM_FOLLOW_ME: 7,  # intelligent tracking
}
STANDBY, MANUAL, AUTO_TAKEOFF, WAYLINE, RETURN_HOME, NOT_CONNECTED = 0, 3, 4, 5, 9, 14
#: metres under a take-off's safe height at which its take-off phase ends (the FC's waypoint tolerance)
CLIMB_REACHED = 1.0

#: what each automatic display mode is, in words (sticks are refused while one flies the aircraft)
AUTOMATIC = {
    DM_ASSISTED_TAKEOFF: "take-off",
    DM_AUTO_TAKEOFF: "take-off",
    DM_AUTO_LANDING: "landing",
    DM_GO_HOME: "return home",
    DM_FORCED_LANDING: "forced landing",
    DM_HOTPOINT: "hotpoint mission",
    DM_WAYPOINT: "waypoint mission",
    DM_FOLLOW_ME: "follow-me mission",
}
KIND_WORDS = {
    "wayline": "wayline",
    "fly_to": "fly-to",
    "takeoff": "take-off to point",
    "return_home": "return home",
    "go_home": "return home",
    "adopted": "waypoint mission",
}


@dataclass
class Task:
    """A mission task: which Cloud API event reports it, where it is, and how it ended.

    ``kind``: ``fly_to``, ``takeoff`` (the mission after a take-off), ``wayline``, ``return_home`` (the
    gateway's own way home, a mission), ``go_home`` (the FC's own go home: no mission, its display mode
    says it runs) or ``adopted`` (found running on the FC after a restart). ``started``: the
    FC accepted the mission start (only then can it disagree). ``dropped``: why the FC ended it without
    finishing (set by the adapter on :func:`reconcile`'s verdict)."""

    kind: str
    task_id: str  # fly_to_id / flight_id
    points: int
    done: asyncio.Event = field(default_factory=asyncio.Event)
    reached: int = -1
    offset: int = 0  # waypoints the gateway prepended: the cloud's index = mission index - offset
    finished: bool = False
    failed: int | None = None
    dropped: str | None = None
    canceled: bool = False  # ended by a stop the gateway sent (finished is set too)
    started: bool = False
    adopted: bool = False
    #: told the mission index of every waypoint reached (wayline tasks: adapters/osdk/wayline.py)
    on_reached: Callable[[int], None] | None = None
    path: list[tuple[float, float, float]] = field(default_factory=list)  # lat, lon, m above take-off
    speed: float = 0.0  # the mission's planned speed (m/s)
    planned: list[dict[str, float]] = field(default_factory=list)  # the cloud's points (WGS84 height)
    #: a take-off to point: the safe height (m above take-off) that ends its take-off phase (mode_code 4);
    #: None once the aircraft got there (the fly-to phase, 5) or for any other task
    climb_to: float | None = None
    end_told: bool = False  # a take-off to point's terminal status (and task_finish) went out

    def taking_off(self, height: float | None) -> bool:
        """Is this take-off to point still climbing to its safe height? Ends for good once the aircraft
        got within :data:`CLIMB_REACHED` of it (a fly-to phase lower than the safe height stays 5)."""
        if self.climb_to is None or not self.live:
            return False
        if height is not None and height >= self.climb_to - CLIMB_REACHED:
            self.climb_to = None
            return False
        return True

    @property
    def live(self) -> bool:
        """Not ended in any way: flying, paused, or about to start."""
        return not self.finished and self.failed is None and self.dropped is None


@dataclass
class FcMissionState:
    """The FC's waypoint mission as its pushes tell it (clock values of the adapter's clock)."""

    status_at: float = float("-inf")  # last 0x02 0x03 push with mission_type 1
    target: int | None = None  # its target waypoint
    broken_at: float = float("-inf")  # last default status push with is_broken set

    def on_status(self, fields: Mapping[str, Any], now: float) -> None:
        kind = fields.get("mission_type")
        if kind == 1:
            self.status_at = now
            self.target = int(fields.get("target_waypoint", 0))
        elif kind in (0, 4) and fields.get("last_mission_type") == 1:
            flags = fields.get("flags")
            broken = flags.get("is_broken") if isinstance(flags, Mapping) else fields.get("is_broken")
            if broken:
                self.broken_at = now
                self.status_at = float("-inf")

    def running(self, display_mode: int | None, now: float) -> bool:
        """Does the FC fly (or hold, paused) a waypoint mission now?"""
        return display_mode == DM_WAYPOINT or now - self.status_at <= STATUS_STALE

    def reset(self) -> None:
        """A new link: nothing the old one said holds."""
        self.status_at = self.broken_at = float("-inf")
        self.target = None


def mode_code(
    *,
    connected: bool,
    in_air: bool,
    display_mode: int | None,
    mission_running: bool,
    mission_kind: str | None,
    taking_off: bool = False,
) -> int:
    """The Cloud API ``mode_code`` from what the FC reports: not connected 14; the FC's own take-off 4
    (from the moment it starts, on the ground too); on the ground 0; a waypoint mission the FC flies 5,
    or 9 when that mission is the gateway's way home (``mission_kind`` is the intent that names it; the FC
    only says a mission runs); else by display mode (:data:`DISPLAY_MODE_CODES`), 3 otherwise.

    ``taking_off``: a ``takeoff_to_point`` still climbing to its safe height (``Task.taking_off``). DJI's
    aircraft reports 4 "auto take-off" for the whole take-off phase, the FC's own take-off and the climb
    that follows (our climb is a waypoint mission, which alone would read 5); the fly-to phase after it
    reads 5 like a ``fly_to_point`` (docs/osdk.md)."""
    if not connected:
        return NOT_CONNECTED
    if display_mode in (DM_ASSISTED_TAKEOFF, DM_AUTO_TAKEOFF):
        return DISPLAY_MODE_CODES[display_mode]
    if not in_air:
        return STANDBY
    if display_mode in (DM_GO_HOME, DM_AUTO_LANDING, DM_FORCED_LANDING):
        return DISPLAY_MODE_CODES[display_mode]  # the FC's own automatic flight, whatever came before
    if taking_off:
        return AUTO_TAKEOFF
    if mission_running:
        return RETURN_HOME if mission_kind == "return_home" else WAYLINE
    return DISPLAY_MODE_CODES.get(display_mode if display_mode is not None else -1, MANUAL)


@dataclass(frozen=True, slots=True)
class Verdict:
    """:func:`reconcile`'s answer: the task ends (``reason``), or nothing to do (``None`` instead)."""

    reason: str


def reconcile(
    task: Task | None,
    fc_running: bool,
    *,
    disagree_since: float | None,
    now: float,
    stop_requested: str | None = None,
    broken: bool = False,
) -> tuple[Verdict | None, float | None]:
    """Intent against the FC. ``task``: the gateway's mission task; ``fc_running``: the FC flies a
    waypoint mission now; ``disagree_since``: when they started to disagree (None: they agreed last time);
    ``stop_requested``: a stop the gateway itself asked for (an emergency brake: no grace, that is the
    reason); ``broken``: the FC said the mission was broken off. Returns the verdict (None: none yet) and
    the new ``disagree_since``."""
    if task is None or not task.live or not task.started or (fc_running and not broken):
        return None, None
    if broken:
        return Verdict(stop_requested or "the flight controller broke the mission off"), None
    if stop_requested is not None:
        return Verdict(stop_requested), None
    since = now if disagree_since is None else disagree_since
    if now - since >= GRACE:
        return Verdict("the flight controller is no longer flying the mission"), None
    return None, since


class MissionHost(Protocol):
    """What the wayline runner (``adapters/osdk/wayline.py``) may use of the aircraft adapter."""

    settings: OsdkDeviceSettings
    home_position: tuple[float, float] | None

    @property
    def clock(self) -> Clock: ...

    @property
    def info(self) -> Any: ...

    @property
    def online(self) -> bool: ...

    @property
    def in_air(self) -> bool: ...

    @property
    def has_control(self) -> bool: ...

    @property
    def telemetry(self) -> Any: ...

    @property
    def display_mode(self) -> int | None: ...

    @property
    def limits(self) -> MissionLimits:
        """The FC's mission rules (adapters/osdk/limits.py)."""

    def begin_mission(self, task: Task) -> None:
        """``task`` is the mission the FC flies from now on (its pushes are routed to it)."""

    def mission_started(self, task: Task) -> None:
        """The FC accepted the start of ``task``'s mission: from now on it may disagree."""

    async def start_mission(self, task: Task) -> None:
        """Start the uploaded mission of ``task``; a refused start ends the task and raises."""

    def require_no_mission(self) -> None:
        """Raise while a task is live (before anything is uploaded)."""

    async def stop_current_mission(self) -> bool:
        """Stop whatever task the FC flies for the gateway and end it canceled; whether it flew one."""

    def mission_stopped(self) -> None:
        """The FC acknowledged a mission stop: it flies none from now (whatever its last push said)."""

    async def exit_go_home(self) -> None:
        """End the FC's go home in whichever phase it is (flying home or landing at home): it hovers."""

    @property
    def current_mission(self) -> Task | None: ...

    async def ground_station(self, name: str, fields: Mapping[str, Any] | None = None) -> cmds.Message: ...

    async def obtain_control(self, control: int) -> None: ...

    async def flight_task(self, task: str) -> None: ...

    @property
    def fw(self) -> str:
        """The firmware generation: ``new`` (``01 41``/``01 42`` go-home altitude) or ``m100``."""

    async def set_go_home_altitude(self, altitude: int) -> None: ...

    async def read_go_home_altitude(self) -> float: ...

    async def secure(self, what: str, task_id: str, reason: str) -> str | None:
        """A task failed after take-off: land or go home (adapters/osdk/limits.py after_failure)."""


def distance_m(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Metres between two (latitude, longitude) points in degrees, flat earth."""
    north = math.radians(b[0] - a[0]) * 6_378_137.0
    east = math.radians(b[1] - a[1]) * 6_378_137.0 * math.cos(math.radians(a[0]))
    return math.hypot(north, east)
