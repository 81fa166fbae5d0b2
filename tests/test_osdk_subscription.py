"""Onboard SDK data subscription (0x0B, pushes 0x02 0x05): the topic table and payloads against byte
vectors produced by DJI's Onboard-SDK 3.9.0 (tag 3.9.0, commit 295915e6), and the simulated flight
controller driven the way that library drives a real A3: verify, add package, pushes decoded at the
package's offsets, remove, reset.

Where the vectors come from (the library is not needed to run these tests): a throw-away program
linked against the library's ``libdjiosdk-core.a`` printed ``sizeof`` of every ``TypeMap<topic>::type``,
the bytes ``SubscriptionPackage::serializePackageInfo`` writes for the packages DJI's telemetry,
flight-control and mission samples (and ``Vehicle::initGimbal``) subscribe, and the bytes of typed
structs (``GPSFused``, ``GimbalStatus``, ``EscData``...) filled with the values written next to them.
"""

from __future__ import annotations

import math
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from adapters.errors import LayoutError, UnknownCommandError
from adapters.osdk import commands as cmds
from adapters.osdk import subscription as sub
from adapters.osdk.protocol import encode_command
from adapters.osdk.sim import NOT_ACTIVATED_ACK, SUBSCRIBE_REFUSED_ACK, OsdkFcModel
from tests.test_osdk_sim import APP_ID, TAKEOFF, FakeHost

# sizeof(TypeMap<TOPIC_...>::type), OSDK 3.9.0 headers, packed (g++ on x86-64).
LIBRARY_SIZES = {
    "quaternion": 16, "acceleration_ground": 12, "acceleration_body": 12, "acceleration_raw": 12,
    "velocity": 13, "angular_rate_fusioned": 12, "angular_rate_raw": 12, "altitude_fusioned": 4,
    "altitude_barometer": 4, "height_homepoint": 4, "height_fusion": 4, "gps_fused": 22, "gps_date": 4,
    "gps_time": 4, "gps_position": 12, "gps_velocity": 12, "gps_details": 36, "rtk_position": 20,
    "rtk_velocity": 12, "rtk_yaw": 2, "rtk_position_info": 1, "rtk_yaw_info": 1, "compass": 6, "rc": 12,
    "gimbal_angles": 12, "gimbal_status": 4, "status_flight": 1, "status_displaymode": 1,
    "status_landinggear": 1, "status_motor_start_error": 2, "battery_info": 13, "control_device": 2,
    "hard_sync": 55, "gps_signal_level": 1, "gps_control_level": 1, "rc_full_raw_data": 44,
    "rc_with_flag_data": 17, "esc_data": 80, "rtk_connect_status": 2, "gimbal_control_mode": 1,
    "flight_anomaly": 4, "position_vo": 13, "avoid_data": 25, "home_point_set_status": 1,
    "home_point_info": 16,
}  # fmt: skip

# serializePackageInfo(): (package id, topics, Hz, time stamp) -> bytes, and getBufferSize().
_RTK = ["rtk_position", "rtk_yaw_info", "rtk_position_info", "rtk_velocity", "rtk_yaw"]
_NEWER = [
    "rc", "rc_full_raw_data", "rc_with_flag_data", "esc_data", "rtk_connect_status", "gimbal_control_mode",
    "flight_anomaly", "position_vo", "avoid_data", "home_point_set_status", "home_point_info",
]  # fmt: skip
# fmt: off
LIBRARY_PACKAGES: list[tuple[str, int, list[str], int, bool, str, int]] = [
    ("initGimbal", 0, ["gimbal_status"], 50, False, "00320000015cd46c8b", 4),
    ("telemetry 0", 0, ["status_flight"], 1, False, "00010000012ab0cf20", 1),
    ("telemetry 1", 1, ["gps_fused", "altitude_fusioned"], 10, False, "010a000002c7a8194b1ac8e911", 26),
    ("telemetry 2", 2, ["rc", "velocity"], 50, False, "0232000002e47f9f731d27fb18", 25),
    ("telemetry 3", 3, ["quaternion"], 200, False, "03c80000011f2893a4", 16),
    ("telemetry 4", 4, _RTK, 5, False, "0405000005b6a6f91de3b972cbb5574adac3133d76fd735df4", 36),
    ("take-off", 0, ["status_flight", "status_displaymode"], 10, False, "000a0000022ab0cf20a1d6671a", 2),
    ("position", 0, ["quaternion", "gps_fused"], 50, False, "00320000021f2893a4c7a8194b", 38),
    ("mission", 0, ["gps_fused"], 10, False, "000a000001c7a8194b", 22),
    ("telemetry b", 0, _NEWER, 50, False,
     "003200000be47f9f730e4dec16cdcf04fe89f5a0aa2693346f6d446a324b4b620a972646d3"
     "aa5d40f61f21c2b520b5e4bf", 215),
    ("time stamp", 2, ["quaternion"], 100, True, "02640001011f2893a4", 24),
]

