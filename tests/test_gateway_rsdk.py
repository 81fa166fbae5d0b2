"""The first vertical slice, end to end: a cloud-side paho client → a real mosquitto → the gateway →
R SDK frames on a python-can bus → the simulated gimbal → reply, osd and topology back to the cloud."""

from __future__ import annotations

import time
from collections.abc import Iterator
from typing import Any

import pytest

from adapters.rsdk.sim import GimbalCanSim
from gateway.local_broker import LocalBroker
from tests.support import BusSniffer, CloudClient, GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker

GW = "GW-TEST-1"
SN = "RSDK-T-1"
PI = "20-0-0"


def _device(channel: str, **extra: Any) -> dict[str, Any]:
    return {
        "type": "rsdk",
        "sn": SN,
        "payload_index": PI,
        "interface": "virtual",
        "channel": channel,
        **extra,
    }


@pytest.fixture
def rig(broker: LocalBroker, can_channel: str) -> Iterator[dict[str, Any]]:
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    sniffer = BusSniffer(can_channel)
    cloud = CloudClient(broker.host, broker.port, GW)
    gw = GatewayThread(gateway_settings(broker.port, [_device(can_channel)])).start()
    try:
        cloud.wait_for("status", lambda b: any(d["sn"] == SN for d in b["data"]["sub_devices"]))
        yield {"sim": sim, "sniffer": sniffer, "cloud": cloud, "gw": gw, "channel": can_channel}
    finally:
        gw.stop()
        cloud.close()
        sniffer.close()
        sim.stop()


def _grab(cloud: CloudClient) -> None:
    assert cloud.service("payload_authority_grab", {"payload_index": PI})["data"]["result"] == 0


def _osd(cloud: CloudClient, predicate: Any, timeout: float = 5.0) -> dict[str, Any]:
    return cloud.wait_for(f"{SN}/osd", lambda b: predicate(b["data"]), timeout=timeout)[-1]["data"]


def test_topology_state_and_osd_after_connect(rig: dict[str, Any]) -> None:
    cloud = rig["cloud"]
    # the first topology (at connect) may precede the gimbal's first word; the next one names it
    topo = cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == 1)[0]
    assert topo["method"] == "update_topo" and topo["gateway"] == GW
    sub = topo["data"]["sub_devices"][0]
    assert (sub["sn"], sub["domain"], sub["type"]) == (SN, "1", 20)
    osd = _osd(cloud, lambda d: "gimbal_pitch" in d)
    assert osd["payload_index"] == PI and osd["cameras"][0]["recording_state"] == 0
    assert osd["x_angle_limits"]["pitch_max"] == 145.0 and osd["x_motor_stiffness"]["yaw"] == 50
    # the push was switched on by the gateway, and the version was asked once at start
    assert rig["sniffer"].names()["push_settings"] >= 1


def test_camera_methods_need_payload_authority(rig: dict[str, Any]) -> None:
    reply = rig["cloud"].service("camera_photo_take", {"payload_index": PI})
    assert reply["data"]["result"] == 319031
    assert rig["sim"].model.photos == 0
    state = rig["cloud"]
    _grab(state)
    st = state.wait_for(f"{SN}/state", lambda b: b["data"]["payloads"][0]["control_source"] == "A")[-1]
    assert st["data"]["payloads"][0] == {"control_source": "A", "payload_index": PI, "sn": SN}


