"""SIGTERM on the real ``dji-gateway run`` process while every device moves: the aircraft mid-mission,
the robot driving, the gimbal dragging. Motion stops on every device before the exit, the offline
topology is published, and the process exits 0 within a bounded time."""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from adapters.osdk.sim import OsdkFcDevice
from adapters.robomaster.sim import RobomasterSim
from adapters.rsdk.sim import SlcanGimbal
from adapters.simio import TcpEndpoint
from gateway.local_broker import LocalBroker
from tests.support import CloudClient, wait_until

pytestmark = pytest.mark.broker
GW = "GW-SHUTDOWN-1"


def _config(tmp: Path, broker: LocalBroker, gimbal: str, aircraft: str, robot: str) -> Path:
    cfg = tmp / "gateway.toml"
    cfg.write_text(
        f"""gateway_sn = "{GW}"
[broker]
url = "{broker.url}"
[metrics]
enabled = false
[[devices]]
type = "rsdk"
sn = "RS-STOP-1"
interface = "slcan"
channel = "{gimbal}"
bus_options = {{ sleep_after_open = 0 }}
[[devices]]
type = "osdk"
sn = "FC-STOP-1"
url = "{aircraft}"
on_stop = "hover"
[[devices]]
type = "robomaster"
sn = "RM-STOP-1"
url = "{robot}"
"""
    )
    return cfg


def test_sigterm_mid_mission_stops_every_device(broker: LocalBroker, tmp_path: Path) -> None:
    gimbal, fc, robot = SlcanGimbal(), OsdkFcDevice(), RobomasterSim()
    endpoints = [TcpEndpoint(d).start() for d in (gimbal, fc, robot)]
    cfg = _config(tmp_path, broker, *(e.url for e in endpoints))
    cloud = CloudClient(broker.host, broker.port, GW)
    proc = subprocess.Popen(
        [sys.executable, "-m", "gateway.cli", "run", "--config", str(cfg)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        cloud.wait_for(f"{GW}/status", lambda b: len(b["data"]["sub_devices"]) == 2, timeout=20)
        cloud.wait_for("RM-STOP-1/status", lambda b: len(b["data"]["sub_devices"]) == 1, timeout=20)
        # the gimbal drags, the robot drives, the aircraft flies a mission
        assert cloud.service("payload_authority_grab", {"payload_index": "20-0-0"})["data"]["result"] == 0
        drive = {"sn": "RM-STOP-1", "vx": 1.0, "vy": 0.0, "wz": 0.0, "duration": 10.0}
        assert cloud.service("x_robomaster_chassis_velocity", drive)["data"]["result"] == 0
        assert cloud.service("flight_authority_grab", {})["data"]["result"] == 0
        home = fc.inspect(lambda m: (math.degrees(m.latitude), math.degrees(m.longitude)))
        target = {"target_latitude": home[0] + 0.003, "target_longitude": home[1], "target_height": 80.0,
                  "security_takeoff_height": 20.0, "rth_altitude": 30, "flight_id": "stop",
                  "max_speed": 10}  # fmt: skip
        assert cloud.service("takeoff_to_point", target)["data"]["result"] == 0
        wait_until(
            lambda: fc.inspect(lambda m: m.task == "waypoint" and m.speed > 3.0), 30, what="mission flying"
        )
        drag = {"payload_index": "20-0-0", "locked": False, "pitch_speed": 0.0, "yaw_speed": 20.0}
        assert cloud.service("camera_screen_drag", drag)["data"]["result"] == 0  # a drag lasts 0.5 s
        assert gimbal.model.yaw.speed == 20.0 and robot.board.vx == 1.0
        cloud.clear()

        t0 = time.monotonic()
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(15) == 0
        elapsed = time.monotonic() - t0

        # every motion stopped before the exit
        assert gimbal.model.yaw.speed == 0.0
        assert robot.board.last_stop_reason is not None and robot.board.vx == 0.0
        assert fc.inspect(lambda m: m.task) == "hover"  # mission cancelled, braking to a hover
        wait_until(lambda: fc.inspect(lambda m: m.speed) < 0.3, 10, what="aircraft hovering")
        assert cloud.wait_for(f"{GW}/status", timeout=5)[-1]["data"]["sub_devices"] == []
        # the robot, its own gateway, is announced offline on its own topic (the will covers only GW's)
        assert cloud.wait_for("RM-STOP-1/status", timeout=5)[-1]["data"]["sub_devices"] == []
        assert elapsed < 10.0
        # the take-off's final progress event went out before the offline topology
        kinds = [(t.rsplit("/", 1)[1], b.get("method"), (b.get("data") or {}).get("status"))
                 for t, b, _ in list(cloud.messages) if b is not None]  # fmt: skip
        final = ("events", "takeoff_to_point_progress", "wayline_cancel")
        assert final in kinds and kinds.index(final) < kinds.index(("status", "update_topo", None)), kinds
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
        out = proc.stdout.read() if proc.stdout else ""
        if proc.stdout:
            proc.stdout.close()
        cloud.close()
        for e in endpoints:
            e.stop()
    assert "Traceback" not in out, out[-3000:]
    # what each device was left doing, for the operator who stopped it
    assert "left FC-STOP-1 (aircraft) hovering at " in out and "m above home, its task cancelled" in out
    assert "left RS-STOP-1 (gimbal) holding yaw " in out
    assert "left RM-STOP-1 (robot) stopped" in out
