"""``dji-gateway decode`` / ``encode``: the byte-level tools an integrator debugs a link with.

Owns argument parsing of hex and ``field=value`` input and JSON-lines output; the families and their
options come from the registry (:mod:`adapters.families`), every protocol detail from each family's
describe module. Must not know any family or frame layout itself.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterable, Sequence
from types import ModuleType
from typing import Any, TextIO

from adapters import families
from gateway.jsonsafe import json_safe


def _describe(family: str) -> ModuleType:
    module = families.get(family).describe_module()
    if module is None:
        raise ValueError(f"family {family!r} has no describe module")
    return module


def _hex_to_bytes(chunks: Iterable[str]) -> bytes:
    text = "".join(chunks)
    cleaned = "".join(text.replace("0x", " ").replace("0X", " ").replace(",", " ").split())
    if len(cleaned) % 2:
        raise ValueError("odd number of hex digits")
    return bytes.fromhex(cleaned)


def _read_input(args: Sequence[str], stdin: TextIO) -> str:
    if not args or list(args) == ["-"]:
        return stdin.read()
    return " ".join(args)


def _looks_like_candump(text: str) -> bool:
    return "#" in text or "[" in text


def _cli_options() -> list[families.CliOption]:
    """Every registered family's decode/encode options, each flag once."""
    seen: dict[str, families.CliOption] = {}
    for family in families.all_families():
        for option in family.cli_options:
            seen.setdefault(option.flag, option)
    return list(seen.values())


def _options(ns: argparse.Namespace) -> dict[str, Any]:
    values = ((o.option, getattr(ns, o.option, None)) for o in _cli_options())
    return {name: value for name, value in values if value is not None}


def run_decode(ns: argparse.Namespace, stdin: TextIO, stdout: TextIO) -> int:
    mod = _describe(ns.protocol)
    text = _read_input(ns.hex, stdin)
    if hasattr(mod, "decode_can_lines") and _looks_like_candump(text):
        records = mod.decode_can_lines(text, **_options(ns))  # e.g. rsdk --angle-order: candump too
    else:
        try:
            data = _hex_to_bytes(text.split())
        except ValueError as exc:
            print(
                json.dumps({"protocol": ns.protocol, "valid": False, "error": f"bad hex input: {exc}"}),
                file=stdout,
            )
            return 2
        records = mod.decode_bytes(data, **_options(ns))
    for rec in records:
        print(json.dumps(json_safe(rec), separators=(",", ":"), allow_nan=False), file=stdout)
    return 0


def _parse_value(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def parse_assignments(items: Sequence[str]) -> dict[str, Any]:
    fields: dict[str, Any] = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ValueError(f"expected field=value, got {item!r}")
        fields[name] = _parse_value(value)
    return fields


def run_encode(ns: argparse.Namespace, stdout: TextIO, stderr: TextIO) -> int:
    mod = _describe(ns.protocol)
    try:
        fields = parse_assignments(ns.fields)
        if ns.can and hasattr(mod, "encode_can"):  # --can is for a CAN family (rsdk); others: one frame
            for arb_id, payload in mod.encode_can(ns.command, ns.seq, fields, **_options(ns)):
                print(f"{arb_id:03X}#{payload.hex().upper()}", file=stdout)
            return 0
        frame = mod.encode_command(ns.command, ns.seq, fields, **_options(ns))
    except ValueError as exc:
        print(f"error: {exc}", file=stderr)
        return 2
    print(" ".join(f"{b:02X}" for b in frame), file=stdout)
    return 0


def is_assignment(word: str) -> bool:
    """A ``field=value`` word that argparse left over after an option (``cli.main`` gathers them)."""
    return "=" in word and not word.startswith("-")


def _is_hex_word(word: str) -> bool:
    return word == "-" or not word.startswith("-")


def add_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    dec = sub.add_parser(
        "decode",
        help="decode frames from hex (arguments or stdin) into JSON lines",
        description="Decode hex (or, for rsdk, candump lines) into one JSON object per frame.",
    )
    dec.add_argument("protocol", choices=families.names(), help="the device family: its frame format")
    dec.add_argument("hex", nargs="*", help="hex bytes; '-' or nothing reads stdin")
    _family_options(dec, "decode")
    dec.set_defaults(handler=lambda ns: run_decode(ns, sys.stdin, sys.stdout), trailing=("hex", _is_hex_word))

    enc = sub.add_parser("encode", help="encode one command as a frame (hex)")
    enc.add_argument("protocol", choices=families.names(), help="the device family: its frame format")
    enc.add_argument("command", help="command name from the protocol's table")
    enc.add_argument(
        "--seq", type=lambda s: int(s, 0), default=0, help="the frame's sequence number (decimal or 0x…; 0)"
    )
    enc.add_argument("--can", action="store_true", help="rsdk: print the CAN split as ID#DATA lines")
    enc.add_argument("fields", nargs="*", help="field=value (JSON values; hex strings for bytes)")
    _family_options(enc, "encode")
    enc.set_defaults(
        handler=lambda ns: run_encode(ns, sys.stdout, sys.stderr), trailing=("fields", is_assignment)
    )


def _family_options(p: argparse.ArgumentParser, command: str) -> None:
    for option in _cli_options():
        if command not in option.commands:
            continue
        parse: dict[str, Any] = {"type": _integer} if option.integer else {}
        p.add_argument(
            option.flag, dest=option.option, choices=option.choices, default=None, help=option.help, **parse
        )


def _integer(text: str) -> int:
    return int(text, 0)  # 0x… accepted
