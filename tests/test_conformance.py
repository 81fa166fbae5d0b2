"""Conformance: each real client's default flow, replayed message by message against ``dji-gateway run
--simulate`` (its own process) through a real mosquitto, and every accepted message does what it says
(issue #33). The shapes are copied from the clients' sources, read at these commits:

* DJI's reference cloud, **DJI-Cloud-API-Demo** ``bef525cb94772b06786c1e033719a6fa1b94bcc5`` (Java): the
  wayline job flow of ``sample/.../wayline/service/impl/FlightTaskServiceImpl.java`` (``prepareFlightTask``
  lines 291-318: the fields it sets, serialised by ``cloud-sdk/.../common/Common.java``'s mapper, snake
  case, ``NON_ABSENT``; ``FlighttaskPrepareRequest``'s ``rth_mode`` defaults to 1 PRESET_HEIGHT; no
  ``wayline_precision_type`` for a non-Dock-2 gateway), the ``flighttask_resource_get`` answer of
  ``FlighttaskResourceGetResponse``, then ``flighttask_execute``; it never sends ``flight_authority_grab``
  for a job (a dock owns its aircraft).
* DJI's **Cloud-API-Demo-Web** ``bfcf3ee998b876dc5d372e5dbac913a19ccdac9f``: the take-off popover's
  defaults (``src/components/g-map/DroneControlPanel.vue`` lines 388-445: ``rc_lost_action`` 2,
  ``exit_wayline_when_rc_lost`` 1, ``rth_mode`` 1, ``commander_mode_lost_action`` 0,
  ``commander_flight_mode`` 1, ``max_speed`` 14), sent through the Java cloud after its flight-control
  button (``postFlightAuth`` → ``flight_authority_grab`` with ``"data": ""``).
* An RC-side client used with real RC Plus 2 controllers, **wudizhr/DJI_Cloud_API_demo**
  ``d53db04f37cefa0e36b79c7a88238f802e30416e``: ``CluodAPI_Terminal_Client/services_publisher.py``
  (``cloud_control_auth_request``, ``drc_mode_enter`` with ``"enable_tls": "false"`` and
  ``osd_frequency`` 50, ``fly_to_point``, ``return_home`` with ``"data": "null"``) and
  ``DRC_controler.py`` (``stick_control`` and ``heart_beat`` with ``seq`` at the top level, the heartbeat's
  timestamp in hundredths of a second; each heartbeat must come back with that ``seq`` at the top level,
  issue #38). It never grabs: the granted cloud control is the hand-over.
"""

from __future__ import annotations

import json
import math
import time
import uuid
from collections.abc import Iterator
from typing import Any

import paho.mqtt.client as paho
import pytest
from paho.mqtt.enums import CallbackAPIVersion

from adapters.wayline.writer import PointSpec, kmz_bytes, md5_hex, waylines_wpml
from gateway.cli.run import SIM_AIRCRAFT_SN, SIM_GATEWAY_SN
from gateway.local_broker import LocalBroker
from gateway.mqtt import close_client
from tests.support import CloudClient, Proc, simulated_gateway, wait_until
from tests.test_wayline_e2e import FileStore

pytestmark = pytest.mark.broker

GW, SN = SIM_GATEWAY_SN, SIM_AIRCRAFT_SN
SERVICES = f"thing/product/{GW}/services"
RC_CLIENT_USER = "123456"  # the RC-side client's user_id, on this gateway's allow-list


def _offset(lat: float, lon: float, north: float, east: float) -> tuple[float, float]:
    return (
        lat + math.degrees(north / 6_378_137.0),
        lon + math.degrees(east / (6_378_137.0 * math.cos(math.radians(lat)))),
    )


def _flat(a: tuple[float, float], b: tuple[float, float]) -> float:
    n = math.radians(b[0] - a[0]) * 6_378_137.0
    e = math.radians(b[1] - a[1]) * 6_378_137.0 * math.cos(math.radians(a[0]))
    return math.hypot(n, e)


