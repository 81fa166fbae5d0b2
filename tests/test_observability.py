"""Observability end to end: a real session through mosquitto, then ``/metrics`` scraped over HTTP shows it
(services by method and result, reply latency, DRC heartbeats and failsafe stops, CAN frames in/out, CRC
and framing errors, broker reconnects, inbound queue drops, device online); ``/healthz`` follows the
broker and the event loop; ``dji-gateway status`` reads ``/status``. And the logs of a full session
through ``dji-gateway run`` (JSON and text, DEBUG) carry the request context and never a secret."""

from __future__ import annotations

import json
import logging
import os
import signal
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import can
import pytest
from prometheus_client.parser import text_string_to_metric_families

from adapters.rsdk.can import GIMBAL_TX_ID, segment
from adapters.rsdk.sim import GimbalCanSim, SlcanGimbal
from adapters.simio import TcpEndpoint
from gateway import logcontext
from gateway.cli import main as cli_main
from gateway.local_broker import LocalBroker
from gateway.observability import _Monotonic
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker

GW = "GW-OBS-1"
PI = "20-0-0"
SEED_000_SAMPLE = bytes.fromhex("AA1A000300000000 2211A2420E00200030004000 01147B4097BE".replace(" ", ""))


def scrape(port: int) -> dict[tuple[str, frozenset[tuple[str, str]]], float]:
    with urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=5) as resp:
        text = resp.read().decode()
    return {
        (s.name, frozenset(s.labels.items())): s.value
        for family in text_string_to_metric_families(text)
        for s in family.samples
    }


def value(samples: dict[tuple[str, frozenset[tuple[str, str]]], float], name: str, **labels: str) -> float:
    """Sum of ``name`` over the series whose labels include ``labels``."""
    want = set(labels.items())
    return sum(v for (n, lab), v in samples.items() if n == name and want <= lab)


