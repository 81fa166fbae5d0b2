"""A DJI flight controller (A3/N3 on an M600/M210, "new" firmware) that speaks the Onboard SDK open
protocol: the simulator every OSDK adapter test talks to.

It models what the gateway relies on: activation and the version query, broadcast frequencies and
the ``0x02 0x00`` flight-data push at those rates, control authority (RC mode switch, "in progress"),
flight tasks (take-off to 1.2 m, landing, go home, motors), movement control and the emergency brake,
the seed 004 ground station (waypoint missions with the FC's own validation, status and event
pushes; hotpoint and follow-me), the RC taking control back (``0x02 0x01``), and the link rules:
every command on session >= 1 gets its ACK (same session and seq), a resent command gets the stored
ACK again and never acts twice.

Layers: :class:`OsdkFcModel` is sans-I/O (bytes and a clock value in, bytes out; a point-mass flight
model advanced by the clock); :class:`OsdkFcDevice` is the :class:`~adapters.simio.StreamDevice` with a
lock, for :class:`~adapters.simio.PtyEndpoint` / :class:`~adapters.simio.TcpEndpoint`; :func:`main` is
``dji-gateway simulate osdk``. Payloads come from the codec's table (``commands.py``,
``telemetry.py``): no layout is written twice.

Choices where the protocol is silent (also next to the code that makes them):

* Before activation the FC answers every command outside set ``0x00`` on session >= 1 with the u16
  common ACK ``0xFF01`` (OSDK ``ErrorCode::CommonACK::NO_AUTHORIZATION_ERROR``, the same value the
  version query reports as "not activated") and does not act; ``unactivated="ignore"`` makes it
  silent instead. Set ``0x00`` (version, activation, frequencies) always works, and the flight-data
  push runs before activation too (the link is visibly alive).
* Flight tasks without control authority: u16 ``0xFF02`` (``CommonACK::NO_RIGHTS_ERROR``); not
  confirmed on hardware. Mission starts without it: ``0xD1`` (OSDK ``OBTAIN_CONTROL_REQUIRED``).
* Movement control holds the last set-point for ``setpoint_hold`` seconds after the last movement
  frame (``--setpoint-hold SECONDS|inf``), then brakes and hovers (task "hover", display mode 6).
  What a real A3/N3 does is not documented (the protocol has no heartbeat and no documented hold
  time), so the default is the worst case, ``inf``: the set-point is held until another arrives, and
  the gateway must stop the aircraft itself (its own watchdog); tests run both kinds. It acts only in
  the air, under SDK control, while no automatic task (take-off, landing, go home, mission) runs.
* The emergency brake stops whatever the SDK started (movement, go home, landing, missions; no
  "finished" event), decelerates at the normal limit and holds where it stopped.
* A waypoint mission started on the ground takes off first (motors on, the 1.2 m automatic take-off)
  and then flies its route: DJI's own mission samples (Onboard-SDK 3.9.0 ``runWaypointMission``) start
  it on the ground without a take-off, while they take off before a hotpoint; hotpoint and follow-me
  on the ground get ``0xDA`` "drone not in air when init". A mission needs a complete, valid upload (``0xEA``
  nothing initialised, ``0xEB`` not all waypoints accepted). Validation happens when the last waypoint
  arrives (seed: "valid all waypoints' data together after the last one"), with the Mobile SDK's
  documented limits: 2..255 waypoints (``min_waypoints``), max speed 2..15 m/s, idle speed in
  (0, max]; altitude in [-200, 500] m (``0xC1``/``0xC0``); within ``max_distance_m`` of home
  (``0xC7``); neighbours 0.5..2000 m apart in 3-D (``0xE5``/``0xE6``); waypoint 1 to n at most 60 km
  (``0xE2``) and with home to waypoint 1 and back at most 100 km (``0xE3``; 30 and 60 km on M100
  firmware: OSDK ``dji_error.cpp``); action commands 0..5 (``0xE8``). The first waypoint must be within
  ``max_distance_m`` of the aircraft at the start (``0xC9``). A waypoint whose ACK is an error is not
  stored. The ``0x02 0x04`` upload event (incident 0) follows every validation, valid or not.
* One reached event (incident 2, ``current_status`` 6 "post-action") per waypoint, after its actions;
  ``reach_pre_action_events=True`` adds the ``current_status`` 4 event on arrival, as OSDK describes.
  Mission status (``0x02 0x03``) at 1 Hz while a mission runs.
* ``break_mission(error, now)`` (fault injection) breaks off the running waypoint mission as the FC does
  on an error: a status push with the error, then the default status with ``is_broken``; it hovers.
* ``rc_takeover()`` always pushes ``0x02 0x01`` (reason 4) on an ACK-required session (resent
  0.5 s x 2 until the host ACKs), revokes SDK control, flips the RC switch to P and hovers.
* Releasing control does not stop a running mission; landing and go home cancel it.
* The go-home altitude (``go_home_altitude_m``, 20 m by default) is written with ``0x01 0x42`` and read
  with ``0x01 0x41`` (new firmware; hash-checked: another hash gets ret code 1); go home climbs to it
  (or stays higher) before flying home.

Flight model: a point mass with a 4 m/s^2 acceleration limit on a flat earth around ``home``
(north/east metres; latitude = home + north / R, longitude = home + east / (R cos(home lat)),
R = 6378137 m), good to centimetres over the few kilometres a mission spans. Height is above the
take-off point; altitude is ``home_altitude`` + height. Attitude is yaw only.

Why this module is longer than 500 lines: it is one flight controller: its link rules, every command it
answers, the flight model every task flies on and the pushes it makes share one state, and a simulator
split across files would hide the interplay (a brake ends a mission, a take-off precedes a mission) that
makes it faithful.
"""

from __future__ import annotations

import argparse
import contextlib
import itertools
import logging
import math
import signal
import threading
import zlib
from collections import Counter
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, TypeVar

from adapters.families import InProcessSim
from adapters.osdk import commands as cmds
from adapters.osdk import subscription as sub
from adapters.osdk.commands import (
    FRAME_BODY,
    HORIZONTAL_ANGLE,
    HORIZONTAL_POSITION,
    HORIZONTAL_VELOCITY,
    TO_FC,
    VERTICAL_POSITION,
    VERTICAL_THRUST,
    VERTICAL_VELOCITY,
    YAW_RATE,
    split_control_flag,
)
from adapters.osdk.protocol import BadFrame, Decoder, DuplicateFilter, Frame, SessionMode, SessionTable
from adapters.osdk.telemetry import ITEMS as TELEMETRY_ITEMS
from adapters.osdk.telemetry import NEW_ITEMS, encode_flight_data
from adapters.simio import PtyEndpoint, TcpEndpoint
from adapters.wire.layout import LayoutError

log = logging.getLogger(__name__)

__all__ = [
    "DEFAULT_HOME",
    "DEFAULT_RATES",
    "NOT_ACTIVATED_ACK",
    "NO_RIGHTS_ACK",
    "TAKEOFF_HEIGHT_M",
    "OsdkFcDevice",
    "OsdkFcModel",
    "main",
]

T = TypeVar("T")

EARTH_RADIUS_M = 6378137.0  # flat-earth approximation around home (module docstring)
DEFAULT_HOME = (22.5431, 113.9580)  # degrees
NOT_ACTIVATED_ACK = 0xFF01  # OSDK ErrorCode::CommonACK::NO_AUTHORIZATION_ERROR
M100_TASK_STARTED, M100_TASK_FAILED = 0x0002, 0x0001  # M100 0x01 0x01 ACKs (FLIGHT_TASK_M100_ACK)
#: An M100 on firmware 3.1.10.0 (OSDK ``Version::M100_31``, the only M100 firmware DJI's Onboard-SDK 3.x
#: accepts), as it writes it: the third number a tenth of the real one (the library multiplies it by 10
#: for "M100"). It answers in the 3.1 layout (u32 CRC, ID and its NUL, name): the seed-era "M100 2.3"
#: reply (CRC + name, ``M100-02.03.00.00``) stops the 3.x library at "Drone version not obtained".
M100_VERSION_NAME = "SDK-v1.1 BETA M100-03.01.01.00"
#: The M100's ID after the CRC: 10 characters and the NUL (the 3.1-era library reads an 11-byte ID).
M100_SERIAL = "SIMFC00001"
NO_RIGHTS_ACK = 0xFF02  # OSDK ErrorCode::CommonACK::NO_RIGHTS_ERROR (flight task without authority)
#: A command the simulated FC does not implement, asking for an answer: u16 OSDK
#: ``ErrorCode::CommonACK::KEY_ERROR`` (0xFF00). Which code real firmware uses is not confirmed; what
#: matters to a client is that the answer comes at once instead of a time-out.
UNKNOWN_COMMAND_ACK = 0xFF00
#: The data subscription set (0x0B: 0x00 verify, 0x01 add package, 0x02 reset, 0x03 remove; subscription.py).
SUBSCRIBE_SET = 0x0B
#: The 0x0B commands without a known layout (0x04 frequency, 0x05 pause, 0x06 config: OSDK has no API for
#: them) and every 0x0B command on M100 firmware (no subscription there) are refused with u8 OSDK
#: ``ErrorCode::SubscribeACK::PERMISSION_DENY`` (0x23): never the u16 unknown-command code, whose first
#: byte (0x00) the library would read as success.
SUBSCRIBE_REFUSED_ACK = 0x23