class Sim:
    """One ``run --simulate`` and a cloud on the same broker; ``home`` is where the aircraft stands."""

    def __init__(self, broker: LocalBroker, proc: Proc, cloud: CloudClient) -> None:
        self.broker, self.proc, self.cloud = broker, proc, cloud
        osd = cloud.wait_for(f"{SN}/osd", lambda b: "latitude" in b["data"], timeout=20)[-1]["data"]
        self.home = (float(osd["latitude"]), float(osd["longitude"]))
        self.home_height = float(osd["height"])

    def send(self, message: dict[str, Any]) -> dict[str, Any]:
        """Publish ``message`` as the client writes it (a fresh tid; ``data`` untouched), return the reply."""
        tid = message["tid"] = str(uuid.uuid4())
        self.cloud.publish(SERVICES, json.dumps(message))
        return self.cloud.wait_for("services_reply", lambda b: b.get("tid") == tid, timeout=10)[-1]["data"]

    def osd(self) -> dict[str, Any]:
        return dict(self.cloud.find(f"{SN}/osd", lambda b: "latitude" in b["data"])[-1]["data"])

    def position(self) -> tuple[float, float]:
        d = self.osd()
        return float(d["latitude"]), float(d["longitude"])

    def track(self) -> list[tuple[float, float]]:
        """Every position the osd has reported so far."""
        return [
            (float(b["data"]["latitude"]), float(b["data"]["longitude"]))
            for b in self.cloud.find(f"{SN}/osd", lambda b: "latitude" in b["data"])
        ]

    def elevation(self) -> float:
        return float(self.osd().get("elevation", 0.0))

    def events(self, method: str, key: str, value: str) -> list[dict[str, Any]]:
        def match(b: dict[str, Any]) -> bool:
            if b.get("method") != method:
                return False
            out = b["data"].get("output") or {}
            return bool(b["data"].get(key) == value or (out.get("ext") or {}).get(key) == value)

        return self.cloud.find("/events", match)


@pytest.fixture
def sim() -> Iterator[Sim]:
    with LocalBroker() as broker:
        proc, _ = simulated_gateway(broker.url, DJIGW_CLOUD_CONTROL__ALLOW=json.dumps([RC_CLIENT_USER]))
        cloud = CloudClient(broker.host, broker.port, GW)
        try:
            yield Sim(broker, proc, cloud)
        finally:
            cloud.close()
            assert proc.stop() == 0, proc.output()[-3000:]


# ------------------------------------------------------------------ DJI-Cloud-API-Demo (the Java cloud)
@pytest.mark.slow
def test_the_java_clouds_wayline_job_flies_to_ok_without_a_grab(sim: Sim) -> None:
    store = FileStore()
    answered: list[dict[str, Any]] = []
    job_id = str(uuid.uuid4())
    points = [_offset(*sim.home, n, e) for n, e in [(0.0, 0.0), (25.0, 0.0), (25.0, 25.0)]]
    kmz = kmz_bytes(
        waylines_wpml([PointSpec(*p, 12.0) for p in points], speed=10.0, transitional_speed=10.0,
                      take_off_security_height=8.0)
    )  # fmt: skip
    store.put("route.kmz", kmz)

    def resource_get(client: paho.Client, userdata: Any, msg: paho.MQTTMessage) -> None:
        body = json.loads(msg.payload)  # FlighttaskResourceGetResponse: {file: {url, fingerprint}}
        answered.append(body)
        file = {"url": store.url("route.kmz"), "fingerprint": md5_hex(kmz)}
        reply = {"tid": body["tid"], "bid": body["bid"], "timestamp": int(time.time() * 1000),
                 "method": body["method"], "data": {"result": 0, "output": {"file": file}}}  # fmt: skip
        client.publish(msg.topic + "_reply", json.dumps(reply), qos=1)

    java = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"java-{uuid.uuid4().hex[:8]}")
    java.on_message = resource_get
    java.connect(sim.broker.host, sim.broker.port)
    java.loop_start()
    java.subscribe(f"thing/product/{GW}/requests", 1)
    try:
        # prepareFlightTask: exactly the fields it sets, as the SDK's mapper writes them
        now = int(time.time() * 1000)
        prepare = {"bid": str(uuid.uuid4()), "timestamp": now, "method": "flighttask_prepare",
                   "data": {"flight_id": job_id, "execute_time": int(time.time() * 1000), "task_type": 0,
                            "wayline_type": 0, "rth_altitude": 50, "out_of_control_action": 0,
                            "exit_wayline_when_rc_lost": 1,
                            "file": {"url": store.url("route.kmz"), "fingerprint": md5_hex(kmz)},
                            "rth_mode": 1}}  # fmt: skip
        assert sim.send(prepare)["result"] == 0
        execute = {"bid": str(uuid.uuid4()), "timestamp": now, "method": "flighttask_execute",
                   "data": {"flight_id": job_id}}  # fmt: skip
        assert sim.send(execute)["result"] == 0  # no flight_authority_grab was sent: the dock takes control
        wait_until(lambda: any(b["data"]["flight_id"] == job_id for b in answered), 10,
                   what="flighttask_resource_get asked")  # fmt: skip
        wait_until(lambda: sim.elevation() > 5.0, 30, what="the aircraft took off for the job")
        wait_until(
            lambda: any(
                b["data"]["output"]["status"] == "ok"
                for b in sim.events("flighttask_progress", "flight_id", job_id)
            ),
            90,
            what="the job's progress ends ok",
        )
        # it flew the route: it was at the last waypoint (the osd of the flight, not the latest: the route's
        # finish action may already have it on its way on, and a loaded machine reads late)
        statuses = [
            b["data"]["output"]["status"] for b in sim.events("flighttask_progress", "flight_id", job_id)
        ]
        assert "failed" not in statuses and statuses[-1] == "ok", statuses
        # (the osd may lag the event on a loaded machine: a few seconds for it to show the aircraft there)
        wait_until(lambda: min(_flat(p, points[-1]) for p in sim.track()) < 5.0, 5,
                   what=f"the aircraft at the last waypoint {points[-1]}, not {sim.position()}")  # fmt: skip
    finally:
        java.disconnect()
        java.loop_stop()
        close_client(java)
        store.close()


