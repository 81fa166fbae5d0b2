"""The Onboard SDK flight-controller simulator, driven the way a host drives a real FC: commands encoded
with the codec go in as bytes, and everything that comes back is decoded with the codec's ``Decoder``.

Most behaviour runs on a fake clock (``FakeHost`` calls the device's ``on_bytes``/``tick`` directly,
so a whole mission flies in milliseconds); the link itself is exercised over real pseudo-terminals
and one loopback TCP port with pyserial, and ``main`` in its own process.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import serial
from hypothesis import given
from hypothesis import strategies as st

from adapters.osdk import commands as cmds
from adapters.osdk.commands import (
    FRAME_BODY,
    FRAME_GROUND,
    HORIZONTAL_VELOCITY,
    VERTICAL_VELOCITY,
    YAW_ANGLE,
    YAW_RATE,
    control_flag,
)
from adapters.osdk.protocol import Decoder, Frame, encode_ack, encode_command, encode_frame
from adapters.osdk.sim import (
    NO_RIGHTS_ACK,
    NOT_ACTIVATED_ACK,
    SUBSCRIBE_REFUSED_ACK,
    UNKNOWN_COMMAND_ACK,
    OsdkFcDevice,
    OsdkFcModel,
    main,
)
from adapters.osdk.telemetry import FlightData, decode_flight_data
from adapters.simio import PtyEndpoint, TcpEndpoint

ROOT = Path(__file__).resolve().parent.parent
APP_ID = 1027123
TAKEOFF, LANDING, GO_HOME = 1, 2, 6


class Host:
    """The onboard computer: frames commands with the codec and sorts what comes back into ACKs
    (by session and seq) and pushes. Transports supply ``write`` and ``wait_for``."""

    def __init__(self) -> None:
        self.decoder = Decoder()
        self.seq = 100
        self.acks: dict[tuple[int, int], Frame] = {}
        self.ack_log: list[Frame] = []  # every ACK frame, repeats included
        self.pushes: list[Frame] = []
        self.bad = 0

    # transport
    def write(self, raw: bytes) -> None:
        raise NotImplementedError

    def wait_for(self, predicate: Callable[[], Any], timeout: float, what: str = "") -> Any:
        raise NotImplementedError

    def receive(self, data: bytes) -> None:
        for item in self.decoder.feed(data):
            if not isinstance(item, Frame):
                self.bad += 1
            elif item.is_ack:
                self.acks[(item.session, item.seq)] = item
                self.ack_log.append(item)
            else:
                self.pushes.append(item)

    # commands
    def frame(self, name: str, fields: dict[str, Any] | None = None, session: int = 2) -> tuple[bytes, int]:
        spec = cmds.spec_for(name)
        self.seq += 1
        payload = cmds.encode_request(name, fields)
        return encode_command(spec.cmd_set, spec.cmd_id, payload, session, self.seq), self.seq

    def ack_for(self, session: int, seq: int, timeout: float = 5.0) -> Frame:
        return self.wait_for(lambda: self.acks.get((session, seq)), timeout, f"ACK {session}/{seq}")

    def request(
        self, name: str, fields: dict[str, Any] | None = None, session: int = 2, timeout: float = 5.0
    ) -> dict[str, Any]:
        """Send and wait for the ACK; returns the decoded ACK fields."""
        raw, seq = self.frame(name, fields, session)
        self.write(raw)
        return cmds.decode_ack(name, self.ack_for(session, seq, timeout).data).fields

    def send(self, name: str, fields: dict[str, Any] | None = None, session: int = 0) -> None:
        self.write(self.frame(name, fields, session)[0])

    # pushes
    def decoded(self, cmd_set: int, cmd_id: int) -> list[dict[str, Any]]:
        return [
            cmds.decode_request(f.cmd_set, f.cmd_id, f.payload).fields
            for f in self.pushes
            if (f.cmd_set, f.cmd_id) == (cmd_set, cmd_id)
        ]

    def events(self) -> list[dict[str, Any]]:
        return self.decoded(0x02, 0x04)

    def statuses(self) -> list[dict[str, Any]]:
        return self.decoded(0x02, 0x03)

    def flight_data(self) -> list[FlightData]:
        return [decode_flight_data(f.payload) for f in self.pushes if (f.cmd_set, f.cmd_id) == (0x02, 0x00)]

    def latest(self, item: str) -> dict[str, Any] | None:
        for fd in reversed(self.flight_data()):
            if item in fd.items:
                return fd.items[item]
        return None

    # the usual start-up
    def activate_and_obtain(self) -> None:
        assert self.request("activate", {"app_id": APP_ID})["ack"] == 0
        assert self.request("obtain_control", {"control": 1})["ack"] == 0x0002


class FakeHost(Host):
    """The device called directly on a fake clock: the byte boundary without the OS."""

    def __init__(self, model: OsdkFcModel | None = None, dt: float = 0.02) -> None:
        super().__init__()
        self.device = OsdkFcDevice(model or OsdkFcModel(app_id=APP_ID))
        self.model = self.device.model
        self.now = 0.0
        self.dt = dt
        self.receive(self.device.tick(self.now))

    def write(self, raw: bytes) -> None:
        self.receive(self.device.on_bytes(raw, self.now))

    def run(self, seconds: float) -> None:
        end = self.now + seconds
        while self.now < end - 1e-9:
            self.now += self.dt
            self.receive(self.device.tick(self.now))

    def wait_for(self, predicate: Callable[[], Any], timeout: float, what: str = "") -> Any:
        """``timeout`` is simulated seconds."""
        end = self.now + timeout
        while True:
            value = predicate()
            if value:
                return value
            if self.now >= end:
                raise AssertionError(f"simulated {timeout}s passed without {what or predicate}")
            self.run(self.dt)

    def takeoff(self) -> None:
        self.activate_and_obtain()
        assert self.request("flight_task", {"command": TAKEOFF})["ack"] == 0
        self.wait_for(lambda: self.model.task == "hover", 10, "the end of the take-off")


class SerialHost(Host):
    """A pyserial port on a pty path or a socket:// URL, read with wall-clock deadlines."""

    def __init__(self, url: str) -> None:
        super().__init__()
        self.port = serial.serial_for_url(url, baudrate=230400, timeout=0.05)

    def write(self, raw: bytes) -> None:
        self.port.write(raw)

    def wait_for(self, predicate: Callable[[], Any], timeout: float, what: str = "") -> Any:
        deadline = time.monotonic() + timeout
        while True:
            value = predicate()
            if value:
                return value
            if time.monotonic() > deadline:
                raise AssertionError(f"timed out after {timeout}s waiting for {what or predicate}")
            self.receive(self.port.read(4096))

    def close(self) -> None:
        self.port.close()


