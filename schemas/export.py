"""Generate the contract documents: one JSON Schema per message, a bundle, the result codes and AsyncAPI 3.0.

Owns the layout of ``schemas/json/`` (committed; ``tests/test_schemas_export.py`` regenerates it and fails
on drift). Knows nothing about devices; it reads the seed registry only, so adapters' extension methods are
not part of the committed contract.

Layout::

    schemas/json/
        messages/<kind>.<name>.json   one self-contained JSON Schema (2020-12) per message, e.g.
                                      services.fly_to_point.json, drc_up.hsi_info_push.json, osd.aircraft.json
        bundle.json                   every model under $defs
        result_codes.json             ResultCode table with meanings
        asyncapi.yaml                 channels (topic templates), operations (gateway's side), messages

Run ``python -m schemas.export [DIR]`` (or ``dji-gateway schema export [DIR]``); DIR defaults to
``schemas/json``. Stale ``messages/*.json`` files in DIR are removed so renamed messages do not linger.
"""

from __future__ import annotations

import argparse
import inspect
import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from pydantic import BaseModel
from pydantic.json_schema import GenerateJsonSchema, JsonSchemaValue, models_json_schema
from pydantic_core import core_schema

from . import __doc__ as package_doc
from .envelope import PropertySetMessage, PropertySetReplyMessage
from .examples import CLOUD_SHAPES, GATEWAY_EXAMPLES, SEED_003, WAYLINE_EXAMPLES
from .registry import TELEMETRY, Profile, Registry, default_registry
from .results import GROUND_STATION_ACK_BASE, ResultCode
from .topics import TOPICS, Direction, TopicKind, template

DEFAULT_DIR = Path(__file__).resolve().parent / "json"
JSON_SCHEMA_DIALECT = "https://json-schema.org/draft/2020-12/schema"
ASYNCAPI_VERSION = "3.0.0"
CONTRACT_VERSION = "0.1.0"


class ContractJsonSchema(GenerateJsonSchema):
    """JSON Schema as the wire is: an optional field is absent, never ``null`` (the models drop None)."""

    def nullable_schema(self, schema: core_schema.NullableSchema) -> JsonSchemaValue:
        return self.generate_inner(schema["schema"])

    def default_schema(self, schema: core_schema.WithDefaultSchema) -> JsonSchemaValue:
        json_schema = super().default_schema(schema)
        if json_schema.get("default", ...) is None:
            del json_schema["default"]
        return json_schema


@dataclass(frozen=True, slots=True)
class ExportedMessage:
    """One message of the contract: where it travels and which class validates it."""

    kind: TopicKind
    name: str  # the method, the device profile (osd/state) or "properties" (property/set)
    model: type[BaseModel]
    summary: str

    @property
    def key(self) -> str:
        return f"{self.kind.slug}.{self.name}"

    @property
    def path(self) -> str:
        return f"messages/{self.key}.json"


def contract_messages(registry: Registry) -> list[ExportedMessage]:
    """Every message of the contract, in a stable order (topic table order, then registration order)."""
    found: list[ExportedMessage] = []
    for spec in registry.specs():
        found.append(ExportedMessage(spec.kind, spec.method, spec.message, spec.summary))
        if spec.reply_message is not None and spec.reply_kind is not None:
            found.append(
                ExportedMessage(spec.reply_kind, spec.method, spec.reply_message, f"Reply: {spec.summary}")
            )
    found.append(ExportedMessage(TopicKind.PROPERTY_SET, "properties", PropertySetMessage, "Set properties"))
    found.append(
        ExportedMessage(
            TopicKind.PROPERTY_SET_REPLY, "properties", PropertySetReplyMessage, "Property results"
        )
    )
    for kind, profile in TELEMETRY:
        body = TELEMETRY[(kind, profile)]
        summary = f"{profile.value} {kind.value}: {(body.__doc__ or '').strip().splitlines()[0]}"
        found.append(ExportedMessage(kind, profile.value, registry.telemetry_class(kind, profile), summary))
    order = list(TOPICS)
    return sorted(found, key=lambda message: order.index(message.kind))


