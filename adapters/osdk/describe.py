"""CLI contract for the Onboard SDK family (``dji-gateway decode/encode --family osdk``).

Options: ``firmware="new"`` (default) or ``"m100"`` picks the control and flight-data layouts.
``decode_bytes`` also takes ``ack_command=<name>`` to decode ACK frames whose command is not in the
same byte stream; ACKs that follow their command in the stream are matched by ``(session, seq)``.
``encode_command`` also takes ``session=<0..31>`` and ``ack=True`` (build the ACK frame instead).

Owns: the translation between table-derived codecs and JSON-able dicts. Must not know the CLI's
argument parsing or any transport.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from adapters.errors import UnknownCommandError
from adapters.osdk import protocol
from adapters.osdk.commands import (
    COMMAND_NAMES,
    CommandSpec,
    TaggedUnion,
    ack_text,
    decode_ack,
    decode_request,
    encode_ack_payload,
    encode_request,
    spec_for,
    specs_at,
)
from adapters.osdk.protocol import BadFrame, Decoder, Frame
from adapters.osdk.telemetry import FlightDataCodec, check_firmware
from adapters.wire.bits import BitLayout
from adapters.wire.describe_util import check_options, jsonable
from adapters.wire.layout import Layout, LayoutError, PayloadCodec

__all__ = ["COMMANDS", "decode_bytes", "encode_command"]

COMMANDS: list[str] = list(COMMAND_NAMES)


def _base(frame: Frame) -> dict[str, Any]:
    return {
        "protocol": "osdk",
        "valid": True,
        "seq": frame.seq,
        "session": frame.session,
        "is_ack": frame.is_ack,
        "cmd_set": frame.cmd_set,
        "cmd_id": frame.cmd_id,
        "command": None,
        "fields": None,
        "error": None,
    }


def _bad(item: BadFrame) -> dict[str, Any]:
    return {
        "protocol": "osdk",
        "valid": False,
        "seq": None,
        "session": None,
        "is_ack": None,
        "cmd_set": None,
        "cmd_id": None,
        "command": None,
        "fields": None,
        "error": item.reason,
        "raw": item.raw.hex(),
    }


def _with_ack_text(out: dict[str, Any], spec: CommandSpec, fields: Mapping[str, Any]) -> None:
    code = fields.get("ack")
    if isinstance(code, int):
        out["ack_text"] = ack_text(spec, code)


def decode_bytes(data: bytes, **options: Any) -> list[dict[str, Any]]:
    """One dict per frame or BadFrame, in stream order (the decoder is flushed at the end)."""
    check_options(options, {"firmware", "ack_command"}, "osdk")
    firmware = check_firmware(options.get("firmware", "new"))
    ack_command: str | None = options.get("ack_command")
    if ack_command is not None:
        spec_for(ack_command, firmware)  # fail early on a bad name
    decoder = Decoder()
    items = decoder.feed(data) + decoder.flush()
    awaiting: dict[tuple[int, int], str] = {}  # (session, seq) of commands seen -> command name
    out: list[dict[str, Any]] = []
    for item in items:
        if isinstance(item, BadFrame):
            out.append(_bad(item))
            continue
        d = _base(item)
        if item.is_ack:
            name = awaiting.pop((item.session, item.seq), None) or ack_command
            if name is None:
                d["payload"] = item.payload.hex()
            else:
                d["command"] = name
                try:
                    msg = decode_ack(name, item.payload, firmware)
                    d["fields"] = jsonable(msg.fields)
                    _with_ack_text(d, spec_for(name, firmware), msg.fields)
                except LayoutError as exc:
                    d["error"], d["payload"] = str(exc), item.payload.hex()
            out.append(d)
            continue
        assert item.cmd_set is not None and item.cmd_id is not None
        try:
            msg = decode_request(item.cmd_set, item.cmd_id, item.payload, firmware)
        except UnknownCommandError:
            d["payload"] = item.payload.hex()
        except LayoutError as exc:
            names = sorted({s.name for s in specs_at(item.cmd_set, item.cmd_id, firmware)})
            d["command"] = names[0] if len(names) == 1 else None
            d["error"], d["payload"] = str(exc), item.payload.hex()
        else:
            d["command"], d["fields"] = msg.name, jsonable(msg.fields)
            if item.session >= 1 and spec_for(msg.name, firmware).reply:
                awaiting[(item.session, item.seq)] = msg.name
        out.append(d)
    return out


def _bytes_fields(codec: PayloadCodec) -> set[str]:
    """Names of the fields that hold bytes (the CLI passes them as hex strings)."""
    if isinstance(codec, BitLayout):
        return _bytes_fields(codec.layout)
    if isinstance(codec, Layout):
        names = {f.name for f in codec.fields if f.code == "s"}
        return names | ({codec.tail.name} if codec.tail else set())
    if isinstance(codec, TaggedUnion):
        return {n for cs in (*codec.arms.values(), codec.default) for c in cs for n in _bytes_fields(c)}
    if isinstance(codec, FlightDataCodec):
        return {"unknown"}
    return set()


def _from_hex(codec: PayloadCodec, fields: Mapping[str, Any]) -> dict[str, Any]:
    names = _bytes_fields(codec)
    out = dict(fields)
    for k, v in fields.items():
        if k in names and isinstance(v, str):
            try:
                out[k] = bytes.fromhex(v)
            except ValueError:
                raise ValueError(f"{k}: expected a hex string, got {v!r}") from None
    return out


def encode_command(command: str, seq: int, fields: dict[str, Any], **options: Any) -> bytes:
    """One complete frame for ``command``. Missing fields take the table's defaults, then zero.
    Unknown command, field or option -> ValueError naming the valid ones."""
    check_options(options, {"firmware", "session", "ack"}, "osdk")
    firmware = check_firmware(options.get("firmware", "new"))
    spec = spec_for(command, firmware)
    if options.get("ack"):
        if not spec.reply:
            raise ValueError(f"{command} takes no ACK")
        payload = encode_ack_payload(command, _from_hex(spec.reply[0], fields), firmware)
        return protocol.encode_ack(int(options.get("session", 2)), seq, payload)
    payload = encode_request(command, _from_hex(spec.request[0], fields), firmware)
    session = int(options.get("session", int(spec.delivery.session)))
    return protocol.encode_command(*spec.set_and_id, payload, session, seq)


# -- the console's frame inspector (gateway/web/frames.py) -------------------------------------------
#: the decode option naming the command an ACK answers, and the record key that marks an ACK
REPLY_OPTION = "ack_command"
REPLY_FLAG = "is_ack"


def frame_rules(options: Mapping[str, Any]) -> protocol.FrameRules:
    """How the inspector cuts a serial link's bytes into open-protocol frames."""
    return protocol.FrameRules()


def options_for(settings: Any) -> dict[str, Any]:
    """The decode options that match a configured aircraft: its flight controller's firmware."""
    return {"firmware": settings.firmware}
