"""The obstacle push's resampling (gateway.drc.around_distances) and live control's authority answers on
a gimbal-only gateway, without a broker."""

from __future__ import annotations

import asyncio
import json

from gateway.devices import DeviceTable
from gateway.drc import around_distances
from tests.support import FakeAdapter, RecordingOutbox, drc_controller, live_drc_session


def test_four_sectors_fill_360_bins_clockwise_from_the_nose() -> None:
    readings = {"front": (1.0, True), "right": (2.0, True), "back": (3.5, True), "left": (4.25, False)}
    bins = around_distances(readings)
    assert len(bins) == 360
    assert {bins[d] for d in (*range(0, 45), *range(315, 360))} == {1000}
    assert {bins[d] for d in range(45, 135)} == {2000}
    assert {bins[d] for d in range(135, 225)} == {3500}
    assert {bins[d] for d in range(225, 315)} == {0}  # a sensor that does not work reads nothing
    assert around_distances({**readings, "front": (float("nan"), True)})[0] == 0


def test_sticks_without_payload_authority_on_a_gimbal_only_gateway_answer_319031() -> None:
    gimbal = FakeAdapter("GIMBAL-1", "39-0-7", {})  # domain 1: a payload, no aircraft here
    devices = DeviceTable([gimbal])
    devices.authority.payloads.add("39-0-7")
    loop = asyncio.new_event_loop()
    try:
        up = RecordingOutbox()
        drc = drc_controller(devices, up, loop, "GW-HSI")
        sid = live_drc_session(drc)
        devices.authority.payloads.clear()  # the cloud lost payload authority
        drc.handle_down(b'{"method":"drone_control","data":{"seq":1,"w":10}}', sid, up)
    finally:
        loop.close()
    reply = json.loads(up.payloads()[-1])
    assert reply["method"] == "drone_control" and reply["data"]["result"] == 319031
    assert reply["data"]["output"]["seq"] == 1
