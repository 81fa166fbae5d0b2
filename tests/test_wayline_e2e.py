"""Wayline tasks end to end: the cloud (a paho client on a real mosquitto) prepares and executes a KMZ
served by a plain HTTP server on 127.0.0.1; the gateway downloads it, asks flighttask_resource_get,
checks the fingerprint, plans, and flies it on the simulated flight controller over a real pty."""

from __future__ import annotations

import contextlib
import hashlib
import hmac
import itertools
import json
import logging
import math
import threading
import time
import uuid
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any
from urllib.parse import parse_qsl

import paho.mqtt.client as paho
import pytest
from paho.mqtt.enums import CallbackAPIVersion

from adapters.osdk.sim import OsdkFcDevice, OsdkFcModel
from adapters.simio import PtyEndpoint
from adapters.wayline.writer import ActionSpec, PointSpec, kmz_bytes, md5_hex, waylines_wpml
from gateway.local_broker import LocalBroker
from gateway.mqtt import close_client
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker

GW = "GW-TEST-1"
SN = "OSDK-W-1"
HOME = (22.5431, 113.958)
HOME_ALT = 50.0


def _ne(north: float, east: float) -> tuple[float, float]:
    lat = HOME[0] + math.degrees(north / 6_378_137.0)
    lon = HOME[1] + math.degrees(east / (6_378_137.0 * math.cos(math.radians(HOME[0]))))
    return lat, lon


def _distance(lat1: float, lon1: float, lat2: float, lon2: float) -> float:
    n = math.radians(lat2 - lat1) * 6_378_137.0
    e = math.radians(lon2 - lon1) * 6_378_137.0 * math.cos(math.radians(lat1))
    return math.hypot(n, e)


class FileStore:
    """Object storage on 127.0.0.1 with pre-signed, expiring URLs (``?Expires=<unix s>&Signature=<hmac>``,
    the shape of an OSS/S3 v2 pre-signed URL): past its expiry or with a wrong signature a GET is 403.
    (moto's server mode was tried for this and does not enforce a pre-signed URL's expiry.)"""

    KEY = b"test-signing-key"

    def __init__(self) -> None:
        self.files: dict[str, bytes] = {}
        self.gets: list[tuple[str, int]] = []
        store = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:
                path, _, query = self.path.partition("?")
                args = dict(parse_qsl(query))
                body = store.files.get(path)
                expires = int(args.get("Expires", "0"))
                if body is None:
                    code = 404
                elif args.get("Signature") != store.sign(path, expires) or expires < time.time():
                    code = 403
                else:
                    code = 200
                store.gets.append((path, code))
                self.send_response(code)
                self.send_header("Content-Length", str(len(body) if code == 200 and body else 0))
                self.end_headers()
                if code == 200 and body:
                    self.wfile.write(body)

            def log_message(self, *args: Any) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def sign(self, path: str, expires: int) -> str:
        return hmac.new(self.KEY, f"GET {path} {expires}".encode(), hashlib.sha256).hexdigest()

    def put(self, name: str, data: bytes) -> None:
        self.files[f"/{name}"] = data

    def url(self, name: str, expires_in: float = 3600.0) -> str:
        expires = int(time.time() + expires_in)
        path = f"/{name}"
        query = f"Expires={expires}&Signature={self.sign(path, expires)}"
        return f"http://127.0.0.1:{self.server.server_port}{path}?{query}"

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


class ResourceAnswerer:
    """The cloud's answer to flighttask_resource_get: a fresh URL and the stored fingerprint."""

    def __init__(self, broker: LocalBroker, files: dict[str, tuple[Any, str]], store: FileStore) -> None:
        self.files = files
        self.store = store
        self.asked: list[dict[str, Any]] = []
        self.client = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"res-{uuid.uuid4().hex[:8]}")
        self.client.on_message = self._on_message
        self.client.connect(broker.host, broker.port)
        self.client.loop_start()
        self.client.subscribe(f"thing/product/{GW}/requests", 1)

    def _on_message(self, client: paho.Client, userdata: Any, msg: paho.MQTTMessage) -> None:
        body = json.loads(msg.payload)
        self.asked.append(body)
        name, fingerprint = self.files[body["data"]["flight_id"]]
        # a fresh pre-signed URL, as DJI's reference cloud makes one (from the test's store or S3)
        url = name() if callable(name) else self.store.url(name)
        answer = {"result": 0, "output": {"file": {"url": url, "fingerprint": fingerprint}}}
        reply = {"tid": body["tid"], "bid": body["bid"], "timestamp": int(time.time() * 1000),
                 "method": body["method"], "data": answer}  # fmt: skip
        client.publish(msg.topic + "_reply", json.dumps(reply), qos=1)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
        close_client(self.client)


@pytest.fixture
def rig(broker: LocalBroker) -> Iterator[dict[str, Any]]:
    with _rig(broker, grab=True) as made:
        yield made


