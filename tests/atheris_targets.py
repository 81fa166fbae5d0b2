"""Coverage-guided fuzz targets (atheris, libFuzzer for Python) for every byte and JSON inbound path.

The hypothesis suite (test_fuzz_decoders, test_fuzz_inbound) draws inputs from what we thought of;
these targets let libFuzzer grow its own corpus from the branches it reaches, so a path the strategies
never thought of still gets inputs. They reuse that suite's seed frames, fake device and notion of a
readable request, so the two cannot drift apart:

- stream decoders (``rsdk``, ``osdk``, ``robomaster``) and the R SDK CAN reassembler (``rsdk-can``): the
  input is fed in chunks (sizes, CAN ids and mid-stream flushes chosen by ``FuzzedDataProvider`` from the
  input's tail; optionally with every CRC repaired first), then flushed: nothing raises, nothing stays
  pending, and the events tile the bytes fed, in order (each byte in exactly one frame or ``BadFrame``);
- ``services``: the input is a raw payload on the gateway's ``services`` topic, handled by the real
  dispatcher (no broker: the function the MQTT thread calls): no handler exception, a readable tid gets
  exactly one reply with that tid and a valid result code, everything published is JSON without NaN;
- ``kmz``: a wayline file (a KMZ, or the WPML inside one) read, parsed and mapped onto Onboard SDK
  missions: only the documented refusals (314xxx with a reason) come out;
- ``drc``: the input is a DRC session with payload authority, one ``drc/down`` payload per line:
  nothing raises, replies are JSON, the set-point stays finite, and an emergency stop holds a zero
  set-point (no device driven otherwise) until the sticks restart at seq 0.

Run one (``-runs``, ``-seed``, ``-max_len`` … are libFuzzer's flags; a directory is a corpus, a file an
input to replay, e.g. a ``crash-…`` artifact)::

    python -m tests.atheris_targets rsdk -runs=100000 -seed=1 CORPUS_DIR
    python -m tests.atheris_targets services crash-0123abcd

This module imports only the standard library at the top: the project's packages are imported by
the chosen target inside ``atheris.instrument_imports`` so that their code is instrumented for coverage
(a module imported before that would run blind). tests/test_fuzz_atheris.py runs every target.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import os
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["SEALERS", "TARGETS", "Target", "main", "pack_can", "pack_stream"]

INSTRUMENTED = ["adapters", "gateway", "schemas"]
OneInput = Callable[[bytes], None]


# -- input formats ---------------------------------------------------------------------------------
# FuzzedDataProvider takes integers from the end of the input and bytes from the front, so an input is
# "stream bytes … control bytes (last one first)". pack_* build such inputs for the seed corpus.
#
# Every frame carries CRCs that random mutations almost never keep right, which would leave everything
# behind the CRC checks to the seeds. When the first control byte says "seal", the target rewrites the
# CRCs of every frame it can find in the stream (left to right, as the decoder would meet them) before
# feeding it, so libFuzzer can explore header fields, lengths and flags behind valid CRCs.

_CHUNK_MASK = 0x3F  # stream control byte: chunk size = 1 + (ctl & 0x3F); flush after it; seal (1st only)
_FLUSH = 0x40
_SEAL = 0x80
_CAN_FOREIGN = 0x10  # CAN control byte: length = ctl & 0x0F (10..15 read as 8), foreign id, flush after,
_CAN_FLUSH = 0x20  # seal the gimbal id's bytes (first control byte only)
_CAN_SEAL = 0x40


def pack_stream(stream: bytes, chunk: int, *, seal: bool = False) -> bytes:
    """The decoder-target input that feeds ``stream`` in chunks of ``chunk`` (1..64) bytes."""
    if not 1 <= chunk <= _CHUNK_MASK + 1:
        raise ValueError("chunk is 1..64")
    ctl = bytearray([chunk - 1]) * -(-len(stream) // chunk)
    if ctl and seal:
        ctl[-1] |= _SEAL
    return stream + bytes(ctl)


def pack_can(can_frames: list[bytes], *, seal: bool = False) -> bytes:
    """The ``rsdk-can`` input that feeds these CAN payloads (each 0..9 bytes) on the gimbal's id."""
    if any(len(p) > 9 for p in can_frames):
        raise ValueError("a CAN payload here is 0..9 bytes")
    ctl = bytearray(reversed([len(p) for p in can_frames]))
    if ctl and seal:
        ctl[-1] |= _CAN_SEAL
    return b"".join(can_frames) + bytes(ctl)


