"""A gimbal that answers badly, through the whole gateway: the cloud → mosquitto → the gateway → a
python-can bus → the simulated gimbal with :class:`~adapters.rsdk.sim.ReplyFaults` switched on.

Each bad answer (CRC error, a frame cut short, a duplicate, a reply after the deadline, a reply with
another request's seq, CAN error frames around it) gets the cloud one clear result per request
(325004 when no usable answer came), is counted on the link, is never applied to another request, and
leaves the next request working. The gimbal's parameter push stays intact throughout, so it stays
online: these are bad answers, not a dead device (that is ``test_gateway_rsdk::test_device_timeout…``).
"""

from __future__ import annotations

import json
import time
import uuid
from collections.abc import Iterator
from typing import Any

import pytest

from adapters.base import LinkStats
from adapters.rsdk.sim import GimbalCanSim, ReplyFaults
from gateway.local_broker import LocalBroker
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker

GW = "GW-FAULTS-1"
SN = "RSDK-F-1"
PI = "20-0-0"
TIMEOUT = 325004


class Rig:
    def __init__(self, sim: GimbalCanSim, cloud: CloudClient, gw: GatewayThread) -> None:
        self.sim, self.cloud, self.gw = sim, cloud, gw
        assert gw.app is not None
        self.adapter = gw.app.devices.by_sn(SN)

    def link(self) -> LinkStats:
        stats = self.gw.call(self.adapter.link_stats)
        assert stats is not None
        return stats

    def send(self, method: str, data: dict[str, Any] | None = None) -> str:
        """Publish one service without waiting (several can be in flight); returns its tid."""
        tid = str(uuid.uuid4())
        body = {"tid": tid, "bid": str(uuid.uuid4()), "timestamp": int(time.time() * 1000), "method": method,
                "data": {"payload_index": PI, **(data or {})}}  # fmt: skip
        self.cloud.publish(f"thing/product/{GW}/services", json.dumps(body))
        return tid

    def result(self, tid: str) -> int:
        reply = self.cloud.wait_for("services_reply", lambda b: b.get("tid") == tid)[-1]
        return int(reply["data"]["result"])

    def replies(self, tid: str) -> int:
        return len(self.cloud.find("services_reply", lambda b: b.get("tid") == tid))

    def photo(self) -> int:
        return self.result(self.send("camera_photo_take"))

    def photos_taken(self) -> int:
        with self.sim.node.lock:
            return self.sim.model.photos

    def answer_with(self, faults: ReplyFaults) -> None:
        with self.sim.node.lock:
            self.sim.model.faults = faults


@pytest.fixture
def rig(broker: LocalBroker, can_channel: str) -> Iterator[Rig]:
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    cloud = CloudClient(broker.host, broker.port, GW)
    device = {"type": "rsdk", "sn": SN, "payload_index": PI, "interface": "virtual", "channel": can_channel}
    gw = GatewayThread(gateway_settings(broker.port, [device], gateway_sn=GW)).start()
    try:
        cloud.wait_for("status", lambda b: any(d["sn"] == SN for d in b["data"]["sub_devices"]))
        r = Rig(sim, cloud, gw)
        assert cloud.service("payload_authority_grab", {"payload_index": PI})["data"]["result"] == 0
        wait_until(lambda: r.adapter.online and r.adapter.attitude is not None, 5, what="the gimbal's push")
        yield r
    finally:
        gw.stop()
        cloud.close()
        sim.stop()


@pytest.mark.parametrize(
    ("fault", "counter"),
    [(ReplyFaults(corrupt_crc=True), "crc_errors"), (ReplyFaults(truncate=True), "framing_errors")],
    ids=["crc-error", "truncated"],
)
def test_an_unreadable_reply_is_dropped_and_the_request_times_out(
    rig: Rig, fault: ReplyFaults, counter: str
) -> None:
    before = getattr(rig.link(), counter)
    rig.answer_with(fault)
    assert rig.photo() == TIMEOUT
    # the broken reply is counted once the decoder sees where it ends (at the next push, 10 Hz)
    wait_until(
        lambda: getattr(rig.link(), counter) > before, 3, what=f"the broken reply counted in {counter}"
    )
    assert rig.photos_taken() == 1  # the gimbal acted; the gateway did not send the command again
    assert rig.adapter.online  # its pushes are intact
    rig.answer_with(ReplyFaults())
    assert rig.photo() == 0 and rig.photos_taken() == 2


def test_a_duplicated_reply_answers_once(rig: Rig) -> None:
    before = rig.link().unmatched_replies
    rig.answer_with(ReplyFaults(duplicate=True))
    first = rig.send("camera_photo_take")
    assert rig.result(first) == 0
    # the next request's reply comes behind the duplicate (one bus, one loop, one MQTT session)
    assert rig.photo() == 0
    assert rig.replies(first) == 1
    assert rig.link().unmatched_replies == before + 2  # one duplicate per request
    assert rig.photos_taken() == 2


def test_a_reply_after_the_deadline_matches_nothing_later(rig: Rig) -> None:
    before = rig.link().unmatched_replies
    rig.answer_with(ReplyFaults(delay=0.8))  # request_timeout is 0.3 s
    t0 = time.monotonic()
    assert rig.photo() == TIMEOUT
    assert time.monotonic() - t0 < 2.0
    rig.answer_with(ReplyFaults())
    wait_until(
        lambda: rig.link().unmatched_replies == before + 1, 3, what="the late reply arrived and was dropped"
    )
    # the next request gets its own reply, not the late one
    assert rig.result(rig.send("x_rsdk_stiffness_get")) == 0
    assert rig.link().unmatched_replies == before + 1


def test_a_reply_with_another_requests_seq_is_never_misapplied(rig: Rig) -> None:
    """Replies carry seq + 1, and come 0.1 s late (within the deadline) so that both requests are in
    flight: the photo's reply lands on the seq of the stiffness query. Its command set and id give it
    away, so the query does not take the photo's answer (nor fail on it): both time out."""
    before = rig.link().unmatched_replies
    rig.answer_with(ReplyFaults(seq_offset=1, delay=0.1))
    photo, stiffness = rig.send("camera_photo_take"), rig.send("x_rsdk_stiffness_get")
    assert (rig.result(photo), rig.result(stiffness)) == (TIMEOUT, TIMEOUT)
    wait_until(lambda: rig.link().unmatched_replies >= before + 2, 3, what="both replies dropped")
    assert rig.photos_taken() == 1
    rig.answer_with(ReplyFaults())
    photo, stiffness = rig.send("camera_photo_take"), rig.send("x_rsdk_stiffness_get")
    assert (rig.result(photo), rig.result(stiffness)) == (0, 0)


def test_can_error_frames_around_replies_are_ignored(rig: Rig) -> None:
    rig.sim.error_frames = True
    before = rig.link()
    for _ in range(3):
        assert rig.photo() == 0
    after = rig.link()
    assert rig.photos_taken() == 3
    assert (after.crc_errors, after.framing_errors, after.unmatched_replies) == (
        before.crc_errors, before.framing_errors, before.unmatched_replies)  # fmt: skip


def test_fault_specs_of_the_simulator_cli() -> None:
    f = ReplyFaults.parse(["crc", "duplicate", "seq=-2", "delay=0.5"])
    assert (f.corrupt_crc, f.truncate, f.duplicate, f.seq_offset, f.delay) == (True, False, True, -2, 0.5)
    for bad in ("crc=1", "seq=x", "delay=-1", "delay=nan", "loud"):
        with pytest.raises(ValueError, match="unknown fault"):
            ReplyFaults.parse([bad])
