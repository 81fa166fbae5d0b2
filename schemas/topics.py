"""MQTT topic names of the Cloud API: one table of topic kinds, pure builders and a strict parser.

Owns the topic templates, who publishes on each (direction), and which kind carries the reply. Knows
nothing about messages, sockets or devices.

Templates (``{sn}`` is one topic level, see ``base.SerialNumber``):

======================  ======================================  =========  ===================
kind                    template                                direction  reply on
======================  ======================================  =========  ===================
``osd``                 ``thing/product/{sn}/osd``              up         (none)
``state``               ``thing/product/{sn}/state``            up         (none)
``services``            ``thing/product/{sn}/services``         down       ``services_reply``
``events``              ``thing/product/{sn}/events``           up         ``events_reply``
``requests``            ``thing/product/{sn}/requests``         up         ``requests_reply``
``property/set``        ``thing/product/{sn}/property/set``     down       ``property/set_reply``
``drc/down``            ``thing/product/{sn}/drc/down``         down       ``drc/up``
``status``              ``sys/product/{sn}/status``             up         ``status_reply``
======================  ======================================  =========  ===================

"up" is gateway → cloud, "down" cloud → gateway. ``osd``/``state`` use each device's own SN; the others
use the gateway's SN (the seed writes ``{device_sn}`` for events; PROTOCOL-NOTES and real docks use the
gateway's, and the builder does not care).
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass
from typing import NamedTuple


class Direction(enum.StrEnum):
    """Who publishes: ``UP`` the gateway (to the cloud), ``DOWN`` the cloud (to the gateway)."""

    UP = "up"
    DOWN = "down"


class TopicKind(enum.StrEnum):
    """The kinds of Cloud API topic; the value is the topic's suffix after the SN."""

    OSD = "osd"
    STATE = "state"
    SERVICES = "services"
    SERVICES_REPLY = "services_reply"
    EVENTS = "events"
    EVENTS_REPLY = "events_reply"
    REQUESTS = "requests"
    REQUESTS_REPLY = "requests_reply"
    PROPERTY_SET = "property/set"
    PROPERTY_SET_REPLY = "property/set_reply"
    DRC_DOWN = "drc/down"
    DRC_UP = "drc/up"
    STATUS = "status"
    STATUS_REPLY = "status_reply"

    @property
    def slug(self) -> str:
        """The kind as one identifier (``property/set`` → ``property_set``), for file and channel names."""
        return self.value.replace("/", "_")


@dataclass(frozen=True, slots=True)
class TopicInfo:
    """One row of the topic table."""

    kind: TopicKind
    root: str  # "thing/product" or "sys/product"
    direction: Direction
    reply: TopicKind | None  # the kind that carries the answer, None when nobody answers
    sn_role: str  # "device" (each device's own SN) or "gateway"
    envelope: str  # "thing" (tid/bid/timestamp/...), "drc" (method/data/seq/timestamp)
    description: str


_THING = "thing/product"
_SYS = "sys/product"

TOPICS: dict[TopicKind, TopicInfo] = {
    info.kind: info
    for info in (
        TopicInfo(
            TopicKind.OSD,
            _THING,
            Direction.UP,
            None,
            "device",
            "thing",
            "Periodic telemetry (0.5 Hz outside DRC), one message per device under its own SN.",
        ),
        TopicInfo(
            TopicKind.STATE,
            _THING,
            Direction.UP,
            None,
            "device",
            "thing",
            "State properties, published when they change, under the device's own SN.",
        ),
        TopicInfo(
            TopicKind.SERVICES,
            _THING,
            Direction.DOWN,
            TopicKind.SERVICES_REPLY,
            "gateway",
            "thing",
            "Commands from the cloud; each is answered on services_reply within 3 s.",
        ),
        TopicInfo(
            TopicKind.SERVICES_REPLY,
            _THING,
            Direction.UP,
            None,
            "gateway",
            "thing",
            "Answers to services, echoing tid, bid and method.",
        ),
        TopicInfo(
            TopicKind.EVENTS,
            _THING,
            Direction.UP,
            TopicKind.EVENTS_REPLY,
            "gateway",
            "thing",
            "Events from the gateway (progress, DRC link state); need_reply asks for events_reply.",
        ),
        TopicInfo(
            TopicKind.EVENTS_REPLY,
            _THING,
            Direction.DOWN,
            None,
            "gateway",
            "thing",
            "The cloud's answers to events.",
        ),
        TopicInfo(
            TopicKind.REQUESTS,
            _THING,
            Direction.UP,
            TopicKind.REQUESTS_REPLY,
            "gateway",
            "thing",
            "Requests from the gateway to the cloud (none in seed 003; extensions only).",
        ),
        TopicInfo(
            TopicKind.REQUESTS_REPLY,
            _THING,
            Direction.DOWN,
            None,
            "gateway",
            "thing",
            "The cloud's answers to requests.",
        ),
        TopicInfo(
            TopicKind.PROPERTY_SET,
            _THING,
            Direction.DOWN,
            TopicKind.PROPERTY_SET_REPLY,
            "gateway",
            "thing",
            "The cloud writes read-write properties.",
        ),
        TopicInfo(
            TopicKind.PROPERTY_SET_REPLY,
            _THING,
            Direction.UP,
            None,
            "gateway",
            "thing",
            "Per-property results of a property/set.",
        ),
        TopicInfo(
            TopicKind.DRC_DOWN,
            _THING,
            Direction.DOWN,
            TopicKind.DRC_UP,
            "gateway",
            "drc",
            "Live flight control (DRC) from the cloud: sticks, emergency stop, heartbeats.",
        ),
        TopicInfo(
            TopicKind.DRC_UP,
            _THING,
            Direction.UP,
            None,
            "gateway",
            "drc",
            "DRC answers and high-rate pushes (osd_info_push, hsi_info_push, delay_info_push).",
        ),
        TopicInfo(
            TopicKind.STATUS,
            _SYS,
            Direction.UP,
            TopicKind.STATUS_REPLY,
            "gateway",
            "thing",
            "Topology (update_topo): published on every (re)connect before any telemetry.",
        ),
        TopicInfo(
            TopicKind.STATUS_REPLY,
            _SYS,
            Direction.DOWN,
            None,
            "gateway",
            "thing",
            "The cloud's answer to update_topo.",
        ),
    )
}


