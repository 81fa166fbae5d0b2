"""A parsed WPML route (``adapters.wayline.kmz.Route``) → seed 004 ground-station missions: the 0x03 0x10
mission init and the 0x03 0x11 waypoints, chained when the route is longer than one mission.

Sans-I/O: values in, values out (no clock, no link). Owns what an Onboard SDK flight controller can fly
of a route and the refusals of what it cannot (:class:`RouteRefused`, with the matching
``break_reason`` of WAYLINE-NOTES §4.1). Knows nothing of MQTT, downloads or tasks.

Mapping (WAYLINE-NOTES §7; seed 004 § 0x03 0x10 / 0x11, read byte by byte in commands.py):

=================================  ================================================================
WPML                               flight controller
=================================  ================================================================
executeHeightMode                  ``relativeToStartPoint``: ``altitude`` as is (the FC's waypoints are
                                   relative to take-off); ``WGS84``: minus the home altitude (telemetry
                                   altitude − height); ``realTimeFollowSurface`` and others: refused, 1541
autoFlightSpeed / waypointSpeed    the segment from waypoint i flies at waypointSpeed(i) (else
                                   autoFlightSpeed): ``idle_vel`` of the init for the first one, then
                                   0x03 0x16 set idle velocity on reaching each waypoint whose speed
                                   differs (the FC has one cruise speed per mission); > 15 m/s or ≤ 0: 1547
globalTransitionalSpeed            speed of the entry leg (to the first waypoint) and between waylines
waypointHeadingMode                followWayline → yaw_mode 0; fixed → 1 (locked); manually → 2 (RC);
                                   smoothTransition → 3 with tgt_yaw = waypointHeadingAngle and turn_mode
                                   from waypointHeadingPathMode (followBadArc: the shorter way);
                                   towardPOI, or modes mixed in one wayline: refused, 1543
waypointTurnMode                   toPointAndStopWithDiscontinuityCurvature → trace_mode 0;
                                   coordinateTurn on every inner waypoint → trace_mode 1 with
                                   damping_dis (the end points stop, damping 0); coordinateTurn with
                                   actions (trace mode 1 runs none) or mixed with stops inside, and the
                                   curvature modes: refused, 1545
finishAction                       noAction → 0 (hover); autoLand → 2; gotoFirstWaypoint → 3; goHome →
                                   two waypoints the gateway adds (up to the RTH height over the last
                                   point, over home at that height) and 2 (land), so ``rth_altitude`` is
                                   flown (the FC's own go-home height is not settable by the protocol)
exitOnRCLost / prepare's           ``action_on_rc_lost`` 0 (exit, the FC's RC-lost failsafe) or 1
exit_wayline_when_rc_lost          (continue); the prepare field wins when present (the cloud's latest
                                   word; WAYLINE-NOTES §8.8 leaves it open), a conflict is logged
executeRCLostAction                goBack accepted (the FC's failsafe, set in DJI Assistant, is RTH by
                                   default); landing/hover refused: the protocol cannot set it
takeOffSecurityHeight /            an entry waypoint the gateway adds above the aircraft: on the ground
flyToWaylineMode                   at takeOffSecurityHeight (``rth_altitude`` when resuming from a break
                                   point, §8.10), ``safely`` at least the first waypoint's height
                                   (climb, then level), ``pointToPoint`` that height only (then slanted)
actions (reachPoint trigger)       takePhoto 1, startRecord 2, stopRecord 3, rotateYaw 4
                                   (aircraftHeading), gimbalRotate 5 (pitch only; roll/yaw enabled
                                   with a non-zero angle refused), hover 0 (ms, split into 32.767 s
                                   slots); at most 16 per waypoint. Skipped and listed in ``skipped``
                                   (camera settings the FC cannot reach): focus, zoom, customDirName.
                                   Any other action: refused, 1634; other triggers: refused, 1649
=================================  ================================================================

A mission holds at most :data:`MISSION_MAX` waypoints (the u8 ``length``; the simulator and the Mobile
SDK's documented range 2..255). Longer routes are split: mission k+1 starts at mission k's last waypoint
(its actions already ran, so they are dropped there) and is uploaded and started when mission k ends.
"""

