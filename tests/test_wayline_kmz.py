"""The KMZ reader against hostile files (zip bomb, entity expansion, paths outside the archive, 100,000
waypoints, wrong namespace) and a hypothesis fuzz; the OSDK mapping byte by byte; the task book."""

from __future__ import annotations

import io
import math
import struct
import zipfile
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from adapters.errors import KmzError, RouteRefused
from adapters.osdk import commands as cmds
from adapters.osdk.wayline_plan import MISSION_MAX, PlanOptions, plan_route
from adapters.wayline.kmz import Limits, load_route, parse_wpml, unpack_wpml
from adapters.wayline.writer import ActionSpec, PointSpec, kmz_bytes, md5_hex, waylines_wpml
from gateway.wayline.task import ON_SEGMENT, ON_WAYPOINT, Phase, TaskBook, Verdict, break_point_at
from tests.test_sans_io import ROOT, _imports

HOME = (22.5431, 113.958)


def _ne(n: float, e: float) -> tuple[float, float]:
    return (
        HOME[0] + math.degrees(n / 6_378_137.0),
        HOME[1] + math.degrees(e / (6_378_137.0 * math.cos(math.radians(HOME[0])))),
    )


def _points(count: int, step: float = 10.0, height: float = 30.0, **kw: Any) -> list[PointSpec]:
    return [PointSpec(*_ne(i * step, 0.0), height, **kw) for i in range(count)]


def _options(**kw: Any) -> PlanOptions:
    base: dict[str, Any] = {"here": (*HOME, 0.0), "in_air": False, "home": HOME, "home_altitude": 50.0}
    return PlanOptions(**{**base, **kw})


# ------------------------------------------------------------------------------------- the happy path


def test_written_kmz_reads_back_with_uppercase_fingerprint_accepted() -> None:
    actions = [ActionSpec("gimbalRotate", {"gimbalPitchRotateEnable": 1, "gimbalPitchRotateAngle": -45}),
               ActionSpec("takePhoto", {"fileSuffix": "wp1"})]  # fmt: skip
    pts = _points(3)
    pts[1] = PointSpec(pts[1].latitude, pts[1].longitude, 30.0, actions=actions)
    kmz = kmz_bytes(waylines_wpml(pts))
    route = load_route(kmz, md5_hex(kmz).upper())
    (wl,) = route.waylines
    assert [p.index for p in wl.placemarks] == [0, 1, 2]
    assert abs(wl.placemarks[1].latitude - pts[1].latitude) < 1e-8  # lon,lat order kept apart
    assert [a.func for a in wl.placemarks[1].action_groups[0].actions] == ["gimbalRotate", "takePhoto"]


@pytest.mark.parametrize("version", ["1.0.0", "1.0.2", "1.0.6"])
def test_every_wpml_1_0_version_is_read_and_unknown_elements_ignored(version: str) -> None:
    mode = "<wpml:missionAutoRerouteMode>0</wpml:missionAutoRerouteMode>"
    extra = f"<wpml:autoRerouteInfo>{mode}</wpml:autoRerouteInfo>"
    xml = waylines_wpml(_points(2), namespace=f"http://www.dji.com/wpmz/{version}", extra_config=extra)
    xml = xml.replace("<wpml:index>0</wpml:index>", "<wpml:index>0</wpml:index><wpml:isRisky>0</wpml:isRisky>"
                      "<foo:bar xmlns:foo='urn:x'>1</foo:bar>")  # fmt: skip
    assert parse_wpml(xml.encode()).waypoint_count == 2


# ------------------------------------------------------------------------------------- hostile files


def _zip(entries: dict[str, bytes], method: int = zipfile.ZIP_DEFLATED) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", method) as z:
        for name, data in entries.items():
            z.writestr(name, data)
    return buf.getvalue()


def test_zip_bomb_is_refused_without_unpacking_it() -> None:
    bomb = _zip({"wpmz/waylines.wpml": b"\0" * (64 * 1024 * 1024)})
    assert len(bomb) < 200_000
    with pytest.raises(KmzError) as err:
        unpack_wpml(bomb)
    assert err.value.code == 314003 and "zip bomb" in err.value.reason