@pytest.fixture
def dock_rig(broker: LocalBroker) -> Iterator[dict[str, Any]]:
    """The rig as DJI-Cloud-API-Demo's wayline job flow drives a dock: no flight_authority_grab, ever."""
    with _rig(broker, grab=False) as made:
        yield made


@contextlib.contextmanager
def _rig(broker: LocalBroker, *, grab: bool) -> Iterator[dict[str, Any]]:
    device = OsdkFcDevice(OsdkFcModel(home=HOME, home_altitude=HOME_ALT))
    pty = PtyEndpoint(device).start()
    settings = gateway_settings(
        broker.port, [{"type": "osdk", "sn": SN, "url": pty.path, "app_id": 1234}], gateway_sn=GW
    )
    store = FileStore()
    files: dict[str, tuple[Any, str]] = {}
    answerer = ResourceAnswerer(broker, files, store)
    cloud = CloudClient(broker.host, broker.port, GW)
    gw = GatewayThread(settings).start()
    try:
        cloud.wait_for("status", lambda b: [d["sn"] for d in b["data"]["sub_devices"]] == [SN], timeout=10)
        cloud.wait_for(f"{SN}/osd", lambda b: "latitude" in b["data"])
        if grab:
            assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
        yield {"fc": device, "cloud": cloud, "gw": gw, "store": store, "files": files, "answerer": answerer,
               "pty": pty}  # fmt: skip
    finally:
        gw.stop()
        cloud.close()
        answerer.close()
        store.close()
        pty.stop()


HEIGHT = 12.0  # m above the take-off point
POINTS = [(0.0, 0.0), (30.0, 0.0), (30.0, 30.0)]  # north, east (m) from home


def _route_kmz(height: float = HEIGHT, **kw: Any) -> tuple[bytes, list[tuple[float, float]]]:
    coords = [_ne(n, e) for n, e in POINTS]
    pts = [PointSpec(*coords[0], height), PointSpec(*coords[1], height, actions=[
        ActionSpec("gimbalRotate", {"gimbalRotateMode": "absoluteAngle", "gimbalPitchRotateEnable": 1,
                                    "gimbalPitchRotateAngle": -45}),
        ActionSpec("takePhoto", {"fileSuffix": "wp1", "payloadPositionIndex": 0})]),
        PointSpec(*coords[2], height)]  # fmt: skip
    kw.setdefault("take_off_security_height", 8.0)  # the dock minimum
    return kmz_bytes(waylines_wpml(pts, speed=10.0, transitional_speed=10.0, **kw)), coords


def _prepare(
    rig: dict[str, Any],
    flight_id: str,
    kmz: bytes,
    fingerprint: str | None = None,
    expires_in: float = 3600.0,
    rth_altitude: int = 40,
) -> dict[str, Any]:
    name = f"{flight_id}.kmz"
    rig["store"].put(name, kmz)
    url = rig["store"].url(name, expires_in)
    fp = md5_hex(kmz) if fingerprint is None else fingerprint
    rig["files"][flight_id] = (name, fp)
    data = {"flight_id": flight_id, "execute_time": int(time.time() * 1000), "task_type": 0,
            "wayline_type": 0, "file": {"url": url, "fingerprint": fp}, "rth_altitude": rth_altitude,
            "rth_mode": 1, "out_of_control_action": 0, "exit_wayline_when_rc_lost": 1,
            "wayline_precision_type": 0}  # fmt: skip
    return rig["cloud"].service("flighttask_prepare", data)


def _prepare_and_execute(rig: dict[str, Any], rth_altitude: int = 40) -> str:
    """A route prepared and executed (both answered 0): its flight_id."""
    kmz, _ = _route_kmz()
    flight = str(uuid.uuid4())
    assert _prepare(rig, flight, kmz, rth_altitude=rth_altitude)["data"]["result"] == 0
    assert rig["cloud"].service("flighttask_execute", {"flight_id": flight})["data"]["result"] == 0
    return flight


def _progress(cloud: CloudClient, flight_id: str) -> list[dict[str, Any]]:
    return [
        b
        for b in cloud.find("/events", lambda b: b.get("method") == "flighttask_progress")
        if b["data"]["output"]["ext"]["flight_id"] == flight_id
    ]


def _status(cloud: CloudClient, flight_id: str) -> list[str]:
    return [b["data"]["output"]["status"] for b in _progress(cloud, flight_id)]


def _flying_leg_one(rig: dict[str, Any], flight: str) -> None:
    """Wait until the route flies between waypoints 0 and 1 at speed."""
    cloud, fc = rig["cloud"], rig["fc"]
    wait_until(
        lambda: (
            any(e["data"]["output"]["ext"]["current_waypoint_index"] >= 1 for e in _progress(cloud, flight))
            and fc.inspect(lambda m: m.speed) > 3.0
        ),
        60,
        what="flying the route",
    )


