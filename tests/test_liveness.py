"""A broker link that acknowledges subscriptions and delivers nothing is found *deaf* and left.

A small TCP proxy sits between the gateway and a real mosquitto: it passes everything, until told to drop
every PUBLISH packet on its way to the gateway (it reads MQTT fixed headers, so CONNACK, SUBACK, PUBACK
and PINGRESP still pass: the connection looks perfectly healthy to paho and to TCP). The gateway's
liveness probe misses, ``/healthz`` says ``deaf`` (not ``disconnected``), the gateway resubscribes, then
moves to the next broker url (mosquitto itself) and answers requests again, well within 15 s.
"""

from __future__ import annotations

import json
import threading
import time
import urllib.error
import urllib.request
from typing import Any

import pytest

from adapters.rsdk.sim import GimbalCanSim
from gateway.local_broker import LocalBroker
from tests.mqtt_proxy import PUBLISH, MqttProxy, mqtt_packets, packet_type
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker

GW = "GW-DEAF-1"


class DeafProxy(MqttProxy):
    """TCP proxy to ``upstream``; while ``deaf`` is set, PUBLISH packets to the client are dropped
    (counted in ``dropped``). What the client sends is passed as is."""

    def __init__(self, upstream: tuple[str, int]) -> None:
        self.deaf = threading.Event()
        self.dropped = 0
        super().__init__(upstream, to_client=self._to_client, name="deaf-proxy")

    def _to_client(self, packet: bytes) -> bool:
        if packet_type(packet) == PUBLISH and self.deaf.is_set():
            self.dropped += 1
            return False
        return True


def test_the_proxy_parses_packets_split_anywhere() -> None:
    """The proxy's framing: packets come out whole however the stream is cut (a 200-byte remaining
    length takes two bytes)."""
    stream = bytes([0x20, 2, 0, 0]) + bytes([0x30, 0xC8, 0x01]) + b"x" * 200 + bytes([0xD0, 0])
    for cut in range(len(stream) + 1):
        buf = bytearray(stream[:cut])
        out = list(mqtt_packets(buf))
        buf.extend(stream[cut:])
        out += list(mqtt_packets(buf))
        assert [p[0] for p in out] == [0x20, 0x30, 0xD0] and not buf


def healthz(port: int) -> tuple[int, dict[str, Any]]:
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/healthz", timeout=2) as resp:
            return resp.status, json.loads(resp.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read())


def test_a_link_that_acknowledges_subscriptions_and_delivers_nothing_is_detected_and_left(
    private_broker: LocalBroker, can_channel: str
) -> None:
    proxy = DeafProxy((private_broker.host, private_broker.port))
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    settings = gateway_settings(
        private_broker.port,
        [{"type": "rsdk", "sn": "RSDK-DEAF-1", "interface": "virtual", "channel": can_channel}],
        gateway_sn=GW,
        metrics={"enabled": True, "port": 0},
        broker={
            "url": [f"mqtt://127.0.0.1:{proxy.port}", f"mqtt://127.0.0.1:{private_broker.port}"],
            "liveness_interval": 1.0,
            # 2 s, not 1: a probe's round trip on a loaded two-core machine running the suite beside it
            # can take a second, and one false "deaf" would make the counts below 2
            "liveness_timeout": 2.0,
        },
    )
    gw = GatewayThread(settings).start()
    cloud = CloudClient(private_broker.host, private_broker.port, GW)
    try:
        assert gw.app is not None and gw.app.bridge is not None and gw.app.observability is not None
        bridge, port = gw.app.bridge, gw.app.observability.port
        assert bridge.current is not None and bridge.current.port == proxy.port  # the first url
        wait_until(lambda: bridge.liveness.state.value == "live", 5, what="the first probe back")
        status, body = healthz(port)
        assert status == 200 and body["broker"] == "connected", body
        wait_until(lambda: gw.app.devices.by_sn("RSDK-DEAF-1").online, 5, what="gimbal online")
        grab = {"payload_index": "20-0-0"}
        assert cloud.service("payload_authority_grab", grab)["data"]["result"] == 0

        proxy.deaf.set()
        started = time.monotonic()
        seen: list[str] = []

        def recovered() -> bool:
            status, body = healthz(port)
            if not seen or seen[-1] != body["broker"]:
                seen.append(body["broker"])
            if body["broker"] == "deaf":
                assert status == 503 and body["checks"]["broker_receives"] is False
            return bool(
                status == 200 and bridge.current is not None and bridge.current.port == private_broker.port
            )

        wait_until(recovered, 15, interval=0.05, what="deaf link detected and left")
        took = time.monotonic() - started
        assert "deaf" in seen, seen  # said so meanwhile, distinctly from "disconnected"
        assert took < 15.0
        assert proxy.dropped >= 2  # the probe, then the probe after resubscribing
        assert cloud.service("payload_authority_grab", grab)["data"]["result"] == 0  # answers again
        metrics = urllib.request.urlopen(f"http://127.0.0.1:{port}/metrics", timeout=2).read().decode()
        assert 'djigw_mqtt_deaf_total{link="main"} 1.0' in metrics
        assert 'djigw_mqtt_resubscribes_total{link="main"} 1.0' in metrics
    finally:
        cloud.close()
        gw.stop()
        sim.stop()
        proxy.close()