# Typed structs filled in C++ -> their bytes; the same values as our fields.
LIBRARY_STRUCTS: list[tuple[str, dict[str, Any], str]] = [
    ("gps_fused", {"longitude": 1.9889, "latitude": 0.39345, "altitude": 51.25, "visible_satellites": 18},
     "fb3a70ce88d2ff3fe71da7e8482ed93f00004d421200"),
    ("velocity", {"x": 1.5, "y": -2.0, "z": 0.25, "health": 1, "reserved": 0}, "0000c03f000000c00000803e01"),
    ("gimbal_status", {"mounted": 1, "esc_pitch_ok": 1, "esc_roll_ok": 1, "esc_yaw_ok": 1,
                       "drone_data_received": 1, "init_complete": 1}, "01f80000"),
    ("control_device", {"control_mode": 3, "device_status": 2, "flight_status": 1}, "030a"),
    ("rc_with_flag_data", {"pitch": 0.5, "roll": -0.25, "yaw": 0.0, "throttle": 0.125, "logic_connected": 1,
                           "sky_connected": 1, "ground_connected": 1}, "0000003f000080be000000000000003e07"),
    ("esc_data", {"esc0_current": 3000, "esc0_speed": 2500, "esc0_voltage": 48000, "esc0_temperature": 40,
                  "esc7_disconnected": 1}, "b80bc40980bb2800" + "00" * 70 + "0800"),
    ("position_vo", {"x": 3.0, "y": -4.0, "z": -10.0, "x_health": 1, "y_health": 1, "z_health": 1},
     "00004040000080c0000020c107"),
    ("rtk_connect_status", {"rtk_connected": 1}, "0100"),
    ("flight_anomaly", {"strong_wind_level1": 1, "gps_yaw_error": 1}, "40100000"),
    ("gps_position", {"latitude": 225431000, "longitude": 1139580000, "altitude": 50000},
     "d8cd6f0d609cec4350c30000"),
    ("hard_sync", {"time_2p5ms": 400, "time_ns": 5, "reset_time_2p5ms": 399, "index": 7, "flag": 1,
                   "q_w": 1.0, "accel_z": -1.0, "gyro_z": 0.5},
     "90010000050000008f0100000700010000803f0000000000000000000000000000000000000000000080bf"
     "00000000000000000000003f"),
    ("home_point_info", {"latitude": 0.39345, "longitude": 1.9889}, "e71da7e8482ed93ffb3a70ce88d2ff3f"),
    ("battery_info", {"capacity": 4500, "voltage": 50100, "current": -18000, "percentage": 95},
     "94110000b4c30000b0b9ffff5f"),
]
# fmt: on


def _frame(payload: bytes, cmd_id: int, seq: int) -> bytes:
    return encode_command(0x0B, cmd_id, payload, 2, seq)


# ---------------------------------------------------------------------------------------------- table


def test_every_topic_has_the_library_size_and_a_unique_uid() -> None:
    assert {t.name: t.size for t in sub.TOPICS} == LIBRARY_SIZES
    assert len({t.uid for t in sub.TOPICS}) == len(sub.TOPICS) == 45
    for t in sub.TOPICS:
        assert 1 <= t.max_freq <= 400 and t.codec.size == t.size
        example = t.codec.example()
        assert t.codec.decode(t.codec.encode(example)) == example


@pytest.mark.parametrize(("what", "pid", "topics", "hz", "stamp", "hexbytes", "size"), LIBRARY_PACKAGES)
def test_add_package_is_what_the_library_serializes(
    what: str, pid: int, topics: list[str], hz: int, stamp: bool, hexbytes: str, size: int
) -> None:
    fields = sub.add_package_fields(pid, topics, hz, timestamp=stamp)
    payload = cmds.encode_request("subscribe_add_package", fields)
    assert payload == bytes.fromhex(hexbytes), what
    assert cmds.decode_request(0x0B, 0x01, payload).fields == fields
    assert sub.package_size(topics, timestamp=stamp) == size


