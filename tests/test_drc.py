"""Live flight control (DRC) through two real mosquittos: the cloud's broker and a DRC broker with
username/password, as ``drc_mode_enter`` names it. Devices under live control here: the simulated R SDK
gimbal (``drc_drive``); the aircraft's DRC tests are in test_drc_aircraft.py."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterator
from typing import Any

import paho.mqtt.client as paho
import pytest
from paho.mqtt.enums import CallbackAPIVersion

from adapters.rsdk.sim import GimbalCanSim
from gateway.local_broker import LocalBroker
from gateway.mqtt import close_client
from tests.support import BusSniffer, CloudClient, GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker

GW = "GW-TEST-1"
PI = "20-0-0"
DRC_USER, DRC_PASSWORD = "drc-operator", "s3cret-drc-token-9f2c"


class DrcClient:
    """The cloud side of the DRC link: publishes drc/down, collects drc/up."""

    def __init__(self, port: int, username: str, password: str) -> None:
        self.up: list[dict[str, Any]] = []
        self._cond = threading.Condition()
        self.client = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"drc-cloud-{uuid.uuid4().hex[:6]}")
        self.client.username_pw_set(username, password)
        self.client.on_message = self._on_message
        ready = threading.Event()
        self.client.on_subscribe = lambda *a: ready.set()
        self.client.connect("127.0.0.1", port)
        self.client.loop_start()
        self.client.subscribe(f"thing/product/{GW}/drc/up", qos=0)
        assert ready.wait(5)

    def _on_message(self, client: Any, userdata: Any, msg: paho.MQTTMessage) -> None:
        with self._cond:
            self.up.append(json.loads(msg.payload))
            self._cond.notify_all()

    def send(self, method: str, data: dict[str, Any], **beside: Any) -> None:
        body = json.dumps({"method": method, "data": data, **beside})
        self.client.publish(f"thing/product/{GW}/drc/down", body, qos=0)

    def wait(self, method: str, predicate: Any = lambda d: True, timeout: float = 5.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                for msg in self.up:
                    if msg.get("method") == method and predicate(msg["data"]):
                        return msg
                left = deadline - time.monotonic()
                if left <= 0:
                    raise AssertionError(f"no {method} on drc/up within {timeout}s")
                self._cond.wait(left)

    def count(self, method: str, predicate: Any = lambda d: True) -> int:
        with self._cond:
            return sum(1 for m in self.up if m.get("method") == method and predicate(m["data"]))

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
        close_client(self.client)


@pytest.fixture
def drc_broker() -> Iterator[LocalBroker]:
    b = LocalBroker(users={DRC_USER: DRC_PASSWORD}).start()
    try:
        yield b
    finally:
        b.stop()


@pytest.fixture
def rig(broker: LocalBroker, drc_broker: LocalBroker, can_channel: str) -> Iterator[dict[str, Any]]:
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    sniffer = BusSniffer(can_channel)
    device = {
        "type": "rsdk",
        "sn": "RSDK-DRC-1",
        "interface": "virtual",
        "channel": can_channel,
        "drc_drive": True,
    }
    settings = gateway_settings(broker.port, [device], drc={"heartbeat_timeout": 1.0, "idle_timeout": 30.0})
    cloud = CloudClient(broker.host, broker.port, GW)
    gw = GatewayThread(settings).start()
    try:
        cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == 1)
        assert cloud.service("payload_authority_grab", {"payload_index": PI})["data"]["result"] == 0
        yield {"sim": sim, "sniffer": sniffer, "cloud": cloud, "gw": gw, "drc_broker": drc_broker}
    finally:
        gw.stop()
        cloud.close()
        sniffer.close()
        sim.stop()


def _enter(cloud: CloudClient, drc_broker: LocalBroker, **over: Any) -> dict[str, Any]:
    broker = {
        "address": f"127.0.0.1:{drc_broker.port}",
        "client_id": f"drc-gw-{uuid.uuid4().hex[:6]}",
        "username": DRC_USER,
        "password": DRC_PASSWORD,
        "expire_time": int(time.time()) + 3600,
        "enable_tls": False,
        **over,
    }
    return cloud.service("drc_mode_enter", {"mqtt_broker": broker, "osd_frequency": 10, "hsi_frequency": 1})


def test_enter_sticks_heartbeats_seq_rules_and_exit(
    rig: dict[str, Any], caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.DEBUG)
    cloud, model, sniffer = rig["cloud"], rig["sim"].model, rig["sniffer"]
    reply = _enter(cloud, rig["drc_broker"])
    assert reply["data"]["result"] == 0, reply
    states = [
        e["data"]["drc_state"]
        for e in cloud.wait_for("events", lambda b: b["method"] == "drc_status_notify", count=2)
    ]
    assert states[:2] == [1, 2]
    cloud.wait_for(f"{GW}/osd", lambda b: b["data"].get("drc_state") == 2)

    drc = DrcClient(rig["drc_broker"].port, DRC_USER, DRC_PASSWORD)
    try:
        # heartbeat: echoed at once with the same seq and timestamp, whether ts or timestamp, inside or beside
        drc.send("heart_beat", {"seq": 1, "timestamp": 1670415891013})
        assert drc.wait("heart_beat")["data"] == {"seq": 1, "timestamp": 1670415891013}
        drc.send("heart_beat", {"ts": 1670415891999}, seq=2)
        assert drc.wait("heart_beat", lambda d: d.get("seq") == 2)["data"]["timestamp"] == 1670415891999

        # sticks: w (yaw rate) drives the gimbal's yaw speed; replies carry the seq
        drc.send("drone_control", {"seq": 1, "w": 30.0})
        assert drc.wait("drone_control", lambda d: d["output"]["seq"] == 1)["data"]["result"] == 0
        wait_until(lambda: model.yaw.speed == 30.0, 3, what="gimbal yaw speed 30")
        for seq in (5, 5, 5):  # clouds repeat each DRC message: the repeats are ignored
            drc.send("drone_control", {"seq": seq, "w": 40.0})
        drc.send("drone_control", {"seq": 3, "w": -90.0})  # older than 5: refused with 319033
        stale = drc.wait("drone_control", lambda d: d["result"] == 319033)
        assert stale["data"]["output"]["seq"] == 3
        assert drc.count("drone_control", lambda d: d["output"].get("seq") == 5) == 1
        wait_until(lambda: model.yaw.speed == 40.0, 3, what="seq 5 applied")
        last_stick = time.monotonic()  # (before the send: the timeout may fire before the wait below ends)
        drc.send("drone_control", {"seq": 0, "w": -20.0})  # seq 0 restarts the sequence
        wait_until(lambda: model.yaw.speed == -20.0, 3, what="restarted sequence accepted")

        # sticks stop: the set-point is zeroed within stick_timeout (0.5 s) plus a stream period
        wait_until(lambda: model.yaw.speed == 0.0, 3, what="zero speed after sticks stop")

        def zeros() -> list[float]:  # the sniffer hears the bus on its own thread: it may lag the gimbal
            return [
                t for t, (n, f) in zip(list(sniffer.times), list(sniffer.commands), strict=False)
                if t > last_stick and n == "speed_control" and f["yaw_speed"] == 0
            ]  # fmt: skip

        wait_until(lambda: bool(zeros()), 3, what="the zeroing speed_control heard on the bus")
        first_zero = zeros()[0]
        assert first_zero - last_stick < 0.5 + 0.04 + 0.35  # deadline + one period + scheduling margin

        # exit: motion already stopped, drc_state back to 0
        drc.send("heart_beat", {"seq": 3, "timestamp": 5})
        assert cloud.service("drc_mode_exit", {})["data"]["result"] == 0
        cloud.wait_for("events", lambda b: b["method"] == "drc_status_notify" and b["data"]["drc_state"] == 0)
    finally:
        drc.close()
    # the DRC password never reaches a log line
    assert DRC_PASSWORD not in caplog.text
    assert rig["gw"].app.metrics.count("drc_heartbeats_total") >= 2


def test_heartbeat_loss_stops_motion_and_emergency_stop_holds(rig: dict[str, Any]) -> None:
    cloud, model = rig["cloud"], rig["sim"].model
    assert _enter(cloud, rig["drc_broker"])["data"]["result"] == 0
    drc = DrcClient(rig["drc_broker"].port, DRC_USER, DRC_PASSWORD)
    try:
        stop = threading.Event()

        def sticks() -> None:  # a steady 20 Hz stick stream, but no heartbeats
            seq = 1
            while not stop.is_set():
                drc.send("drone_control", {"seq": seq, "w": 25.0})
                seq += 1
                time.sleep(0.05)

        t = threading.Thread(target=sticks, daemon=True)
        t.start()
        wait_until(lambda: model.yaw.speed == 25.0, 3, what="moving")
        # heartbeats are 1 s overdue (heartbeat_timeout in this rig): stop, and 514301 to the cloud
        cloud.wait_for(
            "events", lambda b: b["method"] == "drc_status_notify" and b["data"]["result"] == 514301
        )
        wait_until(lambda: model.yaw.speed == 0.0, 3, what="stopped without heartbeats")
        stop.set()
        t.join(2)
        # a heartbeat brings the sticks back
        drc.send("heart_beat", {"seq": 1, "timestamp": 1})
        drc.send("drone_control", {"seq": 1000, "w": 10.0})
        wait_until(lambda: model.yaw.speed == 10.0, 3, what="moving again after a heartbeat")

        # emergency stop: zero at once, and sticks are refused until the sequence restarts at 0
        drc.send("drone_emergency_stop", {})
        assert drc.wait("drone_emergency_stop")["data"]["result"] == 0
        wait_until(lambda: model.yaw.speed == 0.0, 3, what="emergency stop")
        drc.send("heart_beat", {"seq": 2, "timestamp": 2})
        drc.send("drone_control", {"seq": 1001, "w": 10.0})
        held = drc.wait("drone_control", lambda d: d["output"]["seq"] == 1001)
        assert held["data"]["result"] == 314000
        time.sleep(0.2)
        assert model.yaw.speed == 0.0
        drc.send("drone_control", {"seq": 0, "w": 12.0})
        wait_until(lambda: model.yaw.speed == 12.0, 3, what="released by seq 0")
    finally:
        drc.close()


def test_drc_broker_killed_stops_motion_and_ends_the_session(rig: dict[str, Any]) -> None:
    cloud, model, drc_broker = rig["cloud"], rig["sim"].model, rig["drc_broker"]
    assert _enter(cloud, drc_broker)["data"]["result"] == 0
    drc = DrcClient(drc_broker.port, DRC_USER, DRC_PASSWORD)
    drc.send("heart_beat", {"seq": 1, "timestamp": 1})
    drc.send("drone_control", {"seq": 1, "w": 15.0})
    wait_until(lambda: model.yaw.speed == 15.0, 3, what="moving")
    drc.client.loop_stop()
    close_client(drc.client)
    drc_broker.stop(kill=True)
    wait_until(lambda: model.yaw.speed == 0.0, 3, what="stopped when the DRC broker vanished")
    cloud.wait_for(
        "events",
        lambda b: b["method"] == "drc_status_notify" and b["data"] == {"result": 514303, "drc_state": 0},
    )


def test_main_broker_killed_does_not_disturb_a_dedicated_drc_link(
    private_broker: LocalBroker, drc_broker: LocalBroker, can_channel: str
) -> None:
    """The cloud's broker crashes while the operator flies over a dedicated DRC broker: the live link goes
    on (heartbeats echoed, sticks obeyed, no failsafe), and the gateway is back on the main broker after."""
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {"type": "rsdk", "sn": "RSDK-DRC-3", "interface": "virtual", "channel": can_channel,
              "drc_drive": True}  # fmt: skip
    settings = gateway_settings(private_broker.port, [device], drc={"heartbeat_timeout": 1.0})
    cloud = CloudClient(private_broker.host, private_broker.port, GW)
    gw = GatewayThread(settings).start()
    drc: DrcClient | None = None
    try:
        cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == 1)
        assert cloud.service("payload_authority_grab", {"payload_index": PI})["data"]["result"] == 0
        assert _enter(cloud, drc_broker)["data"]["result"] == 0
        drc = DrcClient(drc_broker.port, DRC_USER, DRC_PASSWORD)
        private_broker.stop(kill=True)
        wait_until(lambda: not gw.app.bridge.connected, 5, what="main link down")
        for seq in range(1, 31):  # 1.5 s of sticks at 20 Hz with heartbeats, all during the outage
            drc.send("drone_control", {"seq": seq, "w": 30.0 + seq % 2})
            if seq % 5 == 0:
                drc.send("heart_beat", {"seq": seq, "timestamp": seq})
            time.sleep(0.05)
        wait_until(lambda: drc.count("heart_beat") == 6, 3, what="every heartbeat echoed in the outage")
        assert sim.model.yaw.speed in (30.0, 31.0)
        assert gw.app.drc.active
        assert gw.app.metrics.count("drc_failsafe_stops_total") == 0
        private_broker.start()
        wait_until(lambda: gw.app.bridge.subscribed, 10, what="main link back")
        assert gw.app.drc.active
    finally:
        if drc is not None:
            drc.close()
        gw.stop()
        cloud.close()
        sim.stop()


def test_enter_refusals(rig: dict[str, Any]) -> None:
    cloud, drc_broker = rig["cloud"], rig["drc_broker"]
    expired = _enter(cloud, drc_broker, expire_time=int(time.time()) - 10)
    assert expired["data"]["result"] == 325001 and "expired" in expired["data"]["output"]["reason"]
    wrong = _enter(cloud, drc_broker, password="not-the-password")
    assert wrong["data"]["result"] == 514304
    # nothing the gateway published (replies, events, telemetry) repeats a credential
    published = [raw for t, _, raw in cloud.messages if not t.endswith("/services")]
    assert published and not any(
        b"not-the-password" in raw or DRC_PASSWORD.encode() in raw for raw in published
    )
    # sticks on the main broker without a session are ignored (no reply, no motion)
    cloud.publish(f"thing/product/{GW}/drc/down", {"method": "drone_control", "data": {"seq": 1, "w": 50.0}})
    time.sleep(0.2)
    assert rig["sim"].model.yaw.speed == 0.0


def test_credentials_that_expire_during_a_session_do_not_drop_it(rig: dict[str, Any]) -> None:
    """``expire_time`` bounds when ``drc_mode_enter`` may use the credentials, not how long an open link
    lives: the operator flying when it passes keeps flying (heartbeats echoed, sticks obeyed)."""
    cloud, model, gw = rig["cloud"], rig["sim"].model, rig["gw"]
    expire = int(time.time()) + 2
    assert _enter(cloud, rig["drc_broker"], expire_time=expire)["data"]["result"] == 0
    drc = DrcClient(rig["drc_broker"].port, DRC_USER, DRC_PASSWORD)
    try:
        seq = 0
        while time.time() < expire + 1.0:  # 20 Hz sticks, 5 Hz heartbeats, across the expiry
            seq += 1
            drc.send("drone_control", {"seq": seq, "w": 15.0})
            if seq % 4 == 1:
                drc.send("heart_beat", {"seq": seq, "timestamp": seq})
            time.sleep(0.05)
        drc.send("heart_beat", {"seq": 100_000, "timestamp": 1})
        assert drc.wait("heart_beat", lambda d: d["seq"] == 100_000)["data"]["timestamp"] == 1
        drc.send("drone_control", {"seq": seq + 1, "w": 16.0})
        wait_until(lambda: model.yaw.speed == 16.0, 3, what="sticks obeyed after the expiry")
    finally:
        drc.close()
    assert gw.app.drc.active and gw.app.drc.drc_state == 2
    assert gw.app.metrics.count("drc_failsafe_stops_total") == 0
    assert not cloud.find(
        "events", lambda b: b["method"] == "drc_status_notify" and b["data"]["drc_state"] == 0
    )


def test_drc_on_the_main_broker_reuses_its_connection(broker: LocalBroker, can_channel: str) -> None:
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {
        "type": "rsdk",
        "sn": "RSDK-DRC-2",
        "interface": "virtual",
        "channel": can_channel,
        "drc_drive": True,
    }
    cloud = CloudClient(broker.host, broker.port, GW)
    with GatewayThread(gateway_settings(broker.port, [device])) as gw:
        cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == 1)
        cloud.service("payload_authority_grab", {"payload_index": PI})
        same = {"address": f"127.0.0.1:{broker.port}", "client_id": "x", "username": "", "password": "",
                "expire_time": 4102444800, "enable_tls": False}  # fmt: skip
        r = cloud.service("drc_mode_enter", {"mqtt_broker": same, "osd_frequency": 5, "hsi_frequency": 1})
        assert r["data"]["result"] == 0
        assert gw.app.drc.dedicated_link is None  # the main connection carries drc/down and drc/up
        cloud.publish(
            f"thing/product/{GW}/drc/down",
            {"method": "heart_beat", "data": {"seq": 7, "timestamp": 9}},
            qos=0,
        )
        echo = cloud.wait_for("drc/up", lambda b: b["method"] == "heart_beat")[0]
        assert echo["data"] == {"seq": 7, "timestamp": 9}
        cloud.publish(
            f"thing/product/{GW}/drc/down", {"method": "drone_control", "data": {"seq": 1, "w": 5.0}}, qos=0
        )
        wait_until(lambda: sim.model.yaw.speed == 5.0, 3, what="driven over the main connection")
    cloud.close()
    sim.stop()


#: a cloud gone wrong, in its own process (as it would be): drone_control at RATE a second, a
#: hundred times the 20 Hz a cloud streams (past what paho can read, a flood on the same connection
#: queues in the broker and the kernel, whatever the gateway does: see docs/drc.md)
_FLOOD = """
import signal, sys, time
import paho.mqtt.client as paho
from paho.mqtt.enums import CallbackAPIVersion
port, user, password, topic, rate = sys.argv[1:6]
signal.signal(signal.SIGTERM, lambda *a: sys.exit(0))
client = paho.Client(CallbackAPIVersion.VERSION2, client_id="flooder")
client.username_pw_set(user, password)
client.connect("127.0.0.1", int(port))
client.loop_start()
seq, start, batch = 1, time.monotonic(), int(rate) // 20
try:
    while True:  # a batch every 50 ms, paced against the start so the rate holds on a busy machine
        for _ in range(batch):
            body = '{"method": "drone_control", "data": {"seq": %d, "w": %d}}' % (seq, 20 + seq % 2)
            client.publish(topic, body, qos=0)
            seq += 1
        if seq <= batch + 1:
            print("started", flush=True)
        time.sleep(max(0.0, start + (seq - 1) / int(rate) - time.monotonic()))
