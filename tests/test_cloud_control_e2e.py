"""Cloud-control authorisation end to end: a cloud (RC Plus 2 style, as wudizhr/DJI_Cloud_API_demo sends
it) through a real mosquitto to the gateway with the simulated R SDK gimbal on a virtual CAN bus; the
operator answers through ``dji-gateway control-auth`` (the CLI, over the gateway's HTTP endpoint) and the
console's endpoint. DRC rides the main broker (drc_mode_enter names it) to keep each test short."""

from __future__ import annotations

import json
import time
import urllib.error
import urllib.request
import uuid
from collections.abc import Iterator
from typing import Any

import pytest

from adapters.rsdk.sim import GimbalCanSim
from gateway.cli import main as cli
from gateway.local_broker import LocalBroker
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker

GW = "GW-TEST-1"
PI = "20-0-0"
TOKEN = "console-token-for-cloud-control-tests"


def _rig(broker: LocalBroker, can_channel: str, **cloud_control: Any) -> Iterator[dict[str, Any]]:
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {
        "type": "rsdk",
        "sn": "RSDK-CC-1",
        "interface": "virtual",
        "channel": can_channel,
        "drc_drive": True,
    }
    settings = gateway_settings(
        broker.port,
        [device],
        cloud_control=cloud_control,
        metrics={"enabled": True, "host": "127.0.0.1", "port": 0},
        console={"token": TOKEN},
        drc={"heartbeat_timeout": 5.0, "idle_timeout": 30.0},
    )
    cloud = CloudClient(broker.host, broker.port, GW)
    gw = GatewayThread(settings).start()
    try:
        cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == 1)
        assert cloud.service("payload_authority_grab", {"payload_index": PI})["data"]["result"] == 0
        assert gw.app is not None and gw.app.web is not None
        yield {
            "sim": sim,
            "cloud": cloud,
            "gw": gw,
            "url": f"http://127.0.0.1:{gw.app.web.port}",
            "broker": broker,
        }
    finally:
        gw.stop()
        cloud.close()
        sim.stop()


@pytest.fixture
def rig(broker: LocalBroker, can_channel: str) -> Iterator[dict[str, Any]]:
    yield from _rig(broker, can_channel, allow=["ops-1"], timeout=30.0)


@pytest.fixture
def strict_rig(broker: LocalBroker, can_channel: str) -> Iterator[dict[str, Any]]:
    yield from _rig(broker, can_channel, timeout=0.5, required=True)


def _ask(cloud: CloudClient, user: str) -> tuple[dict[str, Any], str]:
    """cloud_control_auth_request as the RC Plus 2 client sends it; the reply and the request's bid."""
    bid = str(uuid.uuid4())
    body = {
        "bid": bid,
        "tid": str(uuid.uuid4()),
        "timestamp": int(time.time() * 1000),
        "method": "cloud_control_auth_request",
        "data": {"control_keys": ["flight"], "user_callsign": user.upper(), "user_id": user},
    }
    cloud.publish(f"thing/product/{GW}/services", body)
    reply = cloud.wait_for("services_reply", lambda b: b.get("tid") == body["tid"])[-1]
    return reply, bid


def _notify(cloud: CloudClient, bid: str, timeout: float = 5.0) -> dict[str, Any]:
    found = cloud.wait_for(
        "events",
        lambda b: b.get("method") == "cloud_control_auth_notify" and b.get("bid") == bid,
        timeout=timeout,
    )
    return found[-1]


def _enter(cloud: CloudClient, broker: LocalBroker) -> dict[str, Any]:
    mqtt = {
        "address": f"127.0.0.1:{broker.port}",
        "client_id": f"drc-{uuid.uuid4().hex[:6]}",
        "username": "",
        "password": "",
        "expire_time": int(time.time()) + 3600,
        "enable_tls": False,
    }
    return cloud.service("drc_mode_enter", {"mqtt_broker": mqtt, "osd_frequency": 10, "hsi_frequency": 1})


def _stick(cloud: CloudClient, seq: int, w: float) -> dict[str, Any]:
    cloud.publish(
        f"thing/product/{GW}/drc/down", {"method": "drone_control", "data": {"seq": seq, "w": w}}, qos=0
    )
    return cloud.wait_for(
        "drc/up",
        lambda b: b.get("method") == "drone_control" and b["data"].get("output", {}).get("seq") == seq,
    )[-1]


