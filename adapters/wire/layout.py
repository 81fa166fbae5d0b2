"""Declarative little-endian struct layouts: the one place payload bytes become named fields.

Every command table in ``adapters/*/commands.py`` describes payloads with :class:`Layout`, so
encoders, decoders, the ``decode`` CLI and the test matrix all derive from one declaration
instead of hand-written ``struct`` calls. Values stay in wire units (0.1°, radians, raw ADC).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from adapters.errors import LayoutError

__all__ = ["Field", "Layout", "LayoutError", "PayloadCodec", "Tail"]

_INT_RANGES = {
    "B": (0, 0xFF),
    "b": (-0x80, 0x7F),
    "H": (0, 0xFFFF),
    "h": (-0x8000, 0x7FFF),
    "I": (0, 0xFFFFFFFF),
    "i": (-0x80000000, 0x7FFFFFFF),
    "Q": (0, 0xFFFFFFFFFFFFFFFF),
    "q": (-0x8000000000000000, 0x7FFFFFFFFFFFFFFF),
}
_FLOATS = {"f", "d"}


@dataclass(frozen=True, slots=True)
class Field:
    """One named field: ``code`` is a struct code (B b H h I i Q q f d), ``count`` > 1 makes a list,
    ``code='s'`` with ``count`` N is an N-byte string kept as ``bytes``."""

    name: str
    code: str
    count: int = 1
    unit: str = ""
    doc: str = ""
    minimum: float | None = None
    maximum: float | None = None

    @property
    def struct_code(self) -> str:
        if self.code == "s":
            return f"{self.count}s"
        return f"{self.count}{self.code}" if self.count > 1 else self.code

    @property
    def is_float(self) -> bool:
        return self.code in _FLOATS

    def default(self) -> Any:
        if self.code == "s":
            return bytes(self.count)
        zero: float | int = 0.0 if self.is_float else 0
        return [zero] * self.count if self.count > 1 else zero

    def check(self, value: Any) -> Any:
        """Coerce ``value`` to the wire type or raise :class:`LayoutError` naming the field."""
        if self.code == "s":
            if isinstance(value, str):
                value = value.encode()
            if not isinstance(value, bytes | bytearray):
                raise LayoutError(f"{self.name}: expected bytes, got {type(value).__name__}")
            if len(value) > self.count:
                raise LayoutError(f"{self.name}: at most {self.count} bytes, got {len(value)}")
            return bytes(value).ljust(self.count, b"\0")
        if self.count > 1:
            if not isinstance(value, list | tuple):
                raise LayoutError(f"{self.name}: expected a list of {self.count}")
            if len(value) > self.count:
                raise LayoutError(f"{self.name}: at most {self.count} items, got {len(value)}")
            items = [self._scalar(v) for v in value]
            return items + [self.default()[0]] * (self.count - len(items))
        return self._scalar(value)

    def _scalar(self, value: Any) -> int | float:
        if isinstance(value, bool):
            value = int(value)
        if self.is_float:
            if not isinstance(value, int | float):
                raise LayoutError(f"{self.name}: expected a number, got {type(value).__name__}")
            number = float(value)
            if math.isnan(number) or math.isinf(number):
                raise LayoutError(f"{self.name}: must be finite")
            # never -0.0 on the wire (+ 0.0 turns it into 0.0 and leaves every other value as it is): a
            # negated zero (a stick's "-x" at rest) reads as a sign to a device or a log, not as nothing
            return number + 0.0
        if not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            else:
                raise LayoutError(f"{self.name}: expected an integer, got {value!r}")
        integer: int = value
        lo, hi = _INT_RANGES[self.code]
        if not lo <= integer <= hi:
            raise LayoutError(f"{self.name}: {integer} outside {self.code} range {lo}..{hi}")
        return integer


class PayloadCodec(Protocol):
    """What a command table entry needs from a payload description (a Layout or a custom codec)."""

    @property
    def size(self) -> int | None: ...  # fixed size in bytes, None when variable

    def decode(self, data: bytes) -> dict[str, Any]: ...

    def encode(self, values: Mapping[str, Any]) -> bytes: ...

    def example(self) -> dict[str, Any]: ...


@dataclass(frozen=True, slots=True)
class Tail:
    """A variable-length tail after the fixed fields (a TLV buffer, a string): kept as bytes unless
    ``decode``/``encode`` turn it into a value."""

    name: str
    doc: str = ""
    decode: Callable[[bytes], Any] | None = None
    encode: Callable[[Any], bytes] | None = None
    max_len: int = 1024


@dataclass(frozen=True)
class Layout:
    """A packed little-endian layout: fixed ``fields`` then an optional variable ``tail``."""

    fields: tuple[Field, ...]
    tail: Tail | None = None
    _struct: struct.Struct = field(init=False, repr=False, compare=False)

    def __init__(self, fields: Iterable[Field] = (), tail: Tail | None = None) -> None:
        fields = tuple(fields)
        names = [f.name for f in fields] + ([tail.name] if tail else [])
        if len(set(names)) != len(names):
            raise ValueError(f"duplicate field names in {names}")
        object.__setattr__(self, "fields", fields)
        object.__setattr__(self, "tail", tail)
        object.__setattr__(self, "_struct", struct.Struct("<" + "".join(f.struct_code for f in fields)))

    @property
    def fixed_size(self) -> int:
        return self._struct.size

    @property
    def size(self) -> int | None:
        return None if self.tail else self._struct.size

    def decode(self, data: bytes) -> dict[str, Any]:
        n = self._struct.size
        if len(data) < n or (self.tail is None and len(data) != n):
            want = f"at least {n}" if self.tail else str(n)
            raise LayoutError(f"payload is {len(data)} bytes, layout needs {want}")
        values = self._struct.unpack_from(data)
        out: dict[str, Any] = {}
        i = 0
        for f in self.fields:
            if f.count > 1 and f.code != "s":
                out[f.name] = list(values[i : i + f.count])
                i += f.count
            else:
                out[f.name] = values[i]
                i += 1
        if self.tail is not None:
            rest = bytes(data[n:])
            out[self.tail.name] = self.tail.decode(rest) if self.tail.decode else rest
        return out

    def encode(self, values: Mapping[str, Any]) -> bytes:
        known = {f.name for f in self.fields} | ({self.tail.name} if self.tail else set())
        unknown = set(values) - known
        if unknown:
            raise LayoutError(f"unknown field(s) {sorted(unknown)}; known: {sorted(known)}")
        flat: list[Any] = []
        for f in self.fields:
            v = f.check(values.get(f.name, f.default()))
            if f.count > 1 and f.code != "s":
                flat.extend(v)
            else:
                flat.append(v)
        head = self._struct.pack(*flat)
        if self.tail is None:
            return head
        raw = values.get(self.tail.name, b"")
        if self.tail.encode is not None and not isinstance(raw, bytes | bytearray):
            raw = self.tail.encode(raw)
        if isinstance(raw, str):
            raw = bytes.fromhex(raw)
        if not isinstance(raw, bytes | bytearray):
            raise LayoutError(f"{self.tail.name}: expected bytes")
        if len(raw) > self.tail.max_len:
            raise LayoutError(f"{self.tail.name}: at most {self.tail.max_len} bytes")
        return head + bytes(raw)

    def example(self) -> dict[str, Any]:
        """A deterministic, in-range sample used by the round-trip test matrix."""
        out: dict[str, Any] = {}
        for k, f in enumerate(self.fields, start=1):
            if f.code == "s":
                out[f.name] = bytes((k + j) & 0x7F for j in range(f.count))
                continue
            lo, hi = (f.minimum, f.maximum)
            if f.is_float:
                base = 1.5 * k if lo is None else float(lo) + (float(hi or lo) - float(lo)) / 3
                sample: float | int = (
                    struct.unpack("<f", struct.pack("<f", base))[0] if f.code == "f" else base
                )
            else:
                tlo, thi = _INT_RANGES[f.code]
                lo_i = tlo if lo is None else int(lo)
                hi_i = thi if hi is None else int(hi)
                sample = min(max(k, lo_i), hi_i)
            out[f.name] = [sample] * f.count if f.count > 1 else sample
        if self.tail is not None:
            out[self.tail.name] = self.tail.decode(b"") if self.tail.decode else b""
        return out
