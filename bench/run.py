"""Benchmark runner behind ``make bench``: runs every registered suite, prints plain-text tables and
writes each suite's report to ``bench/results/<suite>.txt`` (git-ignored).

A suite is a ``(name, callable)`` pair in :data:`SUITES`; the callable takes a :class:`Config` and
returns a list of :class:`Row`. Add a suite by appending one pair (imported lazily, so a suite's
dependencies load only when it runs). The shared timing helper :func:`best_of` lives here so every
suite measures the same way: warm-up, best of N, gc disabled only inside the timed region.

Exit status: 0 when every suite ran and every sanity check held; 1 when a suite failed (a decoder
that decoded the wrong number of frames is a failure, not a slow result); 2 with ``--strict`` when a
performance target was missed. Missing a target is otherwise reported, not fatal: timings depend on
the machine, and a smoke test must not turn into a timed test.

Run: ``.venv/bin/python bench/run.py [--quick] [--only NAME] [--strict]``.
"""

from __future__ import annotations

import argparse
import gc
import importlib
import os
import platform
import subprocess
import sys
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "bench" / "results"


@dataclass(frozen=True, slots=True)
class Config:
    """What a suite is asked to do: ``quick`` = short runs (smoke test), ``repeat`` = best of N."""

    quick: bool = False
    repeat: int = 5
    warmup: int = 1


@dataclass(frozen=True, slots=True)
class Row:
    """One measured line of a suite's table.

    ``rate`` is ours (``unit`` per second, best of N); ``base_rate`` the baseline's, if the suite has
    one. ``min_rate``/``min_ratio`` are targets; a row without targets reports no verdict."""

    group: str
    case: str
    count: int
    rate: float
    base_rate: float | None = None
    base_count: int | None = None
    min_rate: float | None = None
    min_ratio: float | None = None
    max_over_base: float | None = None  # latency rows: ours may exceed the baseline by at most this
    unit: str = "frames/s"
    note: str = ""

    @property
    def ratio(self) -> float | None:
        if self.base_rate is None or self.base_rate <= 0:
            return None
        return self.rate / self.base_rate

    @property
    def target(self) -> str:
        parts = []
        if self.min_rate is not None:
            parts.append(f">={self.min_rate:,.0f}/s")
        if self.min_ratio is not None:
            parts.append(f">={self.min_ratio:g}x")
        if self.max_over_base is not None:
            parts.append(f"<=base+{self.max_over_base:g}")
        return " & ".join(parts)

    @property
    def passed(self) -> bool | None:
        """None when the row has no target."""
        if self.min_rate is None and self.min_ratio is None and self.max_over_base is None:
            return None
        ok = True
        if self.min_rate is not None:
            ok = ok and self.rate >= self.min_rate
        if self.min_ratio is not None:
            ratio = self.ratio
            ok = ok and ratio is not None and ratio >= self.min_ratio
        if self.max_over_base is not None:
            ok = ok and self.base_rate is not None and self.rate - self.base_rate <= self.max_over_base
        return ok


Suite = Callable[[Config], list[Row]]


def _lazy(module: str, func: str = "run") -> Suite:
    def call(cfg: Config) -> list[Row]:
        suite: Suite = getattr(importlib.import_module(module), func)
        return suite(cfg)

    return call


# name -> callable(Config) -> rows. Later suites (end-to-end MQTT round trips) append here.
SUITES: list[tuple[str, Suite]] = [
    ("codecs", _lazy("bench.codecs")),
    ("e2e", _lazy("bench.e2e")),
    ("drc_session", _lazy("bench.drc_session")),
    ("drc", _lazy("bench.drc")),
    ("scale", _lazy("bench.scale")),
    ("fleet", _lazy("bench.fleet")),
    ("restarts", _lazy("bench.restarts")),
    ("resume", _lazy("bench.resume")),
    ("partitions", _lazy("bench.partitions")),
    ("failover", _lazy("bench.failover")),
    ("console", _lazy("bench.console")),
    ("wayline", _lazy("bench.wayline")),
    ("soak", _lazy("bench.soak")),
    ("video", _lazy("bench.video")),
]
#: suites timed inside this one process, pinned to one CPU. The others run brokers, gateways and
#: simulators as several processes, which inherit the affinity: pinned, 100 gateway processes and the
#: broker would share one core of a two-core machine. They get every CPU, as deployed.
PINNED = frozenset({"codecs", "drc_session"})


