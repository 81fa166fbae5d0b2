"""The gateway's one crash-safe store: what must outlive the process (the wayline tasks in flight, so a
restarted gateway reports the mission the aircraft still flies under the same ``flight_id``).

Besides the wayline tasks it is the devices' :class:`adapters.base.TaskJournal` (the fly-to or take-off
to point a device started, so it continues under the same id after a restart) and the dispatcher's
reply journal (``tid`` → the reply, bounded by count and age): a request resent with the same ``tid``
after a restart is answered from here and not acted on again. The reply is written before it is
published, so a process killed between acting and replying still knows it acted. A request with a
visible effect is also marked *started* (``tid`` → method) before it is acted on, and the mark goes in
the same transaction that keeps its reply: a process killed after acting and before keeping the reply
leaves the mark, and the next process answers a resend "outcome unknown, not repeated" instead of acting
twice.

A damaged database file (not a database, a corrupt page) is set aside, renamed
``<name>.damaged-<unix ms>`` with its WAL, with an ERROR log line, and a fresh store is made: never a
crash at start.

Owns one SQLite database (the standard library's ``sqlite3``) in the configured state directory
(``state_dir``; without one, ``dji-gateway run`` and ``run --simulate`` alike keep the store in memory,
with a log line). Every write is one transaction in WAL mode with
``synchronous=FULL`` (the reply to a read: ``NORMAL``, :meth:`StateStore.reply_recorded`): a process
killed at any instant leaves either the state before a write or the state after it. Nothing else of the
gateway writes to disk.

Must not know MQTT, devices or the wayline task book: rows in, rows out, as plain values. Called on the
event loop only (one connection, never shared across threads); each write is a few hundred
microseconds on a local disk, once per task start, waypoint and end.
"""

from __future__ import annotations

import json
import logging
import sqlite3
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

__all__ = ["DB_NAME", "REPLIES_KEPT", "StateStore", "StoredTask"]

#: At most this many replies are kept (the oldest go first), as in the dispatcher's memory cache.
REPLIES_KEPT = 10_000

DB_NAME = "dji-gateway.sqlite3"
SCHEMA_VERSION = 1

_SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE IF NOT EXISTS tasks (
    flight_id TEXT PRIMARY KEY,
    aircraft_sn TEXT NOT NULL,
    request TEXT NOT NULL,          -- the flighttask_prepare data, as JSON
    status TEXT NOT NULL,           -- the last flighttask_progress status
    total_points INTEGER NOT NULL DEFAULT 0,
    done_points INTEGER NOT NULL DEFAULT 0,
    wayline_id INTEGER NOT NULL DEFAULT 65535,
    waypoint_index INTEGER NOT NULL DEFAULT 0,
    live INTEGER NOT NULL DEFAULT 1, -- 1 while the task runs or is paused
    updated_ms INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS device_tasks (
    sn TEXT PRIMARY KEY,            -- one live device task per device
    kind TEXT NOT NULL,             -- fly_to, takeoff
    task_id TEXT NOT NULL,
    data TEXT NOT NULL,             -- what continuing it needs, as JSON
    updated_ms INTEGER NOT NULL
);
CREATE TABLE IF NOT EXISTS replies (
    tid TEXT PRIMARY KEY,           -- the request's tid
    payload BLOB NOT NULL,          -- the services_reply exactly as published
    stored_ms INTEGER NOT NULL
);
CREATE INDEX IF NOT EXISTS replies_by_age ON replies (stored_ms);
CREATE TABLE IF NOT EXISTS started (
    tid TEXT PRIMARY KEY,           -- a request being acted on: written before acting, gone with its reply
    method TEXT NOT NULL,
    stored_ms INTEGER NOT NULL
);
"""


@dataclass(frozen=True, slots=True)
class StoredTask:
    """A wayline task as the store kept it."""

    flight_id: str
    aircraft_sn: str
    request: dict[str, Any]
    status: str
    total_points: int
    done_points: int
    wayline_id: int
    waypoint_index: int
    live: bool
    updated_ms: int


class StateStore:
    """The gateway's state on disk (or in memory when ``directory`` is None)."""

    def __init__(self, directory: Path | None, *, now_ms: Callable[[], int] | None = None) -> None:
        self.path: Path | None = None
        self._now_ms = now_ms or (lambda: int(time.time() * 1000))
        self.set_aside: Path | None = None  # where a damaged file went, if one was found at start
        self._replies_written = 0
        if directory is None:
            self._db = self._open(":memory:")
            return
        directory.mkdir(parents=True, exist_ok=True)
        self.path = directory / DB_NAME
        try:
            self._db = self._open(str(self.path))
        except sqlite3.DatabaseError as exc:  # not a database, or a corrupt page: keep it for a post-mortem
            self.set_aside = self.path.with_name(f"{DB_NAME}.damaged-{self._now_ms()}")
            for suffix in ("", "-wal", "-shm"):
                part = Path(f"{self.path}{suffix}")
                if part.exists():
                    part.rename(Path(f"{self.set_aside}{suffix}"))
            log.error("state store %s is damaged (%s): set aside as %s; starting with an empty store",
                      self.path, exc, self.set_aside)  # fmt: skip
            self._db = self._open(str(self.path))

    def _open(self, target: str) -> sqlite3.Connection:
        db = sqlite3.connect(target, isolation_level=None, check_same_thread=False)
        try:
            db.execute("PRAGMA journal_mode=WAL")
            db.execute("PRAGMA synchronous=FULL")
            (check,) = db.execute("PRAGMA quick_check").fetchone()
            if check != "ok":
                raise sqlite3.DatabaseError(f"quick_check: {check}")
            db.executescript(_SCHEMA)  # idempotent; executescript commits on its own
            db.execute("BEGIN IMMEDIATE")
            db.execute(
                "INSERT OR IGNORE INTO meta (key, value) VALUES ('schema_version', ?)", (str(SCHEMA_VERSION),)
            )
            db.execute("COMMIT")
        except sqlite3.DatabaseError:
            db.close()
            raise
        return db

    def _tx(self) -> _Transaction:
        return _Transaction(self._db)

    # -- wayline tasks -----------------------------------------------------------------------------
    def task_started(self, flight_id: str, aircraft_sn: str, request: dict[str, Any], now_ms: int) -> None:
        with self._tx():
            self._db.execute(
                "INSERT INTO tasks (flight_id, aircraft_sn, request, status, live, updated_ms) "
                "VALUES (?, ?, ?, 'sent', 1, ?) ON CONFLICT(flight_id) DO UPDATE SET "
                "aircraft_sn=excluded.aircraft_sn, request=excluded.request, status='sent', live=1, "
                "updated_ms=excluded.updated_ms",
                (flight_id, aircraft_sn, json.dumps(request), now_ms),
            )

    def task_progress(
        self,
        flight_id: str,
        *,
        status: str,
        total_points: int,
        done_points: int,
        wayline_id: int,
        waypoint_index: int,
        live: bool,
        now_ms: int,
    ) -> None:
        with self._tx():
            self._db.execute(
                "UPDATE tasks SET status=?, total_points=?, done_points=?, wayline_id=?, waypoint_index=?, "
                "live=?, updated_ms=? WHERE flight_id=?",
                (status, total_points, done_points, wayline_id, waypoint_index, int(live), now_ms, flight_id),
            )

    def live_task(self, aircraft_sn: str) -> StoredTask | None:
        """The task that was running or paused on ``aircraft_sn`` when the store last heard of it."""
        row = self._db.execute(
            "SELECT flight_id, aircraft_sn, request, status, total_points, done_points, wayline_id, "
            "waypoint_index, live, updated_ms FROM tasks WHERE aircraft_sn=? AND live=1 "
            "ORDER BY updated_ms DESC LIMIT 1",
            (aircraft_sn,),
        ).fetchone()
        if row is None:
            return None
        return StoredTask(
            row[0], row[1], json.loads(row[2]), row[3], row[4], row[5], row[6], row[7], bool(row[8]), row[9]
        )

    # -- device tasks (adapters.base.TaskJournal) ----------------------------------------------------
    def remember(self, sn: str, kind: str, task_id: str, data: Mapping[str, Any]) -> None:
        with self._tx():
            self._db.execute(
                "INSERT INTO device_tasks (sn, kind, task_id, data, updated_ms) VALUES (?, ?, ?, ?, ?) "
                "ON CONFLICT(sn) DO UPDATE SET kind=excluded.kind, task_id=excluded.task_id, "
                "data=excluded.data, updated_ms=excluded.updated_ms",
                (sn, kind, task_id, json.dumps(dict(data)), self._now_ms()),
            )

    def forget(self, sn: str, task_id: str) -> None:
        with self._tx():
            self._db.execute("DELETE FROM device_tasks WHERE sn=? AND task_id=?", (sn, task_id))

    def recall(self, sn: str) -> tuple[str, str, dict[str, Any]] | None:
        row = self._db.execute("SELECT kind, task_id, data FROM device_tasks WHERE sn=?", (sn,)).fetchone()
        return None if row is None else (row[0], row[1], json.loads(row[2]))

    def forget_before(self, cutoff_ms: int) -> int:
        """Drop ended tasks last changed before ``cutoff_ms`` (the store stays small)."""
        with self._tx():
            cur = self._db.execute("DELETE FROM tasks WHERE live=0 AND updated_ms < ?", (cutoff_ms,))
        return cur.rowcount

    # -- replies (the dispatcher's reply journal) -----------------------------------------------------
    def request_started(self, tid: str, method: str) -> None:
        """``tid`` is about to be acted on (one INSERT, its own transaction): until its reply is kept, a
        resend after a restart is not acted on again (:meth:`started_request`)."""
        self._db.execute(
            "INSERT OR REPLACE INTO started (tid, method, stored_ms) VALUES (?, ?, ?)",
            (tid, method, self._now_ms()),
        )

    def started_request(self, tid: str, max_age_ms: int) -> str | None:
        """The method of ``tid`` if it was started at most ``max_age_ms`` ago and has no reply kept."""
        row = self._db.execute(
            "SELECT method FROM started WHERE tid=? AND stored_ms >= ?", (tid, self._now_ms() - max_age_ms)
        ).fetchone()
        return None if row is None else str(row[0])

    def reply_recorded(self, tid: str, payload: bytes, *, durable: bool = True) -> None:
        """Keep the reply to ``tid`` and clear its started mark (one transaction); now and then the
        oldest beyond :data:`REPLIES_KEPT` go.

        ``durable=False``, for the reply to a request that changed nothing (a read): committed without
        waiting for the disk (``synchronous=NORMAL`` for this transaction; WAL mode keeps the file
        whole either way). It outlives the process (a killed gateway loses nothing: the kernel holds
        the write), not a power cut, after which a resend is read again, which changes nothing. It
        saves the fsync, some 300 µs a request on this project's VMs (``make bench``, e2e, "state
        store" rows); a reply to a request with a visible effect always waits for the disk."""
        if not durable:
            self._db.execute("PRAGMA synchronous=NORMAL")
        try:
            with self._tx():
                self._db.execute(
                    "INSERT OR REPLACE INTO replies (tid, payload, stored_ms) VALUES (?, ?, ?)",
                    (tid, payload, self._now_ms()),
                )
                self._db.execute("DELETE FROM started WHERE tid=?", (tid,))
        finally:
            if not durable:
                self._db.execute("PRAGMA synchronous=FULL")
        self._replies_written += 1
        if self._replies_written % 1000 == 0:
            self.replies_pruned(REPLIES_KEPT)

    def recorded_reply(self, tid: str, max_age_ms: int) -> bytes | None:
        """The reply kept for ``tid`` if it is at most ``max_age_ms`` old."""
        row = self._db.execute(
            "SELECT payload FROM replies WHERE tid=? AND stored_ms >= ?", (tid, self._now_ms() - max_age_ms)
        ).fetchone()
        return None if row is None else bytes(row[0])

    def replies_pruned(self, keep: int, max_age_ms: int | None = None) -> int:
        """Drop replies beyond the newest ``keep`` (and older than ``max_age_ms``); how many went."""
        with self._tx():
            cur = self._db.execute(
                "DELETE FROM replies WHERE tid NOT IN "
                "(SELECT tid FROM replies ORDER BY stored_ms DESC LIMIT ?)",
                (keep,),
            )
            gone = cur.rowcount
            self._db.execute(
                "DELETE FROM started WHERE tid NOT IN "
                "(SELECT tid FROM started ORDER BY stored_ms DESC LIMIT ?)",
                (keep,),
            )
            if max_age_ms is not None:
                cur = self._db.execute(
                    "DELETE FROM replies WHERE stored_ms < ?", (self._now_ms() - max_age_ms,)
                )
                gone += cur.rowcount
                self._db.execute("DELETE FROM started WHERE stored_ms < ?", (self._now_ms() - max_age_ms,))
        return gone

    def close(self) -> None:
        self._db.close()


class _Transaction:
    """``BEGIN IMMEDIATE`` … ``COMMIT`` (``ROLLBACK`` on an exception): one write, whole or not at all."""

    def __init__(self, db: sqlite3.Connection) -> None:
        self._db = db

    def __enter__(self) -> None:
        self._db.execute("BEGIN IMMEDIATE")

    def __exit__(self, kind: object, exc: object, tb: object) -> None:
        self._db.execute("COMMIT" if kind is None else "ROLLBACK")