def _chunks(data: bytes) -> tuple[list[tuple[bytes, bool]], bool]:
    """((chunk, flush after), …) and whether to seal."""
    import atheris

    fdp = atheris.FuzzedDataProvider(data)
    out: list[tuple[bytes, bool]] = []
    seal = False
    while fdp.remaining_bytes():
        ctl = fdp.ConsumeIntInRange(0, 255)
        seal = seal or (not out and bool(ctl & _SEAL))
        out.append((fdp.ConsumeBytes(1 + (ctl & _CHUNK_MASK)), bool(ctl & _FLUSH)))
    return out, seal


def _can_frames(data: bytes) -> tuple[list[tuple[bytes, bool, bool]], bool]:
    """((payload, on a foreign id, flush after), …) and whether to seal."""
    import atheris

    fdp = atheris.FuzzedDataProvider(data)
    out: list[tuple[bytes, bool, bool]] = []
    seal = False
    while fdp.remaining_bytes():
        ctl = fdp.ConsumeIntInRange(0, 255)
        seal = seal or (not out and bool(ctl & _CAN_SEAL))
        n = ctl & 0x0F
        out.append((fdp.ConsumeBytes(8 if n > 9 else n), bool(ctl & _CAN_FOREIGN), bool(ctl & _CAN_FLUSH)))
    return out, seal


def _resplit(pieces: list[bytes], sealer: Callable[[bytearray], None]) -> list[bytes]:
    """``pieces`` with the CRCs of their concatenation sealed, cut at the same places."""
    buf = bytearray(b"".join(pieces))
    sealer(buf)
    out, i = [], 0
    for p in pieces:
        out.append(bytes(buf[i : i + len(p)]))
        i += len(p)
    return out


def _seal_dji(buf: bytearray) -> None:
    """R SDK / Onboard SDK: header CRC16 at every SOF, CRC32 of every frame whose length fits."""
    from adapters.wire.dji_frame import CRC32_LEN, HEADER_LEN, MAX_FRAME_LEN, SOF, header_crc16, seal_crc32

    i = 0
    while i + HEADER_LEN <= len(buf):
        if buf[i] != SOF:
            i += 1
            continue
        crc = header_crc16(buf[i : i + HEADER_LEN])
        buf[i + 10], buf[i + 11] = crc & 0xFF, crc >> 8
        n = (buf[i + 1] | buf[i + 2] << 8) & MAX_FRAME_LEN
        if n < HEADER_LEN + CRC32_LEN or i + n > len(buf):
            i += 1
            continue
        frame = buf[i : i + n]
        seal_crc32(frame)
        buf[i : i + n] = frame
        i += n


def _seal_rm(buf: bytearray) -> None:
    """RoboMaster: header CRC8 at every SOF, CRC16 of every frame whose length fits."""
    from adapters.robomaster.protocol import FRAME_OVERHEAD, HEADER_LEN, SOF
    from adapters.wire.crc import crc8_rm, crc16_rm

    i = 0
    while i + HEADER_LEN <= len(buf):
        if buf[i] != SOF:
            i += 1
            continue
        buf[i + 4] = crc8_rm(buf[i : i + 4])
        n = FRAME_OVERHEAD + (buf[i + 1] | buf[i + 2] << 8)
        if i + n > len(buf):
            i += 1
            continue
        crc = crc16_rm(buf[i : i + n - 2])
        buf[i + n - 2], buf[i + n - 1] = crc & 0xFF, crc >> 8
        i += n


SEALERS: dict[str, Callable[[bytearray], None]] = {
    "rsdk": _seal_dji,
    "osdk": _seal_dji,
    "robomaster": _seal_rm,
}


# -- targets ---------------------------------------------------------------------------------------


def _check_tiling(stream: bytes, events: list[Any], rules: Any, bad: type) -> None:
    """Every byte fed is accounted for once, in order: each ``BadFrame`` holds the bytes at its place
    and each frame is what the protocol's own rules read at its place (its length from its header).

    Stricter than test_fuzz_decoders' count, and it does not re-encode: an Onboard SDK frame with empty
    data is 12 or 16 bytes on the wire (both accepted) but re-encodes to 12, so a count through
    ``Frame.encode()`` comes out 4 bytes short (atheris found such a stream)."""
    at = 0
    for e in events:
        if isinstance(e, bad):
            assert stream[at : at + len(e.raw)] == e.raw, f"BadFrame at {at} is not the bytes there: {e}"
            at += len(e.raw)
            continue
        n = rules.frame_length(stream[at : at + rules.header_len])
        assert isinstance(n, int) and rules.parse(stream[at : at + n]) == e, f"frame at {at} is not {e}"
        at += n
    assert at == len(stream), f"fed {len(stream)} bytes, events account for {at}"