from __future__ import annotations

import itertools
import logging
import math
from dataclasses import dataclass, field
from typing import Any

from adapters.errors import RouteRefused
from adapters.osdk.limits import MissionLimits, check_mission
from adapters.wayline.kmz import Action, ActionGroup, Placemark, Route

log = logging.getLogger(__name__)

__all__ = ["MISSION_MAX", "FcMission", "Plan", "PlanOptions", "RouteRefused", "plan_route"]

MISSION_MAX = 255
ACTION_SLOTS = 16
MAX_SPEED = 15.0
EARTH_RADIUS_M = 6_378_137.0
_HOVER_SLOT_MS = 32_767
#: WPML actions → seed 004 WP_ACTIONS command values
WP_STAY, WP_SHOT, WP_VIDEO_START, WP_VIDEO_STOP, WP_CRAFT_YAW, WP_GIMBAL_PITCH = 0, 1, 2, 3, 4, 5
_SKIPPED_ACTIONS = frozenset({"focus", "zoom", "customDirName"})
_YAW_MODES = {"followWayline": 0, "fixed": 1, "manually": 2, "smoothTransition": 3}
_FINISH = {"noAction": 0, "autoLand": 2, "gotoFirstWaypoint": 3}


@dataclass(frozen=True, slots=True)
class PlanOptions:
    """What the plan needs from the aircraft and the prepare request."""

    here: tuple[float, float, float]  # latitude, longitude (°), height above take-off (m)
    in_air: bool
    home: tuple[float, float]  # latitude, longitude of the home point (°)
    home_altitude: float | None  # WGS84 altitude of the take-off point (m); None: unknown
    rth_altitude: float | None = None
    exit_wayline_when_rc_lost: int | None = None
    break_point: tuple[int, int, int] | None = None  # wayline_id, index, state (0 segment, 1 waypoint)
    vel_cmd_range: float = MAX_SPEED
    mission_max: int = MISSION_MAX
    #: the FC's mission rules (adapters/osdk/limits.py): a route that breaks one is refused (None: unchecked)
    limits: MissionLimits | None = None


@dataclass
class FcMission:
    """One ground-station mission: the 0x03 0x10 fields and one 0x03 0x11 field set per waypoint.

    ``points[i]`` is (wayline_id, index) of the route waypoint that mission waypoint i is, or None for a
    waypoint the gateway added (entry, return home, a chained mission's repeated start).
    """

    init: dict[str, Any]
    waypoints: list[dict[str, Any]]
    points: list[tuple[int, int] | None]
    speeds: list[float]  # speed of the segment that starts at mission waypoint i
    photos: list[int]  # takePhoto actions at mission waypoint i


@dataclass
class Plan:
    missions: list[FcMission]
    route_points: int  # waypoints of the route the cloud counts (after a break point)
    skipped: list[str] = field(default_factory=list)
    rc_lost_conflict: bool = False


@dataclass
class _Point:
    lat: float
    lon: float
    alt: float  # relative to take-off
    speed: float
    ref: tuple[int, int] | None
    yaw: int = 0
    turn: int = 0
    damping: float = 0.0
    commands: list[tuple[int, int]] = field(default_factory=list)


def _speed(value: float | None, what: str) -> float:
    if value is None:
        raise RouteRefused(1547, f"{what} missing")
    if not 0.0 < value <= MAX_SPEED:
        raise RouteRefused(1547, f"{what} {value:g} m/s outside (0, {MAX_SPEED:g}]")
    return value


def _num(params: dict[str, str], name: str, default: float = 0.0) -> float:
    raw = params.get(name)
    if raw is None or raw == "":
        return default
    try:
        value = float(raw)
    except ValueError:
        raise RouteRefused(6, f"action parameter {name} is not a number") from None
    if not math.isfinite(value):
        raise RouteRefused(6, f"action parameter {name} is not finite")
    return value