def test_every_gimbal_method(rig: dict[str, Any]) -> None:
    cloud, sim, sniffer = rig["cloud"], rig["sim"], rig["sniffer"]
    model = sim.model
    _grab(cloud)

    def ok(method: str, **data: Any) -> dict[str, Any]:
        reply = cloud.service(method, {"payload_index": PI, **data})
        assert reply["data"]["result"] == 0, reply
        return reply

    ok("camera_photo_take")
    assert model.photos == 1
    sniffer.last("camera_control", lambda f: f["camera_control_command"] == 0x0001)

    ok("camera_recording_start")
    assert model.recording
    _osd(cloud, lambda d: d["cameras"][0]["recording_state"] == 1)
    ok("camera_recording_stop")
    assert not model.recording
    sniffer.last("camera_control", lambda f: f["camera_control_command"] == 0x0004)

    # seed 000 has no camera-mode command: "not supported", never a 0 for nothing sent
    refused = cloud.service("camera_mode_switch", {"payload_index": PI, "camera_mode": 1})["data"]
    assert refused["result"] == 399001 and "no camera mode command" in refused["output"]["reason"]

    # aim at the right edge of the view: yaw turns by half the horizontal field of view (70° → 35°)
    ok("camera_aim", camera_type="wide", locked=False, x=1.0, y=0.5)
    sent = sniffer.last("position_control", lambda f: f["yaw_angle"] == 350)
    assert sent["pitch_angle"] == 0 and sent["ctrl_byte"] == 0x04
    wait_until(lambda: abs(model.yaw.angle - 35.0) < 0.5, 3, what="gimbal yaw at 35°")
    _osd(cloud, lambda d: abs(d["gimbal_yaw"] - 35.0) < 0.5)

    # drag: speed control refreshed at >= 10 Hz while it lasts, then zero speed and release
    before = sniffer.names()["speed_control"]
    ok("camera_screen_drag", locked=False, pitch_speed=20.0, yaw_speed=0.0)
    start_pitch = model.pitch.angle
    wait_until(lambda: model.pitch.angle > start_pitch + 3, 3, what="pitch moving up")
    sniffer.last("speed_control", lambda f: f["ctrl_byte"] == 0x08)
    drag_frames = [f for n, f in sniffer.commands[-20:] if n == "speed_control"]
    assert sniffer.names()["speed_control"] - before >= 5  # first + refreshes + stop + release
    assert any(f["pitch_speed"] == 200 and f["ctrl_byte"] == 0x88 for f in drag_frames)
    assert drag_frames[-2] == {"yaw_speed": 0, "roll_speed": 0, "pitch_speed": 0, "ctrl_byte": 0x88}
    wait_until(lambda: model.pitch.speed == 0.0 and model.speed_until == 0.0, 3, what="gimbal released")
    settled = model.pitch.angle
    time.sleep(0.3)
    assert abs(model.pitch.angle - settled) < 0.01  # nothing moves after the drag

    ok("gimbal_reset", reset_mode=0)
    sniffer.last("recenter_selfie", lambda f: f["recenter_and_selfie_command"] == 0x01)
    wait_until(lambda: max(abs(a) for a in model.attitude()) < 0.5, 3, what="recentred")
    ok("gimbal_reset", reset_mode=3)
    sniffer.last(
        "position_control", lambda f: f["ctrl_byte"] == 0x01 | 0x02 | 0x04 and f["pitch_angle"] == -560
    )
    wait_until(lambda: abs(model.pitch.angle + 56) < 0.5, 3, what="pitch down")

    zoom = cloud.service(
        "camera_focal_length_set", {"payload_index": PI, "camera_type": "zoom", "zoom_factor": 4}
    )
    assert zoom["data"]["result"] == 399001 and "zoom" in zoom["data"]["output"]["reason"]


def test_extension_methods(rig: dict[str, Any]) -> None:
    cloud, model, sniffer = rig["cloud"], rig["sim"].model, rig["sniffer"]
    _grab(cloud)
    r = cloud.service("x_rsdk_stiffness_set", {"payload_index": PI, "pitch": 10, "roll": 20, "yaw": 30})
    assert r["data"]["result"] == 0
    r = cloud.service("x_rsdk_stiffness_get", {"payload_index": PI})
    assert r["data"] == {"result": 0, "output": {"pitch": 10, "roll": 20, "yaw": 30}}
    limits = {
        "pitch_max": 90,
        "pitch_min": 30,
        "yaw_max": 100,
        "yaw_min": 100,
        "roll_max": 20,
        "roll_min": 20,
    }
    r = cloud.service("x_rsdk_limit_angle_set", {"payload_index": PI, **limits})
    assert r["data"]["result"] == 0
    assert cloud.service("x_rsdk_limit_angle_get", {"payload_index": PI})["data"]["output"]["pitch_max"] == 90
    assert (
        cloud.service("x_rsdk_version_get", {"payload_index": PI})["data"]["output"]["version"]
        == "01.02.03.04"
    )
    assert cloud.service("x_rsdk_follow_mode_set", {"payload_index": PI, "mode": 3})["data"]["result"] == 0
    assert model.follow_mode == 3
    r = cloud.service(
        "x_rsdk_position_set", {"payload_index": PI, "yaw": -20.0, "pitch": 10.0, "duration": 0.2}
    )
    assert r["data"]["result"] == 0
    wait_until(lambda: abs(model.yaw.angle + 20) < 0.2 and abs(model.pitch.angle - 10) < 0.2, 3, what="moved")
    # commands the seed gives no reply frame: sent with CmdType 0, answered once on the bus
    assert cloud.service("x_rsdk_active_track_toggle", {"payload_index": PI})["data"]["result"] == 0
    wait_until(lambda: model.active_track, 3, what="tracking toggled")
    sniffer.last("active_track")
    assert sniffer.cmd_type_of("active_track") == 0
    r = cloud.service("x_rsdk_auto_calibration", {"payload_index": PI, "start": True})
    assert r["data"]["result"] == 0
    sent = sniffer.last("auto_calibration")
    assert sent["tlv_buffer"][0]["value"] == 0x03  # start, self-tuning type 1 (seed Figure 29's note)
    assert sniffer.cmd_type_of("auto_calibration") == 0
    gimbal = rig["gw"].app.devices.by_sn(SN)
    wait_until(lambda: gimbal.calibration == (2, 100), 6, what="calibration completed (0x0E 0x10 push)")
    assert model.calibration_type == 1 and model.calibrations_completed == 1
    # out of the seed's range for this device: refused by the contract before any frame is sent
    r = cloud.service("x_rsdk_stiffness_set", {"payload_index": PI, "pitch": 101, "roll": 0, "yaw": 0})
    assert r["data"]["result"] == 325001


