"""Broker outages: what the gateway produced while the broker was gone is delivered, in order, once it is
back; what the cloud asked is answered and acted on once. Real mosquitto with persistence, restarted."""

from __future__ import annotations

import asyncio
import json
import math
import os
import threading
import time
import uuid
from collections.abc import Callable
from typing import Any

import paho.mqtt.client as paho
import pytest
from paho.mqtt.enums import CallbackAPIVersion

from adapters.osdk.sim import OsdkFcDevice, OsdkFcModel
from adapters.rsdk.sim import GimbalCanSim
from adapters.simio import PtyEndpoint
from gateway.local_broker import LocalBroker
from gateway.mqtt import close_client
from tests.support import DrcSticks, GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker

GW = "GW-OUTAGE-1"


class PersistentCloud:
    """A cloud client with a persistent session (clean_session false, QoS 1): the broker keeps what
    arrives for it while it is away, as production cloud consumers are configured."""

    def __init__(self, port: int) -> None:
        self.messages: list[tuple[str, dict[str, Any]]] = []
        self._lock = threading.Lock()
        self.client = paho.Client(
            CallbackAPIVersion.VERSION2, client_id=f"cloud-{uuid.uuid4().hex[:6]}", clean_session=False
        )
        self.client.reconnect_delay_set(0.1, 0.5)
        self.client.max_inflight_messages_set(1000)
        self.client.on_connect = lambda c, u, f, rc, p: c.subscribe(f"thing/product/{GW}/#", qos=1)
        self.client.on_message = self._on_message
        self.client.connect("127.0.0.1", port)
        self.client.loop_start()
        wait_until(self.client.is_connected, 5, what="cloud connected")
        time.sleep(0.2)

    def _on_message(self, client: Any, userdata: Any, msg: paho.MQTTMessage) -> None:
        with self._lock:
            self.messages.append((msg.topic, json.loads(msg.payload)))
        body = self.messages[-1][1]
        if msg.topic.endswith("/events") and body.get("need_reply") == 1:
            reply = {"tid": body["tid"], "bid": body["bid"], "timestamp": 0, "method": body["method"],
                     "data": {"result": 0}}  # fmt: skip
            client.publish(msg.topic + "_reply", json.dumps(reply), qos=1)

    def find(
        self, suffix: str, predicate: Callable[[dict[str, Any]], bool] = lambda b: True
    ) -> list[dict[str, Any]]:
        with self._lock:
            return [b for t, b in self.messages if t.endswith(suffix) and predicate(b)]

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
        close_client(self.client)


def _ne(lat: float, lon: float, n: float, e: float) -> tuple[float, float]:
    return (
        lat + math.degrees(n / 6_378_137.0),
        lon + math.degrees(e / (6_378_137.0 * math.cos(math.radians(lat)))),
    )


def test_no_progress_event_is_lost_across_a_broker_outage() -> None:
    broker = LocalBroker(persistence=True).start()
    model = OsdkFcModel()
    fc = OsdkFcDevice(model)
    pty = PtyEndpoint(fc).start()
    settings = gateway_settings(
        broker.port, [{"type": "osdk", "sn": "OSDK-OUT-1", "url": pty.path}], gateway_sn=GW
    )
    cloud = PersistentCloud(broker.port)
    gw = GatewayThread(settings).start()
    try:
        wait_until(lambda: gw.app.devices.by_sn("OSDK-OUT-1").online, 10, what="aircraft online")
        adapter = gw.app.devices.by_sn("OSDK-OUT-1")
        asyncio.run_coroutine_threadsafe(adapter.obtain_control(1), gw.loop).result(5)
        gw.app.devices.authority.flight.add("OSDK-OUT-1")
        asyncio.run_coroutine_threadsafe(adapter.flight_task("takeoff"), gw.loop).result(5)
        wait_until(lambda: fc.inspect(lambda m: m.in_air and m.display_mode == 6), 10, what="airborne")
        home = (adapter.telemetry.latitude, adapter.telemetry.longitude)
        alt = adapter.telemetry.home_altitude
        points = [{"latitude": p[0], "longitude": p[1], "height": alt + 10}
                  for p in (_ne(*home, 12 * (i + 1), 0) for i in range(4))]  # fmt: skip
        request = {"tid": "fly-out", "bid": "b", "timestamp": 0, "method": "fly_to_point",
                   "data": {"fly_to_id": "outage", "max_speed": 8, "points": points}}  # fmt: skip
        cloud.client.publish(f"thing/product/{GW}/services", json.dumps(request), qos=1)
        progress = lambda: cloud.find("/events", lambda b: b["method"] == "fly_to_point_progress")  # noqa: E731
        wait_until(
            lambda: any(e["data"]["way_point_index"] == 0 for e in progress()), 20, what="first waypoint"
        )
        broker.stop()  # the outage: waypoints keep being reached meanwhile
        time.sleep(3.0)
        broker.start()
        wait_until(
            lambda: any(e["data"]["status"] == "wayline_ok" for e in progress()), 30, what="mission end"
        )
        seen: list[tuple[str, int]] = []
        for e in progress():
            key = (e["data"]["status"], e["data"]["way_point_index"])
            if key not in seen:  # an event re-sent because its reply was lost is the same event
                seen.append(key)
        assert seen == [("wayline_progress", i) for i in range(4)] + [("wayline_ok", 3)], seen
        assert gw.app.metrics.count("mqtt_connects_total") >= 2
    finally:
        gw.stop()
        cloud.close()
        pty.stop()
        broker.stop()