def _action_commands(action: Action, where: str, skipped: list[str]) -> list[tuple[int, int]]:
    func, p = action.func, action.params
    if func == "takePhoto":
        return [(WP_SHOT, 0)]
    if func == "startRecord":
        return [(WP_VIDEO_START, 0)]
    if func == "stopRecord":
        return [(WP_VIDEO_STOP, 0)]
    if func == "rotateYaw":
        heading = _num(p, "aircraftHeading")
        if not -180.0 <= heading <= 180.0:
            raise RouteRefused(1553, f"{where}: rotateYaw heading {heading:g}° outside [-180, 180]")
        return [(WP_CRAFT_YAW, round(heading))]
    if func == "hover":
        ms = round(_num(p, "hoverTime") * 1000)
        if ms <= 0:
            raise RouteRefused(6, f"{where}: hover time must be > 0")
        out = []
        while ms > 0:
            out.append((WP_STAY, min(ms, _HOVER_SLOT_MS)))
            ms -= _HOVER_SLOT_MS
        return out
    if func == "gimbalRotate":
        for axis in ("Roll", "Yaw"):
            if _num(p, f"gimbal{axis}RotateEnable") and _num(p, f"gimbal{axis}RotateAngle"):
                raise RouteRefused(
                    1634, f"{where}: gimbalRotate {axis.lower()}: the FC's action moves pitch only"
                )
        if p.get("gimbalRotateMode", "absoluteAngle") != "absoluteAngle":
            raise RouteRefused(1634, f"{where}: gimbalRotate mode {p.get('gimbalRotateMode')} not supported")
        if not _num(p, "gimbalPitchRotateEnable"):
            return []
        pitch = _num(p, "gimbalPitchRotateAngle")
        if not -120.0 <= pitch <= 45.0:
            raise RouteRefused(6, f"{where}: gimbal pitch {pitch:g}° out of range")
        if _num(p, "gimbalRotateTimeEnable"):
            skipped.append(f"{where}: gimbalRotate time (the FC's pitch action has no duration)")
        return [(WP_GIMBAL_PITCH, round(pitch))]
    if func in _SKIPPED_ACTIONS:
        skipped.append(f"{where}: {func} (a camera setting the flight controller cannot reach)")
        return []
    raise RouteRefused(1634, f"{where}: action {func} is not supported by an Onboard SDK flight controller")


def _group_commands(groups: list[ActionGroup], where: str, skipped: list[str]) -> list[tuple[int, int]]:
    out: list[tuple[int, int]] = []
    for g in groups:
        if g.trigger != "reachPoint":
            raise RouteRefused(1649, f"{where}: action trigger {g.trigger} not supported (reachPoint only)")
        for a in sorted(g.actions, key=lambda a: a.action_id):
            if a.action_id == 65535:
                raise RouteRefused(1598, f"{where}: action id 65535")
            out += _action_commands(a, where, skipped)
    if len(out) > ACTION_SLOTS:
        raise RouteRefused(1602, f"{where}: {len(out)} actions, the FC runs at most {ACTION_SLOTS}")
    return out


def _wrap(deg: float) -> float:
    return (deg + 180.0) % 360.0 - 180.0


