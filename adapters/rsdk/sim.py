"""A DJI RS-series gimbal that speaks R SDK over CAN: the simulator every gimbal test talks to.

It models what the gateway relies on: three axes with the seed's limits (yaw ±180°, roll ±30°,
pitch −56°…+146°), speed control that lapses 0.5 s after the last command (seed §2.3.4.2), position
control that moves at constant speed over ``time_for_action`` (§2.3.4.1), the 10 Hz parameter push
once enabled (§2.3.4.8/9), limit and stiffness settings, recenter/selfie, follow modes, camera
recording state (§2.3.5) and the version query. Replies come in the latest format by default and in
the legacy format (no CmdSet/CmdID) by option.

Layers: :class:`GimbalModel` is sans-I/O (frames and a clock value in, frames out);
:class:`GimbalNode` adds CAN segmentation/reassembly; the runners give it a real bus: a python-can
bus (``virtual`` in-process) or an SLCAN USB-CAN adapter on a pty or loopback TCP port, which the
gateway opens with python-can's own ``slcan`` interface as it would a CANable.

Time: a simulator keeps its own, real time (``time.monotonic``), as the device it stands for does; the
gateway's injected clock is not the device's.

Why this module is longer than 500 lines: it holds the sans-I/O gimbal model (three axes, speed and position
control, pushes, every command it answers) and its two transports (a virtual CAN node, an SLCAN adapter) with
the simulator's entry points; the model is one device's behaviour on one clock.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import select
import signal
import threading
import time
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from adapters.errors import CommandError
from adapters.families import InProcessSim
from adapters.rsdk.can import GIMBAL_TX_ID, HOST_TX_ID, Reassembler, segment
from adapters.rsdk.commands import build_frame, decode_message
from adapters.rsdk.protocol import Frame, encode
from adapters.simio import PtyEndpoint, TcpEndpoint
from adapters.wire.slcan import SlcanAdapterState, format_frame

log = logging.getLogger(__name__)

__all__ = ["GimbalCanSim", "GimbalModel", "GimbalNode", "SlcanGimbal", "main"]

SPEED_HOLD_S = 0.5  # seed §2.3.4.2: one speed command controls for 0.5 s
PUSH_PERIOD_S = 0.1  # 10 Hz parameter push
CALIBRATION_S = 2.0  # a simulated auto calibration takes this long (a real one takes minutes)
CALIBRATION_PUSH_S = 0.5  # its progress push (0x0E 0x10) period
DEFAULT_VERSION = 0x01020304  # shows as 01.02.03.04
RC_OK, RC_PARSE_ERROR, RC_FAILED = 0x00, 0x01, 0x02


@dataclass
class Axis:
    """One axis in degrees; limits are the mechanical range, clamps are the user limit angles."""

    angle: float = 0.0
    low: float = -180.0
    high: float = 180.0
    speed: float = 0.0  # deg/s from speed control
    # position move in progress: (start angle, target angle, start time, duration)
    move: tuple[float, float, float, float] | None = None

    def clamp(self, value: float) -> float:
        return min(self.high, max(self.low, value))


@dataclass
class ReplyFaults:
    """How a misbehaving gimbal answers (tests, and ``simulate rsdk --fault``). Replies only: the
    parameter push stays intact, so the gimbal stays online while its answers go wrong."""

    corrupt_crc: bool = False  # the last CRC32 byte flipped
    truncate: bool = False  # the CRC32 never sent (the frame ends short)
    seq_offset: int = 0  # replies carry the command's seq plus this
    duplicate: bool = False  # every reply sent twice
    delay: float = 0.0  # replies sent this many seconds late

    @classmethod
    def parse(cls, specs: Sequence[str]) -> ReplyFaults:
        """``crc``, ``truncate``, ``duplicate``, ``seq=N``, ``delay=SECONDS`` (the CLI's ``--fault``)."""
        f = cls()
        for spec in specs:
            name, _, value = spec.partition("=")
            if name == "crc" and not value:
                f.corrupt_crc = True
            elif name == "truncate" and not value:
                f.truncate = True
            elif name == "duplicate" and not value:
                f.duplicate = True
            elif name == "seq" and value.lstrip("-").isdigit():
                f.seq_offset = int(value)
            elif name == "delay" and _is_seconds(value):
                f.delay = float(value)
            else:
                raise ValueError(f"unknown fault {spec!r} (crc, truncate, duplicate, seq=N, delay=SECONDS)")
        return f

    def apply(self, raws: list[bytes]) -> list[bytes]:
        out: list[bytes] = []
        for raw in raws:
            if self.corrupt_crc:
                raw = raw[:-1] + bytes([raw[-1] ^ 0xFF])
            if self.truncate:
                raw = raw[:-4]
            out += [raw, raw] if self.duplicate else [raw]
        return out


def _is_seconds(text: str) -> bool:
    try:
        return 0 <= float(text) < 3600
    except ValueError:
        return False


@dataclass
class GimbalModel:
    """The gimbal's state and its answers. Time is passed in; nothing here sleeps or reads a clock."""

    legacy_replies: bool = False
    #: with ``legacy_replies``: the angle order of a 0x0E 0x02 reply (commands.LEGACY_ANGLE_ORDERS): the
    #: seed's yaw_roll_pitch, or yaw_pitch_roll as ArduPilot reads older gimbal firmware
    legacy_angle_order: str = "yaw_roll_pitch"
    version: int = DEFAULT_VERSION
    yaw: Axis = field(default_factory=lambda: Axis(0.0, -180.0, 180.0))
    roll: Axis = field(default_factory=lambda: Axis(0.0, -30.0, 30.0))
    pitch: Axis = field(default_factory=lambda: Axis(0.0, -56.0, 146.0))
    limits: dict[str, int] = field(
        default_factory=lambda: {
            "pitch_max": 145,
            "pitch_min": 55,
            "yaw_max": 179,
            "yaw_min": 179,
            "roll_max": 30,
            "roll_min": 30,
        }
    )
    stiffness: dict[str, int] = field(
        default_factory=lambda: {"pitch_stiffness": 50, "yaw_stiffness": 50, "roll_stiffness": 50}
    )
    push_enabled: bool = False
    recording: bool = False
    photos: int = 0
    follow_mode: int = 0
    active_track: bool = False
    #: auto calibration (0x0E 0x0F): None when idle, else when it started; progress is pushed (0x0E 0x10)
    #: every CALIBRATION_PUSH_S until it completes after CALIBRATION_S
    calibration_started: float | None = None
    calibration_type: int | None = None  # the self-tuning type of the last start (seed: 1)
    calibrations_completed: int = 0
    _next_calibration_push: float = 0.0
    speed_until: float = 0.0
    received: Counter[str] = field(default_factory=Counter)
    faults: ReplyFaults = field(default_factory=ReplyFaults)
    _late: list[tuple[float, bytes]] = field(default_factory=list)  # delayed replies: (due, frame)
    _last: float | None = None
    _next_push: float = 0.0
    _push_seq: int = 0

    @property
    def axes(self) -> dict[str, Axis]:
        return {"yaw": self.yaw, "roll": self.roll, "pitch": self.pitch}

    def attitude(self) -> tuple[float, float, float]:
        return (self.yaw.angle, self.roll.angle, self.pitch.angle)

    # -- physics -----------------------------------------------------------------------------------
    def advance(self, now: float) -> None:
        last = self._last if self._last is not None else now
        dt = max(0.0, now - last)
        self._last = now
        speed_active = now < self.speed_until
        for ax in self.axes.values():
            if ax.move is not None:
                start, target, t0, dur = ax.move
                frac = 1.0 if dur <= 0 else min(1.0, (now - t0) / dur)
                ax.angle = ax.clamp(start + (target - start) * frac)
                if frac >= 1.0:
                    ax.move = None
            elif speed_active and ax.speed:
                ax.angle = ax.clamp(ax.angle + ax.speed * dt)
        if not speed_active:
            for ax in self.axes.values():
                ax.speed = 0.0

    # -- protocol ----------------------------------------------------------------------------------
    def handle(self, frame: Frame, now: float) -> list[bytes]:
        """Answer one received frame (already CRC-checked); returns encoded reply frames."""
        self.advance(now)
        if frame.is_reply:
            return []
        try:
            msg = decode_message(frame)
        except CommandError:
            self.received["<undecodable>"] += 1
            return self._reply_raw(frame, RC_PARSE_ERROR, now) if frame.needs_reply else []
        self.received[msg.name] += 1
        handler = getattr(self, f"_on_{msg.name}", None)
        fields: dict[str, Any] = {"return_code": RC_OK}
        if handler is not None:
            fields = handler(msg.fields, now)
        if not frame.needs_reply:
            return []
        return self._answer([self._reply(msg.name, frame.seq, fields)], now)

    def _answer(self, replies: list[bytes], now: float) -> list[bytes]:
        replies = self.faults.apply(replies)
        if self.faults.delay > 0:
            self._late += [(now + self.faults.delay, r) for r in replies]
            return []
        return replies

    def tick(self, now: float) -> list[bytes]:
        """Advance the axes; returns delayed replies that are due and the 10 Hz push when it is due."""
        self.advance(now)
        due = [r for t, r in self._late if t <= now]
        if due:
            self._late = [(t, r) for t, r in self._late if t > now]
        due += self._calibration_push(now)
        if not self.push_enabled or now < self._next_push:
            return due
        self._next_push = now + PUSH_PERIOD_S
        self._push_seq = (self._push_seq + 1) & 0xFFFF
        y, r, p = (round(a * 10) for a in self.attitude())
        fields = {
            "ctrl_byte": 0x07,
            "yaw_angle": y,
            "roll_angle": r,
            "pitch_angle": p,
            "yaw_joint_angle": y,
            "roll_joint_angle": r,
            "pitch_joint_angle": p,
            **self.limits,
            **self.stiffness,
        }
        return [*due, encode(build_frame("param_push", self._push_seq, fields))]

    def _reply(self, name: str, seq: int, fields: dict[str, Any]) -> bytes:
        seq = (seq + self.faults.seq_offset) & 0xFFFF
        frame = build_frame(
            name, seq, fields, reply=True, legacy=self.legacy_replies, angle_order=self.legacy_angle_order
        )
        return encode(frame)

    def _reply_raw(self, frame: Frame, code: int, now: float) -> list[bytes]:
        if frame.key is None:
            return []
        cmd_set, cmd_id = frame.key
        seq = (frame.seq + self.faults.seq_offset) & 0xFFFF
        if self.legacy_replies:
            return self._answer([encode(Frame(None, None, bytes([code]), seq, 0, True))], now)
        return self._answer([encode(Frame(cmd_set, cmd_id, bytes([code]), seq, 0, True))], now)

    # -- command handlers: fields in wire units, reply fields out --------------------------------------
    def _on_position_control(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        ctrl = f["ctrl_byte"]
        absolute = bool(ctrl & 0x01)
        duration = max(0.0, f["time_for_action"] / 10)
        for bit, name, key in (
            (0x02, "yaw", "yaw_angle"),
            (0x04, "roll", "roll_angle"),
            (0x08, "pitch", "pitch_angle"),
        ):
            if ctrl & bit:
                continue  # axis marked invalid
            ax = self.axes[name]
            value = f[key] / 10
            target = ax.clamp(value if absolute else ax.angle + value)
            ax.move = (ax.angle, target, now, duration)
            ax.speed = 0.0
        return {"return_code": RC_OK}

    def _on_speed_control(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if not f["ctrl_byte"] & 0x80:  # release speed control
            self.speed_until = 0.0
            for ax in self.axes.values():
                ax.speed = 0.0
            return {"return_code": RC_OK}
        self.speed_until = now + SPEED_HOLD_S
        for name in ("yaw", "roll", "pitch"):
            ax = self.axes[name]
            ax.speed = f[f"{name}_speed"] / 10
            ax.move = None
        return {"return_code": RC_OK}

    def _on_get_angle(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        kind = f["ctrl_byte"]
        if kind not in (1, 2):
            return {"return_code": RC_OK, "data_type": 0, "yaw": 0, "roll": 0, "pitch": 0}
        y, r, p = (round(a * 10) for a in self.attitude())
        return {"return_code": RC_OK, "data_type": kind, "yaw": y, "roll": r, "pitch": p}

    def _on_set_limit_angle(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if f["ctrl_byte"] == 0x01:
            self.limits = {k: f[k] for k in self.limits}
            self.yaw.low, self.yaw.high = -float(f["yaw_min"]), float(f["yaw_max"])
            self.roll.low, self.roll.high = -float(f["roll_min"]), float(f["roll_max"])
            self.pitch.low, self.pitch.high = -float(f["pitch_min"]), float(f["pitch_max"])
        return {"return_code": RC_OK}

    def _on_get_limit_angle(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        return {"return_code": RC_OK, **self.limits}

    def _on_set_stiffness(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if f["ctrl_byte"] == 0x01:
            self.stiffness = {k: f[k] for k in self.stiffness}
        return {"return_code": RC_OK}

    def _on_get_stiffness(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        return {"return_code": RC_OK, **self.stiffness}

    def _on_push_settings(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if f["ctrl_byte"] == 0x01:
            self.push_enabled = True
            self._next_push = now
        elif f["ctrl_byte"] == 0x02:
            self.push_enabled = False
        return {"return_code": RC_OK}

    def _on_get_version(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        return {"return_code": RC_OK, "device_id": f["device_id"], "version": self.version}

    def _on_recenter_selfie(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        cmd = f["recenter_and_selfie_command"]
        if cmd == 0x01:
            targets = {"yaw": 0.0, "roll": 0.0, "pitch": 0.0}
        elif cmd == 0x02:
            targets = {"yaw": self.yaw.clamp(180.0 if self.yaw.angle <= 0 else -180.0)}
        else:
            return {"return_code": RC_FAILED}
        for name, target in targets.items():
            ax = self.axes[name]
            ax.move = (ax.angle, ax.clamp(target), now, 1.0)
        return {"return_code": RC_OK}

    def _on_follow_mode(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if f["operating_mode"] not in (0x00, 0x02, 0x03):
            return {"return_code": RC_FAILED}
        self.follow_mode = f["operating_mode"]
        return {"return_code": RC_OK}

    def _on_auto_calibration(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        """No reply frame (seed Figure 29): bit 0 starts/stops, bits 7:1 are the self-tuning type."""
        for item in f["tlv_buffer"]:
            if item.get("id") != 0x00:
                continue
            value = int(item["value"])
            if value & 0x01:
                self.calibration_started, self.calibration_type = now, value >> 1
                self._next_calibration_push = now
            else:
                self.calibration_started = None
        return {"return_code": RC_OK}

    def _calibration_push(self, now: float) -> list[bytes]:
        started = self.calibration_started
        if started is None or now < self._next_calibration_push:
            return []
        self._next_calibration_push = now + CALIBRATION_PUSH_S
        progress = min(100, int((now - started) / CALIBRATION_S * 100))
        status = 2 if progress >= 100 else 1
        if status == 2:
            self.calibration_started = None
            self.calibrations_completed += 1
        item = {"id": 0x00, "value": {"status": status, "progress": progress, "error": bytes(4)}}
        self._push_seq = (self._push_seq + 1) & 0xFFFF
        return [encode(build_frame("calibration_push", self._push_seq, {"tlv_buffer": [item]}))]

    def _on_active_track(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        if f["enable_active_track"] == 0x03:
            self.active_track = not self.active_track
            return {"return_code": RC_OK}
        return {"return_code": RC_FAILED}

    def _on_camera_control(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        cmd = f["camera_control_command"]
        if cmd == 0x0001:
            self.photos += 1
        elif cmd == 0x0003:
            self.recording = True
        elif cmd == 0x0004:
            self.recording = False
        elif cmd not in (0x0002, 0x0005, 0x000B):
            return {"return_code": RC_FAILED}
        return {"return_code": RC_OK}

    def _on_camera_status(self, f: dict[str, Any], now: float) -> dict[str, Any]:
        return {"return_code": RC_OK, "camera_status": 0x02 if self.recording else 0x00}


class GimbalNode:
    """The model on a CAN bus: reassembles host frames from 0x223, answers on 0x222."""

    def __init__(
        self, model: GimbalModel | None = None, rx_id: int = HOST_TX_ID, tx_id: int = GIMBAL_TX_ID
    ) -> None:
        self.model = model or GimbalModel()
        self.tx_id = tx_id
        self._rx = Reassembler(rx_id=rx_id)
        self.lock = threading.Lock()  # tests read the model from another thread

    def on_can(self, arb_id: int, data: bytes, now: float) -> list[tuple[int, bytes]]:
        out: list[tuple[int, bytes]] = []
        with self.lock:
            for item in self._rx.feed(arb_id, data):
                if isinstance(item, Frame):
                    for raw in self.model.handle(item, now):
                        out += segment(raw, self.tx_id)
        return out

    def tick(self, now: float) -> list[tuple[int, bytes]]:
        with self.lock:
            return [seg for raw in self.model.tick(now) for seg in segment(raw, self.tx_id)]


class GimbalCanSim:
    """The gimbal on a python-can bus, in a thread (``virtual`` in-process, or any interface)."""

    def __init__(
        self,
        node: GimbalNode | None = None,
        *,
        interface: str = "virtual",
        channel: str = "djigw",
        **bus_kwargs: Any,
    ) -> None:
        import can  # the runner needs python-can; the model above does not

        self.node = node or GimbalNode()
        self._bus = can.Bus(interface=interface, channel=channel, receive_own_messages=False, **bus_kwargs)
        self._can = can
        from adapters.rsdk.link import virtual_batch_sender, virtual_reader

        # a real device's frames cost it nothing to put on the wire: on the in-process bus, no deep copy;
        # nor to take them off it: the thread waits on a pipe and takes frames without queue locks
        self._put_all = virtual_batch_sender(self._bus) if interface == "virtual" else None
        self._reader = virtual_reader(self._bus) if interface == "virtual" else None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="gimbal-sim", daemon=True)
        self.paused = False
        self.error_frames = False  # put a CAN error frame on the bus before every reply

    @property
    def model(self) -> GimbalModel:
        return self.node.model

    def start(self) -> GimbalCanSim:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5)
        self._bus.shutdown()
        if self._reader is not None:  # (after the shutdown: no sender writes to its pipe any more)
            self._reader.close()

    def __enter__(self) -> GimbalCanSim:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _send(self, frames: list[tuple[int, bytes]]) -> None:
        if not frames:
            return
        msgs = [
            self._can.Message(arbitration_id=arb_id, data=data, is_extended_id=False)
            for arb_id, data in frames
        ]
        if self._put_all is not None:  # one command's reply frames together: the gateway wakes once
            self._put_all(msgs)
            return
        for msg in msgs:
            self._bus.send(msg)

    #: frames taken in one go before the model's clock ticks (a command's frames arrive back to back)
    BATCH = 64

    def _run(self) -> None:
        reader = self._reader
        take = reader.take if reader is not None else None
        more = False  # frames left waiting after a full batch: no wait before the next one
        while not self._stop.is_set():
            if reader is not None and take is not None:
                if not more and select.select([reader.fd], [], [], 0.01)[0]:
                    reader.clear()  # first: a frame put after this signals again
                msg = take()
            else:
                msg = self._bus.recv(timeout=0.01)
            now = time.monotonic()
            more = False
            if self.paused:  # a gimbal that does not answer: what arrives meanwhile is lost
                while take is not None and msg is not None:
                    msg = take()
                continue
            for taken in range(1, self.BATCH + 1):  # the frames waiting, each answered as it completes
                if msg is None:
                    break
                if not msg.is_extended_id and not msg.is_error_frame:
                    replies = self.node.on_can(msg.arbitration_id, bytes(msg.data), now)
                    if replies and self.error_frames:  # a bit error / stuff error flagged by a controller
                        self._bus.send(self._can.Message(arbitration_id=0x088, is_error_frame=True, dlc=8,
                                                         data=bytes(8)))  # fmt: skip
                    self._send(replies)
                if taken == self.BATCH:  # (the rest: next turn, after the model's clock ticks)
                    more = True
                    break
                msg = take() if take is not None else self._bus.recv(0)
            self._send(self.node.tick(now))


class SlcanGimbal:
    """The gimbal behind an emulated SLCAN USB-CAN adapter (a :class:`~adapters.simio.StreamDevice`)."""

    def __init__(self, node: GimbalNode | None = None) -> None:
        self.node = node or GimbalNode()
        self.adapter = SlcanAdapterState()

    @property
    def model(self) -> GimbalModel:
        return self.node.model

    def on_bytes(self, data: bytes, now: float) -> bytes:
        answer, frames = self.adapter.feed(data)
        out = bytearray(answer)
        for arb_id, payload in frames:
            for tx_id, seg in self.node.on_can(arb_id, payload, now):
                out += format_frame(tx_id, seg)
        return bytes(out)

    def tick(self, now: float) -> bytes:
        if not self.adapter.is_open:
            return b""
        return b"".join(format_frame(i, d) for i, d in self.node.tick(now))


def main(argv: Sequence[str] | None = None) -> int:
    """``dji-gateway simulate rsdk``: a gimbal as an SLCAN adapter on a pty or a TCP port."""
    p = argparse.ArgumentParser(prog="dji-gateway simulate rsdk", description=__doc__.split("\n\n")[0])
    where = p.add_mutually_exclusive_group()
    where.add_argument("--tcp", type=int, metavar="PORT", help="listen on 127.0.0.1:PORT (0 = any free port)")
    where.add_argument("--pty", action="store_true", help="create a pseudo-terminal (default)")
    where.add_argument(
        "--can", metavar="INTERFACE:CHANNEL", help="sit on a python-can bus, e.g. socketcan:vcan0"
    )
    p.add_argument("--legacy-replies", action="store_true", help="answer in the pre-2.2.0.5 reply format")
    p.add_argument(
        "--legacy-angle-order",
        choices=("yaw_roll_pitch", "yaw_pitch_roll"),
        default="yaw_roll_pitch",
        help="with --legacy-replies: the angle order of 0x0E 0x02 replies (default the seed's)",
    )
    p.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="FAULT",
        help="answer badly, to see what the gateway does (repeatable): crc, truncate, duplicate, "
        "seq=N (replies carry seq+N), delay=SECONDS",
    )
    ns = p.parse_args(argv)
    try:
        faults = ReplyFaults.parse(ns.fault)
    except ValueError as exc:
        p.error(str(exc))
    model = GimbalModel(
        legacy_replies=ns.legacy_replies, legacy_angle_order=ns.legacy_angle_order, faults=faults
    )
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    runner: Any
    if ns.can:
        interface, _, channel = ns.can.partition(":")
        runner = GimbalCanSim(GimbalNode(model), interface=interface, channel=channel or "vcan0").start()
        print(f"gimbal simulator on python-can {interface}:{channel}", flush=True)
    elif ns.tcp is not None:
        runner = TcpEndpoint(SlcanGimbal(GimbalNode(model)), port=ns.tcp).start()
        print(f"gimbal simulator (SLCAN adapter) at {runner.url}", flush=True)
        print(f"gateway channel: interface=slcan channel={runner.url}", flush=True)
    else:
        runner = PtyEndpoint(SlcanGimbal(GimbalNode(model))).start()
        print(f"gimbal simulator (SLCAN adapter) at {runner.path}", flush=True)
        print(f"gateway channel: interface=slcan channel={runner.path}", flush=True)
    with contextlib.suppress(KeyboardInterrupt):
        stop.wait()
    runner.stop()
    print(f"gimbal simulator stopped: {model.photos} photo(s) taken", flush=True)  # what a test reads back
    return 0


def in_process(device: Any) -> tuple[InProcessSim, Any] | None:
    """``dji-gateway run --simulate`` (:mod:`adapters.families`): a gimbal entry on a ``virtual`` CAN
    interface gets a simulator on its channel; the entry is unchanged. Any other entry: None."""
    if device.interface != "virtual":
        return None
    sim = GimbalCanSim(interface="virtual", channel=device.channel).start()
    log.info(
        "simulated gimbal %s (payload %s) on virtual CAN %s", device.sn, device.payload_index, device.channel
    )
    return sim, device