class TopicError(ValueError):
    """A topic string that is not a Cloud API topic (the message says why)."""


class ParsedTopic(NamedTuple):
    kind: TopicKind
    sn: str


_SN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")


def _check_sn(sn: str) -> str:
    if not isinstance(sn, str) or not _SN.fullmatch(sn):
        raise TopicError(
            f"invalid serial number {sn!r:.80}: expected 1-64 characters of A-Z a-z 0-9 . _ - "
            "(no '/', '+' or '#')"
        )
    return sn


def template(kind: TopicKind) -> str:
    """The topic template, e.g. ``thing/product/{sn}/services``."""
    info = TOPICS[TopicKind(kind)]
    return f"{info.root}/{{sn}}/{info.kind.value}"


def topic(kind: TopicKind, sn: str) -> str:
    """The topic of ``kind`` for serial number ``sn``; raises ``TopicError`` for an unusable SN."""
    info = TOPICS[TopicKind(kind)]
    return f"{info.root}/{_check_sn(sn)}/{info.kind.value}"


_BY_SUFFIX: dict[tuple[str, str], TopicKind] = {
    (info.root, info.kind.value): info.kind for info in TOPICS.values()
}


def parse_topic(name: str) -> ParsedTopic:
    """``thing/product/SN/services`` → ``ParsedTopic(TopicKind.SERVICES, "SN")``; ``TopicError`` otherwise."""
    if not isinstance(name, str):
        raise TopicError(f"topic must be a string, not {type(name).__name__}")
    parts = name.split("/")
    if len(parts) < 4:
        raise TopicError(f"not a Cloud API topic {name!r:.120}: expected '<thing|sys>/product/<sn>/<kind>'")
    root = "/".join(parts[:2])
    if root not in (_THING, _SYS):
        raise TopicError(
            f"not a Cloud API topic {name!r:.120}: must start with 'thing/product/' or 'sys/product/'"
        )
    suffix = "/".join(parts[3:])
    kind = _BY_SUFFIX.get((root, suffix))
    if kind is None:
        known = sorted(k for r, k in _BY_SUFFIX if r == root)
        raise TopicError(f"unknown topic kind {suffix!r:.60} under {root}/: expected one of {known}")
    return ParsedTopic(kind, _check_sn(parts[2]))


def reply_kind(kind: TopicKind) -> TopicKind:
    """The kind that carries answers to ``kind`` (services → services_reply); ``ValueError`` if none."""
    info = TOPICS[TopicKind(kind)]
    if info.reply is None:
        raise ValueError(f"nobody answers on {info.kind.value!r}")
    return info.reply


def request_kind(kind: TopicKind) -> TopicKind | None:
    """The inverse of ``reply_kind``: services_reply → services; None for a kind that answers nothing."""
    for info in TOPICS.values():
        if info.reply == kind:
            return info.kind
    return None


def subscriptions(gateway_sn: str) -> list[str]:
    """Every topic the gateway subscribes to: the ``down`` kinds under its own SN."""
    return [topic(info.kind, gateway_sn) for info in TOPICS.values() if info.direction is Direction.DOWN]
