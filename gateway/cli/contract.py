"""The Cloud API contract for people: ``dji-gateway methods [METHOD]`` and the checks ``send`` runs
before it publishes anything.

Owns reading the registry (the same one the gateway validates with, extension methods included) as
a person needs it: which methods exist on which topic, their fields (type, range, required, meaning),
and a request's problems in words — an unknown method with the closest names, an unknown field with
the fields the method takes, every validation error as ``data.x: Input should be …``. Owns turning
``field=value`` text into typed values *by the contract*: a field the contract says is a string keeps
its text (``payload_index=1001`` stays ``"1001"``), other values are JSON when they parse.
Knows nothing of MQTT, devices or bytes; the console (``gateway.cli.console``) publishes what passes here.
"""

from __future__ import annotations

import argparse
import difflib
import json
import sys
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

from pydantic import ValidationError

from schemas import TopicKind
from schemas.registry import MethodSpec, Registry

__all__ = ["Check", "FieldDoc", "add_parsers", "check_request", "closest", "fields_of", "registry"]

#: The topics a person sends on (services; drc/down with ``send --drc``), in the order ``methods`` lists them.
SENT_KINDS = (TopicKind.SERVICES, TopicKind.DRC_DOWN)


@cache
def registry() -> Registry:
    """The gateway's registry: the seed's methods and every family's extensions (built once)."""
    from gateway.app import build_registry

    return build_registry()


# ------------------------------------------------------------------------------------------ fields
@dataclass(frozen=True, slots=True)
class FieldDoc:
    """One field of a request body, as ``methods METHOD`` shows it (nested fields are dotted)."""

    name: str
    type: str
    required: bool
    detail: str  # range, enum, length, default
    description: str


def _resolve(schema: dict[str, Any], root: dict[str, Any]) -> dict[str, Any]:
    """Follow ``$ref`` (into ``root``'s ``$defs``) and merge the referring keys (description) over it."""
    while "$ref" in schema:
        target = root.get("$defs", {}).get(schema["$ref"].rsplit("/", 1)[-1], {})
        schema = {**target, **{k: v for k, v in schema.items() if k != "$ref"}}
    return schema


def _variants(schema: dict[str, Any], root: dict[str, Any]) -> list[dict[str, Any]]:
    """The alternatives of an ``anyOf``/``oneOf`` (one element otherwise), each resolved."""
    schema = _resolve(schema, root)
    alts = schema.get("anyOf") or schema.get("oneOf")
    if not alts:
        return [schema]
    return [v for alt in alts for v in _variants(alt, root)]


def _type_name(schema: dict[str, Any], root: dict[str, Any]) -> str:
    names = []
    for v in _variants(schema, root):
        if "enum" in v:
            names.append(" | ".join(json.dumps(e) for e in v["enum"]))
        elif "const" in v:
            names.append(json.dumps(v["const"]))
        elif v.get("type") == "array":
            names.append(f"list of {_type_name(v.get('items', {}), root)}")
        elif v.get("type") == "object" and "properties" in v:
            names.append("object")
        elif v.get("type") is not None:
            names.append(str(v["type"]))
    return " | ".join(dict.fromkeys(n for n in names if n != "null")) or "any"


def _detail(schema: dict[str, Any], root: dict[str, Any], name: str = "x") -> str:
    """Ranges (written with the field's ``name``: ``0 ≤ y ≤ 1``), lengths, patterns, the default."""
    parts = []
    for v in _variants(schema, root):
        lo, hi = v.get("minimum", v.get("exclusiveMinimum")), v.get("maximum", v.get("exclusiveMaximum"))
        if lo is not None or hi is not None:
            left = "" if lo is None else f"{lo} {'<' if 'exclusiveMinimum' in v else '≤'} "
            right = "" if hi is None else f" {'<' if 'exclusiveMaximum' in v else '≤'} {hi}"
            parts.append(f"{left}{name}{right}")
        if "maxLength" in v:
            parts.append(f"≤ {v['maxLength']} chars")
        if "pattern" in v:
            parts.append(f"pattern {v['pattern']}")
    schema = _resolve(schema, root)
    if schema.get("default") is not None:
        parts.append(f"default {json.dumps(schema['default'])}")
    return ", ".join(dict.fromkeys(parts))