def test_a_lying_size_in_the_archive_is_caught_by_the_bounded_read() -> None:
    data = b"<kml/>" + b" " * 5000
    kmz = bytearray(_zip({"wpmz/waylines.wpml": data}, zipfile.ZIP_STORED))
    # shrink the declared size in the central directory: the reader must not trust it
    cd = kmz.rfind(b"PK\x01\x02")
    kmz[cd + 24 : cd + 28] = struct.pack("<I", 10)
    with pytest.raises(KmzError) as err:
        unpack_wpml(bytes(kmz), Limits(max_entry_bytes=1000, max_ratio=1e9))
    assert err.value.code == 314003


@pytest.mark.parametrize("name", ["../evil.wpml", "/etc/passwd", "wpmz/../../x", "C:/x", "wpmz\\..\\x"])
def test_paths_outside_the_archive_are_refused(name: str) -> None:
    kmz = _zip({"wpmz/waylines.wpml": waylines_wpml(_points(2)).encode(), name: b"x"})
    with pytest.raises(KmzError, match="outside the archive"):
        unpack_wpml(kmz)


def test_too_many_entries_are_refused() -> None:
    kmz = _zip({f"wpmz/res/{i}": b"" for i in range(300)})
    with pytest.raises(KmzError, match="entries"):
        unpack_wpml(kmz)


def test_entity_expansion_is_refused() -> None:
    laughs = (
        '<?xml version="1.0"?><!DOCTYPE kml [<!ENTITY a "aaaaaaaaaa">'
        + "".join(f'<!ENTITY {chr(98 + i)} "{("&" + chr(97 + i) + ";") * 10}">' for i in range(8))
        + ']><kml xmlns="http://www.opengis.net/kml/2.2">&i;</kml>'
    )
    with pytest.raises(KmzError, match="no DTDs or entities"):
        load_route(kmz_bytes(laughs), md5_hex(kmz_bytes(laughs)))


def test_external_entity_is_refused(tmp_path: Path) -> None:
    secret = tmp_path / "secret"
    secret.write_text("s3cr3t")
    xxe = f'<?xml version="1.0"?><!DOCTYPE kml [<!ENTITY x SYSTEM "file://{secret}">]><kml>&x;</kml>'
    with pytest.raises(KmzError, match="no DTDs or entities"):
        parse_wpml(xxe.encode())


def test_100000_waypoints_are_refused() -> None:
    one = "<Placemark><Point><coordinates>113.9,22.5</coordinates></Point><wpml:index>{}</wpml:index>" \
          "<wpml:executeHeight>30</wpml:executeHeight></Placemark>"  # fmt: skip
    head, tail = waylines_wpml([]).split("</Folder>")
    xml = head + "".join(one.format(i) for i in range(100_000)) + "</Folder>" + tail
    with pytest.raises(KmzError, match="more than 5000 waypoints"):
        parse_wpml(xml.encode())
    kmz = kmz_bytes(xml)  # as a file: refused too (by size or count), never a crash
    with pytest.raises(KmzError):
        load_route(kmz, md5_hex(kmz))


@pytest.mark.parametrize(
    "namespace", ["http://www.dji.com/wpmz/2.0.0", "http://www.dji.com/wpmz/1.1.0", "urn:not-dji"]
)
def test_wrong_namespace_is_refused(namespace: str) -> None:
    with pytest.raises(KmzError, match=r"namespace|no WPML"):
        parse_wpml(waylines_wpml(_points(2), namespace=namespace).encode())


def test_fingerprint_checks() -> None:
    kmz = kmz_bytes(waylines_wpml(_points(2)))
    with pytest.raises(KmzError) as empty:
        load_route(kmz, "")
    assert empty.value.code == 314002
    with pytest.raises(KmzError) as wrong:
        load_route(kmz, md5_hex(kmz + b"x"))
    assert wrong.value.code == 314005


def test_not_a_zip_and_missing_waylines() -> None:
    with pytest.raises(KmzError, match="not a KMZ"):
        unpack_wpml(b"PK\x03\x04garbage")
    with pytest.raises(KmzError, match=r"without wpmz/waylines\.wpml"):
        unpack_wpml(_zip({"wpmz/template.kml": b"<kml/>"}))


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=2000))
def test_fuzz_random_bytes_never_crash_the_reader(data: bytes) -> None:
    for reader in (unpack_wpml, parse_wpml):
        try:
            reader(data)
        except KmzError as exc:
            assert exc.code in (314002, 314003, 314005) and exc.reason


_WPML = waylines_wpml(_points(3), finish_action="goHome").encode()