def plan_route(route: Route, o: PlanOptions) -> Plan:
    """The missions that fly ``route`` from where the aircraft is; RouteRefused for what the FC cannot do."""
    cfg = route.config
    skipped: list[str] = []
    if cfg.exit_on_rc_lost not in ("goContinue", "executeLostAction"):
        raise RouteRefused(6, f"exitOnRCLost {cfg.exit_on_rc_lost} unknown")
    kmz_exit = cfg.exit_on_rc_lost == "executeLostAction"
    exit_rc = kmz_exit if o.exit_wayline_when_rc_lost is None else o.exit_wayline_when_rc_lost == 1
    conflict = o.exit_wayline_when_rc_lost is not None and exit_rc != kmz_exit
    if conflict:
        log.warning("exit_wayline_when_rc_lost contradicts the KMZ's exitOnRCLost: the prepare request wins")
    if exit_rc and (cfg.execute_rc_lost_action or "goBack") != "goBack":
        raise RouteRefused(
            6,
            f"executeRCLostAction {cfg.execute_rc_lost_action}: the FC's RC-lost failsafe is set in DJI"
            " Assistant 2, not by the open protocol; only goBack is accepted",
        )
    if cfg.finish_action not in (*_FINISH, "goHome"):
        raise RouteRefused(6, f"finishAction {cfg.finish_action} unknown")
    if cfg.fly_to_wayline_mode not in ("safely", "pointToPoint"):
        raise RouteRefused(1542, f"flyToWaylineMode {cfg.fly_to_wayline_mode} not supported")
    transit = _speed(cfg.global_transitional_speed, "globalTransitionalSpeed")

    points: list[_Point] = []
    yaw_mode: int | None = None
    trace_mode = 0
    started = o.break_point is None
    for wl in route.waylines:
        if wl.execute_height_mode == "relativeToStartPoint":
            offset = 0.0
        elif wl.execute_height_mode == "WGS84":
            if o.home_altitude is None:
                raise RouteRefused(
                    1541, "WGS84 heights need the aircraft's home altitude (no position yet)", 314000
                )
            offset = o.home_altitude
        else:
            raise RouteRefused(
                1541,
                f"executeHeightMode {wl.execute_height_mode} not supported by an Onboard SDK FC",
            )
        if wl.start_actions:
            raise RouteRefused(1634, f"wayline {wl.wayline_id}: startActionGroup not supported")
        auto = _speed(wl.auto_flight_speed, f"wayline {wl.wayline_id} autoFlightSpeed")
        modes = {pm.heading_mode or "followWayline" for pm in wl.placemarks}
        if len(modes) > 1 or not modes <= set(_YAW_MODES):
            raise RouteRefused(
                1543, f"wayline {wl.wayline_id}: heading mode(s) {sorted(modes)} not supported"
            )
        mode = _YAW_MODES[modes.pop()]
        if yaw_mode is not None and mode != yaw_mode:
            raise RouteRefused(1543, "waylines with different heading modes")
        yaw_mode = mode
        trace_mode = max(trace_mode, _trace_mode(wl.wayline_id, wl.placemarks))
        groups_at: dict[int, list[ActionGroup]] = {}
        for pm in wl.placemarks:
            for g in pm.action_groups:
                if not 0 <= g.start_index <= g.end_index < len(wl.placemarks):
                    raise RouteRefused(1603, f"wayline {wl.wayline_id}: action group {g.group_id} range")
                for i in range(g.start_index, g.end_index + 1):
                    groups_at.setdefault(i, []).append(g)
        prev_yaw = 0.0
        for pm in wl.placemarks:
            if not started:
                bw, bi, bs = o.break_point  # type: ignore[misc]
                if wl.wayline_id != bw or pm.index < (bi if bs == 1 else bi + 1):
                    continue
                started = True
            where = f"wayline {wl.wayline_id} waypoint {pm.index}"
            speed = _speed(pm.speed if pm.speed is not None else auto, f"{where} waypointSpeed")
            p = _Point(
                pm.latitude, pm.longitude, pm.execute_height - offset, speed, (wl.wayline_id, pm.index)
            )
            if mode == 3:
                angle = pm.heading_angle if pm.heading_angle is not None else prev_yaw
                if not -180.0 <= angle <= 180.0:
                    raise RouteRefused(1553, f"{where}: heading {angle:g}° outside [-180, 180]")
                path = pm.heading_path_mode or "followBadArc"
                p.turn = {"clockwise": 0, "counterClockwise": 1}.get(
                    path, 0 if _wrap(angle - prev_yaw) >= 0 else 1
                )
                p.yaw, prev_yaw = round(angle), angle
            if pm.turn_mode == "coordinateTurn":
                p.damping = pm.turn_damping or 0.0
            p.commands = _group_commands(groups_at.get(pm.index, []), where, skipped)
            if trace_mode == 1 and p.commands:
                raise RouteRefused(1545, f"{where}: coordinateTurn routes run no waypoint actions on the FC")
            points.append(p)
    if not points:
        raise RouteRefused(1539, "the break point is past the end of the route")
    route_points = len(points)

    # entry: above the aircraft, at a safe height, before the first waypoint (module docstring)
    lat, lon, height = o.here
    first = points[0]
    climb = o.rth_altitude if (o.break_point is not None and o.rth_altitude) else cfg.take_off_security_height
    entry_h = height if o.in_air else max(height, climb)
    if cfg.fly_to_wayline_mode == "safely":
        entry_h = max(entry_h, first.alt)
    entry = _Point(lat, lon, entry_h, transit, None, yaw=first.yaw)
    if _dist(entry, first) >= 1.0:
        points.insert(0, entry)
    # between waylines the transitional speed applies
    for a, b in itertools.pairwise(points):
        if a.ref is not None and b.ref is not None and a.ref[0] != b.ref[0]:
            a.speed = transit
    finish = _FINISH.get(cfg.finish_action, 2)
    if cfg.finish_action == "goHome":
        last = points[-1]
        rth = o.rth_altitude or cfg.global_rth_height or last.alt
        rth = max(rth, last.alt)
        up = _Point(last.lat, last.lon, rth, transit, None, yaw=last.yaw)
        home = _Point(o.home[0], o.home[1], rth, transit, None, yaw=last.yaw)
        last.speed = transit
        for extra in (up, home):
            if _dist(points[-1], extra) >= 1.0:
                points.append(extra)
    if len(points) < 2:
        points.insert(0, _Point(lat, lon, max(height, climb), transit, None))
    _check_limits(points, o)
    missions = _split(points, o, yaw_mode or 0, trace_mode, finish, exit_rc, transit)
    return Plan(missions, route_points, skipped, conflict)