def test_allow_list_grants_drc_flies_a_handover_by_the_cli_stops_the_old_session(
    rig: dict[str, Any], capsys: pytest.CaptureFixture[str]
) -> None:
    cloud, model, url = rig["cloud"], rig["sim"].model, rig["url"]
    # the allow-listed user: the reply, then the notify (status ok, the request's bid, need_reply 0)
    reply, bid = _ask(cloud, "ops-1")
    assert reply["data"] == {"result": 0, "output": {"status": "ok"}}, reply
    note = _notify(cloud, bid)
    assert note["data"] == {"result": 0, "output": {"status": "ok"}} and note["need_reply"] == 0
    assert _enter(cloud, rig["broker"])["data"]["result"] == 0
    cloud.publish(
        f"thing/product/{GW}/drc/down", {"method": "heart_beat", "data": {"seq": 1, "timestamp": 1}}, qos=0
    )
    assert _stick(cloud, 1, 30.0)["data"]["result"] == 0
    wait_until(lambda: model.yaw.speed == 30.0, 3, what="the holder's sticks drive the gimbal")

    # another user (not on the list) waits for the operator: no notify yet
    reply, guest_bid = _ask(cloud, "guest")
    assert reply["data"]["result"] == 0
    assert cli(["control-auth", "--url", url]) == 0
    shown = capsys.readouterr().out
    assert "held by OPS-1 (ops-1)" in shown and "waiting: GUEST (guest)" in shown, shown
    assert not cloud.find("events", lambda b: b.get("bid") == guest_bid)
    # an answer meant for another user is refused; without the token nothing is answered
    assert cli(["control-auth", "accept", "--user", "nobody", "--url", url, "--token", TOKEN]) == 1
    assert (
        cli(
            ["control-auth", "accept", "--user", "guest", "--url", url, "--token", "wrong-token-xxxxxxxxxxxx"]
        )
        == 1
    )
    capsys.readouterr()
    assert cli(["control-auth", "accept", "--user", "guest", "--url", url, "--token", TOKEN]) == 0
    assert "held by GUEST (guest), granted by the operator" in capsys.readouterr().out
    assert _notify(cloud, guest_bid)["data"]["output"]["status"] == "ok"

    # the session ops-1 entered no longer flies: stopped at once, its sticks refused with 399003
    wait_until(lambda: model.yaw.speed == 0.0, 3, what="the old holder's session stopped")
    refused = _stick(cloud, 2, 45.0)
    assert refused["data"]["result"] == 399003 and "'guest'" in refused["data"]["output"]["reason"], refused
    time.sleep(0.2)
    assert model.yaw.speed == 0.0
    # the new holder enters live control and flies
    assert _enter(cloud, rig["broker"])["data"]["result"] == 0
    assert _stick(cloud, 3, -20.0)["data"]["result"] == 0
    wait_until(lambda: model.yaw.speed == -20.0, 3, what="the new holder's sticks drive the gimbal")

    # release: the grant ends, the session's sticks are refused again
    assert cloud.service("cloud_control_release", {"control_keys": ["flight"]})["data"]["result"] == 0
    wait_until(lambda: model.yaw.speed == 0.0, 3, what="stopped on release")
    assert "released" in _stick(cloud, 4, 10.0)["data"]["output"]["reason"]


def test_no_answer_denies_after_the_timeout_and_drc_stays_closed(strict_rig: dict[str, Any]) -> None:
    cloud, url = strict_rig["cloud"], strict_rig["url"]
    # required: even before any request, live control needs cloud control
    first = _enter(cloud, strict_rig["broker"])["data"]
    assert first["result"] == 399003 and "cloud_control_auth_request" in first["output"]["reason"]
    asked = time.monotonic()
    reply, bid = _ask(cloud, "guest")
    assert reply["data"]["result"] == 0
    waiting = _enter(cloud, strict_rig["broker"])["data"]
    assert waiting["result"] == 399003 and "waits for the operator" in waiting["output"]["reason"]
    note = _notify(cloud, bid, timeout=5.0)
    assert note["data"]["output"]["status"] == "failed"
    assert time.monotonic() - asked >= 0.5  # the operator's whole timeout, not earlier
    assert _enter(cloud, strict_rig["broker"])["data"]["result"] == 399003

    # the console's endpoint: nothing to answer now (409); an unauthenticated answer is refused (401)
    def post(body: dict[str, Any], token: str | None) -> int:
        headers = {"Content-Type": "application/json"}
        if token:
            headers["Authorization"] = f"Bearer {token}"
        req = urllib.request.Request(
            f"{url}/api/cloud-control", json.dumps(body).encode(), headers, method="POST"
        )
        try:
            with urllib.request.urlopen(req, timeout=5) as resp:
                return int(resp.status)
        except urllib.error.HTTPError as exc:
            return int(exc.code)

    assert post({"decision": "accept"}, None) == 401
    assert post({"decision": "accept"}, TOKEN) == 409
    assert post({"decision": "maybe"}, TOKEN) == 400
    assert post({"decision": "accept", "extra": 1}, TOKEN) == 400
    # a new request, denied by the operator through the console's endpoint
    _, bid2 = _ask(cloud, "guest")
    assert post({"decision": "deny", "user_id": "guest"}, TOKEN) == 200
    assert _notify(cloud, bid2)["data"]["output"]["status"] == "failed"
    status = json.loads(urllib.request.urlopen(f"{url}/status", timeout=5).read())
    assert status["cloud_control"]["holder"] is None and status["cloud_control"]["pending"] is None