@settings(max_examples=300, deadline=None)
@given(st.data(), st.booleans())
def test_fuzz_mutated_kmz_and_wpml_are_read_or_refused_cleanly(data: st.DataObject, zipped: bool) -> None:
    """Found so far: an unknown declared encoding (LookupError), corrupt deflate data (zlib.error), an
    unknown zip version (NotImplementedError): each now a 314003 refusal."""
    raw = kmz_bytes(_WPML) if zipped else _WPML
    xml = bytearray(raw)
    for _ in range(data.draw(st.integers(1, 8))):
        i = data.draw(st.integers(0, len(xml) - 1))
        xml[i] = data.draw(st.integers(0, 255))
    try:
        route = parse_wpml(unpack_wpml(bytes(xml)) if zipped else bytes(xml))
    except KmzError:
        return
    try:
        plan_route(route, _options())
    except RouteRefused as exc:
        assert exc.break_reason > 0 and exc.reason


# ------------------------------------------------------------------------------------- the mapping


def _route(points: list[PointSpec], **kw: Any) -> Any:
    return parse_wpml(waylines_wpml(points, **kw).encode())


def test_mapping_onto_mission_init_and_waypoints_byte_by_byte() -> None:
    pts = _points(3)
    pts[1] = PointSpec(pts[1].latitude, pts[1].longitude, 30.0, speed=4.0, actions=[
        ActionSpec("gimbalRotate", {"gimbalPitchRotateEnable": 1, "gimbalPitchRotateAngle": -45}),
        ActionSpec("takePhoto"), ActionSpec("hover", {"hoverTime": 40}),
        ActionSpec("rotateYaw", {"aircraftHeading": 90}),
        ActionSpec("startRecord"), ActionSpec("stopRecord")])  # fmt: skip
    route = _route(pts, speed=6.0, finish_action="autoLand", exit_on_rc_lost="goContinue")
    plan = plan_route(route, _options(exit_wayline_when_rc_lost=None))
    (m,) = plan.missions
    # entry above the take-off point at takeOffSecurityHeight (20 m) < first waypoint (30 m) → skipped:
    # safely climbs straight to the first waypoint's height over it
    assert m.points == [(0, 0), (0, 1), (0, 2)] and plan.route_points == 3
    init = cmds.encode_request("wp_init", m.init, "new")
    assert len(init) == 51
    length, vel_range, idle, finish, exec_num, yaw, trace, rc_lost, gimbal = struct.unpack_from(
        "<BffBBBBBB", init
    )
    assert (length, vel_range, idle, finish, exec_num, yaw, trace, rc_lost, gimbal) == (
        3,
        15.0,
        8.0,
        2,
        1,
        0,
        0,
        1,
        0,
    )
    assert init[-16:] == bytes(16)
    wp = cmds.encode_request("wp_upload", m.waypoints[1], "new")
    assert len(wp) == 90
    index, lat, _lon, alt = struct.unpack_from("<Bddf", wp)
    assert index == 1 and math.isclose(math.degrees(lat), pts[1].latitude) and alt == 30.0
    assert wp[29] == 0  # turn_mode (index 1 + 8 + 8 + 4 + damping 4 + yaw 2 + pitch 2)
    has_action, limit, action = struct.unpack_from("<BHB", wp, 38)  # after resv[8]
    assert has_action == 1 and limit == 100 + 40 and action == (1 << 4) | 7  # rpt 1 : num 7 (C bit order)
    commands = list(wp[42:58])
    params = list(struct.unpack_from("<16h", wp, 58))
    assert commands[:7] == [5, 1, 0, 0, 4, 2, 3] and params[:7] == [-45, 0, 32767, 7233, 90, 0, 0]
    assert m.speeds == [6.0, 4.0, 6.0] and m.photos == [0, 1, 0]


def test_wgs84_heights_use_the_home_altitude_and_follow_surface_is_refused() -> None:
    route = _route(_points(2, height=80.0), height_mode="WGS84")
    (m,) = plan_route(route, _options(home_altitude=50.0)).missions
    assert [w["altitude"] for w in m.waypoints if w["index"] >= 0][-1] == 30.0
    with pytest.raises(RouteRefused) as err:
        plan_route(_route(_points(2), height_mode="realTimeFollowSurface"), _options())
    assert err.value.break_reason == 1541


