"""A bounded soak of live flight control: DRC at 20 Hz sticks and 1 Hz heartbeats against the gateway
with a simulated gimbal under ``drc_drive``, for 5 minutes (quick: 4 s; ``DJIGW_SOAK_SECONDS`` sets
another length, e.g. 3600 for an hour: the whole ``make bench`` stays under 15 minutes with the default).

Counts every heartbeat echo that did not come back (must be 0), the failsafe stops (must be 0: sticks and
heartbeats never stop), and the gateway's resident memory at the start and the end (flat: no growth
beyond a small allowance)."""

from __future__ import annotations

import json
import os
import threading
import time
import uuid
from collections import Counter
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion

from adapters.rsdk.sim import GimbalCanSim
from bench.run import Config, Row
from gateway.local_broker import LocalBroker
from gateway.settings import load_settings
from tests.support import GatewayThread, answer_event

GW = "GW-SOAK-1"


def _rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def run(cfg: Config) -> list[Row]:
    seconds = 4.0 if cfg.quick else float(os.environ.get("DJIGW_SOAK_SECONDS", "300"))
    with LocalBroker() as broker:
        channel = f"soak-{uuid.uuid4().hex[:6]}"
        sim = GimbalCanSim(interface="virtual", channel=channel).start()
        device = {
            "type": "rsdk",
            "sn": "RSDK-SOAK",
            "interface": "virtual",
            "channel": channel,
            "drc_drive": True,
        }
        settings = load_settings(None, gateway_sn=GW, broker={"url": broker.url}, devices=[device],
                                 metrics={"enabled": False})  # fmt: skip
        gw = GatewayThread(settings).start()
        echoes: set[int] = set()
        replies = threading.Event()
        events: list[str] = []
        cloud = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"soak-{uuid.uuid4().hex[:6]}")

        def on_message(c: Any, u: Any, msg: paho.MQTTMessage) -> None:
            body = json.loads(msg.payload)
            if msg.topic.endswith("/drc/up") and body.get("method") == "heart_beat":
                echoes.add(int(body["data"]["seq"]))
            elif msg.topic.endswith("/services_reply"):
                replies.set()
            elif answer_event(c, msg.topic, body):  # as a real cloud does
                events.append(body["method"])

        cloud.on_message = on_message
        cloud.connect("127.0.0.1", broker.port)
        cloud.loop_start()
        cloud.subscribe([(f"thing/product/{GW}/drc/up", 0), (f"thing/product/{GW}/services_reply", 1),
                         (f"thing/product/{GW}/events", 1)])  # fmt: skip
        time.sleep(0.5)
        deadline = time.monotonic() + 10
        while not gw.app.devices.by_sn("RSDK-SOAK").online and time.monotonic() < deadline:
            time.sleep(0.05)

        def service(method: str, data: dict[str, Any]) -> None:
            replies.clear()
            body = {"tid": uuid.uuid4().hex, "bid": "b", "timestamp": 0, "method": method, "data": data}
            cloud.publish(f"thing/product/{GW}/services", json.dumps(body), qos=1)
            if not replies.wait(5):
                raise RuntimeError(f"{method}: no reply")

        service("payload_authority_grab", {"payload_index": "20-0-0"})
        same = {"address": f"127.0.0.1:{broker.port}", "client_id": "soak", "username": "", "password": "",
                "expire_time": 4102444800, "enable_tls": False}  # fmt: skip
        service("drc_mode_enter", {"mqtt_broker": same, "osd_frequency": 10, "hsi_frequency": 1})
        down = f"thing/product/{GW}/drc/down"
        rss0 = _rss_mb()
        t0 = time.monotonic()
        beats = sticks = 0
        next_beat = t0
        while time.monotonic() - t0 < seconds:
            now = time.monotonic()
            if now >= next_beat:
                beats += 1
                cloud.publish(
                    down, json.dumps({"method": "heart_beat", "data": {"seq": beats, "timestamp": beats}})
                )
                next_beat += 1.0
            sticks += 1
            w = 20.0 if (sticks // 40) % 2 else -20.0
            cloud.publish(down, json.dumps({"method": "drone_control", "data": {"seq": sticks, "w": w}}))
            time.sleep(0.05)
        # read the failsafe counter while sticks and heartbeats still flow: once they stop, the failsafe
        # rightly fires, and that one must not be counted against the soak
        failsafes = gw.app.metrics.count("drc_failsafe_stops_total")
        time.sleep(1.0)
        rss1 = _rss_mb()
        missed = beats - len(echoes & set(range(1, beats + 1)))
        cloud.disconnect()
        cloud.loop_stop()
        gw.stop()
        sim.stop()
    if missed:
        raise AssertionError(f"{missed} of {beats} heartbeat echoes missing")
    kinds = ", ".join(f"{n}× {m}" for m, n in Counter(events).most_common()) or "none"
    note = f"{seconds:.0f} s, {sticks} sticks at 20 Hz, {beats} heartbeats at 1 Hz; events answered: {kinds}"
    return [
        Row(group="soak", case="heartbeat echoes missed (must be 0)", count=beats, rate=float(missed),
            unit="missed", note=note),
        Row(group="soak", case="failsafe stops (must be 0)", count=sticks, rate=failsafes, unit="stops"),
        Row(group="soak", case="RSS growth (process, MB)", count=sticks, rate=rss1 - rss0, unit="MB",
            note=f"{rss0:.0f} MB → {rss1:.0f} MB"),
    ]  # fmt: skip
