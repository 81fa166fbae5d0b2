"""Property tests over every message model: out-of-range or wrongly typed values are rejected with a
ValidationError that maps to 325001 (never another exception); inbound models ignore unknown keys, outbound
models reject them; arbitrary payloads only ever raise ValidationError.

Samples are the seed's examples and schemas.examples.GATEWAY_EXAMPLES, normalised through their models; the
mutations are derived from each model's own JSON Schema (type, minimum/maximum, enum, const, pattern,
lengths, required keys), so a new field is fuzzed without touching this file.
"""

from __future__ import annotations

import copy
import functools
import json
import math
import re
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import BaseModel, ValidationError

from schemas import (
    ResultCode,
    TopicKind,
    default_registry,
    error_reply_from_validation,
    is_valid_result,
    result_for_validation_error,
)
from schemas.envelope import DrcDownMessage, InboundThingMessage
from schemas.examples import GATEWAY_EXAMPLES, SEED_003
from schemas.export import ContractJsonSchema
from schemas.replies import DrcErrorReply

REGISTRY = default_registry()
# Parametrised over ~60 samples: a share of the profile's max_examples each (never more than the profile).
PER_SAMPLE = settings(max_examples=max(10, settings().max_examples // 8))
INBOUND_KINDS = (TopicKind.SERVICES, TopicKind.DRC_DOWN, TopicKind.PROPERTY_SET)


@dataclass(frozen=True, eq=False)
class Sample:
    label: str
    kind: TopicKind
    profile: str | None
    model: type[BaseModel]
    payload: dict[str, Any]  # canonical: what the model dumps
    schema: dict[str, Any]

    @property
    def inbound(self) -> bool:
        return issubclass(self.model, (InboundThingMessage, DrcDownMessage))


def _sample(label: str, kind: TopicKind, raw: dict[str, Any], profile: str | None = None) -> Sample:
    message = REGISTRY.validate(kind, raw, profile=profile)
    model = type(message)
    payload = json.loads(message.model_dump_json(context={"reveal_secrets": True}))
    schema = model.model_json_schema(schema_generator=ContractJsonSchema)
    return Sample(label, kind, profile, model, payload, schema)


def _samples() -> list[Sample]:
    found = []
    for example in SEED_003:
        profile = "aircraft" if example.kind is TopicKind.STATE else None
        raw = {**json.loads(example.text), **example.patch}
        found.append(_sample(f"{example.kind.slug}.{example.method or 'state'}", example.kind, raw, profile))
    for extra in GATEWAY_EXAMPLES:
        profile = extra.name if extra.kind in (TopicKind.OSD, TopicKind.STATE) else None
        found.append(_sample(f"{extra.kind.slug}.{extra.name}", extra.kind, extra.payload, profile))
    # Fields the seed's examples leave out, so they are fuzzed too.
    takeoff = next(e for e in SEED_003 if e.method == "takeoff_to_point" and e.kind is TopicKind.SERVICES)
    raw = json.loads(takeoff.text)
    raw["data"] |= {"rc_lost_action": 2, "exit_wayline_when_rc_lost": 1}
    found.append(_sample("services.takeoff_to_point+optional", TopicKind.SERVICES, raw))
    reply = {"tid": "t", "bid": "b", "timestamp": 1, "gateway": "GW", "method": "camera_aim"}
    reply["data"] = {"result": 327005, "output": {"reason": "aim failed"}}
    found.append(_sample("services_reply.with_output", TopicKind.SERVICES_REPLY, reply))
    found.append(
        _sample(
            "drc_up.heart_beat-no-seq", TopicKind.DRC_UP, {"method": "heart_beat", "data": {"timestamp": 5}}
        )
    )
    error = DrcErrorReply(method="drone_control", data={"result": 325001, "output": {"reason": "bad"}})
    payload = json.loads(error.model_dump_json())
    found.append(
        Sample(
            "drc_up.error",
            TopicKind.DRC_UP,
            None,
            DrcErrorReply,
            payload,
            DrcErrorReply.model_json_schema(schema_generator=ContractJsonSchema),
        )
    )
    return found


SAMPLES = _samples()
IDS = [sample.label for sample in SAMPLES]

# ---------------------------------------------------------------------------------- schema walking


def _resolve(node: dict[str, Any], root: dict[str, Any]) -> dict[str, Any]:
    while "$ref" in node:
        target = root["$defs"][node["$ref"].rsplit("/", 1)[-1]]
        node = {**target, **{k: v for k, v in node.items() if k != "$ref"}}
    return node


def _schema_at(root: dict[str, Any], path: tuple[Any, ...]) -> dict[str, Any] | None:
    node = _resolve(root, root)
    for part in path:
        if isinstance(part, int):
            node = node.get("items")
        elif part in node.get("properties", {}):
            node = node["properties"][part]
        elif isinstance(node.get("additionalProperties"), dict):
            node = node["additionalProperties"]
        else:
            return None
        if node is None:
            return None
        node = _resolve(node, root)
    return node


def _paths(value: Any, prefix: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    if isinstance(value, dict):
        for key, item in value.items():
            yield (*prefix, key)
            yield from _paths(item, (*prefix, key))
    elif isinstance(value, list):
        for index, item in enumerate(value):
            yield (*prefix, index)
            yield from _paths(item, (*prefix, index))


def _get(value: Any, path: tuple[Any, ...]) -> Any:
    for part in path:
        value = value[part]
    return value


def _set(value: Any, path: tuple[Any, ...], new: Any) -> Any:
    value = copy.deepcopy(value)
    _get(value, path[:-1])[path[-1]] = new
    return value


def _delete(value: Any, path: tuple[Any, ...]) -> Any:
    value = copy.deepcopy(value)
    del _get(value, path[:-1])[path[-1]]
    return value


# ---------------------------------------------------------------------------------- bad values

TEXT = st.text(alphabet="ab1 -", max_size=6)
SCALAR_JUNK = {
    "text": TEXT,
    "bool": st.booleans(),
    "int": st.integers(min_value=-(10**20), max_value=10**20),
    "float": st.floats(allow_nan=False, allow_infinity=False),
    "list": st.just([]),
    "dict": st.just({}),
}
NON_FINITE = st.sampled_from([math.nan, math.inf, -math.inf])


def _wrong_types(value: Any) -> st.SearchStrategy[Any]:
    """JSON values of another type than ``value``: never valid in a strict model."""
    if isinstance(value, bool):
        kinds = ["text", "int", "float", "list", "dict"]
    elif isinstance(value, int):  # an int in a canonical dump is an int field: floats are wrong too
        kinds = ["text", "bool", "float", "list", "dict"]
    elif isinstance(value, float):
        kinds = ["text", "bool", "list", "dict"]
        return st.one_of(*(SCALAR_JUNK[k] for k in kinds), NON_FINITE)
    elif isinstance(value, str):
        kinds = ["int", "float", "bool", "list", "dict"]
    elif isinstance(value, list):
        kinds = ["text", "int", "dict"]
    else:
        kinds = ["text", "int", "list", "bool"]
    return st.one_of(*(SCALAR_JUNK[k] for k in kinds))


def _coercible(value: Any) -> list[Any]:
    """Wrong-typed values that pydantic's lax mode would coerce: a strict model must refuse each."""
    if isinstance(value, bool):
        return [1, 0, "true", "1"]
    if isinstance(value, int):
        return ["1", float(value), True]
    if isinstance(value, float):
        return ["1", "1.5", True]
    if isinstance(value, str):
        return [7, 7.5, False]
    return ["x", 0]


def _out_of_range(value: Any, node: dict[str, Any]) -> list[st.SearchStrategy[Any]]:
    found: list[st.SearchStrategy[Any]] = []
    is_int = isinstance(value, int) and not isinstance(value, bool)
    if "minimum" in node:
        low = node["minimum"]
        found.append(
            st.integers(max_value=math.ceil(low) - 1, min_value=math.ceil(low) - 10**6)
            if is_int
            else st.floats(max_value=low, exclude_max=True, allow_nan=False, allow_infinity=False)
        )
    if "maximum" in node:
        high = node["maximum"]
        found.append(
            st.integers(min_value=math.floor(high) + 1, max_value=math.floor(high) + 10**6)
            if is_int
            else st.floats(min_value=high, exclude_min=True, allow_nan=False, allow_infinity=False)
        )
    if "enum" in node:
        allowed = node["enum"]
        if is_int:
            found.append(st.integers(-1000, 1000).filter(lambda v: v not in allowed))
        elif isinstance(value, str):
            found.append(TEXT.filter(lambda v: v not in allowed))
    if "const" in node:
        found.append(TEXT.filter(lambda v: v != node["const"]))
    if "anyOf" in node and is_int:  # the result-code rule
        found.append(st.integers(-(10**7), 10**7).filter(lambda v: not is_valid_result(v)))
    if isinstance(value, str):
        if node.get("maxLength") is not None:
            size = node["maxLength"] + 1
            found.append(st.text(alphabet="ab", min_size=size, max_size=size + 3))
        if node.get("minLength", 0) > 0:
            found.append(st.just(""))
        if "pattern" in node:
            pattern = node["pattern"]
            found.append(TEXT.filter(lambda v: re.search(pattern, v) is None))
    if isinstance(value, list):
        if node.get("maxItems") is not None and value:
            found.append(st.just([value[0]] * (node["maxItems"] + 1)))
        if node.get("minItems", 0) > 0:
            found.append(st.just([]))
    if isinstance(value, dict):
        if node.get("minProperties", 0) > 0:
            found.append(st.just({}))
        if node.get("additionalProperties") is False:
            found.append(st.just({**value, "zz_not_in_the_contract": 1}))
    return found


@functools.cache
def _mutable_paths(sample: Sample) -> list[tuple[tuple[Any, ...], dict[str, Any]]]:
    found = []
    for path in _paths(sample.payload):
        node = _schema_at(sample.schema, path)
        if not node:  # JsonValue (anything goes) or not described
            continue
        found.append((path, node))
    return found


def _tolerated_integer(sample: Sample, path: tuple[Any, ...], node: dict[str, Any]) -> bool:
    """An integer field inside an inbound ``data``: the tolerant reader takes an integral float for it
    (schemas.base.read_integral_floats); enums and the envelope's own fields stay strict."""
    value = _get(sample.payload, path)
    return (
        sample.inbound
        and path[:1] == ("data",)
        and type(value) is int
        and node.get("type") == "integer"
        and "enum" not in node
    )


def _integral_float(value: Any) -> bool:
    return type(value) is float and math.isfinite(value) and value.is_integer()


def _tolerated_boolean(sample: Sample, path: tuple[Any, ...]) -> bool:
    """A boolean field inside an inbound ``data``: the tolerant reader takes ``"true"``/``"false"`` for it
    (schemas.base.read_integral_floats)."""
    return sample.inbound and path[:1] == ("data",) and type(_get(sample.payload, path)) is bool


def _boolean_string(value: Any) -> bool:
    return value in ("true", "false")


@st.composite
def _mutation(draw: st.DrawFn, sample: Sample) -> tuple[tuple[Any, ...], Any]:
    path, node = draw(st.sampled_from(_mutable_paths(sample)))
    value = _get(sample.payload, path)
    options = [_wrong_types(value), *_out_of_range(value, node)]
    if path == ("data",) and sample.inbound:
        # an inbound "data": "" or "null" means "no parameters" like null (DJI's reference cloud, an
        # RC-side client): not a bad value, so it is no mutation here (test_schemas_examples covers it)
        return path, draw(st.one_of(options).filter(lambda v: v not in ("", "null")))
    if _tolerated_integer(sample, path, node):
        # 60.0 for an integer field is read as 60 there (the tolerant reader): no mutation either
        return path, draw(st.one_of(options).filter(lambda v: not _integral_float(v)))
    if _tolerated_boolean(sample, path):
        # "true"/"false" for a boolean field is read as the boolean there (the tolerant reader)
        return path, draw(st.one_of(options).filter(lambda v: not _boolean_string(v)))
    return path, draw(st.one_of(options))


def _required_paths(sample: Sample) -> list[tuple[Any, ...]]:
    found = []
    for path in [(), *_paths(sample.payload)]:
        node = _schema_at(sample.schema, path)
        value = _get(sample.payload, path)
        if not node or not isinstance(value, dict):
            continue
        for key in node.get("required", []):
            if key in value and not (path == () and key == "data" and sample.inbound):  # data: null == {}
                found.append((*path, key))
    return found


# ---------------------------------------------------------------------------------- the properties


def _check_rejected(sample: Sample, mutated: Any, path: tuple[Any, ...]) -> None:
    with pytest.raises(ValidationError) as caught:
        sample.model.model_validate(mutated)
    assert result_for_validation_error(caught.value) is ResultCode.INVALID_PARAMETERS
    text = json.dumps(mutated)  # NaN/Infinity tokens included: pydantic parses them and must refuse them
    with pytest.raises(ValidationError):
        sample.model.model_validate_json(text)
    if sample.kind in INBOUND_KINDS and path[:1] == ("data",):
        # Through the dispatcher's path: the same error becomes a 325001 reply that echoes the request.
        with pytest.raises(ValidationError) as caught:
            REGISTRY.validate(sample.kind, text.encode())
        reply = error_reply_from_validation(sample.kind, text.encode(), caught.value, timestamp=1)
        assert reply is not None
        dumped = json.loads(reply.model_dump_json())
        if sample.kind is TopicKind.PROPERTY_SET:
            assert all(entry == {"result": 325001} for entry in dumped["data"].values())
        else:
            assert dumped["data"]["result"] == 325001 and dumped["method"] == sample.payload["method"]
            assert len(dumped["data"]["output"]["reason"]) <= 300


@pytest.mark.parametrize("sample", SAMPLES, ids=IDS)
def test_samples_are_valid(sample: Sample) -> None:
    assert _mutable_paths(sample), "nothing to fuzz"
    assert (
        json.loads(
            sample.model.model_validate(sample.payload).model_dump_json(context={"reveal_secrets": True})
        )
        == sample.payload
    )


@pytest.mark.parametrize("sample", SAMPLES, ids=IDS)
@PER_SAMPLE
@given(data=st.data())
def test_bad_values_are_rejected_with_325001(sample: Sample, data: st.DataObject) -> None:
    path, bad = data.draw(_mutation(sample))
    _check_rejected(sample, _set(sample.payload, path, bad), path)


@pytest.mark.parametrize("sample", SAMPLES, ids=IDS)
def test_every_required_key_is_required(sample: Sample) -> None:
    # Exhaustive: each required key of each object in the sample, removed in turn.
    for path in _required_paths(sample):
        _check_rejected(sample, _delete(sample.payload, path), path)


@pytest.mark.parametrize("sample", SAMPLES, ids=IDS)
def test_every_leaf_rejects_a_wrong_type(sample: Sample) -> None:
    # Exhaustive: every described position in the sample gets one value of the wrong JSON type.
    for path, node in _mutable_paths(sample):
        value = _get(sample.payload, path)
        for wrong in _coercible(value):
            if _tolerated_integer(sample, path, node) and _integral_float(wrong):
                # the tolerant reader: 7.0 is read as 7 (and 7.5 is still refused)
                read = sample.model.model_validate(_set(sample.payload, path, wrong))
                assert json.loads(read.model_dump_json(context={"reveal_secrets": True})) == sample.payload
                wrong = wrong + 0.5
            if _tolerated_boolean(sample, path) and _boolean_string(wrong):
                # the tolerant reader: "true"/"false" is read as the boolean ("True", "1" are still refused)
                read = sample.model.model_validate(_set(sample.payload, path, wrong))
                dumped = json.loads(read.model_dump_json(context={"reveal_secrets": True}))
                assert _get(dumped, path) is (wrong == "true")
                wrong = wrong.capitalize()
            _check_rejected(sample, _set(sample.payload, path, wrong), path)


JSON = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=8), inner, max_size=3),
    max_leaves=8,
)


