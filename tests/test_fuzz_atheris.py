"""Coverage-guided fuzzing in the test suite: every target of tests/atheris_targets.py runs in its own
process for a fixed number of libFuzzer runs from a fixed seed, starting from its seed corpus.

A crash (an exception escaping a decoder or handler, a violated property, a hang past libFuzzer's
``-timeout``) makes libFuzzer exit non-zero and leave the input in ``crash-…``/``timeout-…``: the
failure message shows it in hex and how to replay it, and replaying that one input is deterministic.
The fixed seed fixes libFuzzer's choices, but not the whole exploration: the hit-count feedback from
Python code is not bit-stable between processes, so two runs may part ways after a few hundred inputs
(``-use_counters=0`` would make them identical, at the cost of most of the corpus). The runs are
counted in the session's fuzz summary as ``atheris:<target>``. Needs the atheris wheel (dev extras,
Linux x86_64 only).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from adapters.wire.stream import BadFrame
from tests import fuzz_stats
from tests.atheris_targets import SEALERS, TARGETS, _can_frames, _chunks, pack_can, pack_stream
from tests.test_fuzz_decoders import FRAMES

try:
    import atheris  # noqa: F401
except ImportError:  # pragma: no cover - depends on the platform
    pytest.skip(
        "atheris is not installed (it has wheels for Linux x86_64 only: pip install -e '.[dev]')",
        allow_module_level=True,
    )

pytestmark = pytest.mark.atheris

ROOT = Path(__file__).resolve().parent.parent
SEED = 20240611
#: runs per target: the whole file stays well under 30 s on one core (1-3 s per target here, ~10 s in all;
#: halved on 2026-11-28 to keep make test within its 5 minutes; longer runs: python -m tests.atheris_targets)
RUNS = {"rsdk": 10_000, "rsdk-can": 10_000, "osdk": 10_000, "robomaster": 10_000, "services": 15_000,
        "drc": 5_000, "kmz": 5_000}  # fmt: skip
DONE = re.compile(r"^Done (\d+) runs in (\d+) second", re.MULTILINE)


def test_every_target_has_a_run_count() -> None:
    assert sorted(RUNS) == sorted(TARGETS)


def test_seed_inputs_feed_what_they_were_packed_from() -> None:
    """The corpus encoders match how the targets read an input (or the seeds would be noise)."""
    stream = bytes(range(100))
    for chunk in (1, 7, 64):
        for seal in (False, True):
            got, sealed = _chunks(pack_stream(stream, chunk, seal=seal))
            assert b"".join(c for c, _ in got) == stream and sealed is seal
            assert {len(c) for c, _ in got[:-1]} <= {chunk} and not any(flush for _, flush in got)
    parts = [b"\xaa" * 8, b"", b"\x01\x02\x03", bytes(9)]
    for seal in (False, True):
        assert _can_frames(pack_can(parts, seal=seal)) == ([(p, False, False) for p in parts], seal)


@pytest.mark.parametrize("family", sorted(SEALERS))
def test_sealing_repairs_every_crc_of_a_broken_stream(family: str) -> None:
    """A stream of valid frames with every CRC byte zeroed decodes intact once sealed."""
    make, frames = FRAMES[family]
    decoder, broken = make(), bytearray()
    for frame in frames:
        f = bytearray(frame)
        crc_at = {"robomaster": [4, -2, -1]}.get(family, [10, 11] + ([-4, -3, -2, -1] if len(f) > 12 else []))
        for i in crc_at:
            f[i] = 0
        broken += f
    assert not [e for e in decoder.feed(bytes(broken)) + decoder.flush() if not isinstance(e, BadFrame)]
    buf = bytearray(broken)
    SEALERS[family](buf)
    assert bytes(buf) == b"".join(frames)


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_atheris_target(name: str, tmp_path: Path) -> None:
    target = TARGETS[name]
    corpus = tmp_path / "corpus"
    corpus.mkdir()
    for i, seed in enumerate(target.seeds()):
        (corpus / f"seed-{i:02d}").write_bytes(seed)
    runs = RUNS[name]
    cmd = [
        sys.executable,
        "-m",
        "tests.atheris_targets",
        name,
        f"-runs={runs}",
        f"-seed={SEED}",
        "-timeout=30",
        "-rss_limit_mb=1024",
        f"-artifact_prefix={tmp_path}/",
        str(corpus),
    ]
    env = {**os.environ, "PYTHONHASHSEED": "0"}
    proc = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=100, check=False)
    # libFuzzer's crash-…/timeout-… inputs (the target's dictionary is written here too, its own per run)
    artifacts = [p for p in sorted(tmp_path.iterdir()) if p.is_file() and p.suffix != ".dict"]
    found = "\n".join(f"{p.name}: {p.read_bytes().hex()}" for p in artifacts)
    assert proc.returncode == 0, (
        f"atheris target {name} failed (exit {proc.returncode}); replay with "
        f"`python -m tests.atheris_targets {name} FILE`\n{found}\n{proc.stderr[-6000:]}"
    )
    done = DONE.search(proc.stderr)
    assert done is not None, proc.stderr[-3000:]
    assert int(done.group(1)) == runs
    assert not artifacts
    fuzz_stats.CASES[f"atheris:{name}"] += runs