@pytest.mark.slow
def test_three_waypoint_route_flies_and_ends_ok(rig: dict[str, Any]) -> None:
    cloud, fc = rig["cloud"], rig["fc"]
    kmz, _ = _route_kmz()
    flight = str(uuid.uuid4())
    assert _prepare(rig, flight, kmz)["data"]["result"] == 0
    # the reference cloud resends with a new tid: the same answer, nothing new
    assert _prepare(rig, flight, kmz)["data"]["result"] == 0
    assert cloud.service("flighttask_execute", {"flight_id": flight})["data"]["result"] == 0
    assert cloud.service("flighttask_execute", {"flight_id": flight})["data"]["result"] == 0  # idempotent

    # flown within 5 m of every waypoint, at the planned height
    visited = [False] * 3

    def track() -> bool:
        n, e, h = fc.inspect(lambda m: (m.n, m.e, m.u))  # local metres from home
        for i, (pn, pe) in enumerate(POINTS):
            if math.dist((n, e, h), (pn, pe, HEIGHT)) < 5.0:
                visited[i] = True
        return "ok" in _status(cloud, flight) or "failed" in _status(cloud, flight)

    wait_until(track, 90, what="route flown", interval=0.05)
    assert visited == [True, True, True], visited
    statuses = _status(cloud, flight)
    assert statuses[-1] == "ok", statuses
    events = _progress(cloud, flight)
    assert all(e["bid"] == flight and e["need_reply"] == 1 for e in events)
    assert statuses[0] == "sent" and "in_progress" in statuses
    final = events[-1]["data"]
    assert final["result"] == 0 and final["output"]["progress"]["percent"] == 100
    ext = final["output"]["ext"]
    assert ext["media_count"] == 1 and ext["current_waypoint_index"] == 3 and ext["wayline_id"] == 0
    # the simulated FC ran the actions: one photo, gimbal pitch at -45°
    assert fc.inspect(lambda m: m.photos) == 1
    assert fc.inspect(lambda m: m.gimbal_pitch) == -45.0
    # a fresh URL was asked for before the run (flighttask_resource_get on requests, bid = flight_id)
    asked = [a for a in rig["answerer"].asked if a["method"] == "flighttask_resource_get"]
    assert asked and asked[0]["data"] == {"flight_id": flight} and asked[0]["bid"] == flight
    # progress at >= 1 Hz while flying: no stalled report between in_progress events
    stamps = [e["timestamp"] for e in events if e["data"]["output"]["status"] == "in_progress"]
    # sent each second by design: a silence over 2.5 s is a stalled report, not a loaded machine's jitter
    assert max(b - a for a, b in itertools.pairwise(stamps)) <= 2500


def test_wrong_fingerprint_fails_and_nothing_moves(rig: dict[str, Any]) -> None:
    cloud, fc = rig["cloud"], rig["fc"]
    kmz, _ = _route_kmz()
    flight = str(uuid.uuid4())
    reply = _prepare(rig, flight, kmz, fingerprint="0" * 32)
    assert reply["data"]["result"] == 314005, reply
    assert "MD5" in reply["data"]["output"]["reason"]
    r = cloud.service("flighttask_execute", {"flight_id": flight})
    assert r["data"]["result"] == 314005
    time.sleep(1.0)
    assert fc.inspect(lambda m: (m.in_air, m.motors_on, m.speed)) == (False, False, 0.0)
    assert fc.inspect(lambda m: m.upload) is None  # nothing was uploaded to the FC


@pytest.mark.slow
def test_pause_holds_and_recovery_finishes(rig: dict[str, Any]) -> None:
    cloud, fc = rig["cloud"], rig["fc"]
    flight = _prepare_and_execute(rig)
    _flying_leg_one(rig, flight)
    assert cloud.service("flighttask_pause", None)["data"]["result"] == 0
    paused_at = time.monotonic()
    wait_until(lambda: math.hypot(*fc.inspect(lambda m: (m.vn, m.ve))) < 0.5, 3.0, what="holding")
    assert time.monotonic() - paused_at < 3.0
    wait_until(lambda: "paused" in _status(cloud, flight), 3, what="progress says paused")
    time.sleep(1.5)
    assert math.hypot(*fc.inspect(lambda m: (m.vn, m.ve))) < 0.5  # still holding
    assert _status(cloud, flight)[-1] == "paused"
    # pause again: already paused, so done (issue #33: 0, not 319046), and nothing new happens
    again = cloud.service("flighttask_pause", None)["data"]
    assert again == {"result": 0}, again
    assert _status(cloud, flight)[-1] == "paused"
    assert cloud.service("flighttask_recovery", None)["data"]["result"] == 0
    # recovery again while it runs: already running, so done as well
    assert cloud.service("flighttask_recovery", None)["data"] == {"result": 0}
    wait_until(lambda: math.hypot(*fc.inspect(lambda m: (m.vn, m.ve))) > 1.0, 10, what="flying again")
    wait_until(lambda: _status(cloud, flight)[-1] == "ok", 90, what="finished after recovery")
    assert cloud.service("flighttask_recovery", None)["data"]["result"] == 319044


