"""schemas: the northbound contract (DJI Cloud API over MQTT) as pydantic v2 models.

Owns every message of seed 003 (services, events, state, property, DRC) with its reply, the envelopes,
topic names, result codes, the method registry and the generated JSON Schema / AsyncAPI documents in
``schemas/json/``. Imports only pydantic and the standard library; knows nothing about devices, bytes,
sockets or clocks (callers pass ``timestamp``).

README
======

Modules
-------
- ``base``: strictness and unknown-field policy, constrained types (``Float``, ``Int``, ``Latitude``, ...).
- ``topics``: ``TopicKind``, the topic table, ``topic()``, ``parse_topic()``, ``reply_kind()``.
- ``envelope``: thing and DRC envelopes per kind, reply bodies, ``message_class()``.
- ``services`` / ``events`` / ``drc`` / ``status`` / ``state`` / ``osd``: the bodies.
- ``results``: ``ResultCode`` (with ``.meaning``), ``ResultValue``, ``ground_station_ack()``.
- ``registry``: ``SEED_METHODS``, ``TELEMETRY``, ``Registry`` (``validate``, ``register``, ``build``).
- ``replies``: ``reply_for``, ``error_reply_from_validation``, ``echo_heart_beat``, ``property_set_reply``.
- ``examples``: every JSON example of seed 003, verbatim, with the decision that applies to it.
- ``export``: ``python -m schemas.export [DIR]`` writes ``schemas/json/``
  (wired as ``dji-gateway schema export``).

Dispatching an inbound ``services`` message
-------------------------------------------
::

    registry = default_registry()          # once; adapters may registry.register(...) their x_ methods
    kind, sn = parse_topic(msg.topic)      # TopicError for a foreign topic
    try:
        request = registry.validate(kind, msg.payload)     # one call; typed envelope, typed .data
    except ValidationError as exc:                         # the only exception a payload can cause
        reply = error_reply_from_validation(kind, msg.payload, exc, timestamp=now_ms, gateway=gw_sn)
    else:
        reply = reply_for(request, ResultCode.SUCCESS, timestamp=now_ms, gateway=gw_sn)
    if reply is not None:
        publish(topic(reply_kind(kind), sn), reply.model_dump_json())

Decisions
---------
- Unknown fields: inbound envelopes and bodies ignore them (a newer cloud may add fields); outbound models
  forbid them, so nothing the contract does not define is ever sent.
- Types: numbers, booleans and strings are strict (no "5" for 5, no 1 for true, no 5.5 for an int enum);
  floats take integers and reject NaN/Inf; integer enums take their integer values only. Ranges of speeds,
  angles, heights, zoom and frequencies are enforced and out-of-range values rejected (325001), never
  clamped. Absent optional values are left out of dumps (the Cloud API has no nulls).
- Secrets: ``mqtt_broker.password`` is a SecretStr, masked in repr and dumps unless
  ``context={"reveal_secrets": True}``; validation reasons never quote values and mask ``mqtt_broker``.
- Seed contradictions, each documented on its model and tested: fly_to_point accepts 1..16 points flown in
  order (``services.FlyToPoint``); hsi_info_push accepts ``around_distance`` and emits ``around_distances``
  and defines the example's extra flags as optional (``drc.HsiInfoPush``); drone_control ``h`` is -4..5 m/s
  and absent axes are 0 (``drc.DroneControl``); heartbeats take ``timestamp`` or ``ts`` and ``seq``/
  ``timestamp`` inside or beside ``data`` (``drc.HeartBeat``, ``envelope.DrcDownMessage``); ``data: null``
  equals ``{}``; the events examples omit ``method``, which the gateway always sends; osd_info_push's
  ``height`` is metres, not degrees.
- Result codes: six digits led by 3 or 5 (or 0), enforced on every outbound ``result``; this project's own:
  399001 method not supported by this device, 399002 unknown method, 599001 internal error, 336000 + ack
  for Onboard SDK ground-station ACKs (``results`` module docstring).
- Extensions: methods ``x_<family>_<name>`` (e.g. ``x_rsdk_gimbal_speed``) registered at run time with
  ``Registry.register``; extension telemetry properties start with ``x_`` and their description with
  "Extension.". DJI names are used wherever the Cloud API has one.
"""

from __future__ import annotations

from .base import EXTENSION_PREFIX, InboundModel, OutboundModel
from .envelope import (
    DrcDownMessage,
    DrcUpMessage,
    Envelope,
    ErrorOutput,
    InboundResult,
    PropertySetMessage,
    PropertySetReplyMessage,
    ResultReply,
    TelemetryMessage,
)
from .registry import (
    SEED_METHODS,
    TELEMETRY,
    WAYLINE_METHODS,
    MethodSpec,
    Profile,
    Registry,
    default_registry,
)
from .replies import (
    echo_heart_beat,
    error_reply_from_validation,
    property_set_reply,
    reply_for,
    result_for_validation_error,
    validation_reason,
)
from .results import ResultCode, ResultValue, ground_station_ack, is_valid_result, meaning
from .topics import (
    TOPICS,
    Direction,
    ParsedTopic,
    TopicError,
    TopicKind,
    parse_topic,
    reply_kind,
    subscriptions,
    topic,
)

__all__ = [
    "EXTENSION_PREFIX",
    "SEED_METHODS",
    "TELEMETRY",
    "TOPICS",
    "WAYLINE_METHODS",
    "Direction",
    "DrcDownMessage",
    "DrcUpMessage",
    "Envelope",
    "ErrorOutput",
    "InboundModel",
    "InboundResult",
    "MethodSpec",
    "OutboundModel",
    "ParsedTopic",
    "Profile",
    "PropertySetMessage",
    "PropertySetReplyMessage",
    "Registry",
    "ResultCode",
    "ResultReply",
    "ResultValue",
    "TelemetryMessage",
    "TopicError",
    "TopicKind",
    "default_registry",
    "echo_heart_beat",
    "error_reply_from_validation",
    "ground_station_ack",
    "is_valid_result",
    "meaning",
    "parse_topic",
    "property_set_reply",
    "reply_for",
    "reply_kind",
    "result_for_validation_error",
    "subscriptions",
    "topic",
    "validation_reason",
]
