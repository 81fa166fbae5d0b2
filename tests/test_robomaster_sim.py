"""The RoboMaster simulator without a gateway: the referee's match (stages, rates, season layouts,
power and heat, hits, penalties), the main board obeying control messages on a real byte stream,
and ``dji-gateway simulate robomaster`` as its own process on a pty and a TCP port."""

from __future__ import annotations

import itertools
import math
import os
import re
import subprocess
import sys
from collections import Counter
from typing import Any

import pytest
import serial
from hypothesis import given
from hypothesis import strategies as st

from adapters.robomaster.commands import (
    INTERACTION_CMD_ID,
    ControlChannel,
    decode_message,
    encode_message,
)
from adapters.robomaster.describe import decode_bytes
from adapters.robomaster.protocol import Decoder, Frame, encode_frame
from adapters.robomaster.sim import (
    BOARD_HOLD_S,
    NOMINAL_RATES,
    RefereeMatch,
    RobomasterSim,
    RobotBoard,
    Stages,
)
from tests.support import wait_until

SEASONS = ("2024", "2025", "2026")
QUICK = Stages(not_started=1.0, preparation=2.0, self_check=2.0, countdown=5.0, in_game=20.0, settling=3.0)


class Run:
    """The referee and a board on a simulated clock (starting at t=100), ticked every ``step``."""

    def __init__(self, match: RefereeMatch, board: RobotBoard | None = None, step: float = 0.01) -> None:
        self.match, self.board, self.step = match, board or RobotBoard(), step
        self.k = 0

    @property
    def now(self) -> float:
        return 100.0 + self.k * self.step

    def __call__(self, seconds: float) -> bytes:
        out = bytearray()
        for _ in range(round(seconds / self.step)):
            self.board.advance(self.now)
            out += b"".join(self.match.tick(self.now, self.board))
            self.k += 1
        return bytes(out)


def records(data: bytes, season: str) -> list[dict[str, Any]]:
    recs = decode_bytes(data, season=season)
    bad = [r for r in recs if not r["valid"] or r["error"]]
    assert not bad, bad[:3]
    return recs


# --------------------------------------------------------------------------- the match


@pytest.mark.parametrize("season", SEASONS)
def test_every_frame_fits_its_season_table(season: str) -> None:
    match = RefereeMatch(season=season, stages=QUICK, hit_period=3.0)
    run = Run(match)
    data = run(20.0)
    match.penalize(2)
    data += run(0.05)
    recs = records(data, season)
    names = Counter(r["command"] for r in recs)
    assert set(names) >= {
        "game_status",
        "game_robot_hp",
        "robot_status",
        "power_heat_data",
        "robot_pos",
        "shoot_data",
        "hurt_data",
        "referee_warning",
        "projectile_allowance",
    }
    # the season decides the layout: 2026 reports only the ally side's HP and one 17 mm barrel
    power = next(r["fields"] for r in recs if r["command"] == "power_heat_data")
    hp = next(r["fields"] for r in recs if r["command"] == "game_robot_hp")
    if season == "2026":
        assert "shooter_17mm_barrel_heat" in power and "ally_3_robot_HP" in hp
    else:
        assert "shooter_17mm_1_barrel_heat" in power and "red_3_robot_HP" in hp
    assert ("chassis_power" in power) == (season == "2024")


def test_periodic_messages_keep_their_nominal_rates() -> None:
    run = Run(RefereeMatch(stages=QUICK, shot_period=0, hit_period=0))
    names = Counter(r["command"] for r in records(run(10.0), "2026"))
    for name, hz in NOMINAL_RATES.items():
        assert abs(names[name] - 10.0 * hz) <= 1, (name, names[name])


def test_game_status_counts_down_through_the_stages_and_loops() -> None:
    run = Run(RefereeMatch(stages=Stages(1, 2, 2, 5, 4, 2), shot_period=0, hit_period=0))
    seen = [r["fields"] for r in records(run(16.5), "2026") if r["command"] == "game_status"]
    progress = [f["game_progress"] for f in seen]
    # one full match (0..5) and the next one starting
    first = progress[: progress.index(5) + 1]
    assert first == sorted(first) and set(first) == {0, 1, 2, 3, 4, 5} and progress[-1] == 0
    assert [f["stage_remain_time"] for f in seen if f["game_progress"] == 3] == [5, 4, 3, 2, 1]
    assert all(f["game_type"] == 1 for f in seen)
    once = Run(RefereeMatch(stages=Stages(0.5, 0.5, 0.5, 0.5, 0.5, 1), loop=False))
    results = [r["fields"] for r in records(once(5.0), "2026") if r["command"] == "game_result"]
    assert results == [{"winner": 1}]  # red robot 3: red wins, once, when settling starts


