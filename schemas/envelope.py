"""Envelopes: the outer JSON of every Cloud API message, per topic kind, and the per-method message classes.

Owns ``tid``/``bid``/``timestamp``/``gateway``/``method``/``data``/``need_reply`` (thing topics), the DRC
envelope (``method``, ``data``, optional top-level ``seq`` and ``timestamp``, no tid/bid), the reply bodies
every answer shares (``result`` + ``output``), and ``message_class``, which makes the typed envelope of one
(kind, method). Knows nothing about devices or bytes.

Decisions:

- Inbound envelopes (services, events_reply, requests_reply, status_reply, property/set, drc/down) ignore
  unknown keys; ``timestamp`` and ``gateway`` are optional there (the dispatcher needs neither, and a cloud
  that omits them, or sends an odd ``gateway`` string, must not get 325001). ``tid``/``bid`` are
  required: without them no reply can be matched.
- A missing or ``null`` inbound ``data`` is read as ``{}``: the seed documents "Data: null" for
  flight_authority_grab/drc_mode_exit/fly_to_point_stop/drone_emergency_stop and sends ``{}`` in the
  example; both mean "no parameters", and so do ``""`` (DJI's reference cloud) and the JSON string
  ``"null"`` (an RC-side client). A method that has parameters then fails on them by name.
- Outbound thing envelopes always carry ``tid``, ``bid`` and ``timestamp`` (ms). ``gateway`` is required on
  osd/state (cloud stacks route sub-device telemetry by it) and optional elsewhere (the seed's replies,
  events and update_topo examples omit it; the gateway fills it when it knows it).
- DRC down: ``seq`` may sit beside ``data`` instead of inside; heart_beat's ``timestamp`` may be spelled
  ``ts`` or sit beside ``data``. The envelope folds them into ``data`` (inside wins when both are given,
  except ``seq``, where the newer envelope's top-level value wins: ``BESIDE_WINS``), so handlers see one
  shape. Each data model lists what it takes from beside ``data`` in ``envelope_fields``.
- The seed's events examples omit ``method``; the table names it and the gateway always sends it.
"""

from __future__ import annotations

import inspect
import re
from typing import Annotated, Any, ClassVar, Literal, cast

from pydantic import ConfigDict, Field, JsonValue, StringConstraints, create_model, model_validator

from .base import (
    ContractModel,
    Identifier,
    InboundModel,
    Int,
    MethodName,
    OutboundModel,
    Reason,
    Seq,
    SerialNumber,
    Text,
    TimestampMs,
)
from .results import ResultValue
from .topics import TopicKind

# ------------------------------------------------------------------------------------------- reply bodies


class ErrorOutput(OutboundModel):
    """``output`` of a failed reply: a short reason (never the request's values or secrets)."""

    reason: Reason = Field(description="Why the request failed, for a human; not machine-readable.")


class ResultReply(OutboundModel):
    """``data`` of a reply that carries only ``result`` (the seed's services replies: "Non-0 means error")."""

    result: ResultValue
    output: ErrorOutput | None = None


class InboundResult(InboundModel):
    """``data`` of an answer from the cloud (events_reply, status_reply, requests_reply): tolerant."""

    result: Int = Field(description="0 = success.")
    output: dict[str, JsonValue] | None = None


class EmptyRequest(InboundModel):
    """No parameters ("Data: null" in the seed; ``{}``, ``null``, ``""`` (DJI's reference cloud), the string
    ``"null"`` (an RC-side client) and a missing ``data`` are all accepted)."""


class PropertyResult(OutboundModel):
    """The result for one property in a property/set_reply."""

    result: ResultValue


PropertyName = Annotated[str, StringConstraints(pattern=r"^[a-z][a-z0-9_]{0,63}$", max_length=64)]

# ---------------------------------------------------------------------------------------------- envelopes


class Envelope(ContractModel):
    """Root of every envelope. ``kind`` is the topic kind it travels on; message classes made by
    ``message_class`` also know their method and the model of their reply's ``data``."""

    kind: ClassVar[TopicKind]
    reply_data: ClassVar[type[ContractModel] | None] = None


#: ``data`` values that mean "no parameters" besides ``{}``, a JSON null and a missing key: ``""`` (DJI's
#: reference cloud, for every method without parameters) and the JSON *string* ``"null"`` (an RC-side
#: client, github wudizhr/DJI_Cloud_API_demo, sends ``return_home`` so).
_EMPTY_DATA = ("", "null")


def _data_or_empty(value: Any) -> Any:
    # null, a missing data, "" and "null" all mean "no parameters"; a method that needs some then names
    # the missing field
    if isinstance(value, dict):
        data = value.get("data")
        if data is None or (type(data) is str and data in _EMPTY_DATA):
            return {**value, "data": {}}
    return value


