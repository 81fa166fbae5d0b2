"""CLI contract for the R SDK family: decode bytes or candump text to JSON-able dicts, encode commands.

Used by ``gateway/cli/__init__.py`` (``decode``/``encode``); everything derives from the command table.
Replies are matched to the commands seen earlier in the same input by SEQ, so a legacy reply (no
CmdSet/CmdID) is decoded against the command it answers; ``reply_to=<command name>`` covers replies
whose command is not in the input; ``angle_order`` says how a legacy angle reply is laid out
(``commands.LEGACY_ANGLE_ORDERS``, default the seed's). Must not know MQTT, the gateway or any bus library.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from adapters.errors import CommandError
from adapters.rsdk import commands as cmds
from adapters.rsdk.can import GIMBAL_TX_ID, HOST_TX_ID, Reassembler, segment
from adapters.rsdk.candump import parse_lines
from adapters.rsdk.protocol import BadFrame, Decoder, Frame, FrameRules
from adapters.wire.describe_util import check_options, jsonable

__all__ = ["COMMANDS", "decode_bytes", "decode_can_lines", "encode_can", "encode_command"]

COMMANDS: list[str] = list(cmds.COMMANDS)

# Human-readable companions of some wire values, by field name (shown under "text").
_TEXTS: dict[str, Callable[[int], str]] = {
    "return_code": cmds.return_code_text,
    "version": cmds.version_text,
    "device_id": lambda v: cmds.DEVICE_IDS.get(v, f"device 0x{v:08X}"),
}


class _Session:
    """Decodes frames of one input in order, remembering sent commands by SEQ for their replies."""

    def __init__(self, reply_to: str | None, angle_order: str | None = None) -> None:
        self.reply_to = cmds.lookup(reply_to) if reply_to is not None else None
        self.sent: dict[int, tuple[int, int, str]] = {}
        self.angle_order = angle_order or cmds.SEED_ANGLE_ORDER

    def describe(self, item: Frame | BadFrame) -> dict[str, Any]:
        if isinstance(item, BadFrame):
            return {
                "protocol": "rsdk",
                "valid": False,
                "seq": None,
                "command": None,
                "cmd_set": None,
                "cmd_id": None,
                "is_reply": None,
                "fields": None,
                "error": item.reason,
                "raw": item.raw.hex(),
            }
        out: dict[str, Any] = {
            "protocol": "rsdk",
            "valid": True,
            "seq": item.seq,
            "command": None,
            "cmd_set": item.cmd_set,
            "cmd_id": item.cmd_id,
            "is_reply": item.is_reply,
            "cmd_type": item.cmd_type,
            "fields": None,
            "error": None,
        }
        try:
            msg = self._decode(item)
        except CommandError as e:
            out["error"] = str(e)
            out["payload"] = item.data.hex()
            return out
        out.update(command=msg.name, cmd_set=msg.cmd_set, cmd_id=msg.cmd_id, fields=jsonable(msg.fields))
        if item.is_reply:
            out["legacy"] = msg.legacy
        texts = {k: f(v) for k, f in _TEXTS.items() if isinstance(v := msg.fields.get(k), int)}
        if texts:
            out["text"] = texts
        return out

    def _decode(self, frame: Frame) -> cmds.Message:
        if not frame.is_reply:
            msg = cmds.decode_message(frame)
            self.sent[frame.seq] = (*cmds.lookup(msg.name).set_and_id, msg.name)
            return msg
        sent = self.sent.get(frame.seq)
        if sent is not None:
            return cmds.decode_reply(frame, *sent, angle_order=self.angle_order)
        if self.reply_to is not None:
            spec = self.reply_to
            return cmds.decode_reply(frame, *spec.set_and_id, spec.name, angle_order=self.angle_order)
        return cmds.decode_message(frame)


def decode_bytes(data: bytes, **options: Any) -> list[dict[str, Any]]:
    """One dict per frame or BadFrame, in order. Options: ``can`` (data is candump text, see
    :func:`decode_can_lines`), ``reply_to`` (command name for replies whose command is not in the input),
    ``angle_order`` (legacy angle replies: ``yaw_roll_pitch``, the seed's, or ``yaw_pitch_roll``)."""
    check_options(options, {"can", "reply_to", "host_id", "gimbal_id", "angle_order"}, "rsdk")
    if options.get("can"):
        rest = {k: v for k, v in options.items() if k != "can"}
        return decode_can_lines(bytes(data).decode("utf-8", errors="replace"), **rest)
    check_options(options, {"can", "reply_to", "angle_order"}, "rsdk")
    session = _Session(options.get("reply_to"), options.get("angle_order"))
    decoder = Decoder()
    items = decoder.feed(data) + decoder.flush()
    return [session.describe(item) for item in items]


def decode_can_lines(text: str, **options: Any) -> list[dict[str, Any]]:
    """Decode candump text (screen or log format). Frames on ``gimbal_id`` (0x222) and ``host_id``
    (0x223) are reassembled per id; each dict also has ``can_id``. Other ids are skipped."""
    check_options(options, {"reply_to", "host_id", "gimbal_id", "angle_order"}, "rsdk")
    session = _Session(options.get("reply_to"), options.get("angle_order"))
    ids = (int(options.get("host_id", HOST_TX_ID)), int(options.get("gimbal_id", GIMBAL_TX_ID)))
    reassemblers = {i: Reassembler(i) for i in ids}
    out: list[dict[str, Any]] = []

    def emit(can_id: int, items: list[Frame | BadFrame]) -> None:
        for item in items:
            d = session.describe(item)
            d["can_id"] = can_id
            out.append(d)

    for arb_id, payload in parse_lines(text):
        r = reassemblers.get(arb_id)
        if r is not None:
            emit(arb_id, r.feed(arb_id, payload))
    for can_id, r in reassemblers.items():
        emit(can_id, r.flush())
    return out


def encode_command(command: str, seq: int, fields: dict[str, Any], **options: Any) -> bytes:
    """Frame bytes for a table command. Options: ``reply`` (encode its reply, as the gimbal would),
    ``legacy`` (that reply in the old format, its angles in ``angle_order``), ``cmd_type`` (override the
    CmdType reply type). Unknown command or field -> ValueError listing the valid names."""
    check_options(options, {"reply", "legacy", "cmd_type", "angle_order"}, "rsdk")
    if options.get("angle_order") and not (options.get("reply") and options.get("legacy")):
        raise ValueError("angle_order applies to legacy replies only (reply and legacy)")
    return cmds.encode_command(
        command,
        seq,
        fields,
        reply=bool(options.get("reply", False)),
        legacy=bool(options.get("legacy", False)),
        cmd_type=options.get("cmd_type"),
        angle_order=options.get("angle_order") or cmds.SEED_ANGLE_ORDER,
    )


def encode_can(command: str, seq: int, fields: dict[str, Any], **options: Any) -> list[tuple[int, bytes]]:
    """The CAN frames for :func:`encode_command`; ``arb_id`` defaults to 0x223 for commands and 0x222
    for replies (``reply=True``)."""
    check_options(options, {"reply", "legacy", "cmd_type", "arb_id", "angle_order"}, "rsdk")
    rest = {k: v for k, v in options.items() if k != "arb_id"}
    default_id = GIMBAL_TX_ID if options.get("reply") else HOST_TX_ID
    return segment(encode_command(command, seq, fields, **rest), int(options.get("arb_id", default_id)))


# -- the console's frame inspector (gateway/web/frames.py) -------------------------------------------
#: the decode option naming the command a reply answers, and the record key that marks a reply
REPLY_OPTION = "reply_to"
REPLY_FLAG = "is_reply"


def frame_rules(options: Mapping[str, Any]) -> FrameRules:
    """How the inspector cuts one CAN id's reassembled bytes into R SDK frames."""
    return FrameRules()


def options_for(settings: Any) -> dict[str, Any]:
    """The decode options that match a configured gimbal: none (the inspector keeps ids apart)."""
    return {}
