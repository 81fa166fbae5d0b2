"""Codec benchmark: frames/s decoded and encoded per protocol on one core, next to a naive baseline.

For each protocol (R SDK ``adapters/rsdk``, RoboMaster ``adapters/robomaster``, Onboard SDK
``adapters/osdk``) a realistic frame mix is encoded once with our table encoders, then measured:

* frame-layer decode: the stream decoder fed the way the link delivers bytes (R SDK: 8-byte CAN
  payloads through ``can.Reassembler``, and the whole buffer at once through ``protocol.Decoder``;
  serial protocols: 64-byte reads);
* full decode: the same input, each frame then decoded by its command table;
* encode: every frame of the mix built from its fields by the table encoder.

The baseline is what a first implementation looks like (seed 002's style): find the SOF, slice the
header, check both CRCs with the pure-Python ``crc`` package (``Calculator(Configuration(...),
optimized=True)``, configured with the protocols' published CRC models), unpack payloads with one
hand-written ``struct`` format per command; its encoder packs with ``struct`` and appends CRCs from
the same calculators. The baseline is fed the same bytes in the same chunks.

Every measurement is checked after timing (outside the timed region): the decoders must report
exactly the frames of the mix, in order, with the right identity (and, for full decode, the right
fields); the encoders must reproduce the mix byte for byte, ours and the baseline's alike (which
also proves the ``crc`` configurations equal our CRC engines). A failed check raises
``AssertionError``: a decoder that silently decodes nothing would otherwise look very fast.

Targets (issue #1): >= 200,000 R SDK frames/s through the frame layer and >= 20x the baseline. They
are applied to the frame-layer decode rows (the R SDK rate to both R SDK input paths; the ratio to
every protocol); full decode and encode rows print their ratio without a verdict. To hold those rows
to 20x as well, pass ``min_ratio=MIN_RATIO`` in their :class:`Case`.

Must not know MQTT or any I/O: it feeds bytes to sans-I/O codecs and reads a clock.
"""

from __future__ import annotations

import random
import struct
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from crc import Calculator, Configuration

from adapters.osdk import commands as osdk_cmd
from adapters.osdk import protocol as osdk_proto
from adapters.osdk import telemetry as osdk_tel
from adapters.robomaster import commands as rm_cmd
from adapters.robomaster import protocol as rm_proto
from adapters.rsdk import can as rsdk_can
from adapters.rsdk import commands as rsdk_cmd
from adapters.rsdk import protocol as rsdk_proto
from adapters.wire.stream import BadFrame
from bench.run import Config, Row, best_of

__all__ = ["MIN_RATIO", "RSDK_MIN_RATE", "run"]

RSDK_MIN_RATE = 200_000.0  # R SDK frames/s through the frame layer (a saturated CAN bus: ~2,000)
MIN_RATIO = 20.0  # against the crc-package baseline
SERIAL_CHUNK = 64  # bytes per UART read
CAN_RX_ID = rsdk_can.GIMBAL_TX_ID  # the host receives on 0x222

# frames per timed run: (ours, baseline). The baseline is 10-80x slower, so it runs on a prefix of the
# same mix (each run still ~0.1-0.2 s); rates are per frame, so the counts need not match.
SIZES: dict[str, tuple[int, int]] = {
    "rsdk": (20_000, 1_000),
    "robomaster": (21_000, 1_050),
    "osdk": (6_000, 400),
}
QUICK_SIZES: dict[str, tuple[int, int]] = {"rsdk": (2_000, 40), "robomaster": (2_100, 42), "osdk": (600, 20)}


def _progress(msg: str) -> None:
    print(f"  .. {msg}", file=sys.stderr, flush=True)


# =========================================================================== the baseline

# Seed 000 §3.2 Figure 40, exactly as published (the crc package takes init unreflected, as pycrc does).
RSDK_CRC16 = Configuration(
    width=16, polynomial=0x8005, init_value=0xC55C, final_xor_value=0, reverse_input=True, reverse_output=True
)
RSDK_CRC32 = Configuration(
    width=32,
    polynomial=0x04C11DB7,
    init_value=0xC55C0000,
    final_xor_value=0,
    reverse_input=True,
    reverse_output=True,
)
# Seed 002, verbatim (its names are wrong, its parameters right: see adapters/robomaster/protocol.py).
RM_MAXIM_DOW = Configuration(
    width=8, polynomial=0x31, init_value=0xFF, final_xor_value=0, reverse_input=True, reverse_output=True
)
RM_KERMIT = Configuration(
    width=16, polynomial=0x1021, init_value=0xFFFF, final_xor_value=0, reverse_input=True, reverse_output=True
)

crc16_dji = Calculator(RSDK_CRC16, optimized=True)
crc32_dji = Calculator(RSDK_CRC32, optimized=True)
crc8_rm = Calculator(RM_MAXIM_DOW, optimized=True)
crc16_rm = Calculator(RM_KERMIT, optimized=True)


