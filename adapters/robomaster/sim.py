"""A RoboMaster robot on its referee UART: the simulator every robot test talks to.

Two sans-I/O models (a clock value in, frames out; nothing here sleeps or reads a clock):

* :class:`RefereeMatch` plays a match as the referee system reports it: ``game_status`` counting
  down through the stages (not started, preparation, self-check, 5 s countdown, in game,
  settling; then a new match when ``loop``), HP, robot status, power and barrel heat, buffs,
  shots, projectile allowance, hits (``hurt_data``) and penalties (``referee_warning``, repeated
  at 1 Hz after the first, so a receiver is shown that a repeat is not a new penalty).
  Payloads follow the chosen season's layouts (``commands.REFEREE_TABLE``).
* :class:`RobotBoard` is the team's main board: it obeys the gateway's control messages
  (``chassis_velocity`` for at most :data:`BOARD_HOLD_S` after the last one, ``gimbal_angle``,
  ``stop``), integrates its pose on the field and records the 0x0301 interaction data it is asked
  to relay. The referee reports the board's pose through 0x0203.

:class:`RobomasterSim` combines them into a :class:`~adapters.simio.StreamDevice` for a
:class:`~adapters.simio.PtyEndpoint` (the gateway opens the pty path with pyserial) or a
:class:`~adapters.simio.TcpEndpoint` (``socket://127.0.0.1:PORT``); :func:`main` is
``dji-gateway simulate robomaster``.

Conventions of the simulated field (RMUC, 28 m × 15 m): x east, y north, heading CCW from +x.
The referee's 0x0203 ``angle`` is a compass bearing in degrees (north = 0, clockwise), so the
robot starts at (2, 7.5) facing east: angle 90.

Time: a simulator keeps its own, real time (``time.monotonic``), as the device it stands for does; the
gateway's injected clock is not the device's.

Why this module is longer than 500 lines: it holds the two sans-I/O models of one device on one UART (the
referee's match, the robot's main board), the stream device that carries both and the simulator's entry
points; each model is one device's behaviour on one clock.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import math
import signal
import threading
import time
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from adapters.errors import CommandError
from adapters.families import InProcessSim
from adapters.robomaster.commands import (
    DEFAULT_CONTROL,
    DEFAULT_SEASON,
    REFEREE_TABLE,
    ControlChannel,
    check_season,
    codec_field_names,
    decode_message,
    encode_message,
    robot_name,
    robot_team,
)
from adapters.robomaster.protocol import REFEREE_MAX_DATA_LEN, Decoder, Frame
from adapters.simio import PtyEndpoint, TcpEndpoint

log = logging.getLogger(__name__)

__all__ = [
    "BOARD_HOLD_S",
    "NOMINAL_RATES",
    "RefereeMatch",
    "RobomasterSim",
    "RobotBoard",
    "Stages",
    "main",
]

#: The control contract: a board stops by itself when no chassis_velocity came for ~0.5 s.
BOARD_HOLD_S = 0.5
FIELD_SIZE = (28.0, 15.0)  # RMUC field, metres
GIMBAL_RATE = 6.0  # rad/s the simulated gimbal slews toward its set-point

#: Send rates (Hz) of the periodic referee messages: V1.6.1's nominal rates, used for every season
#: (the layouts differ by season; we have no rate table of the later appendices that says otherwise).
#: 0x0203 is 10 Hz as in the older appendices, so a moving robot shows up quickly.
NOMINAL_RATES: dict[str, float] = {
    "game_status": 1.0,
    "game_robot_hp": 3.0,
    "event_data": 1.0,
    "robot_status": 10.0,
    "power_heat_data": 50.0,
    "robot_pos": 10.0,
    "buff": 3.0,
    "projectile_allowance": 10.0,
    "rfid_status": 3.0,
}

# Level-1 performance by role (id % 100): max HP, barrel cooling (/s), heat limit, chassis power (W).
_ROLE_STATS: dict[int, tuple[int, int, int, int]] = {
    1: (250, 40, 200, 70),  # hero
    2: (250, 0, 0, 120),  # engineer: no shooter
    7: (400, 80, 400, 100),  # sentry
}
_STANDARD_STATS = (200, 40, 200, 60)
_SHOT = {"bullet_type": 1, "shooter_number": 1, "launching_frequency": 1, "initial_speed": 24.5}


def _wrap_pi(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


# --------------------------------------------------------------------------------------- board


@dataclass
class RobotBoard:
    """The robot's main board: control messages in, pose out. Time is passed in."""

    x: float = 2.0
    y: float = 7.5
    heading: float = 0.0  # rad, CCW from +x (east)
    vx: float = 0.0  # body frame: forward, left (m/s), CCW (rad/s)
    vy: float = 0.0
    wz: float = 0.0
    velocity_until: float = float("-inf")
    gimbal_yaw: float = 0.0  # rad, CCW from the calibrated zero
    gimbal_pitch: float = 0.0  # rad, up positive
    gimbal_yaw_set: float = 0.0
    gimbal_pitch_set: float = 0.0
    last_stop_reason: int | None = None
    received: Counter[str] = field(default_factory=Counter)
    interactions: list[dict[str, Any]] = field(default_factory=list)
    _last: float | None = None

    def advance(self, now: float) -> None:
        """Move the chassis and the gimbal up to ``now``."""
        last = now if self._last is None else self._last
        dt = max(0.0, now - last)
        self._last = now
        if now >= self.velocity_until:
            self.vx = self.vy = self.wz = 0.0
        if dt > 0 and (self.vx or self.vy or self.wz):
            mid = self.heading + self.wz * dt / 2  # midpoint rule: arcs stay arcs
            self.x += (self.vx * math.cos(mid) - self.vy * math.sin(mid)) * dt
            self.y += (self.vx * math.sin(mid) + self.vy * math.cos(mid)) * dt
            self.x = min(FIELD_SIZE[0], max(0.0, self.x))
            self.y = min(FIELD_SIZE[1], max(0.0, self.y))
            self.heading = _wrap_pi(self.heading + self.wz * dt)
        step = GIMBAL_RATE * dt
        self.gimbal_yaw += max(-step, min(step, _wrap_pi(self.gimbal_yaw_set - self.gimbal_yaw)))
        self.gimbal_yaw = _wrap_pi(self.gimbal_yaw)
        self.gimbal_pitch += max(-step, min(step, self.gimbal_pitch_set - self.gimbal_pitch))

    @property
    def speed(self) -> float:
        return math.hypot(self.vx, self.vy)

    @property
    def bearing_deg(self) -> float:
        """The 0x0203 ``angle``: compass bearing, north = 0, clockwise."""
        return (90.0 - math.degrees(self.heading)) % 360.0

    def handle(self, name: str, fields: Mapping[str, Any], now: float) -> None:
        """One decoded message from the host (control message or 0x0301 to relay)."""
        self.advance(now)
        self.received[name] += 1
        handler = getattr(self, f"_on_{name}", None)
        if handler is not None:
            handler(fields, now)

    def _on_chassis_velocity(self, f: Mapping[str, Any], now: float) -> None:
        self.vx, self.vy, self.wz = f["vx"], f["vy"], f["wz"]
        self.velocity_until = now + BOARD_HOLD_S

    def _on_gimbal_angle(self, f: Mapping[str, Any], now: float) -> None:
        self.gimbal_yaw_set = _wrap_pi(f["yaw"])
        self.gimbal_pitch_set = f["pitch"]

    def _on_stop(self, f: Mapping[str, Any], now: float) -> None:
        self.vx = self.vy = self.wz = 0.0
        self.velocity_until = float("-inf")
        self.gimbal_yaw_set, self.gimbal_pitch_set = self.gimbal_yaw, self.gimbal_pitch
        self.last_stop_reason = f["reason"]

    def _on_robot_interaction_data(self, f: Mapping[str, Any], now: float) -> None:
        self.interactions.append(dict(f))


