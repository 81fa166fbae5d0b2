"""Broker outages: what the gateway produced while the broker was gone is delivered, in order, once it is
back; what the cloud asked is answered and acted on once. Real mosquitto with persistence, restarted."""

from __future__ import annotations

import asyncio
import json
import math
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
from tests.support import GatewayThread, gateway_settings, wait_until

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
        asyncio.run_coroutine_threadsafe(adapter._obtain(1), gw.loop).result(5)
        gw.app.devices.authority.flight.add("OSDK-OUT-1")
        asyncio.run_coroutine_threadsafe(adapter._flight_task(1), gw.loop).result(5)
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
                "data": {"payload_index": "1001-0-0"}}  # fmt: skip
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
