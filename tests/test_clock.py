"""One clock from GatewayApp down: timers driven by a ManualClock, without sleeping for them.

The unit part checks the clock itself (sleepers and waits move only when it is advanced, from any
thread). The rest runs the real gateway (a real mosquitto, a python-can virtual bus, the simulated
gimbal) on a ManualClock and shows that the timers of the parts it builds run on that clock: a device
request's deadline, the offline timeout of a silent device, an event re-send by the northbound's loop.
Each timer is set far longer than the test waits in real time, so a part that kept its own time fails.
"""

from __future__ import annotations

import asyncio
import threading
import time
from typing import Any

import pytest

from adapters.clock import SYSTEM_CLOCK, ManualClock, SystemClock
from adapters.rsdk.sim import GimbalCanSim
from gateway import clock as gateway_clock
from gateway.devices import DeviceTable
from gateway.local_broker import LocalBroker
from gateway.metrics import Metrics
from gateway.northbound import Northbound
from schemas import default_registry
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until

GW = "GW-TEST-1"


def test_gateway_clock_is_the_adapters_clock() -> None:
    assert gateway_clock.Clock is not None
    assert gateway_clock.ManualClock is ManualClock and gateway_clock.SystemClock is SystemClock
    assert gateway_clock.SYSTEM_CLOCK is SYSTEM_CLOCK


def test_manual_clock_sleep_and_wait_for_move_only_when_advanced() -> None:
    async def main() -> None:
        clock = ManualClock()
        woke: list[float] = []

        async def sleeper(seconds: float) -> None:
            await clock.sleep(seconds)
            woke.append(clock.monotonic())

        tasks = [asyncio.create_task(sleeper(s)) for s in (2.0, 1.0)]
        await asyncio.sleep(0)
        assert clock.sleepers == 2
        clock.advance(0.5)
        await asyncio.sleep(0)
        assert woke == []
        clock.advance(0.5)  # 1.0: the shorter one wakes, the other still sleeps
        await asyncio.sleep(0)
        assert woke == [1001.0] and clock.sleepers == 1
        clock.advance(5)
        await asyncio.gather(*tasks)
        assert woke == [1001.0, 1006.0]

        # wait_for: the result when it comes first; TimeoutError (and the awaitable cancelled) when the
        # clock passes the timeout first
        fut: asyncio.Future[int] = asyncio.get_running_loop().create_future()
        waiting = asyncio.create_task(clock.wait_for(fut, 3.0))
        await asyncio.sleep(0)
        fut.set_result(7)
        assert await waiting == 7
        never: asyncio.Future[int] = asyncio.get_running_loop().create_future()
        waiting = asyncio.create_task(clock.wait_for(never, 3.0))
        await asyncio.sleep(0)
        clock.advance(2.9)
        await asyncio.sleep(0)
        assert not waiting.done()
        clock.advance(0.2)
        with pytest.raises(TimeoutError):
            await waiting
        assert never.cancelled()
        assert clock.sleepers == 0

    asyncio.run(main())


def test_manual_clock_advanced_from_another_thread_wakes_the_loop() -> None:
    async def main() -> None:
        clock = ManualClock()
        task = asyncio.create_task(clock.sleep(10))
        await asyncio.sleep(0)
        threading.Thread(target=clock.advance, args=(10,)).start()
        await asyncio.wait_for(task, 5)  # woken through call_soon_threadsafe

    asyncio.run(main())


