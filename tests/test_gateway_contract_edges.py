"""Dispatcher edges through a real broker: property/set, methods nobody here serves, legacy-firmware
gimbals, MQTT 3.1.1, TCP_NODELAY, and events that ask for a reply."""

from __future__ import annotations

import json
import socket
from typing import Any

import pytest

from adapters.rsdk.sim import GimbalCanSim, GimbalModel, GimbalNode
from gateway.clock import ManualClock
from gateway.devices import DeviceTable
from gateway.local_broker import LocalBroker
from gateway.metrics import Metrics
from gateway.northbound import Northbound
from schemas import default_registry
from tests.support import CloudClient, GatewayThread, gateway_settings

pytestmark = pytest.mark.broker
GW = "GW-TEST-1"


def _gimbal(channel: str, sn: str = "RSDK-E-1") -> dict[str, Any]:
    return {"type": "rsdk", "sn": sn, "interface": "virtual", "channel": channel}


def test_property_set_and_unserved_methods(broker: LocalBroker, can_channel: str) -> None:
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    cloud = CloudClient(broker.host, broker.port, GW)
    with GatewayThread(gateway_settings(broker.port, [_gimbal(can_channel)])):
        # drc_state is the seed's only property and it is read-only: refused per property
        cloud.publish(f"thing/product/{GW}/property/set", {"tid": "p1", "bid": "b", "timestamp": 0,
                                                           "data": {"drc_state": 2}})  # fmt: skip
        reply = cloud.wait_for("property/set_reply", lambda b: b["tid"] == "p1")[0]
        assert reply["data"] == {"drc_state": {"result": 325001}}
        # flight methods on a gateway without an aircraft
        assert cloud.service("flight_authority_grab", {})["data"]["result"] == 399001
        fly = {
            "fly_to_id": "f1",
            "max_speed": 5,
            "points": [{"latitude": 1.0, "longitude": 2.0, "height": 50.0}],
        }
        r = cloud.service("fly_to_point", fly)
        assert r["data"]["result"] == 399001 and "fly_to_point" in r["data"]["output"]["reason"]
    cloud.close()
    sim.stop()


def test_gimbal_on_legacy_firmware_replies(broker: LocalBroker, can_channel: str) -> None:
    """Firmware before R SDK 2.2.0.5 replies without CmdSet/CmdID; the adapter matches by SEQ."""
    model = GimbalModel(legacy_replies=True)
    sim = GimbalCanSim(GimbalNode(model), interface="virtual", channel=can_channel).start()
    cloud = CloudClient(broker.host, broker.port, GW)
    settings = gateway_settings(broker.port, [_gimbal(can_channel)], dispatcher={"require_authority": False})
    with GatewayThread(settings):
        cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == 1)
        assert cloud.service("camera_photo_take", {"payload_index": "20-0-0"})["data"]["result"] == 0
        r = cloud.service("x_rsdk_stiffness_get", {"payload_index": "20-0-0"})
        assert r["data"] == {"result": 0, "output": {"pitch": 50, "roll": 50, "yaw": 50}}
        assert cloud.service("x_rsdk_version_get", {"payload_index": "20-0-0"})["data"]["output"]["version"]
    assert model.photos == 1
    cloud.close()
    sim.stop()


@pytest.mark.parametrize(
    ("gimbal_order", "setting", "expected"),
    [
        ("yaw_roll_pitch", None, (5.0, 20.0)),  # seed 000's order, the default
        ("yaw_pitch_roll", "yaw_pitch_roll", (5.0, 20.0)),  # ArduPilot's reading of older firmware
        ("yaw_pitch_roll", None, (20.0, 5.0)),  # a gimbal that answers otherwise than configured
    ],
)
def test_legacy_angle_replies_in_the_configured_order(
    broker: LocalBroker,
    can_channel: str,
    gimbal_order: str,
    setting: str | None,
    expected: tuple[float, float],
) -> None:
    """Issue #16 item 8: a legacy-firmware 0x0E 0x02 reply is read in the gimbal's legacy_angle_order."""
    model = GimbalModel(legacy_replies=True, legacy_angle_order=gimbal_order)
    model.yaw.angle, model.roll.angle, model.pitch.angle = 30.0, 5.0, 20.0
    sim = GimbalCanSim(GimbalNode(model), interface="virtual", channel=can_channel).start()
    cloud = CloudClient(broker.host, broker.port, GW)
    gimbal = _gimbal(can_channel) | ({} if setting is None else {"legacy_angle_order": setting})
    settings = gateway_settings(broker.port, [gimbal], dispatcher={"require_authority": False})
    with GatewayThread(settings):
        cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == 1)
        out = cloud.service("x_rsdk_angle_get", {"payload_index": "20-0-0"})["data"]["output"]
        assert (out["kind"], out["yaw"], (out["roll"], out["pitch"])) == ("attitude", 30.0, expected)
    cloud.close()
    sim.stop()


def test_mqtt_311_and_tcp_nodelay(broker: LocalBroker, can_channel: str) -> None:
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    cloud = CloudClient(broker.host, broker.port, GW)
    settings = gateway_settings(
        broker.port, [_gimbal(can_channel)], broker={"url": broker.url, "protocol": "3.1.1"},
        dispatcher={"require_authority": False},
    )  # fmt: skip
    with GatewayThread(settings) as gw:
        cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == 1)
        assert cloud.service("camera_photo_take", {"payload_index": "20-0-0"})["data"]["result"] == 0
        sock = gw.app.bridge._client.socket()
        assert sock.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY) == 1
    cloud.close()
    sim.stop()


class _Recorder:
    def __init__(self) -> None:
        self.sent: list[tuple[str, bytes, int]] = []

    def publish(self, topic: str, payload: bytes, qos: int = 1, retain: bool = False) -> bool:
        self.sent.append((topic, payload, qos))
        return True


def test_events_with_need_reply_are_resent_until_answered() -> None:
    settings = gateway_settings(1883, [], dispatcher={"event_retries": 2, "event_retry_interval": 3.0})
    clock, out, metrics = ManualClock(), _Recorder(), Metrics()
    nb = Northbound(settings=settings, registry=default_registry(), devices=DeviceTable([]), outbox=out,
                    clock=clock, metrics=metrics)  # fmt: skip
    nb.event("GW-TEST-1", "drc_status_notify", {"result": 0, "drc_state": 2}, need_reply=True)
    nb.event("GW-TEST-1", "drc_status_notify", {"result": 0, "drc_state": 0}, need_reply=False)
    assert len(out.sent) == 2 and all(t.endswith("/events") and q == 1 for t, _, q in out.sent)
    first = out.sent[0][1]
    clock.advance(2.9)
    nb.retry_events()
    assert len(out.sent) == 2
    clock.advance(0.2)
    nb.retry_events()
    assert out.sent[-1][1] == first  # the same message, same tid
    clock.advance(3.1)
    nb.retry_events()
    clock.advance(3.1)
    nb.retry_events()  # retries exhausted: given up and counted
    assert len(out.sent) == 4 and metrics.count("events_unanswered_total") == 1
    # an answered event is not re-sent
    nb.event("GW-TEST-1", "drc_status_notify", {"result": 0, "drc_state": 1}, need_reply=True)
    tid = json.loads(out.sent[-1][1])["tid"]
    nb.events_reply(tid, 0)
    clock.advance(10)
    nb.retry_events()
    assert len(out.sent) == 5
