"""What keeps the suite fast and honest in parallel: the example counts that matter survive every
Hypothesis profile (the quick one included), and ``make test`` runs the suite under pytest-xdist."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from hypothesis import settings

from tests.test_drc_session import DrcSessionMachine

ROOT = Path(__file__).resolve().parent.parent


def test_the_drc_state_machine_keeps_its_2000_examples_under_every_profile() -> None:
    assert DrcSessionMachine.TestCase.settings.max_examples >= 2000
    for name in ("default", "ci", "quick"):
        profile = settings.get_profile(name)
        # a profile sets the others' count; the state machine's own settings are not derived from it
        assert settings(profile, max_examples=2000).max_examples == 2000


def test_the_ci_profile_is_reproducible() -> None:
    ci = settings.get_profile("ci")
    assert ci.derandomize and ci.database is None
    assert ci.max_examples >= settings.get_profile("default").max_examples


def test_make_test_runs_the_suite_in_parallel() -> None:
    makefile = (ROOT / "Makefile").read_text()
    recipe = re.search(r"^test:.*\n((?:\t.+\n)+)", makefile, re.MULTILINE)
    assert recipe is not None
    lines = recipe.group(1).splitlines()
    # the last line runs the suite in parallel, with the bytecode cache on (the lines before fill it)
    assert "-m pytest" in lines[-1] and "-n $(TEST_WORKERS)" in lines[-1], lines
    assert all(line.startswith("\tPYTHONDONTWRITEBYTECODE= ") for line in lines), lines
    workers = re.search(r"^TEST_WORKERS \?= (\d+)$", makefile, re.MULTILINE)
    assert workers is not None and int(workers.group(1)) >= 2


#: Modules excused from the rule (none: every long module says why)
SIZE_EXEMPT: tuple[str, ...] = ()


def test_a_module_over_500_lines_says_why_at_its_top() -> None:
    """A long module is a smell unless its docstring says why it is one piece (issue #32)."""
    missing = []
    for package in ("schemas", "adapters", "gateway"):
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            text = path.read_text()
            if text.count("\n") <= 500 or (SIZE_EXEMPT and rel.startswith(SIZE_EXEMPT)):
                continue
            doc = ast.get_docstring(ast.parse(text)) or ""
            if "Why this module is longer than 500 lines" not in doc:
                missing.append(rel)
    assert missing == []


def test_every_module_with_a_shared_fixture_runs_as_one_group() -> None:
    """A module- or class-scoped fixture split over parallel workers starts once per worker (a simulated
    gateway, a browser, a NATS cluster): such modules are listed in conftest's SHARED_FIXTURE_MODULES."""
    from tests.conftest import SHARED_FIXTURE_MODULES

    shared = re.compile(r"scope=[\"'](module|class|package)[\"']")
    found = {p.name for p in (ROOT / "tests").glob("test_*.py") if shared.search(p.read_text())}
    assert found == set(SHARED_FIXTURE_MODULES)


def test_the_parallel_scheduler_keeps_a_shared_fixture_module_together() -> None:
    from xdist.scheduler import LoadScopeScheduling

    from tests.conftest import shared_fixture_scope

    assert callable(getattr(LoadScopeScheduling, "_split_scope", None)), "xdist moved its scope hook"
    together = {shared_fixture_scope(f"tests/test_drc_interop.py::test_{n}") for n in ("a", "b[x]")}
    assert together == {"tests/test_drc_interop.py"}
    assert shared_fixture_scope("tests/test_outage.py::test_a") == "tests/test_outage.py::test_a"


def test_every_longest_hint_names_a_test(request: pytest.FixtureRequest) -> None:
    """conftest.LONGEST orders the run; a hint that names no test any more is a stale hint."""
    from tests.conftest import LONGEST

    session_ids = [item.nodeid for item in request.session.items]
    if len(session_ids) < 100:  # run alone (-k, one file): collect the whole suite's ids
        import subprocess
        import sys

        out = subprocess.run(
            [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider"],
            cwd=ROOT, capture_output=True, text=True, timeout=120, check=True,
        ).stdout  # fmt: skip
        session_ids = [line for line in out.splitlines() if "::" in line]
    for hint in LONGEST:
        assert any(nodeid.startswith(hint) for nodeid in session_ids), hint