def test_northbound_loop_resends_an_event_on_the_manual_clock() -> None:
    """The northbound's periodic loop (``run``) waits on the clock: an event that asks for a reply is
    re-sent once the clock passes ``event_retry_interval`` (60 s: a real wait would fail the test)."""

    class Recorder:
        def __init__(self) -> None:
            self.sent: list[bytes] = []

        def publish(self, topic: str, payload: bytes, qos: int = 1, retain: bool = False) -> bool:
            if topic.endswith("/events"):  # (the gateway's own osd goes out on its schedule too)
                self.sent.append(payload)
            return True

    async def main() -> None:
        settings = gateway_settings(1883, [], dispatcher={"event_retries": 2, "event_retry_interval": 60.0})
        clock, out = ManualClock(), Recorder()
        nb = Northbound(settings=settings, registry=default_registry(), devices=DeviceTable([]), outbox=out,
                        clock=clock, metrics=Metrics())  # fmt: skip
        stop = asyncio.Event()
        runner = asyncio.create_task(nb.run(stop))
        nb.event(GW, "drc_status_notify", {"result": 0, "drc_state": 2}, need_reply=True)
        assert len(out.sent) == 1
        for _ in range(20):  # the loop turns on the clock's ticks only: nothing more without an advance
            await asyncio.sleep(0)
        assert len(out.sent) == 1
        for _ in range(int(60.5 / nb.tick_interval()) + 2):
            clock.advance(nb.tick_interval())
            await asyncio.sleep(0)
            await asyncio.sleep(0)
        assert len(out.sent) == 2 and out.sent[1] == out.sent[0]  # the same message, same tid
        stop.set()
        clock.advance(1)
        await asyncio.wait_for(runner, 5)

    asyncio.run(main())


@pytest.mark.broker
def test_gateway_on_a_manual_clock_device_deadline_and_offline_timeout(
    broker: LocalBroker, can_channel: str
) -> None:
    """GatewayApp(clock=) reaches the adapter: with the gimbal gone silent, a request fails on its
    deadline (2 s) only when the clock is advanced, and the gimbal goes offline (silence 60 s) only
    when the clock passes that; neither is waited for in real time."""
    clock = ManualClock()
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    cloud = CloudClient(broker.host, broker.port, GW)
    device: dict[str, Any] = {
        "type": "rsdk",
        "sn": "RSDK-CLOCK-1",
        "interface": "virtual",
        "channel": can_channel,
        "request_timeout": 2.0,
        "silence_timeout": 60.0,
    }
    settings = gateway_settings(broker.port, [device], dispatcher={"require_authority": False})
    try:
        with GatewayThread(settings, clock=clock) as gw:
            assert gw.app is not None
            gimbal = gw.app.devices.by_sn("RSDK-CLOCK-1")
            wait_until(lambda: gimbal.online, 10, what="gimbal online (no clock move)")
            # answered while the gimbal talks: the clock need not move for a reply that comes
            ok = cloud.service("x_rsdk_version_get", {"payload_index": "20-0-0"})
            assert ok["data"]["result"] == 0
            sim.stop()  # the gimbal falls silent; its CAN bus stays up
            tid = "clock-deadline-1"
            cloud.publish(f"thing/product/{GW}/services", {"tid": tid, "bid": "b", "timestamp": 0,
                          "method": "x_rsdk_version_get", "data": {"payload_index": "20-0-0"}})  # fmt: skip
            time.sleep(0.3)  # in real time nothing is due: the deadline is on the manual clock
            assert not cloud.find("services_reply", lambda b: b.get("tid") == tid)
            assert gw.app.dispatcher is not None and gw.app.dispatcher.in_flight == 1  # on its deadline
            started = time.monotonic()
            clock.advance(2.05)
            reply = cloud.wait_for("services_reply", lambda b: b.get("tid") == tid, timeout=1.5)[0]
            assert reply["data"]["result"] == 325004, reply  # device timeout
            assert time.monotonic() - started < 1.9  # sooner than the 2 s deadline in real time
            assert gimbal.online  # 2 s of silence is not 60
            cloud.clear()
            clock.advance(57.0)
            time.sleep(0.3)
            assert gimbal.online  # 59.05 s of silence: not yet over the timeout
            clock.advance(1.0)
            wait_until(lambda: not gimbal.online, 1.5, what="offline once the clock passes 60 s of silence")
            status = cloud.wait_for("status", lambda b: b["data"]["sub_devices"] == [], timeout=2)
            assert status
    finally:
        cloud.close()
        sim.stop()