finally:
    print(seq - 1, flush=True)
"""


def test_a_flood_of_sticks_starves_no_heartbeat_reply_or_device(rig: dict[str, Any]) -> None:
    """drone_control at 2,000 a second from another process: heartbeats are still echoed, services
    to the same gimbal still answered, no failsafe fires, and the gimbal's link carries at most
    ``max_stick_rate`` plus the stream, not the flood: the excess is dropped unread and counted."""
    cloud, model, sniffer, gw = rig["cloud"], rig["sim"].model, rig["sniffer"], rig["gw"]
    drc_broker = rig["drc_broker"]
    assert _enter(cloud, drc_broker)["data"]["result"] == 0
    operator = DrcClient(drc_broker.port, DRC_USER, DRC_PASSWORD)
    operator.send("heart_beat", {"seq": 1, "timestamp": 1})
    flood = subprocess.Popen(
        [sys.executable, "-c", _FLOOD, str(drc_broker.port), DRC_USER, DRC_PASSWORD,
         f"thing/product/{GW}/drc/down", "2000"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert flood.stdout is not None and flood.stdout.readline()  # the first batch is out
        wait_until(lambda: model.yaw.speed in (20.0, 21.0), 3, what="moving under the flood")
        started, frames_before = time.monotonic(), sniffer.names()["speed_control"]
        for i in range(20):  # 2 s at 10 Hz: heartbeats and services through the flood
            operator.send("heart_beat", {"seq": 100 + i, "timestamp": 1000 + i})
            reply = cloud.service("x_rsdk_version_get", {"payload_index": PI}, timeout=3)
            assert reply["data"]["result"] == 0, reply
            time.sleep(0.1)
        wait_until(lambda: operator.count("heart_beat", lambda d: d["seq"] >= 100) == 20, 3,
                   what="20 heartbeats echoed in the flood")  # fmt: skip
        elapsed = time.monotonic() - started
        frames = sniffer.names()["speed_control"] - frames_before
        assert flood.poll() is None, "the flood ran throughout"
    finally:
        flood.terminate()
        out, _ = flood.communicate(timeout=10)
        operator.close()
    sent = int(out.split()[-1])
    dropped = gw.app.metrics.count("drc_rejected_total", reason="rate")
    applied = gw.app.metrics.count("drc_sticks_total")
    print(f"flood: {sent} sticks sent, {applied:.0f} applied, {dropped:.0f} dropped unread, "
          f"{frames} speed frames to the gimbal in {elapsed:.1f} s")  # fmt: skip
    cfg = gw.app.settings.drc
    assert dropped > 0 and applied <= cfg.max_stick_rate * (elapsed + 5) + 100
    # stick frames + stream frames, with a stream tick's worth of slack per second
    assert frames <= (cfg.max_stick_rate + cfg.stream_hz + 5) * elapsed + 20
    assert gw.app.metrics.count("drc_failsafe_stops_total") == 0
    assert model.yaw.speed in (20.0, 21.0)


def test_stick_control_drives_the_gimbal_and_drc_gimbal_reset_resets_it(rig: dict[str, Any]) -> None:
    """The RC Plus methods on a gateway with only a gimbal (payload authority): stick_control's yaw
    channel → yaw speed, throttle → pitch speed (× drc_pitch_gain); drc_gimbal_reset is gimbal_reset."""
    cloud, model, sniffer = rig["cloud"], rig["sim"].model, rig["sniffer"]
    assert _enter(cloud, rig["drc_broker"])["data"]["result"] == 0
    drc = DrcClient(rig["drc_broker"].port, DRC_USER, DRC_PASSWORD)
    try:
        drc.send("heart_beat", {"timestamp": 1}, seq=1)
        drc.wait("heart_beat")
        # half yaw (45 °/s clockwise) and a quarter throttle (1.25 m/s up → 12.5 °/s pitch at gain 10)
        drc.send("stick_control", {"roll": 1024, "pitch": 1024, "throttle": 1189, "yaw": 1354}, seq=1)
        wait_until(lambda: model.yaw.speed == 45.0, 3, what="gimbal yaw speed 45")
        wait_until(lambda: model.pitch.speed == 12.5, 3, what="gimbal pitch speed 12.5")
        drc.send("stick_control", {"yaw": 364}, seq=2)  # full counter-clockwise, other channels neutral
        wait_until(lambda: model.yaw.speed == -90.0 and model.pitch.speed == 0.0, 3, what="full left")
        assert drc.count("stick_control") == 0  # accepted stick_control is not answered
        drc.send("stick_control", {"yaw": 1700}, seq=3)  # outside 364..1684: refused, never clamped
        bad = drc.wait("stick_control")["data"]
        assert bad["result"] == 325001 and "yaw" in bad["output"]["reason"], bad
        wait_until(lambda: model.yaw.speed == 0.0, 3, what="stopped once the sticks stop")

        recentered = lambda: sum(  # noqa: E731
            1 for n, f in sniffer.commands if n == "recenter_selfie" and f["recenter_and_selfie_command"] == 1
        )
        before = recentered()
        for _ in range(5):  # five copies of one message (one seq): one recenter, five equal answers
            drc.send("drc_gimbal_reset", {"payload_index": PI, "reset_mode": 0}, seq=4)
        wait_until(lambda: drc.count("drc_gimbal_reset") == 5, 5, what="five answers")
        assert drc.count("drc_gimbal_reset", lambda d: d == {"result": 0}) == 5
        assert drc.wait("drc_gimbal_reset")["seq"] == 4  # DJI's replies repeat the seq beside data
        time.sleep(0.3)
        assert recentered() == before + 1  # the gimbal_reset service's recenter, once
        drc.send("drc_gimbal_reset", {"payload_index": "1009-0-0", "reset_mode": 0}, seq=5)
        unknown = drc.wait("drc_gimbal_reset", lambda d: d["result"] != 0)["data"]
        assert unknown["result"] == 325001 and unknown["output"]["reason"], unknown
    finally:
        drc.close()
    assert rig["gw"].app.metrics.count("drc_sticks_total") >= 2


def test_both_stick_methods_share_the_rate_budget_read_before_parsing() -> None:
    from gateway.drc import _STICK

    for method in (b"drone_control", b"stick_control"):
        assert _STICK.search(b'{"seq": 3, "method" : "' + method + b'", "data": {}}')
    for method in (b"heart_beat", b"drone_emergency_stop", b"drc_gimbal_reset"):
        assert not _STICK.search(b'{"method":"' + method + b'","data":{}}')