def test_verify_reset_remove_payloads() -> None:
    assert cmds.encode_request("subscribe_verify", {"version": sub.DB_VERSION}) == bytes.fromhex("00010000")
    assert cmds.encode_request("subscribe_reset", {}) == b"\x00"
    assert cmds.encode_request("subscribe_remove_package", {"package_id": 3}) == b"\x03"
    for name in ("subscribe_verify", "subscribe_add_package", "subscribe_reset", "subscribe_remove_package"):
        spec = cmds.spec_for(name)
        assert spec.reply_codes is sub.SUBSCRIBE_ACK and spec.variant == "new"
        assert cmds.decode_ack(name, b"\x25").fields == {"ack": 0x25}
        with pytest.raises(UnknownCommandError):
            cmds.spec_for(name, "m100")  # the library never subscribes on an M100
    assert sub.SUBSCRIBE_ACK[0x25] == "source device offline" and sub.SUBSCRIBE_ACK[0x23] == "permission deny"
    with pytest.raises(LayoutError, match="whole number"):
        cmds.decode_request(0x0B, 0x01, bytes.fromhex("000a000001c7a819"))  # a UID cut short


@pytest.mark.parametrize(("name", "fields", "hexbytes"), LIBRARY_STRUCTS, ids=[s[0] for s in LIBRARY_STRUCTS])
def test_topic_layouts_are_the_library_structs(name: str, fields: dict[str, Any], hexbytes: str) -> None:
    codec = sub.BY_NAME[name].codec
    raw = bytes.fromhex(hexbytes)
    assert codec.encode(fields) == raw
    decoded = codec.decode(raw)
    for key, value in fields.items():
        assert decoded[key] == pytest.approx(value, rel=1e-6), key
    assert all(v == 0 for k, v in decoded.items() if k not in fields)


topic_lists = st.lists(st.sampled_from(sub.TOPICS), min_size=1, max_size=8)


@given(topic_lists, st.booleans(), st.data())
def test_package_data_round_trips(topics: list[sub.Topic], stamp: bool, data: st.DataObject) -> None:
    """Any package: encode_package lays each topic at the library's offsets, decode_package reads it back."""
    values = {t.name: t.codec.decode(data.draw(st.binary(min_size=t.size, max_size=t.size))) for t in topics}
    values = {
        k: v for k, v in values.items() if not any(isinstance(x, float) and math.isnan(x) for x in v.values())
    }
    topics = [t for t in topics if t.name in values]
    if not topics:
        return
    ts = {"time_ms": 1234, "time_ns": 5} if stamp else None
    raw = sub.encode_package(values, topics, timestamp=ts)
    assert len(raw) == sub.package_size(topics, timestamp=stamp)
    out = sub.decode_package(raw, topics, timestamp=stamp)
    offset = 8 if stamp else 0
    for t in topics:  # each topic at the offset the library computes (setTopicList)
        assert raw[offset : offset + t.size] == t.codec.encode(values[t.name])
        offset += t.size
    assert {k: v for k, v in out.items() if k != "timestamp"} == {t.name: values[t.name] for t in topics}
    with pytest.raises(LayoutError):
        sub.decode_package(raw + b"\x00", topics, timestamp=stamp)


@settings(max_examples=200)
@given(st.integers(0, 6), st.binary(max_size=64))
def test_random_subscription_payloads_decode_or_raise_layout_error(cmd_id: int, payload: bytes) -> None:
    try:
        cmds.decode_request(0x0B, cmd_id, payload)
        cmds.decode_request(0x02, 0x05, payload)
    except (UnknownCommandError, LayoutError):
        pass


# -------------------------------------------------------------------------------------------- the FC's rules


def _add(fc: sub.FcSubscriptions, pid: int, topics: list[str], hz: int, **kw: Any) -> int:
    fields = sub.add_package_fields(pid, topics, hz) | kw
    return fc.handle("subscribe_add_package", fields, 0.0)["ack"]