@pytest.mark.parametrize("sample", SAMPLES, ids=IDS)
def test_unknown_keys_inbound_ignored_outbound_rejected(sample: Sample) -> None:
    # Exhaustive over the sample's objects that are models (not free-form dicts such as property/set data).
    original = sample.model.model_validate(sample.payload)
    for path in [(), *_paths(sample.payload)]:
        node = _schema_at(sample.schema, path)
        if not isinstance(_get(sample.payload, path), dict) or not node or "properties" not in node:
            continue
        target = copy.deepcopy(sample.payload)
        _get(target, path)["zz_newer_cloud_field"] = {"nested": [1, "two", None]}
        if sample.inbound:
            assert sample.model.model_validate(target) == original
        else:
            with pytest.raises(ValidationError):
                sample.model.model_validate(target)


@pytest.mark.parametrize("sample", SAMPLES, ids=IDS)
@PER_SAMPLE
@given(data=st.data())
def test_arbitrary_values_raise_nothing_but_validation_error(sample: Sample, data: st.DataObject) -> None:
    paths = list(_paths(sample.payload))
    path = data.draw(st.sampled_from(paths))
    mutated = _set(sample.payload, path, data.draw(JSON))
    try:
        sample.model.model_validate(mutated)
    except ValidationError as exc:
        assert result_for_validation_error(exc) in (ResultCode.INVALID_PARAMETERS, ResultCode.UNKNOWN_METHOD)


