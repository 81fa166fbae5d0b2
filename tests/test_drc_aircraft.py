"""Live flight control of the simulated Onboard SDK aircraft over a real pty: sticks move it, and
every failsafe stops it — sticks stopping, heartbeats stopping, the broker dying, an emergency stop —
also while the MQTT side is flooded with sticks or the device link is stalled."""

from __future__ import annotations

import asyncio
import json
import math
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest

from adapters.osdk import commands as cmds
from adapters.osdk.protocol import Decoder, Frame
from adapters.osdk.sim import OsdkFcDevice, OsdkFcModel
from adapters.simio import PtyEndpoint
from gateway.local_broker import LocalBroker
from gateway.mqtt import close_client
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker

GW = "GW-TEST-1"
SN = "OSDK-DRC-1"


def _setpoint(fc: OsdkFcDevice) -> tuple[float, float] | None:
    """The forward/right velocity the flight controller was last told (body frame), or None."""
    return fc.inspect(lambda m: None if m._sp is None else (m._sp.x, m._sp.y))


class WireTap(OsdkFcDevice):
    """The simulated FC, with every host frame also decoded here from the bytes that crossed the pty."""

    def __init__(self, model: OsdkFcModel) -> None:
        super().__init__(model)
        self._tap = Decoder()
        self.frames: list[Frame] = []

    def on_bytes(self, data: bytes, now: float) -> bytes:
        with self.lock:
            self.frames += [f for f in self._tap.feed(data) if isinstance(f, Frame)]
        return super().on_bytes(data, now)

    def movement(self) -> list[dict[str, Any]]:
        with self.lock:
            frames = [f for f in self.frames if not f.is_ack and (f.cmd_set, f.cmd_id) == (0x01, 0x03)]
        return [cmds.decode_request(0x01, 0x03, f.payload).fields for f in frames]


DRC_USER, DRC_PASSWORD = "drc-pilot", "drc-aircraft-secret-31f"


@pytest.fixture
def rig(private_broker: LocalBroker) -> Iterator[dict[str, Any]]:
    """The cloud's broker, plus a DRC broker with username/password that drc_mode_enter names."""
    drc_broker = LocalBroker(users={DRC_USER: DRC_PASSWORD}).start()
    fc = WireTap(OsdkFcModel())
    pty = PtyEndpoint(fc).start()
    settings = gateway_settings(
        private_broker.port,
        [{"type": "osdk", "sn": SN, "url": pty.path}],
        drc={"heartbeat_timeout": 1.5, "stick_timeout": 0.5, "stream_hz": 25},
    )
    cloud = CloudClient(private_broker.host, private_broker.port, GW)
    gw = GatewayThread(settings).start()
    try:
        cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == 1, timeout=10)
        assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
        adapter = gw.app.devices.by_sn(SN)
        asyncio.run_coroutine_threadsafe(adapter.flight_task("takeoff"), gw.loop).result(5)  # take off
        wait_until(lambda: fc.inspect(lambda m: m.in_air and m.display_mode == 6), 10, what="airborne")
        # and the gateway has heard that the FC's take-off is over: sticks during it are refused
        wait_until(lambda: adapter.autonomous_task() is None, 10, what="the take-off over, for the gateway")
        link = {"address": f"127.0.0.1:{drc_broker.port}", "client_id": "drc-gw", "username": DRC_USER,
                "password": DRC_PASSWORD, "expire_time": int(time.time()) + 600,
                "enable_tls": False}  # fmt: skip
        r = cloud.service("drc_mode_enter", {"mqtt_broker": link, "osd_frequency": 10, "hsi_frequency": 2})
        assert r["data"]["result"] == 0
        # live control is on once the gateway's own link to the DRC broker has subscribed (drc_state 2);
        # a QoS 0 message sent before that reaches nobody (a loaded machine made the window seconds wide)
        cloud.wait_for(
            "events", lambda b: b["method"] == "drc_status_notify" and b["data"]["drc_state"] == 2, timeout=10
        )
        drc = CloudClient(drc_broker.host, drc_broker.port, GW, username=DRC_USER, password=DRC_PASSWORD)
        yield {"fc": fc, "pty": pty, "cloud": cloud, "drc": drc, "gw": gw, "drc_broker": drc_broker}
        drc.close()
    finally:
        gw.stop()
        cloud.close()
        pty.stop()
        drc_broker.stop()


def _down(cloud: CloudClient, method: str, data: dict[str, Any]) -> None:
    cloud.publish(f"thing/product/{GW}/drc/down", json.dumps({"method": method, "data": data}), qos=0)