def test_requests_across_broker_kills_are_answered_and_acted_on_once(can_channel: str) -> None:
    """Crashes (SIGKILL) lose what the broker held only in memory; a cloud re-sends an unanswered request
    after 3 s (the reference cloud SDK's rule; here with the same tid). Every request ends up answered,
    and the gateway acts on each once: a repeat is answered from the reply cache."""
    broker = LocalBroker(persistence=True).start()
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {"type": "rsdk", "sn": "RSDK-OUT-1", "interface": "virtual", "channel": can_channel}
    settings = gateway_settings(broker.port, [device], gateway_sn=GW, dispatcher={"require_authority": False})
    cloud = PersistentCloud(broker.port)
    gw = GatewayThread(settings).start()
    tids = [f"photo-{i}" for i in range(30)]

    def send(tid: str) -> None:
        body = {"tid": tid, "bid": "b", "timestamp": 0, "method": "camera_photo_take",
                "data": {"payload_index": "20-0-0"}}  # fmt: skip
        cloud.client.publish(f"thing/product/{GW}/services", json.dumps(body), qos=1)

    def answered() -> set[str]:
        return {r["tid"] for r in cloud.find("services_reply")}

    try:
        wait_until(lambda: gw.app.devices.by_sn("RSDK-OUT-1").online, 10, what="gimbal online")
        time.sleep(1.2)  # the broker's autosave (1 s) has both sessions on disk before the first crash
        for i, tid in enumerate(tids):
            send(tid)
            if i in (10, 20):
                broker.stop(kill=True)  # a crash, not a clean stop
                time.sleep(0.5)
                broker.start()
            time.sleep(0.02)
        deadline = time.monotonic() + 30
        while answered() < set(tids) and time.monotonic() < deadline:
            time.sleep(3.0)
            for tid in sorted(set(tids) - answered()):
                send(tid)
        assert answered() >= set(tids), f"unanswered: {sorted(set(tids) - answered())}"
        replies: dict[str, list[dict[str, Any]]] = {}
        for r in cloud.find("services_reply"):
            replies.setdefault(r["tid"], []).append(r)
        for tid in tids:
            assert all(r["data"] == {"result": 0} for r in replies[tid]), replies[tid]
        assert sim.model.photos == len(tids)  # never acted on twice
        assert gw.app.metrics.count("mqtt_connects_total") >= 2
    finally:
        gw.stop()
        cloud.close()
        sim.stop()
        broker.stop()


def _echoed_after(cloud: PersistentCloud, seq: int) -> bool:
    return bool(cloud.find("drc/up", lambda b: b["method"] == "heart_beat" and b["data"]["seq"] > seq))