# ------------------------------------------------------------ DJI Cloud-API-Demo-Web (through the Java cloud)
def test_the_demo_webs_default_take_off_climbs_to_the_target(sim: Sim) -> None:
    grab = {"bid": str(uuid.uuid4()), "timestamp": int(time.time() * 1000), "method": "flight_authority_grab",
            "data": ""}  # fmt: skip
    assert sim.send(grab)["result"] == 0  # the panel's flight-control button (postFlightAuth)
    target = _offset(*sim.home, 30.0, 0.0)
    flight_id = str(uuid.uuid4())
    # the popover's defaults; the numbers its form asks for typed in (heights: ellipsoid, as the map gives)
    takeoff = {"bid": str(uuid.uuid4()), "timestamp": int(time.time() * 1000), "method": "takeoff_to_point",
               "data": {"flight_id": flight_id, "target_latitude": target[0], "target_longitude": target[1],
                        "target_height": sim.home_height + 25.0, "security_takeoff_height": 20.0,
                        "rth_altitude": 100, "max_speed": 14, "rc_lost_action": 2,
                        "exit_wayline_when_rc_lost": 1, "rth_mode": 1, "commander_mode_lost_action": 0,
                        "commander_flight_mode": 1, "commander_flight_height": 25.0}}  # fmt: skip
    reply = sim.send(takeoff)
    assert reply["result"] == 0, reply
    wait_until(
        lambda: any(
            b["data"]["status"] == "task_finish"
            for b in sim.events("takeoff_to_point_progress", "flight_id", flight_id)
        ),
        60,
        what="the take-off's task_finish",
    )
    # the osd that shows it there may come a moment after the event on a loaded machine
    wait_until(lambda: _flat(sim.position(), target) < 3.0, 5, what=f"at {target}, not {sim.position()}")
    assert abs(sim.elevation() - 25.0) < 2.0, sim.elevation()
    failed = [b for b in sim.events("takeoff_to_point_progress", "flight_id", flight_id)
              if b["data"]["status"] in ("wayline_failed", "wayline_cancel")]  # fmt: skip
    assert not failed, failed


