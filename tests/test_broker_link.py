"""The reconnect policy and the offline buffer, without sockets or sleeps (clock values in, decisions out)."""

from __future__ import annotations

import itertools
import random

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.broker_link import (
    SHORT_LIVED,
    STABLE_AFTER,
    TAKEOVER_STREAK,
    Loss,
    OfflineBuffer,
    ReconnectPolicy,
)


def policy(endpoints: int = 3, *, seed: int = 1) -> ReconnectPolicy:
    return ReconnectPolicy(
        endpoints,
        reconnect_min=0.5,
        reconnect_max=30.0,
        probe_interval=0.5,
        takeover_backoff_max=120.0,
        rng=random.Random(seed),
    )


@given(outage=st.floats(min_value=0.0, max_value=86_400.0), seed=st.integers(0, 2**32))
def test_probing_never_waits_longer_than_the_probe_interval_whatever_the_outage(
    outage: float, seed: int
) -> None:
    """A growing backoff waits longer the longer the broker was away; probe rounds do not: the round
    after any number of failed rounds starts within probe_interval, so the broker is found at most
    ~0.5 s after it returns."""
    p = policy(seed=seed)
    now = p.lost(1000.0, lasted=100.0, how=Loss.CLOSED)
    assert 1000.0 <= now <= 1000.5  # the first round after a loss: within reconnect_min
    end = now + outage
    rounds = 0
    while now < end and rounds < 10_000:
        nxt = p.next_round(now)
        assert 0.25 <= nxt - now <= 0.5
        now = nxt
        rounds += 1


def test_failover_prefers_the_node_after_the_one_that_died() -> None:
    p = policy(3)
    assert p.choose({0, 1, 2}) == 0  # the first url first
    p.connected(0.0, 0)
    assert p.choose({1, 2}) == 1  # node 0 died: the next one
    assert p.choose({0, 2}) == 2
    p.connected(1.0, 2)
    assert p.choose({0, 1, 2}) == 0  # wraps around
    with pytest.raises(ValueError):
        p.choose(set())


def test_a_broker_that_refuses_gets_capped_exponential_backoff_with_jitter() -> None:
    p = policy()
    waits = [p.refused(0.0) for _ in range(12)]
    ceilings = [min(30.0, 0.5 * 2**i) for i in range(12)]
    for wait, ceiling in zip(waits, ceilings, strict=True):
        assert ceiling / 2 <= wait <= ceiling
    assert max(waits) <= 30.0
    p.lost(100.0, lasted=STABLE_AFTER, how=Loss.CLOSED)  # a stable connection resets it
    assert p.refused(0.0) <= 0.5


def test_mqtt5_session_taken_over_backs_off_to_at_least_30_s_and_is_flagged() -> None:
    p = policy()
    waits = [p.lost(0.0, lasted=5.0, how=Loss.TAKEN_OVER) for _ in range(10)]
    assert p.takeover_suspected and p.takeover_count == 10
    assert 1.0 <= waits[0] <= 2.0
    assert all(b >= a / 2 for a, b in itertools.pairwise(waits))
    assert 60.0 <= waits[-1] <= 120.0  # the cap (takeover_backoff_max), well past 30 s
    p.lost(0.0, lasted=STABLE_AFTER, how=Loss.CLOSED)  # a connection that held clears it
    assert not p.takeover_suspected


def test_without_0x8e_a_takeover_is_a_streak_of_immediate_disconnects() -> None:
    p = policy()
    for _ in range(TAKEOVER_STREAK - 1):
        p.lost(0.0, lasted=0.4, how=Loss.CLOSED)
        assert not p.takeover_suspected
    wait = p.lost(0.0, lasted=0.4, how=Loss.CLOSED)
    assert p.takeover_suspected and wait >= 1.0
    # a broker restart (a long connection closed) is not a takeover
    q = policy()
    for _ in range(10):
        q.lost(0.0, lasted=SHORT_LIVED + 1, how=Loss.CLOSED)
    assert not q.takeover_suspected
    # the same pattern on MQTT 5 (mosquitto 2.0 closes a taken-over MQTT 5 connection without 0x8E)
    r = policy()
    for _ in range(TAKEOVER_STREAK):
        r.lost(0.0, lasted=0.4, how=Loss.CLOSED)
    assert r.takeover_suspected


def test_short_connections_with_outages_between_them_are_not_a_takeover() -> None:
    """A broker (or network) that goes down every 2 s closes short connections too; a probe round that
    no node answered in between says so: a twin needs the broker up to take the session over."""
    p = policy()
    for k in range(3 * TAKEOVER_STREAK):
        p.lost(10.0 * k, lasted=2.0, how=Loss.CLOSED)
        p.unreachable(10.0 * k + 1)
    assert not p.takeover_suspected and p.takeover_count == 0
    # with the broker answering every probe in between, the same short connections are a streak
    for k in range(TAKEOVER_STREAK):
        p.lost(100.0 + k, lasted=2.0, how=Loss.CLOSED)
    assert p.takeover_suspected


def test_a_stalled_connection_dropped_because_a_node_answers_reconnects_at_once() -> None:
    p = policy()
    assert p.lost(50.0, lasted=10.0, how=Loss.STALLED) == 50.0


def test_offline_buffer_is_bounded_by_count_and_age_oldest_first_in_order() -> None:
    b = OfflineBuffer(limit=3, max_age=10.0)
    for i in range(5):
        b.add(float(i), "t/osd", bytes([i]))
    assert b.dropped_overflow == 2 and len(b) == 3
    assert [p for _, _, p in b.take(5.0)] == [b"\x02", b"\x03", b"\x04"]  # the oldest went first
    for i in range(3):
        b.add(100.0 + i, "t/osd", bytes([i]))
    assert [p for _, _, p in b.take(111.5)] == [b"\x02"]  # the two older than 10 s expired
    assert b.dropped_age == 2
    b.add(200.0, "t/osd", b"new")
    b.put_back([(199.0, "t/osd", b"old")])  # what a flush could not send goes back in front
    assert [p for _, _, p in b.take(200.0)] == [b"old", b"new"]
    off = OfflineBuffer(limit=0, max_age=1.0)
    off.add(0.0, "t", b"x")
    assert len(off) == 0 and off.dropped_overflow == 1


def test_the_policy_module_is_sans_io() -> None:
    """No sockets, threads, clocks or paho in the decisions: everything arrives as values."""
    from tests.test_sans_io import FORBIDDEN_STDLIB, ROOT, _imports

    names = _imports(ROOT / "gateway" / "broker_link.py")
    assert not {n.split(".")[0] for n in names} & (FORBIDDEN_STDLIB | {"paho"}), names
    assert all(
        n.split(".")[0] in {"__future__", "random", "collections", "dataclasses", "enum"} for n in names
    )
