"""Stop commands are accepted in every shape a cloud sends, and never refused for a parsing reason:
``"data": {}``, ``""`` (DJI's reference cloud), ``null``, no ``data`` at all, and data that cannot be
parsed. Services through the dispatcher; ``drone_emergency_stop`` through the DRC controller, five
times over (the reference cloud publishes every DRC message five times)."""

from __future__ import annotations

import asyncio
import json
from typing import Any

import pytest

from adapters.base import CallResult
from gateway import drc_session as ds
from gateway.app import build_registry
from gateway.clock import SystemClock
from gateway.devices import DeviceTable
from gateway.dispatcher import Dispatcher
from gateway.metrics import Metrics
from gateway.settings import DispatcherSettings
from schemas import TopicKind, topic
from tests.support import FakeAdapter, RecordingOutbox, drc_controller, live_drc_session

GW = "GW-STOP-1"
_ABSENT = object()
SHAPES: list[Any] = [{}, "", None, _ABSENT, 5, [1, 2], "garbage", {"unexpected": True}]
IDS = ["object", "empty-string", "null", "absent", "number", "list", "string", "extra-field"]


class StopCounter(FakeAdapter):
    def __init__(self) -> None:
        super().__init__("STOP-DEV", "39-0-7", {"fly_to_point_stop": self._stop})
        self.stops = 0

    async def _stop(self, data: Any) -> CallResult:
        self.stops += 1
        return CallResult()


class FakeDrc:
    def __init__(self) -> None:
        self.exits = 0

    async def exit(self) -> tuple[int, None]:
        self.exits += 1
        return 0, None


def _message(method: str, data: Any, **envelope: Any) -> bytes:
    body: dict[str, Any] = {"tid": "t-1", "bid": "b-1", "timestamp": 1, "method": method, **envelope}
    if data is not _ABSENT:
        body["data"] = data
    return json.dumps(body).encode()


@pytest.mark.parametrize("data", SHAPES, ids=IDS)
@pytest.mark.parametrize("method", ["fly_to_point_stop", "drc_mode_exit"])
def test_a_stop_service_in_any_shape_stops_and_is_answered_0(method: str, data: Any) -> None:
    device, drc, out, metrics = StopCounter(), FakeDrc(), RecordingOutbox(), Metrics()
    dispatcher = Dispatcher(
        gateway_sn=GW,
        registry=build_registry(),
        devices=DeviceTable([device]),
        outbox=out,
        settings=DispatcherSettings(require_authority=False),
        clock=SystemClock(),
        metrics=metrics,
        drc=drc,
    )
    asyncio.run(dispatcher.handle(topic(TopicKind.SERVICES, GW), _message(method, data)))
    replies = [json.loads(p) for t, p in out.sent if t.endswith("/services_reply")]
    assert [(r["tid"], r["method"], r["data"]["result"]) for r in replies] == [("t-1", method, 0)]
    assert (device.stops, drc.exits) == ((1, 0) if method == "fly_to_point_stop" else (0, 1))
    tolerated = metrics.count("services_stops_obeyed_total", method=method)
    assert tolerated == (0 if data in ({}, "", None, _ABSENT) or isinstance(data, dict) else 1)


def test_a_service_with_parameters_and_empty_string_data_names_the_missing_field() -> None:
    out = RecordingOutbox()
    dispatcher = Dispatcher(
        gateway_sn=GW,
        registry=build_registry(),
        devices=DeviceTable([StopCounter()]),
        outbox=out,
        settings=DispatcherSettings(require_authority=False),
        clock=SystemClock(),
        metrics=Metrics(),
    )
    asyncio.run(dispatcher.handle(topic(TopicKind.SERVICES, GW), _message("fly_to_point", "")))
    reply = json.loads(out.sent[-1][1])
    assert reply["data"]["result"] == 325001 and "fly_to_id" in reply["data"]["output"]["reason"]


class Braked(FakeAdapter):
    def __init__(self) -> None:
        super().__init__("BRAKE-DEV", "39-0-7", {})
        self.braked = 0

    def emergency_stop(self) -> None:
        self.braked += 1


@pytest.mark.parametrize("data", SHAPES, ids=IDS)
def test_emergency_stop_in_any_shape_five_times_stops_once_and_answers_each(data: Any) -> None:
    device, up = Braked(), RecordingOutbox()
    devices = DeviceTable([device])
    devices.authority.payloads.add("39-0-7")
    loop = asyncio.new_event_loop()
    try:
        drc = drc_controller(devices, up, loop, GW)
        sid = live_drc_session(drc)
        drc.start()
        body = {"method": "drone_emergency_stop"}
        if data is not _ABSENT:
            body["data"] = data
        for _ in range(5):
            drc.handle_down(json.dumps(body).encode(), sid, up)
        assert drc.session.state is ds.State.HOLDING and drc.session.setpoint == ds.ZERO
        drc.writer.stop()  # sends what is pending, then ends
        assert drc.writer.setpoint == ds.ZERO and device.braked == 1
    finally:
        loop.close()
    replies = [json.loads(p) for p in up.payloads()]
    assert [(r["method"], r["data"]["result"]) for r in replies] == [("drone_emergency_stop", 0)] * 5
