"""Many gateways on one broker, the cloud reading their replies through a shared subscription.

G gateway instances (quick: 10, full: 100) run in this process, each with its own event loop and its
own MQTT connection, all on one private mosquitto. The cloud side is one publisher and two consumers
sharing ``$share/cloud/thing/product/+/services_reply`` (MQTT shared subscription: each reply goes to
one of them). The publisher keeps up to 64 requests in flight, round-robin over the gateways, and each
request's round trip is timed by whichever consumer gets its reply. The requests are answered by the
gateways' dispatchers (``flight_authority_grab`` on gateways without an aircraft: validated, routed,
answered 399001), so the figure is the gateways' and the broker's, not a device's.
"""

from __future__ import annotations

import json
import threading
import time
import uuid
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion, MQTTProtocolVersion

from bench.run import Config, Row
from gateway.local_broker import LocalBroker
from gateway.settings import load_settings
from tests.support import GatewayThread


def _pct(samples: list[float], q: float) -> float:
    s = sorted(samples)
    return s[min(len(s) - 1, int(q * len(s)))] if s else float("nan")


def run(cfg: Config) -> list[Row]:
    n_gateways = 10 if cfg.quick else 100
    n_requests = 2_000 if cfg.quick else 20_000
    window = 64
    sent: dict[str, float] = {}
    rtts: list[float] = []
    lock = threading.Lock()
    slots = threading.Semaphore(window)
    done = threading.Event()
    with LocalBroker(extra_config="max_inflight_messages 1000\nmax_queued_messages 100000") as broker:
        gateways = []
        for g in range(n_gateways):
            settings = load_settings(None, gateway_sn=f"GW-FLEET-{g:03d}", broker={"url": broker.url},
                                     metrics={"enabled": False}, log_level="WARNING")  # fmt: skip
            gateways.append(GatewayThread(settings).start())

        def on_reply(client: Any, userdata: Any, msg: paho.MQTTMessage) -> None:
            tid = json.loads(msg.payload).get("tid")
            now = time.perf_counter()
            with lock:
                t0 = sent.pop(tid, None)
                if t0 is not None:
                    rtts.append((now - t0) * 1000)
                    if len(rtts) >= n_requests:
                        done.set()
            if t0 is not None:
                slots.release()

        consumers = []
        for i in range(2):
            c = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"cloud-consumer-{i}",
                            protocol=MQTTProtocolVersion.MQTTv5)  # fmt: skip
            c.on_message = on_reply
            c.connect("127.0.0.1", broker.port)
            c.loop_start()
            c.subscribe("$share/cloud/thing/product/+/services_reply", qos=1)
            consumers.append(c)
        publisher = paho.Client(CallbackAPIVersion.VERSION2, client_id="cloud-publisher")
        publisher.max_inflight_messages_set(window)
        publisher.connect("127.0.0.1", broker.port)
        publisher.loop_start()
        time.sleep(0.5)
        t_start = time.perf_counter()
        for i in range(n_requests):
            slots.acquire()
            tid = uuid.uuid4().hex
            body = json.dumps(
                {"tid": tid, "bid": "b", "timestamp": 0, "method": "flight_authority_grab", "data": {}}
            )
            with lock:
                sent[tid] = time.perf_counter()
            publisher.publish(f"thing/product/GW-FLEET-{i % n_gateways:03d}/services", body, qos=1)
        done.wait(60)
        elapsed = time.perf_counter() - t_start
        for c in (*consumers, publisher):
            c.disconnect()
            c.loop_stop()
        for gw in gateways:
            gw.stop()
    lost = n_requests - len(rtts)
    note = f"{n_gateways} gateways in one process, 2 consumers on a shared subscription, {window} in flight"
    return [
        Row(group="fleet", case=f"{n_gateways} gateways: aggregate replies/s", count=n_requests,
            rate=len(rtts) / elapsed, unit="replies/s", note=note + f"; {lost} requests unanswered"),
        Row(group="fleet", case=f"{n_gateways} gateways: round trip p50", count=len(rtts),
            rate=_pct(rtts, 0.5), unit="ms"),
        Row(group="fleet", case=f"{n_gateways} gateways: round trip p99", count=len(rtts),
            rate=_pct(rtts, 0.99), unit="ms"),
    ]  # fmt: skip
