"""The RoboMaster robot end to end: a cloud-side paho client → a real mosquitto → the gateway →
0xA5 frames through a real pseudo-terminal (pyserial on the slave, the simulator on the master) →
the simulated referee and main board → osd, state, events and topology back to the cloud."""

from __future__ import annotations

import gc
import json
import math
import os
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from adapters.robomaster.adapter import RobotAdapter
from adapters.robomaster.commands import DEFAULT_CONTROL, INTERACTION_CMD_ID, ControlChannel
from adapters.robomaster.config import RobomasterDeviceSettings
from adapters.robomaster.sim import RefereeMatch, RobomasterSim, Stages
from adapters.simio import PtyEndpoint
from gateway.cli.run import SIM_ROBOT_SN, SIM_ROBOT_URL, simulated_settings, start_simulators
from gateway.local_broker import LocalBroker
from gateway.settings import ConfigError, load_settings
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until

pytestmark = pytest.mark.broker

GW = "GW-TEST-1"
SN = "RM-T-1"
PI = "39-0-7"
FAST = Stages(not_started=0.2, preparation=0.3, self_check=0.3, countdown=0.5, in_game=120.0, settling=1.0)


class Rig:
    """The simulator on a pty behind a symlink (as /dev/serial/by-id/… would be), the gateway, the cloud."""

    def __init__(
        self,
        broker: LocalBroker,
        tmp_path: Path,
        season: str,
        sim_control: ControlChannel = DEFAULT_CONTROL,
        gateway: dict[str, Any] | None = None,
        **device: Any,
    ) -> None:
        self.season, self.sim_control = season, sim_control
        self.link = tmp_path / "ttyRM0"
        self.endpoint = self._endpoint()
        self.cloud = CloudClient(broker.host, broker.port, GW)
        doc = {"type": "robomaster", "sn": SN, "url": str(self.link), "season": season, **device}
        self.gw = GatewayThread(gateway_settings(broker.port, [doc], **(gateway or {}))).start()

    def _endpoint(self) -> PtyEndpoint:
        match = RefereeMatch(season=self.season, stages=FAST, shot_period=1.0, hit_period=0)
        endpoint = PtyEndpoint(RobomasterSim(match, control=self.sim_control)).start()
        tmp = self.link.with_suffix(".new")
        tmp.unlink(missing_ok=True)
        os.symlink(endpoint.path, tmp)
        os.replace(tmp, self.link)  # atomic: the gateway never sees a missing link mid-swap
        return endpoint

    @property
    def sim(self) -> RobomasterSim:
        return self.endpoint.device  # type: ignore[return-value]

    @property
    def adapter(self) -> RobotAdapter:
        assert self.gw.app is not None
        adapter = self.gw.app.devices.by_sn(SN)
        assert isinstance(adapter, RobotAdapter)
        return adapter

    def board(self, attr: str) -> Any:
        with self.sim.lock:
            return getattr(self.sim.board, attr)

    def replug(self) -> None:
        """Close the pty (the adapter's read fails) and plug a fresh simulator in behind the link."""
        self.endpoint.stop()
        self.endpoint = self._endpoint()

    def osd(self, predicate: Any, timeout: float = 5.0) -> dict[str, Any]:
        return self.cloud.wait_for(f"{SN}/osd", lambda b: predicate(b["data"]), timeout=timeout)[-1]["data"]

    def in_topology(self, present: bool, timeout: float = 6.0) -> None:
        """The robot's own update_topo (it is announced as its own gateway) lists it, or no longer does."""
        self.cloud.wait_for(
            f"{SN}/status",
            lambda b: any(d["sn"] == SN for d in b["data"]["sub_devices"]) == present,
            timeout=timeout,
        )

    def close(self) -> None:
        self.gw.stop()
        self.cloud.close()
        self.endpoint.stop()
        del self.gw, self.cloud
        _collect()


