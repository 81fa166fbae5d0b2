"""``bench/run.py --quick`` runs inside ``make test`` as a smoke test: every suite runs to the end and
its sanity checks hold (a lost DRC session, a missed heartbeat echo, a decoder that decodes the wrong
frames all fail a suite). Bounded in time; no timing is asserted (speed is ``make bench``'s business:
without ``--strict`` a missed target does not change the exit status).

One test per suite (``--only NAME``), so a parallel run spreads them over its workers (all of them in
one process took 3.5 min, most of it waiting on brokers and simulated devices), each writing its report
under its own ``tmp_path``, never over a developer's ``bench/results/``."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from bench.run import SUITES

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.parametrize("suite", [name for name, _ in SUITES])
def test_every_bench_suite_runs_quick_to_the_end(suite: str, tmp_path: Path) -> None:
    argv = [sys.executable, str(ROOT / "bench" / "run.py"), "--quick", "--only", suite]
    proc = subprocess.run(
        [*argv, "--results", str(tmp_path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=540,
    )
    report = tmp_path / f"{suite}.txt"  # a failed suite's report holds its traceback (stderr goes on)
    assert proc.returncode == 0, (
        report.read_text()[-4000:] if report.is_file() else "(no report)",
        proc.stdout[-2000:],
        proc.stderr[-2000:],
    )
    assert f"== {suite} ==" in proc.stdout, f"suite {suite} did not run"
    assert report.is_file()
