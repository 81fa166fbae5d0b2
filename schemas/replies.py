"""Building answers: ``reply_for`` a validated request, ``error_reply_from_validation`` for a rejected one.

Owns how a reply echoes its request (tid, bid and method exactly; DRC replies carry method and data only),
and how a ``ValidationError`` becomes a short, secret-free reason. Knows nothing about clocks: the caller
passes ``timestamp`` (ms).

- A ``ValidationError`` maps to 325001 (bad parameters), or to 399002 when the method is unknown on the topic
  (``result_for_validation_error``).
- The reason names where the problem is and what was expected (``data.points.0.height: Input should be less
  than or equal to 1500``), at most three problems and 300 characters; it never quotes an input value, and
  anything under ``mqtt_broker`` is reduced to "invalid value" / "Field required".
- Only kinds the cloud sends and expects an answer on get one: services → services_reply, drc/down →
  drc/up, property/set → property/set_reply. A reply is impossible, and the function returns None, when the
  request's ``tid``/``bid``/``method`` cannot be read back (the cloud could not match it), or when the kind
  takes no answer (events_reply, status_reply, ...).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any, TypeGuard

from pydantic import BaseModel, TypeAdapter, ValidationError

from .base import Identifier, MethodName, SerialNumber
from .drc import HeartBeat, HeartBeatEcho
from .envelope import (
    DrcDownMessage,
    DrcUpMessage,
    Envelope,
    ErrorOutput,
    InboundThingMessage,
    PropertyName,
    PropertyResult,
    PropertySetMessage,
    PropertySetReplyMessage,
    ResultReply,
    ServicesReplyMessage,
    message_class,
)
from .results import ResultCode
from .topics import TopicKind, reply_kind

MAX_REASON = 300
_MASKED = ("mqtt_broker", "password", "username", "device_secret")
_identifier = TypeAdapter(Identifier)
_method_name = TypeAdapter(MethodName)
_property_name = TypeAdapter(PropertyName)
_serial = TypeAdapter(SerialNumber)


class DrcErrorReply(DrcUpMessage):
    """A DRC answer to a message that failed validation: ``{"method": ..., "data": {"result", "output"}}``."""

    data: ResultReply


def result_for_validation_error(exc: ValidationError) -> ResultCode:
    """325001 for bad parameters; 399002 when the method is not registered on the topic."""
    if any(error["type"] == "union_tag_invalid" for error in exc.errors(include_url=False)):
        return ResultCode.UNKNOWN_METHOD
    return ResultCode.INVALID_PARAMETERS


def validation_reason(exc: ValidationError, *, tag: str | None = None, limit: int = 3) -> str:
    """A short human reason for ``exc`` that never quotes input values or credentials.

    ``tag`` is the request's method: pydantic puts it first in the location of errors found through the
    discriminated union, where it only adds noise.
    """
    errors = exc.errors(include_url=False, include_context=False)
    parts: list[str] = []
    for error in errors[:limit]:
        loc = [str(part)[:40] for part in error["loc"]]
        if tag is not None and len(loc) > 1 and loc[0] == tag:
            loc = loc[1:]
        if error["type"] == "union_tag_invalid":
            message = "unknown method for this topic"
        elif error["type"] == "union_tag_not_found":
            message = "method is missing"
        elif any(part in _MASKED for part in loc):
            message = "Field required" if error["type"] == "missing" else "invalid value"
        else:
            message = str(error["msg"])
            value = error.get("input")
            if isinstance(value, str) and len(value) >= 3 and value in message:
                message = message.replace(value, "<input>")
        where = ".".join(loc)
        parts.append(f"{where}: {message}" if where else message)
    if len(errors) > limit:
        parts.append(f"(+{len(errors) - limit} more)")
    reason = "; ".join(parts)
    return reason if len(reason) <= MAX_REASON else reason[: MAX_REASON - 3] + "..."


def _as_dict(raw: Any) -> dict[str, Any] | None:
    if isinstance(raw, Mapping):
        return dict(raw)
    if isinstance(raw, (bytes, bytearray, str)):
        try:
            parsed = json.loads(raw)
        except (ValueError, RecursionError):
            return None
        return parsed if isinstance(parsed, dict) else None
    return None


def _valid(value: Any, adapter: TypeAdapter[Any]) -> TypeGuard[str]:
    """``value`` passes ``adapter`` (a constrained string: an identifier, a method or property name …)."""
    try:
        adapter.validate_python(value)
    except ValidationError:
        return False
    return True


def _echo_gateway(value: Any) -> str | None:
    # The inbound envelope takes any gateway string; only a well-formed SN is echoed back.
    return value if _valid(value, _serial) else None


def error_reply_from_validation(
    kind: TopicKind,
    raw: Any,
    exc: ValidationError,
    *,
    timestamp: int | None = None,
    gateway: str | None = None,
) -> Envelope | None:
    """The answer to a payload of ``kind`` that failed validation with ``exc`` (result 325001 or 399002).

    ``raw`` is what was received (bytes, str or a parsed mapping); tid, bid and method are echoed from it.
    ``timestamp`` (ms) is required for thing topics and unused on DRC (whose replies have none).
    Returns None when no answer is possible (see the module docstring).
    """
    kind = TopicKind(kind)
    if kind not in (TopicKind.SERVICES, TopicKind.DRC_DOWN, TopicKind.PROPERTY_SET):
        return None
    message = _as_dict(raw) or {}
    method = message.get("method")
    method = method if _valid(method, _method_name) else None
    result = result_for_validation_error(exc)
    output = ErrorOutput(reason=validation_reason(exc, tag=method))
    gateway = gateway if _valid(gateway, _serial) else None
    if kind is TopicKind.DRC_DOWN:
        if method is None:
            return None
        return DrcErrorReply(method=method, data=ResultReply(result=result, output=output))
    tid, bid = message.get("tid"), message.get("bid")
    if not _valid(tid, _identifier) or not _valid(bid, _identifier):
        return None
    if timestamp is None:
        raise ValueError("timestamp (ms) is required for a thing-topic reply")
    if kind is TopicKind.PROPERTY_SET:
        data = message.get("data")
        names = [name for name in data if _valid(name, _property_name)][:64] if isinstance(data, dict) else []
        return PropertySetReplyMessage(
            tid=tid,
            bid=bid,
            timestamp=timestamp,
            gateway=gateway,
            data={name: PropertyResult(result=result) for name in names},
        )
    if method is None:
        return None
    return ServicesReplyMessage(
        tid=tid,
        bid=bid,
        timestamp=timestamp,
        gateway=gateway,
        method=method,
        data=ResultReply(result=result, output=output),
    )


def reply_for(
    request: Envelope,
    result: int,
    output: Mapping[str, Any] | BaseModel | None = None,
    *,
    timestamp: int | None = None,
    gateway: str | None = None,
) -> Envelope:
    """The answer to a validated ``request``: echoes tid, bid and method; ``data = {result, output}``.

    ``output`` is validated against the method's reply model (``{"reason": ...}`` fits every reply;
    drone_control's also takes ``seq``). ``timestamp`` (ms) is required on thing topics; DRC replies carry
    none. ``gateway`` defaults to the request's when that is a well-formed SN. Raises ``ValidationError``
    for a result that breaks the six-digit rule or an output the contract does not define, and
    ``ValueError`` for a request that has no reply of this shape (drc/up pushes, events; heart_beat is
    answered by ``echo_heart_beat``).
    """
    reply_data = getattr(type(request), "reply_data", None)
    method = getattr(request, "method", None)
    if reply_data is None or not isinstance(method, str) or "result" not in reply_data.model_fields:
        raise ValueError(f"{type(request).__name__} is not answered with a result")
    if not isinstance(request, (InboundThingMessage, DrcDownMessage)):
        raise ValueError(f"{type(request).__name__} is not a request from the cloud")
    body: dict[str, Any] = {"result": result}
    if output is not None:
        body["output"] = output
    cls = message_class(reply_kind(request.kind), method, reply_data)
    if isinstance(request, DrcDownMessage):  # DJI's drc/up replies repeat the seq beside data
        beside = {"seq": request.seq} if request.seq is not None else {}
        return cls.model_validate({"method": method, "data": body, **beside})
    if timestamp is None:
        raise ValueError("timestamp (ms) is required for a thing-topic reply")
    return cls.model_validate(
        {
            "tid": request.tid,
            "bid": request.bid,
            "timestamp": timestamp,
            "gateway": gateway if gateway is not None else _echo_gateway(request.gateway),
            "method": method,
            "data": body,
        }
    )


def echo_heart_beat(request: DrcDownMessage) -> Envelope:
    """The drc/up echo of a heart_beat: the received ``seq`` and ``timestamp`` as they came.

    ``seq`` goes where the request had it, in both places when in doubt: always in ``data`` (seed 003's
    shape, which older clients read) and also at the top level when the request carried it there (the newer
    envelope, whose clients match the answer on the top-level ``seq``)."""
    data = request.data
    if not isinstance(data, HeartBeat):
        raise ValueError("not a heart_beat")
    cls = message_class(TopicKind.DRC_UP, "heart_beat", HeartBeatEcho)
    beside = {"seq": request.seq} if request.seq is not None else {}
    return cls.model_validate(
        {"method": "heart_beat", "data": {"seq": data.seq, "timestamp": data.timestamp}, **beside}
    )


def property_set_reply(
    request: PropertySetMessage, results: Mapping[str, int], *, timestamp: int, gateway: str | None = None
) -> PropertySetReplyMessage:
    """The property/set_reply: one ``{"result": code}`` per property name."""
    return PropertySetReplyMessage(
        tid=request.tid,
        bid=request.bid,
        timestamp=timestamp,
        gateway=gateway if gateway is not None else _echo_gateway(request.gateway),
        data={name: PropertyResult(result=code) for name, code in results.items()},
    )
