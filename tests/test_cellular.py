"""Cellular links: the gateway in a network namespace of its own, joined to the broker by a veth pair
that this test makes; an LTE-like profile (80 ms RTT ± 20 ms, 1 % loss) with ``tc netem``, or, where the
kernel has no netem, with the userspace relay ``tests/linkemu.py`` (both run where they can; each skips
saying why where it cannot); and a 5 s partition (``ip link set … down``: real TCP retransmissions, no
reset) with osd, services and live control going. ``make bench`` (``bench/partitions.py``) measures the
30 s and 120 s partitions and more services; docs/reliability.md has the figures."""

from __future__ import annotations

from typing import Any

import pytest

from bench.partitions import LTE, Rig, measure_partition, measure_services
from tests.netlab import netem_problem, netns_problem

pytestmark = [pytest.mark.broker, pytest.mark.netns]


def _need(method: str) -> None:
    problem = netns_problem() if method == "relay" else netem_problem()
    if problem is not None:
        pytest.skip(f"{method}: {problem}")


@pytest.mark.parametrize("method", ["netem", "relay"])
def test_services_under_an_lte_profile(method: str) -> None:
    _need(method)
    with Rig(method, LTE) as rig:
        s = measure_services(rig, 30)
    print(f"\nLTE ({method}): {s.ok}/{s.sent} answered, p50 {s.p50_ms:.0f} ms, p99 {s.p99_ms:.0f} ms")
    assert s.ok == s.sent  # 1 % loss costs time (a retransmission), never an answer
    assert s.max_ms < 3000  # each within the cloud's 3 s (generous: the profile adds ~80 ms)
    assert s.p50_ms > 60  # the profile really is in the path (80 ms RTT)


@pytest.mark.parametrize("method", ["netem", "relay"])
def test_a_5_s_partition_under_lte(method: str) -> None:
    _need(method)
    with Rig(method, LTE) as rig:
        p = measure_partition(rig, 5.0)
        app: Any = rig.gw.app
        assert app.bridge.subscribed
    print(f"\npartition 5 s ({method}): {p}")
    # traffic resumes soon after the heal (make bench: <= 1 s; generous here for a loaded machine)
    assert p.resume_osd < 3.0 and p.resume_services < 3.0, p
    # osd produced during the partition was buffered and delivered after it, in order, nothing dropped
    assert p.osd_during >= 10 and p.osd_out_of_order == 0 and p.osd_dropped == 0, p
    # what the cloud asked meanwhile was queued by the broker and answered after the heal
    assert p.requests_during > 0 and p.requests_during_answered == p.requests_during, p
    # live control: stopped during the partition, the session ended (the link was lost), and the
    # gimbal did not move again by itself although the cloud's sticks kept coming after the heal
    assert p.failsafe_after < 3.0 + 1.0, p
    assert 514303 in p.drc_events and not p.moved_after_heal, p
    assert p.stalls >= 1