#: The tolerant reader's note on ``data`` in every request envelope's JSON Schema.
EMPTY_DATA_NOTE: dict[str, JsonValue] = {
    "empty_data": (
        'data may be {}, null, "", the string "null" or absent: each means no parameters (DJI\'s Java Cloud '
        'SDK sends "data": "" for every method without any; an RC-side client, github '
        'wudizhr/DJI_Cloud_API_demo, sends "data": "null"); a method that needs parameters then names the '
        "missing field."
    )
}


class InboundThingMessage(Envelope):
    """A thing-topic message from the cloud (tid/bid required; unknown keys ignored)."""

    model_config = ConfigDict(extra="ignore", json_schema_extra={"x-tolerant-reader": EMPTY_DATA_NOTE})

    tid: Identifier
    bid: Identifier
    timestamp: TimestampMs | None = None
    gateway: Text | None = Field(default=None, description="Echo of the gateway SN; any string (not used).")
    method: MethodName
    data: InboundModel

    @model_validator(mode="before")
    @classmethod
    def _null_data(cls, value: Any) -> Any:
        return _data_or_empty(value)


class OutboundThingMessage(Envelope):
    """A thing-topic message from the gateway (every field defined; ``timestamp`` in ms)."""

    model_config = ConfigDict(extra="forbid")

    tid: Identifier
    bid: Identifier
    timestamp: TimestampMs
    gateway: SerialNumber | None = None
    method: MethodName
    data: OutboundModel


class ServicesMessage(InboundThingMessage):
    kind = TopicKind.SERVICES


class ServicesReplyMessage(OutboundThingMessage):
    kind = TopicKind.SERVICES_REPLY
    data: ResultReply


class EventsMessage(OutboundThingMessage):
    kind = TopicKind.EVENTS
    need_reply: Annotated[int, Field(strict=True, ge=0, le=1)] | None = Field(
        default=None, description="1: the cloud answers on events_reply (0/1, not a boolean)."
    )


class EventsReplyMessage(InboundThingMessage):
    kind = TopicKind.EVENTS_REPLY
    data: InboundResult


class RequestsMessage(OutboundThingMessage):
    kind = TopicKind.REQUESTS


class RequestsReplyMessage(InboundThingMessage):
    kind = TopicKind.REQUESTS_REPLY
    data: InboundResult


class StatusMessage(OutboundThingMessage):
    kind = TopicKind.STATUS


class StatusReplyMessage(InboundThingMessage):
    kind = TopicKind.STATUS_REPLY
    data: InboundResult


class PropertySetMessage(InboundThingMessage):
    """property/set: ``data`` maps property names to new values (no method in DJI's messages)."""

    kind = TopicKind.PROPERTY_SET
    method: MethodName | None = None  # type: ignore[assignment]
    data: dict[PropertyName, JsonValue] = Field(min_length=1, max_length=64)  # type: ignore[assignment]


class PropertySetReplyMessage(OutboundThingMessage):
    """property/set_reply: ``data`` maps each property named in the request to its result."""

    kind = TopicKind.PROPERTY_SET_REPLY
    method: MethodName | None = None  # type: ignore[assignment]
    data: dict[PropertyName, PropertyResult]  # type: ignore[assignment]


class TelemetryMessage(Envelope):
    """osd / state: published under the device's own SN; no method; ``gateway`` names the gateway."""

    model_config = ConfigDict(extra="forbid")

    tid: Identifier
    bid: Identifier
    timestamp: TimestampMs
    gateway: SerialNumber
    data: OutboundModel


class OsdMessage(TelemetryMessage):
    kind = TopicKind.OSD


class StateMessage(TelemetryMessage):
    kind = TopicKind.STATE


#: Fields a DRC message may carry beside ``data`` where the top-level value wins over one inside: ``seq`` sits
#: at the top level in the newer DRC envelope (DJI's Dock 2/3 and RC Plus 2 DRC pages: ``stick_control``,
#: ``drc_gimbal_reset``; newer clients send ``heart_beat`` so too and match answers on it), and in
#: ``data`` in seed 003's. Other fields (a heartbeat's ``timestamp``) keep "inside wins": the top-level
#: ``timestamp`` of the newer envelope is the message's send time, not the heartbeat's.
BESIDE_WINS = frozenset({"seq"})


