"""The flight controller's ground-station mission rules, checked before anything moves: a take-off, fly-to
or wayline whose mission the flight controller would refuse is refused in the reply instead of after a
take-off. Also the rule for an aircraft whose task failed after it took off (:func:`after_failure`).

Owns the numbers and the order of the checks (:class:`MissionLimits`, :func:`check_mission`) and the
words of a refusal (:class:`LimitBreach`: the field, the distance or height, the limit, the FC's ACK code
it stands for). Sans-I/O: points and positions in, a verdict out. Must not know the serial link, MQTT,
Cloud API services or the simulator (which enforces the same rules on its own, as the FC does).

The rules, as DJI's Onboard-SDK documents the waypoint mission ACKs (``DJI::OSDK::ErrorCode::MissionACK``,
``dji_error.hpp``/``dji_error.cpp``, https://developer.dji.com/onboard-api-reference/
structDJI_1_1OSDK_1_1ErrorCode_1_1MissionACK_1_1Common.html and ``..._WayPoint.html``), in the order the
gateway checks them:

=========  ==============================================  ==================================================
ACK        rule                                            limit
=========  ==============================================  ==================================================
``0xC0``   a waypoint higher than the maximum height       ``max_height`` (the FC's user limit, 20..500 m)
``0xC1``   a waypoint lower than the minimum               -200 m (the Mobile SDK's waypoint range)
``0xC7``   a waypoint too far from home                    ``max_distance`` (the FC's radius limit)
``0xC9``   the first waypoint too far from the aircraft    ``max_distance``
``0xE6``   neighbouring waypoints too far apart            2000 m in 3-D (the Mobile SDK's [0.5, 2000] m)
``0xE2``   the route (waypoint 1 to n) too long            60 km on new A3/N3 firmware, 30 km on others
``0xE3``   home → waypoint 1 + route + waypoint n → home   100 km on new A3/N3 firmware, 60 km on others
=========  ==============================================  ==================================================

The FC does not publish its radius limit (``0xC7``): it is set in DJI Assistant 2 / DJI GO, and the
Mobile SDK bounds it to [15, 500] m (3.x) or [15, 8000] m (4.x) from home. The gateway takes the
``max_distance`` setting (2000 m by default, the neighbour limit and the simulator's): conservative, so
that a route the FC would refuse is refused here, raised by whoever knows the FC's own setting.

After a failure (:func:`after_failure`): DJI's return-home rule (Inspire 2 / Matrice user manuals,
"Return to Home": within 20 m of the home point the aircraft lands where it is; farther, it climbs to the
return-home altitude, flies home and lands), applied to a task that failed once the aircraft was in the
air: an aircraft hovering 1.2 m over its take-off point lands; one out on its route goes home.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

__all__ = [
    "LAND_RADIUS",
    "LimitBreach",
    "MissionLimits",
    "after_failure",
    "check_mission",
    "flat_distance",
]

EARTH_RADIUS_M = 6_378_137.0
#: DJI's return-home rule: closer than this (m, horizontally) to home, return home lands where it is
LAND_RADIUS = 20.0

TOO_HIGH, TOO_LOW, TOO_FAR_FROM_HOME, TOO_FAR_FROM_AIRCRAFT = 0xC0, 0xC1, 0xC7, 0xC9
TRACE_TOO_LONG, TOTAL_TOO_LONG, POINTS_TOO_FAR = 0xE2, 0xE3, 0xE6


@dataclass(frozen=True, slots=True)
class MissionLimits:
    """What one flight controller accepts in a waypoint mission (metres)."""

    max_distance: float = 2000.0  # from home (0xC7) and of the first waypoint from the aircraft (0xC9)
    max_height: float = 500.0  # above take-off (0xC0)
    min_height: float = -200.0  # (0xC1)
    max_leg: float = 2000.0  # neighbouring waypoints, 3-D (0xE6)
    max_trace: float = 60_000.0  # waypoint 1 to n (0xE2)
    max_total: float = 100_000.0  # home to waypoint 1, the route, waypoint n to home (0xE3)

    @classmethod
    def for_firmware(cls, firmware: str, *, max_distance: float, max_height: float) -> MissionLimits:
        """The limits of ``firmware`` ("new": A3/N3 3.x; anything else, e.g. "m100": the older ones)."""
        trace, total = (60_000.0, 100_000.0) if firmware == "new" else (30_000.0, 60_000.0)
        return cls(max_distance=max_distance, max_height=max_height, max_trace=trace, max_total=total)


@dataclass(frozen=True, slots=True)
class LimitBreach:
    """Why the FC would refuse a mission: ``ack`` the ground-station ACK it would answer, ``field`` the
    request field (or route point) at fault, ``text`` the sentence for the reply."""

    ack: int
    field: str
    text: str
    kind: str  # "distance" or "height"

    def __str__(self) -> str:
        return self.text


def flat_distance(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Metres between two (latitude, longitude) points in degrees, on a local flat earth (as the FC's
    own mission check; good to a fraction of a percent over the tens of kilometres that matter here)."""
    north = math.radians(b[0] - a[0]) * EARTH_RADIUS_M
    east = math.radians(b[1] - a[1]) * EARTH_RADIUS_M * math.cos(math.radians((a[0] + b[0]) / 2))
    return math.hypot(north, east)


