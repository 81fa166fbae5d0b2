"""The command-table layer every device family's ``commands.py`` is built on.

Owns: :class:`CommandSpec` (one table entry: name, key, request and reply payloads, the variant it
belongs to, values that pick it, its push handler), :class:`Table` (the entries of one family,
grouped by key and by name, looked up by variant), :class:`TaggedUnion` (a payload whose shape a tag
byte chooses), :class:`Message` (a decoded payload), :class:`Delivery` (how a sender resends an
acknowledged command) and :func:`bind_handlers` (push handlers, declared in the table entry, bound to
an adapter class at import).

What differs between families is a parameter of this layer, not a copy of it:

* **variants**: the Onboard SDK's firmware generations (``"new"``, ``"m100"``) and the referee
  system's seasons (``"2024"``..``"2026"``) are ``CommandSpec.variant`` values; an entry with
  ``variant=None`` exists in every variant. :meth:`Table.named` and :meth:`Table.at` filter by it.
* **legacy replies** (R SDK firmware before 2.2.0.5 answers without CmdSet/CmdID): ``Message.legacy``
  says which format a reply came in; the R SDK's ``decode_reply`` tries both against one entry.
* **shared keys**: several entries at one key are told apart by payload size and by ``fixed``
  values (R SDK 0x0E 0x0E, Onboard SDK 0x01 0x03).

Must not know frames, links, clocks or the Cloud API (sans-I/O: standard library, ``adapters.wire``
and ``adapters.errors`` only). Values stay in wire units.
"""

from __future__ import annotations

import types
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple, TypeVar

from adapters.errors import LayoutError, UnknownCommandError
from adapters.wire.layout import Layout, PayloadCodec

__all__ = [
    "EMPTY",
    "CommandSpec",
    "Delivery",
    "Message",
    "Table",
    "TaggedUnion",
    "bind_handlers",
    "sizes_text",
]

EMPTY: Mapping[Any, Any] = types.MappingProxyType({})


@dataclass(frozen=True, slots=True)
class Delivery:
    """How a sender delivers a command on a link with acknowledged sessions (DJI's v1 frame):
    ``session`` 0 none, 1 tolerant, 2 = a free session 2..31, resent ``retries`` times ``timeout``
    seconds apart. Families whose replies are matched otherwise (R SDK by SEQ, the referee link
    never) keep the default and do not read it."""

    session: int = 2
    timeout: float = 0.5
    retries: int = 2


NO_ACK = Delivery(session=0, retries=0)


@dataclass(frozen=True, slots=True)
class CommandSpec:
    """One command, push or reply on the wire.

    ``request`` payloads: the first is what we encode, any of them decodes (chosen by size, then by
    ``fixed``). ``reply`` likewise; empty means no reply frame (or ACK) comes. ``reply_codes`` are the
    documented meanings of a reply's code. ``variant`` None means every variant of the family.
    ``defaults`` fill missing request fields on encode; ``fixed`` values are forced on encode and must
    match on decode (they pick this entry among several at one key). ``handler`` names the adapter
    method a received payload of this entry goes to (checked by :func:`bind_handlers`).
    ``cmd_set`` is None for families keyed by one number (the referee system's cmd_id)."""

    name: str
    cmd_set: int | None
    cmd_id: int
    request: tuple[PayloadCodec, ...]
    reply: tuple[PayloadCodec, ...] = ()
    reply_codes: Mapping[int, str] = field(default_factory=lambda: EMPTY)
    direction: str = ""
    variant: str | None = None
    defaults: Mapping[str, Any] = field(default_factory=lambda: EMPTY)
    fixed: Mapping[str, Any] = field(default_factory=lambda: EMPTY)
    section: str = ""
    doc: str = ""
    delivery: Delivery = Delivery()
    examples: tuple[Mapping[str, Any], ...] = ()
    handler: str = ""

    @property
    def key(self) -> tuple[int | None, int]:
        return (self.cmd_set, self.cmd_id)

    @property
    def set_and_id(self) -> tuple[int, int]:
        """``(cmd_set, cmd_id)`` of an entry of a family keyed by both (R SDK, Onboard SDK)."""
        if self.cmd_set is None:
            raise ValueError(f"{self.name} is keyed by cmd_id alone")
        return (self.cmd_set, self.cmd_id)

    def fits(self, variant: str | None) -> bool:
        """Whether this entry exists in ``variant`` (None asks for entries of every variant)."""
        return self.variant is None or variant is None or self.variant == variant

    def values(self, fields: Mapping[str, Any] | None) -> dict[str, Any]:
        """The request values to encode: ``defaults``, then ``fields``, then ``fixed`` (a field given
        with another value than its fixed one is a :class:`LayoutError`)."""
        given = dict(fields or {})
        out = {**self.defaults, **given}
        for k, v in self.fixed.items():
            if k in given and given[k] != v:
                raise LayoutError(f"{self.name}: {k} is fixed at {v!r}")
            out[k] = v
        return out

    def matches(self, fields: Mapping[str, Any]) -> bool:
        """Whether decoded request fields carry this entry's ``fixed`` values."""
        if not self.fixed:
            return True
        return all(fields.get(k) == v for k, v in self.fixed.items())


