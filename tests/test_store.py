"""The crash-safe store (gateway/store.py): what a restarted gateway reads back, and a writer killed with
SIGKILL in the middle of its writes leaves a database that opens and holds a whole row."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from gateway.store import DB_NAME, StateStore


def test_a_task_survives_a_new_store_on_the_same_directory(tmp_path: Path) -> None:
    store = StateStore(tmp_path)
    request = {"flight_id": "f-1", "task_type": 0, "file": {"url": "http://x", "fingerprint": "ab"}}
    store.task_started("f-1", "AC-1", request, 1000)
    store.task_progress(
        "f-1", status="in_progress", total_points=5, done_points=2, wayline_id=0, waypoint_index=2, live=True,
        now_ms=2000,
    )  # fmt: skip
    store.close()
    again = StateStore(tmp_path)  # a new process
    row = again.live_task("AC-1")
    assert row is not None
    assert (row.flight_id, row.status, row.done_points, row.total_points, row.waypoint_index) == (
        "f-1", "in_progress", 2, 5, 2,
    )  # fmt: skip
    assert row.request == request
    assert again.live_task("AC-2") is None
    again.task_progress(
        "f-1", status="ok", total_points=5, done_points=5, wayline_id=0, waypoint_index=5, live=False,
        now_ms=3000,
    )  # fmt: skip
    assert again.live_task("AC-1") is None  # ended: nothing to adopt
    assert again.forget_before(4000) == 1
    assert (tmp_path / DB_NAME).exists()
    again.close()


def test_the_newest_live_task_wins_and_a_memory_store_writes_nothing(tmp_path: Path) -> None:
    store = StateStore(None)
    store.task_started("old", "AC-1", {}, 1000)
    store.task_started("new", "AC-1", {}, 2000)
    row = store.live_task("AC-1")
    assert row is not None and row.flight_id == "new"
    assert store.path is None and not list(tmp_path.iterdir())
    store.close()


_WRITER = """
import sys
from pathlib import Path
from gateway.store import StateStore
store = StateStore(Path(sys.argv[1]))
store.task_started("f", "AC", {"n": 0}, 1)
print("ready", flush=True)
n = 0
while True:
    n += 1
    store.task_progress("f", status="in_progress", total_points=n, done_points=n, wayline_id=0,
                        waypoint_index=n, live=True, now_ms=n)
"""


def test_a_writer_killed_mid_write_leaves_a_whole_row(tmp_path: Path) -> None:
    proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout is not None and proc.stdout.readline().strip() == "ready"
        time.sleep(0.3)  # hundreds of committed writes, one in progress
        proc.send_signal(signal.SIGKILL)
        proc.wait(5)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(5)
        if proc.stdout is not None:
            proc.stdout.close()
    store = StateStore(tmp_path)
    row = store.live_task("AC")
    store.close()
    assert row is not None
    assert row.total_points == row.done_points == row.waypoint_index == row.updated_ms > 0


def test_the_device_task_journal_keeps_one_task_per_device(tmp_path: Path) -> None:
    store = StateStore(tmp_path, now_ms=lambda: 5)
    assert store.recall("AC-1") is None
    store.remember("AC-1", "fly_to", "f-1", {"path": [[22.5, 113.9, 20.0]], "speed": 8.0})
    store.remember("AC-1", "fly_to", "f-2", {"speed": 5.0})  # a new task replaces the old
    store.forget("AC-1", "f-1")  # the old one's late end leaves the new one alone
    store.close()
    again = StateStore(tmp_path)
    assert again.recall("AC-1") == ("fly_to", "f-2", {"speed": 5.0})
    again.forget("AC-1", "f-2")
    assert again.recall("AC-1") is None
    again.close()


# ------------------------------------------------------------------------------------------ the reply journal
def test_a_reply_outlives_the_store_and_ages_out(tmp_path: Path) -> None:
    now = [1_000_000]
    store = StateStore(tmp_path, now_ms=lambda: now[0])
    store.reply_recorded("tid-1", b'{"tid":"tid-1","data":{"result":0}}')
    store.close()
    again = StateStore(tmp_path, now_ms=lambda: now[0])
    assert again.recorded_reply("tid-1", 120_000) == b'{"tid":"tid-1","data":{"result":0}}'
    assert again.recorded_reply("tid-2", 120_000) is None
    now[0] += 120_001
    assert again.recorded_reply("tid-1", 120_000) is None  # older than the cache's age: a new request
    again.close()


_READ_WRITER = """
import os, signal, sys
from pathlib import Path
from gateway.store import StateStore
store = StateStore(Path(sys.argv[1]))
store.reply_recorded("read-1", b"a read's reply", durable=False)
store.reply_recorded("action-1", b"an action's reply")
os.kill(os.getpid(), signal.SIGKILL)  # no close, no checkpoint: the process dies right here
"""


def test_a_reads_reply_kept_without_waiting_for_the_disk_outlives_a_killed_process(tmp_path: Path) -> None:
    """``durable=False`` skips the fsync, never the write: a gateway killed after answering a read still
    answers its resend from the journal (only a power cut may lose it; then it is read again)."""
    done = subprocess.run([sys.executable, "-c", _READ_WRITER, str(tmp_path)], timeout=30)
    assert done.returncode == -signal.SIGKILL
    store = StateStore(tmp_path)
    assert store.recorded_reply("read-1", 60_000) == b"a read's reply"
    assert store.recorded_reply("action-1", 60_000) == b"an action's reply"
    # the connection waits for the disk again after a read's reply: the next write with a visible effect
    # (a started mark, a task) is as durable as ever
    store.reply_recorded("read-2", b"x", durable=False)
    assert store._db.execute("PRAGMA synchronous").fetchone() == (2,)  # FULL
    store.close()


def test_the_reply_journal_is_bounded_by_count_and_age(tmp_path: Path) -> None:
    now = [0]
    store = StateStore(tmp_path, now_ms=lambda: now[0])
    for i in range(50):
        now[0] = i
        store.reply_recorded(f"t{i}", b"r")
    assert store.replies_pruned(20) == 30
    assert store.recorded_reply("t29", 10**9) is None and store.recorded_reply("t30", 10**9) == b"r"
    now[0] = 100
    assert store.replies_pruned(20, max_age_ms=60) == 10  # t30..t39 are older than 60 ms
    assert store.recorded_reply("t40", 10**9) == b"r"
    store.close()


@pytest.mark.parametrize("damage", ["garbage", "truncated"])
def test_a_damaged_store_is_set_aside_with_a_log_line_never_a_crash(
    tmp_path: Path, damage: str, caplog: pytest.LogCaptureFixture
) -> None:
    store = StateStore(tmp_path, now_ms=lambda: 5)
    store.reply_recorded("tid-1", b"reply")
    store.close()
    path = tmp_path / DB_NAME
    raw = path.read_bytes()
    path.write_bytes(b"this is not a database" * 200 if damage == "garbage" else raw[:100] + b"\xff" * 3000)
    with caplog.at_level("ERROR", logger="gateway.store"):
        fresh = StateStore(tmp_path, now_ms=lambda: 7)
    assert fresh.set_aside is not None and fresh.set_aside.exists()
    assert fresh.set_aside.name == f"{DB_NAME}.damaged-7"
    assert any("damaged" in r.getMessage() and "set aside" in r.getMessage() for r in caplog.records)
    assert fresh.recorded_reply("tid-1", 10**9) is None  # an empty store, working
    fresh.reply_recorded("tid-2", b"r2")
    assert fresh.recorded_reply("tid-2", 10**9) == b"r2"
    fresh.close()