def _mission(host: FakeHost | SerialHost, model: OsdkFcModel, points: list[tuple[float, float, float]],
             **info: Any) -> list[dict[str, Any]]:  # fmt: skip
    """wp_init + every waypoint (local north/east/up metres); returns the upload ACKs."""
    init = {"length": len(points), "vel_cmd_range": 15.0, "idle_vel": 8.0, "mission_exec_num": 1, **info}
    assert host.request("wp_init", init)["ack"] == 0
    acks = []
    for i, (n, e, u) in enumerate(points):
        lat, lon = model.to_latlon(n, e)
        acks.append(host.request("wp_upload", {"index": i, "latitude": lat, "longitude": lon, "altitude": u}))
    return acks


# ----------------------------------------------------------------------------------------------------
# activation, version, control


def test_activation_gates_every_other_command_set() -> None:
    host = FakeHost()
    version = host.request("get_version", {"arbitrary": 0})
    assert version["ack"] == NOT_ACTIVATED_ACK
    # the A3 layout DJI's own library reads: ID string + NUL, then the 32-byte name
    info = cmds.parse_version_reply(version["ack"], version["version_data"])
    assert (info.layout, info.hardware, info.firmware) == ("id", "A3", "03.03.100.00")
    assert version["version_data"] == b"SIMFC0000000001\x00" + b"SDK-v1.1 BETA A3-03.03.100.00\x00\x00\x00"
    # before activation: the common "no authorization" ACK, and nothing happens
    raw, seq = host.frame("obtain_control", {"control": 1})
    host.write(raw)
    assert host.ack_for(2, seq).data == NOT_ACTIVATED_ACK.to_bytes(2, "little")
    assert not host.model.sdk_control and host.model.actions["obtain_control"] == 0
    assert host.model.refused_not_activated == 1
    # the wrong app id, then a refusal forced by the test hook, then the right one
    assert host.request("activate", {"app_id": APP_ID + 1})["ack"] == 0x0006
    host.model.reject_activation = 0x0007
    assert host.request("activate", {"app_id": APP_ID})["ack"] == 0x0007
    assert not host.model.activated
    host.model.reject_activation = 0
    assert host.request("activate", {"app_id": APP_ID})["ack"] == 0
    assert host.request("get_version", {})["ack"] == 0
    assert host.request("obtain_control", {"control": 1})["ack"] == 0x0002


def _library_reads_version(reply: bytes) -> tuple[str, tuple[int, int, int, int], int, str] | None:
    """What DJI's Onboard-SDK 3.x makes of a 0x00 0x00 reply (``Vehicle::parseDroneVersionInfo``, 3.8.1 and
    3.9.0, re-told step by step): (hardware, firmware, version CRC, serial), or None where it gives up."""
    at = 2
    crc_id = bytearray()
    while reply[at] != 0:  # CRC and/or ID up to the first NUL, at most 16 bytes
        crc_id.append(reply[at])
        at += 1
        if at > 18:
            return None
    at += 1
    name = reply[at : at + 32]
    words = name.split(b" ", 2)  # "SDK-v1.x" "BETA" "<hardware>-<a>.<b>.<c>.<d>"
    if len(words) < 3 or b"-" not in words[2]:
        return None
    hardware, _, numbers = words[2].partition(b"-")
    parts = numbers.split(b"\0", 1)[0].split(b".")
    if len(parts) != 4:
        return None
    a, b, c, d = (int(p) for p in parts)
    if hardware == b"M100" or (a, b, c, d) == (3, 2, 10, 0):
        c *= 10  # "Bug in M100 does not report the right FW" (and M600/A3 3.2.10)
    if (a, b, c, d) < (3, 2, 0, 0):
        if len(crc_id) < 4 or len(crc_id) - 4 > 12:
            return None
        return hardware.decode(), (a, b, c, d), int.from_bytes(crc_id[:4], "little"), crc_id[4:].decode()
    return hardware.decode(), (a, b, c, d), 0, crc_id.decode()


M100_31 = (3, 1, 10, 0)  # OSDK Version::M100_31: the one M100 firmware the 3.x library runs on
EXTENDED_VERSION_BASE = (3, 2, 36, 6)  # the library refuses anything else older ("Upgrade firmware")


@pytest.mark.parametrize("firmware", ["new", "m100"])
def test_version_reply_is_one_dji_onboard_sdk_3_accepts(firmware: str) -> None:
    """The M100 simulator used to answer CRC + ``M100-02.03.00.00`` (the 2.3 protocol): the 3.x library
    stopped at "Drone version not obtained". Now each firmware answers in the layout and with a version
    that the library's own parsing accepts (checked by hand against the built library: docs/osdk.md)."""
    host = FakeHost(OsdkFcModel(firmware=firmware))
    raw, seq = host.frame("get_version", {"arbitrary": 0})
    host.write(raw)
    reply = host.ack_for(2, seq).data
    read = _library_reads_version(reply)
    assert read is not None
    hardware, version, crc, serial = read
    info = cmds.parse_version_reply(int.from_bytes(reply[:2], "little"), reply[2:])  # the gateway's reading
    if firmware == "m100":
        assert (hardware, version, serial) == ("M100", M100_31, "SIMFC00001")
        assert crc != 0 and 0 not in crc.to_bytes(4, "little")
        assert (info.layout, info.hardware, info.firmware) == ("crc_id", "M100", "03.01.01.00")
        assert (info.version_crc, info.serial) == (crc, serial)
    else:
        assert hardware == "A3" and version >= EXTENDED_VERSION_BASE and serial == "SIMFC0000000001"
        assert (info.layout, info.hardware, info.serial) == ("id", "A3", serial)


def test_unactivated_ignore_policy_answers_nothing() -> None:
    host = FakeHost(OsdkFcModel(unactivated="ignore"))
    raw, seq = host.frame("wp_start_stop", {"start": 0})
    host.write(raw)
    host.run(1.0)
    assert (2, seq) not in host.acks and host.model.refused_not_activated == 1


