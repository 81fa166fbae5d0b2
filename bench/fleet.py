"""Many gateways on one broker, the cloud reading their replies through a shared subscription.

G gateways (quick: 4, full: 100) on one private mosquitto, two ways: G instances in this process (each
with its own event loop and MQTT connection), and G ``dji-gateway run`` processes (each its own
interpreter, as a fleet of edge computers would be; their memory is summed from /proc). The cloud side
is one publisher and two consumers sharing ``$share/cloud/thing/product/+/services_reply`` (MQTT shared
subscription: each reply goes to one of them). The publisher keeps up to 64 requests in flight,
round-robin over the gateways, and each request's round trip is timed by whichever consumer gets its
reply. The requests are answered by the gateways' dispatchers (``flight_authority_grab`` on gateways
without an aircraft: validated, routed, answered 399001), so the figure is the gateways' and the
broker's, not a device's.
"""

from __future__ import annotations

import contextlib
import json
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion, MQTTProtocolVersion

from bench.run import ROOT, Config, Row
from gateway.local_broker import LocalBroker
from gateway.mqtt import close_client
from gateway.settings import load_settings
from tests.support import GatewayThread


def _pct(samples: list[float], q: float) -> float:
    s = sorted(samples)
    return s[min(len(s) - 1, int(q * len(s)))] if s else float("nan")


def _names(n: int) -> list[str]:
    return [f"GW-FLEET-{g:03d}" for g in range(n)]


@contextlib.contextmanager
def _in_process(broker: LocalBroker, n: int) -> Iterator[str]:
    gateways = []
    try:
        for sn in _names(n):
            settings = load_settings(None, gateway_sn=sn, broker={"url": broker.url},
                                     metrics={"enabled": False}, log_level="WARNING")  # fmt: skip
            gateways.append(GatewayThread(settings).start())
        yield f"{n} gateways in one process"
    finally:
        for gw in gateways:
            gw.stop()


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


@contextlib.contextmanager
def _processes(broker: LocalBroker, n: int) -> Iterator[str]:
    """n gateway processes; ready when every one has announced its topology on the broker."""
    seen: set[str] = set()
    watcher = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"fleet-watch-{uuid.uuid4().hex[:6]}")
    watcher.on_message = lambda c, u, m: seen.add(m.topic.split("/")[2])
    watcher.connect("127.0.0.1", broker.port)
    watcher.loop_start()
    watcher.subscribe("sys/product/+/status", qos=1)
    procs: list[subprocess.Popen[bytes]] = []
    try:
        for sn in _names(n):
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "gateway.cli", "run", "--broker", broker.url, "--gateway-sn", sn,
                 "--no-metrics", "--log-level", "WARNING"],
                cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            ))  # fmt: skip
        deadline = time.monotonic() + 120 + n
        while len(seen) < n and time.monotonic() < deadline:
            time.sleep(0.2)
        if len(seen) < n:
            raise RuntimeError(f"only {len(seen)} of {n} gateway processes connected")
        rss = sum(_rss_mb(p.pid) for p in procs)
        yield f"{n} gateway processes ({rss:.0f} MB RSS together, {rss / n:.0f} MB each)"
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(20)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(5)
        watcher.disconnect()
        watcher.loop_stop()
        close_client(watcher)


def _measure(broker: LocalBroker, n_gateways: int, n_requests: int, window: int) -> tuple[list[float], float]:
    sent: dict[str, float] = {}
    rtts: list[float] = []
    lock = threading.Lock()
    slots = threading.Semaphore(window)
    done = threading.Event()

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
        c = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"cloud-consumer-{i}-{uuid.uuid4().hex[:4]}",
                        protocol=MQTTProtocolVersion.MQTTv5)  # fmt: skip
        c.on_message = on_reply
        c.connect("127.0.0.1", broker.port)
        c.loop_start()
        c.subscribe("$share/cloud/thing/product/+/services_reply", qos=1)
        consumers.append(c)
    publisher = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"cloud-publisher-{uuid.uuid4().hex[:4]}")
    publisher.max_inflight_messages_set(window)
    publisher.connect("127.0.0.1", broker.port)
    publisher.loop_start()
    time.sleep(0.5)
    names = _names(n_gateways)
    t_start = time.perf_counter()
    for i in range(n_requests):
        if not slots.acquire(timeout=10):
            break  # replies stopped coming: report what was answered
        tid = uuid.uuid4().hex
        request = {"tid": tid, "bid": "b", "timestamp": 0, "method": "flight_authority_grab", "data": {}}
        body = json.dumps(request)
        with lock:
            sent[tid] = time.perf_counter()
        publisher.publish(f"thing/product/{names[i % n_gateways]}/services", body, qos=1)
    done.wait(60)
    elapsed = time.perf_counter() - t_start
    for c in (*consumers, publisher):
        c.disconnect()
        c.loop_stop()
        close_client(c)
    return rtts, elapsed


def run(cfg: Config) -> list[Row]:
    n_gateways = 4 if cfg.quick else 100  # quick: a smoke test inside make test (CPU is its budget)
    n_requests = 400 if cfg.quick else 20_000
    window = 64
    rows: list[Row] = []
    for mode, start in (("instances", _in_process), ("processes", _processes)):
        limits = "max_inflight_messages 1000\nmax_queued_messages 100000"
        with LocalBroker(extra_config=limits) as broker, start(broker, n_gateways) as what:
            rtts, elapsed = _measure(broker, n_gateways, n_requests, window)
        lost = n_requests - len(rtts)
        note = f"{what}, 2 consumers on a shared subscription, {window} in flight; {lost} requests unanswered"
        rows += [
            Row(group="fleet", case=f"{n_gateways} gateway {mode}: aggregate replies/s", count=n_requests,
                rate=len(rtts) / elapsed, unit="replies/s", note=note),
            Row(group="fleet", case=f"{n_gateways} gateway {mode}: round trip p50", count=len(rtts),
                rate=_pct(rtts, 0.5), unit="ms"),
            Row(group="fleet", case=f"{n_gateways} gateway {mode}: round trip p99", count=len(rtts),
                rate=_pct(rtts, 0.99), unit="ms"),
        ]  # fmt: skip
        if lost:
            raise AssertionError(f"{mode}: {lost} of {n_requests} requests unanswered")
    return rows