#: Cloud API results (WAYLINE-NOTES §3.7, [ERR]) and break reasons (§4.1) of a route beyond the FC's limits
#: (schemas.results.ResultCode.WAYLINE_ALTITUDE_LIMIT / _DISTANCE_LIMIT: this sans-I/O module imports no
#: contract; tests/test_osdk_preflight.py holds them equal)
ALTITUDE_LIMIT, DISTANCE_LIMIT = 321513, 321514
BREAK_ALTITUDE, BREAK_DISTANCE = 513, 514


def _check_limits(points: list[_Point], o: PlanOptions) -> None:
    """Refuse a route any of whose missions the FC would refuse (adapters/osdk/limits.py): each chained
    mission is checked as the FC checks an upload, from where the aircraft will be when it starts."""
    if o.limits is None:
        return
    names = []
    for k, p in enumerate(points):
        if p.ref is not None:
            names.append(f"wayline {p.ref[0]} waypoint {p.ref[1]}")
        else:
            names.append("the entry point above the aircraft" if k == 0 else "the way home")
    here = (o.here[0], o.here[1])
    for start, chunk in _chunks(points, o):
        at = here if start == 0 else (chunk[0].lat, chunk[0].lon)
        breach = check_mission(
            [(p.lat, p.lon, p.alt) for p in chunk],
            aircraft=at,
            home=o.home,
            limits=o.limits,
            names=names[start : start + len(chunk)],
        )
        if breach is not None:
            height = breach.kind == "height"
            raise RouteRefused(
                BREAK_ALTITUDE if height else BREAK_DISTANCE,
                f"{breach.text} (the flight controller would refuse it: 0x{breach.ack:02X})",
                ALTITUDE_LIMIT if height else DISTANCE_LIMIT,
            )


def _chunks(points: list[_Point], o: PlanOptions) -> list[tuple[int, list[_Point]]]:
    """The missions ``points`` are split into: (index of the first point, the points); mission k+1 starts
    at mission k's last waypoint."""
    size = max(2, min(o.mission_max, MISSION_MAX))
    chunks: list[tuple[int, list[_Point]]] = []
    start = 0
    while True:
        chunks.append((start, points[start : start + size]))
        if start + size >= len(points):
            break
        start += size - 1  # the next mission starts where this one ends
    return chunks