def test_obtain_control_follows_the_rc_switch_and_in_progress() -> None:
    host = FakeHost(OsdkFcModel(rc_mode="P", obtain_in_progress_once=True))
    assert host.request("activate", {"app_id": 99})["ack"] == 0  # app_id None: any app id
    assert host.request("obtain_control", {"control": 1})["ack"] == 0x0006  # RC must be in F
    host.model.rc_not_f_ack = 0x0000  # older firmware's answer
    assert host.request("obtain_control", {"control": 1})["ack"] == 0x0000
    host.model.rc_mode = "F"
    assert host.request("obtain_control", {"control": 1})["ack"] == 0x0003  # in progress: ask again
    assert not host.model.sdk_control
    assert host.request("obtain_control", {"control": 1})["ack"] == 0x0002
    assert host.model.sdk_control
    assert host.request("obtain_control", {"control": 0})["ack"] == 0x0001
    assert not host.model.sdk_control


# ----------------------------------------------------------------------------------------------------
# flight tasks and telemetry


def test_takeoff_climbs_to_1_2_m_and_hovers() -> None:
    host = FakeHost()
    assert host.request("activate", {"app_id": APP_ID})["ack"] == 0
    assert host.request("flight_task", {"command": TAKEOFF})["ack"] == NO_RIGHTS_ACK  # no authority
    assert host.request("obtain_control", {"control": 1})["ack"] == 0x0002
    assert host.request("flight_task", {"command": LANDING})["ack"] == 4  # not in air
    assert host.request("flight_task", {"command": TAKEOFF})["ack"] == 0
    host.run(0.5)
    assert host.latest("status") == {"flight": 2, "display_mode": 11, "gear": 0, "error": 0}
    assert host.request("flight_task", {"command": TAKEOFF})["ack"] == 3  # already in the air
    host.run(3.0)
    pos, status, vel = host.latest("position"), host.latest("status"), host.latest("velocity")
    assert pos is not None and status is not None and vel is not None
    assert abs(pos["height"] - 1.2) < 0.05 and abs(pos["altitude"] - (50.0 + pos["height"])) < 1e-3
    assert status["flight"] == 2 and status["display_mode"] == 6  # P-GPS hover after the take-off
    assert abs(vel["z"]) < 0.05
    assert pos["latitude"] == pytest.approx(math.radians(22.5431), abs=1e-9)
    assert pos["health"] == 5
    assert host.latest("control_device") == {
        "control_mode": 0, "device_status": 2, "flight_status": 1, "vrc_status": 0, "reserved": 0,
    }  # fmt: skip


def test_default_telemetry_rates_and_the_new_firmware_layout() -> None:
    host = FakeHost(dt=0.01)
    host.run(2.0)  # t = 0 .. 2 s
    fds = host.flight_data()
    assert fds and all(fd.firmware == "new" and not fd.unknown for fd in fds)
    counts = {name: sum(name in fd.items for fd in fds) for name in ("position", "gps", "rc")}
    assert 20 <= counts["position"] <= 21 and 2 <= counts["gps"] <= 3 and 2 <= counts["rc"] <= 3
    rc = host.latest("rc")
    assert rc is not None and rc["mode"] == 8000  # F
    battery = host.latest("battery")
    assert battery is not None and battery["percentage"] == 95 and battery["capacity"] > 0
    q = host.latest("quaternion")
    assert q is not None and q["w"] == pytest.approx(1.0)


def test_broadcast_frequency_sets_the_push_schedule() -> None:
    host = FakeHost(dt=0.01)
    off = {"frequency": [0] * 16}
    assert host.request("set_broadcast_frequency", off)["ack"] == 0
    host.pushes.clear()
    host.run(1.0)
    assert host.flight_data() == []
    codes = [5] * 16  # keep (still off) ...
    codes[5] = 3  # ... except position at 50 Hz
    codes[11] = 1  # and status at 1 Hz
    assert host.request("set_broadcast_frequency", {"frequency": codes})["ack"] == 0
    host.run(1.0)
    fds = host.flight_data()
    assert 48 <= len(fds) <= 52
    assert all(set(fd.items) <= {"position", "status"} for fd in fds)
    assert 1 <= sum("status" in fd.items for fd in fds) <= 2
    assert host.request("set_broadcast_frequency", {"frequency": [6] + [0] * 15})["ack"] == 1


def test_landing_stops_the_motors_and_go_home_returns() -> None:
    host = FakeHost()
    host.takeoff()
    host.send("movement_control", {"flag": control_flag(), "x": 0.0, "y": 5.0, "z": 2.0, "yaw": 0.0})
    host.run(6.0)
    assert host.model.e > 15.0
    host.send("emergency_brake")
    host.run(3.0)
    assert host.request("flight_task", {"command": GO_HOME})["ack"] == 0
    host.run(0.5)
    status = host.latest("status")
    assert status is not None and status["display_mode"] == 15
    host.wait_for(lambda: host.model.task == "landing", 30, "the go-home landing")
    host.wait_for(lambda: host.model.flight_status == 0, 60, "touchdown")
    assert math.hypot(host.model.n, host.model.e) < 0.6 and host.model.u == 0.0
    host.run(0.5)
    status = host.latest("status")
    assert status is not None and status["flight"] == 0
    # again, landing in place
    assert host.request("flight_task", {"command": TAKEOFF})["ack"] == 0
    host.wait_for(lambda: host.model.task == "hover", 10)
    assert host.request("flight_task", {"command": LANDING})["ack"] == 0
    assert host.request("flight_task", {"command": LANDING})["ack"] == 8  # already landing
    host.run(0.3)
    status = host.latest("status")
    assert status is not None and status["display_mode"] == 12
    host.wait_for(lambda: not host.model.motors_on, 10, "motors off after landing")
    assert host.request("flight_task", {"command": 8})["ack"] == 2  # motors already off
    assert host.request("flight_task", {"command": 99})["ack"] == 10  # unknown task


# ----------------------------------------------------------------------------------------------------
# movement control