def _km(metres: float) -> str:
    return f"{metres / 1000:.1f} km" if metres >= 1000 else f"{metres:.0f} m"


def check_mission(
    points: Sequence[tuple[float, float, float]],
    *,
    aircraft: tuple[float, float],
    home: tuple[float, float],
    limits: MissionLimits,
    names: Sequence[str] | None = None,
) -> LimitBreach | None:
    """The first rule ``points`` (latitude, longitude in degrees, height above take-off in m; the mission
    as it would be uploaded) break, or None. ``aircraft``: where it is now; ``home``: where it took off
    (where it stands, on the ground). ``names[i]`` names point i in the refusal (default ``waypoint i``)."""

    def name(i: int) -> str:
        return names[i] if names is not None and i < len(names) else f"waypoint {i}"

    for i, (_, _, h) in enumerate(points):
        if h > limits.max_height:
            return LimitBreach(
                TOO_HIGH, name(i), f"{name(i)}: {h:.1f} m above take-off, higher than the "
                f"{limits.max_height:g} m limit", "height",
            )  # fmt: skip
        if h < limits.min_height:
            return LimitBreach(
                TOO_LOW, name(i), f"{name(i)}: {h:.1f} m relative to take-off, lower than the "
                f"{limits.min_height:g} m limit", "height",
            )  # fmt: skip
    for i, (lat, lon, _) in enumerate(points):
        d = flat_distance(home, (lat, lon))
        if d > limits.max_distance:
            where = "the aircraft (its home)" if flat_distance(aircraft, home) < 1.0 else "home"
            return LimitBreach(
                TOO_FAR_FROM_HOME, name(i), f"{name(i)}: {_km(d)} from {where}, more than the "
                f"{_km(limits.max_distance)} limit (max_distance)", "distance",
            )  # fmt: skip
    if points:
        d = flat_distance(aircraft, points[0][:2])
        if d > limits.max_distance:
            return LimitBreach(
                TOO_FAR_FROM_AIRCRAFT, name(0), f"{name(0)}: {_km(d)} from the aircraft, more than the "
                f"{_km(limits.max_distance)} limit (max_distance)", "distance",
            )  # fmt: skip
    trace = 0.0
    for i, (a, b) in enumerate(itertools.pairwise(points)):
        leg = math.hypot(flat_distance(a[:2], b[:2]), b[2] - a[2])
        if leg > limits.max_leg:
            return LimitBreach(
                POINTS_TOO_FAR, name(i + 1), f"{name(i + 1)}: {_km(leg)} from {name(i)}, more than the "
                f"{_km(limits.max_leg)} the flight controller flies between two waypoints", "distance",
            )  # fmt: skip
        trace += leg
    if trace > limits.max_trace:
        return LimitBreach(
            TRACE_TOO_LONG, "route", f"route: {_km(trace)} long, more than the flight controller's "
            f"{_km(limits.max_trace)}", "distance",
        )  # fmt: skip
    if points:
        total = trace + flat_distance(home, points[0][:2]) + flat_distance(points[-1][:2], home)
        if total > limits.max_total:
            return LimitBreach(
                TOTAL_TOO_LONG, "route", f"route: {_km(total)} from home and back, more than the flight "
                f"controller's {_km(limits.max_total)}", "distance",
            )  # fmt: skip
    return None


def after_failure(*, in_air: bool, has_control: bool, home_distance: float | None) -> str | None:
    """What the gateway does with an aircraft whose task failed after it took off: ``"landing"`` (within
    :data:`LAND_RADIUS` of home), ``"go_home"`` (farther, or home unknown: the FC knows its home), or None
    (on the ground, or not the gateway's to command: the RC took it back)."""
    if not in_air or not has_control:
        return None
    if home_distance is not None and home_distance < LAND_RADIUS:
        return "landing"
    return "go_home"
