"""The RoboMaster codec as the ``dji-gateway decode/encode`` CLI sees it (CLI contract).

Owns: turning frames and messages into JSON-able dicts and CLI options into codec settings.
Must not know argument parsing or output formatting (``gateway/cli/codec.py``).

Options: ``season`` = "2024" | "2025" | "2026" (default 2026), ``control_cmd_id`` = int (default
0x0F01; 0x0301 carries control messages inside robot interaction frames). Also accepted:
``control_data_cmd_id``, ``control_sender_id``, ``control_receiver_id`` (the 0x0301 sub-header)
and ``max_data_len`` (decoder bound; 1024 default, 119 on a referee link).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from adapters.errors import CommandError, UnknownCommandError
from adapters.robomaster.commands import (
    COMMAND_NAMES,
    DEFAULT_CONTROL,
    DEFAULT_SEASON,
    ControlChannel,
    check_season,
    decode_message,
    encode_message,
)
from adapters.robomaster.protocol import DEFAULT_MAX_DATA_LEN, BadFrame, Decoder, Frame, FrameRules
from adapters.wire.describe_util import check_options, jsonable

__all__ = ["COMMANDS", "OPTIONS", "decode_bytes", "encode_command"]

PROTOCOL = "robomaster"
COMMANDS: list[str] = list(COMMAND_NAMES)
OPTIONS: tuple[str, ...] = (
    "season",
    "control_cmd_id",
    "control_data_cmd_id",
    "control_sender_id",
    "control_receiver_id",
    "max_data_len",
)


def _int(name: str, value: Any) -> int:
    if isinstance(value, bool):
        raise ValueError(f"{name}: expected an integer, got {value!r}")
    if isinstance(value, int):
        return value
    if isinstance(value, str):
        try:
            return int(value, 0)
        except ValueError:
            pass
    raise ValueError(f"{name}: expected an integer, got {value!r}")


def _settings(options: Mapping[str, Any]) -> tuple[str, ControlChannel, int]:
    check_options(options, OPTIONS, PROTOCOL)
    season = check_season(options.get("season") or DEFAULT_SEASON)
    kwargs = {
        key: _int(opt, options[opt])
        for opt, key in (
            ("control_cmd_id", "cmd_id"),
            ("control_data_cmd_id", "data_cmd_id"),
            ("control_sender_id", "sender_id"),
            ("control_receiver_id", "receiver_id"),
        )
        if options.get(opt) is not None
    }
    control = ControlChannel(**kwargs) if kwargs else DEFAULT_CONTROL
    max_len = options.get("max_data_len")
    return season, control, DEFAULT_MAX_DATA_LEN if max_len is None else _int("max_data_len", max_len)


def _record(event: Frame | BadFrame, season: str, control: ControlChannel) -> dict[str, Any]:
    if isinstance(event, BadFrame):
        return {
            "protocol": PROTOCOL,
            "valid": False,
            "seq": None,
            "command": None,
            "cmd_id": None,
            "fields": None,
            "error": event.reason,
            "raw": event.raw.hex(),
        }
    rec: dict[str, Any] = {
        "protocol": PROTOCOL,
        "valid": True,
        "seq": event.seq,
        "command": None,
        "cmd_id": event.cmd_id,
        "fields": None,
        "error": None,
    }
    try:
        msg = decode_message(event, season, control)
    except UnknownCommandError:
        rec["payload"] = event.data.hex()  # a valid frame we have no table entry for
    except CommandError as exc:
        rec.update(command=exc.name, error=str(exc), payload=event.data.hex())
    else:
        rec.update(command=msg.name, fields=jsonable(msg.fields))
    return rec


def decode_bytes(data: bytes, **options: Any) -> list[dict[str, Any]]:
    """One dict per frame or BadFrame in stream order; the decoder is flushed at the end."""
    season, control, max_len = _settings(options)
    decoder = Decoder(max_len)
    events = decoder.feed(bytes(data)) + decoder.flush()
    return [_record(e, season, control) for e in events]


def encode_command(command: str, seq: int, fields: dict[str, Any], **options: Any) -> bytes:
    """The 0xA5 frame for a table command; hex strings stand for bytes fields (``user_data``)."""
    season, control, _ = _settings(options)
    if command not in COMMAND_NAMES:
        raise ValueError(f"unknown command {command!r}; valid: {', '.join(COMMANDS)}")
    return encode_message(command, fields, season, seq, control)


# -- the console's frame inspector (gateway/web/frames.py) -------------------------------------------
def frame_rules(options: Mapping[str, Any]) -> FrameRules:
    """How the inspector cuts a serial link's bytes into frames (bounded by ``max_data_len``)."""
    return FrameRules(int(options.get("max_data_len", DEFAULT_MAX_DATA_LEN)))


def options_for(settings: Any) -> dict[str, Any]:
    """The decode options that match a configured robot: its season, decoder bound and control channel."""
    control = settings.control
    return {
        "season": settings.season,
        "max_data_len": settings.max_data_len,
        "control_cmd_id": control.cmd_id,
        "control_data_cmd_id": control.data_cmd_id,
        "control_sender_id": control.sender_id,
        "control_receiver_id": control.receiver_id,
    }