def test_add_package_refusals_in_order() -> None:
    fc = sub.FcSubscriptions()
    assert _add(fc, 5, ["quaternion"], 10) == sub.PACKAGE_OUT_OF_RANGE
    assert _add(fc, 0, ["quaternion"], 10) == sub.SUCCESS
    assert _add(fc, 0, ["quaternion"], 10) == sub.PACKAGE_ALREADY_EXISTS
    assert _add(fc, 1, [], 10) == sub.PACKAGE_EMPTY
    assert _add(fc, 1, ["quaternion"], 10, topic_count=2) == sub.INCORRECT_NUM_OF_TOPICS
    assert _add(fc, 1, [], 10, topic_count=1, uids=[0x12345678]) == sub.ILLEGAL_UID
    assert _add(fc, 1, ["quaternion"], 10, config=2) == sub.ILLEGAL_DATA_LENGTH
    assert _add(fc, 1, ["gps_fused"], 100) == sub.ILLEGAL_FREQUENCY  # GPS fused tops at 50 Hz
    assert _add(fc, 1, ["quaternion"], 0) == sub.ILLEGAL_FREQUENCY
    assert _add(fc, 1, ["esc_data", "esc_data", "esc_data", "quaternion"], 10) == sub.PACKAGE_TOO_LARGE
    assert _add(fc, 1, ["rtk_position", "rtk_yaw"], 5) == sub.SOURCE_DEVICE_OFFLINE
    assert sorted(fc.packages) == [0]
    assert sub.FcSubscriptions(offline=frozenset()).handle(
        "subscribe_add_package", sub.add_package_fields(4, ["rtk_position"], 5), 0.0
    ) == {"ack": sub.SUCCESS}  # with an RTK module
    assert fc.refused[sub.ILLEGAL_FREQUENCY] == 2


def test_push_rate_follows_each_package() -> None:
    fc = sub.FcSubscriptions()
    src = {"quaternion": {"w": 1.0}, "status": {"flight": 2}, "timestamp": {"time_ms": 7}}
    for pid, hz, topic in ((0, 1, "status_flight"), (1, 10, "status_flight"), (3, 200, "quaternion")):
        assert fc.handle("subscribe_add_package", sub.add_package_fields(pid, [topic], hz), 0.0)["ack"] == 0
    counts = {0: 0, 1: 0, 3: 0}
    now = 0.0
    while now < 2.0 - 1e-9:  # a 50 Hz caller
        for payload in fc.pushes(now, src):
            counts[payload[0]] += 1
        now += 0.02
    assert counts[0] == 2 and counts[1] == 20 and 396 <= counts[3] <= 398  # pushes at t <= 1.98 s
    # a stalled caller does not get an unbounded burst
    assert len(fc.pushes(10.0, src)) <= 3 * sub.MAX_CATCH_UP


# ------------------------------------------------------------------------------------------ the simulated FC


def _subscribed(host: FakeHost, pid: int) -> list[bytes]:
    return [
        f.payload[1:] for f in host.pushes if (f.cmd_set, f.cmd_id) == (0x02, 0x05) and f.payload[0] == pid
    ]


def test_verify_answers_the_database_version() -> None:
    host = FakeHost()
    host.write(_frame(bytes.fromhex("00010000"), 0x00, 7))
    assert host.ack_for(2, 7).data == NOT_ACTIVATED_ACK.to_bytes(2, "little")  # like every set but 0x00
    host.request("activate", {"app_id": APP_ID})
    host.write(_frame(bytes.fromhex("00010000"), 0x00, 8))  # the library's verify()
    assert host.ack_for(2, 8).data == b"\x00"
    assert host.request("subscribe_verify", {"version": 0x200})["ack"] == sub.VERSION_DOES_NOT_MATCH
    host.write(_frame(b"\x00\x01\x00", 0x00, 9))
    assert host.ack_for(2, 9).data == bytes([sub.ILLEGAL_DATA_LENGTH])


def test_add_package_pushes_the_topics_at_the_library_offsets() -> None:
    """The flight-control sample's take-off package, byte for byte as the library sends it, then a take-off:
    the pushes carry what the FC's physics says, where the library's memcpy expects it."""
    host = FakeHost()
    host.activate_and_obtain()
    host.write(_frame(bytes.fromhex("000a0000022ab0cf20a1d6671a"), 0x01, 11))
    assert host.ack_for(2, 11).data == b"\x00"
    host.run(1.0)
    first = _subscribed(host, 0)
    assert 10 <= len(first) <= 11  # 10 Hz from the moment it was added
    topics = ["status_flight", "status_displaymode"]
    assert sub.decode_package(first[-1], topics) == {
        "status_flight": {"flight": 0},
        "status_displaymode": {"display_mode": 6},
    }
    assert host.request("flight_task", {"command": TAKEOFF})["ack"] == 0
    host.wait_for(lambda: host.model.task == "hover", 10, "take-off done")
    host.run(0.2)
    decoded = [sub.decode_package(d, topics) for d in _subscribed(host, 0)]
    seen = [(d["status_flight"]["flight"], d["status_displaymode"]["display_mode"]) for d in decoded]
    # on the ground (0, P-GPS) -> motors on in auto take-off (1, 11) -> in the air (2, 11) -> hovering (2, 6)
    assert [s for i, s in enumerate(seen) if i == 0 or s != seen[i - 1]] == [(0, 6), (1, 11), (2, 11), (2, 6)]