def get(port: int, path: str) -> tuple[int, dict[str, Any]]:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=5) as resp:
            return resp.status, json.loads(resp.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


@pytest.fixture
def rig(private_broker: LocalBroker, can_channel: str) -> Iterator[dict[str, Any]]:
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {"type": "rsdk", "sn": "RSDK-OBS-1", "interface": "virtual", "channel": can_channel}
    settings = gateway_settings(
        private_broker.port,
        [{**device, "drc_drive": True}],
        gateway_sn=GW,
        metrics={"enabled": True, "port": 0},
        broker={"inbound_queue": 10},
        drc={"stick_timeout": 0.3},
    )
    gw = GatewayThread(settings).start()
    cloud = CloudClient(private_broker.host, private_broker.port, GW)
    try:
        assert gw.app.observability is not None
        wait_until(lambda: gw.app.devices.by_sn("RSDK-OBS-1").online, 5, what="gimbal online")
        yield {
            "gw": gw,
            "cloud": cloud,
            "sim": sim,
            "port": gw.app.observability.port,
            "broker": private_broker,
        }
    finally:
        cloud.close()
        gw.stop()
        sim.stop()


def test_a_session_shows_in_the_metrics(rig: dict[str, Any], can_channel: str) -> None:
    gw, sim, port, broker = rig["gw"], rig["sim"], rig["port"], rig["broker"]
    cloud: CloudClient = rig["cloud"]
    assert get(port, "/healthz") == (
        200,
        {
            "status": "ok",
            "broker": "connected",
            "checks": {
                "started": True,
                "event_loop": True,
                "broker": True,
                "broker_receives": True,
                "drc_broker_receives": True,
                "client_id_unique": True,
            },
        },
    )

    # a broker outage: /healthz says so, the gateway reconnects by itself
    cloud.close()
    broker.stop(kill=True)
    wait_until(lambda: get(port, "/healthz")[0] == 503, 5, what="unhealthy without the broker")
    assert get(port, "/healthz")[1]["checks"]["broker"] is False
    assert get(port, "/healthz")[1]["broker"] == "disconnected"  # not "deaf": nothing to hear from
    broker.start()
    wait_until(lambda: get(port, "/healthz")[0] == 200, 10, what="healthy after the reconnect")
    cloud = rig["cloud"] = CloudClient(broker.host, broker.port, GW)

    # services: success, a bad payload index, a device error result
    assert cloud.service("payload_authority_grab", {"payload_index": PI})["data"]["result"] == 0
    aim = {"payload_index": PI, "camera_type": "wide", "locked": False, "x": 0.9, "y": 0.5}
    assert cloud.service("camera_aim", aim)["data"]["result"] == 0
    assert cloud.service("camera_aim", {**aim, "payload_index": "9-9-9"})["data"]["result"] == 325001

    # the CAN link: one frame with a broken CRC32 and one of garbage, as a faulty bus would deliver them
    bus = can.Bus(interface="virtual", channel=can_channel)
    try:
        broken = SEED_000_SAMPLE[:-1] + bytes([SEED_000_SAMPLE[-1] ^ 0xFF])
        for arb_id, data in [*segment(broken, GIMBAL_TX_ID), (GIMBAL_TX_ID, b"\x01\x02\x03")]:
            bus.send(can.Message(arbitration_id=arb_id, data=data, is_extended_id=False))
    finally:
        bus.shutdown()

    # live control on the main broker: heartbeats, sticks, the sticks failsafe, an emergency stop
    drc_broker = {
        "address": f"127.0.0.1:{broker.port}",  # the main broker: the session reuses the main connection
        "client_id": "drc-obs",
        "username": "u",
        "password": "unused-on-the-main-broker",
        "expire_time": int(time.time()) + 600,
        "enable_tls": False,
    }
    enter = {"mqtt_broker": drc_broker, "osd_frequency": 10, "hsi_frequency": 1}
    assert cloud.service("drc_mode_enter", enter)["data"]["result"] == 0
    down = f"thing/product/{GW}/drc/down"
    for seq in (1, 2):
        cloud.publish(
            down, {"method": "heart_beat", "data": {"seq": seq, "timestamp": int(time.time() * 1000)}}
        )
    cloud.wait_for("drc/up", lambda b: b["method"] == "heart_beat" and b["data"]["seq"] == 2)
    cloud.publish(down, {"method": "drone_control", "data": {"seq": 1, "w": 30.0}})
    wait_until(lambda: sim.model.yaw.speed == 30.0, 3, what="sticks reach the gimbal")
    wait_until(lambda: sim.model.yaw.speed == 0.0, 3, what="the sticks failsafe zeroes the speed")
    cloud.publish(down, {"method": "drone_emergency_stop", "data": {}})
    cloud.wait_for("drc/up", lambda b: b["method"] == "drone_emergency_stop")
    status = get(port, "/status")[1]
    assert status["drc"]["active"] and status["drc"]["state"] == 2 and status["drc"]["emergency_stop"]
    assert cloud.service("drc_mode_exit", {})["data"]["result"] == 0

    # a flood while the loop is busy: the bounded inbound queue drops and counts, never blocks paho
    loop = gw.loop
    assert loop is not None
    blocked = threading.Event()

    def busy_until_backlog() -> None:  # runs on the gateway's loop: a slow handler
        blocked.set()
        deadline = time.monotonic() + 5
        while len(loop._ready) < 40 and time.monotonic() < deadline:  # the paho thread's hand-overs pile up
            time.sleep(0.005)

    hog = threading.Thread(target=lambda: gw.call(busy_until_backlog, timeout=10), daemon=True)
    hog.start()
    assert blocked.wait(5)
    for i in range(60):
        body = {"tid": f"flood-{i}", "bid": "b", "timestamp": 0, "method": "x", "data": {"result": 0}}
        cloud.client.publish(f"thing/product/{GW}/events_reply", json.dumps(body), qos=0)
    hog.join(10)

    def dropped() -> float:
        return value(scrape(port), "djigw_mqtt_inbound_dropped_total", link="main")

    wait_until(dropped, 5, what="inbound queue drops counted")

    m = scrape(port)
    assert value(m, "djigw_services_total", method="camera_aim", result="0") == 1
    assert value(m, "djigw_services_total", method="camera_aim", result="325001") == 1
    assert value(m, "djigw_services_total", method="payload_authority_grab", result="0") == 1
    assert value(m, "djigw_services_latency_seconds_count", method="camera_aim") == 2
    assert value(m, "djigw_services_latency_seconds_bucket", method="camera_aim", le="+Inf") == 2
    assert value(m, "djigw_services_latency_seconds_sum", method="camera_aim") > 0
    assert value(m, "djigw_drc_sessions_total") == 1
    assert value(m, "djigw_drc_heartbeats_total") >= 2
    assert value(m, "djigw_drc_failsafe_stops_total", reason="sticks") >= 1
    assert value(m, "djigw_drc_failsafe_stops_total", reason="emergency_stop") == 1
    link = {"device": "RSDK-OBS-1", "kind": "can"}
    assert value(m, "djigw_link_frames_in_total", **link) > 0
    assert value(m, "djigw_link_frames_out_total", **link) > 0
    assert value(m, "djigw_link_crc_errors_total", **link) >= 1
    assert value(m, "djigw_link_framing_errors_total", **link) >= 1
    assert value(m, "djigw_link_opens_total", **link) == 1
    assert value(m, "djigw_link_up", **link) == 1
    assert value(m, "djigw_mqtt_connects_total", link="main") >= 2
    assert value(m, "djigw_mqtt_disconnects_total", link="main") >= 1
    assert value(m, "djigw_mqtt_inbound_dropped_total", link="main") > 0
    assert value(m, "djigw_device_online", device="RSDK-OBS-1", type="rsdk") == 1
    assert value(m, "djigw_healthy") == 1 and value(m, "djigw_info", gateway_sn=GW) == 1
    assert value(m, "djigw_drc_state") == 0

    # /status and `dji-gateway status` read the same live state
    doc = get(port, "/status")[1]
    assert doc["gateway_sn"] == GW and doc["healthy"] is True
    (dev,) = doc["devices"]
    assert dev["sn"] == "RSDK-OBS-1" and dev["online"] and dev["payload_authority"]
    assert dev["link"]["crc_errors"] >= 1 and dev["link"]["frames_in"] > 0
    assert doc["services_by_result"]["325001"] == 1
    url = f"http://127.0.0.1:{port}"
    assert cli_main(["status", "--check", "--url", url]) == 0
    assert cli_main(["status", "--url", url]) == 0


def test_a_stalled_event_loop_fails_the_health_check(rig: dict[str, Any]) -> None:
    gw, port = rig["gw"], rig["port"]
    gw.app.observability.loop_deadline = 0.2
    release = threading.Event()
    hog = threading.Thread(target=lambda: gw.call(lambda: release.wait(5), timeout=10), daemon=True)
    hog.start()
    try:
        code, body = get(port, "/healthz")
        assert code == 503 and body["checks"]["event_loop"] is False
        assert cli_main(["status", "--check", "--url", f"http://127.0.0.1:{port}"]) == 1
    finally:
        release.set()
        hog.join(5)
    assert get(port, "/healthz")[0] == 200


def test_status_reports_an_absent_gateway(capsys: pytest.CaptureFixture[str]) -> None:
    from gateway.local_broker import free_port

    assert cli_main(["status", "--url", f"http://127.0.0.1:{free_port()}"]) == 2
    assert "no gateway answers" in capsys.readouterr().err


def test_counters_stay_monotonic_when_a_decoder_restarts() -> None:
    mono = _Monotonic()
    assert [mono("D", "crc", v) for v in (0, 3, 5, 1, 2, 0, 4)] == [0, 3, 5, 6, 7, 7, 11]


# ------------------------------------------------------------------------------------------ logs
BROKER_PW = "brk-pw-7f3a91c2e4"
CLOUD_PW = "cloud-pw-55d0e1a9b3"
DRC_PW = "drc-pw-1b9e0c44aa"
DEVICE_SECRET = "dev-secret-9c8e7d6f5a"
GATEWAY_SECRET = "gw-secret-0a1b2c3d4e"
SECRETS = (BROKER_PW, CLOUD_PW, DRC_PW, DEVICE_SECRET, GATEWAY_SECRET)


def test_the_secret_registry_masks_every_format() -> None:
    logcontext.register_secret("s3cr3t-value-for-the-test")
    record = logging.LogRecord(
        "x", logging.INFO, __file__, 1, "token=%s", ("s3cr3t-value-for-the-test",), None
    )
    with logcontext.request_context(method="camera_aim", tid="t-1", device="G1"):
        logcontext.ContextFilter().filter(record)
    text = logcontext.TextFormatter().format(record)
    assert "s3cr3t" not in text and "token=***" in text and "[method=camera_aim tid=t-1 device=G1]" in text
    line = json.loads(logcontext.JsonFormatter().format(record))
    assert line["msg"] == "token=***" and (line["method"], line["tid"], line["device"]) == (
        "camera_aim",
        "t-1",
        "G1",
    )
    # request secrets (a DRC password per session) are bounded; the settings' stay for good
    for i in range(logcontext.RECENT_SECRETS + 1):
        logcontext.register_secret(f"drc-token-{i:04d}", permanent=False)
    assert (
        logcontext.scrub("drc-token-0000 drc-token-0256 s3cr3t-value-for-the-test")
        == "drc-token-0000 *** ***"
    )


@pytest.mark.parametrize("log_format", ["json", "text"])
def test_a_full_session_logs_context_and_no_secret(tmp_path: Path, log_format: str) -> None:
    broker = LocalBroker(users={"gateway": BROKER_PW, "cloud": CLOUD_PW}, workdir=tmp_path / "main").start()
    drc_broker = LocalBroker(users={"drc-op": DRC_PW}, workdir=tmp_path / "drc").start()
    gimbal = SlcanGimbal()
    endpoint = TcpEndpoint(gimbal).start()
    config = tmp_path / "gateway.toml"
    config.write_text(
        f'''gateway_sn = "{GW}"
log_level = "DEBUG"
[product]
device_secret = "{GATEWAY_SECRET}"
[broker]
url = "{broker.url}"
username = "gateway"
reconnect_min = 0.2
[metrics]
port = 0
[[devices]]
type = "rsdk"
sn = "RSDK-LOG-1"
interface = "slcan"
channel = "{endpoint.url}"
bus_options = {{ sleep_after_open = 0 }}
drc_drive = true
product = {{ domain = "1", type = 20, device_secret = "{DEVICE_SECRET}" }}
'''
    )
    cloud = CloudClient(broker.host, broker.port, GW, username="cloud", password=CLOUD_PW)
    env = {**os.environ, "DJIGW_BROKER__PASSWORD": BROKER_PW, "PYTHONUNBUFFERED": "1"}
    args = ["run", "--config", str(config), *(["--log-json"] if log_format == "json" else [])]
    proc = subprocess.Popen(
        [sys.executable, "-m", "gateway.cli", *args],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    stderr: list[str] = []
    reader = threading.Thread(target=lambda: stderr.extend(proc.stderr or []), daemon=True)
    reader.start()
    served: list[str] = []
    try:
        topo = cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == 1, timeout=15)[-1]
        # the secrets were really in play: the topology carries the device secrets by design (Cloud API)
        assert topo["data"]["device_secret"] == GATEWAY_SECRET
        assert topo["data"]["sub_devices"][0]["device_secret"] == DEVICE_SECRET
        assert cloud.service("payload_authority_grab", {"payload_index": PI})["data"]["result"] == 0
        aim = {"payload_index": PI, "camera_type": "wide", "locked": False, "x": 0.7, "y": 0.5}
        assert cloud.service("camera_aim", aim)["data"]["result"] == 0
        enter = {
            "mqtt_broker": {
                "address": f"127.0.0.1:{drc_broker.port}",
                "client_id": "drc-log",
                "username": "drc-op",
                "password": DRC_PW,
                "enable_tls": False,
                "expire_time": int(time.time()) + 600,
            },
            "osd_frequency": 5,
            "hsi_frequency": 1,
        }
        assert cloud.service("drc_mode_enter", enter)["data"]["result"] == 0  # authenticated with DRC_PW
        wrong = {**enter, "mqtt_broker": {**enter["mqtt_broker"], "password": "not-the-drc-password"}}
        assert cloud.service("drc_mode_enter", wrong)["data"]["result"] != 0  # refused by the DRC broker
        bad = {**enter, "osd_frequency": "often"}  # invalid: the dispatcher's rejection path logs it
        assert cloud.service("drc_mode_enter", bad)["data"]["result"] == 325001
        assert cloud.service("drc_mode_exit", {})["data"]["result"] == 0
        status_port = _metrics_port(stderr)
        for path in ("/metrics", "/status", "/healthz"):
            with urllib.request.urlopen(f"http://127.0.0.1:{status_port}{path}", timeout=5) as resp:
                served.append(resp.read().decode())
    finally:
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(15)
        reader.join(5)
        if proc.stderr:
            proc.stderr.close()
        cloud.close()
        endpoint.stop()
        broker.stop()
        drc_broker.stop()
    log = "".join(stderr)
    assert code == 0, log[-2000:]
    assert "answered camera_aim" in log and "DRC session started" in log, log[-2000:]
    for secret in SECRETS:
        assert secret not in log, f"a secret reached the {log_format} log"
        assert all(secret not in page for page in served), "a secret reached the HTTP endpoint"
    lines = [line for line in log.splitlines() if line.strip()]
    if log_format == "json":
        records = [json.loads(line) for line in lines]  # one JSON object per line, nothing else
        aim_lines = [r for r in records if r.get("method") == "camera_aim"]
        assert aim_lines and all(r.get("tid") for r in aim_lines), aim_lines
        assert any(r.get("device") == "RSDK-LOG-1" for r in aim_lines), aim_lines
    else:
        assert any("[method=camera_aim tid=" in line and "device=RSDK-LOG-1]" in line for line in lines), log


def _metrics_port(stderr: list[str]) -> int:
    import re

    def find() -> int | None:
        for line in list(stderr):
            m = re.search(r"metrics on http://127\.0\.0\.1:(\d+)/metrics", line)
            if m:
                return int(m.group(1))
        return None

    return int(wait_until(find, 10, what="the metrics port in the log"))