def test_movement_control_moves_holds_the_set_point_and_the_brake_stops() -> None:
    host = FakeHost()
    host.activate_and_obtain()
    vel = {"flag": control_flag(), "x": 3.0, "y": 0.0, "z": 0.0, "yaw": 0.0}
    host.send("movement_control", vel)
    host.run(1.0)
    assert host.model.n == 0.0 and host.model.actions["movement_control"] == 1  # on the ground: ignored
    assert host.request("flight_task", {"command": TAKEOFF})["ack"] == 0
    host.wait_for(lambda: host.model.task == "hover", 10)
    host.send("movement_control", vel)  # 3 m/s north, sent once: the FC holds it
    host.run(4.0)
    m = host.model
    assert m.task == "sdk" and m.vn == pytest.approx(3.0, abs=0.01) and m.n > 8.0
    status = host.latest("status")
    assert status is not None and status["display_mode"] == 17
    # body frame after turning east: forward is east
    turn = {"flag": control_flag(yaw=YAW_ANGLE), "x": 0.0, "y": 0.0, "z": 0.0, "yaw": 90.0}
    host.send("movement_control", turn)
    host.run(2.0)
    assert m.yaw == pytest.approx(90.0, abs=0.5)
    body = control_flag(HORIZONTAL_VELOCITY, VERTICAL_VELOCITY, YAW_RATE, FRAME_BODY)
    host.send("movement_control", {"flag": body, "x": 2.0, "y": 0.0, "z": 1.0, "yaw": 0.0})
    host.run(3.0)
    assert m.ve == pytest.approx(2.0, abs=0.01) and abs(m.vn) < 0.01 and m.vu == pytest.approx(1.0, abs=0.01)
    host.send("emergency_brake")
    host.run(2.0)
    stopped = (m.n, m.e, m.u)
    host.run(2.0)
    assert m.speed < 0.01 and math.dist(stopped, (m.n, m.e, m.u)) < 0.05
    assert m.task == "hover"
    # the same movement without authority does nothing
    assert host.request("obtain_control", {"control": 0})["ack"] == 0x0001
    host.send(
        "movement_control", {"flag": control_flag(frame=FRAME_GROUND), "x": 5.0, "y": 0, "z": 0, "yaw": 0}
    )
    host.run(1.0)
    assert m.speed < 0.01


def _flying_north(host: FakeHost, speed: float) -> None:
    host.takeoff()
    host.send("movement_control", {"flag": control_flag(), "x": speed, "y": 0.0, "z": 0.0, "yaw": 0.0})


def test_setpoint_hold_inf_holds_the_last_set_point_for_ever() -> None:
    """The default (and the worst case a gateway must survive): one frame, and the FC flies on."""
    host = FakeHost(OsdkFcModel(app_id=APP_ID), dt=0.1)
    assert host.model.setpoint_hold == math.inf
    _flying_north(host, 4.0)
    host.run(120.0)  # two minutes of model time after the only frame
    m = host.model
    assert m.task == "sdk" and m.vn == pytest.approx(4.0, abs=0.01) and m.n > 450.0


def test_setpoint_hold_seconds_brakes_and_hovers_after_the_last_frame() -> None:
    host = FakeHost(OsdkFcModel(app_id=APP_ID, setpoint_hold=0.5))
    m = host.model
    _flying_north(host, 4.0)
    frame = {"flag": control_flag(), "x": 4.0, "y": 0.0, "z": 0.0, "yaw": 0.0}
    for _ in range(50):  # streamed at 10 Hz: held, whatever the hold time
        host.run(0.1)
        host.send("movement_control", frame)
    assert m.task == "sdk" and m.vn == pytest.approx(4.0, abs=0.01)
    host.run(0.48)  # just under the hold time after the last frame: still flying
    assert m.task == "sdk" and m.vn == pytest.approx(4.0, abs=0.01)
    host.run(0.04)  # past it: the FC brakes (4 m/s^2) and hovers where it stops
    assert m.task == "hover"
    host.run(1.5)
    stopped = (m.n, m.e, m.u)
    host.run(3.0)
    assert m.speed < 0.01 and math.dist(stopped, (m.n, m.e, m.u)) < 0.05
    status = host.latest("status")
    assert status is not None and status["display_mode"] == 6  # P-GPS hover, no longer SDK control (17)
    host.send("movement_control", frame)  # a new frame flies again
    host.run(0.3)
    assert m.task == "sdk" and m.vn > 1.0


# ----------------------------------------------------------------------------------------------------
# waypoint missions


def test_a_three_waypoint_mission_flies_with_its_events() -> None:
    host = FakeHost()
    host.takeoff()
    points = [(30.0, 0.0, 10.0), (30.0, 30.0, 15.0), (0.0, 30.0, 5.0)]
    acks = _mission(host, host.model, points)
    assert acks == [{"ack": 0, "index": i} for i in range(3)]
    upload = host.events()
    assert upload[0]["incident_type"] == 0 and upload[0]["is_mission_valid"] == 1
    assert upload[0]["estimated_run_time"] == round(
        (math.dist((30, 0, 10), (30, 30, 15)) + math.hypot(30, 10)) / 8
    )
    assert host.request("wp_start_stop", {"start": 0})["ack"] == 0
    host.wait_for(lambda: any(e["incident_type"] == 1 for e in host.events()), 120, "mission finished")
    host.run(3.0)
    events = [(e["incident_type"], e.get("waypoint_index")) for e in host.events()]
    assert events == [(0, None), (2, 0), (2, 1), (2, 2), (1, None)]
    assert all(e["current_status"] == 6 for e in host.events() if e["incident_type"] == 2)
    m = host.model
    assert math.dist((m.n, m.e, m.u), points[-1]) < 1.0 and m.task == "hover" and m.speed < 0.01
    statuses = host.statuses()
    assert statuses and all(s["mission_type"] == 1 and s["error_notification"] == 0 for s in statuses)
    targets = [s["target_waypoint"] for s in statuses]
    assert targets == sorted(targets) and targets[0] == 0 and targets[-1] == 2
    assert statuses[0]["current_status"] == 0 and statuses[-1]["current_status"] == 1
    assert m.actions["wp_start_stop"] == 1 and m.errors == 0
    pos = host.latest("position")
    assert pos is not None and math.dist(m.to_local(pos["latitude"], pos["longitude"]), points[-1][:2]) < 1.0


