"""Another gateway with this gateway's serial number on the same broker (issue #35): reported, never merged.

Owns :class:`TwinWatch`: the ``tid`` of every osd this gateway published under its own serial number
(:meth:`TwinWatch.sent`, called before the message is handed to the broker), and what came back on that
topic (:meth:`TwinWatch.heard`): the gateway subscribes to its own osd topic, and an osd whose ``tid`` it
never sent was published by someone else under its serial number — another gateway configured with the
same ``gateway_sn`` on the same broker. A cloud would take the two for one gateway (topologies and osd
alternating, replies from either): the watch counts them, and ``/status``, ``dji-gateway status`` and
the web console say so. Sans-I/O: bytes and times in, a snapshot out; the app wires it to the broker.

Must not know MQTT, the broker link or HTTP.
"""

from __future__ import annotations

import json
from collections import deque
from typing import Any

__all__ = ["TwinWatch"]


def _tid(payload: bytes) -> str | None:
    try:
        body = json.loads(payload)
    except ValueError:
        return None
    tid = body.get("tid") if isinstance(body, dict) else None
    return tid if isinstance(tid, str) else None


class TwinWatch:
    """This gateway's own osd, told apart from another publisher's under the same serial number."""

    def __init__(self, *, keep: int = 256, recent: float = 10.0) -> None:
        self._ours: deque[str] = deque(maxlen=keep)  # the tids sent lately (osd every period: a few)
        self._known: set[str] = set()
        self._recent = recent  # another's osd this recent: it is there now
        self.count = 0  # osd messages seen from another publisher under our serial number
        self.first: float | None = None
        self.last: float | None = None

    def sent(self, payload: bytes) -> None:
        """One osd this gateway is about to publish under its own serial number."""
        tid = _tid(payload)
        if tid is None:
            return
        if len(self._ours) == self._ours.maxlen:
            self._known.discard(self._ours[0])
        self._ours.append(tid)
        self._known.add(tid)

    def heard(self, payload: bytes, now: float) -> bool:
        """One osd heard on our own osd topic: True when it is not one of ours (another gateway's)."""
        tid = _tid(payload)
        if tid is None or tid in self._known:
            return False
        self.count += 1
        if self.first is None:
            self.first = now
        self.last = now
        return True

    def snapshot(self, now: float) -> dict[str, Any]:
        """``{"active", "count", "last_age_s"}``: active while another's osd came within ``recent`` s."""
        age = None if self.last is None else round(now - self.last, 1)
        return {"active": age is not None and age <= self._recent, "count": self.count, "last_age_s": age}
