"""Limits that keep one misbehaving device or cloud from starving the rest: the number of requests in
flight, a device that never answers, and the reply cache."""

from __future__ import annotations

import asyncio
import json
from typing import Any

from adapters.base import CallResult
from gateway.app import build_registry
from gateway.clock import ManualClock, SystemClock
from gateway.devices import DeviceTable
from gateway.dispatcher import Dispatcher
from gateway.metrics import Metrics
from gateway.settings import DispatcherSettings
from schemas import TopicKind, topic
from tests.support import FakeAdapter

GW = "GW-LIMITS-1"


class SlowAdapter(FakeAdapter):
    """Answers camera_photo_take only when released; camera_mode_switch at once."""

    def __init__(self) -> None:
        super().__init__("SLOW-1", "39-0-7", {"camera_photo_take": self._slow, "camera_mode_switch": self.ok})
        self.release = asyncio.Event()
        self.calls = 0

    async def _slow(self, data: Any) -> CallResult:
        self.calls += 1
        await self.release.wait()
        return CallResult()


class Recorder:
    def __init__(self) -> None:
        self.replies: list[dict[str, Any]] = []

    def publish(self, topic: str, payload: bytes, qos: int = 1, retain: bool = False) -> bool:
        self.replies.append(json.loads(payload))
        return True


def _request(tid: str, method: str, **data: Any) -> bytes:
    body = {
        "tid": tid,
        "bid": "b",
        "timestamp": 0,
        "method": method,
        "data": {"payload_index": "39-0-7", **data},
    }
    return json.dumps(body).encode()


def _dispatcher(settings: DispatcherSettings, clock: Any = None) -> tuple[Dispatcher, SlowAdapter, Recorder]:
    adapter, out = SlowAdapter(), Recorder()
    devices = DeviceTable([adapter])
    devices.authority.payloads.add("39-0-7")
    d = Dispatcher(gateway_sn=GW, registry=build_registry(), devices=devices, outbox=out, settings=settings,
                   clock=clock or SystemClock(), metrics=Metrics())  # fmt: skip
    return d, adapter, out


def test_too_many_requests_in_flight_get_busy_and_others_still_pass() -> None:
    async def scenario() -> None:
        d, adapter, out = _dispatcher(DispatcherSettings(max_pending=2, request_timeout=2.0))
        services = topic(TopicKind.SERVICES, GW)
        for i in range(2):
            d.submit(services, _request(f"slow-{i}", "camera_photo_take"))
        await asyncio.sleep(0.05)
        await d.handle(services, _request("third", "camera_photo_take"))  # the limit is reached: busy
        assert out.replies[-1]["tid"] == "third" and out.replies[-1]["data"]["result"] == 314000
        adapter.release.set()
        await d.drain()
        assert sorted(r["tid"] for r in out.replies if r["data"]["result"] == 0) == ["slow-0", "slow-1"]
        await d.handle(services, _request("after", "camera_mode_switch", camera_mode=1))
        assert out.replies[-1]["data"]["result"] == 0  # capacity is back
        assert adapter.calls == 2

    asyncio.run(scenario())


def test_a_device_that_never_answers_yields_325004_within_the_deadline() -> None:
    async def scenario() -> None:
        d, _, out = _dispatcher(DispatcherSettings(request_timeout=0.2))
        loop = asyncio.get_running_loop()
        t0 = loop.time()
        await d.handle(topic(TopicKind.SERVICES, GW), _request("hang", "camera_photo_take"))
        assert out.replies[-1]["data"]["result"] == 325004
        assert loop.time() - t0 < 1.0

    asyncio.run(scenario())


def test_the_reply_cache_expires() -> None:
    async def scenario() -> None:
        clock = ManualClock()
        d, adapter, out = _dispatcher(DispatcherSettings(reply_cache_seconds=5.0), clock)
        adapter.release.set()
        services = topic(TopicKind.SERVICES, GW)
        await d.handle(services, _request("same", "camera_photo_take"))
        await d.handle(services, _request("same", "camera_photo_take"))
        assert adapter.calls == 1 and len(out.replies) == 2 and out.replies[0] == out.replies[1]
        clock.advance(6.0)  # an old tid seen again after the cache window is a new request
        await d.handle(services, _request("same", "camera_photo_take"))
        assert adapter.calls == 2

    asyncio.run(scenario())


def test_a_request_a_broker_redelivers_after_its_ack_wait_is_not_acted_on_twice() -> None:
    """A QoS 1 request whose PUBACK was lost (the broker node died, or the connection moved) is delivered
    again when the broker's ack timer runs out: NATS's ``mqtt.ack_wait`` is 30 s by default, and the
    reply cache used to be 30 s too, so the copy arriving 30.008 s after the reply was acted on again
    (seen in ``test_brokers_cluster``: two photos for one tid). With the default settings the cache
    outlasts a few such redeliveries."""

    async def scenario() -> None:
        clock = ManualClock()
        d, adapter, out = _dispatcher(DispatcherSettings(), clock)
        adapter.release.set()
        services = topic(TopicKind.SERVICES, GW)
        await d.handle(services, _request("redelivered", "camera_photo_take"))
        for _ in range(3):  # NATS re-sends each ack_wait (30 s) until a PUBACK gets through
            clock.advance(30.01)
            await d.handle(services, _request("redelivered", "camera_photo_take"))
        assert adapter.calls == 1, adapter.calls
        assert len(out.replies) == 4 and all(r == out.replies[0] for r in out.replies)

    asyncio.run(scenario())