def test_position_package_tracks_the_aircraft() -> None:
    host = FakeHost()
    host.takeoff()
    raw = cmds.encode_request(
        "subscribe_add_package", sub.add_package_fields(0, ["quaternion", "gps_fused"], 50)
    )
    assert raw == bytes.fromhex("00320000021f2893a4c7a8194b")
    host.write(_frame(raw, 0x01, 12))
    assert host.ack_for(2, 12).data == b"\x00"
    flag = cmds.control_flag(cmds.HORIZONTAL_POSITION, cmds.VERTICAL_POSITION, cmds.YAW_ANGLE, stable=True)
    assert flag == 0x91  # what Control::positionAndYawCtrl sends ("145")
    host.send("movement_control", {"flag": flag, "x": 0.0, "y": 6.0, "z": 7.2, "yaw": 30.0})
    host.run(6.0)
    last = sub.decode_package(_subscribed(host, 0)[-1], ["quaternion", "gps_fused"])
    q, gps = last["quaternion"], last["gps_fused"]
    yaw = math.degrees(
        math.atan2(2 * (q["w"] * q["z"] + q["x"] * q["y"]), 1 - 2 * (q["y"] ** 2 + q["z"] ** 2))
    )
    assert yaw == pytest.approx(30.0, abs=0.5)
    assert gps["latitude"] == pytest.approx(host.model.latitude, abs=1e-9)
    assert (gps["longitude"] - host.model.home_lon) * 6378137.0 * math.cos(
        host.model.home_lat
    ) == pytest.approx(6.0, abs=0.2)
    assert gps["altitude"] == pytest.approx(host.model.home_altitude + 7.2, abs=0.2)
    assert gps["visible_satellites"] == 18


def test_remove_and_reset_stop_the_pushes() -> None:
    host = FakeHost()
    host.request("activate", {"app_id": APP_ID})
    for pid, topic in ((0, "rc"), (1, "battery_info"), (2, "gimbal_status")):
        assert host.request("subscribe_add_package", sub.add_package_fields(pid, [topic], 50))["ack"] == 0
    host.run(0.5)
    assert sub.decode_package(_subscribed(host, 2)[-1], ["gimbal_status"])["gimbal_status"]["mounted"] == 1
    assert sub.decode_package(_subscribed(host, 0)[-1], ["rc"])["rc"]["mode"] == 8000  # F
    host.write(_frame(b"\x00", 0x03, 13))  # the library's removePackage(0)
    assert host.ack_for(2, 13).data == b"\x00"
    assert host.request("subscribe_remove_package", {"package_id": 0})["ack"] == sub.PACKAGE_DOES_NOT_EXIST
    assert host.request("subscribe_remove_package", {"package_id": 7})["ack"] == sub.PACKAGE_OUT_OF_RANGE
    before = {pid: len(_subscribed(host, pid)) for pid in (0, 1, 2)}
    host.run(0.5)
    after = {pid: len(_subscribed(host, pid)) for pid in (0, 1, 2)}
    assert after[0] == before[0] and after[1] > before[1] and after[2] > before[2]
    host.write(_frame(b"\x00", 0x02, 14))  # reset(), as ~Vehicle sends it
    assert host.ack_for(2, 14).data == b"\x00"
    host.run(0.02)
    count = len([f for f in host.pushes if f.cmd_id == 0x05])
    host.run(0.5)
    assert (
        len([f for f in host.pushes if f.cmd_id == 0x05]) == count and not host.model.subscriptions.packages
    )
    # the same package id can be added again (the flight-control sample reuses package 0 for every step)
    assert host.request("subscribe_add_package", sub.add_package_fields(0, ["quaternion"], 50))["ack"] == 0


