"""The token bucket behind ``drc.max_stick_rate``: never more than the rate allows, never less."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from gateway.ratelimit import TokenBucket


def test_a_burst_then_the_rate() -> None:
    bucket = TokenBucket(rate=10, burst=3, now=0.0)
    assert [bucket.take(0.0) for _ in range(4)] == [True, True, True, False]
    assert not bucket.take(0.05)  # half a token
    assert bucket.take(0.1)  # one token a tenth of a second
    assert not bucket.take(0.1)
    assert [bucket.take(10.0) for _ in range(4)] == [True, True, True, False]  # capped at the burst


def test_a_clock_that_steps_back_grants_nothing() -> None:
    bucket = TokenBucket(rate=10, burst=1, now=5.0)
    assert bucket.take(5.0)
    assert not bucket.take(4.0)
    assert not bucket.take(5.05)


@pytest.mark.parametrize(("rate", "burst"), [(0, 1), (-1, 5), (10, 0.5)])
def test_nonsense_is_refused(rate: float, burst: float) -> None:
    with pytest.raises(ValueError):
        TokenBucket(rate, burst, now=0.0)


@given(
    rate=st.floats(1, 1000),
    burst=st.floats(1, 100),
    gaps=st.lists(st.floats(0, 0.5), min_size=1, max_size=300),
)
def test_never_more_than_burst_plus_rate_times_time(rate: float, burst: float, gaps: list[float]) -> None:
    bucket, now, taken = TokenBucket(rate, burst, now=0.0), 0.0, 0
    for gap in gaps:
        now += gap
        taken += bucket.take(now)
    assert taken <= burst + rate * now + 1e-6


@given(rate=st.floats(1, 1000), burst=st.floats(1, 100), n=st.integers(1, 200))
def test_events_at_the_rate_are_never_refused(rate: float, burst: float, n: int) -> None:
    bucket = TokenBucket(rate, burst, now=0.0)
    assert all(bucket.take(i / rate * 1.0001) for i in range(n))