# --------------------------------------------------------------------------- timing


def best_of(fn: Callable[[], Any], repeat: int, warmup: int = 1) -> tuple[float, Any]:
    """Best wall time of ``repeat`` calls of ``fn`` (after ``warmup`` untimed calls) and the output of
    the last call, for the caller's sanity checks. The garbage collector is off only while ``fn``
    runs: a collection landing in one run would measure the allocator, not the code."""
    out: Any = None
    for _ in range(warmup):
        out = fn()
    best = float("inf")
    was_enabled = gc.isenabled()
    for _ in range(max(1, repeat)):
        out = None  # free the previous run's output before the next one
        gc.collect()
        gc.disable()
        try:
            t0 = time.perf_counter()
            out = fn()
            dt = time.perf_counter() - t0
        finally:
            if was_enabled:
                gc.enable()
        best = min(best, dt)
    return best, out


def pin_one_cpu() -> tuple[str, set[int] | None]:
    """Pin this process to one CPU (the measurements are single-threaded anyway; pinning keeps the
    scheduler from migrating it mid-run). Returns a description and the previous affinity."""
    getaff = getattr(os, "sched_getaffinity", None)
    setaff = getattr(os, "sched_setaffinity", None)
    if getaff is None or setaff is None:
        return "not pinned (no sched_setaffinity on this platform)", None
    before = set(getaff(0))
    cpu = min(before)
    try:
        setaff(0, {cpu})
    except OSError as exc:
        return f"not pinned ({exc})", None
    return f"pinned to CPU {cpu} (of {len(before)} allowed)", before


def unpin(before: set[int] | None) -> None:
    if before is not None:
        os.sched_setaffinity(0, before)


def cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def git_revision() -> str:
    try:
        rev = subprocess.run(
            ["git", "-C", str(ROOT), "describe", "--always", "--dirty"],
            capture_output=True,
            text=True,
            timeout=5,
            check=False,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        rev = ""
    return rev or "unknown"


# --------------------------------------------------------------------------- report


def _num(x: float | None) -> str:
    if x is None:
        return "-"
    if x >= 100:
        return f"{x:,.0f}"
    return f"{x:,.1f}" if x >= 10 else f"{x:,.3f}"


def format_table(rows: Sequence[Row]) -> str:
    """Plain-text table: one line per row, groups separated by a blank line."""
    head = ("group", "case", "n", "ours", "n base", "baseline", "ratio", "target", "verdict")
    lines: list[tuple[str, ...]] = []
    for r in rows:
        ratio = r.ratio
        verdict = {None: "-", True: "PASS", False: "FAIL"}[r.passed]
        lines.append(
            (
                r.group,
                r.case,
                f"{r.count:,}",
                f"{_num(r.rate)} {r.unit}",
                "-" if r.base_count is None else f"{r.base_count:,}",
                "-" if r.base_rate is None else f"{_num(r.base_rate)} {r.unit}",
                "-" if ratio is None else f"{ratio:,.1f}x",
                r.target or "-",
                verdict,
            )
        )
    widths = [max(len(c) for c in col) for col in zip(head, *lines, strict=True)]
    right = {2, 3, 4, 5, 6}

    def fmt(cells: Sequence[str]) -> str:
        return "  ".join(
            c.rjust(w) if i in right else c.ljust(w)
            for i, (c, w) in enumerate(zip(cells, widths, strict=True))
        ).rstrip()

    out = [fmt(head), fmt(["-" * w for w in widths])]
    prev = None
    for r, cells in zip(rows, lines, strict=True):
        if prev is not None and r.group != prev:
            out.append("")
        out.append(fmt(cells))
        prev = r.group
    notes = [f"  [{i}] {r.group} / {r.case}: {r.note}" for i, r in enumerate(rows, 1) if r.note]
    if notes:
        out += ["", "notes:", *notes]
    return "\n".join(out)


def header(cfg: Config, pinning: str) -> str:
    impl = platform.python_implementation()
    mode = "quick (short runs: indicative only)" if cfg.quick else "full"
    return "\n".join(
        [
            f"dji-gateway benchmarks  {time.strftime('%Y-%m-%d %H:%M:%S')}  rev {git_revision()}",
            f"python  {impl} {platform.python_version()} ({sys.executable})",
            f"cpu     {cpu_model()}; {pinning}",
            f"method  {mode}; best of {cfg.repeat} after {cfg.warmup} warm-up, gc disabled while timed",
        ]
    )


def main(argv: Sequence[str] | None = None) -> int:
    names = [n for n, _ in SUITES]
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], prog="bench/run.py")
    ap.add_argument(
        "--quick", action="store_true", help="short runs (smoke test); numbers are indicative only"
    )
    ap.add_argument("--only", choices=names, action="append", help="run only this suite (repeatable)")
    ap.add_argument("--strict", action="store_true", help="exit 2 when a performance target is missed")
    ap.add_argument(
        "--results", type=Path, default=RESULTS, metavar="DIR",
        help=f"where the reports go (default: {RESULTS.relative_to(ROOT)}/; the smoke test gives its own)",
    )  # fmt: skip
    args = ap.parse_args(argv)
    results: Path = args.results
    cfg = Config(quick=args.quick, repeat=2 if args.quick else 5)
    chosen = [(n, s) for n, s in SUITES if not args.only or n in args.only]

    pinning, before = pin_one_cpu()  # for the header's description; each PINNED suite pins again
    unpin(before)
    before = None
    try:
        head = header(cfg, f"{', '.join(sorted(PINNED))} {pinning}; the other suites on every CPU")
        print(head, flush=True)
        results.mkdir(parents=True, exist_ok=True)
        broken: list[str] = []
        missed: list[str] = []
        for name, suite in chosen:
            print(f"\n== {name} ==", flush=True)
            try:
                if name in PINNED:
                    _, before = pin_one_cpu()
                try:
                    rows = suite(cfg)
                finally:
                    if name in PINNED:
                        unpin(before)
                        before = None
            except Exception:  # a broken suite must not hide the others' results
                broken.append(name)
                text = traceback.format_exc()
                print(f"suite {name} FAILED:\n{text}", file=sys.stderr, flush=True)
                (results / f"{name}.txt").write_text(f"{head}\n\n== {name} ==\nFAILED\n{text}")
                continue
            table = format_table(rows)
            fails = [f"{r.group} / {r.case}" for r in rows if r.passed is False]
            missed += [f"{name}: {f}" for f in fails]
            verdict = "all targets met" if not fails else f"{len(fails)} target(s) missed"
            print(table)
            print(f"\n{name}: {verdict}", flush=True)
            (results / f"{name}.txt").write_text(f"{head}\n\n== {name} ==\n{table}\n\n{name}: {verdict}\n")
        print(f"\nreports in {results}/")
        if broken:
            print(f"FAILED suites: {', '.join(broken)}", file=sys.stderr)
            return 1
        if missed:
            print("targets missed:\n  " + "\n  ".join(missed))
            if args.strict:
                return 2
        return 0
    finally:
        unpin(before)


if __name__ == "__main__":
    # Run as a script (``python bench/run.py``): make the repository importable and hand over to the
    # importable module, so suites share one ``bench.run`` (its Row, best_of) with the runner.
    # sys.path[0] is bench/ itself: replace it, or bench/codecs.py would shadow the stdlib codecs.
    sys.path[0] = str(ROOT)
    from bench.run import main as _main

    sys.exit(_main())
