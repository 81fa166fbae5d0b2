"""``bench/run.py --quick`` runs inside ``make test`` as a smoke test: every suite runs to the end and
its sanity checks hold (a lost DRC session, a missed heartbeat echo, a decoder that decodes the wrong
frames all fail a suite). Bounded in time; no timing is asserted (speed is ``make bench``'s business:
without ``--strict`` a missed target does not change the exit status).

One test per suite (``--only NAME``), so a parallel run spreads them over its workers (all of them in
one process took 3.5 min, most of it waiting on brokers and simulated devices), each writing its report
under its own ``tmp_path``, never over a developer's ``bench/results/``.

The suites in :data:`BENCH_ONLY` are not run here: their quick runs cost 4-8 s of CPU each (a NATS
cluster, four gateways, a browser's worth of pages, video encoders), a sixth of make test's CPU on two
cores, and make test must hold its 5 minutes on a loaded CI machine. ``make bench`` runs them, before any
issue that touches a hot path is resolved; what they drive is tested here by the modules named."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from bench.run import SUITES

ROOT = Path(__file__).resolve().parents[1]


#: suite -> the tests that cover what it drives (its quick run's CPU, measured 2026-11-28 on 2 cores)
BENCH_ONLY: dict[str, tuple[str, ...]] = {
    "console": ("test_console_browser.py", "test_web_console.py"),  # 7.6 s
    "fleet": ("test_takeover.py", "test_gateway_service.py"),  # 6.9 s
    "video": ("test_video.py", "test_video_machine.py", "test_video_whip.py"),  # 5.1 s
    "e2e": ("test_gateway_service.py", "test_cli.py"),  # 4.8 s
    "failover": ("test_brokers_cluster.py", "test_exactly_once_kill.py", "test_liveness.py"),  # 4.0 s
    "scale": ("test_gateway_robomaster.py", "test_families.py"),  # 4.0 s
}


def test_every_bench_only_suite_exists_and_names_tests_that_do() -> None:
    names = {name for name, _ in SUITES}
    assert set(BENCH_ONLY) <= names, set(BENCH_ONLY) - names
    for suite, modules in BENCH_ONLY.items():
        for module in modules:
            assert (ROOT / "tests" / module).is_file(), (suite, module)
    assert len(BENCH_ONLY) < len(names) / 2  # most suites still run here


@pytest.mark.slow
@pytest.mark.timeout(600)
@pytest.mark.parametrize("suite", [name for name, _ in SUITES if name not in BENCH_ONLY])
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