def _object(schema: dict[str, Any], root: dict[str, Any]) -> dict[str, Any] | None:
    """The object schema among ``schema``'s variants that has properties (a nested model), if any."""
    for v in _variants(schema, root):
        if v.get("type") == "object" and "properties" in v:
            return v
    return None


def fields_of(spec: MethodSpec) -> list[FieldDoc]:
    """Every field of the method's request body, nested ones dotted (``mqtt_broker.address``)."""
    root = spec.data.model_json_schema(by_alias=True)

    def walk(obj: dict[str, Any], prefix: str) -> Iterator[FieldDoc]:
        required = set(obj.get("required", ()))
        for name, prop in obj.get("properties", {}).items():
            nested = _object(prop, root)
            resolved = _resolve(prop, root)
            yield FieldDoc(
                f"{prefix}{name}",
                _type_name(prop, root),
                name in required,
                _detail(prop, root, name),
                " ".join(str(resolved.get("description", "")).split("\n\n")[0].split()),
            )
            if nested is not None:
                yield from walk(nested, f"{prefix}{name}.")

    return list(walk(root, ""))


def closest(word: str, choices: Sequence[str], n: int = 3) -> list[str]:
    """The names most like ``word`` (difflib's ratio, cut-off 0.6), best first."""
    return difflib.get_close_matches(word, list(choices), n=n, cutoff=0.6)


def _wants_text(schema: dict[str, Any] | None, root: dict[str, Any]) -> bool:
    """True when every alternative the contract allows is a string (so ``1001`` must stay text)."""
    if schema is None:
        return False
    variants = [v for v in _variants(schema, root) if v.get("type") != "null"]

    def text_only(v: dict[str, Any]) -> bool:
        if "enum" in v:
            return all(isinstance(e, str) for e in v["enum"])
        if "const" in v:
            return isinstance(v["const"], str)
        return v.get("type") == "string"

    return bool(variants) and all(text_only(v) for v in variants)


# ------------------------------------------------------------------------------------------ checking
@dataclass(frozen=True, slots=True)
class Check:
    """What :func:`check_request` found: the typed ``data`` and, when it must not be sent, why
    (``problems``, one line each) and what to try (``hint``)."""

    data: dict[str, Any]
    problems: tuple[str, ...] = ()
    hint: str = ""

    @property
    def ok(self) -> bool:
        return not self.problems


def _kind_of(method: str, reg: Registry) -> TopicKind | None:
    for kind in SENT_KINDS:
        if reg.spec(kind, method) is not None:
            return kind
    return None


def _typed(
    pairs: Sequence[str], base: dict[str, Any], root: dict[str, Any]
) -> tuple[dict[str, Any], list[str]]:
    """``field=value`` words over ``base`` (``--data``), each value typed by the contract; unknown
    field names are problems, named with the fields their object takes."""
    out = dict(base)
    problems: list[str] = []
    for pair in pairs:
        key, sep, text = pair.partition("=")
        if not sep or not key:
            raise ValueError(f"expected field=value, got {pair!r}")
        node: dict[str, Any] = out
        obj: dict[str, Any] | None = root
        *parents, leaf = key.split(".")
        for name in parents:
            child = node.setdefault(name, {})
            if not isinstance(child, dict):
                raise ValueError(f"{key}: {name} is already a value")
            node = child
            prop = (obj or {}).get("properties", {}).get(name)
            obj = _object(prop, root) if prop is not None else None
        prop = (obj or {}).get("properties", {}).get(leaf) if obj is not None else None
        value: Any = text
        if not _wants_text(prop, root) or text.startswith('"'):
            try:
                value = json.loads(text)
            except ValueError:
                value = text
        node[leaf] = value
    problems += _unknown(out, root, root, "")
    return out, problems


def _unknown(data: dict[str, Any], obj: dict[str, Any], root: dict[str, Any], prefix: str) -> list[str]:
    props = obj.get("properties", {})
    if not props and obj.get("additionalProperties", True) is not False:
        return []  # a free-form object
    problems = []
    for key, value in data.items():
        if key not in props:
            near = closest(key, list(props), 1)
            takes = ", ".join(props) or "no fields"
            guess = f" (did you mean {prefix}{near[0]}?)" if near else ""
            owner = prefix[:-1] or "the method"
            problems.append(f"unknown field {prefix}{key}{guess}: {owner} takes {takes}")
            continue
        nested = _object(props[key], root)
        if nested is not None and isinstance(value, dict):
            problems += _unknown(value, nested, root, f"{prefix}{key}.")
    return problems


