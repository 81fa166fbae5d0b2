"""Broker failover on a real 3-node NATS cluster (JetStream, MQTT listeners; ``tests/nats_cluster.py``).

Each round: a gateway with ``url = [victim, …the other two]`` and ``protocol = "3.1.1"`` drives a simulated
gimbal; the cloud, on node 3, sends ``camera_photo_take`` at 10/s, each with a tid of its own, never
re-sent; once 20 are answered the victim (the gateway's node: node 1 or 2, alternately) is SIGKILLed.
Figures per round: when the gateway was connected to another node, when the first request sent after
the kill was answered, that 20 more were answered afterwards, that every request was answered, how
many replies the broker delivered twice (the same bytes: QoS 1 across a node crash) and that the gimbal
acted once per request. Target (issue #19): answered again within 10 s, 20 of 20 afterwards.
``tests/test_brokers_cluster.py`` runs one round.
"""

from __future__ import annotations

import json
import statistics
import threading
import time
import uuid
from dataclasses import dataclass
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion, MQTTProtocolVersion

from adapters.rsdk.sim import GimbalCanSim
from bench.run import Config, Row
from gateway.mqtt import close_client
from tests.nats_cluster import NatsCluster, nats_version
from tests.support import GatewayThread, gateway_settings, wait_until

GW = "GW-CLUSTER-1"
PI = "20-0-0"


class Cloud:
    """A cloud consumer on one node: MQTT 3.1.1, persistent session, QoS 1; keeps every reply's bytes."""

    def __init__(self, host: str, port: int, *, topics: list[str] | None = None) -> None:
        self.replies: dict[str, list[bytes]] = {}
        self.reply_times: dict[str, float] = {}
        self._lock = threading.Lock()
        self.client = paho.Client(
            CallbackAPIVersion.VERSION2,
            client_id=f"cloud-{uuid.uuid4().hex[:8]}",
            protocol=MQTTProtocolVersion.MQTTv311,
            clean_session=False,
        )
        self.client.reconnect_delay_set(0.1, 0.5)
        self.client.max_inflight_messages_set(1000)
        self.topologies: list[float] = []  # when each update_topo arrived
        subs = [
            (t, 1) for t in (topics or [f"thing/product/{GW}/services_reply", f"sys/product/{GW}/status"])
        ]
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
        if msg.topic.endswith("/status"):
            with self._lock:
                self.topologies.append(now)
            return
        tid = json.loads(msg.payload)["tid"]
        with self._lock:
            self.replies.setdefault(tid, []).append(bytes(msg.payload))
            self.reply_times.setdefault(tid, now)

    def request(self, tid: str) -> None:
        body = {"tid": tid, "bid": "b", "timestamp": 0, "method": "camera_photo_take",
                "data": {"payload_index": PI}}  # fmt: skip
        self.client.publish(f"thing/product/{GW}/services", json.dumps(body), qos=1)

    def answered(self) -> set[str]:
        with self._lock:
            return set(self.replies)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
        close_client(self.client)


@dataclass(frozen=True, slots=True)
class Failover:
    victim: int
    reconnected: float  # kill → the gateway connected to another node (s)
    first_answer: float  # kill → the first request sent after the kill answered (s)
    requests: int  # all answered, each acted on once (checked)
    after: int  # answered after the kill
    redelivered: int  # replies the broker delivered twice (same bytes)
    node: int  # the node the gateway moved to