class NaiveStruct:
    """A payload as a first implementation writes it: one ``struct`` format, names in order, bit
    fields split by hand. ``spec`` is ``"name:code ..."`` with struct counts (``command_list:16B``,
    ``resv:8s``); ``bits`` maps a carrier field to ``"part:width ..."`` from bit 0 upward."""

    def __init__(self, spec: str, bits: Mapping[str, str] | None = None) -> None:
        self.items: list[tuple[str, str, int]] = []
        fmt = "<"
        for tok in spec.split():
            name, code = tok.split(":")
            self.items.append((name, code[-1], int(code[:-1]) if len(code) > 1 else 1))
            fmt += code
        self.struct = struct.Struct(fmt)
        self.size = self.struct.size
        self.bits = {
            word: [(p.split(":")[0], int(p.split(":")[1])) for p in parts.split()]
            for word, parts in (bits or {}).items()
        }

    def pack(self, fields: Mapping[str, Any]) -> bytes:
        values: list[Any] = []
        for name, code, count in self.items:
            parts = self.bits.get(name)
            if parts:
                word, shift = 0, 0
                for part, width in parts:
                    word |= fields[part] << shift
                    shift += width
                values.append(word)
            elif count > 1 and code != "s":
                values.extend(fields[name])
            else:
                values.append(fields[name])
        return self.struct.pack(*values)

    def unpack(self, data: bytes) -> dict[str, Any]:
        values = self.struct.unpack(data)
        out: dict[str, Any] = {}
        i = 0
        for name, code, count in self.items:
            if count > 1 and code != "s":
                out[name] = list(values[i : i + count])
                i += count
                continue
            v = values[i]
            i += 1
            parts = self.bits.get(name)
            if parts is None:
                out[name] = v
                continue
            for part, width in parts:
                out[part] = v & ((1 << width) - 1)
                v >>= width
        return out


class NaiveDecoder:
    """Hunt the SOF, check the header CRC, wait for the announced length, check the frame CRC; on a
    failure drop one byte and hunt again. Remembers a checked header's length between feeds (any
    sane first implementation does; rechecking it per chunk would flatter the ratio)."""

    sof = 0
    header_len = 0

    def __init__(self) -> None:
        self.buf = bytearray()
        self.need = 0  # length of the frame whose header passed, 0 while hunting

    def check_header(self, header: bytes) -> int | None:
        raise NotImplementedError

    def check_frame(self, frame: bytes) -> dict[str, Any] | None:
        raise NotImplementedError

    def feed(self, chunk: bytes) -> list[dict[str, Any]]:
        buf = self.buf
        buf += chunk
        out: list[dict[str, Any]] = []
        while True:
            if not self.need:
                i = buf.find(self.sof)
                if i < 0:
                    buf.clear()
                    break
                if i:
                    del buf[:i]
                if len(buf) < self.header_len:
                    break
                n = self.check_header(bytes(buf[: self.header_len]))
                if n is None:
                    del buf[:1]
                    continue
                self.need = n
            if len(buf) < self.need:
                break
            frame = bytes(buf[: self.need])
            self.need = 0
            item = self.check_frame(frame)
            if item is None:
                del buf[:1]
                continue
            del buf[: len(frame)]
            out.append(item)
        return out


class NaiveDjiDecoder(NaiveDecoder):
    """R SDK / Onboard SDK frame: 12-byte header with CRC16 over bytes 0..9, CRC32 at the end."""

    sof = 0xAA
    header_len = 12

    def check_header(self, header: bytes) -> int | None:
        if crc16_dji.checksum(header[:10]) != int.from_bytes(header[10:12], "little"):
            return None
        word = int.from_bytes(header[1:3], "little")
        n = word & 0x3FF
        if word >> 10 or (n != 12 and n < 16):
            return None
        return n

    def check_frame(self, frame: bytes) -> dict[str, Any] | None:
        if len(frame) == 12:
            return self.make(frame, b"")
        if crc32_dji.checksum(frame[:-4]) != int.from_bytes(frame[-4:], "little"):
            return None
        return self.make(frame, frame[12:-4])

    def make(self, frame: bytes, data: bytes) -> dict[str, Any]:
        raise NotImplementedError


class NaiveRsdkDecoder(NaiveDjiDecoder):
    def make(self, frame: bytes, data: bytes) -> dict[str, Any]:
        return {
            "cmd_set": data[0],
            "cmd_id": data[1],
            "seq": int.from_bytes(frame[8:10], "little"),
            "is_reply": bool(frame[3] & 0x20),
            "payload": data[2:],
        }


class NaiveOsdkDecoder(NaiveDjiDecoder):
    def make(self, frame: bytes, data: bytes) -> dict[str, Any]:
        return {
            "session": frame[3] & 0x1F,
            "is_ack": bool(frame[3] & 0x20),
            "seq": int.from_bytes(frame[8:10], "little"),
            "data": data,
        }


class NaiveRmDecoder(NaiveDecoder):
    """RoboMaster 0xA5 frame: CRC8 over bytes 0..3 at byte 4, CRC16 over everything before it."""

    sof = 0xA5
    header_len = 5

    def check_header(self, header: bytes) -> int | None:
        if crc8_rm.checksum(header[:4]) != header[4]:
            return None
        n = header[1] | header[2] << 8
        return n + 9 if n <= rm_proto.REFEREE_MAX_DATA_LEN else None

    def check_frame(self, frame: bytes) -> dict[str, Any] | None:
        if crc16_rm.checksum(frame[:-2]) != int.from_bytes(frame[-2:], "little"):
            return None
        return {"seq": frame[3], "cmd_id": frame[5] | frame[6] << 8, "data": frame[7:-2]}


def naive_dji_frame(data: bytes, flags: int, seq: int) -> bytes:
    """R SDK / OSDK frame the naive way: header bytes, crc package CRC16, data, crc package CRC32."""
    n = 12 + len(data) + 4
    head = bytes([0xAA]) + n.to_bytes(2, "little") + bytes([flags, 0, 0, 0, 0]) + seq.to_bytes(2, "little")
    head += crc16_dji.checksum(head).to_bytes(2, "little")
    body = head + data
    return body + crc32_dji.checksum(body).to_bytes(4, "little")