class Message(NamedTuple):
    """A decoded command, push or reply: ``fields`` maps the document's names to wire-unit values.

    ``cmd_set`` is None for families keyed by one number; ``legacy`` is True for an R SDK reply in
    the pre-2.2.0.5 format (no CmdSet/CmdID in its data). A named tuple: one is built per frame, and a
    frozen dataclass of six fields costs about five times as much to build."""

    name: str
    cmd_set: int | None
    cmd_id: int
    fields: dict[str, Any]
    is_reply: bool = False
    legacy: bool = False


def sizes_text(codecs: Iterable[PayloadCodec]) -> str:
    """``"12 or 16 bytes"``: what a list of payload layouts accepts."""
    sizes = [c.size for c in codecs]
    return " or ".join("variable" if s is None else f"{s}" for s in sizes) + " bytes"


def _group(
    specs: Iterable[CommandSpec], by: Callable[[CommandSpec], Any]
) -> dict[Any, tuple[CommandSpec, ...]]:
    out: dict[Any, tuple[CommandSpec, ...]] = {}
    for s in specs:
        out[by(s)] = (*out.get(by(s), ()), s)
    return out


class Table:
    """One family's entries, grouped by key and by name (in table order: decode preference).

    ``variant_noun`` names the variants in messages ("firmware", "season"); ``variants`` lists them
    (empty: the family has none)."""

    __slots__ = ("_at", "_named", "by_key", "by_name", "names", "specs", "variant_noun", "variants")

    def __init__(
        self, specs: Iterable[CommandSpec], *, variants: Sequence[str] = (), variant_noun: str = "variant"
    ) -> None:
        self.specs = tuple(specs)
        self.variants = tuple(variants)
        self.variant_noun = variant_noun
        self.by_key: dict[tuple[int | None, int], tuple[CommandSpec, ...]] = _group(
            self.specs, lambda s: s.key
        )
        self.by_name: dict[str, tuple[CommandSpec, ...]] = _group(self.specs, lambda s: s.name)
        self.names: tuple[str, ...] = tuple(self.by_name)
        for s in self.specs:
            if s.variant is not None and s.variant not in self.variants:
                raise ValueError(f"{s.name}: {variant_noun} {s.variant!r} is not one of {self.variants}")
        # lookups are on every frame's path: answered from dicts built once
        self._at: dict[tuple[tuple[int | None, int], str | None], tuple[CommandSpec, ...]] = {}
        self._named: dict[tuple[str, str | None], CommandSpec] = {}
        for variant in (None, *self.variants):
            for key, group in self.by_key.items():
                self._at[key, variant] = tuple(s for s in group if s.fits(variant))
            for name, group in self.by_name.items():
                fit = [s for s in group if s.fits(variant)]
                if fit:
                    self._named[name, variant] = fit[0]

    def unknown(self, name: str) -> UnknownCommandError:
        return UnknownCommandError(f"unknown command {name!r}; valid: {', '.join(self.names)}", name=name)

    def named(self, name: str, variant: str | None = None) -> CommandSpec:
        """The entry called ``name`` in ``variant`` (the first, when several fit)."""
        spec = self._named.get((name, variant))
        if spec is not None:
            return spec
        if variant is not None and variant not in self.variants:  # a variant this table does not list
            for spec in self.by_name.get(name, ()):
                if spec.fits(variant):
                    return spec
        if name in self.by_name:
            raise UnknownCommandError(
                f"command {name!r} does not exist on {self.variant_noun} {variant!r}", name=name
            )
        raise self.unknown(name)

    def at(self, key: tuple[int | None, int], variant: str | None = None) -> tuple[CommandSpec, ...]:
        """The entries at ``key`` that exist in ``variant``, in decode-preference order."""
        if variant is None:  # every entry fits
            return self.by_key.get(key, ())
        found = self._at.get((key, variant))
        if found is None:
            return tuple(s for s in self.by_key.get(key, ()) if s.fits(variant))  # a variant not listed
        return found


