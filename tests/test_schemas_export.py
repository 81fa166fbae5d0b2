"""The generated documents: no drift from the committed schemas/json/, a well-formed AsyncAPI 3.0 document
that names every topic kind and method, and message payloads whose $refs resolve to the exported schemas."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import yaml

from gateway.app import build_registry
from schemas import SEED_METHODS, TOPICS, ResultCode, TopicKind
from schemas.export import DEFAULT_DIR, contract_messages, export, main
from schemas.registry import TELEMETRY

COMMITTED = DEFAULT_DIR


@pytest.fixture(scope="module")
def generated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    directory = tmp_path_factory.mktemp("schemas-json")
    # the committed documents come from `dji-gateway schema export`: the seed plus every extension
    assert main([str(directory)], registry=build_registry()) == 0
    return directory


def _files(directory: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(directory)): p.read_bytes() for p in sorted(directory.rglob("*")) if p.is_file()
    }


def test_committed_documents_match_the_models(generated: Path) -> None:
    # Drift: regenerate and compare byte for byte; run `python -m schemas.export` after changing a model.
    fresh, committed = _files(generated), _files(COMMITTED)
    assert sorted(fresh) == sorted(committed), "files differ: run `dji-gateway schema export`"
    changed = [name for name in fresh if fresh[name] != committed[name]]
    assert not changed, f"stale generated files: {changed}; run `dji-gateway schema export`"


def test_export_is_deterministic_and_removes_stale_messages(tmp_path: Path) -> None:
    first = export(tmp_path)
    stale = tmp_path / "messages" / "services.removed_method.json"
    stale.write_text("{}")
    second = export(tmp_path)
    assert first == second and not stale.exists()
    assert all(path.is_file() for path in second)


@pytest.fixture(scope="module")
def asyncapi(generated: Path) -> dict[str, Any]:
    return yaml.safe_load((generated / "asyncapi.yaml").read_text(encoding="utf-8"))


def _resolve_local(document: dict[str, Any], ref: str) -> Any:
    assert ref.startswith("#/"), ref
    node: Any = document
    for part in ref[2:].split("/"):
        node = node[part]
    return node


def _refs(node: Any) -> list[str]:
    if isinstance(node, dict):
        found = [node["$ref"]] if isinstance(node.get("$ref"), str) else []
        return found + [ref for value in node.values() for ref in _refs(value)]
    if isinstance(node, list):
        return [ref for value in node for ref in _refs(value)]
    return []


def test_asyncapi_document_shape(asyncapi: dict[str, Any]) -> None:
    assert asyncapi["asyncapi"] == "3.0.0"
    assert asyncapi["info"]["title"] and asyncapi["info"]["version"]
    assert set(asyncapi) <= {
        "asyncapi",
        "id",
        "info",
        "servers",
        "defaultContentType",
        "channels",
        "operations",
        "components",
    }
    for channel in asyncapi["channels"].values():
        assert set(channel) <= {"address", "title", "summary", "description", "parameters", "messages"}
        for parameter in channel["address"].split("{")[1:]:
            assert parameter.split("}")[0] in channel["parameters"]
    for operation in asyncapi["operations"].values():
        assert operation["action"] in ("send", "receive")
        channel = _resolve_local(asyncapi, operation["channel"]["$ref"])
        for message in operation["messages"]:  # an operation's messages belong to its channel
            assert message["$ref"].startswith(operation["channel"]["$ref"] + "/messages/")
        if "reply" in operation:
            reply_channel = operation["reply"]["channel"]["$ref"]
            assert all(
                m["$ref"].startswith(reply_channel + "/messages/") for m in operation["reply"]["messages"]
            )
        assert channel is not None
    for name in asyncapi["components"]["messages"]:
        assert all(c.isalnum() or c in "._-" for c in name), name  # AsyncAPI component key pattern


def test_every_local_ref_resolves(asyncapi: dict[str, Any]) -> None:
    local = [ref for ref in _refs(asyncapi) if ref.startswith("#/")]
    assert local
    for ref in local:
        _resolve_local(asyncapi, ref)


def test_payloads_reference_the_exported_schemas(asyncapi: dict[str, Any], generated: Path) -> None:
    messages = asyncapi["components"]["messages"]
    exported = sorted(str(p.relative_to(generated)) for p in (generated / "messages").glob("*.json"))
    referenced = sorted(message["payload"]["$ref"].removeprefix("./") for message in messages.values())
    assert referenced == exported
    for relative in referenced:
        schema = json.loads((generated / relative).read_text(encoding="utf-8"))
        assert schema["$id"] == relative and schema["type"] == "object"
        for ref in _refs(schema):  # self-contained: every $ref points into its own $defs
            _resolve_local(schema, ref)


def test_asyncapi_names_every_topic_kind_and_method(asyncapi: dict[str, Any]) -> None:
    channels = asyncapi["channels"]
    assert {channel["address"].split("{sn}/")[1] for channel in channels.values()} == {
        k.value for k in TopicKind
    }
    assert {channel["address"] for channel in channels.values()} == {
        f"{info.root}/{{sn}}/{kind.value}" for kind, info in TOPICS.items()
    }
    for spec in SEED_METHODS:
        assert spec.method in channels[spec.kind.slug]["messages"], spec.method
        operation = asyncapi["operations"][f"{spec.kind.slug}.{spec.method}"]
        assert operation["action"] == (
            "receive" if spec.kind in (TopicKind.SERVICES, TopicKind.DRC_DOWN) else "send"
        )
        if spec.reply is not None:
            assert spec.method in channels[spec.reply_kind.slug]["messages"]
            assert operation["reply"]["channel"]["$ref"] == f"#/channels/{spec.reply_kind.slug}"
        else:
            assert "reply" not in operation
    for kind, profile in TELEMETRY:
        assert profile.value in channels[kind.slug]["messages"]
    assert "properties" in channels["property_set"]["messages"]


def test_examples_in_asyncapi_are_valid(asyncapi: dict[str, Any]) -> None:
    registry = build_registry()
    count = 0
    for key, message in asyncapi["components"]["messages"].items():
        kind = TopicKind(next(k for k in TopicKind if key.startswith(k.slug + ".")))
        for example in message.get("examples", []):
            profile = message["name"] if kind in (TopicKind.OSD, TopicKind.STATE) else None
            registry.validate(kind, example["payload"], profile=profile)
            count += 1
    assert count >= 44


def test_bundle_and_result_codes(generated: Path) -> None:
    bundle = json.loads((generated / "bundle.json").read_text(encoding="utf-8"))
    titles = {definition.get("title") for definition in bundle["$defs"].values()}
    assert {message.model.__name__ for message in contract_messages(build_registry())} <= titles
    codes = json.loads((generated / "result_codes.json").read_text(encoding="utf-8"))
    assert {entry["code"] for entry in codes["codes"]} == {int(code) for code in ResultCode}
