"""Topic builders and the parser: round trips for every kind, and clear errors for everything else."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from schemas import TOPICS, Direction, TopicError, TopicKind, parse_topic, reply_kind, subscriptions, topic
from schemas.topics import request_kind, template

SN = st.from_regex(r"[A-Za-z0-9][A-Za-z0-9._-]{0,63}", fullmatch=True)


@pytest.mark.parametrize(
    ("kind", "expected"),
    [
        (TopicKind.OSD, "thing/product/SN1/osd"),
        (TopicKind.STATE, "thing/product/SN1/state"),
        (TopicKind.SERVICES, "thing/product/SN1/services"),
        (TopicKind.SERVICES_REPLY, "thing/product/SN1/services_reply"),
        (TopicKind.EVENTS, "thing/product/SN1/events"),
        (TopicKind.EVENTS_REPLY, "thing/product/SN1/events_reply"),
        (TopicKind.REQUESTS, "thing/product/SN1/requests"),
        (TopicKind.REQUESTS_REPLY, "thing/product/SN1/requests_reply"),
        (TopicKind.PROPERTY_SET, "thing/product/SN1/property/set"),
        (TopicKind.PROPERTY_SET_REPLY, "thing/product/SN1/property/set_reply"),
        (TopicKind.DRC_DOWN, "thing/product/SN1/drc/down"),
        (TopicKind.DRC_UP, "thing/product/SN1/drc/up"),
        (TopicKind.STATUS, "sys/product/SN1/status"),
        (TopicKind.STATUS_REPLY, "sys/product/SN1/status_reply"),
    ],
)
def test_topic_names(kind: TopicKind, expected: str) -> None:
    assert topic(kind, "SN1") == expected
    assert parse_topic(expected) == (kind, "SN1")
    assert template(kind) == expected.replace("SN1", "{sn}")


def test_every_kind_is_in_the_table() -> None:
    assert set(TOPICS) == set(TopicKind)


@given(kind=st.sampled_from(list(TopicKind)), sn=SN)
def test_build_parse_round_trip(kind: TopicKind, sn: str) -> None:
    parsed = parse_topic(topic(kind, sn))
    assert parsed.kind is kind and parsed.sn == sn


@pytest.mark.parametrize(
    ("name", "why"),
    [
        ("thing/product/SN1", "expected"),
        ("thing/product/SN1/nope", "unknown topic kind"),
        ("thing/product/SN1/status", "unknown topic kind"),  # status lives under sys/
        ("sys/product/SN1/services", "unknown topic kind"),
        ("foo/product/SN1/osd", "must start with"),
        ("thing/product//osd", "invalid serial number"),
        ("thing/product/+/osd", "invalid serial number"),
        ("thing/product/#/osd", "invalid serial number"),
        ("thing/product/SN1/drc/sideways", "unknown topic kind"),
        ("/thing/product/SN1/osd", "must start with"),
    ],
)
def test_parse_errors_are_clear(name: str, why: str) -> None:
    with pytest.raises(TopicError, match=why):
        parse_topic(name)


@pytest.mark.parametrize("sn", ["", "a/b", "+", "#", "x" * 65, "-lead", "sp ace"])
def test_builder_refuses_unusable_serial_numbers(sn: str) -> None:
    with pytest.raises(TopicError, match="invalid serial number"):
        topic(TopicKind.OSD, sn)


@given(st.text(max_size=80))
def test_parser_raises_only_topic_error(name: str) -> None:
    try:
        parsed = parse_topic(name)
    except TopicError:
        return
    assert topic(parsed.kind, parsed.sn) == name


def test_reply_kinds_and_directions() -> None:
    assert reply_kind(TopicKind.SERVICES) is TopicKind.SERVICES_REPLY
    assert reply_kind(TopicKind.DRC_DOWN) is TopicKind.DRC_UP
    assert reply_kind(TopicKind.STATUS) is TopicKind.STATUS_REPLY
    assert reply_kind(TopicKind.PROPERTY_SET) is TopicKind.PROPERTY_SET_REPLY
    assert request_kind(TopicKind.EVENTS_REPLY) is TopicKind.EVENTS
    assert request_kind(TopicKind.OSD) is None
    with pytest.raises(ValueError, match="nobody answers"):
        reply_kind(TopicKind.OSD)
    for info in TOPICS.values():
        if info.reply is not None:  # an answer always travels the other way
            assert TOPICS[info.reply].direction is not info.direction


def test_gateway_subscribes_to_every_down_topic() -> None:
    assert sorted(subscriptions("GW1")) == sorted(
        [
            "thing/product/GW1/services",
            "thing/product/GW1/events_reply",
            "thing/product/GW1/requests_reply",
            "thing/product/GW1/property/set",
            "thing/product/GW1/drc/down",
            "sys/product/GW1/status_reply",
        ]
    )
    assert all(TOPICS[parse_topic(name).kind].direction is Direction.DOWN for name in subscriptions("GW1"))