def test_mission_actions_repeats_and_finish_actions() -> None:
    host = FakeHost(OsdkFcModel(app_id=APP_ID, reach_pre_action_events=True))
    host.takeoff()
    m = host.model
    init = {
        "length": 2,
        "vel_cmd_range": 10.0,
        "idle_vel": 10.0,
        "mission_exec_num": 2,
        "action_on_finish": 1,
    }
    assert host.request("wp_init", init)["ack"] == 0
    for i, (n, e) in enumerate(((10.0, 0.0), (10.0, 10.0))):
        lat, lon = m.to_latlon(n, e)
        wp = {"index": i, "latitude": lat, "longitude": lon, "altitude": 5.0}
        if i == 1:  # stay 1.5 s, a photo, gimbal down
            wp |= {
                "has_action": 1,
                "action_num": 3,
                "command_list": [0, 1, 5],
                "command_param": [1500, 0, -90],
            }
        assert host.request("wp_upload", wp)["ack"] == 0
    assert host.request("wp_download_init", {})["length"] == 2
    down = host.request("wp_download_point", {"index": 1})
    assert down["ack"] == 0 and down["command_param"][:3] == [1500, 0, -90]
    assert host.request("wp_download_point", {"index": 5})["ack"] == 0xE4
    assert host.request("wp_set_idle_velocity", {"idle_velocity": 6.0}) == {"ack": 0, "idle_velocity": 6.0}
    assert host.request("wp_get_idle_velocity", {})["idle_velocity"] == 6.0
    assert host.request("wp_set_idle_velocity", {"idle_velocity": 12.0})["ack"] == 0xDB  # above max
    assert host.request("wp_start_stop", {"start": 0})["ack"] == 0
    host.run(1.0)
    assert host.request("wp_pause_resume", {"pause": 0})["ack"] == 0
    host.run(3.0)
    assert m.speed < 0.01 and m.run is not None and m.run.target == 0
    assert host.request("wp_pause_resume", {"pause": 1})["ack"] == 0
    host.wait_for(lambda: any(e["incident_type"] == 1 for e in host.events()), 120, "mission finished")
    reached = [(e["waypoint_index"], e["current_status"]) for e in host.events() if e["incident_type"] == 2]
    assert reached == [(0, 4), (0, 6), (1, 4), (1, 6)] * 2  # twice, pre- and post-action
    finish = [e for e in host.events() if e["incident_type"] == 1]
    assert finish[0]["repeat"] == 2
    assert m.photos == 2 and m.gimbal_pitch == -90.0
    assert m.task == "go_home"  # action_on_finish 1
    host.wait_for(lambda: m.flight_status == 0, 60, "landed at home")


def test_mission_start_conditions() -> None:
    host = FakeHost()
    assert host.request("activate", {"app_id": APP_ID})["ack"] == 0
    assert host.request("wp_start_stop", {"start": 0})["ack"] == 0xD1  # no control authority
    assert host.request("obtain_control", {"control": 1})["ack"] == 2
    # on the ground: a hotpoint needs the air; a waypoint mission would take off (nothing uploaded yet)
    assert host.request("hp_upload_start", {"hp_radius": 10.0, "angle_rate": 5.0})["ack"] == 0xDA
    assert host.request("fm_upload_start", {})["ack"] == 0xDA
    assert host.request("wp_start_stop", {"start": 0})["ack"] == 0xEA
    assert host.request("flight_task", {"command": TAKEOFF})["ack"] == 0
    assert host.request("wp_start_stop", {"start": 0})["ack"] == 0xF0  # taking off
    host.wait_for(lambda: host.model.task == "hover", 10)
    assert host.request("wp_start_stop", {"start": 0})["ack"] == 0xEA  # nothing uploaded
    init = {"length": 2, "vel_cmd_range": 10.0, "idle_vel": 5.0, "mission_exec_num": 1}
    assert host.request("wp_init", init)["ack"] == 0
    lat, lon = host.model.to_latlon(5.0, 0.0)
    assert (
        host.request("wp_upload", {"index": 0, "latitude": lat, "longitude": lon, "altitude": 3})["ack"] == 0
    )
    assert host.request("wp_start_stop", {"start": 0})["ack"] == 0xEB  # not all uploaded
    assert host.request("wp_start_stop", {"start": 1})["ack"] == 0xD4  # cancel: nothing runs
    assert host.request("wp_pause_resume", {"pause": 0})["ack"] == 0xD4
    lat, lon = host.model.to_latlon(5.0, 40.0)
    assert (
        host.request("wp_upload", {"index": 1, "latitude": lat, "longitude": lon, "altitude": 3})["ack"] == 0
    )
    assert host.request("wp_start_stop", {"start": 0})["ack"] == 0
    assert host.request("wp_start_stop", {"start": 0})["ack"] == 0xD5  # already running
    host.model.rc_mode = "P"
    assert host.request("hp_upload_start", {"hp_radius": 10.0, "angle_rate": 5.0})["ack"] == 0xD0
    host.model.rc_mode = "F"
    assert host.request("hp_upload_start", {"hp_radius": 10.0, "angle_rate": 5.0})["ack"] == 0xD7
    host.run(2.0)
    assert host.request("wp_start_stop", {"start": 1})["ack"] == 0  # cancel: hover where it stops
    host.run(4.0)
    assert host.model.task == "hover" and host.model.speed < 0.01 and host.model.run is None
    assert not any(e["incident_type"] == 1 for e in host.events())


FAR = 2500.0


@pytest.mark.parametrize(
    ("points", "info", "code"),
    [
        ([(10, 0, 10), (20, 0, 10), (FAR, 0, 10)], {}, 0xC7),  # farther than max_distance_m from home
        ([(10, 0, 10), (10.2, 0, 10), (30, 0, 10)], {}, 0xE5),  # neighbours 0.2 m apart
        ([(10, 0, 10), (20, 0, 600), (30, 0, 10)], {}, 0xC0),  # above 500 m
        ([(10, 0, 10), (20, 0, -250), (30, 0, 10)], {}, 0xC1),  # below -200 m
        ([(10, 0, 10)], {}, 0xE0),  # one waypoint: a mission needs two
        ([(10, 0, 10), (20, 0, 10)], {"idle_vel": 20.0}, 0xE0),  # idle above the max speed
        # OSDK dji_error.cpp: waypoint 1 to n over 60 km (new A3/N3 firmware) is 0xE2; 34 legs of 1.9 km
        # zig-zagging inside the 2 km radius make 64.6 km
        ([(950 * (-1) ** i, 0, 10) for i in range(35)], {}, 0xE2),
    ],
)
def test_the_last_upload_ack_validates_the_whole_mission(
    points: list[tuple[float, float, float]], info: dict[str, Any], code: int
) -> None:
    host = FakeHost()
    host.takeoff()
    acks = _mission(host, host.model, points, **info)
    assert [a["ack"] for a in acks] == [0] * (len(points) - 1) + [code]
    assert acks[-1]["index"] == len(points) - 1
    upload = [e for e in host.events() if e["incident_type"] == 0]
    assert len(upload) == 1 and upload[0]["is_mission_valid"] == 0
    assert host.request("wp_start_stop", {"start": 0})["ack"] == 0xEB  # the rejected waypoint is missing


