"""Exactly once across restarts: a ``camera_photo_take`` acted on by one gateway process is, when the cloud
resends it with the same tid to the next process (same ``state_dir``), answered from the reply journal
and not acted on again: the gimbal simulator counts one photo. The reply is written to the store before
it is published, so "acted on, then killed before replying" leaves the same store as this run does."""

from __future__ import annotations

import asyncio
import json
import time
import uuid
from pathlib import Path
from typing import Any

import pytest

from adapters.rsdk.sim import GimbalCanSim
from gateway.app import build_registry
from gateway.clock import ManualClock
from gateway.devices import DeviceTable
from gateway.dispatcher import Dispatcher
from gateway.local_broker import LocalBroker
from gateway.metrics import Metrics
from gateway.settings import DispatcherSettings
from gateway.store import StateStore
from schemas import TopicKind, topic
from tests.support import CloudClient, FakeAdapter, GatewayThread, gateway_settings, wait_until
from tests.test_dispatcher_limits import Recorder, SlowAdapter

GW = "GW-ONCE-1"
SN = "RSDK-ONCE-1"
PI = "20-0-0"


@pytest.mark.broker
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


# ------------------------------------------ started, never answered: the window before the reply is kept
def _request(tid: str, method: str, **data: Any) -> bytes:
    body = {
        "tid": tid,
        "bid": "b",
        "timestamp": 0,
        "method": method,
        "data": {"payload_index": "39-0-7", **data},
    }
    return json.dumps(body).encode()


def _process(store_dir: Path, clock: ManualClock) -> tuple[Dispatcher, SlowAdapter, Recorder, StateStore]:
    """One gateway process as far as the reply journal goes: a dispatcher on the store in ``store_dir``."""
    store = StateStore(store_dir, now_ms=clock.time_ms)
    adapter, out = SlowAdapter(), Recorder()
    devices = DeviceTable([adapter])
    devices.authority.payloads.add("39-0-7")
    d = Dispatcher(gateway_sn=GW, registry=build_registry(), devices=devices, outbox=out,
                   settings=DispatcherSettings(request_timeout=2.0), clock=clock, metrics=Metrics(),
                   journal=store)  # fmt: skip
    return d, adapter, out, store


def test_a_request_started_by_a_process_killed_before_its_reply_is_not_acted_on_again(tmp_path: Path) -> None:
    """The process acts (the device took the photo) and dies before the reply is kept: the store holds
    the tid's *started* mark. The next process answers the resend 399004 (outcome unknown, not repeated),
    keeps that answer, and gives it again to a further resend; the device is not asked again."""

    async def scenario() -> None:
        clock = ManualClock()
        services = topic(TopicKind.SERVICES, GW)
        d1, adapter1, out1, store1 = _process(tmp_path, clock)
        d1.submit(services, _request("photo-1", "camera_photo_take"))
        for _ in range(20):  # until the adapter is acting on it
            await asyncio.sleep(0)
        assert adapter1.calls == 1 and out1.replies == []
        store1.close()  # the process dies here: no reply kept, none published

        clock.advance(5.0)
        d2, adapter2, out2, store2 = _process(tmp_path, clock)
        await d2.handle(services, _request("photo-1", "camera_photo_take"))
        await d2.handle(services, _request("photo-1", "camera_photo_take"))  # the cloud resends again
        assert adapter2.calls == 0  # not acted on again
        assert [r["data"]["result"] for r in out2.replies] == [399004, 399004]
        assert out2.replies[0] == out2.replies[1]
        assert "not repeated" in out2.replies[0]["data"]["output"]["reason"]
        assert (
            d2.metrics.counters[("services_outcome_unknown_total", (("method", "camera_photo_take"),))] == 1
        )
        store2.close()

        # a third process: the 399004 answer was kept like any reply
        d3, adapter3, out3, store3 = _process(tmp_path, clock)
        await d3.handle(services, _request("photo-1", "camera_photo_take"))
        assert adapter3.calls == 0 and out3.replies == [out2.replies[0]]
        store3.close()

    asyncio.run(scenario())


def test_the_started_mark_goes_with_the_reply_and_ages_out(tmp_path: Path) -> None:
    clock = ManualClock()
    store = StateStore(tmp_path, now_ms=clock.time_ms)
    store.request_started("t-1", "camera_photo_take")
    assert store.started_request("t-1", 120_000) == "camera_photo_take"
    store.reply_recorded("t-1", b"reply")  # one transaction: the reply kept, the mark gone
    assert store.started_request("t-1", 120_000) is None and store.recorded_reply("t-1", 120_000) == b"reply"
    store.request_started("t-2", "camera_photo_take")
    clock.advance(121.0)
    assert store.started_request("t-2", 120_000) is None  # older than the journal's window: a new request
    assert store.replies_pruned(10, max_age_ms=120_000) == 1  # the reply; the stale mark goes too
    assert store.started_request("t-2", 10**9) is None
    store.close()

    async def scenario() -> None:
        services = topic(TopicKind.SERVICES, GW)
        d, adapter, out, store = _process(tmp_path, clock)
        adapter.release.set()
        await d.handle(services, _request("mode-1", "camera_mode_switch", camera_mode=1))
        await d.handle(services, _request("photo-2", "camera_photo_take"))
        assert [r["data"]["result"] for r in out.replies] == [0, 0]
        assert store.started_request("photo-2", 10**9) is None  # answered: no mark left
        store.close()

    asyncio.run(scenario())


class _Durability(StateStore):
    """The real store, noting how each reply was kept (a spy on our own class, not a library's)."""

    def __init__(self, directory: Path, clock: ManualClock) -> None:
        super().__init__(directory, now_ms=clock.time_ms)
        self.kept: dict[str, bool] = {}

    def reply_recorded(self, tid: str, payload: bytes, *, durable: bool = True) -> None:
        self.kept[tid] = durable
        super().reply_recorded(tid, payload, durable=durable)


def test_a_reads_reply_is_kept_without_waiting_for_the_disk_an_actions_with(tmp_path: Path) -> None:
    """A read (``*_get``) changes nothing, so its reply is committed without the fsync (it still outlives a
    killed process: tests/test_store.py); a request with a visible effect waits for the disk."""

    async def scenario() -> None:
        clock = ManualClock()
        store = _Durability(tmp_path, clock)
        adapter = FakeAdapter("READ-1", "39-0-7", {"x_rsdk_version_get": FakeAdapter.ok,
                                                    "camera_mode_switch": FakeAdapter.ok})  # fmt: skip
        devices = DeviceTable([adapter])
        devices.authority.payloads.add("39-0-7")
        out = Recorder()
        d = Dispatcher(gateway_sn=GW, registry=build_registry(), devices=devices, outbox=out,
                       settings=DispatcherSettings(request_timeout=2.0), clock=clock, metrics=Metrics(),
                       journal=store)  # fmt: skip
        services = topic(TopicKind.SERVICES, GW)
        await d.handle(services, _request("read-1", "x_rsdk_version_get"))
        await d.handle(services, _request("mode-1", "camera_mode_switch", camera_mode=1))
        assert [r["data"]["result"] for r in out.replies] == [0, 0], out.replies
        assert store.kept == {"read-1": False, "mode-1": True}
        store.close()
        again = StateStore(tmp_path, now_ms=clock.time_ms)  # both kept, whatever the wait
        assert again.recorded_reply("read-1", 10**9) is not None
        assert again.recorded_reply("mode-1", 10**9) is not None
        again.close()

    asyncio.run(scenario())