def test_undo_and_unknown_tasks(rig: dict[str, Any]) -> None:
    cloud = rig["cloud"]
    kmz, _ = _route_kmz()
    flight = str(uuid.uuid4())
    assert _prepare(rig, flight, kmz)["data"]["result"] == 0
    assert cloud.service("flighttask_undo", {"flight_ids": [flight]})["data"]["result"] == 0
    assert cloud.service("flighttask_execute", {"flight_id": flight})["data"]["result"] == 319003


def test_unflyable_route_is_refused_at_prepare(rig: dict[str, Any]) -> None:
    kmz, _ = _route_kmz(height_mode="realTimeFollowSurface")
    reply = _prepare(rig, str(uuid.uuid4()), kmz)
    assert reply["data"]["result"] == 314003
    assert "1541" in reply["data"]["output"]["reason"]


def test_an_expired_url_is_renewed_through_flighttask_resource_get(rig: dict[str, Any]) -> None:
    cloud, store = rig["cloud"], rig["store"]
    kmz, _ = _route_kmz()
    flight = str(uuid.uuid4())
    # the URL expired before the prepare arrived (a timed task prepared long ago): the prepare still
    # answers 0, and the execute asks for a fresh URL, downloads it and flies
    assert _prepare(rig, flight, kmz, expires_in=-10)["data"]["result"] == 0
    assert (f"/{flight}.kmz", 403) in store.gets
    assert cloud.service("flighttask_execute", {"flight_id": flight})["data"]["result"] == 0
    wait_until(lambda: "in_progress" in _status(cloud, flight), 30, what="flying with the fresh URL")
    assert store.gets.count((f"/{flight}.kmz", 200)) == 1
    assert "failed" not in _status(cloud, flight)


def test_no_working_url_fails_the_run_with_314013(rig: dict[str, Any]) -> None:
    cloud, store, fc = rig["cloud"], rig["store"], rig["fc"]
    kmz, _ = _route_kmz()
    flight = str(uuid.uuid4())
    assert _prepare(rig, flight, kmz, expires_in=-10)["data"]["result"] == 0
    del store.files[f"/{flight}.kmz"]  # the object is gone: the fresh URL gets 404
    assert cloud.service("flighttask_execute", {"flight_id": flight})["data"]["result"] == 0
    wait_until(lambda: _status(cloud, flight)[-1:] == ["failed"], 20, what="failed")
    final = _progress(cloud, flight)[-1]["data"]
    assert final["result"] == 314013 and final["output"]["progress"]["current_step"] == 35
    assert fc.inspect(lambda m: (m.in_air, m.motors_on)) == (False, False)


@pytest.mark.slow
def test_return_home_ends_the_task_and_lands_at_home(rig: dict[str, Any]) -> None:
    cloud, fc = rig["cloud"], rig["fc"]
    flight = _prepare_and_execute(rig)
    wait_until(
        lambda: any(
            e["data"]["output"]["ext"]["current_waypoint_index"] >= 2 for e in _progress(cloud, flight)
        ),
        60,
        what="past waypoint 1",
    )
    assert cloud.service("return_home", None)["data"]["result"] == 0
    wait_until(lambda: _status(cloud, flight)[-1:] == ["canceled"], 5, what="task canceled")
    ext = _progress(cloud, flight)[-1]["data"]["output"]["ext"]
    bp = ext["break_point"]
    assert bp["break_reason"] == 1283
    # DJI's numbering: on the segment that starts at the last waypoint reached, with the fraction flown
    done = ext["current_waypoint_index"]
    assert done >= 2 and bp["index"] == done - 1 and bp["state"] == 0 and 0.0 <= bp["progress"] <= 1.0
    info = cloud.wait_for("/events", lambda b: b.get("method") == "return_home_info")[-1]["data"]
    assert info["flight_id"] == flight and len(info["planned_path_points"]) == 2
    home = info["planned_path_points"][-1]
    assert _distance(home["latitude"], home["longitude"], *HOME) < 1.0
    assert abs(home["height"] - (HOME_ALT + 40.0)) < 0.5  # rth_altitude 40 m above the take-off point
    # the way home is the FC's go home, and the osd says what it is (its display mode, within a push or
    # two of the stop): 9 return home, not 5 wayline
    cloud.clear()
    wait_until(lambda: cloud.find(f"{SN}/osd", lambda b: b["data"].get("mode_code") == 9), 5, what="9")
    # over home, then the FC's landing (its go home's end); the descent itself is the FC's
    wait_until(lambda: fc.inspect(lambda m: m.task == "landing"), 30, what="landing over home")
    assert fc.inspect(lambda m: math.hypot(m.n, m.e)) < 2.0
    # its landing is part of the return: a cancel then exits the landing and the aircraft hovers (#37)
    assert cloud.service("return_home_cancel", None)["data"]["result"] == 0
    wait_until(lambda: fc.inspect(lambda m: m.in_air and m.task == "hover"), 5, what="hovering over home")
    assert cloud.service("return_home_cancel", None)["data"]["result"] == 314000  # no longer returning