TAKEOFF_HEIGHT_M = 1.2
VERTICAL_SPEED = 1.0  # take-off climb and landing descent, m/s
ACCEL_LIMIT = 4.0  # m/s^2, every axis
BRAKE = 3.0  # deceleration the position controller plans with (below the limit, so it can follow)
KP = 3.0  # position gain near a target, 1/s
MAX_SPEED = 15.0  # mission / go-home cap
MOVE_H_LIMIT, MOVE_V_LIMIT, MOVE_YAW_LIMIT = 30.0, 5.0, 150.0  # movement control ranges (new FW)
HOLD_SPEED = 5.0  # position hold / "return to point 0"
MISSION_V_SPEED = 4.0
GO_HOME_SPEED = 10.0
FOLLOW_SPEED = 10.0
YAW_SLEW = 90.0  # deg/s for automatic heading changes
ARRIVE_M = 0.5
STEP = 0.02  # integration sub-step, s
STATUS_PERIOD = 1.0  # mission status push
IDLE_FLUSH_S = 0.1  # a quiet line this long: drop half-received candidates (a noise "header")
ANGLE_TO_SPEED = 1.0  # m/s per degree of tilt (movement control angle mode, a rough stand-in)

STOPPED, ON_GROUND, IN_AIR = 0, 1, 2
RATE_HZ = {0: 0.0, 1: 1.0, 2: 10.0, 3: 50.0, 4: 100.0}
RATE_KEEP = 5
ITEM_NAMES: tuple[str, ...] = tuple(it.name for it in NEW_ITEMS)
# Until 0x00 0x10 sets them (DJI Assistant's configuration on real hardware).
DEFAULT_RATES: dict[str, float] = {name: 1.0 for name in ITEM_NAMES} | {
    n: 10.0 for n in ("timestamp", "quaternion", "velocity", "position", "status", "battery")
}
# Display mode per task (OSDK DisplayMode; 14 waypoint and 25 follow-me as in the Mobile SDK's list).
DISPLAY_MODES: dict[str, int] = {
    "ground": 6,
    "takeoff": 11,
    "hover": 6,
    "sdk": 17,
    "landing": 12,
    "go_home": 15,
    "waypoint": 14,
    "hotpoint": 9,
    "follow_me": 25,
}
RC_STICK_MODE = {"P": -8000, "A": 0, "F": 8000}
# Undecodable payloads: the command's own "invalid" code where it has one; set 0x03 -> 0xF4.
_BAD_PAYLOAD_ACK: dict[str, int] = {
    "activate": 0x0001,
    "set_broadcast_frequency": 0x0001,
    "flight_task": 10,
    "go_home_altitude_write": 1,  # another hash or length: not written (not confirmed on hardware)
    "go_home_altitude_read": 1,  # another hash: not a parameter this FC knows (not confirmed on hardware)
} | sub.BAD_PAYLOAD_ACK
_GS_INVALID = 0xF4