def test_route_length_limits_count_the_way_from_and_back_home_and_depend_on_the_firmware() -> None:
    """OSDK dji_error.cpp: 0xE3 when home to waypoint 1, the route and waypoint n back home exceed 100 km
    (new A3/N3 firmware; 60 km others); 0xE2 when the route alone exceeds 60 km (30 km others)."""
    far = FakeHost(OsdkFcModel(app_id=APP_ID, max_distance_m=30_000.0))
    far.takeoff()
    zigzag = [(22_000.0, 950.0 * (-1) ** i, 10.0) for i in range(31)]  # 30 legs of 1.9 km: 57 km
    assert [a["ack"] for a in _mission(far, far.model, zigzag)][-1] == 0xE3  # 57 + 2 x 22 km > 100 km
    near = [(1000.0, 950.0 * (-1) ** i, 10.0) for i in range(31)]  # 57 km + 2 x 1.4 km
    assert [a["ack"] for a in _mission(far, far.model, near)][-1] == 0
    m100 = FakeHost(OsdkFcModel(app_id=APP_ID, firmware="m100"))
    m100.activate_and_obtain()
    short = [(950.0 * (-1) ** i, 0.0, 10.0) for i in range(18)]  # 17 legs of 1.9 km: 32.3 km
    assert [a["ack"] for a in _mission(m100, m100.model, short)][-1] == 0xE2
    new = FakeHost()
    new.activate_and_obtain()
    assert [a["ack"] for a in _mission(new, new.model, short)][-1] == 0


def test_break_mission_reports_the_error_and_the_break_then_hovers() -> None:
    """The fault-injection hook: the status push carries the error, then the default status says broken."""
    host = FakeHost()
    host.takeoff()
    _mission(host, host.model, [(0, 0, 10), (300, 0, 10)])
    assert host.request("wp_start_stop", {"start": 0})["ack"] == 0
    host.run(3.0)
    assert host.model.break_mission(0xD9, host.now)
    host.run(0.5)
    decoded = host.statuses()
    assert any(d.get("error_notification") == 0xD9 for d in decoded)
    broken = [d for d in decoded if d["mission_type"] == 0]
    assert broken and broken[-1]["last_mission_type"] == 1 and broken[-1]["is_broken"] == 1
    host.run(3.0)
    assert host.model.run is None and host.model.task == "hover" and host.model.speed < 0.05
    assert not host.model.break_mission(0xD9, host.now)  # nothing left to break


def test_upload_index_and_action_checks() -> None:
    host = FakeHost()
    host.activate_and_obtain()
    lat, lon = host.model.to_latlon(10.0, 0.0)
    wp = {"index": 0, "latitude": lat, "longitude": lon, "altitude": 5.0}
    assert host.request("wp_upload", wp)["ack"] == 0xEA  # no wp_init yet
    host.request("wp_init", {"length": 2, "vel_cmd_range": 10.0, "idle_vel": 5.0, "mission_exec_num": 1})
    assert host.request("wp_upload", wp | {"index": 2}) == {"ack": 0xE4, "index": 2}
    assert host.request("wp_upload", wp | {"index": 1}) == {"ack": 0xE9, "index": 1}  # last, but 0 missing
    bad = wp | {"has_action": 1, "action_num": 1, "command_list": [9]}
    assert host.request("wp_upload", bad) == {"ack": 0xE8, "index": 0}
    assert host.events()[-1]["is_mission_valid"] == 0


# ----------------------------------------------------------------------------------------------------
# link rules: ACK loss, late ACKs, session 0, garbage


def test_a_lost_ack_is_resent_for_the_same_frame_and_the_action_runs_once() -> None:
    host = FakeHost()
    host.activate_and_obtain()
    host.device.drop_acks(1)
    raw, seq = host.frame("flight_task", {"command": TAKEOFF})
    host.write(raw)
    host.run(0.5)  # the host's timeout: no ACK came
    assert (2, seq) not in host.acks and host.model.task == "takeoff"
    host.write(raw)  # the same frame: same session, same seq
    assert cmds.decode_ack("flight_task", host.ack_for(2, seq).data).fields["ack"] == 0  # not 8 "running"
    assert host.model.actions["flight_task"] == 1 and host.model.duplicates == 1
    assert host.model.acks_dropped == 1


def test_a_late_ack_and_a_resend_in_between() -> None:
    host = FakeHost()
    host.activate_and_obtain()
    host.model.ack_delay = 0.3
    raw, seq = host.frame("wp_init", {"length": 2, "vel_cmd_range": 5.0, "idle_vel": 2.0})
    host.write(raw)
    assert (2, seq) not in host.acks
    host.run(0.1)
    host.write(raw)  # the host gave up early and resent: the stored ACK is queued again
    host.run(0.22)
    assert [(f.session, f.seq) for f in host.ack_log[2:]] == [(2, seq)]  # the first, 0.3 s late
    host.run(0.2)
    assert [(f.session, f.seq, f.data) for f in host.ack_log[2:]] == [(2, seq, b"\x00")] * 2
    assert host.model.actions["wp_init"] == 1 and host.model.duplicates == 1


def test_session_zero_commands_act_without_an_ack() -> None:
    host = FakeHost()
    host.request("activate", {"app_id": APP_ID})
    raw, seq = host.frame("obtain_control", {"control": 1}, session=0)
    host.write(raw)
    host.write(raw)  # session 0 has no duplicate suppression: both act
    host.run(0.5)
    assert (0, seq) not in host.acks
    assert host.model.sdk_control and host.model.actions["obtain_control"] == 2


@given(st.binary(max_size=300), st.booleans())
def test_random_bytes_never_raise_and_a_frame_after_them_is_answered(noise: bytes, split: bool) -> None:
    host = FakeHost()
    raw, seq = host.frame("get_version", {"arbitrary": 1}, session=3)
    if split:
        host.write(noise)
        host.write(raw)
    else:
        host.write(noise + raw)
    host.run(0.2)  # an idle line flushes whatever the noise started
    assert (3, seq) in host.acks
    assert host.model.errors == 0


def test_a_truncated_frame_does_not_hold_back_the_next_one() -> None:
    host = FakeHost()
    header = encode_frame(bytes(900), session=2, seq=1)[:12]  # a valid header announcing 916 bytes
    raw, seq = host.frame("get_version", {}, session=3)
    host.write(header + raw)
    assert (3, seq) not in host.acks  # still inside the announced frame
    host.run(0.2)  # the line goes quiet: the FC gives up on it and finds the frame behind
    assert (3, seq) in host.acks and host.model.bad_frames >= 1


