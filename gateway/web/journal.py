"""The console's log of events, requests and replies: what the gateway said and was asked, bounded.

Owns the :class:`Journal`, fed on the gateway's loop by the app's message observers (every message the
northbound and the dispatcher publish, every message the dispatcher is handed: one bounded ``deque``
append there, parsed later by :meth:`Journal.digest` in the web server's thread) and by the console's
own actions; telemetry (``osd``, ``state``) and live-control traffic (``drc/*``, answered on the network
threads) are left out: they are the instruments' and the DRC panel's business, and they are frequent.
An entry keeps the method, tid, result and the body cut to :data:`MAX_BODY` characters with every value
under a key that names a secret (``password``, ``secret``, ``token``) replaced by ``***``. Readers on
other threads take :meth:`since` copies.

Also remembers what the map draws from the contract alone: the last accepted ``fly_to_point`` /
``takeoff_to_point`` target per tid and the progress events that name them (until a wayline task offers
a snapshot of its own). Must not know HTTP, paho or adapters.
"""

from __future__ import annotations

import itertools
import json
import threading
from collections import deque
from typing import Any

from gateway.clock import SYSTEM_CLOCK, Clock

__all__ = ["MAX_BODY", "Journal", "redact"]

#: the longest body text an entry keeps
MAX_BODY = 2000
_SECRET_KEYS = ("password", "secret", "token")
#: topic suffixes (kinds) the journal keeps: services, events, replies, requests and the topology
_KEPT = (
    "services",
    "services_reply",
    "events",
    "events_reply",
    "requests",
    "requests_reply",
    "status",
    "status_reply",
    "property/set",
    "property/set_reply",
)
_TRACKED = ("fly_to_point", "takeoff_to_point")
_TELEMETRY = ("/osd", "/state")


def redact(value: Any) -> Any:
    """``value`` with every value under a secret-naming key replaced by ``***`` (recursively)."""
    if isinstance(value, dict):
        return {
            k: "***" if any(s in str(k).lower() for s in _SECRET_KEYS) else redact(v)
            for k, v in value.items()
        }
    if isinstance(value, list):
        return [redact(v) for v in value]
    return value


def _kind(topic_name: str) -> str | None:
    parts = topic_name.split("/", 3)
    if len(parts) < 4:
        return None
    kind = parts[3]
    return kind if kind in _KEPT else None


class Journal:
    def __init__(self, keep: int = 300, clock: Clock = SYSTEM_CLOCK) -> None:
        self._clock = clock
        self.entries: deque[dict[str, Any]] = deque(maxlen=keep)
        self._raw: deque[tuple[str, str, bytes]] = deque(maxlen=4 * keep)  # fed, not yet parsed
        self._numbers = itertools.count(1)
        self._lock = threading.RLock()
        self._requests: dict[str, tuple[str, dict[str, Any]]] = {}  # tid -> tracked request, until its reply
        #: the last accepted fly-to / take-off target (method, data) and its progress events
        self.mission: dict[str, Any] | None = None

    # -- feeding (the gateway's loop: an append, nothing parsed there) ---------------------------------
    def published(self, topic_name: str, payload: bytes) -> None:
        if not topic_name.endswith(_TELEMETRY):
            self._raw.append(("up", topic_name, payload))

    def received(self, topic_name: str, payload: bytes) -> None:
        if not topic_name.endswith(_TELEMETRY):
            self._raw.append(("down", topic_name, payload))

    def digest(self) -> None:
        """Parse what was fed since the last call (the web server's thread, once per tick)."""
        raw = self._raw
        while raw:
            try:
                direction, topic_name, payload = raw.popleft()
            except IndexError:
                break
            self._message(direction, topic_name, payload)

    def note(self, kind: str, method: str, **fields: Any) -> None:
        """An entry that is not an MQTT message (a console action and its outcome)."""
        self._add({"dir": "console", "kind": kind, "method": method, **redact(fields)})

    def _message(self, direction: str, topic_name: str, payload: bytes) -> None:
        kind = _kind(topic_name)
        if kind is None:
            return
        try:
            body = json.loads(payload)
        except (ValueError, UnicodeDecodeError):
            self._add({"dir": direction, "kind": kind, "topic": topic_name, "error": "not JSON"})
            return
        if not isinstance(body, dict):
            return
        data = body.get("data")
        method = str(body.get("method", ""))
        result = data.get("result") if isinstance(data, dict) else None
        text = json.dumps(redact(data), separators=(",", ":"), default=str)
        entry = {
            "dir": direction,
            "kind": kind,
            "topic": topic_name,
            "method": method,
            "tid": body.get("tid"),
            "result": result,
            "body": text if len(text) <= MAX_BODY else text[:MAX_BODY] + "…",
        }
        self._add(entry)
        self._track(kind, method, body.get("tid"), data, result)

    def _track(self, kind: str, method: str, tid: Any, data: Any, result: Any) -> None:
        if method in _TRACKED and isinstance(tid, str) and isinstance(data, dict):
            if kind == "services":
                self._requests[tid] = (method, redact(data))
                while len(self._requests) > 32:
                    self._requests.pop(next(iter(self._requests)))
            elif kind == "services_reply" and tid in self._requests:
                asked, body = self._requests.pop(tid)
                if result == 0:
                    self.mission = {
                        "method": asked,
                        "data": body,
                        "progress": None,
                        "since": self._now(),
                    }
        elif (
            method.endswith("_point_progress")
            and kind == "events"
            and isinstance(data, dict)
            and self.mission is not None
        ):
            self.mission = {**self.mission, "progress": redact(data)}

    def track_local(self, method: str, data: dict[str, Any], result: int) -> None:
        """A fly-to / take-off the console itself asked for (its reply never crosses the broker)."""
        if method in _TRACKED and result == 0:
            self.mission = {
                "method": method,
                "data": redact(data),
                "progress": None,
                "since": self._now(),
            }

    def _now(self) -> float:
        return self._clock.time_ms() / 1000  # wall clock, seconds

    def _add(self, entry: dict[str, Any]) -> None:
        with self._lock:
            entry["n"] = next(self._numbers)
            entry["t"] = round(self._now(), 3)
            self.entries.append(entry)

    # -- reading (any thread) ---------------------------------------------------------------------------
    def since(self, n: int) -> list[dict[str, Any]]:
        """Entries numbered above ``n``, oldest first (what was fed is parsed first)."""
        self.digest()
        with self._lock:
            return [e for e in self.entries if e["n"] > n]
