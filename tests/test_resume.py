"""Fast resume after a broker outage: the gateway probes the broker every ``probe_interval`` (0.5 s by
default) instead of a backoff that grows with the outage, so telemetry and services flow again soon
after the broker returns, whatever the outage lasted. The exact schedule is tested without sleeping
in ``tests/test_broker_link.py``; here a real mosquitto is killed and restarted (``make bench`` measures
2, 6 and 15 s outages: ``bench/resume.py``)."""

from __future__ import annotations

import pytest

from bench.resume import measure

pytestmark = pytest.mark.broker


def test_telemetry_and_services_resume_soon_after_a_6_s_outage() -> None:
    (r,) = measure([6.0], settle=0.5)
    print(f"\nresume after 6 s: telemetry {r.telemetry:.2f} s, fresh osd {r.fresh_telemetry:.2f} s, "
          f"services {r.services:.2f} s, {r.buffered_delivered} buffered osd delivered")  # fmt: skip
    # generous deadlines (a loaded CI machine), still well under what a growing backoff gave (6.5 s)
    assert r.telemetry < 3.0 and r.services < 3.0, r
    assert r.buffered_delivered > 0  # osd produced during the outage was kept and delivered after it