def test_heat_rises_with_each_burst_and_cools_at_the_cooling_value() -> None:
    match = RefereeMatch(stages=QUICK, shot_period=2.0, burst=5, hit_period=0)
    run = Run(match)
    run(12.0)  # in game from t=10: the first burst at t=12
    run(0.02)
    assert match.shots == 5 and 45 <= match.heat <= 50
    heat = match.heat
    run(0.5)  # cooling 40/s (standard robot, level 1)
    assert match.heat == pytest.approx(heat - 20, abs=0.5)


def test_buffer_energy_pays_for_power_above_the_limit() -> None:
    match = RefereeMatch(stages=QUICK, shot_period=0, hit_period=0)
    run = Run(match)
    run.board.handle("chassis_velocity", {"vx": 3.0, "vy": 0.0, "wz": 0.0}, run.now)
    run(0.4)
    assert match.chassis_power > 60 and match.buffer_energy < 60
    run.board.handle("stop", {"reason": 0}, run.now)
    run(2.0)
    assert match.buffer_energy == 60


def test_penalties_repeat_at_1_hz_and_hits_cost_hp() -> None:
    match = RefereeMatch(stages=QUICK, shot_period=0, hit_period=0)
    run = Run(match)
    run(1.0)
    match.penalize(3, 4)
    warnings = [r["fields"] for r in records(run(3.0), "2026") if r["command"] == "referee_warning"]
    assert 3 <= len(warnings) <= 4 and all(
        w == {"level": 3, "offending_robot_id": 4, "count": 1} for w in warnings
    )
    match.penalize(3, 4)
    assert match.warning == (3, 4, 2)
    match.hurt(armor_id=2, reason=5, damage=30)
    recs = records(run(0.2), "2026")
    hurt = [r["fields"] for r in recs if r["command"] == "hurt_data"]
    assert hurt == [{"armor_id": 2, "HP_deduction_reason": 5}]
    status = [r["fields"] for r in recs if r["command"] == "robot_status"]
    assert status[-1]["current_HP"] == 170 and status[-1]["maximum_HP"] == 200


# --------------------------------------------------------------------------- the board


def test_board_drives_for_its_hold_then_stops() -> None:
    board = RobotBoard()
    board.handle("chassis_velocity", {"vx": 1.0, "vy": 0.0, "wz": 0.0}, 10.0)
    board.advance(10.4)
    assert board.x == pytest.approx(2.4) and board.y == pytest.approx(7.5)
    board.advance(10.0 + BOARD_HOLD_S + 0.5)  # no fresh command: it stopped by itself
    assert board.vx == 0.0 and board.x == pytest.approx(2.0 + BOARD_HOLD_S, abs=0.11)
    # a left turn at 90°/s for a second: facing north (bearing 0)
    board.handle("chassis_velocity", {"vx": 0.0, "vy": 0.0, "wz": math.pi / 2}, 20.0)
    for k in range(1, 6):
        board.handle("chassis_velocity", {"vx": 0.0, "vy": 0.0, "wz": math.pi / 2}, 20.0 + 0.2 * k)
    board.advance(21.0)
    assert board.bearing_deg == pytest.approx(0.0, abs=0.5) or board.bearing_deg == pytest.approx(
        360, abs=0.5
    )
    board.handle("chassis_velocity", {"vx": 50.0, "vy": 0.0, "wz": 0.0}, 30.0)
    board.advance(30.4)
    assert board.y == 15.0  # the field's edge


def test_board_gimbal_and_stop() -> None:
    board = RobotBoard()
    board.handle("gimbal_angle", {"yaw": 1.0, "pitch": 0.3}, 0.0)
    board.advance(0.1)
    assert 0 < board.gimbal_yaw < 1.0
    board.advance(1.0)
    assert board.gimbal_yaw == pytest.approx(1.0) and board.gimbal_pitch == pytest.approx(0.3)
    board.handle("chassis_velocity", {"vx": 1.0, "vy": 1.0, "wz": 1.0}, 1.0)
    board.handle("gimbal_angle", {"yaw": -1.0, "pitch": 0.0}, 1.0)
    board.handle("stop", {"reason": 2}, 1.05)
    board.advance(1.3)
    assert (board.vx, board.vy, board.wz, board.last_stop_reason) == (0.0, 0.0, 0.0, 2)
    assert board.gimbal_yaw == pytest.approx(0.7, abs=0.01)  # held where the stop found it


DEFAULT = ControlChannel()


