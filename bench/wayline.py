"""Wayline benchmark: check, unpack, parse and map a 1,000-waypoint KMZ onto Onboard SDK missions on one
core (issue #20: <= 200 ms), and encode every resulting 0x03 0x10 / 0x11 frame payload; then the
gateway's own time from ``flighttask_prepare`` to the mission flying on the simulated FC, the FC's
take-off time taken out (issue #20: first waypoint action <= 2 s beyond the flight time).

The KMZ is written by ``adapters.wayline.writer`` (DJI's element layout, a gimbalRotate + takePhoto
every tenth waypoint); the measured path is the gateway's: ``load_route`` (MD5, zip limits, defusedxml
parse) then ``plan_route`` (heights, speeds, actions, chaining). Checked after timing: 1,000 route
waypoints, each once and in order, in missions of at most 255, and every payload 51 / 90 bytes.

The second part is end to end: a private mosquitto, the gateway (``tests.support.GatewayThread``), the
simulated FC on a real pty, the KMZ on a local HTTP server and a cloud that answers
``flighttask_resource_get``. The sim is polled every 2 ms for when its take-off starts and ends and when
the mission starts: overhead = (prepare sent → mission started) − (take-off start → take-off end), i.e.
the download, the checks, the resource request, the upload over the serial link and the start, plus
the FC's own command latency. Everything after the mission start is the FC flying.
"""

from __future__ import annotations

import json
import math
import time
import uuid
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion

from adapters.osdk import commands as cmds
from adapters.osdk.wayline_plan import MISSION_MAX, PlanOptions, plan_route
from adapters.wayline.kmz import load_route
from adapters.wayline.writer import ActionSpec, PointSpec, kmz_bytes, md5_hex, waylines_wpml
from bench.run import Config, Row, best_of

__all__ = ["MAX_OVERHEAD", "MAX_SECONDS", "run"]

MAX_SECONDS = 0.200  # parse + map 1,000 waypoints (issue #20)
MAX_OVERHEAD = 2.0  # prepare → first waypoint action beyond the flight time (issue #20)
GW = "GW-BENCH-WAYLINE"
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
    overheads = _prepare_to_mission(3 if cfg.quick else 10)
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
        Row(
            group="wayline",
            case=f"prepare -> mission flying beyond the take-off, worst of {len(overheads)} "
            f"(<= {MAX_OVERHEAD:g} s)",
            count=len(overheads),
            rate=1.0 / max(overheads),
            min_rate=1.0 / MAX_OVERHEAD,
            unit="1/s",
            note="overhead s: " + ", ".join(f"{o:.2f}" for o in overheads),
        ),
    ]


def _prepare_to_mission(rounds: int) -> list[float]:
    """Seconds the gateway adds between the prepare and the mission flying, one route per round (each on
    a fresh simulated FC on the ground)."""
    from adapters.osdk.sim import OsdkFcDevice, OsdkFcModel
    from adapters.simio import PtyEndpoint
    from gateway.local_broker import LocalBroker
    from gateway.settings import load_settings
    from gateway.wayline.console_files import ServedFile, demo_kmz
    from tests.support import CloudClient, GatewayThread

    kmz = demo_kmz()
    fingerprint = md5_hex(kmz)
    out: list[float] = []
    with LocalBroker() as broker:
        served = ServedFile(kmz, "route.kmz")
        answers = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"bench-cloud-{uuid.uuid4().hex[:6]}")

        def answer(client: paho.Client, userdata: Any, msg: paho.MQTTMessage) -> None:
            body = json.loads(msg.payload)
            data = {"result": 0, "output": {"file": {"url": served.url, "fingerprint": fingerprint}}}
            reply = {
                "tid": body["tid"],
                "bid": body["bid"],
                "timestamp": 0,
                "method": body["method"],
                "data": data,
            }
            client.publish(msg.topic + "_reply", json.dumps(reply), qos=1)

        answers.on_message = answer
        answers.connect(broker.host, broker.port)
        answers.loop_start()
        answers.subscribe(f"thing/product/{GW}/requests", 1)
        try:
            for _ in range(rounds):
                out.append(_one_round(broker, served.url, fingerprint, OsdkFcDevice, OsdkFcModel, PtyEndpoint,
                                      load_settings, CloudClient, GatewayThread))  # fmt: skip
        finally:
            answers.loop_stop()
            answers.disconnect()
            served.close()
    return out


def _one_round(broker: Any, url: str, fingerprint: str, device_cls: Any, model_cls: Any, pty_cls: Any,
               load_settings: Any, cloud_cls: Any, gateway_cls: Any) -> float:  # fmt: skip
    fc = device_cls(model_cls(home=HOME))
    pty = pty_cls(fc).start()
    device = {"type": "osdk", "sn": "OSDK-BENCH-1", "url": pty.path, "app_id": 1}
    settings = load_settings(None, gateway_sn=GW, broker={"url": broker.url}, metrics={"port": 0},
                             dispatcher={"require_authority": False}, devices=[device])  # fmt: skip
    gw = gateway_cls(settings).start()
    cloud = cloud_cls(broker.host, broker.port, GW)
    try:
        adapter = gw.app.devices.by_sn("OSDK-BENCH-1")
        deadline = time.monotonic() + 15
        while not (adapter.online and adapter.telemetry.latitude is not None):
            if time.monotonic() > deadline:
                raise AssertionError("the simulated FC did not come online")
            time.sleep(0.02)
        flight = str(uuid.uuid4())
        data = {"flight_id": flight, "task_type": 0, "execute_time": int(time.time() * 1000),
                "file": {"url": url, "fingerprint": fingerprint}}  # fmt: skip
        t0 = time.monotonic()
        if cloud.service("flighttask_prepare", data)["data"]["result"] != 0:
            raise AssertionError("prepare refused")
        if cloud.service("flighttask_execute", {"flight_id": flight})["data"]["result"] != 0:
            raise AssertionError("execute refused")
        takeoff_begin = takeoff_end = started = None
        deadline = time.monotonic() + 60
        while started is None:
            now = time.monotonic()
            task, run = fc.inspect(lambda m: (m.task, m.run is not None))
            if takeoff_begin is None and task == "takeoff":
                takeoff_begin = now
            if takeoff_begin is not None and takeoff_end is None and task != "takeoff":
                takeoff_end = now
            if run:
                started = now
            if now > deadline:
                raise AssertionError("the mission did not start")
            time.sleep(0.002)
        if takeoff_begin is None or takeoff_end is None:
            raise AssertionError("no take-off seen before the mission")
        return (started - t0) - (takeoff_end - takeoff_begin)
    finally:
        cloud.close()
        gw.stop()
        pty.stop()