def _error_line(err: Any) -> str:
    loc = [str(p) for p in err["loc"]]
    where = ".".join(loc[loc.index("data") :]) if "data" in loc else ".".join(loc[1:] or loc)
    return f"{where}: {err['msg']}"


def check_request(
    method: str, pairs: Sequence[str], base: dict[str, Any] | None = None, *, drc: bool = False
) -> Check:
    """Type ``pairs`` by the contract and check the request as the gateway will: the method exists on
    the topic it is sent to, every field is one the method takes, and the body validates.
    Raises ValueError for words that are not ``field=value``."""
    reg = registry()
    kind = TopicKind.DRC_DOWN if drc else TopicKind.SERVICES
    spec = reg.spec(kind, method)
    if spec is None:
        other = _kind_of(method, reg)
        if other is TopicKind.DRC_DOWN:
            return Check({}, (f"{method} travels on drc/down",), "add --drc")
        if other is TopicKind.SERVICES:
            return Check({}, (f"{method} is a service, not a drc/down message",), "leave out --drc")
        near = closest(method, [m for k in SENT_KINDS for m in reg.methods(k)])
        hint = f"did you mean {' or '.join(near)}?" if near else "dji-gateway methods lists them"
        return Check({}, (f"unknown method {method}",), hint)
    root = spec.data.model_json_schema(by_alias=True)
    data, problems = _typed(pairs, dict(base or {}), root)
    if problems:
        return Check(data, tuple(problems), f"dji-gateway methods {method} lists its fields")
    body: dict[str, Any] = {"method": method, "data": data}
    if kind is TopicKind.SERVICES:
        body.update(tid="check", bid="check", timestamp=0)
    try:
        reg.validate(kind, json.dumps(body).encode())
    except ValidationError as exc:
        lines = tuple(_error_line(e) for e in exc.errors())
        return Check(data, lines, f"dji-gateway methods {method} lists its fields")
    return Check(data)


# ------------------------------------------------------------------------------------------ the command
def add_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "methods",
        help="list the Cloud API methods (or one method's fields) from the contract",
        description="Without METHOD: every method you can send (services, and drc/down with send --drc), "
        "with its summary. With METHOD: its fields — type, range, required, meaning; nested fields dotted "
        "as send takes them (mqtt_broker.address=…). Exit 2 for an unknown method.",
    )
    p.add_argument("method", nargs="?", help="one method, e.g. camera_aim")
    p.add_argument("--json", action="store_true", help="print the method's JSON Schema instead")
    p.set_defaults(handler=cmd_methods)


def cmd_methods(ns: argparse.Namespace) -> int:
    reg = registry()
    if ns.method is None:
        for listed in SENT_KINDS:
            title = (
                "services (dji-gateway send METHOD …)"
                if listed is TopicKind.SERVICES
                else ("drc/down (dji-gateway send --drc METHOD …)")
            )
            print(title)
            specs = reg.specs(listed)
            width = max(len(s.method) for s in specs)
            for s in specs:
                print(f"  {s.method:<{width}}  {s.summary}")
        return 0
    found = _kind_of(ns.method, reg)
    if found is None:
        near = closest(ns.method, [m for k in SENT_KINDS for m in reg.methods(k)])
        guess = f"; did you mean {' or '.join(near)}?" if near else ""
        print(f"dji-gateway methods: unknown method {ns.method}{guess}", file=sys.stderr)
        return 2
    kind = found
    spec = reg.spec(kind, ns.method)
    assert spec is not None
    if ns.json:
        print(json.dumps(spec.data.model_json_schema(by_alias=True), indent=2))
        return 0
    how = "send --drc" if kind is TopicKind.DRC_DOWN else "send"
    print(f"{spec.method} ({kind.value}, {spec.source}): {spec.summary}")
    print(f"  dji-gateway {how} {spec.method} field=value … --gateway-sn SN")
    fields = fields_of(spec)
    if not fields:
        print("  no fields")
        return 0
    rows = [(f.name, f.type, "required" if f.required else "optional", f.detail) for f in fields]
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    for f, row in zip(fields, rows, strict=True):
        head = "  ".join(cell.ljust(widths[i]) for i, cell in enumerate(row[:3]))
        print(f"  {head}  {row[3]}".rstrip())
        if f.description:
            print(f"      {f.description}")
    return 0
