"""Exactly once across a kill (issue #34): ``camera_photo_take`` delivered (QoS 1), acted on, and the gateway
SIGKILLed before its reply reached the cloud; after a restart the cloud resends the same request (same
tid): it is answered once, from the state store, and the gimbal took one photo.

Real parts only: the gimbal in a process of its own (``dji-gateway simulate rsdk --tcp``, an SLCAN adapter
on a loopback port), so it outlives the gateway and counts its photos (it prints the count when it
stops); the gateway as ``dji-gateway run --config`` with a ``state_dir``; a real mosquitto; the cloud a paho
client. Between the gateway and mosquitto a small TCP proxy passes everything until the request has gone
through towards the gateway; from then on it forwards nothing from the gateway to the broker (neither the
PUBACK nor the reply arrive), and it tells the test when the reply has reached it: the gateway has acted
and replied, as far as it knows. Then the gateway is killed.
"""

from __future__ import annotations

import json
import os
import re
import signal
import sys
import threading
import time
import uuid
from pathlib import Path
from typing import Any

import pytest

from gateway.local_broker import LocalBroker
from tests.mqtt_proxy import PUBLISH, MqttProxy, packet_type
from tests.support import CloudClient, Proc, wait_until

pytestmark = [pytest.mark.broker, pytest.mark.slow]  # three processes: started first in make test

GW = "GW-KILL-ONCE-1"
SN = "RSDK-KILL-ONCE-1"
PI = "20-0-0"


class CutProxy(MqttProxy):
    """TCP proxy to ``upstream``. Once a PUBLISH holding ``marker`` has passed towards the client, every
    byte from the client towards the broker is dropped (``cut``); PUBLISH packets from the client that
    hold ``marker`` are noted meanwhile (``held``): the reply the broker never gets."""

    def __init__(self, upstream: tuple[str, int], marker: bytes) -> None:
        self.marker = marker
        self.cut = threading.Event()
        self.held: list[bytes] = []
        super().__init__(upstream, to_server=self._to_server, to_client=self._to_client, name="cut-proxy")

    def _marked(self, packet: bytes) -> bool:
        return packet_type(packet) == PUBLISH and self.marker in packet

    def _to_server(self, packet: bytes) -> bool:
        if self.cut.is_set():
            if self._marked(packet):
                self.held.append(packet)
            return False
        return True

    def _to_client(self, packet: bytes) -> bool:
        if self._marked(packet):
            self.cut.set()  # the request goes through to the gateway: cut its way back
        return True


def _photos(sim: Proc) -> int:
    sim.stop()
    found = re.search(r"stopped: (\d+) photo", sim.output())
    assert found, sim.output()
    return int(found.group(1))


def test_a_photo_acted_on_by_a_gateway_killed_before_its_reply_is_taken_once(
    private_broker: LocalBroker, tmp_path: Path
) -> None:
    exe = str(Path(sys.executable).parent / "dji-gateway")
    env = {k: v for k, v in os.environ.items() if not k.startswith("DJIGW_")} | {"PYTHONUNBUFFERED": "1"}
    sim = Proc("gimbal", [exe, "simulate", "rsdk", "--tcp", "0"], env)
    tid = str(uuid.uuid4())
    proxy = CutProxy((private_broker.host, private_broker.port), tid.encode())
    cloud = CloudClient(private_broker.host, private_broker.port, GW)
    gateway: Proc | None = None
    try:
        url = sim.wait_for_line(r"channel=(socket://127\.0\.0\.1:\d+)", 20).group(1)

        def start_gateway(port: int, name: str) -> Proc:
            config = tmp_path / f"{name}.toml"
            config.write_text(
                f'gateway_sn = "{GW}"\nstate_dir = "{tmp_path / "state"}"\n'
                f'[broker]\nurl = "mqtt://127.0.0.1:{port}"\n[metrics]\nenabled = false\n'
                "[dispatcher]\nrequire_authority = false\n"
                f'[[devices]]\ntype = "rsdk"\nsn = "{SN}"\ninterface = "slcan"\nchannel = "{url}"\n'
            )
            proc = Proc(name, [exe, "run", "--config", str(config)], env)

            def online() -> bool:  # a read-only request answered (it acts on nothing)
                try:
                    reply = cloud.service("x_rsdk_version_get", {"payload_index": PI}, timeout=1.0)
                except AssertionError:
                    return False
                return bool(reply["data"]["result"] == 0)

            wait_until(online, 20, what=f"{name}: the gimbal online")
            return proc

        gateway = start_gateway(proxy.port, "gateway-1")
        request: dict[str, Any] = {"tid": tid, "bid": str(uuid.uuid4()), "timestamp": int(time.time() * 1000),
                                   "method": "camera_photo_take", "data": {"payload_index": PI}}  # fmt: skip
        cloud.publish(f"thing/product/{GW}/services", request)
        wait_until(lambda: proxy.held, 10, what="the gateway's reply, held by the proxy")
        assert json.loads(proxy.held[0][proxy.held[0].index(b"{") :])["data"]["result"] == 0
        gateway.stop(signal.SIGKILL)  # acted, replied as far as it knows; the cloud has nothing
        gateway = None
        time.sleep(0.3)  # anything still in flight would have arrived by now
        assert not cloud.find("services_reply", lambda b: b.get("tid") == tid)

        gateway = start_gateway(private_broker.port, "gateway-2")  # same state_dir, straight to mosquitto
        cloud.publish(f"thing/product/{GW}/services", request)  # the cloud's resend: same tid, same bid
        replies = wait_until(
            lambda: cloud.find("services_reply", lambda b: b.get("tid") == tid), 10, what="the resend's reply"
        )
        time.sleep(0.5)  # a second answer would be here by now
        replies = cloud.find("services_reply", lambda b: b.get("tid") == tid)
        assert len(replies) == 1 and replies[0]["data"]["result"] == 0, replies
        assert "answered from the reply journal" in gateway.output()
        gateway.stop()
        gateway = None
        assert _photos(sim) == 1  # acted on once, across the kill
    finally:
        if gateway is not None:
            gateway.stop(signal.SIGKILL)
        proxy.close()
        cloud.close()
        sim.stop()
