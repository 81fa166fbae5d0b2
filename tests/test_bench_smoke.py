"""``bench/run.py --quick`` runs inside ``make test`` as a smoke test: every suite runs to the end and
its sanity checks hold (a lost DRC session, a missed heartbeat echo, a decoder that decodes the wrong
frames all fail a suite). Bounded in time; no timing is asserted (speed is ``make bench``'s business:
without ``--strict`` a missed target does not change the exit status)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from bench.run import SUITES

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_every_bench_suite_runs_quick_to_the_end() -> None:
    proc = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "run.py"), "--quick"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=840,
    )
    assert proc.returncode == 0, (proc.stdout[-3000:], proc.stderr[-3000:])
    for name, _ in SUITES:
        assert f"== {name} ==" in proc.stdout, f"suite {name} did not run"