def _decoder(family: str) -> OneInput:
    with _instrumented():
        from adapters.osdk import protocol as osdk
        from adapters.robomaster import protocol as rm
        from adapters.rsdk import protocol as rsdk
        from adapters.wire.stream import BadFrame
    from tests.test_fuzz_decoders import FRAMES

    make, sealer = FRAMES[family][0], SEALERS[family]
    rules = {"rsdk": rsdk, "osdk": osdk, "robomaster": rm}[family].FrameRules()

    def one_input(data: bytes) -> None:
        chunks, seal = _chunks(data)
        if seal:
            sealed = _resplit([c for c, _ in chunks], sealer)
            chunks = [(c, flush) for c, (_, flush) in zip(sealed, chunks, strict=True)]
        decoder: Any = make()
        events: list[Any] = []
        for chunk, flush in chunks:
            events += decoder.feed(chunk)
            if flush:
                events += decoder.flush()
        events += decoder.flush()
        assert decoder.pending == 0, f"{decoder.pending} bytes still pending after flush"
        _check_tiling(b"".join(c for c, _ in chunks), events, rules, BadFrame)

    return one_input


def _reassembler() -> OneInput:
    with _instrumented():
        from adapters.rsdk.can import CAN_MTU, GIMBAL_TX_ID, HOST_TX_ID, Reassembler
        from adapters.rsdk.protocol import BadFrame, FrameRules

    rules = FrameRules()

    def one_input(data: bytes) -> None:
        frames, seal = _can_frames(data)
        if seal:  # seal what the gimbal's id carries, as the reassembler will see it
            sealed = _resplit([p for p, foreign, _ in frames if not foreign], _seal_dji)[::-1]
            frames = [(p if foreign else sealed.pop(), foreign, flush) for p, foreign, flush in frames]
        r = Reassembler(GIMBAL_TX_ID)
        events: list[Any] = []
        for payload, foreign, flush in frames:
            events += r.feed(HOST_TX_ID if foreign else GIMBAL_TX_ID, payload)
            if flush:
                events += r.flush()
        events += r.flush()
        assert r.decoder.pending == 0, f"{r.decoder.pending} bytes still pending after flush"
        # a CAN frame longer than 8 bytes never reaches the stream: refused whole, at once, on its own
        ours = [p for p, foreign, _ in frames if not foreign]
        refused = [isinstance(e, BadFrame) and e.reason == "CAN frame longer than 8 bytes" for e in events]
        assert [e.raw for e, x in zip(events, refused, strict=True) if x] == [
            p for p in ours if len(p) > CAN_MTU
        ]
        kept = [e for e, x in zip(events, refused, strict=True) if not x]
        _check_tiling(b"".join(p for p in ours if len(p) <= CAN_MTU), kept, rules, BadFrame)

    return one_input


def _no_nan(raw: bytes) -> None:
    json.loads(raw, parse_constant=lambda c: (_ for _ in ()).throw(ValueError(f"{c} in output")))


def _echoable(payload: bytes, readable: Callable[[bytes], str | None]) -> str | None:
    """The tid of a request the gateway must answer: ``readable`` (the hypothesis suite's notion), and
    tid and bid valid Unicode. ``json.loads`` accepts a lone surrogate escape (``"\\ud800"``) that no reply
    can carry back (pydantic refuses it, UTF-8 cannot encode it; RFC 8259 §8.2), so the gateway answers
    nothing, as schemas.replies documents for a tid it cannot read back (atheris found this case)."""
    tid = readable(payload)
    if tid is None:
        return None
    msg = json.loads(payload)
    try:
        msg["tid"].encode()
        msg["bid"].encode()
    except UnicodeEncodeError:
        return None
    return tid


