"""Cellular links: the gateway in a network namespace of its own, joined to the broker's (the host's) by
a veth pair; an LTE-like profile (80 ms RTT ± 20 ms, 1 % loss) and partitions (the veth taken down).

The impairment comes from ``tc netem`` where the kernel has it (``method = "netem"``), else from the
userspace relay ``tests/linkemu.py`` between the veth and the broker (``method = "relay"``; what differs
is said in docs/reliability.md); partitions are always real (``ip link set … down``: TCP retransmits
into the void, nothing resets). The gateway runs in this process, its thread moved into the namespace
(``tests.netlab.enter_netns``), with a simulated gimbal on a virtual CAN bus; the cloud and mosquitto
stay on the host.

Figures: services success rate and p99 (cloud publish → reply) under the profile; for a partition with
osd every 0.5 s, services every 0.5 s and a DRC session (20 Hz sticks, 5 Hz heartbeats) going:
resume after the heal (first fresh osd, first service answered), osd produced during the partition
and delivered after it (in order; dropped counted), and the DRC failsafe (motion zero within the
heartbeat timeout, never resumed by itself while sticks keep coming after the heal).
Needs root and iproute2; skipped with the reason otherwise. Also used by ``tests/test_cellular.py``.
"""

from __future__ import annotations

import itertools
import json
import threading
import time
import uuid
from dataclasses import dataclass, field
from typing import Any

import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion

from adapters.rsdk.sim import GimbalCanSim
from bench.run import Config, Row
from gateway.local_broker import LocalBroker, free_port
from gateway.mqtt import close_client
from tests.netlab import LinkEmulator, VethLink, enter_netns, netem_problem, netns_problem
from tests.support import DrcSticks, GatewayThread, answer_event, gateway_settings

GW = "GW-CELL-1"
PI = "20-0-0"
LTE = {"delay_ms": 40.0, "jitter_ms": 10.0, "loss": 0.01}  # each direction: 80 ms RTT ± 20 ms, 1 % loss


class _Cloud:
    """The cloud on the host: persistent session, QoS 1; records osd, replies and events."""

    def __init__(self, port: int) -> None:
        self.osd: list[tuple[float, str, int]] = []  # (received, topic, envelope timestamp ms)
        self.replies: dict[str, tuple[float, int]] = {}
        self.events: list[dict[str, Any]] = []
        self.drc_up: list[float] = []
        self._lock = threading.Lock()
        self.client = paho.Client(
            CallbackAPIVersion.VERSION2, client_id=f"cell-{uuid.uuid4().hex[:6]}", clean_session=False
        )
        self.client.reconnect_delay_set(0.05, 0.2)
        self.client.max_inflight_messages_set(1000)
        ready = threading.Event()
        self.client.on_connect = lambda c, u, f, rc, p: c.subscribe(
            [("thing/product/+/osd", 1), (f"thing/product/{GW}/services_reply", 1),
             (f"thing/product/{GW}/events", 1), (f"thing/product/{GW}/drc/up", 0)]
        )  # fmt: skip
        self.client.on_subscribe = lambda *a: ready.set()
        self.client.on_message = self._on_message
        self.client.connect("127.0.0.1", port)
        self.client.loop_start()
        if not ready.wait(10):
            raise RuntimeError("cloud could not subscribe")

    def _on_message(self, client: Any, userdata: Any, msg: paho.MQTTMessage) -> None:
        now = time.monotonic()
        if msg.topic.endswith("/drc/up"):
            with self._lock:
                self.drc_up.append(now)
            return
        body = json.loads(msg.payload)
        with self._lock:
            if msg.topic.endswith("/osd"):
                self.osd.append((now, msg.topic, int(body["timestamp"])))
            elif msg.topic.endswith("/services_reply"):
                self.replies.setdefault(body["tid"], (now, int(body["data"].get("result", -1))))
            elif msg.topic.endswith("/events"):
                self.events.append(body)
        answer_event(client, msg.topic, body)

    def request(self, tid: str, method: str, data: dict[str, Any]) -> float:
        body = {"tid": tid, "bid": "b", "timestamp": 0, "method": method, "data": data}
        at = time.monotonic()
        self.client.publish(f"thing/product/{GW}/services", json.dumps(body), qos=1)
        return at

    def call(self, method: str, data: dict[str, Any], timeout: float = 15.0) -> int:
        tid = uuid.uuid4().hex
        self.request(tid, method, data)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with self._lock:
                if tid in self.replies:
                    return self.replies[tid][1]
            time.sleep(0.01)
        raise RuntimeError(f"{method}: no reply within {timeout:g} s")

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
        close_client(self.client)