def naive_rm_frame(cmd_id: int, data: bytes, seq: int) -> bytes:
    """Seed 002's ``send()`` with a cmd_id and seq (it hard-codes both to 0)."""
    header = b"\xa5" + len(data).to_bytes(2, byteorder="little") + seq.to_bytes(1, byteorder="little")
    crc8 = crc8_rm.checksum(header).to_bytes(1, byteorder="little")
    full_packet = header + crc8 + cmd_id.to_bytes(2, byteorder="little") + data
    return full_packet + crc16_rm.checksum(full_packet).to_bytes(2, byteorder="little")


# =========================================================================== shared measuring


@dataclass
class Mix:
    """One protocol's frame mix: wire frames (made by our encoder), what each must decode to, and the
    encode jobs that made them."""

    frames: list[bytes] = field(default_factory=list)
    idents: list[tuple[Any, ...]] = field(default_factory=list)  # frame-layer identity per frame
    decoded: list[tuple[str, Any]] = field(default_factory=list)  # (name, fields) per frame
    jobs: list[tuple[Any, ...]] = field(default_factory=list)  # encode job per frame


def _first_mismatch(got: Sequence[Any], want: Sequence[Any]) -> str:
    for i, (g, w) in enumerate(zip(got, want, strict=False)):
        if g != w:
            return f"frame {i}: got {g!r}, expected {w!r}"
    return f"got {len(got)} items, expected {len(want)}"


def _check(label: str, out: Sequence[Any], want: Sequence[Any], view: Callable[[Any], Any]) -> None:
    """Raise unless ``out`` holds exactly ``want`` (after ``view``), with no BadFrame among them."""
    bad = [x for x in out if isinstance(x, BadFrame)]
    if bad:
        raise AssertionError(
            f"{label}: {len(bad)} BadFrame(s), the first {bad[0].reason!r} ({bad[0].raw[:16].hex()})"
        )
    if len(out) != len(want):
        raise AssertionError(f"{label}: decoded {len(out)} frames, expected {len(want)}")
    got = [view(x) for x in out]
    if got != list(want):
        raise AssertionError(f"{label}: {_first_mismatch(got, want)}")


@dataclass
class Case:
    """One table row: our callable and optionally the baseline's, each with the output it must give."""

    case: str
    ours: Callable[[], list[Any]]
    want: Sequence[Any]
    view: Callable[[Any], Any]
    base: Callable[[], list[Any]] | None = None
    base_want: Sequence[Any] = ()
    base_view: Callable[[Any], Any] = lambda x: x
    min_rate: float | None = None
    min_ratio: float | None = None
    note: str = ""


def _measure(cfg: Config, group: str, c: Case) -> Row:
    seconds, out = best_of(c.ours, cfg.repeat, cfg.warmup)
    _check(f"{group} {c.case}", out, c.want, c.view)
    n = len(c.want)
    del out
    rate = n / seconds
    base_rate = base_n = None
    if c.base is not None:
        seconds, out = best_of(c.base, cfg.repeat, cfg.warmup)
        _check(f"{group} {c.case} (baseline)", out, c.base_want, c.base_view)
        base_n = len(c.base_want)
        base_rate = base_n / seconds
        del out
    min_ratio = c.min_ratio if c.base is not None else None
    row = Row(group, c.case, n, rate, base_rate, base_n, c.min_rate, min_ratio, note=c.note)
    ratio = f", {row.ratio:.1f}x" if row.ratio is not None else ""
    _progress(f"{group}: {c.case}: {rate:,.0f} frames/s{ratio}")
    return row


def _chunks(buf: bytes, size: int) -> list[bytes]:
    return [buf[i : i + size] for i in range(0, len(buf), size)]


def _stream(make: Callable[[], Any], chunks: Sequence[bytes]) -> Callable[[], list[Any]]:
    """Feed ``chunks`` to a fresh ``make()`` decoder, flush, return everything it reported."""

    def run() -> list[Any]:
        dec = make()
        feed = dec.feed
        out: list[Any] = []
        for c in chunks:
            out += feed(c)
        out += dec.flush()
        return out

    return run


def _stream_naive(make: Callable[[], NaiveDecoder], chunks: Sequence[bytes]) -> Callable[[], list[Any]]:
    def run() -> list[Any]:
        feed = make().feed
        out: list[Any] = []
        for c in chunks:
            out += feed(c)
        return out

    return run


def _stream_decode(
    make: Callable[[], Any], chunks: Sequence[bytes], decode: Callable[[Any], Any]
) -> Callable[[], list[Any]]:
    """Like :func:`_stream`, each frame decoded by ``decode`` as it comes out (BadFrames passed on)."""

    def run() -> list[Any]:
        dec = make()
        feed = dec.feed
        out: list[Any] = []
        add = out.append
        for c in chunks:
            for f in feed(c):
                add(f if isinstance(f, BadFrame) else decode(f))
        for f in dec.flush():
            add(f if isinstance(f, BadFrame) else decode(f))
        return out

    return run


def _stream_naive_decode(
    make: Callable[[], NaiveDecoder], chunks: Sequence[bytes], decode: Callable[[dict[str, Any]], Any]
) -> Callable[[], list[Any]]:
    def run() -> list[Any]:
        feed = make().feed
        out: list[Any] = []
        add = out.append
        for c in chunks:
            for f in feed(c):
                add(decode(f))
        return out

    return run