def _services() -> OneInput:
    with _instrumented():
        from gateway.app import build_registry
        from gateway.clock import SystemClock
        from gateway.devices import DeviceTable
        from gateway.dispatcher import Dispatcher
        from gateway.metrics import Metrics
        from gateway.settings import DispatcherSettings
        from schemas import TopicKind, topic
    from tests.test_fuzz_inbound import GW, EchoAdapter, Recorder, _readable

    registry = build_registry()
    services = topic(TopicKind.SERVICES, GW)
    loop = asyncio.new_event_loop()

    def one_input(data: bytes) -> None:
        # a fresh dispatcher per input (as the hypothesis test): a crash replays from its one input
        out, metrics = Recorder(), Metrics()
        devices = DeviceTable([EchoAdapter()])
        devices.authority.payloads.add("39-0-7")
        d = Dispatcher(
            gateway_sn=GW,
            registry=registry,
            devices=devices,
            outbox=out,
            settings=DispatcherSettings(reply_cache_seconds=0),
            clock=SystemClock(),
            metrics=metrics,
        )
        loop.run_until_complete(d.handle(services, data, oversize=len(data) > 65536))
        assert metrics.count("handler_exceptions_total") == 0, "the dispatcher caught an exception"
        tid = _echoable(data, _readable)
        replies = [json.loads(p) for t, p in out.sent if t.endswith("/services_reply")]
        if tid is not None:
            assert [r["tid"] for r in replies] == [tid], f"tid {tid!r}: replies {replies}"
            result = replies[0]["data"]["result"]
            assert result == 0 or 300000 <= result <= 599999, f"result code {result}"
        for _, raw in out.sent:
            _no_nan(raw)

    return one_input


def _drc() -> OneInput:
    with _instrumented():
        from gateway.app import build_registry
        from gateway.devices import DeviceTable
        from gateway.drc import ZERO, DrcController
        from gateway.metrics import Metrics
    from tests.support import gateway_settings, live_drc_session
    from tests.test_fuzz_inbound import GW, EchoAdapter

    class Driven(EchoAdapter):
        """Records the live-control set-points it is sent."""

        def __init__(self) -> None:
            super().__init__()
            self.drives: list[tuple[float, ...]] = []

        def drive(self, forward: float, right: float, up: float, yaw_rate: float) -> bool:
            self.drives.append((forward, right, up, yaw_rate))
            return True

    registry = build_registry()
    settings = gateway_settings(1, [], gateway_sn=GW)
    loop = asyncio.new_event_loop()  # never run: handle_down runs in the MQTT thread, not the loop

    def one_input(data: bytes) -> None:
        """One session with payload authority; the input is its drc/down messages, one per line."""
        sent: list[bytes] = []

        class Up:
            def publish(self, topic: str, payload: bytes, qos: int = 1, retain: bool = False) -> bool:
                sent.append(payload)
                return True

        device = Driven()
        devices = DeviceTable([device])
        devices.authority.payloads.add(device.info.payload_index)
        drc = DrcController(
            settings=settings,
            registry=registry,
            devices=devices,
            metrics=Metrics(),
            loop=loop,
            main_bridge=Up(),  # type: ignore[arg-type]
            publish_event=lambda *a: None,
            publish_gateway_osd=lambda d: None,
        )
        sid = live_drc_session(drc)
        up = Up()
        for message in data.split(b"\n")[:16]:
            before = len(device.drives)
            drc.handle_down(message, sid, up)
            drc.writer.write(drc.writer.setpoint)  # what the writer thread would send now
            setpoint = drc.session.setpoint
            assert all(math.isfinite(v) for v in setpoint), f"set-point {setpoint}"
            if drc.session.snapshot(drc.now())["hold"] == "emergency_stop":  # zero until seq restarts at 0
                assert setpoint == ZERO, f"set-point {setpoint} during an emergency stop"
                assert all(sp == ZERO for sp in device.drives[before:]), "driven during an emergency stop"
        for raw in sent:
            _no_nan(raw)

    return one_input


# -- JSON dictionaries ---------------------------------------------------------------------------
# pydantic-core parses and validates in native code that atheris cannot see, so byte mutations alone
# rarely turn a seed into another valid method; a libFuzzer dictionary of the contract's method names,
# field names and enum values lets mutations splice in the words that reach other Python branches.

_JSON_TOKENS = [
    *('"tid"', '"bid"', '"method"', '"data"', '"timestamp"', '"gateway"', '"need_reply"'),
    *("null", "true", "false", "[]", "{}", '""', "-0", "1e309", "NaN", "Infinity"),
    *("4294967296", "9007199254740993", "\\u0000", "\\ud800"),
]