class Rig:
    """Namespace + veth + mosquitto on the host + (relay) + gimbal simulator + gateway in the namespace
    + cloud. ``method``: "netem" or "relay"; ``profile``: the impairment (None: a clean link)."""

    def __init__(self, method: str, profile: dict[str, float] | None = None, **gateway: Any) -> None:
        self.method, self.profile, self._gateway = method, profile, gateway

    def __enter__(self) -> Rig:
        self.link = VethLink().__enter__()
        self.emulator: Any = None
        self.sim: Any = None
        self.gw: Any = None
        self.cloud: Any = None
        try:
            port = free_port()
            listeners = f"listener {port} 127.0.0.1\nlistener {port} {self.link.host_ip}"
            self.broker = LocalBroker(port, listener_lines=listeners, persistence=True).start()
            self.gw_host, self.gw_port = self.link.host_ip, port
            if self.profile is not None and self.method == "netem":
                self.link.netem(**self.profile)
            elif self.profile is not None:
                self.gw_port = free_port(self.link.host_ip)
                self.emulator = LinkEmulator(
                    (self.gw_host, self.gw_port), ("127.0.0.1", port), **self.profile
                )
            channel = f"djigw-cell-{uuid.uuid4().hex[:8]}"
            self.sim = GimbalCanSim(interface="virtual", channel=channel).start()
            device = {"type": "rsdk", "sn": "RSDK-CELL-1", "interface": "virtual", "channel": channel,
                      "drc_drive": True}  # fmt: skip
            doc = {"gateway_sn": GW, "osd_period": 0.5,
                   "broker": {"url": f"mqtt://{self.gw_host}:{self.gw_port}", "reconnect_min": 0.5,
                              "reconnect_max": 30.0}}  # fmt: skip
            for key, value in self._gateway.items():
                doc[key] = {**doc.get(key, {}), **value} if isinstance(value, dict) else value
            settings = gateway_settings(port, [device], **doc)
            self.cloud = _Cloud(port)
            self.gw = NetnsGateway(settings, self.link.ns).start()
            deadline = time.monotonic() + 15
            while not self.gw.app.devices.by_sn("RSDK-CELL-1").online and time.monotonic() < deadline:
                time.sleep(0.05)
        except BaseException:
            self.__exit__()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        for part in (self.gw, self.cloud, self.sim, self.emulator):
            if part is not None:
                try:
                    part.stop() if part is not self.cloud else part.close()
                except Exception as err:
                    print(f"  .. cleanup: {type(part).__name__}: {err}", flush=True)
        if getattr(self, "broker", None) is not None:
            self.broker.stop()
        self.link.__exit__()

    @property
    def main_broker(self) -> dict[str, Any]:
        return {"address": f"{self.gw_host}:{self.gw_port}", "client_id": "cell-drc", "username": "",
                "password": "", "expire_time": 4102444800, "enable_tls": False}  # fmt: skip


class NetnsGateway(GatewayThread):
    """The real gateway on a thread moved into the namespace (its paho and probe threads follow)."""

    def __init__(self, settings: Any, ns: str) -> None:
        super().__init__(settings)
        self.ns = ns

    def _main(self) -> None:
        enter_netns(self.ns)
        super()._main()


def _p(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, int(q * len(s)))]


@dataclass
class Services:
    sent: int
    ok: int
    p50_ms: float
    p99_ms: float
    max_ms: float


def measure_services(rig: Rig, n: int, rate: float = 5.0) -> Services:
    """``n`` services (``x_rsdk_version_get``: a device round trip) at ``rate``/s, each its own tid."""
    if rig.cloud.call("payload_authority_grab", {"payload_index": PI}) != 0:
        raise RuntimeError("payload_authority_grab refused")
    sent: dict[str, float] = {}
    for i in range(n):
        tid = f"svc-{i}-{uuid.uuid4().hex[:6]}"
        sent[tid] = rig.cloud.request(tid, "x_rsdk_version_get", {"payload_index": PI})
        time.sleep(1.0 / rate)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        with rig.cloud._lock:
            if all(t in rig.cloud.replies for t in sent):
                break
        time.sleep(0.05)
    with rig.cloud._lock:
        got = {t: rig.cloud.replies[t] for t in sent if t in rig.cloud.replies}
    rtts = [(got[t][0] - at) * 1000 for t, at in sent.items() if t in got]
    ok = sum(1 for t in got if got[t][1] == 0)
    return Services(len(sent), ok, _p(rtts, 0.5), _p(rtts, 0.99), max(rtts) if rtts else float("nan"))


