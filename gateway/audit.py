"""The audit log: one INFO line per motion or authority command, so an operator can answer "who flew it".

Owns the shape of an audit line and which commands are audited. A line is logged on the logger
``dji_gateway.audit`` and its message is one JSON object — ``{"event": "service", "method":
"takeoff_to_point", "tid": "…", "source": "mqtt", "result": 0, …}`` — so it reads as JSON in the text log
format too (``grep dji_gateway.audit | cut -d' ' -f5-``); with ``--log-json`` the same object is the
line's ``audit`` key. Callers: the dispatcher (every service but the read-only ones, authority grabs
included), live control (DRC sessions entered and left, emergency stops), and any other front end that
acts (a web console passes its own ``source``). Knows nothing of MQTT or devices; never logs a secret
(callers pass names and results, never request values; the log's own masking is the second line of
defence).
"""

from __future__ import annotations

import json
import logging
from typing import Any

__all__ = ["LOGGER_NAME", "audit", "audited"]

LOGGER_NAME = "dji_gateway.audit"
_log = logging.getLogger(LOGGER_NAME)

#: Services that only read (answered, never audited): they move nothing and grant nothing.
_READ_ONLY_SUFFIXES = ("_get", "_download")


def audited(method: str) -> bool:
    """True for a service that moves something or changes who controls it (everything but reads)."""
    return not method.endswith(_READ_ONLY_SUFFIXES)


def audit(event: str, **fields: Any) -> None:
    """Log one audit line: ``event`` (``service``, ``drc_enter``, ``drc_exit``, ``emergency_stop`` …)
    and ``fields`` (``method``, ``tid``, ``source``, ``result``, ``device`` …; None values left out),
    as one JSON object at INFO on ``dji_gateway.audit``."""
    record = {"event": event, **{k: v for k, v in fields.items() if v is not None}}
    _log.info(json.dumps(record, separators=(",", ":"), default=str), extra={"audit": record})