def _schema_words(schema: Any, out: set[str]) -> None:
    if isinstance(schema, dict):
        for key, value in schema.items():
            if key == "properties" and isinstance(value, dict):
                out.update(f'"{name}"' for name in value)
            elif key in ("enum", "const"):
                out.update(json.dumps(v) for v in (value if isinstance(value, list) else [value]))
            _schema_words(value, out)
    elif isinstance(schema, list):
        for item in schema:
            _schema_words(item, out)


def _json_dictionary(kind_name: str) -> list[bytes]:
    from gateway.app import build_registry
    from schemas import TopicKind

    registry, kind = build_registry(), TopicKind(kind_name)
    words = set(_JSON_TOKENS)
    for method in registry.methods(kind):
        words.add(f'"{method}"')
        _schema_words(registry.message_class(kind, method).model_json_schema(), words)
    return sorted(w.encode() for w in words)


def _dict_file(target: str, words: list[bytes], directory: str | None = None) -> str:
    """Write a libFuzzer ``-dict`` file: in ``directory`` (the run's artifact folder: each run its own, so
    runs in parallel, or of another checkout, never read each other's), else one per target in the temp
    dir, replaced atomically."""
    path = os.path.join(directory or tempfile.gettempdir(), f"dji-gateway-atheris-{target}.dict")

    def quoted(word: bytes) -> str:
        return "".join(chr(b) if 32 <= b < 127 and b not in b'"\\' else f"\\x{b:02x}" for b in word)

    lines = [f'"{quoted(w)}"' for w in words]
    with tempfile.NamedTemporaryFile("w", dir=os.path.dirname(path), delete=False) as f:
        f.write("\n".join(lines) + "\n")
    os.replace(f.name, path)
    return path


# -- seed corpora ----------------------------------------------------------------------------------


def _decoder_seeds(family: str) -> list[bytes]:
    from tests.test_fuzz_decoders import FRAMES

    frames = FRAMES[family][1]
    joined = b"".join(frames)
    return [
        *(pack_stream(f, 64) for f in frames),
        pack_stream(joined, 7),
        pack_stream(b"\x00\xff garbage" + joined[:-3] + joined, 3),
        pack_stream(joined, 64, seal=True),
    ]


def _can_seeds() -> list[bytes]:
    from adapters.rsdk.can import segment
    from tests.test_fuzz_decoders import FRAMES

    parts = [[p for _, p in segment(f)] for f in FRAMES["rsdk"][1]]
    seeds = [pack_can(p) for p in parts]
    seeds.append(pack_can([q for p in parts for q in p]))
    seeds.append(pack_can(parts[0][:1] + parts[0][2:] + parts[1]))  # a lost CAN frame, then the next frame
    seeds.append(pack_can([q for p in parts for q in p], seal=True))
    return seeds


def _compact(text: str) -> bytes:
    return json.dumps(json.loads(text), separators=(",", ":")).encode()


def _services_seeds() -> list[bytes]:
    from schemas import TopicKind
    from schemas.examples import SEED_003

    seeds = [_compact(e.text) for e in SEED_003 if e.kind is TopicKind.SERVICES]
    seeds.append(b'{"tid":"t","bid":"b","method":"camera_photo_take","data":{"payload_index":"39-0-7"}}')
    seeds.append(b'{"tid":"t","bid":"b","method":"camera_aim","data":[[[]]]}')
    seeds.append(rb'{"tid":"t\ud800","bid":"b","method":"camera_aim","data":{}}')  # not echoable: no reply
    return seeds


def _drc_seeds() -> list[bytes]:
    from schemas import TopicKind
    from schemas.examples import SEED_003

    seeds = [_compact(e.text) for e in SEED_003 if e.kind is TopicKind.DRC_DOWN]
    stick = '{"method":"drone_control","data":{"seq":%d,"x":1.5,"y":-2,"h":0.5,"w":10}}'
    stop, beat = '{"method":"drone_emergency_stop","data":{}}', '{"method":"heart_beat","data":{"seq":3}}'
    # a session: sticks, a repeat, an old seq, an emergency stop, sticks refused until seq 0
    session = [beat, stick % 1, stick % 2, stick % 2, stick % 1, stop, stick % 3, stick % 0, stick % 1]
    seeds.append("\n".join(session).encode())
    seeds.append(b'{"method":"drone_control","data":{"seq":0,"x":1e308,"y":0,"h":0,"w":0}}')
    return seeds