@dataclass
class Partition:
    seconds: float
    resume_osd: float  # heal → first osd produced after the heal, received (s)
    resume_services: float  # heal → first reply to a request sent after the heal (s)
    reconnected: float  # heal → the gateway connected again (s)
    first_reply: float  # heal → the first reply of any request (those queued during it included) (s)
    osd_during: int  # osd produced during the partition and delivered after it
    osd_out_of_order: int
    osd_dropped: int  # by the offline buffer (count or age bound)
    osd_lost_at_onset: int  # gaps in the osd sequence around the partition (not delivered at all)
    osd_duplicates: int  # the same osd delivered twice (re-buffered after the connection was given up)
    requests_during: int
    requests_during_answered: int
    failsafe_after: float  # partition start → gimbal at zero speed (s)
    moved_after_heal: bool  # the gimbal moved again by itself after the heal (must be False)
    drc_events: list[int] = field(default_factory=list)  # drc_status_notify results
    stalls: int = 0


def measure_partition(rig: Rig, seconds: float) -> Partition:
    cloud, sim, app = rig.cloud, rig.sim, rig.gw.app
    if cloud.call("payload_authority_grab", {"payload_index": PI}) != 0:
        raise RuntimeError("payload_authority_grab refused")
    enter = {"mqtt_broker": rig.main_broker, "osd_frequency": 5, "hsi_frequency": 1}
    if cloud.call("drc_mode_enter", enter) != 0:
        raise RuntimeError("drc_mode_enter refused")
    drive = DrcSticks(cloud.client, GW, yaw_rate=20.0)
    requests: dict[str, float] = {}
    stop_requests = threading.Event()

    def ask() -> None:
        i = 0
        while not stop_requests.wait(0.5):
            tid = f"p-{i}"
            i += 1
            requests[tid] = cloud.request(tid, "x_rsdk_version_get", {"payload_index": PI})

    asker = threading.Thread(target=ask, daemon=True)
    try:
        deadline = time.monotonic() + 10
        while sim.model.yaw.speed != 20.0 and time.monotonic() < deadline:
            time.sleep(0.02)
        if sim.model.yaw.speed != 20.0:
            raise RuntimeError("the gimbal is not driven over DRC")
        asker.start()
        time.sleep(2.0)
        dropped0 = app.metrics.count("telemetry_dropped_total")
        stalls0 = app.metrics.count("mqtt_stalls_total", link="main")
        start_wall = time.time() * 1000
        start = time.monotonic()
        rig.link.down()
        failsafe_at: float | None = None
        while time.monotonic() - start < seconds:
            if failsafe_at is None and sim.model.yaw.speed == 0.0:
                failsafe_at = time.monotonic() - start
            time.sleep(0.01)
        heal_wall = time.time() * 1000
        rig.link.up()
        heal = time.monotonic()
        moved = False
        resume_osd = resume_services = reconnected = first_reply = float("nan")
        deadline = heal + 30
        while time.monotonic() < deadline and (
            resume_osd != resume_osd or resume_services != resume_services
        ):
            moved = moved or sim.model.yaw.speed != 0.0
            if reconnected != reconnected and app.bridge.connected:
                reconnected = time.monotonic() - heal
            with cloud._lock:
                replies = [at for at, _ in cloud.replies.values() if at >= heal]
            if replies and first_reply != first_reply:
                first_reply = min(replies) - heal
            with cloud._lock:
                fresh = [at for at, _, ts in cloud.osd if ts >= heal_wall]
                answered = [
                    cloud.replies[t][0] for t, at in requests.items() if at >= heal and t in cloud.replies
                ]
            if fresh and resume_osd != resume_osd:
                resume_osd = min(fresh) - heal
            if answered and resume_services != resume_services:
                resume_services = min(answered) - heal
            time.sleep(0.01)
        watch_until = time.monotonic() + 3.0  # sticks keep coming: the gimbal must stay still
        while time.monotonic() < watch_until:
            moved = moved or sim.model.yaw.speed != 0.0
            time.sleep(0.01)
        stop_requests.set()
        asker.join(2)
        time.sleep(1.0)
        with cloud._lock:
            osd = list(cloud.osd)
            during_req = [t for t, at in requests.items() if start <= at < heal]
            during_ans = sum(1 for t in during_req if t in cloud.replies)
            events = [e["data"]["result"] for e in cloud.events if e.get("method") == "drc_status_notify"]
        # osd produced during the partition, by envelope time, per topic, in arrival order
        during = [(topic, ts) for _, topic, ts in osd if start_wall <= ts < heal_wall]
        out_of_order = 0
        last: dict[str, int] = {}
        for _, topic, ts in osd:
            if ts < last.get(topic, 0):
                out_of_order += 1
            last[topic] = ts
        # what left before the stall was noticed and died with the old connection: the gap between the
        # last osd delivered from before the partition and the first delivered from during it
        period_ms = 500
        per_topic: dict[str, list[int]] = {}
        for _, topic, ts in osd:
            per_topic.setdefault(topic, []).append(ts)
        lost = 0
        for stamps in per_topic.values():
            stamps = sorted(set(stamps))
            for a, b in itertools.pairwise(stamps):
                if b - a > 1.5 * period_ms and a < heal_wall:
                    lost += round((b - a) / period_ms) - 1
        return Partition(
            seconds=seconds,
            resume_osd=resume_osd,
            resume_services=resume_services,
            reconnected=reconnected,
            first_reply=first_reply,
            osd_during=len(during),
            osd_out_of_order=out_of_order,
            osd_dropped=int(app.metrics.count("telemetry_dropped_total") - dropped0),
            osd_lost_at_onset=lost,
            osd_duplicates=len(osd) - len({(topic, ts) for _, topic, ts in osd}),
            requests_during=len(during_req),
            requests_during_answered=during_ans,
            failsafe_after=failsafe_at if failsafe_at is not None else float("nan"),
            moved_after_heal=moved,
            drc_events=events,
            stalls=int(app.metrics.count("mqtt_stalls_total", link="main") - stalls0),
        )
    finally:
        stop_requests.set()
        drive.close()


