"""A distributed broker: a real 3-node NATS cluster (JetStream, MQTT listeners) started on free loopback
ports. The gateway on node 1, the cloud on node 3; node 1 is killed (SIGKILL) mid-traffic: the gateway
moves to another node and every request is answered, none acted on twice. And how the cloud side
scales: a NATS queue group on NATS, a shared subscription (``$share/…``) on mosquitto."""

from __future__ import annotations

import asyncio
import json
import threading
import time
import uuid
from collections.abc import Iterator
from typing import Any

import paho.mqtt.client as paho
import pytest
from paho.mqtt.enums import CallbackAPIVersion, MQTTProtocolVersion

from adapters.rsdk.sim import GimbalCanSim
from gateway.local_broker import LocalBroker
from gateway.mqtt import close_client
from tests.nats_cluster import NatsCluster
from tests.support import GatewayThread, gateway_settings, wait_until

pytestmark = [pytest.mark.broker, pytest.mark.nats]

GW = "GW-CLUSTER-1"
PI = "1001-0-0"


@pytest.fixture(scope="module")
def cluster() -> Iterator[NatsCluster]:
    with NatsCluster() as c:
        yield c


class Cloud:
    """A cloud consumer on one node: MQTT 3.1.1, persistent session, QoS 1; keeps every reply's raw bytes."""

    def __init__(self, host: str, port: int, *, topics: list[str] | None = None) -> None:
        self.replies: dict[str, list[bytes]] = {}
        self.reply_times: dict[str, float] = {}
        self.osd_times: list[float] = []
        self._lock = threading.Lock()
        self.client = paho.Client(
            CallbackAPIVersion.VERSION2,
            client_id=f"cloud-{uuid.uuid4().hex[:8]}",
            protocol=MQTTProtocolVersion.MQTTv311,
            clean_session=False,
        )
        self.client.reconnect_delay_set(0.1, 0.5)
        self.client.max_inflight_messages_set(1000)
        subs = [(t, 1) for t in (topics or [f"thing/product/{GW}/services_reply", "thing/product/+/osd"])]
        self._subscribed = threading.Event()
        self.client.on_connect = lambda c, u, f, rc, p: c.subscribe(subs)
        self.client.on_subscribe = lambda *a: self._subscribed.set()
        self.client.on_message = self._on_message
        self.client.connect(host, port)
        self.client.loop_start()
        if not self._subscribed.wait(15):
            raise AssertionError("cloud could not subscribe")

    def _on_message(self, client: Any, userdata: Any, msg: paho.MQTTMessage) -> None:
        now = time.monotonic()
        if msg.topic.endswith("/osd"):
            with self._lock:
                self.osd_times.append(now)
            return
        tid = json.loads(msg.payload)["tid"]
        with self._lock:
            self.replies.setdefault(tid, []).append(bytes(msg.payload))
            self.reply_times.setdefault(tid, now)

    def request(self, tid: str) -> None:
        body = {
            "tid": tid,
            "bid": "b",
            "timestamp": 0,
            "method": "camera_photo_take",
            "data": {"payload_index": PI},
        }
        self.client.publish(f"thing/product/{GW}/services", json.dumps(body), qos=1)

    def answered(self) -> set[str]:
        with self._lock:
            return set(self.replies)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
        close_client(self.client)


def test_gateway_fails_over_when_its_nats_node_is_killed(cluster: NatsCluster, can_channel: str) -> None:
    """url = [n1, n2, n3], protocol 3.1.1: the gateway connects to n1; n1 is SIGKILLed with requests in
    flight; services are answered again through another node within 10 s, 20 of 20 afterwards; every
    request (none re-sent by the cloud) is answered, and acted on once."""
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {"type": "rsdk", "sn": "RSDK-CL-1", "interface": "virtual", "channel": can_channel}
    settings = gateway_settings(
        1, [device], gateway_sn=GW, dispatcher={"require_authority": False},
        broker={"url": cluster.urls, "protocol": "3.1.1", "reconnect_min": 0.5, "reconnect_max": 30.0},
    )  # fmt: skip
    cloud = Cloud(cluster.host, cluster.mqtt_ports[2])
    gw = GatewayThread(settings).start()
    sent: dict[str, float] = {}
    stop = threading.Event()

    def traffic() -> None:  # ~10 requests/s, each with a tid of its own, never re-sent
        n = 0
        while not stop.wait(0.1):
            tid = f"photo-{n}"
            n += 1
            sent[tid] = time.monotonic()
            cloud.request(tid)

    sender = threading.Thread(target=traffic, daemon=True)
    try:
        wait_until(lambda: gw.app.devices.by_sn("RSDK-CL-1").online, 10, what="gimbal online")
        assert gw.app.bridge.current.port == cluster.mqtt_ports[0]  # the first url that answered
        sender.start()
        wait_until(lambda: len(cloud.answered()) >= 20, 30, what="20 answers before the kill")
        killed_at = time.monotonic()
        cluster.kill(0)
        wait_until(lambda: gw.app.bridge.connected and gw.app.bridge.current.port != cluster.mqtt_ports[0],
                   10, what="the gateway on another node")  # fmt: skip
        after = lambda: sorted(t for t, at in sent.items() if at > killed_at and t in cloud.answered())  # noqa: E731
        wait_until(after, 10, what="a request sent after the kill answered")
        first_answer = min(cloud.reply_times[t] for t in after()) - killed_at
        assert first_answer < 10.0, first_answer
        wait_until(lambda: len(after()) >= 20, 20, what="20 requests answered after the failover")
        stop.set()
        sender.join(2)
        wait_until(lambda: set(sent) <= cloud.answered(), 20, what="every request answered")
        with cloud._lock:
            replies = {tid: list(r) for tid, r in cloud.replies.items()}
        # one answer per request: a reply the broker delivered twice (QoS 1 across a node crash) is the
        # same bytes, never a second, different answer
        for tid in sent:
            assert len(set(replies[tid])) == 1, (tid, replies[tid])
            assert json.loads(replies[tid][0])["data"] == {"result": 0}
        assert sim.model.photos == len(sent)  # acted on once each
        duplicates = sum(len(r) - 1 for r in replies.values())
        print(f"\nfailover: first answer {first_answer:.2f} s after the kill, {len(sent)} requests, "
              f"{duplicates} redelivered replies, now on port {gw.app.bridge.current.port}")  # fmt: skip
    finally:
        stop.set()
        gw.stop()
        cloud.close()
        sim.stop()
        cluster.start_node(0)
        cluster.wait_ready([0])