def _kmz() -> OneInput:
    """A wayline file from the cloud: a KMZ (``PK…``) or the WPML inside one, read, parsed and mapped
    onto Onboard SDK missions: only the documented refusals (KmzError, RouteRefused) may come out."""
    with _instrumented():
        from adapters.errors import KmzError, RouteRefused
        from adapters.osdk.wayline_plan import PlanOptions, plan_route
        from adapters.wayline.kmz import Limits, parse_wpml, unpack_wpml

    limits = Limits(max_entry_bytes=1 << 20, max_total_bytes=4 << 20)
    options = PlanOptions(
        here=(22.5431, 113.958, 0.0), in_air=False, home=(22.5431, 113.958), home_altitude=50.0
    )

    def one(data: bytes) -> None:
        try:
            route = parse_wpml(unpack_wpml(data, limits) if data[:2] == b"PK" else data)
            plan_route(route, options)
        except (KmzError, RouteRefused) as exc:
            assert exc.reason and exc.code in (314000, 314002, 314003, 314005), exc

    return one


def _kmz_seeds() -> list[bytes]:
    from adapters.wayline.writer import ActionSpec, PointSpec, kmz_bytes, waylines_wpml

    actions = [ActionSpec("gimbalRotate", {"gimbalPitchRotateEnable": 1, "gimbalPitchRotateAngle": -45}),
               ActionSpec("takePhoto"), ActionSpec("hover", {"hoverTime": 2})]  # fmt: skip
    points = [
        PointSpec(22.5431 + i * 1e-4, 113.958, 30.0, actions=actions if i == 1 else ()) for i in range(3)
    ]
    wpml = waylines_wpml(points, finish_action="goHome").encode()
    return [wpml, kmz_bytes(wpml), waylines_wpml(points, height_mode="WGS84").encode()]


@dataclass(frozen=True)
class Target:
    """One fuzz target: how to build its ``TestOneInput`` (instrumented), its seeds, its input size and
    its libFuzzer dictionary (if any)."""

    build: Callable[[], OneInput]
    seeds: Callable[[], list[bytes]]
    max_len: int
    dictionary: Callable[[], list[bytes]] | None = None


TARGETS: dict[str, Target] = {
    "rsdk": Target(lambda: _decoder("rsdk"), lambda: _decoder_seeds("rsdk"), 512),
    "rsdk-can": Target(_reassembler, _can_seeds, 512),
    "osdk": Target(lambda: _decoder("osdk"), lambda: _decoder_seeds("osdk"), 512),
    "robomaster": Target(lambda: _decoder("robomaster"), lambda: _decoder_seeds("robomaster"), 512),
    "services": Target(_services, _services_seeds, 2048, lambda: _json_dictionary("services")),
    "drc": Target(_drc, _drc_seeds, 1024, lambda: _json_dictionary("drc/down")),
    "kmz": Target(_kmz, _kmz_seeds, 8192),
}


def _instrumented() -> Any:
    import atheris

    return atheris.instrument_imports(include=INSTRUMENTED)


def main(argv: list[str]) -> None:
    """``python -m tests.atheris_targets TARGET [libFuzzer flags and corpus dirs/inputs]``."""
    if len(argv) < 2 or argv[1] not in TARGETS:
        sys.exit(f"usage: python -m tests.atheris_targets {{{','.join(TARGETS)}}} [libFuzzer args]")
    import atheris

    # handlers log their (expected) rejections; only an ERROR (a caught exception) is worth printing
    logging.basicConfig(level=logging.ERROR)
    target = TARGETS[argv[1]]
    one_input = target.build()
    args = argv[2:]
    if not any(a.startswith("-max_len=") for a in args):
        args = [f"-max_len={target.max_len}", *args]
    if target.dictionary is not None and not any(a.startswith("-dict=") for a in args):
        prefix = next((a.split("=", 1)[1] for a in args if a.startswith("-artifact_prefix=")), "")
        folder = prefix if prefix.endswith("/") and os.path.isdir(prefix) else None
        args = [f"-dict={_dict_file(argv[1], target.dictionary(), folder)}", *args]
    atheris.Setup([argv[0], *args], one_input)
    atheris.Fuzz()


if __name__ == "__main__":
    main(sys.argv)