def test_bad_input_gets_clear_errors_and_loses_nothing(rig: dict[str, Any]) -> None:
    cloud, model = rig["cloud"], rig["sim"].model
    services = f"thing/product/{GW}/services"
    _grab(cloud)

    # out of range, unknown payload, unknown method
    r = cloud.service(
        "camera_aim", {"payload_index": PI, "camera_type": "wide", "locked": False, "x": 2, "y": 0}
    )
    assert r["data"]["result"] == 325001 and "x" in r["data"]["output"]["reason"]
    r = cloud.service("camera_photo_take", {"payload_index": "9-9-9"})
    assert r["data"]["result"] == 325001 and PI in r["data"]["output"]["reason"]
    assert cloud.service("no_such_method", {})["data"]["result"] == 399002

    # malformed JSON whose tid can still be read, and garbage that has none
    cloud.publish(services, b'{"tid": "bad-json-1", "bid": "b1", "method": "camera_photo_take", "data": {')
    r = cloud.wait_for("services_reply", lambda b: b.get("tid") == "bad-json-1")[0]
    assert r["data"]["result"] == 325001 and r["method"] == "camera_photo_take"
    cloud.publish(services, b"\xff\x00 not json at all")

    # a huge payload is refused without parsing, and answered
    huge = (
        b'{"tid": "huge-1", "bid": "b", "method": "camera_photo_take", "data": {"pad": "'
        + b"x" * 70_000
        + b'"}}'
    )
    cloud.publish(services, huge)
    r = cloud.wait_for("services_reply", lambda b: b.get("tid") == "huge-1")[0]
    assert r["data"] == {"result": 325001, "output": {"reason": "payload too large"}}

    # a repeated tid is answered again, identically, and acted on once
    first = cloud.service("camera_photo_take", {"payload_index": PI}, tid="dup-1")
    photos = model.photos
    again = {"tid": "dup-1", "bid": first["bid"], "timestamp": 1, "method": "camera_photo_take"}
    cloud.publish(services, {**again, "data": {"payload_index": PI}})
    replies = cloud.wait_for("services_reply", lambda b: b.get("tid") == "dup-1", count=2)
    assert replies[0] == replies[1]
    assert model.photos == photos

    # and after all that the gateway still works
    assert cloud.service("camera_photo_take", {"payload_index": PI})["data"]["result"] == 0
    app = rig["gw"].app
    assert app.metrics.count("handler_exceptions_total") == 0
    assert app.metrics.count("inbound_rejected_total", reason="unanswerable") == 1
    assert app.metrics.count("inbound_rejected_total", reason="oversize") == 1


def test_device_timeout_and_disconnect(rig: dict[str, Any]) -> None:
    cloud, sim = rig["cloud"], rig["sim"]
    _grab(cloud)
    cloud.clear()
    sim.paused = True  # the gimbal stops answering (and pushing)
    t0 = time.monotonic()
    r = cloud.service("camera_photo_take", {"payload_index": PI})
    assert r["data"]["result"] == 325004 and time.monotonic() - t0 < 3
    # after the silence timeout the gimbal is offline: 325012 at once, and it leaves the topology
    cloud.wait_for("status", lambda b: all(d["sn"] != SN for d in b["data"]["sub_devices"]), timeout=6)
    t0 = time.monotonic()
    assert cloud.service("camera_photo_take", {"payload_index": PI})["data"]["result"] == 325012
    assert time.monotonic() - t0 < 1.0
    # it speaks again: back in the topology, and the next command works
    cloud.clear()
    sim.paused = False
    cloud.wait_for("status", lambda b: any(d["sn"] == SN for d in b["data"]["sub_devices"]), timeout=6)
    assert cloud.service("camera_photo_take", {"payload_index": PI})["data"]["result"] == 0