def test_sticks_fly_the_aircraft_and_stopping_them_brakes(rig: dict[str, Any]) -> None:
    fc, cloud = rig["fc"], rig["drc"]
    _down(cloud, "heart_beat", {"seq": 1, "timestamp": 11})
    assert cloud.wait_for("drc/up", lambda b: b["method"] == "heart_beat")[0]["data"] == {
        "seq": 1,
        "timestamp": 11,
    }
    for seq in range(1, 11):  # 10 Hz sticks: 3 m/s forward (seed: +y forward)
        _down(cloud, "drone_control", {"seq": seq, "y": 3.0})
        time.sleep(0.1)
    wait_until(lambda: fc.inspect(lambda m: m.vn) > 2.0, 5, what="the aircraft flies north")
    assert _setpoint(fc) == (3.0, 0.0)
    # the pushes of live control arrive on drc/up
    osd = cloud.wait_for("drc/up", lambda b: b["method"] == "osd_info_push")[-1]["data"]
    assert {"latitude", "longitude", "height", "speed_x", "attitude_head"} <= osd.keys()
    cloud.wait_for("drc/up", lambda b: b["method"] == "hsi_info_push")
    # sticks stop: a zero set-point reaches the flight controller within 0.5 s plus one stream period
    last = time.monotonic()
    zero_at = wait_until(
        lambda: _setpoint(fc) == (0.0, 0.0) and time.monotonic(), 3, interval=0.002, what="zero"
    )
    assert zero_at - last < 0.5 + 0.04 + 0.3
    wait_until(lambda: fc.inspect(lambda m: m.speed) < 0.3, 5, what="braked to a hover")
    # no -0.0 on the wire: the stick's absent x (seed: +x left) becomes right = -x, a negated zero that
    # used to go out as 00 00 00 80; every float of every movement frame, decoded from the bytes
    frames = fc.movement()
    assert any(f["x"] == 3.0 and f["y"] == 0.0 for f in frames) and any(f["x"] == 0.0 for f in frames)
    signs = {(k, math.copysign(1.0, v)) for f in frames for k, v in f.items() if k != "flag" and v == 0.0}
    assert signs and all(sign == 1.0 for _, sign in signs), signs
    assert rig["cloud"].service("drc_mode_exit", {})["data"]["result"] == 0
    rig["cloud"].wait_for(
        "events", lambda b: b["method"] == "drc_status_notify" and b["data"]["drc_state"] == 0
    )


def test_heartbeats_stop_while_sticks_flood_in(rig: dict[str, Any]) -> None:
    fc, cloud, gw = rig["fc"], rig["drc"], rig["gw"]
    stop = threading.Event()

    def flood() -> None:  # sticks as fast as paho can publish them, no heartbeats
        seq = 1
        while not stop.is_set():
            _down(cloud, "drone_control", {"seq": seq, "y": 2.0})
            seq += 1
            if seq % 200 == 0:
                time.sleep(0.01)

    t = threading.Thread(target=flood, daemon=True)
    _down(cloud, "heart_beat", {"seq": 1, "timestamp": 1})
    t.start()
    try:
        wait_until(lambda: _setpoint(fc) == (2.0, 0.0), 5, what="flying under the flood")
        # heartbeats are overdue: stop and 514301, even with the sticks still pouring in
        hb_lost = lambda b: b["method"] == "drc_status_notify" and b["data"]["result"] == 514301  # noqa: E731
        rig["cloud"].wait_for("events", hb_lost)  # events travel on the cloud's broker
        wait_until(lambda: _setpoint(fc) == (0.0, 0.0), 3, what="stopped without heartbeats")
        # heartbeats are still echoed one by one in the middle of the flood
        for i in range(20):
            _down(cloud, "heart_beat", {"seq": 100 + i, "timestamp": 1000 + i})
        cloud.wait_for("drc/up", lambda b: b["method"] == "heart_beat" and b["data"]["seq"] >= 100, count=20)
    finally:
        stop.set()
        t.join(2)
    assert gw.app.metrics.count("drc_failsafe_stops_total", reason="heartbeat") >= 1