def _clamp(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


def _wrap180(deg: float) -> float:
    return (deg + 180.0) % 360.0 - 180.0


@dataclass
class _Point:
    """A waypoint in local metres, with its decoded wire fields (for download and actions)."""

    n: float
    e: float
    u: float
    fields: dict[str, Any]


@dataclass
class _Upload:
    """What 0x10/0x11 stored: the mission header and the accepted waypoints."""

    info: dict[str, Any]
    points: list[dict[str, Any] | None]
    valid: bool = False


@dataclass
class _Run:
    """A waypoint mission in flight (its own copy: a new upload does not change it)."""

    info: dict[str, Any]
    points: list[_Point]
    target: int = 0
    paused: bool = False
    stay_until: float | None = None
    executions: int = 0
    reached_any: bool = False
    lock_yaw: float = 0.0


@dataclass
class _Hotpoint:
    settings: dict[str, Any]
    n: float
    e: float
    u: float
    radius: float
    rate: float  # deg/s
    clockwise: bool
    paused: bool = False
    auto_radius: tuple[int, int] = (0, 0)


@dataclass
class _Follow:
    settings: dict[str, Any]
    n: float
    e: float
    paused: bool = False


@dataclass
class _SetPoint:
    """The last movement-control input, raw (body-frame values are rotated by the current yaw)."""

    parts: dict[str, int]
    x: float
    y: float
    z: float
    yaw: float
    at: float  # when it arrived (model time): held for ``setpoint_hold`` seconds after it
    target_ne: tuple[float, float] | None = None  # position-offset mode: absolute target


class OsdkFcModel:
    """The flight controller's state and its answers. Time is passed in; nothing here sleeps, reads
    a clock or touches I/O. ``feed``/``handle`` answer host frames, ``tick`` advances the flight and
    emits pushes; both return complete frames (bytes) ready for the wire.

    Test hooks: :meth:`drop_acks`, ``ack_delay``, ``reject_activation``, ``rc_mode``,
    :meth:`rc_takeover`, ``obtain_in_progress_once``; counters ``actions`` (per command name, only
    commands that were acted on), ``duplicates``, ``acks_sent``, ``acks_dropped``,
    ``refused_not_activated``, ``unknown_commands``, ``bad_frames``, ``bad_payloads``, ``errors``,
    ``push_timeouts``; ``host_acks`` (the host's ACKs to our pushes)."""

    def __init__(
        self,
        *,
        app_id: int | None = None,
        home: tuple[float, float] = DEFAULT_HOME,
        home_altitude: float = 50.0,
        rc_mode: str = "F",
        rc_not_f_ack: int = 0x0006,
        obtain_in_progress_once: bool = False,
        reject_activation: int = 0,
        unactivated: str = "ack",
        ack_delay: float = 0.0,
        max_distance_m: float = 2000.0,
        min_waypoints: int = 2,
        max_altitude_m: float = 500.0,
        min_altitude_m: float = -200.0,
        go_home_altitude_m: float = 20.0,
        battery_percent: float = 95.0,
        reach_pre_action_events: bool = False,
        lost_authority_mode: SessionMode = SessionMode.ACK_REQUIRED,
        version_name: str | None = None,
        version_layout: str | None = None,
        serial: str | None = None,
        firmware: str = "new",
        setpoint_hold: float = math.inf,
    ) -> None:
        if unactivated not in ("ack", "ignore"):
            raise ValueError("unactivated must be 'ack' or 'ignore'")
        if firmware not in ("new", "m100"):
            raise ValueError("firmware must be 'new' or 'm100'")
        if not setpoint_hold > 0:
            raise ValueError("setpoint_hold must be a positive number of seconds or math.inf")
        #: "new" (A3/N3/M600/M210, OSDK 3.x) or "m100" (legacy codes, status values and telemetry layout)
        self.firmware = firmware
        legacy = firmware == "m100"
        if version_name is None:
            version_name = M100_VERSION_NAME if legacy else "SDK-v1.1 BETA A3-03.03.100.00"
        if version_layout is None:
            version_layout = "crc_id" if legacy else "id"
        if serial is None:
            serial = M100_SERIAL if legacy else "SIMFC0000000001"
        self._item_names = tuple(it.name for it in TELEMETRY_ITEMS[firmware])
        self._flown = False  # an M100 reports "landed" (5), not "standby" (1), after a flight
        # configuration (plain attributes: tests change them between steps)
        self.app_id = app_id  # None accepts any app id
        self.home_lat, self.home_lon = math.radians(home[0]), math.radians(home[1])
        self.home_altitude = home_altitude
        self.rc_mode = rc_mode
        self.rc_not_f_ack = rc_not_f_ack  # 0x0006 "RC must be in F" (new FW) or 0x0000 (older FW)
        self.obtain_in_progress_once = obtain_in_progress_once
        self.reject_activation = reject_activation  # 0 accept, else the ACTIVATION_ACK code to answer
        self.unactivated = unactivated
        self.ack_delay = ack_delay
        self.max_distance_m = max_distance_m
        self.min_waypoints = min_waypoints
        self.max_altitude_m, self.min_altitude_m = max_altitude_m, min_altitude_m
        self.go_home_altitude_m = go_home_altitude_m
        #: seconds a movement-control set-point is held without a new frame, then brake and hover (inf:
        #: held until the next one; what a real FC does is not documented, module docstring)
        self.setpoint_hold = setpoint_hold
        self.reach_pre_action_events = reach_pre_action_events
        self.lost_authority_mode = lost_authority_mode
        self.version_name = version_name
        self.subscriptions_refused = 0  # 0x0B commands answered SUBSCRIBE_REFUSED_ACK
        #: data subscription (0x0B, pushes 0x02 0x05): packages and their answers (subscription.py)
        self.subscriptions = sub.FcSubscriptions()
        #: working obstacle sensors (an A3 has none; an M210 front, up and down): they read the height
        #: above ground downwards and ``obstacle_range`` (m, nothing closer) elsewhere
        self.obstacle_sensors: set[str] = set()
        self.obstacle_range = 30.0
        self.version_layout = version_layout  # how 0x00 0x00 is answered: cmds.encode_version_reply
        # the flight controller's ID string in the version reply (<= 15 characters; <= 11 after a CRC)
        self.serial = serial
        self.battery_capacity_mah = 4500
        # link
        self._decoder = Decoder()
        self._rx_at: float | None = None  # last bytes in, while the decoder may hold a partial frame
        self._dups = DuplicateFilter()
        self._table: SessionTable[None] = SessionTable()  # nothing waits on its pushes
        self._outbox: list[tuple[float, bytes]] = []
        self._drop = 0
        self.actions: Counter[str] = Counter()
        self.duplicates = 0
        self.acks_sent = 0
        self.acks_dropped = 0
        self.refused_not_activated = 0
        self.unknown_commands = 0
        self.bad_frames = 0
        self.bad_payloads = 0  # CRC-good commands whose payload fits no layout (the host's fault)
        self.errors = 0  # the simulator's own failures: tests expect 0
        self.host_acks: list[Frame] = []
        self.push_timeouts = 0
        # authority and state
        self.activated = False
        self.sdk_control = False
        self.motors_on = False
        self.in_air = False
        self.task = "ground"
        self.battery = float(battery_percent)
        self.gimbal_pitch = 0.0
        self.photos = 0
        self.recording = False
        # kinematics: north/east/up metres from home, NEU m/s, yaw deg clockwise from north
        self.n = self.e = self.u = 0.0
        self.vn = self.ve = self.vu = 0.0
        self.an = self.ae = self.au = 0.0
        self.yaw = 0.0
        self.yaw_rate = 0.0
        self.home_n = self.home_e = 0.0
        self._hold: tuple[float, float, float] | None = None  # hover / landing hold point
        self._yaw_target: float | None = None
        self._yaw_rate_cmd = 0.0
        self._sp: _SetPoint | None = None
        self._gh_alt = 0.0
        self._gh_climbing = True
        self.upload: _Upload | None = None
        self.run: _Run | None = None
        self.hotpoint: _Hotpoint | None = None
        self.follow: _Follow | None = None
        # clock
        self._t0: float | None = None
        self._last: float | None = None
        self._t = 0.0
        self._rates = [DEFAULT_RATES[n] for n in self._item_names]
        self._due: list[float | None] = [None] * len(self._item_names)
        self._next_status = 0.0
        self._gps_counter = 0
        self._tasks: dict[str, Callable[[], tuple[float, float, float]]] = {
            "ground": self._fly_ground,
            "takeoff": self._fly_takeoff,
            "hover": self._fly_hover,
            "sdk": self._fly_sdk,
            "landing": self._fly_landing,
            "go_home": self._fly_go_home,
            "waypoint": self._fly_waypoint,
            "hotpoint": self._fly_hotpoint,
            "follow_me": self._fly_follow,
        }
        self._items: dict[str, Callable[[float], dict[str, Any]]] = {
            name: getattr(self, f"_item_{name}") for name in self._item_names
        }

    # -- geometry ----------------------------------------------------------------------------------
    def to_latlon(self, n: float, e: float) -> tuple[float, float]:
        """Local metres -> (latitude, longitude) in radians, flat earth around home."""
        return (
            self.home_lat + n / EARTH_RADIUS_M,
            self.home_lon + e / (EARTH_RADIUS_M * math.cos(self.home_lat)),
        )

    def to_local(self, lat: float, lon: float) -> tuple[float, float]:
        """(latitude, longitude) in radians -> local north/east metres."""
        return (
            (lat - self.home_lat) * EARTH_RADIUS_M,
            (lon - self.home_lon) * EARTH_RADIUS_M * math.cos(self.home_lat),
        )

    @property
    def latitude(self) -> float:
        return self.to_latlon(self.n, self.e)[0]

    @property
    def longitude(self) -> float:
        return self.to_latlon(self.n, self.e)[1]

    @property
    def flight_status(self) -> int:
        if self.firmware == "m100":  # 1 standby, 2 taking off, 3 in air, 4 landing, 5 landed
            if self.task == "takeoff":
                return 2
            if self.task == "landing":
                return 4
            if self.in_air:
                return 3
            return 5 if self._flown else 1
        return IN_AIR if self.in_air else ON_GROUND if self.motors_on else STOPPED

    @property
    def display_mode(self) -> int:
        if self.rc_mode == "A" and self.task in ("ground", "hover"):
            return 1  # attitude
        return DISPLAY_MODES[self.task]

    @property
    def speed(self) -> float:
        return math.sqrt(self.vn**2 + self.ve**2 + self.vu**2)

    # -- test hooks --------------------------------------------------------------------------------
    def drop_acks(self, n: int) -> None:
        """Lose the next ``n`` ACK frames (originals and re-sends alike); the commands still act."""
        self._drop += n

    def rc_takeover(self, now: float | None = None) -> None:
        """The pilot flips the RC switch out of F: SDK control is revoked, SDK motion ends (hover), and
        the FC pushes ``0x02 0x01`` (reason 4) on an ACK-required session, resent until the host ACKs."""
        now = self._clock(now)
        self.sdk_control = False
        self.rc_mode = "P"
        if self.in_air and self.task not in ("landing",):
            self._abort_missions()
            self._enter_hover(None)
        payload = cmds.encode_request("lost_authority_push", {"reason": 4}, self.firmware)
        sent = self._table.send(0x02, 0x01, payload, now=now, mode=self.lost_authority_mode, timeout=0.5)
        self._emit(sent.frame, now)

    def _clock(self, now: float | None) -> float:
        return now if now is not None else (self._last if self._last is not None else 0.0)

    # -- byte boundary -----------------------------------------------------------------------------
    def feed(self, data: bytes, now: float) -> list[bytes]:
        """Bytes from the host; returns the frames to write back now (ACKs, pushes that fell due)."""
        self.advance(now)
        self._rx_at = now
        self._receive(self._decoder.feed(data), now)
        return self._flush(now)

    def _receive(self, items: list[Frame | BadFrame], now: float) -> None:
        for item in items:
            if isinstance(item, BadFrame):
                self.bad_frames += 1
            else:
                self.handle(item, now)

    def tick(self, now: float) -> list[bytes]:
        """Advance the flight; returns due telemetry, mission pushes, delayed ACKs and resends."""
        self.advance(now)
        if self._rx_at is not None and now - self._rx_at >= IDLE_FLUSH_S:
            self._rx_at = None  # idle line: a bogus length must not hold back the frames behind it
            self._receive(self._decoder.flush(), now)
        self._telemetry(now)
        for payload in self.subscriptions.pushes(now, _Sources(self, now)):
            self._emit(self._table.send(0x02, 0x05, payload, now=now, mode=SessionMode.NO_ACK).frame, now)
        self._mission_status(now)
        poll = self._table.poll(now)
        for raw in poll.resend:
            self._emit(raw, now)
        self.push_timeouts += len(poll.expired)
        return self._flush(now)

    def _emit(self, raw: bytes, due: float) -> None:
        self._outbox.append((due, raw))

    def _flush(self, now: float) -> list[bytes]:
        out = [raw for due, raw in self._outbox if due <= now]
        self._outbox = [(due, raw) for due, raw in self._outbox if due > now]
        return out

    def _queue_ack(self, raw: bytes, now: float) -> None:
        if self._drop > 0:
            self._drop -= 1
            self.acks_dropped += 1
            return
        self.acks_sent += 1
        self._emit(raw, now + self.ack_delay)

    def _ack(self, frame: Frame, value: bytes, now: float) -> None:
        self._queue_ack(self._dups.ack(frame, value), now)  # stored for re-sends of the same seq

    def _push(self, name: str, fields: Mapping[str, Any], now: float) -> None:
        spec = cmds.spec_for(name, self.firmware)
        payload = cmds.encode_request(name, fields, self.firmware)
        self._emit(self._table.send(*spec.set_and_id, payload, now=now, mode=SessionMode.NO_ACK).frame, now)

    # -- protocol ----------------------------------------------------------------------------------
    def handle(self, frame: Frame, now: float) -> None:
        """Act on one CRC-checked frame from the host (ACKs to our pushes, or commands)."""
        if frame.is_ack:
            self._table.on_ack(frame)
            self.host_acks.append(frame)
            return
        verdict = self._dups.check(frame)
        if verdict.duplicate:
            self.duplicates += 1  # a retransmission: the stored ACK again, never a second action
            if verdict.resend is not None:
                self._queue_ack(verdict.resend, now)
            return
        cmd_set, cmd_id = frame.cmd_set, frame.cmd_id
        assert cmd_set is not None and cmd_id is not None  # the decoder drops shorter command frames
        specs = [s for s in cmds.specs_at(cmd_set, cmd_id, self.firmware) if s.direction == TO_FC]
        if not specs:
            # A real flight controller answers every command that asks for an answer; silence would
            # leave a client such as DJI's Onboard-SDK library waiting on its ACK until it times out.
            self.unknown_commands += 1
            if frame.session:
                if cmd_set == SUBSCRIBE_SET:
                    self.subscriptions_refused += 1
                    self._ack(frame, bytes([SUBSCRIBE_REFUSED_ACK]), now)
                else:
                    self._ack(frame, UNKNOWN_COMMAND_ACK.to_bytes(2, "little"), now)
            return
        if not self.activated and cmd_set != 0x00:
            # Real FCs refuse with the common ACK "no authorization" (module docstring).
            self.refused_not_activated += 1
            if frame.session and specs[0].reply and self.unactivated == "ack":
                self._ack(frame, NOT_ACTIVATED_ACK.to_bytes(2, "little"), now)
            return
        try:
            msg = cmds.decode_request(cmd_set, cmd_id, frame.payload, self.firmware)
        except LayoutError:
            self.bad_payloads += 1
            code = _BAD_PAYLOAD_ACK.get(specs[0].name, _GS_INVALID if cmd_set == 0x03 else None)
            if frame.session and specs[0].reply and code is not None:
                self._ack(frame, specs[0].reply[0].encode({"ack": code}), now)
            return
        self.actions[msg.name] += 1
        try:
            if cmd_set == SUBSCRIBE_SET:
                reply = self.subscriptions.handle(msg.name, msg.fields, now)
            else:
                reply = getattr(self, f"_on_{msg.name}")(msg.fields, now)
            if frame.session and reply is not None:
                self._ack(frame, cmds.encode_ack_payload(msg.name, reply, self.firmware), now)
        except (LayoutError, ValueError, KeyError) as exc:
            self.errors += 1
            log.warning("simulated FC could not handle %s: %s", msg.name, exc)

    # -- 0x00 activation set ------------------------------------------------------------------------
    def _on_get_version(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        """The firmware's own layout (``version_layout``): ``id`` for A3/N3/M600/M210 firmware, as DJI's
        Onboard-SDK 3.x library reads it; ``crc_id`` for firmware 3.1 (the M100 3.1.10.0); ``crc`` for
        M100 2.3."""
        ack = 0 if self.activated else NOT_ACTIVATED_ACK
        # The library finds the end of CRC + ID at the first NUL, so a real 3.1 firmware's CRC has no zero
        # byte (DJI's library reads real M100s); this stand-in CRC gets none either.
        crc = zlib.crc32(self.version_name.encode()[:32])
        crc = int.from_bytes(bytes(b or 1 for b in crc.to_bytes(4, "little")), "little")
        raw = cmds.encode_version_reply(
            ack, self.version_name, layout=self.version_layout, serial=self.serial, version_crc=crc
        )
        return {"ack": ack, "version_data": raw[2:]}

    def _on_activate(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if self.reject_activation:
            self.activated = False
            return {"ack": self.reject_activation}
        if self.app_id is not None and f["app_id"] != self.app_id:
            self.activated = False
            return {"ack": 0x0006}  # an unknown app id: the DJI server refuses (not confirmed)
        self.activated = True
        return {"ack": 0}

    def _on_set_broadcast_frequency(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        codes = list(f["frequency"])
        if any(c not in RATE_HZ and c != RATE_KEEP for c in codes):
            return {"ack": 1}
        for i, code in enumerate(codes[: len(self._item_names)]):  # the rest: no item on this firmware
            if code != RATE_KEEP:
                self._rates[i] = RATE_HZ[code]
                self._due[i] = now
        return {"ack": 0}

    # -- 0x01 control set ---------------------------------------------------------------------------
    def _on_obtain_control(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if not f["control"]:
            self.sdk_control = False
            if self.task == "sdk":
                self._enter_hover(None)
            return {"ack": 0x0001}
        if self.rc_mode != "F":
            return {"ack": self.rc_not_f_ack}
        if self.obtain_in_progress_once and not self.sdk_control:
            self.obtain_in_progress_once = False  # the host sends again with a new seq
            return {"ack": 0x0003}
        self.sdk_control = True
        return {"ack": 0x0002}

    def _on_flight_task(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if not self.sdk_control:
            return {"ack": NO_RIGHTS_ACK}
        if self.firmware == "m100":  # 1 go home, 4 take off, 6 landing; ACK 0x0002 started, 0x0001 failed
            legacy = _FLIGHT_TASKS_M100.get(f["command"])
            result = 10 if legacy is None else legacy(self)
            return {"ack": M100_TASK_STARTED if result == 0 else M100_TASK_FAILED}
        action = _FLIGHT_TASKS.get(f["command"])
        return {"ack": 10 if action is None else action(self)}

    def _task_takeoff(self) -> int:
        if self.in_air:
            return 3
        if self.task == "takeoff":
            return 8
        self.motors_on = True
        self.home_n, self.home_e = self.n, self.e  # the FC records home at take-off
        self._hold = (self.n, self.e, TAKEOFF_HEIGHT_M)
        self.task = "takeoff"
        return 0

    def _task_landing(self) -> int:
        if self.task == "landing":
            return 8
        if not self.in_air:
            return 4
        self._abort_missions()
        self._hold = (self.n, self.e, 0.0)
        self.task = "landing"
        return 0

    def _task_go_home(self) -> int:
        if self.task == "go_home":
            return 8
        if not self.in_air:
            return 4
        self._abort_missions()
        self._gh_alt = max(self.u, self.go_home_altitude_m)
        self._gh_climbing = True
        self._hold = (self.n, self.e, self._gh_alt)
        self.task = "go_home"
        return 0

    def _task_start_motors(self) -> int:
        if self.in_air:
            return 3
        if self.motors_on:
            return 1
        self.motors_on = True
        return 0

    def _task_stop_motors(self) -> int:
        if self.in_air:
            return 3
        if not self.motors_on:
            return 2
        self.motors_on = False
        self.task = "ground"
        return 0

    def _on_go_home_altitude_write(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        """0x01 0x42 with the go-home altitude's hash: the value is held and used by the next go home.
        Outside 20..500 m (OSDK checks this before sending; what a real FC answers is not documented)
        the simulator answers ret code 1 and keeps its value; the ACK always carries the value held."""
        lo, hi = cmds.GO_HOME_ALTITUDE_RANGE
        ok = lo <= f["altitude"] <= hi
        if ok:
            self.go_home_altitude_m = float(f["altitude"])
        held = round(self.go_home_altitude_m)
        return {"ack": 0 if ok else 1, "hash": f["hash"], "altitude": held}

    def _on_go_home_altitude_read(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        """0x01 0x41 with the go-home altitude's hash: the value held (what 0x01 0x42 wrote, or the
        configured ``go_home_altitude_m``), in the write's ACK layout."""
        return {"ack": 0, "hash": f["hash"], "altitude": round(self.go_home_altitude_m)}

    def _exit(self, task: str) -> int:
        if self.task != task:
            return 9
        self._enter_hover(None)
        return 0

    def _on_arm(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if not self.sdk_control:
            return {"ack": 1}
        if self.in_air:
            return {"ack": 3}
        if bool(f["arm"]) == self.motors_on:
            return {"ack": 2}
        self.motors_on = bool(f["arm"])
        if not self.motors_on:
            self.task = "ground"
        return {"ack": 0}

    def _on_kill_switch(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if f["cmd"] == 1:  # motors stop wherever the aircraft is: it drops
            self._abort_missions()
            self.motors_on = self.in_air = False
            self.u = self.vn = self.ve = self.vu = 0.0
            self.task = "ground"
        return {"ack": 0}

    def _movement_allowed(self) -> bool:
        return self.sdk_control and self.in_air and self.task in ("hover", "sdk")

    def _on_movement_control(self, f: dict[str, Any], now: float) -> None:
        if not self._movement_allowed():
            return  # ignored: on the ground, without authority, or an automatic task runs
        parts = split_control_flag(f["flag"])
        sp = _SetPoint(parts, f["x"], f["y"], f["z"], f["yaw"], now)
        if parts["horizontal"] == HORIZONTAL_POSITION:
            dn, de = self._frame_to_ne(parts["frame"], f["x"], f["y"])
            sp.target_ne = (self.n + dn, self.e + de)
        self._sp = sp
        self.task = "sdk"

    def _on_advanced_movement_control(self, f: dict[str, Any], now: float) -> None:
        self._on_movement_control(f, now)  # feed-forward terms ignored

    def _on_emergency_brake(self, f: dict[str, Any], now: float) -> None:
        if not (self.sdk_control and self.in_air):
            return
        self._abort_missions()
        self._enter_hover(None)  # brake at the normal limit, then hold where it stopped

    # -- 0x03 ground station: waypoints -------------------------------------------------------------
    def _on_wp_init(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        self.upload = _Upload(dict(f), [None] * f["length"])
        return {"ack": 0}  # seed: always 0, the mission is checked with the last waypoint

    def _on_wp_upload(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        index = f["index"]
        up = self.upload
        if up is None:
            return {"ack": 0xEA, "index": index}
        if index >= len(up.points):
            return {"ack": 0xE4, "index": index}
        up.points[index] = dict(f)
        up.valid = False
        if any(p is None for p in up.points):
            return {"ack": 0xE9 if index == len(up.points) - 1 else 0, "index": index}
        code = self._validate(up)
        up.valid = code == 0
        if code:
            up.points[index] = None  # an ACK error means this waypoint was not taken
        points = [self._point(p) for p in up.points if p is not None]
        speed = self._mission_speed(up.info)
        length = sum(math.dist((a.n, a.e, a.u), (b.n, b.e, b.u)) for a, b in itertools.pairwise(points))
        run_time = min(0xFFFF, round(length / speed)) if up.valid else 0
        event = {"incident_type": 0, "is_mission_valid": int(up.valid), "estimated_run_time": run_time}
        self._push("event_push", event, now)
        return {"ack": code, "index": index}

    def _validate(self, up: _Upload) -> int:
        info = up.info
        ok_info = (
            self.min_waypoints <= info["length"]
            and 2.0 <= info["vel_cmd_range"] <= 15.0
            and 0.0 < info["idle_vel"] <= info["vel_cmd_range"]
            and info["action_on_finish"] <= 4
            and 1 <= info["mission_exec_num"] <= 2
            and info["yaw_mode"] <= 3
            and info["trace_mode"] <= 1
        )
        if not ok_info:
            return 0xE0
        points = [self._point(p) for p in up.points if p is not None]
        for p in points:
            if p.u > self.max_altitude_m:
                return 0xC0
            if p.u < self.min_altitude_m:
                return 0xC1
            if math.hypot(p.n - self.home_n, p.e - self.home_e) > self.max_distance_m:
                return 0xC7
            if p.fields["has_action"] and any(
                c > 5 for c in p.fields["command_list"][: p.fields["action_num"]]
            ):
                return 0xE8
        trace = 0.0
        for a, b in itertools.pairwise(points):
            d = math.dist((a.n, a.e, a.u), (b.n, b.e, b.u))
            if d < ARRIVE_M:
                return 0xE5
            if d > 2000.0:
                return 0xE6
            trace += d
        # OSDK dji_error.cpp: waypoint 1 to n over 60 km (new A3/N3 firmware; 30 km others) is 0xE2; with
        # home to waypoint 1 and waypoint n back home over 100 km (60 km others), 0xE3
        max_trace, max_total = (60_000.0, 100_000.0) if self.firmware == "new" else (30_000.0, 60_000.0)
        if trace > max_trace:
            return 0xE2
        first, last = points[0], points[-1]
        home = (self.home_n, self.home_e)
        total = trace + math.dist(home, (first.n, first.e)) + math.dist((last.n, last.e), home)
        if total > max_total:
            return 0xE3
        return 0

    def _point(self, wp: dict[str, Any]) -> _Point:
        n, e = self.to_local(wp["latitude"], wp["longitude"])
        return _Point(n, e, float(wp["altitude"]), wp)

    @staticmethod
    def _mission_speed(info: Mapping[str, Any]) -> float:
        return max(0.1, min(float(info["idle_vel"]), float(info["vel_cmd_range"]), MAX_SPEED))

    def _on_wp_start_stop(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if f["start"] == 1:  # cancel
            if self.run is None:
                return {"ack": 0xD4}
            self.run = None
            self._enter_hover(None)
            return {"ack": 0}
        code = self._can_start_mission("waypoint")
        up = self.upload
        if not code:
            if up is None:
                code = 0xEA
            elif not up.valid or any(p is None for p in up.points):
                code = 0xEB
        if code:
            return {"ack": code}
        assert up is not None
        points = [self._point(p) for p in up.points if p is not None]
        if math.hypot(points[0].n - self.n, points[0].e - self.e) > self.max_distance_m:
            return {"ack": 0xC9}
        self.run = _Run(dict(up.info), points, lock_yaw=self.yaw)
        if self.in_air:
            self.task = "waypoint"
        else:
            self._task_takeoff()  # on the ground: take off first, the mission follows (docstring)
        self._next_status = now
        return {"ack": 0}

    def _can_start_mission(self, kind: str) -> int:
        """The common ground-station start checks, in the order the FC reports them: ``kind`` is
        "waypoint", "hotpoint" or "follow_me" (the same kind running: 0xD5, another: 0xD7)."""
        if not self.sdk_control:
            return 0xD1
        if self.rc_mode != "F":
            return 0xD0
        running = {"waypoint": self.run, "hotpoint": self.hotpoint, "follow_me": self.follow}
        if running.pop(kind) is not None:
            return 0xD5
        if any(m is not None for m in running.values()):
            return 0xD7
        busy = {"takeoff": 0xF0, "landing": 0xF1, "go_home": 0xF2}.get(self.task)
        if busy:
            return busy
        if not self.in_air and kind != "waypoint":
            return 0xDA  # hotpoint and follow-me start from the air (module docstring)
        return 0

    def break_mission(self, error: int, now: float | None = None) -> bool:
        """Fault injection: the FC breaks off the waypoint mission it flies with ground-station error
        ``error`` (e.g. 0xD9 low battery): the mission status push carries it, then the default status says
        the mission was broken off, and the aircraft brakes and hovers where it is (no "finished" event).
        Returns whether a mission was running."""
        run = self.run
        if run is None:
            return False
        now = self._clock(now)
        self._push("status_push", {"mission_type": 1, "target_waypoint": run.target,
                                   "current_status": 0, "error_notification": error}, now)  # fmt: skip
        self._abort_missions()
        self._enter_hover(None)
        self._push("status_push", {"mission_type": 0, "last_mission_type": 1, "is_broken": 1, "reserved_1": 0,
                                   "reason": error, "reserved_2": 0, "reserved_3": 0}, now)  # fmt: skip
        return True

    def _on_wp_pause_resume(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if self.run is None:
            return {"ack": 0xD4}
        self.run.paused = f["pause"] == 0
        return {"ack": 0}

    def _on_wp_download_init(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if self.upload is None:
            return {"ack": 0xEA}
        return {"ack": 0, **self.upload.info}

    def _on_wp_download_point(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        index = f["index"]
        if self.upload is None:
            return {"ack": 0xEA, "index": index}
        if index >= len(self.upload.points):
            return {"ack": 0xE4, "index": index}
        wp = self.upload.points[index]
        if wp is None:
            return {"ack": 0xE9, "index": index}
        return {"ack": 0, **wp}

    def _mission_infos(self) -> list[dict[str, Any]]:
        """The running mission's header first, then the uploaded one's."""
        return [m.info for m in (self.run, self.upload) if m is not None]

    def _on_wp_set_idle_velocity(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        infos = self._mission_infos()
        if not infos:
            return {"ack": 0xD3, "idle_velocity": 0.0}
        v = f["idle_velocity"]
        if not 0.0 < v <= min(infos[0]["vel_cmd_range"], MAX_SPEED):
            return {"ack": 0xDB, "idle_velocity": infos[0]["idle_vel"]}
        for info in infos:
            info["idle_vel"] = v
        return {"ack": 0, "idle_velocity": v}

    def _on_wp_get_idle_velocity(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        infos = self._mission_infos()
        info = infos[0] if infos else None
        if info is None:
            return {"ack": 0xD3, "idle_velocity": 0.0}
        return {"ack": 0, "idle_velocity": info["idle_vel"]}

    # -- 0x03 ground station: hotpoint ---------------------------------------------------------------
    def _on_hp_upload_start(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        code = self._can_start_mission("hotpoint")
        radius, rate = f["hp_radius"], f["angle_rate"]
        if not code:
            if not 5.0 <= radius <= 500.0:
                code = 0xC2
            elif not 0.0 <= rate <= 30.0 or math.radians(rate) * radius > MAX_SPEED:
                code = 0xC3
            elif f["start_point_position"] > 4:
                code = 0xC4
            elif f["yaw_mode"] > 4:
                code = 0xC5
        if code:
            return {"ack": code, "max_radius": 500.0}
        n, e = self.to_local(f["hp_latitude"], f["hp_longitude"])
        # The simulator always joins the circle at its nearest point (start_point_position 4).
        self.hotpoint = _Hotpoint(
            dict(f), n, e, float(f["hp_altitude"]), radius, rate, bool(f["is_clockwise"])
        )
        self.task = "hotpoint"
        self._next_status = now
        return {"ack": 0, "max_radius": 500.0}

    def _on_hp_stop(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if self.hotpoint is None:
            return {"ack": 0xD4}
        self.hotpoint = None
        self._enter_hover(None)
        return {"ack": 0}

    def _on_hp_pause_resume(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        hp = self.hotpoint
        if hp is None:
            return {"ack": 0xD4}
        pause = f["pause"] == 0
        if pause and hp.paused:
            return {"ack": 0xA9}
        if not pause and not hp.paused:
            return {"ack": 0xAA}
        hp.paused = pause
        return {"ack": 0}

    def _on_hp_set_idle_velocity(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        hp = self.hotpoint
        if hp is None:
            return {"ack": 0xD4}
        rate = f["idle_velocity"]  # OSDK updateYawRate: an angular rate, deg/s
        if not 0.0 <= rate <= 30.0 or math.radians(rate) * hp.radius > MAX_SPEED:
            return {"ack": 0xC3}
        hp.rate, hp.clockwise = rate, bool(f["is_clockwise"])
        return {"ack": 0}

    def _on_hp_set_radius(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        hp = self.hotpoint
        if hp is None:
            return {"ack": 0xD4}
        if not 5.0 <= f["radius"] <= 500.0:
            return {"ack": 0xC2}
        hp.radius = f["radius"]
        return {"ack": 0}

    def _on_hp_reset_yaw(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        return {"ack": 0 if self.hotpoint is not None else 0xD4}

    def _on_hp_download(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if self.hotpoint is None:
            return {"ack": 0xD3}
        return {"ack": 0, **self.hotpoint.settings}

    def _on_hp_auto_radius(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if self.hotpoint is None:
            return {"ack": 0xD4}
        self.hotpoint.auto_radius = (f["on_off"], f["rate"])  # stored, not flown
        return {"ack": 0}

    # -- 0x03 ground station: follow me --------------------------------------------------------------
    def _on_fm_upload_start(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        code = self._can_start_mission("follow_me")
        n, e = self.to_local(f["init_latitude"], f["init_longitude"])
        if not code and math.hypot(n - self.n, e - self.e) > self.max_distance_m:
            code = 0xB0
        if code:
            return {"ack": code}
        self.follow = _Follow(dict(f), n, e)
        self.task = "follow_me"
        self._next_status = now
        return {"ack": 0}

    def _on_fm_stop(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if self.follow is None:
            return {"ack": 0xD4}
        self.follow = None
        self._enter_hover(None)
        return {"ack": 0}

    def _on_fm_pause_resume(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if self.follow is None:
            return {"ack": 0xD4}
        self.follow.paused = f["pause"] == 0
        return {"ack": 0}

    def _on_fm_update_target(self, f: dict[str, Any], now: float) -> None:
        if self.follow is not None:
            self.follow.n, self.follow.e = self.to_local(f["latitude"], f["longitude"])

    # -- tasks -------------------------------------------------------------------------------------
    def _abort_missions(self) -> None:
        self.run = self.hotpoint = self.follow = None
        self._sp = None

    def _enter_hover(self, hold: tuple[float, float, float] | None) -> None:
        """Hover; ``None`` brakes first and holds where the aircraft stops."""
        self._sp = None
        self._hold = hold
        self._clear_yaw()
        self.task = "hover" if self.in_air else "ground"

    def advance(self, now: float) -> None:
        """Integrate the flight up to ``now`` in sub-steps of at most ``STEP`` seconds."""
        if self._last is None:
            self._t0 = self._last = self._t = now
            return
        dt = now - self._last
        if dt <= 0:
            return
        self._last = now
        steps = max(1, math.ceil(dt / STEP))
        h = dt / steps
        for _ in range(steps):
            self._t += h
            self._step(h)
        self._t = now

    def _clear_yaw(self) -> None:
        self._yaw_target, self._yaw_rate_cmd = None, 0.0

    def _step(self, h: float) -> None:
        self._clear_yaw()  # the task sets them again (a call, so a type checker does not narrow them)
        vn, ve, vu = self._tasks[self.task]()
        lim = ACCEL_LIMIT * h
        dvn, dve = vn - self.vn, ve - self.ve
        dh = math.hypot(dvn, dve)
        if dh > lim:
            dvn, dve = dvn * lim / dh, dve * lim / dh
        dvu = _clamp(vu - self.vu, -lim, lim)
        self.an, self.ae, self.au = dvn / h, dve / h, dvu / h
        self.vn, self.ve, self.vu = self.vn + dvn, self.ve + dve, self.vu + dvu
        self.n += self.vn * h
        self.e += self.ve * h
        self.u += self.vu * h
        if self._yaw_target is not None:
            self.yaw_rate = _clamp(_wrap180(self._yaw_target - self.yaw) / h, -YAW_SLEW, YAW_SLEW)
        else:
            self.yaw_rate = self._yaw_rate_cmd
        self.yaw = _wrap180(self.yaw + self.yaw_rate * h)
        self._ground_contact()
        if self.motors_on:
            self.battery = max(0.0, self.battery - h * (1.0 if self.in_air else 0.2) / 60.0)

    def _ground_contact(self) -> None:
        if self.task == "takeoff" and not self.in_air and self.u >= 0.1:
            self.in_air = True
            self._flown = True
        if self.u > 0.0 or (self.task == "takeoff" and self.vu > 0):
            return
        self.u = 0.0
        if self.in_air or self.task not in ("ground", "takeoff"):
            self.vn = self.ve = self.vu = 0.0
            self.in_air = False
            if self.task == "landing":
                self.motors_on = False  # auto landing ends with the motors stopped
            self._abort_missions()
            self.task = "ground"

    def _goto(self, n: float, e: float, u: float, vmax_h: float, vmax_v: float) -> tuple[float, float, float]:
        """Velocity toward a point: capped, braking in time to stop on it (then proportional)."""
        dn, de, du = n - self.n, e - self.e, u - self.u
        dh = math.hypot(dn, de)
        sh = min(vmax_h, math.sqrt(2 * BRAKE * dh), KP * dh)
        vn, ve = (dn / dh * sh, de / dh * sh) if dh > 1e-9 else (0.0, 0.0)
        sv = min(vmax_v, math.sqrt(2 * BRAKE * abs(du)), KP * abs(du))
        return vn, ve, math.copysign(sv, du)

    def _fly_ground(self) -> tuple[float, float, float]:
        self.u = self.vn = self.ve = self.vu = 0.0  # e.g. a take-off cancelled below 0.1 m
        return 0.0, 0.0, 0.0

    def _fly_takeoff(self) -> tuple[float, float, float]:
        assert self._hold is not None
        n, e, u = self._hold
        if abs(u - self.u) < 0.05 and abs(self.vu) < 0.2:
            self._enter_hover(self._hold)
            if self.run is not None:
                self.task = "waypoint"  # a mission started on the ground
        return self._goto(n, e, u, HOLD_SPEED, VERTICAL_SPEED)

    def _fly_hover(self) -> tuple[float, float, float]:
        if self._hold is None:
            if self.speed > 0.05:
                return 0.0, 0.0, 0.0
            self._hold = (self.n, self.e, self.u)
        return self._goto(*self._hold, HOLD_SPEED, 3.0)

    def _fly_sdk(self) -> tuple[float, float, float]:
        sp = self._sp
        if sp is None:
            return 0.0, 0.0, 0.0
        if self._t - sp.at >= self.setpoint_hold:  # no new frame for that long: brake, then hold
            self._enter_hover(None)
            return self._fly_hover()
        hor, ver = sp.parts["horizontal"], sp.parts["vertical"]
        if hor == HORIZONTAL_VELOCITY:
            vn, ve = self._frame_to_ne(sp.parts["frame"], sp.x, sp.y)
        elif hor == HORIZONTAL_POSITION and sp.target_ne is not None:
            vn, ve, _ = self._goto(*sp.target_ne, self.u, MOVE_H_LIMIT, 0.0)
        elif hor == HORIZONTAL_ANGLE:  # roll tilts right, pitch nose-up goes back: a rough stand-in
            vn, ve = self._frame_to_ne(sp.parts["frame"], -sp.y * ANGLE_TO_SPEED, sp.x * ANGLE_TO_SPEED)
        else:
            vn, ve = 0.0, 0.0  # angular-rate mode: not modelled, hold
        h = math.hypot(vn, ve)
        if h > MOVE_H_LIMIT:
            vn, ve = vn * MOVE_H_LIMIT / h, ve * MOVE_H_LIMIT / h
        if ver == VERTICAL_VELOCITY:
            vu = _clamp(sp.z, -MOVE_V_LIMIT, MOVE_V_LIMIT)
        elif ver == VERTICAL_POSITION:
            vu = self._goto(self.n, self.e, sp.z, 0.0, MOVE_V_LIMIT)[2]
        else:  # thrust %: 50 % hovers (rough stand-in)
            vu = _clamp((sp.z - 50.0) / 10.0, -MOVE_V_LIMIT, MOVE_V_LIMIT) if ver == VERTICAL_THRUST else 0.0
        if sp.parts["yaw"] == YAW_RATE:
            self._yaw_rate_cmd = _clamp(sp.yaw, -MOVE_YAW_LIMIT, MOVE_YAW_LIMIT)
        else:
            self._yaw_target = sp.yaw
        return vn, ve, vu

    def _frame_to_ne(self, frame: int, x: float, y: float) -> tuple[float, float]:
        """Ground frame: x north, y east. Body frame: x forward, y right, turned by the heading."""
        if frame != FRAME_BODY:
            return x, y
        c, s = math.cos(math.radians(self.yaw)), math.sin(math.radians(self.yaw))
        return x * c - y * s, x * s + y * c

    def _fly_landing(self) -> tuple[float, float, float]:
        assert self._hold is not None
        vn, ve, _ = self._goto(self._hold[0], self._hold[1], self.u, HOLD_SPEED, 0.0)
        return vn, ve, -VERTICAL_SPEED

    def _fly_go_home(self) -> tuple[float, float, float]:
        assert self._hold is not None
        if self._gh_climbing:
            if abs(self._gh_alt - self.u) < 0.3:
                self._gh_climbing = False
            return self._goto(self._hold[0], self._hold[1], self._gh_alt, HOLD_SPEED, 3.0)
        if math.hypot(self.home_n - self.n, self.home_e - self.e) < ARRIVE_M:
            self._hold = (self.home_n, self.home_e, 0.0)
            self.task = "landing"
        else:
            self._yaw_target = self._bearing(self.home_n, self.home_e)
        return self._goto(self.home_n, self.home_e, self._gh_alt, GO_HOME_SPEED, 3.0)

    def _bearing(self, n: float, e: float) -> float | None:
        if math.hypot(n - self.n, e - self.e) < 1.0:
            return None
        return math.degrees(math.atan2(e - self.e, n - self.n))

    def _fly_waypoint(self) -> tuple[float, float, float]:
        run = self.run
        assert run is not None
        p = run.points[run.target]
        if run.paused:
            return self._goto(self.n, self.e, self.u, 0.0, 0.0)
        if run.stay_until is not None:
            if self._t >= run.stay_until:
                run.stay_until = None
                self._point_done(run)
            return self._goto(p.n, p.e, p.u, HOLD_SPEED, MISSION_V_SPEED)
        cmd = self._goto(p.n, p.e, p.u, self._mission_speed(run.info), MISSION_V_SPEED)
        yaw_mode = run.info["yaw_mode"]
        if yaw_mode == 0:
            self._yaw_target = self._bearing(p.n, p.e)
        elif yaw_mode == 1:
            self._yaw_target = run.lock_yaw
        elif yaw_mode == 3:
            self._yaw_target = float(p.fields["tgt_yaw"])
        if run.info["gimbal_pitch_mode"] == 1:
            self.gimbal_pitch = float(p.fields["tgt_gimbal_pitch"])
        if math.dist((p.n, p.e, p.u), (self.n, self.e, self.u)) <= ARRIVE_M:
            self._arrive(run, p)
        return cmd

    def _arrive(self, run: _Run, p: _Point) -> None:
        run.reached_any = True
        if self.reach_pre_action_events:
            self._push(
                "event_push", {"incident_type": 2, "waypoint_index": run.target, "current_status": 4}, self._t
            )
        stay_ms = 0
        if p.fields["has_action"]:
            for command, param in list(
                zip(p.fields["command_list"], p.fields["command_param"], strict=False)
            )[: p.fields["action_num"]]:
                stay_ms += _WP_ACTIONS.get(command, _no_action)(self, param)
        if stay_ms > 0:
            run.stay_until = self._t + stay_ms / 1000.0
        else:
            self._point_done(run)

    def _point_done(self, run: _Run) -> None:
        self._push(
            "event_push", {"incident_type": 2, "waypoint_index": run.target, "current_status": 6}, self._t
        )
        run.target += 1
        if run.target < len(run.points):
            return
        run.executions += 1
        if run.info["action_on_finish"] == 4 or run.executions < run.info["mission_exec_num"]:
            run.target = 0  # infinite mode, or the second execution
            return
        self._push("event_push", {"incident_type": 1, "repeat": run.executions}, self._t)
        self.run = None
        _ON_FINISH.get(run.info["action_on_finish"], _finish_hover)(self, run)

    def _fly_hotpoint(self) -> tuple[float, float, float]:
        hp = self.hotpoint
        assert hp is not None
        if hp.paused:
            return self._goto(self.n, self.e, self.u, 0.0, 0.0)
        rn, re = self.n - hp.n, self.e - hp.e
        dist = math.hypot(rn, re)
        theta = math.atan2(re, rn) if dist > 0.1 else 0.0
        sign = 1.0 if hp.clockwise else -1.0
        vt = math.radians(hp.rate) * hp.radius
        vr = _clamp(1.5 * (hp.radius - dist), -HOLD_SPEED, HOLD_SPEED)
        vn = -math.sin(theta) * sign * vt + math.cos(theta) * vr
        ve = math.cos(theta) * sign * vt + math.sin(theta) * vr
        vu = self._goto(self.n, self.e, hp.u, 0.0, 3.0)[2]
        yaw_mode = hp.settings["yaw_mode"]
        face = {0: math.degrees(math.atan2(ve, vn)), 1: math.degrees(theta) + 180.0, 2: math.degrees(theta)}
        if yaw_mode in face:
            self._yaw_target = _wrap180(face[yaw_mode])
        return vn, ve, vu

    def _fly_follow(self) -> tuple[float, float, float]:
        fm = self.follow
        assert fm is not None
        if fm.paused:
            return self._goto(self.n, self.e, self.u, 0.0, 0.0)
        if fm.settings["yaw_mode"] == 1:
            self._yaw_target = self._bearing(fm.n, fm.e)
        return self._goto(fm.n, fm.e, self.u, FOLLOW_SPEED, 0.0)

    # -- pushes ------------------------------------------------------------------------------------
    def _mission_status(self, now: float) -> None:
        if now < self._next_status:
            return
        fields = self._status_fields()
        if fields is None:
            return
        self._next_status = now + STATUS_PERIOD
        self._push("status_push", fields, now)

    def _status_fields(self) -> dict[str, Any] | None:
        if self.run is not None:
            run = self.run
            status = 6 if run.stay_until is not None else (1 if run.reached_any else 0)
            return {"mission_type": 1, "target_waypoint": run.target, "current_status": status}
        if self.hotpoint is not None:
            hp = self.hotpoint
            radius = math.hypot(self.n - hp.n, self.e - hp.e)
            return {
                "mission_type": 2,
                "mission_status": 2 if hp.paused else 1,
                "hp_exec_radius": min(0xFFFF, round(radius * 100)),
                "hp_exec_vel": min(0xFF, round(hp.rate * 10)),
            }
        if self.follow is not None:
            return {"mission_type": 3}
        return None

    def _telemetry(self, now: float) -> None:
        due: list[str] = []
        for i, name in enumerate(self._item_names):
            hz = self._rates[i]
            if hz <= 0:
                continue
            nd = self._due[i]
            if nd is None:
                nd = now
            if now >= nd:
                due.append(name)
                nd += 1.0 / hz
                if nd <= now:
                    nd = now + 1.0 / hz
            self._due[i] = nd
        if due:
            items = {name: self._items[name](now) for name in due}
            if self.firmware == "m100":
                items = {name: _m100_item(name, fields) for name, fields in items.items()}
            payload = encode_flight_data(items, self.firmware)
            self._emit(self._table.send(0x02, 0x00, payload, now=now, mode=SessionMode.NO_ACK).frame, now)

    def _item_timestamp(self, now: float) -> dict[str, Any]:
        t = now - (self._t0 or 0.0)
        return {"time_ms": int(t * 1000) & 0xFFFFFFFF, "time_ns": int((t % 0.001) * 1e9)}

    def _item_quaternion(self, now: float) -> dict[str, Any]:
        half = math.radians(self.yaw) / 2
        return {"w": math.cos(half), "x": 0.0, "y": 0.0, "z": math.sin(half)}

    def _item_acceleration(self, now: float) -> dict[str, Any]:
        return {"x": self.an, "y": self.ae, "z": self.au}

    def _item_velocity(self, now: float) -> dict[str, Any]:
        return {"x": self.vn, "y": self.ve, "z": self.vu, "health": 1}

    def _item_angular_rate(self, now: float) -> dict[str, Any]:
        return {"x": 0.0, "y": 0.0, "z": math.radians(self.yaw_rate)}

    def _item_position(self, now: float) -> dict[str, Any]:
        lat, lon = self.to_latlon(self.n, self.e)
        item: dict[str, Any] = {
            "latitude": lat,
            "longitude": lon,
            "altitude": self.home_altitude + self.u,
            "height": self.u,
            "health": 5,
        }
        # new firmware: RelativePosition obstacle distances (m) and health bits
        for side in ("down", "front", "right", "back", "left", "up"):
            working = side in self.obstacle_sensors
            distance = (self.u if side == "down" else self.obstacle_range) if working else 0.0
            item[f"obstacle_{side}"] = distance
            item[f"{side}_health"] = 1 if working else 0
        item["obstacle_reserved"] = 0
        return item

    def _item_gps(self, now: float) -> dict[str, Any]:
        lat, lon = self.to_latlon(self.n, self.e)
        t = int(now - (self._t0 or 0.0))
        self._gps_counter = (self._gps_counter + 1) & 0xFFFF
        return {
            "date": 20240601,
            "time": (t // 3600 % 24) * 10000 + (t // 60 % 60) * 100 + t % 60,
            "longitude": round(math.degrees(lon) * 1e7),
            "latitude": round(math.degrees(lat) * 1e7),
            "hfsl": round((self.home_altitude + self.u) * 1000),
            "velocity_n": self.vn * 100,
            "velocity_e": self.ve * 100,
            "velocity_d": -self.vu * 100,
            "hdop": 0.8,
            "pdop": 1.4,
            "fix": 3.0,
            "gnss_status": 1.0,
            "hacc": 600.0,
            "sacc": 20.0,
            "used_gps": 12,
            "used_glonass": 6,
            "num_sv": 18,
            "gps_counter": self._gps_counter,
        }

    def _item_rtk(self, now: float) -> dict[str, Any]:
        return {}  # no RTK module: all zero, solution type 0

    def _item_mag(self, now: float) -> dict[str, Any]:
        c, s = math.cos(math.radians(self.yaw)), math.sin(math.radians(self.yaw))
        return {"x": round(600 * c), "y": round(-600 * s), "z": 1200}

    def _item_rc(self, now: float) -> dict[str, Any]:
        return {"mode": RC_STICK_MODE.get(self.rc_mode, 0), "gear": -4545}

    def _item_gimbal(self, now: float) -> dict[str, Any]:
        return {"roll": 0.0, "pitch": self.gimbal_pitch, "yaw": self.yaw}

    def _item_status(self, now: float) -> dict[str, Any]:
        return {"flight": self.flight_status, "display_mode": self.display_mode, "gear": 0, "error": 0}

    def _item_battery(self, now: float) -> dict[str, Any]:
        current = 18000 if self.in_air else 1500 if self.motors_on else 300
        return {
            "capacity": self.battery_capacity_mah,
            "voltage": round(44400 + 6000 * self.battery / 100),  # 12S pack: 44.4..50.4 V
            "current": current,
            "percentage": round(self.battery),
        }

    def _item_control_device(self, now: float) -> dict[str, Any]:
        return {"device_status": 2 if self.sdk_control else 0, "flight_status": int(self.sdk_control)}

    # what subscription topics read besides the flight-data items (subscription.SOURCE_ITEMS)
    def _source_home(self, now: float) -> dict[str, Any]:
        lat, lon = self.to_latlon(self.home_n, self.home_e)
        return {"latitude": lat, "longitude": lon, "altitude": self.home_altitude, "set": 1}

    def _source_aircraft(self, now: float) -> dict[str, Any]:
        c, s = math.cos(math.radians(self.yaw)), math.sin(math.radians(self.yaw))
        return {
            "motors_on": int(self.motors_on),
            "gimbal_mounted": 1,
            "rtk_connected": 0,
            "north": self.n - self.home_n,
            "east": self.e - self.home_e,
            "up": self.u,
            "accel_x": self.an * c + self.ae * s,  # body FRD, plus the reaction to gravity an IMU reads
            "accel_y": -self.an * s + self.ae * c,
            "accel_z": -self.au - 9.80665,
        }


class _Sources(Mapping[str, Mapping[str, Any]]):
    """The model's flight-data items and subscription sources at ``now``, read on demand."""

    def __init__(self, model: OsdkFcModel, now: float) -> None:
        self._model, self._now = model, now

    def __getitem__(self, name: str) -> Mapping[str, Any]:
        getter = getattr(self._model, f"_source_{name}", None) or self._model._items[name]
        return getter(self._now)

    def __iter__(self) -> Iterator[str]:
        return iter((*self._model._items, *sub.SOURCE_ITEMS))

    def __len__(self) -> int:
        return len(self._model._items) + len(sub.SOURCE_ITEMS)


# Flight task codes (FLIGHT_TASKS) -> what the FC does; each returns the FLIGHT_TASK_ACK code.
_FLIGHT_TASKS_M100: dict[int, Callable[[OsdkFcModel], int]] = {
    1: OsdkFcModel._task_go_home,
    4: OsdkFcModel._task_takeoff,
    6: OsdkFcModel._task_landing,
}
_FLIGHT_TASKS: dict[int, Callable[[OsdkFcModel], int]] = {
    1: OsdkFcModel._task_takeoff,
    2: OsdkFcModel._task_landing,
    6: OsdkFcModel._task_go_home,
    7: OsdkFcModel._task_start_motors,
    8: OsdkFcModel._task_stop_motors,
    12: lambda m: m._exit("go_home"),
    13: lambda m: m._exit("takeoff"),
    14: lambda m: m._exit("landing"),
}


def _m100_item(name: str, fields: dict[str, Any]) -> dict[str, Any]:
    """A new-firmware item body in the M100 layout of the same item (adapters.osdk.telemetry)."""
    if name == "timestamp":
        return {
            "time": fields["time_ms"] // 2,
            "nano_time": fields["time_ns"],
            "sync_flag": 0,
        }  # 500 Hz ticks
    if name == "velocity":
        return {**fields, "sensor_id": 0}
    if name == "position":
        return {k: fields[k] for k in ("latitude", "longitude", "altitude", "height", "health")}
    if name == "status":
        return {"flight": fields["flight"]}
    if name == "battery":
        return {"percentage": fields["percentage"]}
    return fields


def _no_action(m: OsdkFcModel, param: int) -> int:
    return 0


def _act_stay(m: OsdkFcModel, param: int) -> int:
    return max(0, param)  # hover time, ms


def _act_shot(m: OsdkFcModel, param: int) -> int:
    m.photos += 1
    return 0


def _act_record(on: bool) -> Callable[[OsdkFcModel, int], int]:
    def act(m: OsdkFcModel, param: int) -> int:
        m.recording = on
        return 0

    return act


def _act_yaw(m: OsdkFcModel, param: int) -> int:
    m.yaw = _wrap180(float(param))
    return 0


def _act_gimbal(m: OsdkFcModel, param: int) -> int:
    m.gimbal_pitch = float(param)
    return 0


# Seed 004 waypoint actions (WP_ACTIONS); each returns how long it holds the aircraft, in ms.
_WP_ACTIONS: dict[int, Callable[[OsdkFcModel, int], int]] = {
    0: _act_stay,
    1: _act_shot,
    2: _act_record(True),
    3: _act_record(False),
    4: _act_yaw,
    5: _act_gimbal,
}


def _finish_hover(m: OsdkFcModel, run: _Run) -> None:
    last = run.points[-1]
    m._enter_hover((last.n, last.e, last.u))


def _finish_back_to_first(m: OsdkFcModel, run: _Run) -> None:
    first = run.points[0]
    m._enter_hover((first.n, first.e, first.u))


def _finish_go_home(m: OsdkFcModel, run: _Run) -> None:
    _finish_hover(m, run)
    m._task_go_home()


def _finish_land(m: OsdkFcModel, run: _Run) -> None:
    _finish_hover(m, run)
    m._task_landing()


# action_on_finish: 0 hover, 1 go home, 2 land, 3 back to waypoint 0 (4, infinite, never finishes).
_ON_FINISH: dict[int, Callable[[OsdkFcModel, _Run], None]] = {
    0: _finish_hover,
    1: _finish_go_home,
    2: _finish_land,
    3: _finish_back_to_first,
}


class OsdkFcDevice:
    """The model as a :class:`~adapters.simio.StreamDevice`; every call holds :attr:`lock`, so tests
    may read or poke the model from another thread through :meth:`inspect` or the hooks here."""

    def __init__(self, model: OsdkFcModel | None = None) -> None:
        self.model = model or OsdkFcModel()
        self.lock = threading.Lock()

    def on_bytes(self, data: bytes, now: float) -> bytes:
        with self.lock:
            return b"".join(self.model.feed(data, now))

    def tick(self, now: float) -> bytes:
        with self.lock:
            return b"".join(self.model.tick(now))

    def inspect(self, fn: Callable[[OsdkFcModel], T]) -> T:
        """``fn(model)`` under the lock (a consistent snapshot from another thread)."""
        with self.lock:
            return fn(self.model)

    def drop_acks(self, n: int) -> None:
        with self.lock:
            self.model.drop_acks(n)

    def rc_takeover(self) -> None:
        """The RC takes control back; the push goes out with the next tick."""
        with self.lock:
            self.model.rc_takeover()

    def break_mission(self, error: int) -> bool:
        """The FC breaks off its waypoint mission with ``error`` (:meth:`OsdkFcModel.break_mission`)."""
        with self.lock:
            return self.model.break_mission(error)


def _latlon(text: str) -> tuple[float, float]:
    try:
        lat, lon = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError("expected LAT,LON in degrees, e.g. 22.5431,113.958") from None
    if not (-90 <= lat <= 90 and -180 <= lon <= 180):
        raise argparse.ArgumentTypeError("latitude must be within ±90 and longitude within ±180")
    return lat, lon


def _hold_seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError("expected a number of seconds or 'inf'") from None
    if not value > 0:  # also refuses nan
        raise argparse.ArgumentTypeError("the hold time must be positive (or 'inf')")
    return value


def main(argv: Sequence[str] | None = None) -> int:
    """``dji-gateway simulate osdk``: a flight controller on a pty (default) or a loopback TCP port."""
    p = argparse.ArgumentParser(prog="dji-gateway simulate osdk", description=__doc__.split("\n\n")[0])
    where = p.add_mutually_exclusive_group()
    where.add_argument("--tcp", type=int, metavar="PORT", help="listen on 127.0.0.1:PORT (0 = any free port)")
    where.add_argument("--pty", action="store_true", help="create a pseudo-terminal (default)")
    p.add_argument("--app-id", type=int, help="the app id activation accepts (default: any)")
    p.add_argument(
        "--home", type=_latlon, default=DEFAULT_HOME, metavar="LAT,LON", help="home point, degrees"
    )
    p.add_argument("--rc-mode", choices=("F", "P", "A"), default="F", help="RC mode switch (default F)")
    p.add_argument("--max-distance", type=float, default=2000.0, help="waypoint limit from home, m")
    p.add_argument(
        "--setpoint-hold",
        type=_hold_seconds,
        default=math.inf,
        metavar="SECONDS|inf",
        help="how long a movement-control set-point is held without a new frame before the FC brakes "
        "and hovers (default inf: held until the next; a real FC's hold time is not documented)",
    )
    p.add_argument(
        "--firmware",
        choices=("new", "m100"),
        default="new",
        help="new: A3/N3/M600/M210 (OSDK 3.x, default); m100: the M100's legacy codes, status and telemetry",
    )
    ns = p.parse_args(argv)
    model = OsdkFcModel(
        app_id=ns.app_id,
        home=ns.home,
        rc_mode=ns.rc_mode,
        max_distance_m=ns.max_distance,
        firmware=ns.firmware,
        setpoint_hold=ns.setpoint_hold,
    )
    device = OsdkFcDevice(model)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    runner: TcpEndpoint | PtyEndpoint
    if ns.tcp is not None:
        runner = tcp = TcpEndpoint(device, port=ns.tcp)
        place = tcp.url
    else:
        runner = pty = PtyEndpoint(device)
        place = pty.path
    runner.start()
    print(f"OSDK flight controller simulator at {place}", flush=True)
    app = "any app id" if ns.app_id is None else f"app id {ns.app_id}"
    print(
        f"gateway port: {place} (activation accepts {app}; home {ns.home[0]},{ns.home[1]}; "
        f"firmware {ns.firmware}; set-points held {ns.setpoint_hold:g} s)",
        flush=True,
    )
    with contextlib.suppress(KeyboardInterrupt):
        stop.wait()
    runner.stop()
    return 0


#: The ``url`` of an aircraft entry that ``dji-gateway run --simulate`` replaces with its simulator's.
SIM_URL = "sim://osdk"


def in_process(device: Any) -> tuple[InProcessSim, Any] | None:
    """``dji-gateway run --simulate`` (:mod:`adapters.families`): an aircraft entry whose url is
    :data:`SIM_URL` gets a flight-controller simulator on a loopback TCP port, speaking the firmware the
    entry names (new or m100), and the entry pointed at it. Any other entry: None."""
    if device.url != SIM_URL:
        return None
    # an M100's go-home altitude is the one its entry states (the simulated FC holds it)
    held = device.go_home_altitude
    model = OsdkFcModel(firmware=device.firmware)
    if held is not None:
        model.go_home_altitude_m = float(held)
    endpoint = TcpEndpoint(OsdkFcDevice(model)).start()
    log.info("simulated aircraft %s at %s", device.sn, endpoint.url)
    return endpoint, device.model_copy(update={"url": endpoint.url})
