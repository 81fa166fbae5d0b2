"""Base classes and constrained types shared by every Cloud API model.

Owns the unknown-field policy, the strictness of numbers, the secret masking and the "absent, not null"
serialisation rule. Knows nothing about topics, methods, devices or bytes.

Policy (the contract's rules, applied through these bases and types):

- ``InboundModel`` (what the gateway receives): unknown keys are ignored (a newer cloud may add fields),
  known keys are validated strictly.
- ``OutboundModel`` (what the gateway sends): unknown keys are an error, so a message never carries a field
  the contract does not define.
- Numbers are strict: a JSON string ``"5"``, a boolean or ``5.5`` for an int is rejected, never coerced;
  floats accept JSON integers (``100`` for ``100.0``) and reject NaN and infinities. The one tolerance,
  for what the gateway *receives* (the tolerant reader, ``InboundModel``): an integral JSON number
  (``60.0``) for an integer field is read as that integer, because DJI's Java Cloud SDK declares such
  fields ``Float`` and serialises ``60.0``; ``60.5`` is still refused. JSON Schema's ``integer`` already
  matches ``60.0``, and each such model says which fields in ``x-tolerant-reader``. Booleans are strict
  (``0``/``1`` are not booleans) but for one shape, again only in what the gateway receives: the JSON strings
  ``"true"`` and ``"false"`` (exactly so) are read as the boolean, because an RC-side client in use with real
  controllers (github wudizhr/DJI_Cloud_API_demo) sends ``"enable_tls": "false"``; ``"yes"``, ``"1"`` or
  ``"False"`` are still refused. Integer enums accept their integer values only (not ``"1"``, ``true`` or
  ``1.0``). A wrong type in a speed or a height must never move a device.
- Optional fields that are absent serialise as absent, never as ``null``.
- Secrets (``SecretStr``) serialise masked unless the dump is given ``context={"reveal_secrets": True}``.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from types import UnionType
from typing import TYPE_CHECKING, Annotated, Any, TypeVar, Union, get_args, get_origin

from pydantic import (
    AliasChoices,
    AllowInfNan,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    SecretStr,
    SerializationInfo,
    SerializerFunctionWrapHandler,
    Strict,
    StringConstraints,
    WrapSerializer,
    model_serializer,
    model_validator,
)
from pydantic.fields import FieldInfo

#: Prefix that marks every field and method this project adds to the Cloud API (extension methods are
#: ``x_<family>_<name>``, extension properties ``x_<name>``). DJI never uses it, so an extension cannot
#: collide with a future Cloud API name, and a reader of a raw message sees at once what is not DJI's.
EXTENSION_PREFIX = "x_"


class ContractModel(BaseModel):
    """Common root: frozen values, and optional fields that are ``None`` are left out of every dump."""

    model_config = ConfigDict(frozen=True, populate_by_name=True, validate_default=False)

    @model_serializer(mode="wrap")
    def _drop_absent(self, handler: SerializerFunctionWrapHandler) -> Any:
        # The Cloud API has no nulls: an unknown value is an absent key. Dropping None here (rather than
        # asking every caller for exclude_none=True) makes the rule impossible to forget.
        dumped = handler(self)
        if isinstance(dumped, dict):
            return {key: value for key, value in dumped.items() if value is not None}
        return dumped


def _fields_of_type(cls: type[BaseModel], kind: type) -> tuple[str, ...]:
    """The fields of ``cls`` whose type is plainly ``kind`` (``kind`` or ``kind | None``; for ``int`` not
    bool, not an enum: enums take their integer values only), by their JSON names."""
    cached = _FIELDS_OF_TYPE.get((cls, kind))
    if cached is None:
        names: list[str] = []
        for name, info in cls.model_fields.items():
            types = get_args(info.annotation) if get_origin(info.annotation) in (Union, UnionType) else ()
            plain = [_bare(t) for t in (types or (info.annotation,)) if t is not type(None)]
            if len(plain) == 1 and plain[0] is kind:
                names += _json_names(name, info)
        cached = _FIELDS_OF_TYPE[(cls, kind)] = tuple(names)
    return cached


def _integer_fields(cls: type[BaseModel]) -> tuple[str, ...]:
    """The plain integer fields of ``cls`` (:func:`_fields_of_type`)."""
    return _fields_of_type(cls, int)


def _boolean_fields(cls: type[BaseModel]) -> tuple[str, ...]:
    """The plain boolean fields of ``cls`` (:func:`_fields_of_type`)."""
    return _fields_of_type(cls, bool)


def _bare(annotation: Any) -> Any:
    """``Annotated[int, ...]`` → ``int``."""
    return get_args(annotation)[0] if get_origin(annotation) is Annotated else annotation


def _json_names(name: str, info: FieldInfo) -> list[str]:
    """Every key a field is read from: its name, alias, or each of its validation alias choices."""
    alias = info.validation_alias
    if isinstance(alias, AliasChoices):
        return [choice for choice in alias.choices if isinstance(choice, str)]
    if isinstance(alias, str):
        return [alias]
    return [info.alias or name]


_FIELDS_OF_TYPE: dict[tuple[type[BaseModel], type], tuple[str, ...]] = {}

#: What the tolerant reader says in the JSON Schema of a model with integer fields.
TOLERANT_READER_NOTE = (
    "An integral JSON number (60.0) is accepted for these integer fields and read as the integer (DJI's "
    "Java Cloud SDK serialises them as floats); a fraction (60.5) is refused."
)


#: What the tolerant reader says in the JSON Schema of a model with boolean fields.
BOOLEAN_STRING_NOTE = (
    'The JSON strings "true" and "false" (exactly so) are accepted for these boolean fields and read as the '
    'boolean (an RC-side client, github wudizhr/DJI_Cloud_API_demo, sends "enable_tls": "false"); any other '
    "string is refused."
)
_BOOLEAN_STRINGS = {"true": True, "false": False}


def read_integral_floats(cls: type[BaseModel], value: Any) -> Any:
    """The tolerant reader's step for one model: ``60.0`` → ``60`` for its integer fields and ``"true"`` /
    ``"false"`` → the boolean for its boolean fields, before strict validation. Anything else (``60.5``,
    ``"60"``, ``true`` for an integer; ``"yes"``, ``"1"``, ``1`` for a boolean) is left for validation to
    refuse."""
    if not isinstance(value, dict):
        return value
    changed: dict[str, Any] = {
        name: int(v)
        for name in _integer_fields(cls)
        if type(v := value.get(name)) is float and math.isfinite(v) and v.is_integer()
    }
    for name in _boolean_fields(cls):
        text = value.get(name)
        if type(text) is str and text in _BOOLEAN_STRINGS:
            changed[name] = _BOOLEAN_STRINGS[text]
    return {**value, **changed} if changed else value


def _document_tolerance(schema: dict[str, Any], cls: type[BaseModel]) -> None:
    tolerance: dict[str, Any] = {}
    fields = _integer_fields(cls)
    if fields:
        tolerance.update({"integral_float_fields": list(fields), "note": TOLERANT_READER_NOTE})
    booleans = _boolean_fields(cls)
    if booleans:
        tolerance.update({"boolean_string_fields": list(booleans), "boolean_note": BOOLEAN_STRING_NOTE})
    if tolerance:
        schema["x-tolerant-reader"] = tolerance


class InboundModel(ContractModel):
    """A message (or part of one) the gateway receives from the cloud: unknown keys are ignored, and an
    integral float for an integer field is read as the integer (the tolerant reader, module docstring)."""

    model_config = ConfigDict(extra="ignore", json_schema_extra=_document_tolerance)

    @model_validator(mode="before")
    @classmethod
    def _tolerant_reader(cls, value: Any) -> Any:
        return read_integral_floats(cls, value)


class OutboundModel(ContractModel):
    """A message (or part of one) the gateway sends: unknown keys are rejected."""

    model_config = ConfigDict(extra="forbid")


# ---------------------------------------------------------------------------------------------- numbers

#: A finite JSON number; integers are accepted, strings and booleans are not.
Float = Annotated[float, Strict(), AllowInfNan(False)]
#: A JSON integer; ``1.0``, ``"1"`` and ``true`` are rejected.
Int = Annotated[int, Strict()]
#: A JSON boolean; ``0``, ``1`` and ``"true"`` are rejected.
Bool = Annotated[bool, Strict()]
#: A JSON string; numbers are rejected.
Str = Annotated[str, Strict()]

#: JSON's largest exactly representable integer; bounds counters and timestamps so JavaScript clouds agree.
MAX_SAFE_INT = 2**53 - 1

#: Milliseconds since the Unix epoch.
TimestampMs = Annotated[int, Strict(), Field(ge=0, le=MAX_SAFE_INT, json_schema_extra={"x-unit": "ms"})]
#: A sequence number (DRC ``seq``): non-negative.
Seq = Annotated[int, Strict(), Field(ge=0, le=MAX_SAFE_INT)]

Latitude = Annotated[
    float,
    Strict(),
    AllowInfNan(False),
    Field(ge=-90, le=90, description="Degrees, WGS84; negative is south.", json_schema_extra={"x-unit": "°"}),
]
Longitude = Annotated[
    float,
    Strict(),
    AllowInfNan(False),
    Field(
        ge=-180, le=180, description="Degrees, WGS84; negative is west.", json_schema_extra={"x-unit": "°"}
    ),
]

# ---------------------------------------------------------------------------------------------- strings

#: ``tid`` / ``bid``: DJI sends UUIDs; any non-empty string of sane length is accepted and echoed as is.
Identifier = Annotated[str, Strict(), StringConstraints(min_length=1, max_length=128)]
#: A device or gateway serial number. No ``/``, ``+`` or ``#``, so it is always one safe MQTT topic level.
SerialNumber = Annotated[
    str, Strict(), StringConstraints(pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$", max_length=64)
]
#: A method name: lower-case snake case (extension methods start with ``x_``).
MethodName = Annotated[str, Strict(), StringConstraints(pattern=r"^[a-z][a-z0-9_]{0,63}$", max_length=64)]
#: ``{type-subtype-gimbalindex}``, e.g. ``39-0-7`` (DJI's unofficial device_mode_key).
PayloadIndex = Annotated[
    str,
    Strict(),
    StringConstraints(pattern=r"^[0-9]{1,5}-[0-9]{1,5}-[0-9]{1,5}$", max_length=17),
    Field(description="Payload index {type-subtype-gimbalindex}, e.g. 39-0-7.", examples=["39-0-7"]),
]
#: Free text from the cloud that is only echoed or used as a key (task ids, client ids).
Text = Annotated[str, Strict(), StringConstraints(max_length=256)]
#: A short human-readable reason in a reply's ``output``; never carries request values.
Reason = Annotated[str, Strict(), StringConstraints(max_length=300)]


def _reveal_or_mask(value: SecretStr, handler: SerializerFunctionWrapHandler, info: SerializationInfo) -> str:
    context = info.context if isinstance(info.context, dict) else {}
    if context.get("reveal_secrets") is True:
        return value.get_secret_value()
    return "**********"


#: A credential: hidden in repr, masked in dumps unless ``context={"reveal_secrets": True}``.
Secret = Annotated[
    SecretStr,
    Strict(),
    Field(max_length=4096),
    WrapSerializer(_reveal_or_mask, return_type=str, when_used="always"),
]

# ---------------------------------------------------------------------------------------------- enums

E = TypeVar("E", bound=enum.IntEnum)


def _only_ints(enum_cls: type[enum.IntEnum]) -> Callable[[Any], Any]:
    def check(value: Any) -> Any:
        # pydantic's lax enum validation would take "1", 1.0 and True for 1; the contract takes integers only.
        if isinstance(value, enum_cls) or (type(value) is int):
            return value
        raise ValueError(f"Input should be an integer, one of {[int(member) for member in enum_cls]}")

    return check


def int_enum(enum_cls: type[E]) -> Any:
    """An integer enum field type that accepts the enum's integer values only."""
    return Annotated[enum_cls, BeforeValidator(_only_ints(enum_cls))]


if TYPE_CHECKING:
    #: ``IntEnumField[MyEnum]``: :func:`int_enum` spelt as a type (a type checker sees ``MyEnum``)
    IntEnumField = Annotated[E, "int enum"]
else:

    class IntEnumField:
        """``IntEnumField[MyEnum]``: :func:`int_enum` spelt as a type (a type checker sees ``MyEnum``)."""

        def __class_getitem__(cls, enum_cls: type[E]) -> Any:
            return int_enum(enum_cls)


def enum_description(enum_cls: type[enum.Enum], meanings: dict[Any, str]) -> str:
    """``"0: Disconnected, 1: Connecting, ..."``: the seed's enum table as a description."""
    return ", ".join(f"{member.value}: {meanings[member]}" for member in enum_cls)