# --------------------------------------------------------------------------------------- referee


@dataclass(frozen=True, slots=True)
class Stages:
    """Seconds spent in each ``game_progress`` stage (0 not started … 5 settling)."""

    not_started: float = 3.0
    preparation: float = 10.0
    self_check: float = 15.0
    countdown: float = 5.0
    in_game: float = 420.0
    settling: float = 20.0

    def durations(self) -> tuple[float, ...]:
        return (
            self.not_started,
            self.preparation,
            self.self_check,
            self.countdown,
            self.in_game,
            self.settling,
        )


@dataclass
class RefereeMatch:
    """The referee system's view of one robot's match. ``tick`` returns the frames that are due."""

    season: str = DEFAULT_SEASON
    robot_id: int = 3
    game_type: int = 1  # RMUC
    stages: Stages = field(default_factory=Stages)
    loop: bool = True
    shot_period: float = 2.0  # in game: a burst of 17 mm shots per period while the barrel allows
    burst: int = 5
    hit_period: float = 7.0  # in game: the robot is hit once per period (0: never)
    unix_offset: float = 0.0  # sync_time_stamp = unix_offset + now
    rates: Mapping[str, float] = field(default_factory=lambda: dict(NOMINAL_RATES))
    # state
    progress: int = 0
    remain: int = 0
    hp: int = 0
    max_hp: int = 0
    heat: float = 0.0
    buffer_energy: float = 60.0
    chassis_power: float = 0.0
    allowance: int = 300
    shots: int = 0
    warning: tuple[int, int, int] | None = None  # level, offender, count
    sent: Counter[str] = field(default_factory=Counter)
    _t0: float | None = None
    _last: float | None = None
    _due: dict[str, float] = field(default_factory=dict)
    _next_shot: float = 0.0
    _next_hit: float = 0.0
    _armor: int = 0
    _seq: int = 0
    _queue: list[bytes] = field(default_factory=list)
    _penalties: Counter[tuple[int, int]] = field(default_factory=Counter)

    def __post_init__(self) -> None:
        self.season = check_season(self.season)
        if robot_name(self.robot_id) is None:
            raise ValueError(f"robot id {self.robot_id} is not a referee robot id")
        self._stats = _ROLE_STATS.get(self.robot_id % 100, _STANDARD_STATS)
        self.max_hp = self.hp = self._stats[0]

    # -- scripted incidents (tests and the CLI call these) -----------------------------------
    def penalize(self, level: int, offender: int | None = None) -> None:
        """A referee penalty against our side: 0x0104 now, then repeated at 1 Hz."""
        offender = self.robot_id if offender is None else offender
        self._penalties[(level, offender)] += 1
        self.warning = (level, offender, self._penalties[(level, offender)])
        self._queue.append(self._frame("referee_warning", self._warning_fields()))
        if self._last is not None:
            self._due["referee_warning"] = self._last + 1.0

    def hurt(self, armor_id: int, reason: int = 0, damage: int = 10) -> None:
        """The robot loses ``damage`` HP: 0x0206 now (HP shows in the next 0x0201/0x0003)."""
        self.hp = max(0, self.hp - damage)
        fields = {"armor_id": armor_id & 0x0F, "HP_deduction_reason": reason & 0x0F}
        self._queue.append(self._frame("hurt_data", fields))

    # -- the match ---------------------------------------------------------------------------
    def _stage_at(self, now: float) -> tuple[int, float]:
        """(progress, seconds left in it) at ``now``; restarts the match when ``loop``."""
        assert self._t0 is not None
        durations = self.stages.durations()
        elapsed = now - self._t0
        total = sum(durations)
        if elapsed >= total:
            if not self.loop:
                return 5, 0.0
            self._new_match(self._t0 + total * (elapsed // total))
            elapsed = now - self._t0
        for progress, length in enumerate(durations):
            if elapsed < length:
                return progress, length - elapsed
            elapsed -= length
        return 5, 0.0  # pragma: no cover - the loop above always returns

    def _new_match(self, t0: float) -> None:
        self._t0 = t0
        self.hp = self.max_hp
        self.heat = 0.0
        self.allowance = 300
        self.warning = None
        self._penalties.clear()

    def _update(self, now: float, board: RobotBoard) -> None:
        dt = 0.0 if self._last is None else max(0.0, now - self._last)
        self._last = now
        if self._t0 is None:
            self._t0 = now
        before = self.progress
        self.progress, left = self._stage_at(now)
        self.remain = math.ceil(left) if self.progress else 0
        if self.progress != before:
            if self.progress == 4:
                self._next_shot = now + self.shot_period
                self._next_hit = now + self.hit_period
            if self.progress == 5:
                winner = 1 if robot_team(self.robot_id) == "red" else 2
                self._queue.append(self._frame("game_result", {"winner": winner}))
        _, cooling, heat_limit, power_limit = self._stats
        # power: idle draw plus a share per m/s and rad/s; the buffer pays for power above the limit
        self.chassis_power = 2.0 + 30.0 * board.speed + 4.0 * abs(board.wz)
        self.buffer_energy = min(60.0, max(0.0, self.buffer_energy + (power_limit - self.chassis_power) * dt))
        self.heat = max(0.0, self.heat - cooling * dt)
        if self.progress != 4:
            return
        if self.shot_period > 0 and now >= self._next_shot:
            self._next_shot = now + self.shot_period
            for _ in range(self.burst):
                if not heat_limit or self.allowance <= 0 or self.heat + 10 > heat_limit or self.hp <= 0:
                    break
                self.heat += 10  # 10 heat per 17 mm projectile
                self.allowance -= 1
                self.shots += 1
                self._queue.append(self._frame("shoot_data", _SHOT))
        if self.hit_period > 0 and now >= self._next_hit and self.hp > 0:
            self._next_hit = now + self.hit_period
            self.hurt(self._armor)
            self._armor = (self._armor + 1) % 4

    def tick(self, now: float, board: RobotBoard) -> list[bytes]:
        """Frames due at ``now`` (the board's pose and speed feed 0x0203 and the power model)."""
        self._update(now, board)
        out, self._queue = self._queue, []
        for name, hz in self.rates.items():
            due = self._due.get(name, now)
            if hz <= 0 or now < due:
                continue
            # keep the nominal rate on a coarse tick; after a stall, restart from now (no burst)
            nxt = due + 1.0 / hz
            self._due[name] = nxt if nxt > now else now + 1.0 / hz
            out.append(self._frame(name, self._fields(name, board, now)))
        if self.warning is not None and now >= self._due.get("referee_warning", now):
            self._due["referee_warning"] = now + 1.0
            out.append(self._frame("referee_warning", self._warning_fields()))
        return out

    # -- payloads ------------------------------------------------------------------------------
    def _frame(self, name: str, values: Mapping[str, Any]) -> bytes:
        """Encode ``values`` against this season's layout; names the season lacks are left out."""
        known = set(codec_field_names(REFEREE_TABLE.named(name, self.season).request[0]))
        fields = {k: v for k, v in values.items() if k in known}
        self._seq = (self._seq + 1) & 0xFF
        self.sent[name] += 1
        return encode_message(name, fields, self.season, self._seq)

    def _warning_fields(self) -> dict[str, int]:
        assert self.warning is not None
        level, offender, count = self.warning
        return {"level": level, "offending_robot_id": offender, "count": min(count, 255)}

    def _fields(self, name: str, board: RobotBoard, now: float) -> dict[str, Any]:
        """The values of one periodic message (``_payload_<name>``; unset fields stay zero)."""
        build = getattr(self, f"_payload_{name}", None)
        return {} if build is None else build(board, now)

    def _payload_game_status(self, board: RobotBoard, now: float) -> dict[str, Any]:
        return {
            "game_type": self.game_type,
            "game_progress": self.progress,
            "stage_remain_time": self.remain,
            "sync_time_stamp": max(0, int(self.unix_offset + now)),
        }

    def _payload_robot_status(self, board: RobotBoard, now: float) -> dict[str, Any]:
        _, cooling, heat_limit, power_limit = self._stats
        alive = 1 if self.hp > 0 else 0
        return {
            "robot_id": self.robot_id,
            "robot_level": 1,
            "current_HP": self.hp,
            "maximum_HP": self.max_hp,
            "shooter_barrel_cooling_value": cooling,
            "shooter_barrel_heat_limit": heat_limit,
            "chassis_power_limit": power_limit,
            "power_management_gimbal_output": 1,
            "power_management_chassis_output": alive,
            "power_management_shooter_output": alive,
        }

    def _payload_power_heat_data(self, board: RobotBoard, now: float) -> dict[str, Any]:
        heat = round(self.heat)
        return {  # 2024 only has the chassis fields, 2026 only one 17 mm barrel: _frame drops the rest
            "chassis_voltage": 24000,
            "chassis_current": round(self.chassis_power / 24.0 * 1000),
            "chassis_power": self.chassis_power,
            "buffer_energy": round(self.buffer_energy),
            "shooter_17mm_1_barrel_heat": heat,
            "shooter_17mm_barrel_heat": heat,
        }

    def _payload_robot_pos(self, board: RobotBoard, now: float) -> dict[str, Any]:
        return {"x": board.x, "y": board.y, "angle": board.bearing_deg}

    def _payload_projectile_allowance(self, board: RobotBoard, now: float) -> dict[str, Any]:
        return {"projectile_allowance_17mm": self.allowance, "remaining_gold_coin": 400}

    def _payload_game_robot_hp(self, board: RobotBoard, now: float) -> dict[str, Any]:
        return self._hp_fields()

    def _hp_fields(self) -> dict[str, int]:
        team, n = robot_team(self.robot_id), self.robot_id % 100
        own = {f"{team}_{n}_robot_HP", f"ally_{n}_robot_HP"}
        out: dict[str, int] = {}
        for fname in codec_field_names(REFEREE_TABLE.named("game_robot_hp", self.season).request[0]):
            if fname in own:
                out[fname] = self.hp
            elif fname.endswith("_robot_HP"):
                out[fname] = 200
            elif fname.endswith("_outpost_HP"):
                out[fname] = 1500
            elif fname.endswith("_base_HP"):
                out[fname] = 5000
        return out


# --------------------------------------------------------------------------------------- stream


class RobomasterSim:
    """Referee and main board behind one UART: a :class:`~adapters.simio.StreamDevice`."""

    def __init__(
        self,
        match: RefereeMatch | None = None,
        board: RobotBoard | None = None,
        *,
        control: ControlChannel = DEFAULT_CONTROL,
    ) -> None:
        self.match = match or RefereeMatch()
        self.board = board or RobotBoard()
        self.control = control
        self.decoder = Decoder(REFEREE_MAX_DATA_LEN)
        self.undecodable = 0
        self.lock = threading.Lock()  # tests read and poke the models from another thread

    def on_bytes(self, data: bytes, now: float) -> bytes:
        with self.lock:
            for item in self.decoder.feed(data):
                if not isinstance(item, Frame):
                    continue
                try:
                    msg = decode_message(item, self.match.season, self.control)
                except CommandError:
                    self.undecodable += 1
                    continue
                self.board.handle(msg.name, msg.fields, now)
        return b""

    def tick(self, now: float) -> bytes:
        with self.lock:
            self.board.advance(now)
            return b"".join(self.match.tick(now, self.board))


def main(argv: Sequence[str] | None = None) -> int:
    """``dji-gateway simulate robomaster``: referee + main board on a pty (default) or a TCP port."""
    p = argparse.ArgumentParser(prog="dji-gateway simulate robomaster", description=__doc__.split("\n\n")[0])
    where = p.add_mutually_exclusive_group()
    where.add_argument("--tcp", type=int, metavar="PORT", help="listen on 127.0.0.1:PORT (0 = any free port)")
    where.add_argument("--pty", action="store_true", help="create a pseudo-terminal (default)")
    p.add_argument("--season", choices=("2024", "2025", "2026"), default=DEFAULT_SEASON)
    p.add_argument("--robot-id", type=int, default=3, help="referee robot id (default 3, red standard 3)")
    p.add_argument("--control-cmd-id", type=lambda s: int(s, 0), default=DEFAULT_CONTROL.cmd_id)
    p.add_argument("--game-seconds", type=float, default=420.0, help="length of the in-game stage")
    ns = p.parse_args(argv)
    match = RefereeMatch(
        season=ns.season,
        robot_id=ns.robot_id,
        stages=Stages(in_game=ns.game_seconds),
        unix_offset=time.time() - time.monotonic(),
    )
    device = RobomasterSim(match, control=ControlChannel(cmd_id=ns.control_cmd_id))
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    runner: PtyEndpoint | TcpEndpoint
    if ns.tcp is not None:
        runner = TcpEndpoint(device, port=ns.tcp).start()
        where_url = runner.url
    else:
        runner = PtyEndpoint(device).start()
        where_url = runner.path
    print(f"robomaster simulator at {where_url}", flush=True)
    print(f'gateway device: type = "robomaster", url = "{where_url}", season = "{ns.season}"', flush=True)
    with contextlib.suppress(KeyboardInterrupt):
        stop.wait()
    runner.stop()
    return 0


#: The ``url`` of a robot entry that ``dji-gateway run --simulate`` replaces with its simulator's.
SIM_URL = "sim://robomaster"


def in_process(device: Any) -> tuple[InProcessSim, Any] | None:
    """``dji-gateway run --simulate`` (:mod:`adapters.families`): a robot entry whose url is
    :data:`SIM_URL` gets a referee + main board simulator on a loopback TCP port (the entry's season and
    control channel), and the entry pointed at it. Any other entry: None."""
    if device.url != SIM_URL:
        return None
    match = RefereeMatch(season=device.season, unix_offset=time.time() - time.monotonic())
    endpoint = TcpEndpoint(RobomasterSim(match, control=device.control.channel())).start()
    log.info("simulated robot %s (season %s) at %s", device.sn, device.season, endpoint.url)
    return endpoint, device.model_copy(update={"url": endpoint.url})