def _collect() -> None:
    """Free stopped gateways and cloud clients now. paho keeps an internal socket pair open after
    loop_stop() until its client is finalised; both clients sit in reference cycles, and a cycle
    collected later may finalise a socket before its client (a ResourceWarning, an error here)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        gc.collect()


@pytest.fixture
def rig(broker: LocalBroker, tmp_path: Path) -> Iterator[Rig]:
    r = Rig(broker, tmp_path, "2026", payload_index=PI)
    try:
        r.in_topology(True)
        yield r
    finally:
        r.close()


def _ok(reply: dict[str, Any]) -> None:
    assert reply["data"]["result"] == 0, reply


@pytest.mark.parametrize("season", ["2024", "2025", "2026"])
def test_match_telemetry_arrives_as_osd_and_state(broker: LocalBroker, tmp_path: Path, season: str) -> None:
    r = Rig(broker, tmp_path, season)
    try:
        # the robot is its own gateway in a domain no DJI device claims (docs/cloud-api.md "Device tree"):
        # announced on its own status topic, listing itself; the dock's update_topo does not hold it
        topo = r.cloud.wait_for(f"{SN}/status", lambda b: len(b["data"]["sub_devices"]) == 1)[-1]
        assert topo["gateway"] == SN and (topo["data"]["domain"], topo["data"]["type"]) == ("100", 1)
        sub = topo["data"]["sub_devices"][0]
        assert (sub["sn"], sub["domain"], sub["type"], sub["index"]) == (SN, "100", 1, "A")
        dock = r.cloud.wait_for(f"{GW}/status", count=1) + r.cloud.find(f"{GW}/status")
        assert all(b["data"]["sub_devices"] == [] for b in dock)
        # state on change: the robot id, then the match's stages up to "in game"
        r.cloud.wait_for(f"{SN}/state", lambda b: b["data"].get("x_robot_id") == 3)
        r.cloud.wait_for(f"{SN}/state", lambda b: b["data"].get("x_game_progress") == 4)
        progress = [
            b["data"]["x_game_progress"]
            for b in r.cloud.find(f"{SN}/state")
            if "x_game_progress" in b["data"]
        ]
        assert progress == sorted(progress) and progress[-1] == 4  # each stage once, in order
        osd = r.osd(lambda d: d.get("x_stage_remain_time", 0) > 100 and d.get("x_shooter_heat", [0])[0] > 0)
        assert osd["x_robot_id"] == 3 and osd["x_hp"] == 200 and osd["x_max_hp"] == 200
        assert osd["x_position"] == {"x": 2.0, "y": 7.5} and osd["attitude_head"] == 90.0
        assert osd["x_buffer_energy"] == 60
        assert len(osd["x_shooter_heat"]) == (2 if season == "2026" else 3)
        assert ("x_chassis_power" in osd) == (season == "2024")
        app = r.gw.app
        assert app is not None and app.metrics.count("outbound_invalid_total") == 0
    finally:
        r.close()


def test_a_velocity_command_moves_the_robot_and_its_hold_ends(rig: Rig) -> None:
    start = rig.osd(lambda d: "x_position" in d)["x_position"]
    _ok(rig.cloud.service("x_robomaster_chassis_velocity", {"vx": 1.0, "duration": 1.0}))
    # the referee reports the new position (0x0203) and the gateway publishes it
    moved = rig.osd(lambda d: "x_position" in d and d["x_position"]["x"] > start["x"] + 0.5)
    assert moved["x_position"]["y"] == pytest.approx(start["y"], abs=0.05)
    # resent at >= 10 Hz while the hold lasts, then zero: the robot stops about 1 m further on
    wait_until(lambda: rig.board("vx") == 0.0 and rig.adapter.velocity == (0.0, 0.0, 0.0), 3, what="stopped")
    assert rig.board("received")["chassis_velocity"] >= 10
    x = rig.board("x")
    assert 2.0 + 0.8 <= x <= 2.0 + 1.3
    time.sleep(0.3)
    assert rig.board("x") == x  # nothing moves after the hold
    # a turn shows in attitude_head (compass: a left turn from east heads north, 90° → 0°)
    _ok(rig.cloud.service("x_robomaster_chassis_velocity", {"vx": 0.0, "wz": math.pi / 2, "duration": 0.5}))
    rig.osd(lambda d: d.get("attitude_head", 90) < 80)
    # the turn's hold ends (its last, zero frame reached the board) before counting what arrives
    wait_until(lambda: rig.adapter.velocity == (0.0, 0.0, 0.0) and rig.board("wz") == 0.0, 3, what="turned")
    # over the device's limits: refused before anything moves
    before = rig.board("received")["chassis_velocity"]
    bad = rig.cloud.service("x_robomaster_chassis_velocity", {"vx": 5.0})
    assert bad["data"]["result"] == 325001 and "vx" in bad["data"]["output"]["reason"]
    assert rig.cloud.service("x_robomaster_chassis_velocity", {"vx": 99.0})["data"]["result"] == 325001
    assert rig.board("received")["chassis_velocity"] == before


def test_stop_ends_motion_at_once(rig: Rig) -> None:
    _ok(rig.cloud.service("x_robomaster_chassis_velocity", {"vx": 0.5, "vy": 0.5, "sn": SN, "duration": 5.0}))
    wait_until(lambda: rig.board("vx") == 0.5, 3, what="moving")
    _ok(rig.cloud.service("x_robomaster_stop", {"sn": SN}))
    wait_until(lambda: rig.board("last_stop_reason") == 0, 3, what="stop reason 0 (operator)")
    assert rig.board("vx") == 0.0 and rig.adapter.velocity == (0.0, 0.0, 0.0)
    sent = rig.board("received")["chassis_velocity"]
    time.sleep(0.3)
    assert rig.board("received")["chassis_velocity"] == sent  # the resend loop ended too
    unknown = rig.cloud.service("x_robomaster_stop", {"sn": "NO-SUCH-ROBOT"})
    assert unknown["data"]["result"] == 325001


def test_gimbal_angle_and_the_gimbal_as_a_payload(rig: Rig) -> None:
    _ok(rig.cloud.service("x_robomaster_gimbal_angle", {"yaw": 90.0, "pitch": 10.0}))
    wait_until(lambda: abs(rig.board("gimbal_yaw_set") - math.pi / 2) < 1e-6, 3, what="gimbal set-point")
    assert rig.board("gimbal_pitch_set") == pytest.approx(math.radians(10))
    assert (
        rig.cloud.service("x_robomaster_gimbal_angle", {"yaw": 0.0, "pitch": 60.0})["data"]["result"]
        == 325001
    )
    # camera_screen_drag / gimbal_reset need payload authority, like any payload
    drag = {"payload_index": PI, "locked": False, "pitch_speed": 20.0, "yaw_speed": 0.0}
    assert rig.cloud.service("camera_screen_drag", drag)["data"]["result"] == 319031
    _ok(rig.cloud.service("payload_authority_grab", {"payload_index": PI}))
    _ok(rig.cloud.service("camera_screen_drag", drag))
    wait_until(lambda: rig.board("gimbal_pitch_set") > math.radians(15), 3, what="pitch dragged up")
    wait_until(lambda: not rig.adapter.dragging, 3, what="drag over")
    _ok(rig.cloud.service("gimbal_reset", {"payload_index": PI, "reset_mode": 1}))  # yaw 0, pitch down
    wait_until(
        lambda: rig.board("gimbal_pitch_set") == pytest.approx(math.radians(-20)), 3, what="pitch down"
    )
    assert rig.board("gimbal_yaw_set") == 0.0
    photo = rig.cloud.service("camera_photo_take", {"payload_index": PI})
    assert photo["data"]["result"] == 399001


def test_interaction_data_reaches_the_robot_board(rig: Rig) -> None:
    wait_until(lambda: rig.adapter.robot_id == 3, 3, what="own robot id")
    data = {"data_cmd_id": 0x0233, "receiver_id": 4, "data": "68656c6c6f00ff"}
    _ok(rig.cloud.service("x_robomaster_interaction", data))
    wait_until(lambda: rig.board("interactions"), 3, what="interaction relayed")
    assert rig.board("interactions") == [
        {
            "data_cmd_id": 0x0233,
            "sender_id": 3,
            "receiver_id": 4,
            "user_data": bytes.fromhex("68656c6c6f00ff"),
        }
    ]
    too_long = rig.cloud.service("x_robomaster_interaction", {**data, "data": "00" * 113})
    odd = rig.cloud.service("x_robomaster_interaction", {**data, "data": "abc"})
    not_0301 = rig.cloud.service("x_robomaster_interaction", {**data, "data_cmd_id": 0x0301})
    assert [x["data"]["result"] for x in (too_long, odd, not_0301)] == [325001] * 3
    assert len(rig.board("interactions")) == 1


def test_referee_warnings_and_hits_become_events(rig: Rig) -> None:
    wait_until(lambda: rig.adapter.robot_id == 3, 3, what="own robot id")
    with rig.sim.lock:
        rig.sim.match.penalize(2, 3)
    ev = rig.cloud.wait_for("events", lambda b: b["method"] == "x_robomaster_referee_warning")[0]
    assert ev["need_reply"] == 1 and ev["gateway"] == GW
    assert ev["data"] == {"level": 2, "offending_robot_id": 3, "count": 1, "robot_id": 3}
    # the referee repeats the last penalty at 1 Hz: still one event (answered, so no resend either)
    rig.cloud.publish(
        f"thing/product/{GW}/events_reply",
        {"tid": ev["tid"], "bid": ev["bid"], "method": ev["method"], "data": {"result": 0}},
    )
    wait_until(lambda: rig.sim.match.sent["referee_warning"] >= 3, 5, what="repeats")
    with rig.sim.lock:
        rig.sim.match.penalize(2, 3)  # a second penalty: count 2 is news
    second = rig.cloud.wait_for("events", lambda b: b["data"].get("count") == 2)[0]
    warnings = rig.cloud.find("events", lambda b: b["method"] == "x_robomaster_referee_warning")
    assert {w["tid"] for w in warnings} == {ev["tid"], second["tid"]}
    with rig.sim.lock:
        rig.sim.match.hurt(armor_id=1, reason=0, damage=50)
    hurt = rig.cloud.wait_for("events", lambda b: b["method"] == "x_robomaster_hurt")[0]
    assert (
        hurt["data"] == {"armor_id": 1, "hp_deduction_reason": 0, "robot_id": 3} and hurt["need_reply"] == 0
    )
    rig.osd(lambda d: d.get("x_hp") == 150)


def test_pty_closed_and_reopened(rig: Rig) -> None:
    opens = rig.adapter.link_stats().opens
    rig.cloud.clear()
    rig.replug()  # the pty the gateway had open is gone; a new one sits behind the same path
    rig.in_topology(False)
    rig.cloud.clear()
    rig.in_topology(True)
    assert rig.adapter.link_stats().opens > opens  # SerialLink reopened, not merely a silent gap
    rig.osd(lambda d: d.get("x_robot_id") == 3)
    _ok(rig.cloud.service("x_robomaster_chassis_velocity", {"vx": 1.0, "duration": 0.3}))
    wait_until(lambda: rig.board("received")["chassis_velocity"] >= 1, 3, what="commands reach the new pty")


def test_a_silent_robot_goes_offline_and_comes_back(broker: LocalBroker, tmp_path: Path) -> None:
    r = Rig(broker, tmp_path, "2026", silence_timeout=0.5)
    try:
        r.in_topology(True)
        _ok(r.cloud.service("x_robomaster_chassis_velocity", {"vx": 1.0, "duration": 5.0}))
        r.cloud.clear()
        r.endpoint.paused = True  # nothing from the referee (the board still listens)
        r.in_topology(False)
        t0 = time.monotonic()
        assert r.cloud.service("x_robomaster_stop", {})["data"]["result"] == 325012
        assert time.monotonic() - t0 < 1.0
        assert r.adapter.velocity == (0.0, 0.0, 0.0)  # motion ended when the robot fell silent
        r.endpoint.paused = False
        r.in_topology(True)
        _ok(r.cloud.service("x_robomaster_stop", {}))
    finally:
        r.close()


def test_simulated_robot_of_run_simulate(broker: LocalBroker) -> None:
    doc = simulated_settings({"broker": {"url": f"mqtt://127.0.0.1:{broker.port}"}, "osd_period": 0.2,
                              "metrics": {"enabled": False}})  # fmt: skip
    doc["devices"] = [d for d in doc["devices"] if d["type"] == "robomaster"]
    sims: list[Any] = []
    settings = start_simulators(load_settings(None, **doc), sims)
    cloud = CloudClient(broker.host, broker.port, settings.gateway_sn)
    gw = GatewayThread(settings)
    try:
        (robot,) = settings.devices
        assert robot.url != SIM_ROBOT_URL and robot.url.startswith("socket://127.0.0.1:")
        with gw:
            cloud.wait_for(f"{SIM_ROBOT_SN}/osd", lambda b: "x_position" in b["data"], timeout=10)
    finally:
        cloud.close()
        for sim in sims:
            sim.stop()
    del gw, cloud
    _collect()


def test_control_messages_wrapped_in_0301(broker: LocalBroker, tmp_path: Path) -> None:
    wrapped = ControlChannel(INTERACTION_CMD_ID, data_cmd_id=0x0250, receiver_id=3)
    control = {"cmd_id": INTERACTION_CMD_ID, "data_cmd_id": 0x0250, "receiver_id": 3}
    r = Rig(broker, tmp_path, "2024", sim_control=wrapped, control=control)
    try:
        r.in_topology(True)
        _ok(r.cloud.service("x_robomaster_chassis_velocity", {"vx": 0.5, "duration": 0.3}))
        wait_until(lambda: r.board("received")["chassis_velocity"] >= 1, 3, what="wrapped velocity")
        assert r.board("interactions") == []  # read as control, not as data to relay
        # the referee wants our own id as the sender: learnt from 0x0201
        wait_until(lambda: r.adapter._control.sender_id == 3, 3, what="sender id")
        clash = {"data_cmd_id": 0x0250, "receiver_id": 4, "data": "00"}
        reply = r.cloud.service("x_robomaster_interaction", clash)
        assert reply["data"]["result"] == 325001 and "control" in reply["data"]["output"]["reason"]
        _ok(r.cloud.service("x_robomaster_interaction", {**clash, "data_cmd_id": 0x0251}))
        wait_until(lambda: r.board("interactions"), 3, what="relayed")
    finally:
        r.close()


def test_shutting_the_gateway_down_stops_the_robot(rig: Rig) -> None:
    _ok(rig.cloud.service("x_robomaster_chassis_velocity", {"vx": 1.0, "duration": 5.0}))
    wait_until(lambda: rig.board("vx") == 1.0, 3, what="moving")
    rig.gw.stop()
    wait_until(lambda: rig.board("received")["stop"] >= 2, 3, what="stop frames")
    assert rig.board("vx") == 0.0 and rig.board("last_stop_reason") == 3  # failsafe, then shutdown


@pytest.mark.parametrize(
    ("device", "where"),
    [
        ({"control": {"cmd_id": 0x0201}}, "control"),  # inside DJI's referee range
        ({"control": {"cmd_id": 0x0301, "data_cmd_id": 0x0100}}, "control"),  # not a student id
        ({"product": {"domain": "1"}}, "product"),  # would publish gimbal bodies
        ({"season": "2023"}, "season"),
    ],
)
def test_bad_robot_settings_fail_with_one_clear_line(device: dict[str, Any], where: str) -> None:
    doc = {"type": "robomaster", "sn": "R1", "url": "/dev/ttyUSB0", **device}
    with pytest.raises(ConfigError) as exc:
        load_settings(None, gateway_sn="GW", devices=[doc])
    assert f"devices.0.robomaster.{where}" in str(exc.value)
    assert RobomasterDeviceSettings(type="robomaster", sn="R1", url="/dev/ttyUSB0").product.domain == "100"


def test_live_control_drives_the_robot(broker: LocalBroker, tmp_path: Path) -> None:
    r = Rig(broker, tmp_path, "2026", gateway={"drc": {"stick_timeout": 0.5, "stream_hz": 25}})
    try:
        r.in_topology(True)
        _ok(r.cloud.service("flight_authority_grab", {}))  # the robot's motion, as an aircraft's flight
        same = {"address": f"127.0.0.1:{broker.port}", "client_id": "drc-rm", "username": "",
                "password": "", "expire_time": 4102444800, "enable_tls": False}  # fmt: skip
        _ok(r.cloud.service("drc_mode_enter", {"mqtt_broker": same, "osd_frequency": 10, "hsi_frequency": 1}))

        def down(method: str, data: dict[str, Any]) -> None:
            r.cloud.publish(
                f"thing/product/{GW}/drc/down", json.dumps({"method": method, "data": data}), qos=0
            )

        down("heart_beat", {"seq": 1, "timestamp": 1})
        for seq in range(1, 6):  # seed sticks: +y forward, +x left; w yaw rate (°/s)
            down("drone_control", {"seq": seq, "y": 1.0, "x": 0.5, "w": 0.0})
            time.sleep(0.1)
        wait_until(lambda: (r.board("vx"), r.board("vy")) == (1.0, 0.5), 3, what="driven forward and left")
        # sticks stop: the stream sends zeros, the robot stops
        wait_until(lambda: r.board("vx") == 0.0, 3, what="stopped with the sticks")
        down("drone_control", {"seq": 0, "y": 1.0})
        wait_until(lambda: r.board("vx") == 1.0, 3, what="driven again")
        down("drone_emergency_stop", {})
        wait_until(lambda: r.board("last_stop_reason") == 2, 3, what="emergency stop")
        assert r.board("vx") == 0.0
        _ok(r.cloud.service("drc_mode_exit", {}))
    finally:
        r.close()