def test_refusals_reach_the_library_as_one_byte_codes() -> None:
    host = FakeHost()
    host.request("activate", {"app_id": APP_ID})
    # DJI's telemetry sample, package 4: RTK on an A3 without RTK -> it prints "RTK Not Available"
    host.write(_frame(bytes.fromhex("0405000005b6a6f91de3b972cbb5574adac3133d76fd735df4"), 0x01, 15))
    assert host.ack_for(2, 15).data == bytes([sub.SOURCE_DEVICE_OFFLINE])
    host.write(_frame(bytes.fromhex("0164000001c7a8194b"), 0x01, 16))  # GPS fused at 100 Hz
    assert host.ack_for(2, 16).data == bytes([sub.ILLEGAL_FREQUENCY])
    host.write(_frame(bytes.fromhex("010a00000178563412"), 0x01, 17))  # no such topic
    assert host.ack_for(2, 17).data == bytes([sub.ILLEGAL_UID])
    host.write(_frame(bytes.fromhex("010a000001c7a8"), 0x01, 18))  # cut short
    assert host.ack_for(2, 18).data == bytes([sub.ILLEGAL_DATA_LENGTH])
    assert host.model.bad_payloads == 1 and host.model.errors == 0
    host.run(0.5)
    assert not [f for f in host.pushes if f.cmd_id == 0x05]


def test_a_resent_add_gets_the_same_answer_and_acts_once() -> None:
    """The library resends an unanswered add once after 500 ms with the same seq: the stored ACK again,
    not "package already exists"."""
    host = FakeHost()
    host.request("activate", {"app_id": APP_ID})
    host.model.drop_acks(1)
    raw = _frame(bytes.fromhex("03c80000011f2893a4"), 0x01, 19)
    host.write(raw)
    host.run(0.5)
    assert (2, 19) not in host.acks
    host.write(raw)
    assert host.ack_for(2, 19).data == b"\x00"
    assert host.model.actions["subscribe_add_package"] == 1 and host.model.duplicates == 1


def test_time_stamped_package_leads_with_the_clock() -> None:
    host = FakeHost()
    host.request("activate", {"app_id": APP_ID})
    host.write(_frame(bytes.fromhex("02640001011f2893a4"), 0x01, 20))  # quaternion, 100 Hz, config 1
    assert host.ack_for(2, 20).data == b"\x00"
    host.run(0.5)
    stamps = [
        sub.decode_package(d, ["quaternion"], timestamp=True)["timestamp"]["time_ms"]
        for d in _subscribed(host, 2)
    ]
    assert len(stamps) >= 25 and stamps == sorted(stamps) and stamps[-1] > stamps[0]


def test_m100_firmware_has_no_subscription() -> None:
    host = FakeHost(OsdkFcModel(app_id=APP_ID, firmware="m100"))
    host.write(encode_command(0x00, 0x01, cmds.encode_request("activate", {"app_id": APP_ID}, "m100"), 2, 1))
    assert host.ack_for(2, 1).data == b"\x00\x00"
    host.write(_frame(bytes.fromhex("00010000"), 0x00, 2))
    assert host.ack_for(2, 2).data == bytes([SUBSCRIBE_REFUSED_ACK])


def test_waypoint_mission_started_on_the_ground_takes_off_first() -> None:
    """DJI's mission sample uploads a mission and starts it with the aircraft on the ground."""
    host = FakeHost()
    host.activate_and_obtain()
    init = {
        "length": 3,
        "vel_cmd_range": 10.0,
        "idle_vel": 5.0,
        "mission_exec_num": 1,
        "action_on_rc_lost": 1,
    }
    assert host.request("wp_init", init)["ack"] == 0
    for i, (n, e, u) in enumerate(((0.0, 0.0, 10.0), (6.0, 0.0, 11.0), (0.0, 0.0, 10.0))):
        lat, lon = host.model.to_latlon(n, e)
        assert (
            host.request("wp_upload", {"index": i, "latitude": lat, "longitude": lon, "altitude": u})["ack"]
            == 0
        )
    assert host.request("wp_start_stop", {"start": 0})["ack"] == 0
    assert (host.model.task, host.model.display_mode, host.model.motors_on) == ("takeoff", 11, True)
    host.wait_for(lambda: host.model.task == "waypoint", 10, "take-off into the mission")
    host.wait_for(lambda: any(e["incident_type"] == 1 for e in host.events()), 60, "mission finished")
    assert host.model.task == "hover" and host.model.u == pytest.approx(10.0, abs=0.3)
