"""Test-session fixtures shared by every suite: hypothesis profile, brokers, CAN channels."""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator

import pytest
from hypothesis import HealthCheck, settings

from gateway.local_broker import LocalBroker

# Hypothesis profiles. Tests whose example count matters set it themselves (the DRC session's state
# machine: 2,000 examples in tests/test_drc_session.py; the fuzzers), and every profile keeps those
# (tests/test_suite_hygiene.py checks); the profile sets everyone else's.
#   default  a developer's run: 200 examples, random, the failing examples remembered in .hypothesis/
#   ci       CI=true: the same counts, derandomized (a run is reproducible on every worker and every run),
#            no example database (a fresh clone has none to learn from), the reproduction blob printed
#   quick    HYPOTHESIS_PROFILE=quick: 20 examples for a fast local loop; never in CI
settings.register_profile(
    "default",
    deadline=None,
    max_examples=200,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.register_profile(
    "ci", parent=settings.get_profile("default"), derandomize=True, database=None, print_blob=True
)
settings.register_profile("quick", parent=settings.get_profile("default"), max_examples=20)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE") or ("ci" if os.environ.get("CI") else "default"))


@pytest.fixture(scope="session")
def broker() -> Iterator[LocalBroker]:
    """One mosquitto for the session, on a free loopback port (never a broker someone else started)."""
    with LocalBroker() as b:
        yield b


@pytest.fixture
def private_broker() -> Iterator[LocalBroker]:
    """A broker of this test's own, for tests that kill and restart it."""
    b = LocalBroker().start()
    try:
        yield b
    finally:
        b.stop()


@pytest.fixture
def can_channel() -> str:
    """A fresh python-can virtual channel name, so tests never hear each other."""
    return f"djigw-test-{uuid.uuid4().hex[:8]}"


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    from tests import fuzz_stats

    if fuzz_stats.CASES:
        total = sum(fuzz_stats.CASES.values())
        parts = ", ".join(f"{name} {n}" for name, n in sorted(fuzz_stats.CASES.items()))
        failed = len(terminalreporter.stats.get("failed", []))
        crashes = 0 if not failed else "see failures"
        terminalreporter.write_line(f"fuzz: {total} cases ({parts}), {crashes} crashes")