def message_schema(message: ExportedMessage) -> dict[str, Any]:
    schema = message.model.model_json_schema(schema_generator=ContractJsonSchema, mode="validation")
    return {"$schema": JSON_SCHEMA_DIALECT, "$id": message.path, **schema}


def bundle_schema(messages: Sequence[ExportedMessage]) -> dict[str, Any]:
    _, schema = models_json_schema(
        [(message.model, "validation") for message in messages],
        schema_generator=ContractJsonSchema,
        title="dji-gateway Cloud API contract",
    )
    return {"$schema": JSON_SCHEMA_DIALECT, "$id": "bundle.json", **schema}


def result_codes() -> dict[str, Any]:
    return {
        "rule": "0 is success; errors are six digits led by 3 or 5 (never -1, 1 or 4xxxxx).",
        "codes": [{"code": int(code), "name": code.name, "meaning": code.meaning} for code in ResultCode],
        "families": [
            {
                "first": GROUND_STATION_ACK_BASE + 1,
                "last": GROUND_STATION_ACK_BASE + 999,
                "meaning": "Onboard SDK ground-station ACK: 336000 + ack (ack 0 is reported as 0).",
            }
        ],
    }


def _examples(message: ExportedMessage, registry: Registry) -> list[dict[str, Any]]:
    # The seed's examples, normalised through the model (so they show what the gateway accepts or sends).
    found = []
    for example in SEED_003:
        if example.kind is not message.kind or (example.method or Profile.AIRCRAFT.value) != message.name:
            continue
        raw = {**json.loads(example.text), **example.patch}
        if example.kind is TopicKind.STATE:
            parsed = registry.validate(example.kind, raw, profile=Profile.AIRCRAFT)
        else:
            parsed = registry.validate(example.kind, raw)
        payload = json.loads(parsed.model_dump_json(context={"reveal_secrets": True}))
        found.append({"name": "seed_003", "summary": example.section, "payload": payload})
    for shape in CLOUD_SHAPES:
        if shape.kind is message.kind and shape.method == message.name:
            # a real cloud's shape (source named) as it arrives, and what the tolerant reader reads from it
            parsed = registry.validate(shape.kind, shape.text)
            found.append(
                {
                    "name": "cloud",
                    "summary": f"As sent by {shape.source}; read as the payload shown.",
                    "x-as-sent": json.loads(shape.text),
                    "payload": json.loads(parsed.model_dump_json(context={"reveal_secrets": True})),
                }
            )
    for extra in (*GATEWAY_EXAMPLES, *WAYLINE_EXAMPLES):
        if extra.kind is message.kind and extra.name == message.name:
            profile = extra.name if extra.kind in (TopicKind.OSD, TopicKind.STATE) else None
            parsed = registry.validate(extra.kind, extra.payload, profile=profile)
            found.append(
                {"name": "gateway", "summary": extra.summary, "payload": json.loads(parsed.model_dump_json())}
            )
    return found


def asyncapi(registry: Registry, messages: Sequence[ExportedMessage]) -> dict[str, Any]:
    """The AsyncAPI 3.0 document: channels per topic kind, operations from the gateway's side."""
    channels: dict[str, Any] = {}
    for kind, info in TOPICS.items():
        publisher = "gateway" if info.direction is Direction.UP else "cloud"
        channels[kind.slug] = {
            "address": template(kind),
            "title": kind.value,
            "description": f"{info.description} Published by the {publisher}.",
            "parameters": {
                "sn": {
                    "description": "Serial number of the device (osd, state) or of the gateway (others).",
                }
            },
            "messages": {},
        }
    components: dict[str, Any] = {}
    for message in messages:
        doc = inspect.cleandoc(message.model.__doc__ or "")
        entry: dict[str, Any] = {
            "name": message.name,
            "title": message.model.__name__,
            "summary": message.summary,
            "description": doc,
            "contentType": "application/json",
            "payload": {"$ref": f"./{message.path}"},
        }
        examples = _examples(message, registry)
        if examples:
            entry["examples"] = examples
        components[message.key] = entry
        channels[message.kind.slug]["messages"][message.name] = {
            "$ref": f"#/components/messages/{message.key}"
        }

    by_key = {message.key: message for message in messages}
    operations: dict[str, Any] = {}
    for message in messages:
        info = TOPICS[message.kind]
        spec = registry.spec(message.kind, message.name)
        is_request = spec is not None or message.kind in (
            TopicKind.OSD,
            TopicKind.STATE,
            TopicKind.PROPERTY_SET,
        )
        if not is_request:
            continue  # replies are described by their request's operation
        operation: dict[str, Any] = {
            "action": "send" if info.direction is Direction.UP else "receive",
            "title": message.name,
            "summary": message.summary,
            "channel": {"$ref": f"#/channels/{message.kind.slug}"},
            "messages": [{"$ref": f"#/channels/{message.kind.slug}/messages/{message.name}"}],
        }
        reply = info.reply if (spec is None or spec.reply is not None) else None
        if reply is not None and f"{reply.slug}.{message.name}" in by_key:
            operation["reply"] = {
                "channel": {"$ref": f"#/channels/{reply.slug}"},
                "messages": [{"$ref": f"#/channels/{reply.slug}/messages/{message.name}"}],
            }
        operations[message.key] = operation

    return {
        "asyncapi": ASYNCAPI_VERSION,
        "info": {
            "title": "dji-gateway northbound contract (DJI Cloud API over MQTT)",
            "version": CONTRACT_VERSION,
            "description": _description(),
        },
        "defaultContentType": "application/json",
        "channels": channels,
        "operations": operations,
        "components": {"messages": components},
    }