def _control(name: str, fields: dict[str, Any], control: ControlChannel = DEFAULT, seq: int = 0) -> bytes:
    return encode_message(name, fields, "2026", seq, control)


@pytest.mark.parametrize(
    "control",
    [ControlChannel(), ControlChannel(cmd_id=0x0E7F), ControlChannel(INTERACTION_CMD_ID, 0x0233, 3, 3)],
)
def test_sim_obeys_control_frames_on_a_byte_stream(control: ControlChannel) -> None:
    sim = RobomasterSim(control=control)
    stream = (
        b"\x00\xa5\xff"
        + _control("chassis_velocity", {"vx": 0.5, "vy": -0.25, "wz": 0.0}, control, 1)
        + b"\xa5\x01\x02"
        + _control("gimbal_angle", {"yaw": 0.5, "pitch": -0.1}, control, 2)
    )
    for i in range(len(stream)):  # byte by byte
        sim.on_bytes(stream[i : i + 1], 5.0)
    assert sim.board.received == Counter({"chassis_velocity": 1, "gimbal_angle": 1})
    assert (sim.board.vx, sim.board.vy) == (0.5, -0.25) and sim.board.gimbal_yaw_set == pytest.approx(0.5)
    sim.on_bytes(_control("stop", {"reason": 0}, control), 5.1)
    assert sim.board.vx == 0.0 and sim.board.last_stop_reason == 0


def test_sim_relays_interaction_data_and_counts_what_it_cannot_read() -> None:
    sim = RobomasterSim()
    fields = {"data_cmd_id": 0x0201, "sender_id": 3, "receiver_id": 4, "user_data": b"\x01\x02hello"}
    sim.on_bytes(encode_message("robot_interaction_data", fields, "2026", 9), 1.0)
    assert sim.board.interactions == [fields]
    sim.on_bytes(encode_message("game_status", {}, "2024")[:-2] + b"\x00\x00", 1.0)  # bad CRC: dropped
    sim.on_bytes(encode_frame(0x0F01, b"\x09"), 1.0)  # our cmd_id, unknown message type
    assert sim.undecodable == 1 and sum(sim.board.received.values()) == 1


@given(st.lists(st.binary(max_size=64), max_size=20))
def test_random_bytes_never_raise(chunks: list[bytes]) -> None:
    sim = RobomasterSim()
    for k, chunk in enumerate(chunks):
        assert sim.on_bytes(chunk, float(k)) == b""
        sim.tick(float(k))


def test_tick_output_is_a_clean_frame_stream() -> None:
    sim = RobomasterSim(RefereeMatch(stages=QUICK))
    data = b"".join(sim.tick(100.0 + k * 0.01) for k in range(300))
    dec = Decoder()
    items = dec.feed(data) + dec.flush()
    assert items and all(isinstance(i, Frame) for i in items)
    seqs = [i.seq for i in items]
    assert all((b - a) & 0xFF == 1 for a, b in itertools.pairwise(seqs))
    assert all(decode_message(i, "2026").name for i in items)


# --------------------------------------------------------------------------- as its own process


def _spawn(*args: str) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen(
        [sys.executable, "-m", "gateway.cli", "simulate", "robomaster", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env=env,
    )


@pytest.mark.parametrize("where", [["--pty"], ["--tcp", "0"]])
def test_simulate_robomaster_process_prints_where_and_speaks_the_referee_protocol(where: list[str]) -> None:
    proc = _spawn(*where, "--season", "2024", "--robot-id", "103")
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        found = re.search(r"at (\S+)$", line.strip())
        assert found, line
        url = found.group(1)
        assert url.startswith("/dev/") if where == ["--pty"] else url.startswith("socket://127.0.0.1:")
        port = serial.serial_for_url(url, baudrate=115200, timeout=0.1)
        try:
            port.write(_control("chassis_velocity", {"vx": 1.0, "vy": 0.0, "wz": 0.0}))
            seen: dict[str, dict[str, Any]] = {}
            buffer = bytearray()

            def heard() -> bool:
                buffer.extend(port.read(4096))
                for rec in decode_bytes(bytes(buffer), season="2024"):
                    if rec["valid"] and rec["fields"] is not None:
                        seen[rec["command"]] = rec["fields"]
                return {"game_status", "robot_status", "robot_pos"} <= set(seen)

            wait_until(heard, 10, what="referee frames from the simulator")
            assert seen["robot_status"]["robot_id"] == 103 and "chassis_power" in seen["power_heat_data"]
        finally:
            port.close()
    finally:
        proc.terminate()
        assert proc.wait(5) == 0
        if proc.stdout:
            proc.stdout.close()