def test_go_home_altitude_read_answers_the_value_held() -> None:
    """``01 41`` used to get the unknown-command 0xFF00; DJI's library (getGoHomeAltitudeSync) reads the
    value from the write's ACK layout and wants its hash echoed."""
    host = FakeHost()
    host.activate_and_obtain()
    raw, seq = host.frame("go_home_altitude_read")
    host.write(raw)
    ack = host.ack_for(2, seq).data
    assert ack == bytes([0]) + cmds.GO_HOME_ALTITUDE_HASH.to_bytes(4, "little") + (20).to_bytes(2, "little")
    assert host.request("go_home_altitude_write", {"altitude": 75})["ack"] == 0
    assert host.request("go_home_altitude_read") == {
        "ack": 0,
        "hash": cmds.GO_HOME_ALTITUDE_HASH,
        "altitude": 75,
    }
    assert host.model.actions["go_home_altitude_read"] == 2 and host.model.unknown_commands == 0
    # another parameter's hash (USE_RTK_DATA): ret code 1, nothing else read
    host.write(encode_command(0x01, 0x41, (1288992843).to_bytes(4, "little"), 2, 7))
    assert host.ack_for(2, 7).data[0] == 1


def test_bad_payloads_get_the_commands_invalid_code() -> None:
    host = FakeHost()
    host.request("activate", {"app_id": APP_ID})
    host.write(encode_command(0x03, 0x12, b"\x00\x00", 2, 7))  # wp_start_stop is 1 byte
    assert host.ack_for(2, 7).data == b"\xf4"
    host.write(encode_command(0x00, 0x01, b"\x00", 2, 8))  # activation is 44 bytes
    assert host.ack_for(2, 8).data == (1).to_bytes(2, "little")
    assert host.model.bad_payloads == 2 and host.model.errors == 0


def test_unknown_commands_and_subscription_are_answered_not_ignored() -> None:
    """A real FC answers what asks for an answer: a silent FC leaves a client such as DJI's Onboard-SDK
    library waiting on its ACK until the time-out. The subscription commands without a layout (0x0B
    0x04..0x06; 0x00..0x03 are simulated, test_osdk_subscription.py) get the u8 "permission deny" the
    library understands, never the u16 unknown-command code whose first byte reads as success."""
    host = FakeHost()
    host.request("activate", {"app_id": APP_ID})
    host.write(encode_command(0x07, 0x07, b"\x00", 2, 9))  # no such command
    assert host.ack_for(2, 9, timeout=0.1).data == UNKNOWN_COMMAND_ACK.to_bytes(2, "little")
    for seq, cmd_id in ((10, 0x04), (11, 0x05), (12, 0x06)):  # frequency, pause/resume, config
        host.write(encode_command(0x0B, cmd_id, b"\x00" * 4, 2, seq))
        assert host.ack_for(2, seq, timeout=0.1).data == bytes([SUBSCRIBE_REFUSED_ACK])
    assert host.model.subscriptions_refused == 3 and host.model.unknown_commands == 4
    host.write(encode_command(0x07, 0x08, b"\x00", 0, 13))  # session 0 asks for nothing: nothing comes
    host.run(0.2)
    assert (0, 13) not in host.acks


# ----------------------------------------------------------------------------------------------------
# RC takeover, hotpoint, follow me


def test_rc_takeover_pushes_lost_authority_until_acked() -> None:
    host = FakeHost()
    host.takeoff()
    host.send("movement_control", {"flag": control_flag(), "x": 2.0, "y": 0, "z": 0, "yaw": 0})
    host.run(1.0)
    host.device.rc_takeover()
    host.run(0.6)
    lost = [f for f in host.pushes if (f.cmd_set, f.cmd_id) == (0x02, 0x01)]
    assert (
        len(lost) == 2
        and lost[0].session >= 2
        and (lost[1].session, lost[1].seq) == (lost[0].session, lost[0].seq)
    )
    assert cmds.decode_request(0x02, 0x01, lost[0].payload).fields == {"reason": 4}
    host.write(
        encode_ack(lost[0].session, lost[0].seq, cmds.encode_ack_payload("lost_authority_push", {"ack": 0}))
    )
    host.run(2.0)
    assert len([f for f in host.pushes if (f.cmd_set, f.cmd_id) == (0x02, 0x01)]) == 2  # ACKed: no more
    m = host.model
    assert not m.sdk_control and m.task == "hover" and m.speed < 0.01 and len(m.host_acks) == 1
    assert host.request("obtain_control", {"control": 1})["ack"] == 0x0006  # the switch is in P now


def test_hotpoint_circles_its_centre() -> None:
    host = FakeHost()
    host.takeoff()
    m = host.model
    lat, lon = m.to_latlon(0.0, 20.0)
    hp = {"hp_latitude": lat, "hp_longitude": lon, "hp_altitude": 8.0, "hp_radius": 12.0, "angle_rate": 15.0}
    assert host.request("hp_upload_start", hp | {"hp_radius": 2.0}) == {"ack": 0xC2, "max_radius": 500.0}
    assert host.request("hp_upload_start", hp | {"angle_rate": 40.0})["ack"] == 0xC3
    assert host.request("hp_upload_start", hp | {"is_clockwise": 1})["ack"] == 0
    host.run(20.0)
    radius = math.hypot(m.n - 0.0, m.e - 20.0)
    assert abs(radius - 12.0) < 0.5 and abs(m.u - 8.0) < 0.1
    assert m.speed == pytest.approx(math.radians(15.0) * 12.0, rel=0.05)
    status = host.statuses()[-1]
    assert status["mission_type"] == 2 and status["mission_status"] == 1
    assert abs(status["hp_exec_radius"] - 1200) < 50 and status["hp_exec_vel"] == 150
    assert (host.latest("status") or {}).get("display_mode") == 9
    assert host.request("hp_pause_resume", {"pause": 0})["ack"] == 0
    assert host.request("hp_pause_resume", {"pause": 0})["ack"] == 0xA9
    assert host.request("hp_download", {})["hp_radius"] == 12.0
    assert host.request("hp_stop", {})["ack"] == 0
    assert host.request("hp_stop", {})["ack"] == 0xD4
    host.run(3.0)
    assert m.task == "hover" and m.speed < 0.01