def test_a_conditional_task_is_announced_ready_once(rig: dict[str, Any]) -> None:
    cloud = rig["cloud"]
    kmz, _ = _route_kmz()
    flight = str(uuid.uuid4())
    name = f"{flight}.kmz"
    rig["store"].put(name, kmz)
    now = int(time.time() * 1000)
    file = {"url": rig["store"].url(name), "fingerprint": md5_hex(kmz)}
    conditions = {"battery_capacity": 10, "begin_time": now - 1000, "end_time": now + 60_000}
    data = {"flight_id": flight, "task_type": 2, "file": file, "ready_conditions": conditions}
    assert cloud.service("flighttask_prepare", data)["data"]["result"] == 0
    ready = cloud.wait_for("/events", lambda b: b.get("method") == "flighttask_ready", timeout=5)
    assert ready[0]["data"] == {"flight_ids": [flight]} and ready[0]["need_reply"] == 1
    time.sleep(1.5)
    assert len(cloud.find("/events", lambda b: b.get("method") == "flighttask_ready")) == 1
    # a conditional task without its conditions is refused
    bad = {**data, "flight_id": "other"}
    del bad["ready_conditions"]
    assert cloud.service("flighttask_prepare", bad)["data"]["result"] == 325001


def test_losing_the_flight_controller_fails_the_task(rig: dict[str, Any]) -> None:
    cloud = rig["cloud"]
    flight = _prepare_and_execute(rig)
    wait_until(lambda: "in_progress" in _status(cloud, flight), 30, what="flying")
    rig["pty"].stop()  # the serial link is gone: the FC's pushes stop
    wait_until(lambda: _status(cloud, flight)[-1:] == ["failed"], 20, what="failed")
    assert _progress(cloud, flight)[-1]["data"]["result"] == 325012


@pytest.mark.slow
def test_a_route_longer_than_one_mission_is_chained(rig: dict[str, Any]) -> None:
    cloud, fc, gw = rig["cloud"], rig["fc"], rig["gw"]
    adapter = gw.app.devices.by_sn(SN)
    gw.call(lambda: setattr(adapter.wayline, "mission_max", 2))  # 3 waypoints → 2 chained missions
    inits = fc.inspect(lambda m: m.actions["wp_init"])
    flight = _prepare_and_execute(rig)
    wait_until(lambda: _status(cloud, flight)[-1:] == ["ok"], 90, what="chained route flown")
    assert fc.inspect(lambda m: m.actions["wp_init"]) - inits == 2
    final = _progress(cloud, flight)[-1]["data"]["output"]["ext"]
    assert final["current_waypoint_index"] == 3 and final["media_count"] == 1
    assert fc.inspect(lambda m: math.hypot(m.n - POINTS[2][0], m.e - POINTS[2][1])) < 5.0


def test_a_kmz_in_s3_compatible_storage_with_presigned_urls(rig: dict[str, Any]) -> None:
    """moto's S3 in server mode (a real HTTP S3 API on 127.0.0.1) and boto3's SigV4 pre-signed GET URLs,
    as DJI's reference cloud issues them for its MinIO/S3 storage. (moto does not enforce a pre-signed
    URL's expiry or signature: the expiring-URL behaviour is tested against FileStore above.)"""
    import boto3  # dev extras (pyproject.toml); imported here: moto is slow to import
    from botocore.config import Config
    from moto.server import ThreadedMotoServer

    server = ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    server.start()
    try:
        host, port = server.get_host_and_port()
        s3 = boto3.client("s3", endpoint_url=f"http://{host}:{port}", region_name="us-east-1",
                          aws_access_key_id="test", aws_secret_access_key="test",
                          config=Config(signature_version="s3v4"))  # fmt: skip
        s3.create_bucket(Bucket="waylines")
        kmz, _ = _route_kmz()
        flight = str(uuid.uuid4())
        key = f"wayline/{flight}.kmz"
        s3.put_object(Bucket="waylines", Key=key, Body=kmz)

        def presign() -> str:
            params = {"Bucket": "waylines", "Key": key}
            return str(s3.generate_presigned_url("get_object", Params=params, ExpiresIn=3600))

        url = presign()
        assert "X-Amz-Signature=" in url and "X-Amz-Credential=" in url
        rig["files"][flight] = (presign, md5_hex(kmz))
        data = {"flight_id": flight, "task_type": 0, "execute_time": int(time.time() * 1000),
                "file": {"url": url, "fingerprint": md5_hex(kmz)}}  # fmt: skip
        assert rig["cloud"].service("flighttask_prepare", data)["data"]["result"] == 0
        bad = {**data, "flight_id": str(uuid.uuid4()), "file": {"url": url, "fingerprint": md5_hex(b"other")}}
        assert rig["cloud"].service("flighttask_prepare", bad)["data"]["result"] == 314005
        assert rig["cloud"].service("flighttask_execute", {"flight_id": flight})["data"]["result"] == 0
        wait_until(lambda: "in_progress" in _status(rig["cloud"], flight), 30, what="flying from S3")
    finally:
        server.stop()