def test_cloud_scales_with_a_nats_queue_group(cluster: NatsCluster, can_channel: str) -> None:
    """NATS has no MQTT shared subscriptions; a cloud scales by reading the gateway's MQTT topics as NATS
    subjects (``/`` → ``.``) in one queue group: each reply reaches exactly one of its consumers."""
    import nats

    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {"type": "rsdk", "sn": "RSDK-CL-2", "interface": "virtual", "channel": can_channel}
    settings = gateway_settings(1, [device], gateway_sn=GW, dispatcher={"require_authority": False},
                                broker={"url": cluster.urls, "protocol": "3.1.1"})  # fmt: skip
    got: dict[str, list[str]] = {"a": [], "b": []}
    ready = threading.Event()
    done = threading.Event()

    async def consumers() -> None:
        conns = []
        for name in got:
            nc = await nats.connect(f"nats://{cluster.host}:{cluster.client_ports[2]}")
            conns.append(nc)

            async def handler(msg: Any, name: str = name) -> None:
                got[name].append(json.loads(msg.data)["tid"])

            await nc.subscribe(f"thing.product.{GW}.services_reply", queue="cloud", cb=handler)
            await nc.flush()
        ready.set()
        while not done.is_set():
            await asyncio.sleep(0.05)
        for nc in conns:
            await nc.drain()

    runner = threading.Thread(target=lambda: asyncio.run(consumers()), daemon=True)
    runner.start()
    requester = Cloud(cluster.host, cluster.mqtt_ports[2], topics=["djigw/unused"])
    gw = GatewayThread(settings).start()
    try:
        assert ready.wait(10)
        wait_until(lambda: gw.app.devices.by_sn("RSDK-CL-2").online, 10, what="gimbal online")
        tids = [f"q-{i}" for i in range(40)]
        for tid in tids:
            requester.request(tid)
            time.sleep(0.01)
        wait_until(lambda: len(got["a"]) + len(got["b"]) >= len(tids), 20, what="every reply consumed")
        time.sleep(0.3)  # a reply delivered to both consumers would show up now
        assert sorted(got["a"] + got["b"]) == sorted(tids)  # each exactly once, across the group
        assert got["a"] and got["b"], got  # the group shares the work
    finally:
        done.set()
        runner.join(5)
        gw.stop()
        requester.close()
        sim.stop()


def test_cloud_scales_with_a_shared_subscription_on_mosquitto(broker: LocalBroker, can_channel: str) -> None:
    """On an MQTT 5 broker (mosquitto here; EMQX, HiveMQ alike) two cloud consumers share
    ``$share/cloud/…/services_reply``: each reply reaches exactly one of them."""
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {"type": "rsdk", "sn": "RSDK-CL-3", "interface": "virtual", "channel": can_channel}
    settings = gateway_settings(broker.port, [device], gateway_sn=GW, dispatcher={"require_authority": False})
    share = f"$share/cloud/thing/product/{GW}/services_reply"
    consumers = [Cloud(broker.host, broker.port, topics=[share]) for _ in range(2)]
    requester = Cloud(broker.host, broker.port, topics=["djigw/unused"])
    gw = GatewayThread(settings).start()
    try:
        wait_until(lambda: gw.app.devices.by_sn("RSDK-CL-3").online, 10, what="gimbal online")
        tids = [f"s-{i}" for i in range(40)]
        for tid in tids:
            requester.request(tid)
            time.sleep(0.01)
        wait_until(lambda: sum(len(c.answered()) for c in consumers) >= len(tids), 20, what="every reply")
        time.sleep(0.3)
        seen = [t for c in consumers for t in c.answered()]
        assert sorted(seen) == sorted(tids)
        assert all(c.answered() for c in consumers)
    finally:
        gw.stop()
        for c in consumers:
            c.close()
        requester.close()
        sim.stop()