def test_follow_me_follows_the_target() -> None:
    host = FakeHost()
    host.takeoff()
    m = host.model
    lat, lon = m.to_latlon(0.0, 0.0)
    fm = {"yaw_mode": 1, "init_latitude": lat, "init_longitude": lon, "init_alti": 0}
    assert host.request("fm_upload_start", fm)["ack"] == 0
    lat, lon = m.to_latlon(-20.0, 5.0)
    host.send("fm_update_target", {"latitude": lat, "longitude": lon})  # NO ACK, session 0
    host.run(10.0)
    assert math.hypot(m.n + 20.0, m.e - 5.0) < 0.3
    assert host.statuses()[-1]["mission_type"] == 3
    assert host.request("fm_pause_resume", {"pause": 0})["ack"] == 0
    assert host.request("fm_stop", {})["ack"] == 0
    assert host.request("fm_stop", {})["ack"] == 0xD4


# ----------------------------------------------------------------------------------------------------
# over a real byte boundary


@pytest.fixture
def pty_fc() -> Iterator[tuple[OsdkFcDevice, SerialHost]]:
    device = OsdkFcDevice(OsdkFcModel(app_id=APP_ID))
    endpoint = PtyEndpoint(device).start()
    host = SerialHost(endpoint.path)
    try:
        yield device, host
    finally:
        host.close()
        endpoint.stop()


def test_pty_activation_control_and_the_rc_switch(pty_fc: tuple[OsdkFcDevice, SerialHost]) -> None:
    device, host = pty_fc
    assert host.request("get_version", {})["ack"] == NOT_ACTIVATED_ACK
    assert host.request("activate", {"app_id": 1})["ack"] == 0x0006
    assert host.request("activate", {"app_id": APP_ID})["ack"] == 0
    device.inspect(lambda m: setattr(m, "rc_mode", "P"))
    assert host.request("obtain_control", {"control": 1})["ack"] == 0x0006
    device.inspect(lambda m: setattr(m, "rc_mode", "F"))
    assert host.request("obtain_control", {"control": 1})["ack"] == 0x0002
    assert device.inspect(lambda m: m.sdk_control)
    assert host.bad == 0


def test_pty_takeoff_shows_in_air_at_1_2_m(pty_fc: tuple[OsdkFcDevice, SerialHost]) -> None:
    _, host = pty_fc
    host.activate_and_obtain()
    assert host.request("flight_task", {"command": TAKEOFF})["ack"] == 0

    def hovering() -> bool:
        status, pos = host.latest("status"), host.latest("position")
        return bool(status and pos and status["flight"] == 2 and status["display_mode"] == 6)

    host.wait_for(hovering, 10, "in the air, hovering")
    pos = host.latest("position")
    assert pos is not None and abs(pos["height"] - 1.2) < 0.1


def test_pty_lost_ack_resend_acts_once(pty_fc: tuple[OsdkFcDevice, SerialHost]) -> None:
    device, host = pty_fc
    host.activate_and_obtain()
    device.drop_acks(1)
    raw, seq = host.frame("flight_task", {"command": TAKEOFF})
    host.write(raw)
    host.wait_for(lambda: device.inspect(lambda m: m.acks_dropped == 1), 5, "the dropped ACK")
    assert (2, seq) not in host.acks
    host.write(raw)
    assert cmds.decode_ack("flight_task", host.ack_for(2, seq).data).fields == {"ack": 0}
    assert device.inspect(lambda m: (m.actions["flight_task"], m.duplicates)) == (1, 1)


def test_pty_far_waypoint_is_refused_on_the_last_ack(pty_fc: tuple[OsdkFcDevice, SerialHost]) -> None:
    device, host = pty_fc
    host.activate_and_obtain()
    acks = _mission(host, device.model, [(10.0, 0.0, 10.0), (20.0, 0.0, 10.0), (0.0, 3000.0, 10.0)])
    assert acks == [{"ack": 0, "index": 0}, {"ack": 0, "index": 1}, {"ack": 0xC7, "index": 2}]
    upload = host.wait_for(lambda: [e for e in host.events() if e["incident_type"] == 0], 5, "upload event")
    assert upload[0]["is_mission_valid"] == 0


def test_pty_rc_takeover_push(pty_fc: tuple[OsdkFcDevice, SerialHost]) -> None:
    device, host = pty_fc
    host.activate_and_obtain()
    device.rc_takeover()
    lost = host.wait_for(lambda: [f for f in host.pushes if (f.cmd_set, f.cmd_id) == (2, 1)], 5, "0x02 0x01")
    host.write(encode_ack(lost[0].session, lost[0].seq, b"\x00\x00"))
    host.wait_for(lambda: device.inspect(lambda m: len(m.host_acks)) == 1, 5, "the FC to see our ACK")
    assert lost[0].payload == b"\x04" and not device.inspect(lambda m: m.sdk_control)


def test_tcp_endpoint_serves_the_flight_controller() -> None:
    device = OsdkFcDevice(OsdkFcModel(app_id=APP_ID))
    endpoint = TcpEndpoint(device).start()
    host = SerialHost(endpoint.url)
    try:
        host.activate_and_obtain()
        host.wait_for(lambda: len(host.flight_data()) >= 3, 5, "flight data")
        status = host.latest("status")
        assert status is not None and status["flight"] == 0 and status["display_mode"] == 6
        assert host.bad == 0
    finally:
        host.close()
        endpoint.stop()


def test_main_prints_where_it_listens_and_stops_on_sigterm() -> None:
    code = "import sys; from adapters.osdk.sim import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            code,
            "--tcp",
            "0",
            "--app-id",
            "7",
            "--home",
            "48.85,2.35",
            "--setpoint-hold",
            "0.5",
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    try:
        assert proc.stdout is not None
        first = proc.stdout.readline().strip()
        assert first.startswith("OSDK flight controller simulator at socket://127.0.0.1:")
        assert "set-points held 0.5 s" in proc.stdout.readline()
        host = SerialHost(first.rsplit(" ", 1)[1])
        try:
            assert host.request("activate", {"app_id": 7})["ack"] == 0
            pos = host.wait_for(lambda: host.latest("position"), 5, "a position push")
            assert pos["latitude"] == pytest.approx(math.radians(48.85), abs=1e-9)
        finally:
            host.close()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
            proc.wait()
        if proc.stdout:
            proc.stdout.close()


def test_main_rejects_a_bad_home() -> None:
    with pytest.raises(SystemExit):
        main(["--home", "95,10"])


@pytest.mark.parametrize("hold", ["0", "-1", "nan", "forever"])
def test_main_rejects_a_bad_setpoint_hold(hold: str) -> None:
    with pytest.raises(SystemExit):
        main(["--setpoint-hold", hold])
    with pytest.raises(ValueError, match="setpoint_hold"):
        OsdkFcModel(setpoint_hold=float(hold) if hold != "forever" else -math.inf)
