"""A distributed broker: a real 3-node NATS cluster (JetStream, MQTT listeners) started on free loopback
ports. The gateway on node 1, the cloud on node 3; node 1 is killed (SIGKILL) mid-traffic: the gateway
moves to another node and every request is answered, none acted on twice. And how the cloud side
scales: a NATS queue group on NATS, a shared subscription (``$share/…``) on mosquitto."""

from __future__ import annotations

import asyncio
import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from adapters.rsdk.sim import GimbalCanSim
from bench.failover import Cloud, measure_round
from gateway.local_broker import LocalBroker
from tests.nats_cluster import NatsCluster
from tests.support import GatewayThread, gateway_settings, wait_until

pytestmark = [pytest.mark.broker, pytest.mark.nats]

GW = "GW-CLUSTER-1"
PI = "20-0-0"


@pytest.fixture(scope="module")
def cluster() -> Iterator[NatsCluster]:
    with NatsCluster() as c:
        yield c


def test_gateway_fails_over_when_its_nats_node_is_killed(cluster: NatsCluster, tmp_path: Path) -> None:
    """url = [n1, n2, n3], protocol 3.1.1: the gateway connects to n1; n1 is SIGKILLed with requests in
    flight (10/s, none re-sent by the cloud): the gateway is on another node at once; services are
    answered again, 20 of 20 afterwards; every request answered, none acted on twice
    (``bench/failover.py``; ``make bench`` runs twenty, with the broker's and the gateway's shares)."""
    r = measure_round(cluster, 0, tmp_path)
    print(f"\nfailover: on node {r.node + 1} {r.reconnected:.2f} s after the kill, answered again "
          f"after {r.first_answer:.2f} s, {r.requests} requests, {r.redelivered} twice")  # fmt: skip
    assert r.node != r.victim and r.after >= 20  # (the victim: node 1, or where the gateway settled)
    # the gateway's own part is ~0.5 s, but NATS refuses CONNECTs (closed before CONNACK) until the
    # surviving nodes have elected new JetStream leaders: 9.7-9.8 s in about one run in four here.
    # The 10 s target is measured by `make bench` (failover suite); this deadline is for a loaded CI
    assert r.reconnected < 15.0, r
    # answers wait for NATS too: while the dead node led the stream of MQTT QoS 1 messages, the others
    # elect a new leader (Raft, 4-9 s in 2.9) before any QoS 1 publish goes through (docs/brokers.md);
    # 10 s is the target (make bench reports it), the deadline here is generous for a loaded machine
    assert r.first_answer < 20.0, r


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
                # only this test's replies: the failover test before it leaves QoS 1 requests on the
                # same client id's session, which NATS redelivers to this gateway (a new process, with no
                # reply cache of the old one's), and their replies reach the group too
                tid = json.loads(msg.data)["tid"]
                if tid.startswith("q-"):
                    got[name].append(tid)

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


def test_a_cluster_that_cannot_start_leaves_no_node_running() -> None:
    """Seen on the shared machine: node 0 exited ('address already in use': a port picked free was taken
    before it bound it) and nodes 1 and 2 were left running after the test (ResourceWarning, and two
    nats-server processes nobody stopped). Here node 0's configuration is broken on purpose."""
    cluster = NatsCluster()
    (cluster.dir / "n0.conf").write_text("listen: 127.0.0.1:not-a-port\n")
    with pytest.raises(RuntimeError, match="node 0 exited"):
        cluster.start(timeout=20)
    assert not any(cluster.running(i) for i in range(cluster.NODES))
