"""Wayline benchmark: check, unpack, parse and map a 1,000-waypoint KMZ onto Onboard SDK missions on one
core (issue #20: <= 200 ms), and encode every resulting 0x03 0x10 / 0x11 frame payload.

The KMZ is written by ``adapters.wayline.writer`` (DJI's element layout, a gimbalRotate + takePhoto
every tenth waypoint); the measured path is the gateway's: ``load_route`` (MD5, zip limits, defusedxml
parse) then ``plan_route`` (heights, speeds, actions, chaining). Checked after timing: 1,000 route
waypoints, each once and in order, in missions of at most 255, and every payload 51 / 90 bytes.

Must not know MQTT or any I/O: bytes in, values out, a clock read by ``best_of``.
"""

from __future__ import annotations

import math

from adapters.osdk import commands as cmds
from adapters.osdk.wayline_plan import MISSION_MAX, PlanOptions, plan_route
from adapters.wayline.kmz import load_route
from adapters.wayline.writer import ActionSpec, PointSpec, kmz_bytes, md5_hex, waylines_wpml
from bench.run import Config, Row, best_of

__all__ = ["MAX_SECONDS", "run"]

MAX_SECONDS = 0.200  # parse + map 1,000 waypoints (issue #20)
HOME = (22.5431, 113.958)


def _kmz(n: int) -> bytes:
    actions = [ActionSpec("gimbalRotate", {"gimbalPitchRotateEnable": 1, "gimbalPitchRotateAngle": -30}),
               ActionSpec("takePhoto", {"fileSuffix": "p"})]  # fmt: skip
    points = []
    for i in range(n):  # a lawn-mower pattern, 10 m steps
        north, east = (i // 20) * 10.0, (i % 20) * 10.0 * (1 if (i // 20) % 2 == 0 else -1)
        lat = HOME[0] + math.degrees(north / 6_378_137.0)
        lon = HOME[1] + math.degrees(east / (6_378_137.0 * math.cos(math.radians(HOME[0]))))
        points.append(PointSpec(lat, lon, 40.0, actions=actions if i % 10 == 0 else ()))
    return kmz_bytes(waylines_wpml(points, finish_action="goHome"))


def run(cfg: Config) -> list[Row]:
    n = 1000
    kmz = _kmz(n)
    fingerprint = md5_hex(kmz)
    options = PlanOptions(here=(*HOME, 0.0), in_air=False, home=HOME, home_altitude=50.0, rth_altitude=60)

    def parse_and_map() -> object:
        return plan_route(load_route(kmz, fingerprint), options)

    seconds, plan = best_of(parse_and_map, cfg.repeat, cfg.warmup)
    refs = [r for m in plan.missions for r in m.points if r is not None]  # type: ignore[attr-defined]
    if refs != [(0, i) for i in range(n)]:
        raise AssertionError("the plan does not hold every waypoint once, in order")
    if any(len(m.waypoints) > MISSION_MAX for m in plan.missions):  # type: ignore[attr-defined]
        raise AssertionError("a mission longer than the FC takes")

    def encode() -> list[bytes]:
        out = []
        for m in plan.missions:  # type: ignore[attr-defined]
            out.append(cmds.encode_request("wp_init", m.init, "new"))
            out += [cmds.encode_request("wp_upload", w, "new") for w in m.waypoints]
        return out

    enc_seconds, payloads = best_of(encode, cfg.repeat, cfg.warmup)
    if any(len(p) not in (51, 90) for p in payloads):
        raise AssertionError("a mission payload of the wrong size")
    note = f"{len(kmz):,} B KMZ, {len(plan.missions)} missions, {seconds * 1000:.1f} ms"  # type: ignore[attr-defined]
    return [
        Row(
            group="wayline",
            case=f"load_route + plan_route, {n} waypoints (<= {MAX_SECONDS * 1000:.0f} ms)",
            count=1,
            rate=1.0 / seconds,
            min_rate=1.0 / MAX_SECONDS,
            unit="routes/s",
            note=note,
        ),
        Row(
            group="wayline",
            case="encode every 0x03 0x10 / 0x11 payload of that plan",
            count=len(payloads),
            rate=len(payloads) / enc_seconds,
            unit="payloads/s",
        ),
    ]