class DrcDownMessage(Envelope):
    """A DRC message from the cloud: ``method``, ``data``, maybe ``seq``/``timestamp`` beside ``data``."""

    model_config = ConfigDict(extra="ignore", json_schema_extra={"x-tolerant-reader": EMPTY_DATA_NOTE})
    kind = TopicKind.DRC_DOWN

    method: MethodName
    data: InboundModel
    seq: Seq | None = None
    timestamp: TimestampMs | None = None

    @model_validator(mode="before")
    @classmethod
    def _fold_into_data(cls, value: Any) -> Any:
        value = _data_or_empty(value)
        if not isinstance(value, dict) or not isinstance(value.get("data"), dict):
            return value
        data_model = cls.model_fields["data"].annotation
        fold: dict[str, tuple[str, ...]] = getattr(data_model, "envelope_fields", {})
        data = dict(value["data"])
        for outer, inner_names in fold.items():
            if outer not in value:
                continue
            if outer in BESIDE_WINS:  # the newer envelope's own field: it wins over a copy in data
                for name in inner_names:
                    data.pop(name, None)
                data[outer] = value[outer]
            elif not any(name in data for name in inner_names):
                # Inside wins: only a value missing under every accepted inner spelling is taken from beside.
                data[outer] = value[outer]
        return {**value, "data": data}


class DrcUpMessage(Envelope):
    """A DRC message from the gateway: ``method`` and ``data``; pushes add a top-level ``timestamp``."""

    model_config = ConfigDict(extra="forbid")
    kind = TopicKind.DRC_UP

    method: MethodName
    data: OutboundModel
    seq: Seq | None = None
    timestamp: TimestampMs | None = None


#: The envelope base of each kind that is discriminated on ``method``.
METHOD_BASES: dict[TopicKind, type[Envelope]] = {
    TopicKind.SERVICES: ServicesMessage,
    TopicKind.SERVICES_REPLY: ServicesReplyMessage,
    TopicKind.EVENTS: EventsMessage,
    TopicKind.EVENTS_REPLY: EventsReplyMessage,
    TopicKind.REQUESTS: RequestsMessage,
    TopicKind.REQUESTS_REPLY: RequestsReplyMessage,
    TopicKind.STATUS: StatusMessage,
    TopicKind.STATUS_REPLY: StatusReplyMessage,
    TopicKind.DRC_DOWN: DrcDownMessage,
    TopicKind.DRC_UP: DrcUpMessage,
}

_CLASSES: dict[tuple[TopicKind, str, type, type | None], type[Envelope]] = {}


def camel(name: str) -> str:
    """``fly_to_point`` → ``FlyToPoint``; ``drc/down`` → ``DrcDown``."""
    return "".join(part[:1].upper() + part[1:] for part in re.split(r"[_/]", name) if part)


def message_class(
    kind: TopicKind, method: str, data: type[ContractModel], reply: type[ContractModel] | None = None
) -> type[Envelope]:
    """The envelope class of ``method`` on ``kind`` with ``data`` as its body (made once, then cached).

    ``reply`` is the model of the answer's ``data``; ``replies.reply_for`` reads it from the class.
    """
    kind = TopicKind(kind)
    key = (kind, method, data, reply)
    made = _CLASSES.get(key)
    if made is None:
        base = METHOD_BASES[kind]
        doc = inspect.cleandoc(data.__doc__ or "")
        literal: Any = Literal[method]  # the literal of a value known at run time
        made = cast(
            "type[Envelope]",
            create_model(
                f"{camel(kind.value)}{camel(method)}",
                __base__=base,
                __doc__=f"``{method}`` on ``{kind.value}``. {doc}".strip(),
                __module__=__name__,
                method=(literal, ...),
                data=(data, ...),
            ),
        )
        made.reply_data = reply
        _CLASSES[key] = made
    return made


_TELEMETRY_BASES: dict[TopicKind, type[TelemetryMessage]] = {
    TopicKind.OSD: OsdMessage,
    TopicKind.STATE: StateMessage,
}
_TELEMETRY_CLASSES: dict[tuple[TopicKind, str, type], type[TelemetryMessage]] = {}


def telemetry_class(kind: TopicKind, profile: str, data: type[ContractModel]) -> type[TelemetryMessage]:
    """The osd/state envelope class of one device profile with ``data`` as its body (made once, cached)."""
    kind = TopicKind(kind)
    key = (kind, profile, data)
    made = _TELEMETRY_CLASSES.get(key)
    if made is None:
        doc = inspect.cleandoc(data.__doc__ or "")
        made = cast(
            "type[TelemetryMessage]",
            create_model(
                f"{camel(kind.value)}{camel(profile)}",
                __base__=_TELEMETRY_BASES[kind],
                __doc__=f"``{kind.value}`` of a {profile}. {doc}".strip(),
                __module__=__name__,
                data=(data, ...),
            ),
        )
        _TELEMETRY_CLASSES[key] = made
    return made