def measure_round(cluster: NatsCluster, victim: int) -> Failover:
    """One round: the gateway starts on ``victim``, which is SIGKILLed mid-traffic (then restarted)."""
    channel = f"djigw-fo-{uuid.uuid4().hex[:8]}"
    sim = GimbalCanSim(interface="virtual", channel=channel).start()
    # the gimbal's reply deadline at its ceiling (2 s, default 0.3 s): this suite counts lost and doubled
    # requests across a failover, not device latency, and on a CPU-starved machine (the smoke test beside
    # five other test workers) a reply late by 0.3 s was answered 325004 and failed the suite
    device = {"type": "rsdk", "sn": "RSDK-CL-1", "interface": "virtual", "channel": channel,
              "request_timeout": 2.0}  # fmt: skip
    urls = [cluster.url(victim)] + [cluster.url(i) for i in range(cluster.NODES) if i != victim]
    settings = gateway_settings(
        1, [device], gateway_sn=GW, dispatcher={"require_authority": False},
        broker={"url": urls, "protocol": "3.1.1", "reconnect_min": 0.5, "reconnect_max": 30.0},
    )  # fmt: skip
    cloud = Cloud(cluster.host, cluster.mqtt_ports[2])
    gw = GatewayThread(settings).start()
    sent: dict[str, float] = {}
    stop = threading.Event()

    def traffic() -> None:
        n = 0
        while not stop.wait(0.1):
            tid = f"photo-{victim}-{n}-{uuid.uuid4().hex[:4]}"
            n += 1
            sent[tid] = time.monotonic()
            cloud.request(tid)

    sender = threading.Thread(target=traffic, daemon=True)
    try:
        wait_until(lambda: gw.app.devices.by_sn("RSDK-CL-1").online, 10, what="gimbal online")
        if gw.app.bridge.current.port != cluster.mqtt_ports[victim]:
            raise AssertionError("the gateway did not start on the first url")
        sender.start()
        wait_until(lambda: len(cloud.answered()) >= 20, 30, what="20 answers before the kill")
        killed_at = time.monotonic()
        cluster.kill(victim)
        bridge = gw.app.bridge
        wait_until(lambda: bridge.connected and bridge.current.port != cluster.mqtt_ports[victim], 20,
                   interval=0.005, what="the gateway on another node")  # fmt: skip
        reconnected = time.monotonic() - killed_at

        def after() -> list[str]:
            done = cloud.answered()
            return [t for t, at in list(sent.items()) if at > killed_at and t in done]

        # re-subscribed and announced again on the new node
        wait_until(
            lambda: any(t > killed_at for t in cloud.topologies), 30, what="update_topo after the kill"
        )
        wait_until(after, 30, what="a request sent after the kill answered")
        first_answer = min(cloud.reply_times[t] for t in after()) - killed_at
        wait_until(lambda: len(after()) >= 20, 30, what="20 requests answered after the failover")
        stop.set()
        sender.join(2)
        wait_until(lambda: set(sent) <= cloud.answered(), 30, what="every request answered")
        with cloud._lock:
            replies = {tid: list(r) for tid, r in cloud.replies.items()}
        for tid in sent:  # one answer per request; a redelivery is the same bytes
            if len(set(replies[tid])) != 1 or json.loads(replies[tid][0])["data"] != {"result": 0}:
                raise AssertionError(f"{tid}: {replies[tid]}")
        if sim.model.photos != len(sent):
            raise AssertionError(f"{sim.model.photos} photos for {len(sent)} requests")
        node = cluster.mqtt_ports.index(bridge.current.port)
        return Failover(victim, reconnected, first_answer, len(sent), len(after()),
                        sum(len(r) - 1 for r in replies.values()), node)  # fmt: skip
    finally:
        stop.set()
        gw.stop()
        cloud.close()
        sim.stop()
        cluster.start_node(victim)
        cluster.wait_ready([victim])


def run(cfg: Config) -> list[Row]:
    rounds = 1 if cfg.quick else 6
    results: list[Failover] = []
    with NatsCluster() as cluster:
        for k in range(rounds):
            results.append(measure_round(cluster, k % 2))
            r = results[-1]
            line = (f"  .. failover: kill node {r.victim + 1}: on node {r.node + 1} after "
                    f"{r.reconnected:.2f} s, answered again after {r.first_answer:.2f} s")  # fmt: skip
            print(line, flush=True)
    firsts = [r.first_answer for r in results]
    recon = [r.reconnected for r in results]
    note = (f"nats-server {nats_version()}, 3 nodes; per round: answered again "
            + ", ".join(f"{x:.1f}" for x in firsts) + " s; "
            f"{sum(r.requests for r in results)} requests, all answered, each acted on once; "
            f"{sum(r.redelivered for r in results)} replies delivered twice (same bytes)")  # fmt: skip
    return [
        Row(group="failover", case="gateway on another node after its node's SIGKILL (median)",
            count=len(recon), rate=statistics.median(recon), unit="s", note=f"max {max(recon):.2f} s"),
        Row(group="failover", case="services answered again after the kill (median; target <= 10 s)",
            count=len(firsts), rate=statistics.median(firsts), unit="s", note=note),
        Row(group="failover", case="services answered again after the kill (worst)", count=len(firsts),
            rate=max(firsts), unit="s"),
        Row(group="failover", case="requests answered after the failover (each round >= 20)",
            count=len(results), rate=float(min(r.after for r in results)), unit="req"),
    ]  # fmt: skip