def method() -> str | None:
    """ "netem" or "relay", or None (with the reason printed) when namespaces cannot be made here."""
    problem = netns_problem()
    if problem is not None:
        print(f"  .. partitions: skipped: {problem}", flush=True)
        return None
    why = netem_problem()
    if why is not None:
        print(f"  .. partitions: no netem ({why}); impairing with the userspace relay", flush=True)
        return "relay"
    return "netem"


def run(cfg: Config) -> list[Row]:
    how = method()
    if how is None:
        return [
            Row(group="cellular", case="skipped: no network namespaces here", count=0, rate=0.0, unit="-")
        ]
    rows: list[Row] = []
    n = 15 if cfg.quick else 300
    with Rig(how, LTE) as rig:
        s = measure_services(rig, n)
    share = 100.0 * s.ok / s.sent
    rows += [
        Row(group="cellular", case=f"LTE ({how}): services answered", count=s.sent, rate=share, unit="%",
            note=f"p50 {s.p50_ms:.0f} ms, p99 {s.p99_ms:.0f} ms, max {s.max_ms:.0f} ms"),
        Row(group="cellular", case=f"LTE ({how}): services p99", count=s.sent, rate=s.p99_ms, unit="ms"),
    ]  # fmt: skip
    for seconds in [5.0] if cfg.quick else [5.0, 30.0, 120.0]:
        with Rig(how, LTE) as rig:
            p = measure_partition(rig, seconds)
        note = (f"after the heal: reconnected {p.reconnected:.2f} s, fresh osd {p.resume_osd:.2f} s, first "
                f"reply {p.first_reply:.2f} s, first reply to a request sent after the heal "
                f"{p.resume_services:.2f} s (behind those queued during it); "
                f"{p.osd_during} osd from the partition delivered ({p.osd_out_of_order} out of order, "
                f"{p.osd_dropped} dropped by the buffer, {p.osd_lost_at_onset} missing, "
                f"{p.osd_duplicates} twice); "
                f"{p.requests_during_answered}/{p.requests_during} requests sent during it answered "
                f"after; DRC zero speed {p.failsafe_after:.2f} s into it, moved after the heal: "
                f"{p.moved_after_heal}, drc_status_notify {p.drc_events}")  # fmt: skip
        case = f"{seconds:g} s partition under LTE ({how}): resume after the heal (target <= 1 s)"
        rows.append(Row(group="cellular", case=case, count=1, rate=max(p.resume_osd, p.first_reply),
                        unit="s", note=note))  # fmt: skip
        if p.moved_after_heal or p.osd_out_of_order or p.requests_during_answered != p.requests_during:
            raise AssertionError(f"{seconds:g} s partition: {p}")
    return rows