@pytest.mark.parametrize(
    ("change", "reason"),
    [
        ({"heading_mode": "towardPOI"}, 1543),
        ({"turn_mode": "toPointAndPassWithContinuityCurvature"}, 1545),
        ({"actions": [ActionSpec("panoShot")]}, 1634),
        (
            {
                "actions": [
                    ActionSpec("gimbalRotate", {"gimbalYawRotateEnable": 1, "gimbalYawRotateAngle": 30})
                ]
            },
            1634,
        ),
        ({"speed": 20.0}, 1547),
    ],
)
def test_what_the_fc_cannot_do_is_refused_with_its_break_reason(change: dict[str, Any], reason: int) -> None:
    pts = _points(3)
    pts[1] = PointSpec(pts[1].latitude, pts[1].longitude, 30.0, **change)
    with pytest.raises(RouteRefused) as err:
        plan_route(_route(pts), _options())
    assert err.value.break_reason == reason


def test_skipped_actions_are_listed_not_silent() -> None:
    pts = _points(2, actions=[ActionSpec("zoom", {"focalLength": 24})])
    plan = plan_route(_route(pts), _options())
    assert any("zoom" in s for s in plan.skipped)


def test_long_routes_are_split_into_chained_missions() -> None:
    route = _route(_points(600, step=5.0), finish_action="goHome")
    plan = plan_route(route, _options(in_air=True, here=(*HOME, 30.0), rth_altitude=50))
    sizes = [len(m.waypoints) for m in plan.missions]
    assert all(s <= MISSION_MAX for s in sizes) and len(plan.missions) == 3
    refs = [r for m in plan.missions for r in m.points if r is not None]
    assert refs == [(0, i) for i in range(600)]  # every waypoint once, in order
    # the next mission starts where the previous ended, and only the last one finishes (lands)
    for a, b in zip(plan.missions, plan.missions[1:], strict=False):
        assert a.waypoints[-1]["latitude"] == b.waypoints[0]["latitude"] and b.points[0] is None
        assert a.init["action_on_finish"] == 0
    last = plan.missions[-1]
    assert last.init["action_on_finish"] == 2 and last.waypoints[-1]["altitude"] == 50.0  # home at rth
    for m in plan.missions:
        for w in m.waypoints:
            assert len(cmds.encode_request("wp_upload", w, "new")) == 90


def test_break_point_resumes_from_its_waypoint_at_rth_altitude() -> None:
    route = _route(_points(5))
    plan = plan_route(route, _options(break_point=(0, 3, 1), rth_altitude=60))
    (m,) = plan.missions
    assert m.points[0] is None and m.waypoints[0]["altitude"] == 60.0
    assert m.points[1:] == [(0, 3), (0, 4)] and plan.route_points == 2


def test_a_break_point_names_the_segment_by_the_waypoint_it_starts_from() -> None:
    """DJI's numbering (MSDK 5 ``BreakPointInfo``: 25 % of the way from waypoint 1 to waypoint 2 is
    waypoint 1, progress 0.25): after waypoint k the aircraft is on segment k, with the fraction flown."""
    pts = [(22.0, 113.0), (22.0, 113.001), (22.001, 113.001), (22.001, 113.002)]
    assert break_point_at(0, pts, (21.9999, 113.0)) == (0, ON_WAYPOINT, 0.0)  # before the first
    index, state, progress = break_point_at(2, pts, (22.00025, 113.001))  # a quarter of 1 -> 2
    assert (index, state) == (1, ON_SEGMENT) and progress == pytest.approx(0.25, abs=1e-6)
    assert break_point_at(2, pts, (21.999, 113.001))[2] == 0.0  # behind its start: clamped
    assert break_point_at(2, pts, (22.003, 113.001))[2] == 1.0
    lat = 22.0005  # half way east along segment 2 -> 3, where a degree of longitude is cos(22°) shorter
    assert break_point_at(3, pts, (22.001, 113.0015))[2] == pytest.approx(0.5, abs=1e-6)
    assert break_point_at(3, pts, (lat, 113.0015))[:2] == (2, ON_SEGMENT)
    assert break_point_at(4, pts, (22.001, 113.002)) == (3, ON_WAYPOINT, 0.0)  # after the last
    assert break_point_at(2, None, (22.0, 113.0)) == (1, ON_SEGMENT, 0.0)  # the route unknown
    assert break_point_at(0, pts, (22.0, 113.0), start=2) == (2, ON_WAYPOINT, 0.0)  # a resumed run