# -------------------------------------------------------- wudizhr/DJI_Cloud_API_demo (an RC-side client)
@pytest.mark.slow
def test_the_rc_side_clients_flow_flies_by_sticks_and_returns_home_on_a_null_string(sim: Sim) -> None:
    cloud = sim.cloud
    # services_publisher.py: request_cloud_control_authorization_message (its user on the allow-list)
    request = {"bid": str(uuid.uuid4()), "method": "cloud_control_auth_request", "timestamp": 1654070968655,
               "data": {"control_keys": ["flight"], "user_callsign": "WUDIZHR",
                        "user_id": RC_CLIENT_USER}}  # fmt: skip
    assert sim.send(request)["result"] == 0
    cloud.wait_for("/events", lambda b: b.get("method") == "cloud_control_auth_notify"
                   and b["data"]["output"]["status"] == "ok", timeout=5)  # fmt: skip
    # the pilot takes it up (this client has no take-off of its own): no grab, the grant handed it over
    flight_id = str(uuid.uuid4())
    takeoff = {"bid": str(uuid.uuid4()), "timestamp": int(time.time() * 1000), "method": "takeoff_to_point",
               "data": {"flight_id": flight_id, "target_latitude": sim.home[0],
                        "target_longitude": sim.home[1], "target_height": sim.home_height + 20.0,
                        "security_takeoff_height": 20.0,
                        "rth_altitude": 40, "max_speed": 10, "rc_lost_action": 2,
                        "commander_mode_lost_action": 0, "commander_flight_mode": 1,
                        "commander_flight_height": 20.0}}  # fmt: skip
    reply = sim.send(takeoff)
    assert reply["result"] == 0, reply
    wait_until(
        lambda: any(b["data"]["status"] == "task_finish"
                    for b in sim.events("takeoff_to_point_progress", "flight_id", flight_id)),
        45,
        what="up at the safe height",
    )  # fmt: skip

    # enter_live_flight_controls_mode_message ("false", 50 Hz; a live expire_time: its literal is of 2023)
    enter = {"bid": str(uuid.uuid4()), "timestamp": 1654070968655, "method": "drc_mode_enter",
             "data": {"hsi_frequency": 1, "osd_frequency": 50,
                      "mqtt_broker": {"address": f"127.0.0.1:{sim.broker.port}", "client_id": f"sn_{GW}",
                                      "enable_tls": "false", "expire_time": int(time.time()) + 3600,
                                      "password": "jwt_token", "username": "sn_a_username"}}}  # fmt: skip
    reply = sim.send(enter)
    assert reply == {"result": 0, "output": {"osd_frequency": 30, "hsi_frequency": 1}}, reply

    # DRC_controler.py: heartbeats and sticks with seq at the top level, one seq counter for both
    down = f"thing/product/{GW}/drc/down"
    seq = 0
    start = sim.position()
    deadline = time.monotonic() + 2.5
    delays: list[float] = []
    while time.monotonic() < deadline:
        beat = {"data": {"timestamp": int(time.time() * 100)}, "method": "heart_beat", "seq": seq}
        sent = time.monotonic()
        cloud.publish(down, json.dumps(beat), qos=1)
        # the client matches the echo on the top-level seq (issue #38): it must be there, this seq
        cloud.wait_for("/drc/up", lambda b, s=seq: b.get("method") == "heart_beat" and b.get("seq") == s,
                       timeout=2)  # fmt: skip
        delays.append(time.monotonic() - sent)
        seq += 1
        for _ in range(5):  # forward at half pitch, 10 Hz
            stick = {"seq": seq, "method": "stick_control",
                     "data": {"roll": 1024, "pitch": 1024 + 330, "throttle": 1024, "yaw": 1024}}  # fmt: skip
            cloud.publish(down, json.dumps(stick), qos=0)
            seq += 1
            time.sleep(0.1)
    wait_until(lambda: _flat(start, sim.position()) > 5.0, 5, what="the sticks moved the aircraft")
    assert sorted(delays)[len(delays) // 2] < 0.1, delays  # echoed within 100 ms (the median: 2 busy cores)
    ups = cloud.find("/drc/up", lambda b: b.get("method") == "osd_info_push")
    assert ups, "no osd_info_push on drc/up"
    errors = cloud.find("/drc/up", lambda b: b.get("method") == "stick_control"
                        and (b.get("data") or {}).get("result", 0) != 0)  # fmt: skip
    assert not errors, errors[:3]

    # return_home_message: "data": "null"
    away = _flat(sim.home, sim.position())
    rth = {"bid": str(uuid.uuid4()), "data": "null", "method": "return_home", "timestamp": 1734425015702}
    assert sim.send(rth) == {"result": 0}
    wait_until(lambda: _flat(sim.home, sim.position()) < max(2.0, away / 2), 30, what="on its way home")
    wait_until(lambda: sim.osd().get("mode_code") in (9, 10, 0), 10, what="returning or landing")
