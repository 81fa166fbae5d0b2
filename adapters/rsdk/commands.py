"""DJI R SDK command table (seed 000 §2.3): what each (CmdSet, CmdID) payload means.

One declarative table, :data:`TABLE`, keyed by ``(cmd_set, cmd_id)``, covers every command of the
seed's Figure 4 (0x0E 0x00..0x12, 0x0D 0x00..0x01). Each entry (an
:class:`adapters.wire.table.CommandSpec`) names its command-frame payload, its reply payload (none
where the seed says there is no reply frame), direction, doc and seed section; field names, units and
seed ranges live in the :class:`~adapters.wire.layout.Field`
declarations. Two keys carry two entries (same CmdSet/CmdID, different meaning):

* 0x0E 0x09: ``get_version`` (host asks, 4-byte device id; reply: return code, id, version) and
  ``version_push`` (an external device announces its own version to the gimbal at 1 Hz, 8 bytes,
  no reply). Both are command frames; they differ by direction and so by payload length (4 vs 8).
* 0x0E 0x0E: ``recenter_selfie`` (operating_mode 0xFE + a one-shot action) and ``follow_mode``
  (operating_mode 0x00/0x02/0x03, action 0): the same 2-byte shape; operating_mode == 0xFE picks
  ``recenter_selfie`` (its ``when``), anything else is ``follow_mode``. Their replies are identical,
  so a reply decoded without knowing the sent command is named after the first entry.

Encoding, decoding, the CLI and the test matrix all derive from the table (no per-command code).
Values stay in wire units. Reply frames come in two formats (see ``protocol``); :func:`decode_reply`
decodes a reply against the command that was sent (match replies to commands by SEQ).

Standard library and ``adapters.wire`` only; knows nothing of CAN, MQTT or the Cloud API.

Why this module is longer than 500 lines: it is a declarative table: one entry per command of the seed's
Figure 4, each naming its layouts, fields, units and section; its length is the protocol's.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from adapters.errors import CommandError, UnknownCommandError
from adapters.rsdk.protocol import DEFAULT_CMD_TYPE, Frame, encode
from adapters.wire.layout import Field, Layout, LayoutError, PayloadCodec, Tail
from adapters.wire.table import EMPTY, CommandSpec, Message, Table, TaggedUnion

__all__ = [
    "BY_NAME",
    "COMMANDS",
    "COMMAND_TABLE",
    "DEVICE_IDS",
    "RETURN_CODES",
    "TABLE",
    "CommandSpec",
    "Message",
    "TaggedUnion",
    "TlvCodec",
    "TlvParam",
    "build_frame",
    "decode_message",
    "decode_reply",
    "encode_command",
    "encode_payload",
    "lookup",
    "payload_examples",
    "return_code_text",
    "version_text",
    "wants_reply",
]

# §2.3.2 Figure 5
RETURN_CODES: dict[int, str] = {
    0x00: "command execution succeeds",
    0x01: "command parse error",
    0x02: "command execution fails",
    0xFF: "undefined error",
}

# §2.3.3 Figure 6
DEVICE_IDS: dict[int, str] = {
    0x00000000: "reserved",
    0x00000001: "DJI R SDK",
    0x00000002: "remote controller",
}


def return_code_text(code: int) -> str:
    """Seed §2.3.2 text for a return code."""
    return RETURN_CODES.get(code, f"unknown return code 0x{code:02X}")


def version_text(version: int) -> str:
    """0xAABBCCDD -> "AA.BB.CC.DD" (§2.3.4.10, taken literally: each byte as two hex digits)."""
    return ".".join(f"{(version >> s) & 0xFF:02X}" for s in (24, 16, 8, 0))


# --- custom codecs: only for the TLV and tagged-union shapes ------------------------------------


def _prepare(layout: Layout, values: Mapping[str, Any], where: str = "") -> dict[str, Any]:
    """Check an encode request against a layout: every field present, seed ranges respected,
    hex strings for byte fields turned into bytes (the CLI contract). Layout.encode checks types.

    Encoding is strict (a missing angle must not silently become 0 on a gimbal); decoding is not."""
    out = dict(values)
    missing = [f.name for f in layout.fields if f.name not in values]
    if missing:
        raise LayoutError(f"{where}missing field(s) {missing}")
    for f in layout.fields:
        v = out[f.name]
        if f.code == "s":
            if isinstance(v, str):
                try:
                    out[f.name] = bytes.fromhex(v)
                except ValueError:
                    raise LayoutError(f"{where}{f.name}: expected hex bytes, got {v!r}") from None
            continue
        for item in v if isinstance(v, list | tuple) else (v,):
            if isinstance(item, bool) or not isinstance(item, int | float):
                continue  # Layout.encode reports the type error
            if (f.minimum is not None and item < f.minimum) or (f.maximum is not None and item > f.maximum):
                raise LayoutError(f"{where}{f.name}: {item} outside seed range {f.minimum}..{f.maximum}")
    return out


def _examples(codec: PayloadCodec) -> list[dict[str, Any]]:
    more = getattr(codec, "examples", None)
    return more() if callable(more) else [codec.example()]


def _union(head: Layout, tag: str, arms: Mapping[int, Layout]) -> TaggedUnion:
    """A payload whose tail depends on a tag byte: fixed ``head`` fields (the tag among them), then
    the layout of the ``arms`` entry for the tag value (0x0A device_type, 0x12 command_sub_id);
    encoding is strict (:func:`_prepare`)."""
    return TaggedUnion(tag, arms, head=head, prepare=_prepare)


@dataclass(frozen=True, slots=True)
class TlvParam:
    """One known TLV id: its ``name`` (the seed's, snake_case) and the layout of its VALUE."""

    id: int
    name: str
    value: Layout
    section: str = ""
    doc: str = ""


class TlvCodec:
    """Fixed ``head`` fields, then a buffer of TLV items (id u8, length u8, value) kept under ``name``.

    Decoded items are ``{"id", "name", "length", "value"}``: ``value`` is the decoded VALUE for a known
    id of the expected length (a scalar for a one-field VALUE, a dict otherwise), else raw bytes.
    Encoding accepts the same dicts (``name`` may stand for ``id``; ``length`` is optional and checked),
    a bytes/hex ``value`` for any id, or the whole buffer as bytes/hex."""

    def __init__(self, head: Layout, name: str, params: Iterable[TlvParam]) -> None:
        self.head = head
        self.name = name
        self.params = {p.id: p for p in params}
        self._by_name = {p.name: p for p in self.params.values()}

    @property
    def size(self) -> None:
        return None

    def decode(self, data: bytes) -> dict[str, Any]:
        n = self.head.fixed_size
        if len(data) < n:
            raise LayoutError(f"payload is {len(data)} bytes, needs at least {n}")
        out = self.head.decode(data[:n])
        out[self.name] = self.decode_items(data[n:])
        return out

    def decode_items(self, buf: bytes) -> list[dict[str, Any]]:
        items: list[dict[str, Any]] = []
        i, n = 0, len(buf)
        while i < n:
            if i + 2 > n:
                raise LayoutError(f"{self.name}: TLV item at offset {i} cut inside its id/length")
            tid, ln = buf[i], buf[i + 1]
            raw = bytes(buf[i + 2 : i + 2 + ln])
            if len(raw) < ln:
                raise LayoutError(f"{self.name}: TLV id 0x{tid:02X} announces {ln} bytes, {len(raw)} left")
            p = self.params.get(tid)
            value: Any = raw
            if p is not None and p.value.size == ln:
                d = p.value.decode(raw)
                value = d[p.value.fields[0].name] if len(p.value.fields) == 1 else d
            items.append({"id": tid, "name": p.name if p else None, "length": ln, "value": value})
            i += 2 + ln
        return items

    def encode(self, values: Mapping[str, Any]) -> bytes:
        head_names = {f.name for f in self.head.fields}
        unknown = set(values) - head_names - {self.name}
        if unknown:
            raise LayoutError(
                f"unknown field(s) {sorted(unknown)}; known: {sorted([*head_names, self.name])}"
            )
        head = self.head.encode(_prepare(self.head, {k: v for k, v in values.items() if k in head_names}))
        items = values.get(self.name, [])
        if isinstance(items, str):
            try:
                items = bytes.fromhex(items)
            except ValueError:
                raise LayoutError(f"{self.name}: expected hex bytes or a list of TLV items") from None
        if isinstance(items, bytes | bytearray):
            return head + bytes(items)
        if not isinstance(items, list | tuple):
            raise LayoutError(f"{self.name}: expected a list of TLV items")
        return head + b"".join(self._encode_item(item) for item in items)

    def _encode_item(self, item: Any) -> bytes:
        if not isinstance(item, Mapping):
            raise LayoutError(f"{self.name}: a TLV item is a dict with id (or name) and value")
        extra = set(item) - {"id", "name", "length", "value"}
        if extra:
            raise LayoutError(f"{self.name}: unknown TLV item key(s) {sorted(extra)}")
        p = self.params.get(item["id"]) if isinstance(item.get("id"), int) else None
        if p is None and item.get("name") is not None:
            p = self._by_name.get(item["name"])
            if p is None:
                raise LayoutError(
                    f"{self.name}: unknown TLV name {item['name']!r}; known: {sorted(self._by_name)}"
                )
        tid = item.get("id", p.id if p else None)
        if not isinstance(tid, int) or not 0 <= tid <= 0xFF:
            raise LayoutError(f"{self.name}: TLV id must be 0..255, got {tid!r}")
        if p is not None and p.id != tid:
            raise LayoutError(f"{self.name}: TLV name {p.name!r} is id 0x{p.id:02X}, not 0x{tid:02X}")
        if "value" not in item:
            raise LayoutError(f"{self.name}: TLV id 0x{tid:02X} has no value")
        value = item["value"]
        if isinstance(value, str):
            try:
                value = bytes.fromhex(value)
            except ValueError:
                raise LayoutError(f"{self.name}: TLV value {value!r} is not hex") from None
        if isinstance(value, bytes | bytearray):
            raw = bytes(value)
        elif p is None:
            raise LayoutError(f"{self.name}: TLV id 0x{tid:02X} is unknown; give its value as hex bytes")
        else:
            layout = p.value
            fields = {layout.fields[0].name: value} if len(layout.fields) == 1 else value
            if not isinstance(fields, Mapping):
                raise LayoutError(f"{self.name}: TLV {p.name} value must be a dict of {layout.fields}")
            raw = layout.encode(_prepare(layout, fields, f"{p.name}."))
        if len(raw) > 0xFF:
            raise LayoutError(f"{self.name}: TLV id 0x{tid:02X} value is {len(raw)} bytes, at most 255")
        if "length" in item and item["length"] != len(raw):
            raise LayoutError(
                f"{self.name}: TLV id 0x{tid:02X} length {item['length']} but value is {len(raw)}"
            )
        return bytes((tid, len(raw))) + raw

    def example(self) -> dict[str, Any]:
        """Head sample plus one item per known id (the round-trip matrix covers every id)."""
        out = self.head.example()
        items = []
        for p in self.params.values():
            ex = p.value.example()
            value = ex[p.value.fields[0].name] if len(p.value.fields) == 1 else ex
            items.append({"id": p.id, "name": p.name, "length": p.value.size, "value": value})
        out[self.name] = items
        return out


# --- field helpers ------------------------------------------------------------------------------


def u8(name: str, doc: str = "", unit: str = "", lo: float | None = None, hi: float | None = None) -> Field:
    return Field(name, "B", unit=unit, doc=doc, minimum=lo, maximum=hi)


def i16(name: str, doc: str = "", unit: str = "", lo: float | None = None, hi: float | None = None) -> Field:
    return Field(name, "h", unit=unit, doc=doc, minimum=lo, maximum=hi)


def _byte_list(value: Any) -> bytes:
    if isinstance(value, str):
        try:
            value = list(bytes.fromhex(value))
        except ValueError:
            raise LayoutError(f"expected hex bytes or a list of byte values, got {value!r}") from None
    if not value:
        raise LayoutError("at least one id is needed")
    if not isinstance(value, list | tuple) or not all(isinstance(v, int) and 0 <= v <= 0xFF for v in value):
        raise LayoutError(f"expected a list of byte values, got {value!r}")
    return bytes(value)


RETURN_CODE = u8("return_code", "§2.3.2: 0x00 ok, 0x01 parse error, 0x02 execution failed, 0xFF undefined")
RC = Layout([RETURN_CODE])
DEG10 = "0.1 deg"
DEG10_S = "0.1 deg/s"

# Limit angles (Figures 10, 11, 15): whole degrees, seed ranges.
LIMITS = (
    u8("pitch_max", "max tilt axis angle", "deg", 0, 145),
    u8("pitch_min", "min tilt axis angle", "deg", 0, 55),
    u8("yaw_max", "max pan axis angle", "deg", 0, 179),
    u8("yaw_min", "min pan axis angle", "deg", 0, 179),
    u8("roll_max", "max roll axis angle", "deg", 0, 30),
    u8("roll_min", "min roll axis angle", "deg", 0, 30),
)


def _stiffness(axis: str) -> Field:
    return u8(f"{axis}_stiffness", "motor stiffness", "", 0, 100)


# §2.3.4.12 Figure 23: user parameters, read (0x0B) and written (0x0C) as TLV.
USER_PARAMS = (
    TlvParam(
        0x00, "parameter_table_number_selection", Layout([u8("value", "parameter table 0..2", "", 0, 2)])
    ),
    TlvParam(
        0x22,
        "special_functions_under_follow_mode",
        Layout(
            [
                u8(
                    "value",
                    "bits 5:3 roll 360 mode: 0 3-axis, 1 2-axis, 2 ROLL 360, 3 3D_ROLL360; others reserved",
                )
            ]
        ),
    ),
    TlvParam(
        0x23, "motor_special_function", Layout([u8("value", "bit 0: power off the motor; 7:1 reserved")])
    ),
)

# §2.3.4.16 Figure 29 (auto calibration control) and §2.3.4.17 Figure 30 (its status push).
SELF_TUNING_CONTROL = TlvParam(
    0x00,
    "control_parameters_self_tuning",
    Layout([u8("value", "bit 0: 1 start / 0 stop self-tuning; bits 7:1 type: 0 default, 1 single attitude")]),
)
SELF_TUNING_STATUS = TlvParam(
    0x00,
    "control_parameters_self_tuning",
    Layout(
        [
            u8("status", "0 none, 1 running, 2 completed, 3 error", "", 0, 3),
            u8("progress", "auto calibration progress", "%", 0, 100),
            Field("error", "s", 4, doc="bytes 2-5: auto calibration error status (reserved)"),
        ]
    ),
)

# §2.3.4.19: focus motor sub-commands, a union on command_sub_id (0x12).
FOCUS_SUB_ID = u8("command_sub_id", "0x01 position control, 0x02 calibration, 0x15 get position")
MOTOR_TYPE = u8("motor_type", "0x00 focus motor", "", 0, 0)


def _cmd(
    name: str,
    cmd_set: int,
    cmd_id: int,
    command: PayloadCodec,
    reply: PayloadCodec | None,
    section: str,
    direction: str,
    doc: str = "",
    *,
    when: Mapping[str, int] = EMPTY,
    examples: tuple[Mapping[str, Any], ...] = (),
    handler: str = "",
) -> CommandSpec:
    """One table entry (:class:`adapters.wire.table.CommandSpec`) in the seed's terms.

    ``command``/``reply`` describe the payload after CmdSet/CmdID; ``reply`` is None where the seed says
    the command has no reply frame. ``when`` holds field values that pick this entry among several at
    one key (the spec's ``fixed``: filled in when encoding); ``examples`` adds samples to the test
    matrix; ``handler`` names the adapter method a pushed frame of this entry goes to."""
    return CommandSpec(
        name, cmd_set, cmd_id, (command,), () if reply is None else (reply,), RETURN_CODES, direction,
        fixed=when, section=section, doc=doc, examples=examples, handler=handler,
    )  # fmt: skip


def wants_reply(spec: CommandSpec, values: Mapping[str, Any]) -> bool:
    """Whether a command frame with these fields gets a reply (per-arm for tagged unions)."""
    if not spec.reply:
        return False
    reply, command = spec.reply[0], spec.request[0]
    if isinstance(reply, TaggedUnion) and isinstance(command, TaggedUnion):
        return values.get(command.tag) in reply.arms
    return True


HOST = "host -> gimbal"
GIMBAL = "gimbal -> host"
DEVICE = "external device -> gimbal"

_ENTRIES: tuple[CommandSpec, ...] = (
    _cmd(
        "position_control",
        0x0E,
        0x00,
        Layout(
            [
                i16("yaw_angle", "yaw angle", DEG10, -1800, 1800),
                i16("roll_angle", "roll angle", DEG10, -300, 300),
                i16("pitch_angle", "pitch angle", DEG10, -560, 1460),
                u8(
                    "ctrl_byte",
                    "bit 0: 1 absolute / 0 incremental; bits 1/2/3: yaw/roll/pitch invalid; 7:4 must be 0",
                    "",
                    0,
                    0x0F,
                ),
                u8("time_for_action", "time to reach the position at constant speed", "0.1 s"),
            ]
        ),
        RC,
        "2.3.4.1",
        HOST,
        "move to an angle (seed §3.3 sample)",
    ),
    _cmd(
        "speed_control",
        0x0E,
        0x01,
        Layout(
            [
                # The seed says "0 to 360 deg/s"; real drivers (ArduPilot) send signed speeds, the
                # sign giving the direction: the range is +-3600.
                i16("yaw_speed", "yaw speed", DEG10_S, -3600, 3600),
                i16("roll_speed", "roll speed", DEG10_S, -3600, 3600),
                i16("pitch_speed", "pitch speed", DEG10_S, -3600, 3600),
                u8(
                    "ctrl_byte",
                    "bit 7: 1 take over / 0 release speed control; bit 3: 1 ignore focal length; "
                    "others 0 (typical 0x88)",
                ),
            ]
        ),
        RC,
        "2.3.4.2",
        HOST,
        "holds 0.5 s only: resend at >= 10 Hz while moving; all-zero speeds stop",
    ),
    _cmd(
        "get_angle",
        0x0E,
        0x02,
        Layout([u8("ctrl_byte", "0x00 no operation, 0x01 attitude angle, 0x02 joint angle", "", 0, 2)]),
        # The seed's size column says 4 for return code and data_type: both are uint8_t (1 byte), as
        # the offsets and real replies (24/26-byte frames) show.
        Layout(
            [
                RETURN_CODE,
                u8("data_type", "0x00 not ready, 0x01 attitude angle, 0x02 joint angle", "", 0, 2),
                i16("yaw", "yaw axis angle", DEG10),
                i16("roll", "roll axis angle", DEG10),
                i16("pitch", "pitch axis angle", DEG10),
            ]
        ),
        "2.3.4.3",
        HOST,
        "obtain attitude or joint angles",
    ),
    _cmd(
        "set_limit_angle",
        0x0E,
        0x03,
        Layout([u8("ctrl_byte", "0x00 no operation, 0x01 set limit angle", "", 0, 1), *LIMITS]),
        RC,
        "2.3.4.4",
        HOST,
    ),
    _cmd(
        "get_limit_angle",
        0x0E,
        0x04,
        Layout([u8("ctrl_byte", "0x00 no operation, 0x01 obtain limit angle", "", 0, 1)]),
        Layout([RETURN_CODE, *LIMITS]),
        "2.3.4.5",
        HOST,
    ),
    _cmd(
        "set_stiffness",
        0x0E,
        0x05,
        Layout(
            [
                u8("ctrl_byte", "0x00 no operation, 0x01 set motor stiffness", "", 0, 1),
                _stiffness("pitch"),
                _stiffness("roll"),
                _stiffness("yaw"),
            ]
        ),
        RC,
        "2.3.4.6",
        HOST,
    ),
    _cmd(
        "get_stiffness",
        0x0E,
        0x06,
        Layout([u8("ctrl_byte", "0x00 no operation, 0x01 obtain motor stiffness", "", 0, 1)]),
        # Seed order is pitch, yaw, roll here (pitch, roll, yaw when setting); kept as written.
        # "yaw_ stiffness"/"roll_ stiffness": stray spaces in the seed removed.
        Layout([RETURN_CODE, _stiffness("pitch"), _stiffness("yaw"), _stiffness("roll")]),
        "2.3.4.7",
        HOST,
    ),
    _cmd(
        "push_settings",
        0x0E,
        0x07,
        Layout([u8("ctrl_byte", "0x00 no operation, 0x01 enable, 0x02 disable parameter push", "", 0, 2)]),
        RC,
        "2.3.4.8",
        HOST,
        "0x01 turns on the unsolicited param_push (0x0E 0x08) frames",
    ),
    _cmd(
        "param_push",
        0x0E,
        0x08,
        Layout(
            [
                u8("ctrl_byte", "bit 0 angles valid, bit 1 limits valid, bit 2 stiffness valid", "", 0, 7),
                # "roll_ angle"/"pitch_ angle": stray spaces in the seed removed.
                i16("yaw_angle", "attitude yaw", DEG10),
                i16("roll_angle", "attitude roll", DEG10),
                i16("pitch_angle", "attitude pitch", DEG10),
                # The seed spells these "*_joint_agnle" (typo fixed).
                i16("yaw_joint_angle", "joint yaw", DEG10),
                i16("roll_joint_angle", "joint roll", DEG10),
                i16("pitch_joint_angle", "joint pitch", DEG10),
                *LIMITS,
                _stiffness("pitch"),
                _stiffness("yaw"),
                _stiffness("roll"),
            ]
        ),
        None,
        "2.3.4.9",
        GIMBAL,
        "unsolicited push (40-byte frame), CmdType reply bit clear",
        handler="_on_push",
    ),
    _cmd(
        "get_version",
        0x0E,
        0x09,
        Layout([Field("device_id", "I", doc="§2.3.3 device id (0x00000001 DJI R SDK)")]),
        Layout(
            [
                RETURN_CODE,
                Field("device_id", "I", doc="§2.3.3 device id"),
                Field("version", "I", doc="0xAABBCCDD = version AA.BB.CC.DD"),
            ]
        ),
        "2.3.4.10",
        HOST,
        "module version query: 4-byte command; its reply has the reply bit and 9 bytes",
    ),
    _cmd(
        "version_push",
        0x0E,
        0x09,
        # The seed types "Version Number" uint8_t with size 4: it is a u32 like in the query reply.
        Layout(
            [
                Field("device_id", "I", doc="§2.3.3 device id of the pushing device"),
                Field("version", "I", doc="0xAABBCCDD = version AA.BB.CC.DD"),
            ]
        ),
        None,
        "2.3.4.10",
        DEVICE,
        "an external device shows its version at 1 Hz: a command frame like get_version, told apart "
        "by direction and length (8 bytes vs 4)",
    ),
    _cmd(
        "external_control",
        0x0E,
        0x0A,
        _union(
            Layout([u8("device_type", "0x00 unknown, 0x01 joystick, 0x02 dial controller")]),
            "device_type",
            {
                0x01: Layout(
                    [
                        i16("pitch_speed", "(adc - middle) / range * 15000", "", -15000, 15000),
                        i16("roll_speed", "(adc - middle) / range * 15000", "", -15000, 15000),
                        i16("yaw_speed", "(adc - middle) / range * 15000", "", -15000, 15000),
                    ]
                ),
                0x02: Layout([i16("dial_speed", "dial speed", "", -2048, 2048)]),
            },
        ),
        None,
        "2.3.4.11",
        DEVICE,
        "joystick or dial pushes; no reply frame",
    ),
    _cmd(
        "get_user_params",
        0x0E,
        0x0B,
        Layout(tail=Tail("read_ids", "TLV ids to read (Figure 23)", decode=list, encode=_byte_list)),
        TlvCodec(RC, "tlv_buffer", USER_PARAMS),
        "2.3.4.12",
        HOST,
        examples=({"read_ids": [0x00, 0x22, 0x23]},),
    ),
    _cmd(
        "set_user_params",
        0x0E,
        0x0C,
        # The seed draws one tlv_id/tlv_length/tlv_data item (with garbled sizes); the text says
        # "separately or in combination", so this is a TLV buffer like the 0x0B reply's.
        TlvCodec(Layout(), "tlv_buffer", USER_PARAMS),
        TlvCodec(RC, "tlv_buffer", USER_PARAMS),
        "2.3.4.13",
        HOST,
    ),
    _cmd(
        "set_operating_mode",
        0x0E,
        0x0D,
        Layout(
            [
                u8("operating_mode", "0xFE: mode remains unchanged"),
                u8(
                    "landscape_and_portrait_mode",
                    "0x00 no switch, 0x01 landscape 0 deg, 0x02 landscape 180 deg, 0x03 portrait 90 deg, "
                    "0x04 portrait -90 deg, 0x05 toggle (auto angle), 0xFF restore default",
                ),
            ]
        ),
        RC,
        "2.3.4.14",
        HOST,
    ),
    _cmd(
        "recenter_selfie",
        0x0E,
        0x0E,
        Layout(
            [
                u8("operating_mode", "0xFE for recenter/selfie", "", 0xFE, 0xFE),
                u8("recenter_and_selfie_command", "0x01 recenter once, 0x02 selfie once", "", 1, 2),
            ]
        ),
        RC,
        "2.3.4.15",
        HOST,
        "Figure 27; same key and shape as follow_mode, chosen by operating_mode == 0xFE",
        when={"operating_mode": 0xFE},
    ),
    _cmd(
        "follow_mode",
        0x0E,
        0x0E,
        Layout(
            [
                u8("operating_mode", "0x00 lock, 0x02 yaw follow, 0x03 sport", "", 0, 3),
                u8("recenter_and_selfie_command", "must be 0x00 when setting a mode", "", 0, 0),
            ]
        ),
        RC,
        "2.3.4.15",
        HOST,
        "Figure 28; same key and shape as recenter_selfie",
    ),
    _cmd(
        "auto_calibration",
        0x0E,
        0x0F,
        TlvCodec(Layout(), "tlv_buffer", (SELF_TUNING_CONTROL,)),
        # The seed draws only a command frame for 0x0F (Figure 29) and reports progress by the 0x10
        # push: no reply frame, sent with CmdType 0 (a gimbal would never answer a reply request).
        None,
        "2.3.4.16",
        HOST,
        "no reply frame: progress comes as calibration_push (0x0E 0x10)",
    ),
    _cmd(
        "calibration_push",
        0x0E,
        0x10,
        TlvCodec(Layout(), "tlv_buffer", (SELF_TUNING_STATUS,)),
        None,
        "2.3.4.17",
        GIMBAL,
        "auto calibration status/progress push",
        handler="_on_calibration",
    ),
    _cmd(
        "active_track",
        0x0E,
        0x11,
        # The seed's field is "Enable ActiveTrack"; only 0x03 (toggle tracking) is defined.
        Layout([u8("enable_active_track", "0x03: switch the start or stop status of tracking")]),
        # The seed draws only a command frame for 0x11 (Figure 31, its caption copied from Figure 30):
        # no reply frame, sent with CmdType 0.
        None,
        "2.3.4.18",
        HOST,
        "no reply frame",
    ),
    _cmd(
        "focus_motor",
        0x0E,
        0x12,
        _union(
            Layout([FOCUS_SUB_ID]),
            "command_sub_id",
            {
                # Figure 32 (size column garbled: data_length is one byte)
                0x01: Layout(
                    [
                        u8("control_type", "0x00 focus control", "", 0, 0),
                        u8("data_length", "0x02: two-byte length", "", 2, 2),
                        Field("absolute_position", "H", doc="focus position", minimum=0, maximum=4095),
                    ]
                ),
                # Figure 33: the seed calls the third byte "Calibrating Vision System Cameras", a
                # mistranslation of the calibration action it carries.
                0x02: Layout(
                    [
                        MOTOR_TYPE,
                        u8(
                            "calibration_command",
                            "0x00 none, 0x01 auto, 0x02 manual calibration, 0x04 set min, 0x05 set max, "
                            "0x06 stop",
                            "",
                            0,
                            6,
                        ),
                    ]
                ),
                0x15: Layout([MOTOR_TYPE]),  # Figure 34: get the current position
            },
        ),
        # Position control (0x01) has no reply frame; calibration and get-position do.
        _union(
            Layout([RETURN_CODE, FOCUS_SUB_ID]),
            "command_sub_id",
            {
                0x02: Layout([MOTOR_TYPE, u8("execution_result", "0x00 success, 0x01 failed", "", 0, 1)]),
                0x15: Layout(
                    [
                        MOTOR_TYPE,
                        u8(
                            "endpoints_calibration_status",
                            "0x01 not calibrated, 0x02 calibrating, 0x03 done",
                            "",
                            1,
                            3,
                        ),
                        Field("current_position", "I", doc="focus position", minimum=0, maximum=4095),
                    ]
                ),
            },
        ),
        "2.3.4.19",
        HOST,
        "sub-commands: 0x01 position (100 Hz, no reply), 0x02 calibration, 0x15 get position",
    ),
    _cmd(
        "camera_control",
        0x0D,
        0x00,
        Layout(
            [
                Field(
                    "camera_control_command",
                    "H",
                    doc="0x0001 shutter, 0x0002 stop shutter, 0x0003 start recording, 0x0004 stop recording, "
                    "0x0005 center focus, 0x000B end center focus",
                    minimum=0x01,
                    maximum=0x0B,
                )
            ]
        ),
        RC,
        "2.3.5.1",
        HOST,
        "third-party camera motion command",
    ),
    _cmd(
        "camera_status",
        0x0D,
        0x01,
        Layout([u8("camera_status_obtain", "0x01: query recording status", "", 1, 1)]),
        Layout([RETURN_CODE, u8("camera_status", "0x00 not recording, 0x02 recording", "", 0, 2)]),
        "2.3.5.2",
        HOST,
        "third-party camera status",
    ),
)


COMMAND_TABLE = Table(_ENTRIES)
TABLE = COMMAND_TABLE.by_key
"""(cmd_set, cmd_id) -> its entries (two for 0x0E 0x09 and 0x0E 0x0E, one elsewhere)."""

BY_NAME: dict[str, CommandSpec] = {e.name: e for e in _ENTRIES}
assert len(BY_NAME) == len(_ENTRIES), "command names must be unique"
COMMANDS: list[str] = list(BY_NAME)


# Legacy-firmware angle replies (issue #16 item 8). Seed 000 §2.3.4.3 (0x0E 0x02 "obtain gimbal
# information") gives one reply layout, byte by byte: 0 return code, 1 data_type, 2-3 yaw, 4-5 roll,
# 6-7 pitch (int16, 0.1°), and says nothing of a different order in the pre-2.2.0.5 reply form (which only
# lacks CmdSet/CmdID). ArduPilot's DJI RS2 driver (libraries/AP_Scripting/drivers/mount-djirs2-driver.lua)
# reads a *legacy* attitude reply as yaw, pitch, roll and the latest one as yaw, roll, pitch, and tells
# users whose mount reads wrong to update the gimbal to 01.04.00.20 or later. So the order of a legacy
# reply is a per-gimbal setting; the default is the seed's. Only the legacy form of get_angle is affected.
LEGACY_ANGLE_ORDERS: tuple[str, ...] = ("yaw_roll_pitch", "yaw_pitch_roll")
SEED_ANGLE_ORDER = "yaw_roll_pitch"
#: command -> order -> the two reply fields whose wire slots are swapped relative to the table's layout
_LEGACY_SWAPS: dict[str, dict[str, tuple[str, str]]] = {"get_angle": {"yaw_pitch_roll": ("roll", "pitch")}}


def _check_angle_order(order: str) -> None:
    if order not in LEGACY_ANGLE_ORDERS:
        raise CommandError(f"legacy angle order {order!r}; valid: {', '.join(LEGACY_ANGLE_ORDERS)}")


def _swap_legacy(name: str, fields: Mapping[str, Any], order: str) -> dict[str, Any]:
    """The fields with the legacy order's slots swapped (the swap is its own inverse: used both ways)."""
    _check_angle_order(order)
    out = dict(fields)
    pair = _LEGACY_SWAPS.get(name, {}).get(order)
    if pair is not None and pair[0] in out and pair[1] in out:
        out[pair[0]], out[pair[1]] = out[pair[1]], out[pair[0]]
    return out


def lookup(command: str | tuple[int, int], *, reply: bool = False) -> CommandSpec:
    """Entry by name, or by (cmd_set, cmd_id) (the first entry at the key; with ``reply``, the first
    one that has a reply frame). Raises CommandError listing the valid names."""
    if isinstance(command, str):
        return BY_NAME.get(command) or COMMAND_TABLE.named(command)  # the latter raises, naming the valid
    entries = COMMAND_TABLE.at((command[0], command[1]))
    if not entries:
        raise UnknownCommandError(f"unknown command key {command!r}; valid names: {', '.join(COMMANDS)}")
    if reply:
        for e in entries:
            if e.reply:
                return e
    return entries[0]


def encode_payload(codec: PayloadCodec, fields: Mapping[str, Any]) -> bytes:
    """Payload bytes for ``fields``: all fields required, seed ranges enforced, hex strings accepted
    for byte fields. Raises LayoutError (a ValueError) naming the field."""
    if isinstance(codec, Layout):
        return codec.encode(_prepare(codec, fields))
    return codec.encode(fields)


def build_frame(
    command: str | tuple[int, int],
    seq: int,
    fields: Mapping[str, Any],
    *,
    reply: bool = False,
    legacy: bool = False,
    cmd_type: int | None = None,
    angle_order: str = SEED_ANGLE_ORDER,
) -> Frame:
    """The :class:`Frame` for a table command (or, with ``reply``, its reply; with ``legacy`` too, in
    the old format without CmdSet/CmdID, its angles in ``angle_order``). Command frames get CmdType 0x03
    (reply required), or 0x00 when the seed says no reply frame comes; replies get reply type 0 unless
    ``cmd_type`` says."""
    spec = lookup(command, reply=reply)
    codecs = spec.reply if reply else spec.request
    if not codecs:
        raise CommandError(f"{spec.name} has no reply frame (seed §{spec.section})")
    values = {**spec.fixed, **fields} if spec.fixed and not reply else dict(fields)
    if reply and legacy:
        values = _swap_legacy(spec.name, values, angle_order)
    try:
        payload = encode_payload(codecs[0], values)
    except LayoutError as e:
        raise CommandError(f"{spec.name}{' reply' if reply else ''}: {e}") from None
    if cmd_type is None:
        cmd_type = 0 if reply else (DEFAULT_CMD_TYPE if wants_reply(spec, values) else 0x00)
    if reply and legacy:
        return Frame(None, None, payload, seq, cmd_type, True)
    return Frame(spec.cmd_set, spec.cmd_id, payload, seq, cmd_type, reply)


def encode_command(
    command: str | tuple[int, int],
    seq: int,
    fields: Mapping[str, Any],
    *,
    reply: bool = False,
    legacy: bool = False,
    cmd_type: int | None = None,
    angle_order: str = SEED_ANGLE_ORDER,
) -> bytes:
    """Frame bytes for a table command by name or (cmd_set, cmd_id); see :func:`build_frame`."""
    try:
        frame = build_frame(
            command, seq, fields, reply=reply, legacy=legacy, cmd_type=cmd_type, angle_order=angle_order
        )
        return encode(frame)
    except CommandError:
        raise
    except ValueError as e:  # frame-level limits (seq range, frame too long)
        raise CommandError(str(e)) from None


def _decode_with(codec: PayloadCodec, data: bytes) -> dict[str, Any]:
    size = codec.size
    if size is not None and len(data) != size:
        raise LayoutError(f"payload is {len(data)} bytes, layout needs {size}")
    return codec.decode(data)


def _key_text(cmd_set: int | None, cmd_id: int | None) -> str:
    return f"0x{cmd_set:02X} 0x{cmd_id:02X}" if cmd_set is not None and cmd_id is not None else "(none)"


def decode_message(frame: Frame) -> Message:
    """Decode a frame's payload by its table entry.

    Command and push frames pick their entry by key (and, at shared keys, by length and ``when``).
    A reply frame is decoded in the latest format (CmdSet/CmdID first); a reply from older firmware
    cannot be decoded without the command it answers: use :func:`decode_reply`. Raises CommandError."""
    if frame.enc & 0xE0:
        raise CommandError("encrypted payload (unsupported)")
    key = frame.key
    entries = COMMAND_TABLE.at(key) if key is not None else None
    if not entries:
        if frame.is_reply:
            raise CommandError(
                f"reply without a known CmdSet/CmdID ({_key_text(frame.cmd_set, frame.cmd_id)}): a legacy "
                "reply? decode it with decode_reply(frame, sent_cmd_set, sent_cmd_id)"
            )
        raise UnknownCommandError(f"unknown command {_key_text(frame.cmd_set, frame.cmd_id)}")
    errors = []
    for spec in entries:
        codecs = spec.reply if frame.is_reply else spec.request
        if not codecs:
            errors.append(f"{spec.name} has no reply frame")
            continue
        try:
            fields = _decode_with(codecs[0], frame.payload)
        except LayoutError as e:
            errors.append(f"{spec.name}{' reply' if frame.is_reply else ''}: {e}")
            continue
        if not frame.is_reply and not spec.matches(fields):
            errors.append(f"{spec.name}: needs {dict(spec.fixed)}")
            continue
        return Message(spec.name, spec.cmd_set, spec.cmd_id, fields, frame.is_reply)
    raise CommandError("; ".join(errors))


def decode_reply(
    frame: Frame,
    cmd_set: int,
    cmd_id: int,
    name: str | None = None,
    *,
    angle_order: str = SEED_ANGLE_ORDER,
) -> Message:
    """Decode a reply against the command it answers (the sent frame with the same SEQ).

    ``angle_order``: how this gimbal's legacy-form angle replies are laid out (``LEGACY_ANGLE_ORDERS``;
    default the seed's yaw, roll, pitch). Latest-form replies always follow the seed.

    Latest format: data = CmdSet CmdID (equal to the sent command's) + reply payload. Legacy format
    (firmware before 2.2.0.5): data = reply payload only, 2 bytes shorter. The two are told apart by
    whether data[0:2] equals the command's CmdSet/CmdID and the rest fits the reply layout, else
    whether the whole data fits it. No ambiguity arises: a legacy reply starts with a return code
    (0x00/0x01/0x02/0xFF), never with a command set (0x0D/0x0E). ``name`` picks the entry at a shared
    key (recenter_selfie vs follow_mode). Raises CommandError when neither format fits."""
    if not frame.is_reply:
        raise CommandError("not a reply frame")
    if frame.enc & 0xE0:
        raise CommandError("encrypted payload (unsupported)")
    spec = lookup(name) if name is not None else lookup((cmd_set, cmd_id), reply=True)
    if spec.key != (cmd_set, cmd_id):
        raise CommandError(f"{spec.name} is {_key_text(*spec.set_and_id)}, not {_key_text(cmd_set, cmd_id)}")
    if not spec.reply:
        raise CommandError(f"{spec.name} has no reply frame (seed §{spec.section})")
    codec = spec.reply[0]
    data = frame.data
    latest_err = "data does not start with the command's CmdSet/CmdID"
    if len(data) >= 2 and data[0] == cmd_set and data[1] == cmd_id:
        try:
            return Message(spec.name, cmd_set, cmd_id, _decode_with(codec, data[2:]), is_reply=True)
        except LayoutError as e:
            latest_err = str(e)
    try:
        fields = _swap_legacy(spec.name, _decode_with(codec, data), angle_order)
        return Message(spec.name, cmd_set, cmd_id, fields, is_reply=True, legacy=True)
    except LayoutError as e:
        raise CommandError(
            f"{spec.name} reply fits neither format: latest: {latest_err}; legacy: {e}"
        ) from None


def payload_examples(spec: CommandSpec, *, reply: bool = False) -> list[dict[str, Any]]:
    """In-range samples for the test matrix: every union arm, every TLV id, plus the entry's extras."""
    codecs = spec.reply if reply else spec.request
    if not codecs:
        return []
    if reply:
        return _examples(codecs[0])
    base = [dict(ex) for ex in spec.examples] or _examples(codecs[0])
    return [{**ex, **spec.fixed} for ex in base]


def _check_table(table: Table) -> None:
    """Import-time sanity: shared keys must be separable by payload size or ``fixed`` values."""
    for key, group in table.by_key.items():
        if len(group) > 1:
            sizes = [g.request[0].size for g in group]
            if len(set(sizes)) != len(sizes) and not all(g.fixed for g in group[:-1]):
                raise AssertionError(f"entries at {key} cannot be told apart")


_check_table(COMMAND_TABLE)