def _encoder(encode: Callable[..., bytes], jobs: Sequence[tuple[Any, ...]]) -> Callable[[], list[bytes]]:
    def run() -> list[bytes]:
        return [encode(*job) for job in jobs]

    return run


def _f32(rng: random.Random, lo: float, hi: float) -> float:
    """A value exactly representable as f32 (multiples of 1/64), so decoded fields compare equal."""
    return rng.randint(int(lo * 64), int(hi * 64)) / 64


def _sizes(cfg: Config, protocol: str) -> tuple[int, int]:
    return (QUICK_SIZES if cfg.quick else SIZES)[protocol]


# =========================================================================== R SDK

RSDK_NAIVE: dict[tuple[str, bool], tuple[int, int, int, NaiveStruct]] = {
    # (name, is_reply) -> cmd_set, cmd_id, CmdType, payload
    ("position_control", False): (
        0x0E,
        0x00,
        0x03,
        NaiveStruct("yaw_angle:h roll_angle:h pitch_angle:h ctrl_byte:B time_for_action:B"),
    ),
    ("position_control", True): (0x0E, 0x00, 0x00, NaiveStruct("return_code:B")),
    ("param_push", False): (
        0x0E,
        0x08,
        0x00,
        NaiveStruct(
            "ctrl_byte:B yaw_angle:h roll_angle:h pitch_angle:h yaw_joint_angle:h roll_joint_angle:h "
            "pitch_joint_angle:h pitch_max:B pitch_min:B yaw_max:B yaw_min:B roll_max:B roll_min:B "
            "pitch_stiffness:B yaw_stiffness:B roll_stiffness:B"
        ),
    ),
}
RSDK_NAIVE_BY_KEY = {(cs, ci, reply): (name, ns) for (name, reply), (cs, ci, _, ns) in RSDK_NAIVE.items()}


def rsdk_naive_encode(name: str, seq: int, fields: Mapping[str, Any], reply: bool) -> bytes:
    cmd_set, cmd_id, cmd_type, ns = RSDK_NAIVE[(name, reply)]
    return naive_dji_frame(bytes([cmd_set, cmd_id]) + ns.pack(fields), cmd_type | (0x20 if reply else 0), seq)


