"""The reconnect policy and the offline buffer, without sockets or sleeps (clock values in, decisions out)."""

from __future__ import annotations

import itertools
import random

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.broker_link import (
    BUSY_BACKOFF_MAX,
    CONNACK_FIRST,
    NEXT_NODE_JITTER,
    QUICK_MIN,
    SHORT_LIVED,
    STABLE_AFTER,
    TAKEOVER_STREAK,
    Liveness,
    LivenessProbe,
    Loss,
    OfflineBuffer,
    ProbeStep,
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


def _cycle(p: ReconnectPolicy, *, busy: bool) -> list[float]:
    """One attempt on every node, each failing; the waits the policy asked for."""
    waits = []
    for _ in range(p.endpoints):
        p.attempt(p.choose(set(range(p.endpoints))))
        waits.append(p.refused(0.0, busy=busy))
    return waits


def test_a_broker_that_refuses_gets_capped_exponential_backoff_with_jitter_once_every_node_refused() -> None:
    p = policy()
    cycles = [_cycle(p, busy=False) for _ in range(12)]
    ceilings = [min(30.0, 0.5 * 2**i) for i in range(12)]
    for waits, ceiling in zip(cycles, ceilings, strict=True):
        assert all(0.0 <= w <= NEXT_NODE_JITTER for w in waits[:-1])  # other nodes untried: no backoff
        assert ceiling / 2 <= waits[-1] <= ceiling
    assert max(w for c in cycles for w in c) <= 30.0
    p.lost(100.0, lasted=STABLE_AFTER, how=Loss.CLOSED)  # a stable connection resets it
    assert _cycle(p, busy=False)[-1] <= 0.5


def test_each_node_is_tried_in_turn_before_any_backoff() -> None:
    """A node that answers TCP and fails the attempt is not chosen again while another answers."""
    p = policy(3)
    p.connected(0.0, 0)  # node 0 was ours and died
    tried = []
    for _ in range(4):
        index = p.choose({1, 2})
        p.attempt(index)
        tried.append(index)
        p.refused(0.0, busy=True)
    assert tried == [1, 2, 1, 2]


def test_a_busy_cluster_is_retried_within_a_second_whatever_it_lasted() -> None:
    """No CONNACK, closed before the CONNACK, server unavailable: the cluster is not ready. Once every node
    failed, the backoff grows from reconnect_min/2 but never past BUSY_BACKOFF_MAX: the gateway comes back
    at most ~1 s after the cluster does, and a fleet spreads its attempts (½–1× the ceiling)."""
    for seed in range(20):
        p = policy(seed=seed)
        lasts = [_cycle(p, busy=True)[-1] for _ in range(40)]
        assert 0.25 <= lasts[0] <= 0.5
        assert all(BUSY_BACKOFF_MAX / 2 <= w <= BUSY_BACKOFF_MAX for w in lasts[1:])
        p.connected(0.0, 1)  # a CONNACK resets it
        assert _cycle(p, busy=True)[-1] <= 0.5


def test_the_connack_deadline_is_short_with_several_nodes() -> None:
    assert policy(3).connack_timeout(5.0) == CONNACK_FIRST
    assert policy(1).connack_timeout(5.0) == 5.0  # one broker: nowhere else to go
    assert policy(3).connack_timeout(0.5) == 0.5


def test_a_dead_node_does_not_hold_the_cycle_open() -> None:
    """Node 0 died (it answers no probe): once nodes 1 and 2 both failed, the backoff applies."""
    p = policy(3)
    p.connected(0.0, 0)
    waits = []
    for _ in range(2):
        p.attempt(p.choose({1, 2}))
        waits.append(p.refused(0.0, busy=True))
    assert waits[0] <= NEXT_NODE_JITTER and waits[1] >= 0.25


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


# ------------------------------------------------------------------------------------------ liveness
def probe(interval: float = 5.0, timeout: float = 3.0, seed: int = 1) -> LivenessProbe:
    return LivenessProbe(interval=interval, timeout=timeout, rng=random.Random(seed))


def test_a_probe_goes_out_on_every_suback_and_then_every_interval_while_it_comes_back() -> None:
    p = probe()
    assert p.step(0.0) is ProbeStep.NONE  # not subscribed yet: nothing to prove
    p.subscribed(10.0)
    assert p.step(10.0) is ProbeStep.SEND
    first = p.nonce
    assert p.step(10.5) is ProbeStep.NONE  # outstanding, deadline not reached
    assert p.received(10.02, first.encode())
    assert p.state is Liveness.LIVE and p.last_rtt == pytest.approx(0.02)
    due = p.next_at()
    assert due is not None and 10.02 + 2.5 <= due <= 10.02 + 5.0  # jittered ½–1× interval
    assert p.step(due - 0.01) is ProbeStep.NONE
    assert p.step(due) is ProbeStep.SEND
    assert p.nonce != first  # a new nonce each time: a late copy of the old one proves nothing
    assert not p.received(due + 0.01, first.encode())
    assert p.received(due + 0.01, p.nonce.encode())


def test_a_missed_probe_makes_the_link_deaf_resubscribes_then_reconnects() -> None:
    p = probe(timeout=3.0)
    p.subscribed(0.0)
    assert p.step(0.0) is ProbeStep.SEND
    assert p.step(2.99) is ProbeStep.NONE and p.state is Liveness.UNPROVEN
    assert p.step(3.0) is ProbeStep.RESUBSCRIBE
    assert p.deaf and p.deaf_count == 1
    p.subscribed(3.1)  # the SUBACK of the resubscription
    assert p.step(3.1) is ProbeStep.SEND
    assert p.step(6.1) is ProbeStep.RECONNECT
    assert p.deaf_count == 1  # still the same deafness: counted once
    p.lost()
    assert p.step(100.0) is ProbeStep.NONE  # no connection: nothing to send
    assert p.deaf  # deaf until a probe comes back, whatever node the link is on now
    p.subscribed(100.5)  # connected again (the next node) and subscribed
    assert p.step(100.5) is ProbeStep.SEND
    assert p.received(100.51, p.nonce.encode())
    assert p.state is Liveness.LIVE and not p.deaf


def test_deafness_is_detected_and_acted_on_within_two_timeouts_of_the_suback() -> None:
    """The issue's bound: a link deaf from its SUBACK is given up 2 × timeout later; one deaf in the
    middle of a connection at most interval + 2 × timeout later (5 + 2 × 3 = 11 s < 15 s by default)."""
    for seed in range(50):
        p = probe(seed=seed)
        p.subscribed(0.0)
        t, steps = 0.0, []
        while t < 20.0:
            step = p.step(t)
            if step is ProbeStep.RESUBSCRIBE:
                p.subscribed(t + 0.01)
            if step is not ProbeStep.NONE:
                steps.append((round(t, 2), step))
            if step is ProbeStep.RECONNECT:
                break
            t += 0.05
        assert steps[-1][1] is ProbeStep.RECONNECT and steps[-1][0] <= 2 * 3.0 + 0.2
        # healthy for a while, then deaf: the reconnect comes within interval + 2 × timeout
        p = probe(seed=seed)
        p.subscribed(0.0)
        t = 0.0
        deaf_from = 30.0
        while True:
            step = p.step(t)
            if step is ProbeStep.SEND and t < deaf_from:
                assert p.received(t + 0.01, p.nonce.encode())
            elif step is ProbeStep.RESUBSCRIBE:
                p.subscribed(t + 0.01)
            elif step is ProbeStep.RECONNECT:
                break
            t = round(t + 0.05, 2)
        assert deaf_from < t <= deaf_from + 5.0 + 2 * 3.0 + 0.2


def test_other_messages_delivered_after_a_missed_probe_prove_the_link() -> None:
    """A NATS cluster after a node died: the probe topic's consumer has no leader for seconds while the
    cloud's requests flow. Messages delivered after the probe went out prove the link; none since (or only
    older ones) and it is deaf as before."""
    p = probe(timeout=1.0)
    p.subscribed(0.0)
    assert p.step(0.0) is ProbeStep.SEND
    assert p.step(1.0, traffic_at=0.4) is ProbeStep.NONE  # a request came in after the probe went out
    assert p.state is Liveness.LIVE and not p.deaf and p.last_proof == 0.4
    due = p.next_at()
    assert due is not None and 1.0 + 2.5 <= due <= 1.0 + 5.0  # the next probe at the usual interval
    assert p.step(due) is ProbeStep.SEND
    # the requests stopped too: only a message from before this probe; deaf, resubscribe, then reconnect
    assert p.step(due + 1.0, traffic_at=0.4) is ProbeStep.RESUBSCRIBE and p.deaf
    p.subscribed(due + 1.1)
    assert p.step(due + 1.1, traffic_at=0.4) is ProbeStep.SEND
    assert p.step(due + 2.1, traffic_at=0.4) is ProbeStep.RECONNECT


def test_a_lost_suback_after_resubscribing_still_leads_to_the_next_probe() -> None:
    p = probe(timeout=1.0)
    p.subscribed(0.0)
    assert p.step(0.0) is ProbeStep.SEND
    assert p.step(1.0) is ProbeStep.RESUBSCRIBE
    assert p.step(1.5) is ProbeStep.NONE
    assert p.step(2.0) is ProbeStep.SEND  # no SUBACK seen: probe anyway after a timeout
    assert p.step(3.0) is ProbeStep.RECONNECT


def test_liveness_off_never_asks_anything() -> None:
    p = probe(interval=0.0)
    p.subscribed(0.0)
    assert all(p.step(t) is ProbeStep.NONE for t in (0.0, 1.0, 100.0))
    assert not p.deaf


def test_a_deaf_connection_is_left_for_the_next_node_soon_but_jittered() -> None:
    p = policy(3, seed=4)
    p.connected(0.0, 0)
    waits = []
    for i in range(40):
        at = p.lost(100.0 * i, lasted=6.0, how=Loss.DEAF)
        waits.append(at - 100.0 * i)
    assert all(0.0 <= w <= 0.5 for w in waits) and len({round(w, 4) for w in waits}) > 10
    assert not p.takeover_suspected  # short deaf connections are not a twin's doing
    assert p.choose({0, 1, 2}) == 1  # the node after the deaf one first


def test_a_connection_not_proven_yet_gets_a_quick_deadline_from_the_links_round_trips() -> None:
    """The first connection of a process waits ``timeout`` (no round trip known); once the link has
    shown its round trips, a new connection (after a failover) is given QUICK_FACTOR × the slowest of
    them, at least QUICK_MIN: a connection made while a cluster elects its leaders is found deaf and left
    in well under a second, not 2 × 3 s."""
    p = probe(timeout=3.0)
    p.subscribed(0.0)
    assert p.step(0.0) is ProbeStep.SEND and p.next_at() == 3.0  # nothing known: the full timeout
    assert p.received(0.004, p.nonce.encode())
    p.lost()  # the node dies; a new connection to the next one
    p.subscribed(10.0)
    assert p.step(10.0) is ProbeStep.SEND and p.next_at() == pytest.approx(10.0 + QUICK_MIN)
    assert p.step(10.0 + QUICK_MIN) is ProbeStep.RESUBSCRIBE
    p.subscribed(10.35)
    assert p.step(10.35) is ProbeStep.SEND
    assert p.step(10.35 + QUICK_MIN) is ProbeStep.RECONNECT  # deaf twice: 0.6 s after the SUBACK
    # a proven connection's periodic probe keeps the full timeout (no false alarm on a busy link)
    p.lost()
    p.subscribed(20.0)
    assert p.step(20.0) is ProbeStep.SEND
    assert p.received(20.01, p.nonce.encode())
    due = p.next_at()
    assert due is not None and p.step(due) is ProbeStep.SEND and p.next_at() == pytest.approx(due + 3.0)


def test_a_late_probe_proves_the_link_slow_not_deaf_and_widens_the_quick_deadline() -> None:
    p = probe(timeout=3.0)
    p.subscribed(0.0)
    p.step(0.0)
    assert p.received(0.01, p.nonce.encode())
    p.lost()
    p.subscribed(5.0)
    assert p.step(5.0) is ProbeStep.SEND
    slow = p.nonce.encode()
    assert p.step(5.0 + QUICK_MIN) is ProbeStep.RESUBSCRIBE and p.deaf
    assert p.received(5.0 + 0.5, slow)  # back after 0.5 s: it receives, slowly
    assert p.state is Liveness.LIVE and not p.deaf
    assert p.quick_deadline() == pytest.approx(4 * 0.5)  # the next quick deadline allows for it
    assert not p.received(5.6, b"djigw-probe 000000000000 1")  # another process's probe proves nothing