def _trace_mode(wid: int, pms: tuple[Placemark, ...]) -> int:
    modes = [pm.turn_mode or "toPointAndStopWithDiscontinuityCurvature" for pm in pms]
    allowed = {"toPointAndStopWithDiscontinuityCurvature", "coordinateTurn"}
    bad = sorted(set(modes) - allowed)
    if bad:
        raise RouteRefused(
            1545, f"wayline {wid}: turn mode {bad[0]} not supported (the FC flies straight lines)"
        )
    if modes[0] == "coordinateTurn" or (len(modes) > 1 and modes[-1] == "coordinateTurn"):
        raise RouteRefused(1546, f"wayline {wid}: coordinated turn on the first or last waypoint")
    inner = set(modes[1:-1])
    if "coordinateTurn" not in inner:
        return 0
    if inner != {"coordinateTurn"}:
        raise RouteRefused(
            1545, f"wayline {wid}: coordinated turns mixed with stops (one trace mode per mission)"
        )
    return 1


def _dist(a: _Point, b: _Point) -> float:
    n = math.radians(b.lat - a.lat) * EARTH_RADIUS_M
    e = math.radians(b.lon - a.lon) * EARTH_RADIUS_M * math.cos(math.radians(a.lat))
    return math.sqrt(n * n + e * e + (b.alt - a.alt) ** 2)


def _split(
    points: list[_Point],
    o: PlanOptions,
    yaw_mode: int,
    trace_mode: int,
    finish: int,
    exit_rc: bool,
    transit: float,
) -> list[FcMission]:
    chunks = [chunk for _, chunk in _chunks(points, o)]
    missions = []
    for k, chunk in enumerate(chunks):
        if k > 0:  # the repeated start: already flown, its actions already ran
            p0 = chunk[0]
            chunk = [_Point(p0.lat, p0.lon, p0.alt, p0.speed, None, p0.yaw, p0.turn, p0.damping), *chunk[1:]]
        init = {
            "length": len(chunk),
            "vel_cmd_range": o.vel_cmd_range,
            "idle_vel": min(chunk[0].speed if k else transit, o.vel_cmd_range),
            "action_on_finish": finish if k == len(chunks) - 1 else 0,
            "mission_exec_num": 1,
            "yaw_mode": yaw_mode,
            "trace_mode": trace_mode,
            "action_on_rc_lost": 0 if exit_rc else 1,
            "gimbal_pitch_mode": 0,  # free: the gimbal moves only by gimbalRotate actions
        }
        wps = []
        for i, p in enumerate(chunk):
            cmds = p.commands
            stay = sum(param for c, param in cmds if c == WP_STAY) / 1000.0
            wps.append(
                {
                    "index": i,
                    "latitude": math.radians(p.lat),
                    "longitude": math.radians(p.lon),
                    "altitude": p.alt,
                    "damping_dis": p.damping,
                    "tgt_yaw": p.yaw,
                    "tgt_gimbal_pitch": 0,
                    "turn_mode": p.turn,
                    "has_action": 1 if cmds else 0,
                    "action_time_limit": min(0xFFFF, 100 + math.ceil(stay)),
                    "action_num": len(cmds),
                    "action_rpt": 1 if cmds else 0,
                    "command_list": [c for c, _ in cmds] + [0] * (ACTION_SLOTS - len(cmds)),
                    "command_param": [param for _, param in cmds] + [0] * (ACTION_SLOTS - len(cmds)),
                }
            )
        missions.append(
            FcMission(
                init=init,
                waypoints=wps,
                points=[p.ref for p in chunk],
                speeds=[p.speed for p in chunk],
                photos=[sum(1 for c, _ in p.commands if c == WP_SHOT) for p in chunk],
            )
        )
    return missions