def _description() -> str:
    # The package docstring's "Decisions" section: what a cloud developer needs beyond the schemas.
    doc = (package_doc or "").strip()
    decisions = doc[doc.index("Decisions\n") :] if "Decisions\n" in doc else ""
    intro = (
        "Every MQTT message dji-gateway exchanges with a DJI Cloud API platform (seed 003, PROTOCOL-NOTES). "
        "Operations are described from the gateway's side: 'receive' is cloud to gateway, 'send' gateway to "
        "cloud. Payloads reference the JSON Schemas in messages/."
    )
    return f"{intro}\n\n{decisions}".strip() + "\n"


class _Dumper(yaml.SafeDumper):
    """Multi-line strings as literal blocks, so the document reads like the docstrings it quotes."""


def _str_representer(dumper: yaml.SafeDumper, value: str) -> yaml.ScalarNode:
    style = "|" if "\n" in value else None
    return dumper.represent_scalar("tag:yaml.org,2002:str", value, style=style)


_Dumper.add_representer(str, _str_representer)


def _dump_json(value: Any) -> str:
    return json.dumps(value, indent=2, ensure_ascii=False) + "\n"


def export(directory: Path, registry: Registry | None = None) -> list[Path]:
    """Write every document into ``directory``; return the files written (sorted).

    ``registry`` defaults to the seed's methods; the gateway passes one that also holds every device
    family's extension methods, which is what ``schemas/json`` is generated from."""
    directory = Path(directory)
    registry = registry if registry is not None else default_registry()
    messages = contract_messages(registry)
    texts: dict[str, str] = {message.path: _dump_json(message_schema(message)) for message in messages}
    texts["bundle.json"] = _dump_json(bundle_schema(messages))
    texts["result_codes.json"] = _dump_json(result_codes())
    texts["asyncapi.yaml"] = yaml.dump(
        asyncapi(registry, messages), Dumper=_Dumper, sort_keys=False, allow_unicode=True, width=110
    )
    (directory / "messages").mkdir(parents=True, exist_ok=True)
    for stale in (directory / "messages").glob("*.json"):
        if f"messages/{stale.name}" not in texts:
            stale.unlink()
    written = []
    for relative, text in sorted(texts.items()):
        path = directory / relative
        path.write_text(text, encoding="utf-8")
        written.append(path)
    return written


def main(argv: Sequence[str] | None = None, registry: Registry | None = None) -> int:
    """``python -m schemas.export [DIR]``: write the contract documents (default ``schemas/json``)."""
    parser = argparse.ArgumentParser(
        prog="schema export", description="Write the Cloud API JSON Schemas and AsyncAPI."
    )
    parser.add_argument("directory", nargs="?", type=Path, default=DEFAULT_DIR, help="output directory")
    args = parser.parse_args(list(argv) if argv is not None else None)
    written = export(args.directory, registry)
    print(f"wrote {len(written)} files to {args.directory}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