def test_immediate_tasks_keep_to_their_execute_time(rig: dict[str, Any]) -> None:
    cloud, store = rig["cloud"], rig["store"]
    kmz, _ = _route_kmz()
    store.put("late.kmz", kmz)
    file = {"url": store.url("late.kmz"), "fingerprint": md5_hex(kmz)}
    # execute_time is required for immediate and timed tasks [D2]
    missing = cloud.service("flighttask_prepare", {"flight_id": "no-time", "task_type": 0, "file": file})
    assert missing["data"]["result"] == 325001 and "execute_time" in missing["data"]["output"]["reason"]
    late = {
        "flight_id": "late",
        "task_type": 0,
        "execute_time": int(time.time() * 1000) - 60_000,
        "file": file,
    }
    assert cloud.service("flighttask_prepare", late)["data"]["result"] == 0
    r = cloud.service("flighttask_execute", {"flight_id": "late"})
    assert r["data"]["result"] == 319004 and "30 s" in r["data"]["output"]["reason"]
    assert rig["fc"].inspect(lambda m: m.in_air) is False


def test_the_console_state_carries_the_route_progress_and_break_point(rig: dict[str, Any]) -> None:
    """The web console's pushed document (gathered on the gateway's loop) names the task's route, which
    route_view gives once with the KMZ's waypoints; progress and the break point follow the task."""
    from gateway.web.state import ConsoleState

    cloud, gw = rig["cloud"], rig["gw"]
    console = ConsoleState(gw.app, frames=10, journal=10)
    assert gw.call(console.gather)["wayline"] is None  # no task yet
    kmz, coords = _route_kmz()
    flight = str(uuid.uuid4())
    assert _prepare(rig, flight, kmz)["data"]["result"] == 0
    shown = gw.call(console.gather)["wayline"]
    assert shown["flight_id"] == flight and shown["sn"] == SN and shown["status"] == "sent"
    assert shown["route"] == f"{flight}:{md5_hex(kmz)}" and (shown["reached"], shown["total"]) == (0, 3)
    assert shown["break_point"] is None
    route = gw.call(lambda: console.route_view(flight))
    assert route["key"] == shown["route"] and route["total"] == 3 and not route["decimated"]
    assert [w[0] for w in route["waypoints"]] == [0, 1, 2]
    for (_, lat, lon, height), (want_lat, want_lon) in zip(route["waypoints"], coords, strict=True):
        assert abs(lat - want_lat) < 1e-7 and abs(lon - want_lon) < 1e-7 and height == HEIGHT  # 8 decimals
    assert "waypoints" not in shown  # the route is not pushed with every tick
    assert cloud.service("flighttask_execute", {"flight_id": flight})["data"]["result"] == 0
    seen: list[int] = []

    def past_first() -> bool:
        view = gw.call(console.gather)["wayline"]
        seen.append(view["reached"])
        return bool(view["status"] == "in_progress" and view["reached"] >= 2)

    wait_until(past_first, 60, what="the console's task past waypoint 1")
    assert seen == sorted(seen) and seen[-1] > seen[0]  # reached only grows
    assert gw.call(console.gather)["wayline"]["percent"] > 10
    assert cloud.service("return_home", None)["data"]["result"] == 0
    wait_until(lambda: gw.call(console.gather)["wayline"]["status"] == "canceled", 5, what="task canceled")
    ended = gw.call(console.gather)["wayline"]
    bp = _progress(cloud, flight)[-1]["data"]["output"]["ext"]["break_point"]
    assert ended["break_point"] == bp and bp["break_reason"] == 1283
    assert ended["route"] == shown["route"]  # the same route: the page does not fetch it again


def _osd_mode(cloud: CloudClient) -> int:
    return int(cloud.find(f"{SN}/osd", lambda b: "mode_code" in b["data"])[-1]["data"]["mode_code"])


