"""Exactly once across restarts: a ``camera_photo_take`` acted on by one gateway process is, when the cloud
resends it with the same tid to the next process (same ``state_dir``), answered from the reply journal
and not acted on again: the gimbal simulator counts one photo. The reply is written to the store before
it is published, so "acted on, then killed before replying" leaves the same store as this run does."""

from __future__ import annotations

import json
import time
import uuid
from pathlib import Path
from typing import Any

import pytest

from adapters.rsdk.sim import GimbalCanSim
from gateway.local_broker import LocalBroker
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker

GW = "GW-ONCE-1"
SN = "RSDK-ONCE-1"
PI = "20-0-0"


def test_a_photo_resent_with_the_same_tid_after_a_restart_is_taken_once(
    private_broker: LocalBroker, can_channel: str, tmp_path: Path
) -> None:
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    settings = gateway_settings(
        private_broker.port,
        [{"type": "rsdk", "sn": SN, "interface": "virtual", "channel": can_channel}],
        gateway_sn=GW,
        state_dir=str(tmp_path),
    )
    cloud = CloudClient(private_broker.host, private_broker.port, GW)
    request: dict[str, Any] = {
        "tid": str(uuid.uuid4()),
        "bid": str(uuid.uuid4()),
        "timestamp": int(time.time() * 1000),
        "method": "camera_photo_take",
        "data": {"payload_index": PI},
    }

    def photos() -> int:
        with sim.node.lock:
            return sim.model.photos

    def replies() -> list[dict[str, Any]]:
        return cloud.find("services_reply", lambda b: b.get("tid") == request["tid"])

    try:
        with GatewayThread(settings) as gw:
            assert gw.app is not None
            wait_until(lambda: gw.app.devices.by_sn(SN).online, 5, what="gimbal online")
            assert cloud.service("payload_authority_grab", {"payload_index": PI})["data"]["result"] == 0
            cloud.publish(f"thing/product/{GW}/services", request)
            wait_until(replies, 5, what="the first reply")
        first = replies()[0]
        assert first["data"]["result"] == 0 and photos() == 1

        # the next process, same state directory: the resent request (same tid, same bid)
        with GatewayThread(gateway_settings(
            private_broker.port,
            [{"type": "rsdk", "sn": SN, "interface": "virtual", "channel": can_channel}],
            gateway_sn=GW,
            state_dir=str(tmp_path),
        )) as gw2:  # fmt: skip
            assert gw2.app is not None
            wait_until(lambda: gw2.app.devices.by_sn(SN).online, 5, what="gimbal online again")
            cloud.publish(f"thing/product/{GW}/services", request)
            wait_until(lambda: len(replies()) == 2, 5, what="the reply to the resent request")
            again = replies()[1]
            assert json.dumps(again, sort_keys=True) == json.dumps(first, sort_keys=True)  # the same reply
            # a request with a new tid still acts (the journal answers only what it answered before)
            assert cloud.service("payload_authority_grab", {"payload_index": PI})["data"]["result"] == 0
            assert cloud.service("camera_photo_take", {"payload_index": PI})["data"]["result"] == 0
            assert photos() == 2
            duplicates = gw2.app.metrics.counters.get(("services_duplicates_total", ()), 0)
            assert duplicates == 1
        assert photos() == 2  # the resent request took no photo
    finally:
        cloud.close()
        sim.stop()