KINDS_WITH_VALIDATION = [kind for kind in TopicKind if kind not in (TopicKind.OSD, TopicKind.STATE)]


@pytest.mark.parametrize("kind", KINDS_WITH_VALIDATION, ids=lambda k: k.slug)
@given(payload=st.one_of(st.binary(max_size=64), JSON.map(json.dumps), JSON))
def test_any_payload_raises_only_validation_error(kind: TopicKind, payload: Any) -> None:
    try:
        REGISTRY.validate(kind, payload)
    except ValidationError as exc:
        reply = error_reply_from_validation(kind, payload, exc, timestamp=1, gateway="GW")
        if reply is not None:
            assert json.loads(reply.model_dump_json())["data"] is not None


@pytest.mark.parametrize("kind", [TopicKind.SERVICES, TopicKind.DRC_DOWN], ids=lambda k: k.slug)
@given(
    method=st.sampled_from(["camera_aim", "drone_control", "heart_beat", "fly_to_point", "nope"]),
    data=JSON,
    extra=st.dictionaries(st.sampled_from(["tid", "bid", "seq", "timestamp", "gateway"]), JSON, max_size=3),
)
def test_envelopes_with_junk_data_raise_only_validation_error(
    kind: TopicKind, method: str, data: Any, extra: dict[str, Any]
) -> None:
    raw = {"tid": "t", "bid": "b", **extra, "method": method, "data": data}
    try:
        REGISTRY.validate(kind, raw)
    except ValidationError as exc:
        error_reply_from_validation(kind, raw, exc, timestamp=1)