@pytest.mark.slow
def test_an_emergency_stop_ends_the_task_and_a_new_one_flies(rig: dict[str, Any]) -> None:
    """drone_emergency_stop during a wayline: the FC brakes and drops its mission; within 3 s the task
    ends (canceled, with a break point), the osd leaves mode_code 5, and the next task is accepted and
    flies to ok (issue #31: no state from which only return_home helps)."""
    cloud, fc = rig["cloud"], rig["fc"]
    flight = _prepare_and_execute(rig)
    _flying_leg_one(rig, flight)
    assert _osd_mode(cloud) == 5
    stop = json.dumps({"method": "drone_emergency_stop", "data": {}})
    cloud.publish(f"thing/product/{GW}/drc/down", stop, 0)
    stopped_at = time.monotonic()
    terminal = ("canceled", "failed", "ok")
    wait_until(lambda: _status(cloud, flight)[-1] in terminal, 3.0, what="a terminal progress")
    assert time.monotonic() - stopped_at < 3.0
    final = _progress(cloud, flight)[-1]["data"]
    assert final["output"]["status"] == "canceled", final
    bp = final["output"]["ext"]["break_point"]
    assert bp["index"] == 0 and bp["state"] == 0 and 0.0 < bp["progress"] < 1.0, bp  # on the first leg
    assert fc.inspect(lambda m: m.run) is None  # the FC dropped its mission
    wait_until(lambda: math.hypot(*fc.inspect(lambda m: (m.vn, m.ve))) < 0.5, 3.0, what="braked")
    cloud.clear()
    wait_until(lambda: cloud.find(f"{SN}/osd", lambda b: "mode_code" in b["data"]), 5, what="a fresh osd")
    assert _osd_mode(cloud) != 5
    # nothing is left running: pause and undo say so, and a new task flies
    assert cloud.service("flighttask_pause", None)["data"]["result"] == 319046
    again = _prepare_and_execute(rig)
    wait_until(lambda: _status(cloud, again)[-1] in terminal, 90, what="the next task flown")
    assert _status(cloud, again)[-1] == "ok", _status(cloud, again)


@pytest.mark.slow
def test_sticks_during_a_wayline_are_refused_and_do_nothing(rig: dict[str, Any]) -> None:
    """A DRC session entered during a wayline is accepted (payloads, pushes, the stop), but its sticks are
    answered with a non-zero result naming what flies the aircraft, and the route flies on unchanged."""
    cloud = rig["cloud"]
    flight = _prepare_and_execute(rig)
    _flying_leg_one(rig, flight)
    broker = rig["gw"].app.settings.broker.url
    host_port = broker.split("//", 1)[1]
    link = {"address": host_port, "client_id": "drc-wayline", "username": "", "password": "",
            "expire_time": int(time.time()) + 600, "enable_tls": False}  # fmt: skip
    r = cloud.service("drc_mode_enter", {"mqtt_broker": link, "osd_frequency": 5, "hsi_frequency": 1})
    assert r["data"]["result"] == 0, r
    down = f"thing/product/{GW}/drc/down"
    for seq in range(1, 6):
        cloud.publish(down, json.dumps({"method": "heart_beat", "data": {"seq": seq, "timestamp": 1}}), 0)
        stick = {"seq": seq, "x": 3.0, "y": 0.0, "h": 0.0, "w": 0.0}
        cloud.publish(down, json.dumps({"method": "drone_control", "data": stick}), 0)
        time.sleep(0.1)
    answers = wait_until(
        lambda: cloud.find("drc/up", lambda b: b.get("method") == "drone_control") or None, 5, what="answers"
    )
    assert all(a["data"]["result"] == 314000 for a in answers), answers
    assert "waypoint mission" in answers[0]["data"]["output"]["reason"] or "wayline" in str(answers[0])
    wait_until(lambda: _status(cloud, flight)[-1] == "ok", 90, what="the route flown to its end")
    assert cloud.service("drc_mode_exit", {})["data"]["result"] == 0


# -- issue #33 B: nothing takes off for a route that cannot be flown; a failure after take-off secures it --
def test_a_route_11000_km_away_is_refused_at_prepare_and_nothing_takes_off(rig: dict[str, Any]) -> None:
    cloud, fc = rig["cloud"], rig["fc"]
    far = [PointSpec(HOME[0] + 1.0 * i, HOME[1] - 100.0, HEIGHT) for i in range(3)]  # ~10,000 km west
    kmz = kmz_bytes(waylines_wpml(far, speed=10.0, transitional_speed=10.0, take_off_security_height=8.0))
    flight = str(uuid.uuid4())
    reply = _prepare(rig, flight, kmz)
    assert reply["data"]["result"] == 321514  # the Cloud API's "start/end point too far" (WAYLINE-NOTES §3.7)
    reason = reply["data"]["output"]["reason"]
    assert "wayline 0 waypoint 0:" in reason and "km from the aircraft (its home)" in reason, reason
    assert "break reason 514" in reason
    execute = cloud.service("flighttask_execute", {"flight_id": flight})["data"]
    assert execute["result"] == 321514
    time.sleep(1.0)  # what would have been the take-off: nothing happens
    assert fc.inspect(lambda m: (m.in_air, m.motors_on, m.actions["flight_task"], m.upload)) == (
        False, False, 0, None
    )  # fmt: skip