@given(st.integers(min_value=2, max_value=12), st.data())
@settings(max_examples=40, deadline=None)
def test_resuming_from_a_break_point_flies_on_from_the_next_waypoint(n: int, data: st.DataObject) -> None:
    """Break point out, prepare in: the resumed route starts with the waypoint the aircraft was flying
    to, never skipping it and never flying again the one it had reached (its actions: a second photo)."""
    route = _route(_points(n))
    pts = [(pm.latitude, pm.longitude) for pm in route.waylines[0].placemarks]
    done = data.draw(st.integers(min_value=0, max_value=n - 1))  # waypoints 0 .. done - 1 reached
    f = data.draw(st.floats(min_value=0.0, max_value=1.0))
    if done == 0:
        where = pts[0]
    else:
        (a_lat, a_lon), (b_lat, b_lon) = pts[done - 1], pts[done]
        where = (a_lat + f * (b_lat - a_lat), a_lon + f * (b_lon - a_lon))
    index, state, _ = break_point_at(done, pts, where)
    plan = plan_route(route, _options(break_point=(0, index, state), rth_altitude=60))
    flown = [p for m in plan.missions for p in m.points if p is not None]
    assert flown[0] == (0, done) and flown[-1] == (0, n - 1)


# ------------------------------------------------------------------------------------- the task book


class _Prep:
    def __init__(self, flight_id: str) -> None:
        self.flight_id = flight_id


def test_task_book_transitions_and_idempotence() -> None:
    book = TaskBook()
    task, new = book.prepare(_Prep("a"), 0.0)
    assert new and not book.prepare(_Prep("a"), 1.0)[1]
    assert book.execute("nope", 0.0)[0].result == 319003
    verdict, start = book.execute("a", 1.0)
    assert verdict.ok and start
    assert book.execute("a", 1.5) == (verdict, False)  # a resend does not start it twice
    book.prepare(_Prep("b"), 2.0)
    assert book.execute("b", 2.0)[0].result == 319016
    assert book.undo(["a"]).result == 319006
    assert book.pause()[0].result == 319046  # not yet flying
    book.planned(task, 3)
    book.entered(task)
    assert book.progress(task)["output"]["status"] == "in_progress"
    book.reached(task, 0, 0, 1)
    assert book.recovery() == (Verdict(), None)  # running: what recovery asks already holds, nothing to do
    assert book.pause() == (Verdict(), task)
    book.paused(task)
    # issue #33: a second pause while paused is done already: 0 and nothing for the aircraft to do
    assert book.progress(task)["output"]["status"] == "paused" and book.pause() == (Verdict(), None)
    assert book.recovery() == (Verdict(), task)
    book.resumed(task)
    book.reached(task, 0, 1, 0)
    book.reached(task, 0, 2, 0)
    book.finished(task)
    out = book.progress(task)["output"]
    assert out["status"] == "ok" and out["progress"]["percent"] == 100 and out["ext"]["media_count"] == 1
    assert task.phase is Phase.DONE and book.recovery()[0].result == 319044
    assert book.undo(["b"]).ok and book.get("b") is None


def test_wayline_modules_are_sans_io() -> None:
    allowed_third_party = {"defusedxml"}
    forbidden = {"socket", "threading", "asyncio", "select", "selectors", "subprocess", "time", "aiohttp"}
    for rel in ("adapters/wayline/kmz.py", "adapters/wayline/writer.py", "adapters/wayline/runner.py",
                "adapters/osdk/wayline_plan.py",
                "gateway/wayline/task.py"):  # fmt: skip
        for name in _imports(ROOT / rel):
            top = name.split(".")[0]
            assert top not in forbidden, f"{rel} imports {name}"
            assert (
                top in (allowed_third_party | {"__future__", "adapters"})
                or top in __import__("sys").stdlib_module_names
            ), f"{rel} imports {name}"
            assert not name.startswith(("adapters.osdk.adapter", "adapters.osdk.wayline ", "gateway.")), name


def test_task_book_time_outs() -> None:
    from gateway.wayline.task import PREPARE_TTL, RUN_TIMEOUT

    book = TaskBook()
    book.prepare(_Prep("old"), 0.0)
    run, _ = book.prepare(_Prep("run"), 0.0)
    book.execute("run", 10.0)
    assert book.expired(RUN_TIMEOUT) == []
    assert book.expired(10.0 + RUN_TIMEOUT + 1) == [run]
    book.stopped(run, "timeout", None)
    assert book.progress(run)["output"]["status"] == "timeout"
    assert book.expired(PREPARE_TTL + 1) == [] and book.get("old") is None and book.get("run") is None