def _open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def test_broker_kills_with_services_and_drc_in_flight(can_channel: str) -> None:
    """The broker crashes three times while the cloud drives the gimbal over DRC (on the main broker) and
    asks for photos. Each crash stops the motion at once and ends the DRC session (514303, delivered once
    the broker is back); the cloud enters again. Every request is answered, none is acted on twice, and
    nothing accumulates in the gateway across the restarts (threads, sockets, pending work)."""
    broker = LocalBroker(persistence=True).start()
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {"type": "rsdk", "sn": "RSDK-OUT-2", "interface": "virtual", "channel": can_channel,
              "drc_drive": True}  # fmt: skip
    settings = gateway_settings(broker.port, [device], gateway_sn=GW)
    cloud = PersistentCloud(broker.port)
    gw = GatewayThread(settings).start()
    sticks: DrcSticks | None = None
    photo_tids: list[str] = []

    def request(tid: str, method: str, data: dict[str, Any]) -> None:
        body = {"tid": tid, "bid": "b", "timestamp": 0, "method": method, "data": data}
        cloud.client.publish(f"thing/product/{GW}/services", json.dumps(body), qos=1)

    def replies(tid: str) -> list[dict[str, Any]]:
        return cloud.find("services_reply", lambda b: b["tid"] == tid)

    def call(tid: str, method: str, data: dict[str, Any]) -> dict[str, Any]:
        """Send, re-sending after 3 s while unanswered (the reference cloud's rule)."""
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            request(tid, method, data)
            try:
                wait_until(lambda: bool(replies(tid)), 3, what=f"reply to {tid}")
            except AssertionError:
                continue
            return replies(tid)[0]
        raise AssertionError(f"{method} {tid} never answered")

    def link_lost_events() -> set[str]:
        return {
            e["tid"]
            for e in cloud.find("/events", lambda b: b["method"] == "drc_status_notify")
            if e["data"] == {"result": 514303, "drc_state": 0}
        }

    main_broker = {"address": f"127.0.0.1:{broker.port}", "client_id": "x", "username": "", "password": "",
                   "expire_time": 4102444800, "enable_tls": False}  # fmt: skip
    try:
        wait_until(lambda: gw.app.devices.by_sn("RSDK-OUT-2").online, 10, what="gimbal online")
        assert call("grab", "payload_authority_grab", {"payload_index": "20-0-0"})["data"]["result"] == 0
        time.sleep(1.2)  # the broker's autosave (1 s) has both sessions on disk before the first crash
        sticks = DrcSticks(cloud.client, GW, yaw_rate=20.0)
        baseline: tuple[set[str], int] | None = None
        for cycle in range(3):
            enter = {"mqtt_broker": main_broker, "osd_frequency": 5, "hsi_frequency": 1}
            assert call(f"enter-{cycle}", "drc_mode_enter", enter)["data"]["result"] == 0
            wait_until(lambda: sim.model.yaw.speed == 20.0, 5, what=f"driven over DRC (cycle {cycle})")
            wait_until(lambda n=sticks.seq: _echoed_after(cloud, n), 5, what="heartbeats echoed")
            if baseline is None:  # after one full cycle's start-up: what the gateway holds in steady state
                baseline = ({t.name for t in threading.enumerate()}, _open_fds())
            for i in range(5):
                tid = f"photo-{cycle}-{i}"
                photo_tids.append(tid)
                request(tid, "camera_photo_take", {"payload_index": "20-0-0"})
                time.sleep(0.02)
            broker.stop(kill=True)  # a crash with sticks, heartbeats and requests in flight
            wait_until(lambda: sim.model.yaw.speed == 0.0, 3, what="motion stopped when the broker died")
            wait_until(lambda: not gw.app.drc.active, 3, what="DRC session ended")
            time.sleep(0.5)
            broker.start()
            wait_until(
                lambda n=cycle + 1: len(link_lost_events()) == n, 20, what="514303 delivered after restart"
            )
            assert sim.model.yaw.speed == 0.0  # sticks that arrive after the crash drive nothing
        deadline = time.monotonic() + 30
        answered = lambda: {r["tid"] for r in cloud.find("services_reply")}  # noqa: E731
        while not answered() >= set(photo_tids) and time.monotonic() < deadline:
            for tid in sorted(set(photo_tids) - answered()):
                request(tid, "camera_photo_take", {"payload_index": "20-0-0"})
            time.sleep(3.0)
        assert answered() >= set(photo_tids), f"unanswered: {sorted(set(photo_tids) - answered())}"
        for tid in photo_tids:
            assert all(r["data"] == {"result": 0} for r in replies(tid)), replies(tid)
        assert sim.model.photos == len(photo_tids)  # never acted on twice
        assert gw.app.metrics.count("mqtt_connects_total") >= 4
        # the failsafe counted one link-lost stop per crash
        assert gw.app.metrics.count("drc_failsafe_stops_total") >= 3
        # nothing accumulates across restarts: the same threads and sockets as in the first session's steady
        # state, no request still pending, no event still waiting for its reply
        sticks.close()
        sticks = None
        assert baseline is not None
        wait_until(lambda: gw.app.dispatcher.in_flight == 0, 5, what="no request pending")
        wait_until(lambda: not gw.app.northbound._events, 10, what="every event acknowledged")
        threads, fds = baseline
        assert {t.name for t in threading.enumerate()} <= threads | {"test-sticks"}
        assert _open_fds() <= fds
    finally:
        if sticks is not None:
            sticks.close()
        gw.stop()
        cloud.close()
        sim.stop()
        broker.stop()