def test_a_wayline_broken_off_after_take_off_returns_home_and_says_why(
    rig: dict[str, Any], caplog: pytest.LogCaptureFixture
) -> None:
    cloud, fc = rig["cloud"], rig["fc"]
    with caplog.at_level(logging.ERROR):
        flight = _prepare_and_execute(rig)
        wait_until(
            lambda: fc.inspect(lambda m: m.run is not None and math.hypot(m.n, m.e) > 25.0),
            40,
            what="out there",
        )
        assert fc.break_mission(0xD9)  # low battery: the FC breaks the mission off and hovers
        wait_until(lambda: _status(cloud, flight)[-1:] == ["failed"], 10, what="failed")
        wait_until(lambda: fc.inspect(lambda m: m.task) == "go_home", 5, what="the FC's go home")
    last = _progress(cloud, flight)[-1]["data"]
    assert last["result"] == 336000 + 0xD9
    ext = last["output"]["ext"]
    assert "low battery" in ext["x_reason"] and "returning home" in ext["x_reason"], ext
    assert ext["break_point"]["break_reason"] == 1564
    assert any("failed after take-off" in r.getMessage() and "returning home" in r.getMessage()
               for r in caplog.records if r.levelno == logging.ERROR)  # fmt: skip
    cloud.wait_for(f"{SN}/osd", lambda b: b["data"].get("mode_code") == 9, timeout=5)  # return home


def test_actions_the_aircraft_cannot_do_are_listed_or_refused_under_strict(rig: dict[str, Any]) -> None:
    coords = [_ne(n, e) for n, e in POINTS]
    pts = [PointSpec(*coords[0], HEIGHT), PointSpec(*coords[1], HEIGHT, actions=[
        ActionSpec("zoom", {"focalLength": 48, "payloadPositionIndex": 0}),
        ActionSpec("takePhoto", {"fileSuffix": "wp1", "payloadPositionIndex": 0})]),
        PointSpec(*coords[2], HEIGHT)]  # fmt: skip
    kmz = kmz_bytes(waylines_wpml(pts, speed=10.0, transitional_speed=10.0, take_off_security_height=8.0))
    reply = _prepare(rig, str(uuid.uuid4()), kmz)["data"]
    assert reply["result"] == 0
    assert reply["output"]["x_skipped_actions"] == [
        "wayline 0 waypoint 1: zoom (a camera setting the flight controller cannot reach)"
    ]
    rig["gw"].app.wayline.strict_actions = True  # [wayline] strict_actions = true
    strict = _prepare(rig, str(uuid.uuid4()), kmz)["data"]
    assert strict["result"] == 314003
    assert "strict_actions" in strict["output"]["reason"] and "zoom" in strict["output"]["reason"]
    assert not rig["fc"].inspect(lambda m: m.in_air)


def _service_raw(cloud: CloudClient, method: str, data: Any) -> dict[str, Any]:
    """A service with ``data`` exactly as given (``"null"`` stays the JSON string), its reply."""
    tid, bid = str(uuid.uuid4()), str(uuid.uuid4())
    body = {"tid": tid, "bid": bid, "timestamp": int(time.time() * 1000), "method": method, "data": data}
    cloud.publish(f"thing/product/{GW}/services", body)
    return cloud.wait_for("services_reply", lambda b: b.get("tid") == tid, timeout=10)[-1]


def test_a_dock_flow_without_a_grab_flies_and_returns_home_on_a_null_string(dock_rig: dict[str, Any]) -> None:
    """Issue #33: DJI-Cloud-API-Demo's wayline job flow never sends flight_authority_grab (a dock owns its
    aircraft): prepare and execute fly the route, the gateway takes SDK control itself; a return_home sent
    as an RC-side client sends it (github wudizhr/DJI_Cloud_API_demo: "data": "null") brings it home.
    Stick authority is not given by any of it: live control still needs the grab."""
    cloud, fc = dock_rig["cloud"], dock_rig["fc"]
    assert not fc.inspect(lambda m: m.sdk_control)
    flight = _prepare_and_execute(dock_rig)
    wait_until(
        lambda: any(
            e["data"]["output"]["ext"]["current_waypoint_index"] >= 1 for e in _progress(cloud, flight)
        ),
        60,
        what="flying the route without a grab",
    )
    assert fc.inspect(lambda m: (m.sdk_control, m.in_air)) == (True, True)
    reply = _service_raw(cloud, "return_home", "null")
    assert reply["data"] == {"result": 0}, reply
    wait_until(lambda: _status(cloud, flight)[-1:] == ["canceled"], 5, what="task canceled by return home")
    wait_until(lambda: fc.inspect(lambda m: m.task == "landing"), 30, what="landing over home")
    assert fc.inspect(lambda m: math.hypot(m.n, m.e)) < 2.0
    # the cloud never grabbed, and the dock's own control grants it nothing: a fly-to still asks for the grab
    point = {"latitude": HOME[0], "longitude": HOME[1], "height": HOME_ALT + 20.0}
    refused = cloud.service("fly_to_point", {"fly_to_id": "after-rth", "max_speed": 5, "points": [point]})
    assert refused["data"]["result"] == 319030, refused