def rsdk_naive_decode(f: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    name, ns = RSDK_NAIVE_BY_KEY[(f["cmd_set"], f["cmd_id"], f["is_reply"])]
    return name, ns.unpack(f["payload"])


def rsdk_encode(name: str, seq: int, fields: Mapping[str, Any], reply: bool) -> bytes:
    return rsdk_cmd.encode_command(name, seq, fields, reply=reply)


def rsdk_mix(n: int) -> Mix:
    """Host-side traffic of a gimbal under position control with parameter push on: every command is
    answered (latest reply format, 19 bytes), and two 40-byte 0E 08 pushes arrive per command.
    Commands are 26 bytes. Both directions go into one stream: a decoder does not care."""
    rng = random.Random(0x0E00)
    mix = Mix()
    seq = 0x1122
    while len(mix.jobs) < n:
        seq = (seq + 1) & 0xFFFF
        cmd = {
            "yaw_angle": rng.randint(-1800, 1800),
            "roll_angle": rng.randint(-300, 300),
            "pitch_angle": rng.randint(-560, 1460),
            "ctrl_byte": 0x01,
            "time_for_action": rng.randint(5, 30),
        }
        mix.jobs.append(("position_control", seq, cmd, False))
        mix.jobs.append(("position_control", seq, {"return_code": 0}, True))
        for _ in range(2):
            push = {
                "ctrl_byte": 0x07,
                "yaw_angle": rng.randint(-1800, 1800),
                "roll_angle": rng.randint(-300, 300),
                "pitch_angle": rng.randint(-560, 1460),
                "yaw_joint_angle": rng.randint(-1800, 1800),
                "roll_joint_angle": rng.randint(-300, 300),
                "pitch_joint_angle": rng.randint(-560, 1460),
                "pitch_max": 145,
                "pitch_min": 55,
                "yaw_max": 179,
                "yaw_min": 179,
                "roll_max": 30,
                "roll_min": 30,
                "pitch_stiffness": rng.randint(0, 100),
                "yaw_stiffness": rng.randint(0, 100),
                "roll_stiffness": rng.randint(0, 100),
            }
            seq = (seq + 1) & 0xFFFF
            mix.jobs.append(("param_push", seq, push, False))
    del mix.jobs[n:]
    for name, seq, fields, reply in mix.jobs:
        frame = rsdk_encode(name, seq, fields, reply)
        mix.frames.append(frame)
        mix.idents.append((frame[12], frame[13], seq, reply, frame[14:-4]))
        mix.decoded.append((name, fields))
    return mix


def _rsdk_ident(f: rsdk_proto.Frame) -> tuple[Any, ...]:
    return (f.cmd_set, f.cmd_id, f.seq, f.is_reply, f.payload)


def _rsdk_naive_ident(f: dict[str, Any]) -> tuple[Any, ...]:
    return (f["cmd_set"], f["cmd_id"], f["seq"], f["is_reply"], f["payload"])


def rsdk_cases(cfg: Config) -> list[Case]:
    n, nb = _sizes(cfg, "rsdk")
    mix = rsdk_mix(n)
    base = rsdk_mix(nb)
    segs = [seg for fr in mix.frames for seg in rsdk_can.segment(fr, CAN_RX_ID)]
    base_segs = [seg for fr in base.frames for seg in rsdk_can.segment(fr, CAN_RX_ID)]
    whole = b"".join(mix.frames)
    base_whole = b"".join(base.frames)

    def reassemble() -> list[Any]:
        r = rsdk_can.Reassembler(CAN_RX_ID)
        feed = r.feed
        out: list[Any] = []
        for arb, data in segs:
            out += feed(arb, data)
        out += r.flush()
        return out

    def naive_can() -> list[Any]:
        # the naive host filters on the arbitration id and appends each payload to its buffer
        feed = NaiveRsdkDecoder().feed
        out: list[Any] = []
        for arb, data in base_segs:
            if arb == CAN_RX_ID:
                out += feed(data)
        return out

    def reassemble_decode() -> list[Any]:
        r = rsdk_can.Reassembler(CAN_RX_ID)
        feed = r.feed
        decode = rsdk_cmd.decode_message
        out: list[Any] = []
        add = out.append
        for arb, data in segs:
            for f in feed(arb, data):
                add(f if isinstance(f, BadFrame) else decode(f))
        out += r.flush()
        return out

    def naive_can_decode() -> list[Any]:
        feed = NaiveRsdkDecoder().feed
        out: list[Any] = []
        add = out.append
        for arb, data in base_segs:
            if arb == CAN_RX_ID:
                for f in feed(data):
                    add(rsdk_naive_decode(f))
        return out

    def msg_view(m: rsdk_cmd.Message) -> tuple[str, Any]:
        return (m.name, m.fields)

    can_note = (
        f"{len(segs) / n:.2f} CAN frames per R SDK frame; a regular frame costs the Reassembler an append "
        "per CAN frame and one parse (the general path, decoder plus restart rule, only for irregular ones)"
    )
    return [
        Case(
            "frame decode: CAN 8-byte payloads -> can.Reassembler",
            reassemble,
            mix.idents,
            _rsdk_ident,
            naive_can,
            base.idents,
            _rsdk_naive_ident,
            min_rate=RSDK_MIN_RATE,
            min_ratio=MIN_RATIO,
            note=can_note,
        ),
        Case(
            "frame decode: whole buffer -> protocol.Decoder",
            _stream(rsdk_proto.Decoder, [whole]),
            mix.idents,
            _rsdk_ident,
            _stream_naive(NaiveRsdkDecoder, [base_whole]),
            base.idents,
            _rsdk_naive_ident,
            min_rate=RSDK_MIN_RATE,
            min_ratio=MIN_RATIO,
        ),
        Case(
            "frame decode: 8-byte chunks -> protocol.Decoder",
            _stream(rsdk_proto.Decoder, _chunks(whole, 8)),
            mix.idents,
            _rsdk_ident,
            note="diagnostic, no target: the stream decoder alone at CAN granularity (chunks span frames)",
        ),
        Case(
            "full decode: CAN -> Reassembler -> commands.decode_message",
            reassemble_decode,
            mix.decoded,
            msg_view,
            naive_can_decode,
            base.decoded,
            lambda x: x,
        ),
        Case(
            "encode: commands.encode_command",
            _encoder(rsdk_encode, mix.jobs),
            mix.frames,
            lambda x: x,
            _encoder(rsdk_naive_encode, base.jobs),
            base.frames,
            lambda x: x,
        ),
    ]


# =========================================================================== RoboMaster referee

RM_NAIVE: dict[str, tuple[int, NaiveStruct]] = {
    # 2026 season (V1.2.0) sizes: 13, 14, 12 bytes
    "robot_status": (
        0x0201,
        NaiveStruct(
            "robot_id:B robot_level:B current_HP:H maximum_HP:H shooter_barrel_cooling_value:H "
            "shooter_barrel_heat_limit:H chassis_power_limit:H power_output:B",
            {
                "power_output": "power_management_gimbal_output:1 power_management_chassis_output:1 "
                "power_management_shooter_output:1 power_management_reserved:5"
            },
        ),
    ),
    "power_heat_data": (
        0x0202,
        NaiveStruct(
            "reserved_1:H reserved_2:H reserved_3:I buffer_energy:H shooter_17mm_barrel_heat:H "
            "shooter_42mm_barrel_heat:H"
        ),
    ),
    "robot_pos": (0x0203, NaiveStruct("x:f y:f angle:f")),
}
RM_NAIVE_BY_ID = {cmd_id: (name, ns) for name, (cmd_id, ns) in RM_NAIVE.items()}


def rm_naive_encode(name: str, seq: int, fields: Mapping[str, Any]) -> bytes:
    cmd_id, ns = RM_NAIVE[name]
    return naive_rm_frame(cmd_id, ns.pack(fields), seq)


def rm_naive_decode(f: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    name, ns = RM_NAIVE_BY_ID[f["cmd_id"]]
    return name, ns.unpack(f["data"])


def rm_encode(name: str, seq: int, fields: Mapping[str, Any]) -> bytes:
    return rm_cmd.encode_message(name, fields, seq=seq)


def rm_mix(n: int) -> Mix:
    """What the referee system's main control module sends a robot: 0x0202 power/heat, 0x0201 robot
    status and 0x0203 position in the proportion 5:1:1 (V1.6 send rates 50/10/10 Hz). 2026 layouts."""
    rng = random.Random(0x0201)
    mix = Mix()
    seq = 0
    order = ["power_heat_data", "power_heat_data", "robot_status", "power_heat_data"]
    order += ["power_heat_data", "robot_pos", "power_heat_data"]
    hp = 400
    while len(mix.jobs) < n:
        for name in order:
            seq = (seq + 1) & 0xFF
            if name == "robot_status":
                hp = max(0, hp - rng.randint(0, 10)) or 400
                fields: dict[str, Any] = {
                    "robot_id": 3,
                    "robot_level": rng.randint(1, 10),
                    "current_HP": hp,
                    "maximum_HP": 400,
                    "shooter_barrel_cooling_value": 40,
                    "shooter_barrel_heat_limit": 240,
                    "chassis_power_limit": 80,
                    "power_management_gimbal_output": 1,
                    "power_management_chassis_output": 1,
                    "power_management_shooter_output": 1,
                    "power_management_reserved": 0,
                }
            elif name == "power_heat_data":
                fields = {
                    "reserved_1": 0,
                    "reserved_2": 0,
                    "reserved_3": 0,
                    "buffer_energy": rng.randint(0, 60),
                    "shooter_17mm_barrel_heat": rng.randint(0, 240),
                    "shooter_42mm_barrel_heat": 0,
                }
            else:
                fields = {"x": _f32(rng, 0, 28), "y": _f32(rng, 0, 15), "angle": _f32(rng, 0, 360)}
            mix.jobs.append((name, seq, fields))
    del mix.jobs[n:]
    for name, seq, fields in mix.jobs:
        frame = rm_encode(name, seq, fields)
        mix.frames.append(frame)
        mix.idents.append((seq, RM_NAIVE[name][0], frame[7:-2]))
        mix.decoded.append((name, fields))
    return mix


def rm_cases(cfg: Config) -> list[Case]:
    n, nb = _sizes(cfg, "robomaster")
    mix, base = rm_mix(n), rm_mix(nb)
    chunks = _chunks(b"".join(mix.frames), SERIAL_CHUNK)
    base_chunks = _chunks(b"".join(base.frames), SERIAL_CHUNK)

    def make() -> rm_proto.Decoder:
        return rm_proto.Decoder(rm_proto.REFEREE_MAX_DATA_LEN)

    def ident(f: rm_proto.Frame) -> tuple[Any, ...]:
        return (f.seq, f.cmd_id, f.data)

    def naive_ident(f: dict[str, Any]) -> tuple[Any, ...]:
        return (f["seq"], f["cmd_id"], f["data"])

    return [
        Case(
            f"frame decode: {SERIAL_CHUNK}-byte reads -> protocol.Decoder",
            _stream(make, chunks),
            mix.idents,
            ident,
            _stream_naive(NaiveRmDecoder, base_chunks),
            base.idents,
            naive_ident,
            min_ratio=MIN_RATIO,
        ),
        Case(
            "full decode: ... -> commands.decode_message",
            _stream_decode(make, chunks, rm_cmd.decode_message),
            mix.decoded,
            lambda m: (m.name, m.fields),
            _stream_naive_decode(NaiveRmDecoder, base_chunks, rm_naive_decode),
            base.decoded,
        ),
        Case(
            "encode: commands.encode_message",
            _encoder(rm_encode, mix.jobs),
            mix.frames,
            lambda x: x,
            _encoder(rm_naive_encode, base.jobs),
            base.frames,
        ),
    ]


# =========================================================================== Onboard SDK

# A typical new-firmware broadcast: attitude, motion, position, gimbal, status, battery and control
# device; no GPS detail, RTK, magnetometer or RC (those are usually off or at 1-10 Hz).
OSDK_ITEMS = (
    "timestamp",
    "quaternion",
    "acceleration",
    "velocity",
    "angular_rate",
    "position",
    "gimbal",
    "status",
    "battery",
    "control_device",
)
OSDK_BITMAP = sum(1 << it.bit for it in osdk_tel.NEW_ITEMS if it.name in OSDK_ITEMS)

# The baseline knows the items of the mix only (bit -> name, layout), in bit order.
OSDK_NAIVE_ITEMS: list[tuple[int, str, NaiveStruct]] = [
    (0, "timestamp", NaiveStruct("time_ms:I time_ns:I sync_time_2p5ms:I sync_tag:H sync_flag:B")),
    (1, "quaternion", NaiveStruct("w:f x:f y:f z:f")),
    (2, "acceleration", NaiveStruct("x:f y:f z:f")),
    (3, "velocity", NaiveStruct("x:f y:f z:f info:B", {"info": "health:1 reserved:7"})),
    (4, "angular_rate", NaiveStruct("x:f y:f z:f")),
    (
        5,
        "position",
        NaiveStruct(
            "latitude:d longitude:d altitude:f height:f health:B obstacle_down:f obstacle_front:f "
            "obstacle_right:f obstacle_back:f obstacle_left:f obstacle_up:f obstacle_health:B",
            {
                "obstacle_health": "down_health:1 front_health:1 right_health:1 back_health:1 left_health:1 "
                "up_health:1 obstacle_reserved:2"
            },
        ),
    ),
    (
        10,
        "gimbal",
        NaiveStruct(
            "roll:f pitch:f yaw:f limit:B", {"limit": "pitch_limit:1 roll_limit:1 yaw_limit:1 reserved:5"}
        ),
    ),
    (11, "status", NaiveStruct("flight:B display_mode:B gear:B error:B")),
    (12, "battery", NaiveStruct("capacity:I voltage:i current:i percentage:B")),
    (
        13,
        "control_device",
        NaiveStruct(
            "control_mode:B status:B", {"status": "device_status:3 flight_status:1 vrc_status:1 reserved:3"}
        ),
    ),
]
OSDK_WAYPOINT = NaiveStruct(
    "index:B latitude:d longitude:d altitude:f damping_dis:f tgt_yaw:h tgt_gimbal_pitch:h turn_mode:B "
    "resv:8s has_action:B action_time_limit:H action:B command_list:16B command_param:16h",
    {"action": "action_num:4 action_rpt:4"},
)
OSDK_WP_ACK = NaiveStruct("ack:B index:B")


def osdk_naive_flight_pack(fields: Mapping[str, Any]) -> bytes:
    bitmap = 0
    body = b""
    for bit, name, ns in OSDK_NAIVE_ITEMS:
        if name in fields:
            bitmap |= 1 << bit
            body += ns.pack(fields[name])
    return bitmap.to_bytes(2, "little") + body


def osdk_naive_flight_unpack(payload: bytes) -> dict[str, Any]:
    bitmap = int.from_bytes(payload[:2], "little")
    out: dict[str, Any] = {"bitmap": bitmap}
    pos = 2
    for bit, name, ns in OSDK_NAIVE_ITEMS:
        if bitmap >> bit & 1:
            out[name] = ns.unpack(payload[pos : pos + ns.size])
            pos += ns.size
    return out


# (cmd_set, cmd_id) -> name, pack, unpack
OSDK_NAIVE: dict[tuple[int, int], tuple[str, Callable[..., bytes], Callable[[bytes], dict[str, Any]]]] = {
    (0x02, 0x00): ("flight_data_push", osdk_naive_flight_pack, osdk_naive_flight_unpack),
    (0x03, 0x11): ("wp_upload", OSDK_WAYPOINT.pack, OSDK_WAYPOINT.unpack),
}
OSDK_NAIVE_BY_NAME = {name: key for key, (name, _, _) in OSDK_NAIVE.items()}
OSDK_NAIVE_ACKS = {"wp_upload": OSDK_WP_ACK}


def osdk_encode(kind: str, name: str, session: int, seq: int, fields: Mapping[str, Any]) -> bytes:
    if kind == "ack":
        return osdk_proto.encode_ack(session, seq, osdk_cmd.encode_ack_payload(name, fields))
    spec = osdk_cmd.spec_for(name)
    return osdk_proto.encode_command(
        spec.cmd_set, spec.cmd_id, osdk_cmd.encode_request(name, fields), session, seq
    )


def osdk_naive_encode(kind: str, name: str, session: int, seq: int, fields: Mapping[str, Any]) -> bytes:
    if kind == "ack":
        return naive_dji_frame(OSDK_NAIVE_ACKS[name].pack(fields), session | 0x20, seq)
    cmd_set, cmd_id = OSDK_NAIVE_BY_NAME[name]
    return naive_dji_frame(bytes([cmd_set, cmd_id]) + OSDK_NAIVE[(cmd_set, cmd_id)][1](fields), session, seq)


def osdk_mix(n: int) -> tuple[Mix, dict[tuple[int, int], str]]:
    """An onboard computer uploading a waypoint mission while telemetry streams: per uploaded waypoint
    (0x03 0x11, 90-byte payload, ACK-required session) its ACK comes back ({ack, index}, matched by
    session and seq) and two 0x02 0x00 flight-data pushes arrive (:data:`OSDK_BITMAP`, 152-byte payload).
    Returns the mix and the sender's (session, seq) -> command map that ACK decoding needs."""
    rng = random.Random(0x0211)
    mix = Mix()
    pending: dict[tuple[int, int], str] = {}
    seq = fc_seq = 0
    k = 0
    lat, lon, t_ms = 0.3967, 1.9933, 1_000_000
    while len(mix.jobs) < n:
        for step in ("push", "upload", "ack", "push"):
            if step == "push":
                fc_seq = (fc_seq + 1) & 0xFFFF
                t_ms += 20
                items: dict[str, Any] = {
                    "timestamp": {
                        "time_ms": t_ms,
                        "time_ns": t_ms * 1_000_000 & 0xFFFFFFFF,
                        "sync_time_2p5ms": 0,
                        "sync_tag": 0,
                        "sync_flag": 0,
                    },
                    "quaternion": {a: _f32(rng, -1, 1) for a in ("w", "x", "y", "z")},
                    "acceleration": {a: _f32(rng, -2, 2) for a in ("x", "y", "z")},
                    "velocity": {
                        **{a: _f32(rng, -15, 15) for a in ("x", "y", "z")},
                        "health": 1,
                        "reserved": 0,
                    },
                    "angular_rate": {a: _f32(rng, -3, 3) for a in ("x", "y", "z")},
                    "position": {
                        "latitude": lat + rng.random() * 1e-5,
                        "longitude": lon + rng.random() * 1e-5,
                        "altitude": _f32(rng, 40, 140),
                        "height": _f32(rng, 0, 100),
                        "health": 5,
                        **{
                            f"obstacle_{d}": _f32(rng, 0, 3000)
                            for d in ("down", "front", "right", "back", "left", "up")
                        },
                        **{f"{d}_health": 1 for d in ("down", "front", "right", "back", "left", "up")},
                        "obstacle_reserved": 0,
                    },
                    "gimbal": {
                        "roll": _f32(rng, -5, 5),
                        "pitch": _f32(rng, -90, 0),
                        "yaw": _f32(rng, -180, 180),
                        "pitch_limit": 0,
                        "roll_limit": 0,
                        "yaw_limit": 0,
                        "reserved": 0,
                    },
                    "status": {"flight": 2, "display_mode": 17, "gear": 0, "error": 0},
                    "battery": {
                        "capacity": 5000,
                        "voltage": 22800,
                        "current": -rng.randint(5000, 25000),
                        "percentage": 80,
                    },
                    "control_device": {
                        "control_mode": 2,
                        "device_status": 2,
                        "flight_status": 1,
                        "vrc_status": 0,
                        "reserved": 0,
                    },
                }
                mix.jobs.append(("push", "flight_data_push", 0, fc_seq, items))
                mix.decoded.append(("flight_data_push", {"bitmap": OSDK_BITMAP, **items}))
            elif step == "upload":
                seq = (seq + 1) & 0xFFFF
                session = 2 + k % 30
                wp = {
                    "index": k % 100,
                    "latitude": lat + rng.random() * 1e-4,
                    "longitude": lon + rng.random() * 1e-4,
                    "altitude": _f32(rng, 20, 120),
                    "damping_dis": 0.5,
                    "tgt_yaw": rng.randint(-180, 180),
                    "tgt_gimbal_pitch": rng.randint(-90, 0),
                    "turn_mode": 0,
                    "resv": bytes(8),
                    "has_action": 1,
                    "action_time_limit": 10,
                    "action_num": 1,
                    "action_rpt": 1,
                    "command_list": [1] + [0] * 15,
                    "command_param": [1000] + [0] * 15,
                }
                pending[(session, seq)] = "wp_upload"
                mix.jobs.append(("command", "wp_upload", session, seq, wp))
                mix.decoded.append(("wp_upload", wp))
            else:
                ack = {"ack": 0, "index": k % 100}
                mix.jobs.append(("ack", "wp_upload", 2 + k % 30, seq, ack))
                mix.decoded.append(("wp_upload ack", ack))
                k += 1
    del mix.jobs[n:], mix.decoded[n:]
    for job in mix.jobs:
        frame = osdk_encode(*job)
        kind, _, session, seq_, _ = job
        mix.frames.append(frame)
        mix.idents.append((session, kind == "ack", seq_, frame[12:-4]))
    return mix, pending


def osdk_cases(cfg: Config) -> list[Case]:
    n, nb = _sizes(cfg, "osdk")
    (mix, pending), (base, base_pending) = osdk_mix(n), osdk_mix(nb)
    chunks = _chunks(b"".join(mix.frames), SERIAL_CHUNK)
    base_chunks = _chunks(b"".join(base.frames), SERIAL_CHUNK)

    def decode(f: osdk_proto.Frame) -> osdk_cmd.Message:
        # the gateway matches an ACK to its command by (session, seq) (SessionTable.on_ack), then decodes
        if f.is_ack:
            return osdk_cmd.decode_ack(pending[(f.session, f.seq)], f.data)
        return osdk_cmd.decode_request(f.data[0], f.data[1], f.data[2:])

    def naive_decode(f: dict[str, Any]) -> tuple[str, dict[str, Any]]:
        if f["is_ack"]:
            name = base_pending[(f["session"], f["seq"])]
            return f"{name} ack", OSDK_NAIVE_ACKS[name].unpack(f["data"])
        data = f["data"]
        name, _, unpack = OSDK_NAIVE[(data[0], data[1])]
        return name, unpack(data[2:])

    def ident(f: osdk_proto.Frame) -> tuple[Any, ...]:
        return (f.session, f.is_ack, f.seq, f.data)

    def naive_ident(f: dict[str, Any]) -> tuple[Any, ...]:
        return (f["session"], f["is_ack"], f["seq"], f["data"])

    def msg_view(m: osdk_cmd.Message) -> tuple[str, Any]:
        return (f"{m.name} ack" if m.is_reply else m.name, m.fields)

    return [
        Case(
            f"frame decode: {SERIAL_CHUNK}-byte reads -> protocol.Decoder",
            _stream(osdk_proto.Decoder, chunks),
            mix.idents,
            ident,
            _stream_naive(NaiveOsdkDecoder, base_chunks),
            base.idents,
            naive_ident,
            min_ratio=MIN_RATIO,
        ),
        Case(
            "full decode: ... -> decode_request / decode_ack",
            _stream_decode(osdk_proto.Decoder, chunks, decode),
            mix.decoded,
            msg_view,
            _stream_naive_decode(NaiveOsdkDecoder, base_chunks, naive_decode),
            base.decoded,
        ),
        Case(
            "encode: encode_request + encode_command / encode_ack",
            _encoder(osdk_encode, mix.jobs),
            mix.frames,
            lambda x: x,
            _encoder(osdk_naive_encode, base.jobs),
            base.frames,
        ),
    ]


# =========================================================================== suite entry

PROTOCOLS: list[tuple[str, Callable[[Config], list[Case]]]] = [
    ("rsdk", rsdk_cases),
    ("robomaster", rm_cases),
    ("osdk", osdk_cases),
]


def run(cfg: Config) -> list[Row]:
    """The ``codecs`` suite: one row per (protocol, measurement)."""
    rows: list[Row] = []
    for group, cases in PROTOCOLS:
        for case in cases(cfg):
            rows.append(_measure(cfg, group, case))
    return rows