def test_emergency_stop_brakes_and_holds(rig: dict[str, Any]) -> None:
    fc, cloud = rig["fc"], rig["drc"]
    _down(cloud, "heart_beat", {"seq": 1, "timestamp": 1})
    for seq in range(1, 6):
        _down(cloud, "drone_control", {"seq": seq, "x": -4.0})  # seed: +x left, so -x is right (east)
        time.sleep(0.05)
    wait_until(lambda: fc.inspect(lambda m: m.ve) > 1.0, 5, what="flying east")
    _down(cloud, "drone_emergency_stop", {})
    assert cloud.wait_for("drc/up", lambda b: b["method"] == "drone_emergency_stop")[0]["data"]["result"] == 0
    wait_until(lambda: fc.inspect(lambda m: m.actions["emergency_brake"]) >= 1, 3, what="brake frame")
    wait_until(lambda: fc.inspect(lambda m: m.speed) < 0.3, 5, what="braked")
    _down(cloud, "drone_control", {"seq": 6, "x": -4.0})
    held = cloud.wait_for(
        "drc/up", lambda b: b["method"] == "drone_control" and b["data"]["output"]["seq"] == 6
    )
    assert held[0]["data"]["result"] == 314000
    assert fc.inspect(lambda m: m.speed) < 0.3


def test_broker_killed_mid_drc_stops_the_aircraft(rig: dict[str, Any]) -> None:
    fc, cloud, broker = rig["fc"], rig["drc"], rig["drc_broker"]
    _down(cloud, "heart_beat", {"seq": 1, "timestamp": 1})
    for seq in range(1, 6):
        _down(cloud, "drone_control", {"seq": seq, "y": 3.0})
        time.sleep(0.05)
    wait_until(lambda: _setpoint(fc) == (3.0, 0.0), 5, what="flying")
    cloud.client.loop_stop()
    close_client(cloud.client)
    broker.stop(kill=True)
    wait_until(lambda: _setpoint(fc) == (0.0, 0.0), 3, what="stopped with the broker gone")
    wait_until(lambda: fc.inspect(lambda m: m.speed) < 0.3, 5, what="hovering")
    lost = {"result": 514303, "drc_state": 0}  # the session ends; the cloud hears why on its own broker
    rig["cloud"].wait_for("events", lambda b: b["method"] == "drc_status_notify" and b["data"] == lost)


def test_a_stalled_device_link_does_not_stall_the_gateway(rig: dict[str, Any]) -> None:
    fc, pty, cloud = rig["fc"], rig["pty"], rig["drc"]
    _down(cloud, "heart_beat", {"seq": 1, "timestamp": 1})
    _down(cloud, "drone_control", {"seq": 1, "y": 2.0})
    wait_until(lambda: _setpoint(fc) == (2.0, 0.0), 5, what="flying")
    pty.paused = True  # the flight controller stops reading and answering
    try:
        for i in range(5):
            _down(cloud, "heart_beat", {"seq": 10 + i, "timestamp": 10 + i})
        cloud.wait_for("drc/up", lambda b: b["method"] == "heart_beat" and b["data"]["seq"] >= 10, count=5)
        t0 = time.monotonic()
        r = rig["cloud"].service("x_osdk_hotpoint_stop", {})
        assert r["data"]["result"] in (325004, 325012) and time.monotonic() - t0 < 3.0
    finally:
        pty.paused = False
    # once the link moves again, the zero set-point (sticks stopped meanwhile) reaches the aircraft
    wait_until(lambda: _setpoint(fc) == (0.0, 0.0), 5, what="zero after the stall")


def test_hsi_info_push_has_360_one_degree_bins_from_the_flight_controller(rig: dict[str, Any]) -> None:
    fc, cloud = rig["fc"], rig["drc"]
    _down(cloud, "heart_beat", {"seq": 1, "timestamp": 1})
    # an A3 has no obstacle sensors: 360 bins, every sensor reported not working
    plain = cloud.wait_for("drc/up", lambda b: b["method"] == "hsi_info_push", timeout=5)[-1]["data"]
    assert len(plain["around_distances"]) == 360 and set(plain["around_distances"]) == {0}
    assert plain["front_work"] is False and plain["horizontal_work"] is False
    # an M210-like FC: front, up and down sensors, nothing within 30 m ahead
    fc.inspect(lambda m: setattr(m, "obstacle_sensors", {"front", "up", "down"}))
    data = cloud.wait_for(
        "drc/up", lambda b: b["method"] == "hsi_info_push" and b["data"].get("front_work"), timeout=5
    )[-1]["data"]
    bins = data["around_distances"]
    assert len(bins) == 360 and all(isinstance(v, int) for v in bins)
    assert bins[0] == bins[44] == bins[315] == 30000  # the front sector, in mm
    assert bins[45] == bins[180] == bins[314] == 0  # right, back, left: no sensor there
    assert data["up_distance"] == 30000 and data["down_work"] is True
    height = fc.inspect(lambda m: m.u)
    assert abs(data["down_distance"] - height * 1000) < 2000  # the height above ground, in mm
