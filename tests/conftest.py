"""Test-session fixtures shared by every suite: hypothesis profile, brokers, CAN channels."""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from typing import Any

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


# -- scheduling for parallel runs (make test: pytest -n 6 --dist loadgroup) -------------------------------
#: Modules whose fixtures are module- or class-scoped (a simulated gateway, a browser, a NATS cluster): their
#: tests run on one worker, in file order, so the fixture starts once per run, not once per worker (and a
#: test that leans on what an earlier one left in that fixture still finds it).
SHARED_FIXTURE_MODULES = frozenset(
    {
        "test_brokers_cluster.py",
        "test_cloud_interop.py",
        "test_console_browser.py",
        "test_device_tree.py",
        "test_drc_interop.py",
        "test_fly.py",
        "test_schemas_export.py",
        "test_video.py",
        "test_video_whip.py",
    }
)
#: The longest tests (40-75 s alone on 2 cores, 2026-11-28): they start before the other long ones, so
#: the run does not end on one of them started late (a run ends when its last long test does). An ordering
#: hint only; tests/test_suite_hygiene.py checks each still names a test.
LONGEST: tuple[str, ...] = (
    "tests/test_restart_truth.py::test_killed_mid_return_home_the_restart_reports_it_and_can_cancel_it",
    "tests/test_return_home_e2e.py::test_return_home_lands_at_home_from[200m_away]",
    "tests/test_drc_session.py::TestDrcSession",
    "tests/test_readme_walkthrough.py::test_every_readme_command_block_runs_as_a_reader_would",
    "tests/test_wayline_cli.py::test_fly_a_route_from_the_console",
    "tests/test_console_browser.py::test_the_map_draws_a_wayline_task_and_its_progress",
    "tests/test_fuzz_atheris.py::test_atheris_target[drc]",
)
_FIRST = ("slow", "nats", "atheris", "browser")


def _rank(item: pytest.Item) -> int:
    """-1: :data:`LONGEST`; 0: long (marked slow, a NATS cluster, a fuzzer, a browser); 1: waits on a real
    broker; 2: the rest."""
    if item.nodeid.startswith(LONGEST):
        return -1
    if any(item.get_closest_marker(m) for m in _FIRST):
        return 0
    fixtures = getattr(item, "fixturenames", ())
    if item.get_closest_marker("broker") or "broker" in fixtures or "private_broker" in fixtures:
        return 1
    return 2


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Longest first, so parallel workers start the long waits early and fill the gaps with short tests
    (the run ends when its last long test does); a module with shared fixtures is ranked by its longest
    test and stays in one piece. The order within a module is kept; a test never depends on the order
    tests run in (CONTRIBUTING.md)."""
    modules: dict[str, int] = {}
    for item in items:
        if item.path.name in SHARED_FIXTURE_MODULES:
            modules[item.path.name] = min(modules.get(item.path.name, 2), _rank(item))
    order = {id(item): i for i, item in enumerate(items)}
    items.sort(key=lambda it: (modules.get(it.path.name, _rank(it)), order[id(it)]))


def shared_fixture_scope(nodeid: str) -> str:
    """The unit a parallel run hands to one worker: the whole module for SHARED_FIXTURE_MODULES, else
    the test alone."""
    path = nodeid.split("::", 1)[0]
    return path if path.rsplit("/", 1)[-1] in SHARED_FIXTURE_MODULES else nodeid


def pytest_xdist_make_scheduler(config: pytest.Config, log: Any) -> Any:
    """``--dist loadgroup``: pytest-xdist's scope scheduler with :func:`shared_fixture_scope` as the scope.
    (xdist 3.8's own loadgroup renames ``item._nodeid``, which pytest 9 no longer reads: its groups fell
    apart and a module's tests ran on several workers. ``_split_scope`` is how xdist's own loadscope
    and loadfile schedulers are made; tests/test_suite_hygiene.py checks it still groups.)"""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class ModuleGroups(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return shared_fixture_scope(nodeid)

    return ModuleGroups(config, log)
