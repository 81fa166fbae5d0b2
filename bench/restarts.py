"""Broker crashes, many, with services and DRC traffic in flight: does the gateway hold on to anything?

``dji-gateway run --simulate`` runs as its own process against a mosquitto with persistence. Each cycle the
cloud enters DRC on the main broker, drives the simulated gimbal with 20 Hz sticks and 4 Hz heartbeats while
sending ``camera_photo_take`` services at ~20/s, then the broker is killed (SIGKILL) and restarted. Once the
gateway is back, its resident memory, thread count and open file descriptors are read from /proc.
At the end every unanswered request is re-sent (the reference cloud's rule) until all are answered.

Figures: RSS after the first cycle and after the last, the slope (least squares over the second half of the
cycles, KB per crash: the first ones fill the reply cache (`dispatcher.reply_cache_seconds`, 120 s since
2026-11-26, was 30 s; at most 10,000 entries) and the allocator's arenas, which then stay flat), threads
and fds first → last, requests unanswered at the end (must be 0).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
import uuid
from collections import Counter
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion

from bench.run import ROOT, Config, Row
from gateway.cli.run import SIM_GIMBAL_PAYLOAD_INDEX
from gateway.local_broker import LocalBroker
from gateway.mqtt import close_client

GW = "GW-RESTARTS-1"


def _proc_status(pid: int) -> dict[str, float]:
    out: dict[str, float] = {"fds": float(len(os.listdir(f"/proc/{pid}/fd")))}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            out["rss_kb"] = float(line.split()[1])
        elif line.startswith("Threads:"):
            out["threads"] = float(line.split()[1])
    return out


def _by_code(codes: Counter[int]) -> str:
    """``: 3×327006, 1×319031`` (empty when every request succeeded): what went wrong, not just how often."""
    return (": " + ", ".join(f"{n}×{code}" for code, n in codes.most_common())) if codes else ""


def _slope(ys: list[float]) -> float:
    n = len(ys)
    if n < 2:
        return float("nan")
    mx, my = (n - 1) / 2, sum(ys) / n
    den = sum((x - mx) ** 2 for x in range(n))
    return sum((x - mx) * (y - my) for x, y in enumerate(ys)) / den


class _Cloud:
    """Persistent session, QoS 1, like a production cloud consumer; answers need_reply events."""

    def __init__(self, port: int) -> None:
        self.replies: dict[str, int] = {}
        self.statuses = 0
        self._lock = threading.Lock()
        self.client = paho.Client(
            CallbackAPIVersion.VERSION2, client_id=f"restarts-{uuid.uuid4().hex[:6]}", clean_session=False
        )
        self.client.reconnect_delay_set(0.1, 0.5)
        self.client.max_inflight_messages_set(1000)
        self.client.on_connect = lambda c, u, f, rc, p: c.subscribe(
            [(f"thing/product/{GW}/#", 1), (f"sys/product/{GW}/status", 1)]
        )
        self.client.on_message = self._on_message
        self.client.connect("127.0.0.1", port)
        self.client.loop_start()

    def _on_message(self, client: Any, userdata: Any, msg: paho.MQTTMessage) -> None:
        if msg.topic.endswith("/drc/up") or msg.topic.endswith("/osd") or msg.topic.endswith("/state"):
            return
        body = json.loads(msg.payload)
        with self._lock:
            if msg.topic.endswith("/services_reply"):
                self.replies[body["tid"]] = int(body["data"].get("result", -1))
            elif msg.topic.endswith("/status"):
                self.statuses += 1
        if msg.topic.endswith("/events") and body.get("need_reply") == 1:
            reply = {"tid": body["tid"], "bid": body["bid"], "timestamp": 0, "method": body["method"],
                     "data": {"result": 0}}  # fmt: skip
            client.publish(msg.topic + "_reply", json.dumps(reply), qos=1)

    def request(self, tid: str, method: str, data: dict[str, Any]) -> None:
        body = {"tid": tid, "bid": "b", "timestamp": 0, "method": method, "data": data}
        self.client.publish(f"thing/product/{GW}/services", json.dumps(body), qos=1)

    def call(self, method: str, data: dict[str, Any], timeout: float = 30.0) -> int:
        tid = uuid.uuid4().hex
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.request(tid, method, data)
            until = time.monotonic() + 3.0
            while time.monotonic() < until:
                with self._lock:
                    if tid in self.replies:
                        return self.replies[tid]
                time.sleep(0.02)
        raise RuntimeError(f"{method}: no reply within {timeout:.0f} s")

    def drive(self, seconds: float, seq: int) -> int:
        down = f"thing/product/{GW}/drc/down"
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            seq += 1
            stick = {"method": "drone_control", "data": {"seq": seq, "w": 10.0}}
            self.client.publish(down, json.dumps(stick))
            if seq % 5 == 0:
                beat = {"method": "heart_beat", "data": {"seq": seq, "timestamp": seq}}
                self.client.publish(down, json.dumps(beat))
            time.sleep(0.05)
        return seq

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
        close_client(self.client)


def run(cfg: Config) -> list[Row]:
    kills = 2 if cfg.quick else 30
    broker = LocalBroker(persistence=True).start()
    gw = subprocess.Popen(
        [sys.executable, "-m", "gateway.cli", "run", "--simulate", "--broker", broker.url, "--gateway-sn", GW,
         "--no-metrics", "--log-level", "ERROR"],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    cloud = _Cloud(broker.port)
    sent: list[str] = []
    samples: list[dict[str, float]] = []
    stop_photos = threading.Event()
    try:
        deadline = time.monotonic() + 30
        while cloud.statuses == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        time.sleep(1.0)  # the simulated devices come online
        pi = SIM_GIMBAL_PAYLOAD_INDEX
        if cloud.call("payload_authority_grab", {"payload_index": pi}) != 0:
            raise RuntimeError("payload_authority_grab refused")
        if cloud.call("flight_authority_grab", {}) != 0:  # DRC drives every movable device
            raise RuntimeError("flight_authority_grab refused")
        time.sleep(1.2)  # the broker's autosave has the sessions on disk before the first crash
        main = {"address": f"127.0.0.1:{broker.port}", "client_id": "x", "username": "", "password": "",
                "expire_time": 4102444800, "enable_tls": False}  # fmt: skip
        enter = {"mqtt_broker": main, "osd_frequency": 5, "hsi_frequency": 1}

        def photos() -> None:
            while not stop_photos.wait(0.05):
                tid = f"photo-{len(sent)}"
                sent.append(tid)
                cloud.request(tid, "camera_photo_take", {"payload_index": pi})

        seq = 0
        for k in range(kills):
            if cloud.call("drc_mode_enter", enter) != 0:
                raise RuntimeError("drc_mode_enter refused")
            stop_photos.clear()
            t = threading.Thread(target=photos, daemon=True)
            t.start()
            seq = cloud.drive(2.0, seq)
            broker.stop(kill=True)
            stop_photos.set()
            t.join()
            time.sleep(0.5)
            before = cloud.statuses
            broker.start()
            deadline = time.monotonic() + 30
            while cloud.statuses == before and time.monotonic() < deadline:  # the gateway republished
                time.sleep(0.05)
            time.sleep(0.5)
            samples.append(_proc_status(gw.pid))
            print(f"  .. restarts: crash {k + 1}/{kills}: {samples[-1]}", flush=True)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            with cloud._lock:
                missing = [tid for tid in sent if tid not in cloud.replies]
            if not missing:
                break
            for tid in missing:
                cloud.request(tid, "camera_photo_take", {"payload_index": SIM_GIMBAL_PAYLOAD_INDEX})
            time.sleep(3.0)
        with cloud._lock:
            unanswered = sum(1 for tid in sent if tid not in cloud.replies)
            codes = Counter(cloud.replies[tid] for tid in sent if cloud.replies[tid] != 0)
            failed = sum(codes.values())
    finally:
        stop_photos.set()
        cloud.close()
        gw.terminate()
        try:
            gw.wait(15)
        except subprocess.TimeoutExpired:
            gw.kill()
            gw.wait(5)
        broker.stop()
    if unanswered:
        raise AssertionError(f"{unanswered} of {len(sent)} requests never answered")
    rss = [s["rss_kb"] / 1024 for s in samples]
    slope_kb = _slope([s["rss_kb"] for s in samples[len(samples) // 2 :]])
    first, last = samples[0], samples[-1]
    note = (f"{kills} SIGKILLs, {len(sent)} services "
            f"({failed} non-zero results{_by_code(codes)}), DRC on the main broker; "
            f"threads {first['threads']:.0f} → {last['threads']:.0f}, "
            f"fds {first['fds']:.0f} → {last['fds']:.0f}")  # fmt: skip
    return [
        Row(group="restarts", case="requests unanswered at the end (must be 0)", count=len(sent),
            rate=float(unanswered), unit="missed", note=note),
        Row(group="restarts", case="gateway RSS after the first crash", count=kills, rate=rss[0], unit="MB"),
        Row(group="restarts", case="gateway RSS after the last crash", count=kills, rate=rss[-1], unit="MB",
            note=f"max {max(rss):.1f} MB"),
        Row(group="restarts", case="RSS slope, second half of the crashes (KB per crash)", count=kills,
            rate=slope_kb, unit="KB"),
    ]  # fmt: skip