_T = TypeVar("_T")


def bind_handlers(cls: type[_T], table: Table) -> dict[str, Callable[[_T, Mapping[str, Any]], None]]:
    """Entry name → the method of ``cls`` its ``handler`` names, for every entry that names one.

    Called at import, next to the adapter class: a handler named in the table that the class lacks
    raises ``TypeError`` there, and a renamed entry keeps its handler (the name lives in the entry)."""
    out: dict[str, Callable[[_T, Mapping[str, Any]], None]] = {}
    missing: list[str] = []
    for spec in table.specs:
        if not spec.handler:
            continue
        fn = getattr(cls, spec.handler, None)
        if not callable(fn):
            missing.append(f"{spec.name} → {cls.__name__}.{spec.handler}")
            continue
        known = out.setdefault(spec.name, fn)
        if known is not fn:
            raise TypeError(f"{spec.name}: entries name two handlers ({known.__name__}, {spec.handler})")
    if missing:
        raise TypeError(f"push handlers missing: {', '.join(missing)}")
    return out


def field_names(codec: PayloadCodec) -> list[str]:
    """The public field names of a layout, in wire order (tail last); [] for a custom codec."""
    names = getattr(codec, "field_names", None)
    if isinstance(names, list):
        return names
    if isinstance(codec, Layout):
        return [f.name for f in codec.fields] + ([codec.tail.name] if codec.tail else [])
    return []


Prepare = Callable[[Layout, Mapping[str, Any]], Mapping[str, Any]]


def _as_is(layout: Layout, values: Mapping[str, Any]) -> Mapping[str, Any]:
    return values


