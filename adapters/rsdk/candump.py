"""Parse can-utils ``candump`` output into ``(arbitration_id, bytes)`` tuples.

Two shapes are understood, with or without a leading ``(timestamp)``:

* the screen format ``  can0  222   [8]  AA 1A 00 03 00 00 00 00`` (also ``-x`` extra columns such
  as ``RX - -`` before the id and ``-a``'s trailing ASCII column), and
* the log format (``candump -l`` / ``-L``) ``(1.0) can0 222#AA1A000300000000`` (CAN FD ``##<flags>``
  accepted, its flags nibble dropped).

Remote-request, error and unparseable lines give ``None``. Owns text parsing only; it must not
know R SDK framing or any bus library.
"""

from __future__ import annotations

import re

__all__ = ["parse_line", "parse_lines"]

_LOG = re.compile(
    r"^\s*(?:\(\s*[\d.]+\s*\)\s*)?(?:\S+\s+)?([0-9A-Fa-f]{1,8})#(#[0-9A-Fa-f])?([0-9A-Fa-f]*)\s*$"
)
_SCREEN = re.compile(
    r"^\s*(?:\(\s*[\d.]+\s*\)\s*)?\S+\s+(?:.*?\s)?([0-9A-Fa-f]{1,8})\s+\[(\d{1,2})\]\s*((?:[0-9A-Fa-f]{2}\s*)*)(?:'.*')?\s*$"
)


def parse_line(line: str) -> tuple[int, bytes] | None:
    """One candump line -> (arbitration id, data), or None when it is not a data frame."""
    m = _LOG.match(line)
    if m:
        hexdata = m.group(3)
        if len(hexdata) % 2:
            return None
        return int(m.group(1), 16), bytes.fromhex(hexdata)
    m = _SCREEN.match(line)
    if m:
        data = bytes.fromhex(m.group(3))
        if len(data) != int(m.group(2)):
            return None
        return int(m.group(1), 16), data
    return None


def parse_lines(text: str) -> list[tuple[int, bytes]]:
    """Every data frame of a candump text, in order (other lines skipped)."""
    out = []
    for line in text.splitlines():
        item = parse_line(line)
        if item is not None:
            out.append(item)
    return out
