"""C bit-fields inside packed structs (``uint8_t a : 1; uint8_t b : 7;``) for every device family.

Owns :class:`Bits` (one carrier word and its named parts) and :class:`BitLayout` (a
:class:`~adapters.wire.layout.Layout` whose carrier words are exposed as their parts); BitLayout is a
:class:`~adapters.wire.layout.PayloadCodec`. Parts are allocated from bit 0 upward, as GCC/ARMCC lay
them out on little-endian targets, and must cover the carrier exactly, so a payload survives
decode/encode unchanged. Must not know any device, command table or frame. Standard library and
``adapters.wire`` only.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from adapters.wire.layout import Field, Layout, LayoutError

__all__ = ["BitLayout", "Bits"]

# Carrier codes and their widths: unsigned scalars only (a signed or float word has no portable split).
_WORD_BITS = {"B": 8, "H": 16, "I": 32, "Q": 64}


@dataclass(frozen=True, slots=True)
class Bits:
    """Split the unsigned integer field ``field`` into ``parts`` = ``((name, width), ...)``, LSB first.

    One object per carrier keeps the word and its parts together in the table, in C declaration order:
    ``uint8_t health : 1; uint8_t reserved : 7;`` is ``Bits("info", (("health", 1), ("reserved", 7)))``."""

    field: str
    parts: tuple[tuple[str, int], ...]


class BitLayout:
    """A :class:`Layout` whose listed carrier fields are exposed as their bit-field parts.

    Decoding replaces a carrier by its parts in place (field order stays the struct's order; the
    carrier's own name never appears outside); encoding packs the parts back, defaults a missing part
    to 0 and rejects unknown names and values that do not fit their width with :class:`LayoutError`.
    Declaration errors (parts that do not cover the word, a non-unsigned carrier, duplicate names) are
    ``ValueError`` at import time."""

    __slots__ = ("_bits", "layout")

    def __init__(self, fields: Iterable[Field], bits: Iterable[Bits]) -> None:
        self.layout = Layout(fields)
        by_name = {f.name: f for f in self.layout.fields}
        self._bits: dict[str, Bits] = {}
        for b in bits:
            f = by_name.get(b.field)
            if f is None or f.code not in _WORD_BITS or f.count != 1:
                raise ValueError(
                    f"{b.field}: bit fields need an unsigned integer field (one unsigned scalar, "
                    f"code {'/'.join(_WORD_BITS)})"
                )
            if b.field in self._bits:
                raise ValueError(f"{b.field}: bit fields declared twice")
            width = _WORD_BITS[f.code]
            total = sum(w for _, w in b.parts)
            if any(w < 1 for _, w in b.parts) or total != width:
                raise ValueError(
                    f"{b.field}: bit widths must add up to {width} (each >= 1); "
                    f"parts cover {total} of {width} bits"
                )
            self._bits[b.field] = Bits(b.field, tuple((n, w) for n, w in b.parts))
        names = self.field_names
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate field names in {names}")

    @property
    def bits(self) -> tuple[Bits, ...]:
        """The carrier declarations, in struct order."""
        return tuple(self._bits.values())

    @property
    def field_names(self) -> list[str]:
        """Field names as decoded (bit-field parts in place of their carrier field)."""
        out: list[str] = []
        for f in self.layout.fields:
            b = self._bits.get(f.name)
            if b is None:
                out.append(f.name)
            else:
                out.extend(p for p, _ in b.parts)
        return out

    @property
    def names(self) -> list[str]:
        """Same as :attr:`field_names` (the OSDK callers' spelling)."""
        return self.field_names

    @property
    def size(self) -> int | None:
        return self.layout.size

    def decode(self, data: bytes) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name, value in self.layout.decode(data).items():
            b = self._bits.get(name)
            if b is None:
                out[name] = value
                continue
            for part, width in b.parts:
                out[part] = value & ((1 << width) - 1)
                value >>= width
        return out

    def encode(self, values: Mapping[str, Any]) -> bytes:
        known = self.field_names
        unknown = set(values) - set(known)
        if unknown:
            raise LayoutError(f"unknown field(s) {sorted(unknown)}; known: {sorted(known)}")
        raw: dict[str, Any] = {}
        for f in self.layout.fields:
            b = self._bits.get(f.name)
            if b is None:
                if f.name in values:
                    raw[f.name] = values[f.name]
                continue
            packed, shift = 0, 0
            for part, width in b.parts:
                v = values.get(part, 0)
                if isinstance(v, bool):
                    v = int(v)
                if not isinstance(v, int) or not 0 <= v < (1 << width):
                    raise LayoutError(f"{part}: {v!r} does not fit {width} bit(s) (0..{(1 << width) - 1})")
                packed |= v << shift
                shift += width
            raw[f.name] = packed
        return self.layout.encode(raw)

    def example(self) -> dict[str, Any]:
        """The layout's example with part k (1-based) of each word set to ``min(k, max)``: every part
        is non-zero, so a round trip through the example catches a shifted or swapped part."""
        out: dict[str, Any] = {}
        for name, value in self.layout.example().items():
            b = self._bits.get(name)
            if b is None:
                out[name] = value
                continue
            for k, (part, width) in enumerate(b.parts, start=1):
                out[part] = min(k, (1 << width) - 1)
        return out