class TaggedUnion:
    """A payload whose shape a tag value chooses.

    Two spellings of one idea: with a ``head`` layout (the tag among its fields), the payload is the
    head, then the arm for the tag (R SDK 0x0E 0x0A ``device_type``, 0x0E 0x12 ``command_sub_id``);
    without one, the tag is the first byte of every arm, and each arm is the whole payload (Onboard SDK
    mission status and event pushes). An arm is one or more candidate layouts, chosen by size on
    decode and by field names on encode; tags without an arm use ``default`` (documented for
    ``default_keys``). ``prepare`` checks head and arm values before they are encoded (the R SDK's
    strict presence and range checks); by default values go to the layouts as given."""

    __slots__ = ("arms", "default", "default_keys", "head", "prepare", "tag")

    def __init__(
        self,
        tag: str,
        arms: Mapping[int, PayloadCodec | tuple[PayloadCodec, ...]],
        *,
        head: Layout | None = None,
        default: tuple[PayloadCodec, ...] = (),
        default_keys: tuple[int, ...] = (),
        prepare: Prepare = _as_is,
    ) -> None:
        if head is not None and tag not in {f.name for f in head.fields}:
            raise ValueError(f"tag {tag!r} is not a head field")
        self.tag = tag
        self.head = head
        self.arms: dict[int, tuple[PayloadCodec, ...]] = {
            k: a if isinstance(a, tuple) else (a,) for k, a in arms.items()
        }
        self.default = default
        self.default_keys = default_keys
        self.prepare = prepare

    @property
    def size(self) -> int | None:
        sizes = {c.size for cs in (*self.arms.values(), self.default) for c in cs}
        only = sizes.pop() if len(sizes) == 1 else None
        if only is None or self.head is None:
            return only
        return self.head.fixed_size + only

    def _arm(self, tag_value: Any) -> tuple[PayloadCodec, ...]:
        arm = self.arms.get(tag_value, self.default) if isinstance(tag_value, int) else ()
        if not arm:
            if self.head is None:
                raise LayoutError(f"unknown {self.tag} {tag_value!r}; known: {sorted(self.arms)}")
            known = ", ".join(f"0x{t:02X}" for t in self.arms)
            raise LayoutError(f"{self.tag} {tag_value!r} unknown; known: {known}")
        return arm

    def decode(self, data: bytes) -> dict[str, Any]:
        if self.head is None:
            if not data:
                raise LayoutError(f"empty payload: no {self.tag}")
            codecs = self._arm(data[0])
            for c in codecs:
                if c.size is None or c.size == len(data):
                    return c.decode(data)
            raise LayoutError(
                f"{self.tag} {data[0]}: payload is {len(data)} bytes, expected {sizes_text(codecs)}"
            )
        n = self.head.fixed_size
        if len(data) < n:
            raise LayoutError(f"payload is {len(data)} bytes, needs at least {n}")
        out = self.head.decode(data[:n])
        out.update(self._arm(out[self.tag])[0].decode(data[n:]))
        return out

    def encode(self, values: Mapping[str, Any]) -> bytes:
        if self.head is None:
            if self.tag not in values:
                raise LayoutError(f"{self.tag} is required to choose the payload shape")
            codecs = self._arm(values[self.tag])
            keys = set(values)
            exact = [c for c in codecs if set(field_names(c)) == keys]
            covering = [c for c in codecs if keys <= set(field_names(c))]
            return (exact or covering or list(codecs))[0].encode(values)
        if self.tag not in values:
            raise LayoutError(f"missing field {self.tag!r} (one of {[hex(t) for t in self.arms]})")
        arm = self._arm(values[self.tag])[0]
        if not isinstance(arm, Layout):
            raise LayoutError(f"{self.tag} {values[self.tag]!r}: arm is not a plain layout")
        head_names = {f.name for f in self.head.fields}
        arm_names = {f.name for f in arm.fields}
        unknown = set(values) - head_names - arm_names
        if unknown:
            raise LayoutError(f"unknown field(s) {sorted(unknown)}; known: {sorted(head_names | arm_names)}")
        head = self.prepare(self.head, {k: v for k, v in values.items() if k in head_names})
        tail = self.prepare(arm, {k: v for k, v in values.items() if k in arm_names})
        return self.head.encode(head) + arm.encode(tail)

    def example(self) -> dict[str, Any]:
        return self.examples()[0]

    def examples(self) -> list[dict[str, Any]]:
        """One in-range sample per arm layout (the round-trip matrix covers every arm)."""
        if self.head is not None:
            return [{**self.head.example(), self.tag: t, **arm[0].example()} for t, arm in self.arms.items()]
        out: list[dict[str, Any]] = []
        shapes = [*self.arms.items(), *((k, self.default) for k in self.default_keys)]
        for key, codecs in shapes:
            for c in codecs:
                ex = dict(c.example())
                ex[self.tag] = key
                out.append(c.decode(c.encode(ex)))
        return out
