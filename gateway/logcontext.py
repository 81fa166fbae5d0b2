"""Log lines that say which request they belong to, and never carry a secret.

Owns the per-request context (``method``, ``tid``, ``device``) kept in a :class:`contextvars.ContextVar`:
the dispatcher sets it inside each request's own task, so every line logged while that request runs,
the adapter's included, carries it without passing it around. Owns the two formats (human text by
default, one JSON object per line with ``--log-json``) and a last line of defence against secrets:
values registered with :func:`register_secret` (the broker password, device secrets, every
``SecretStr`` that arrives in a request such as ``drc_mode_enter``'s ``mqtt_broker.password``) are
replaced by ``***`` in the final line, whoever wrote it. Knows nothing of MQTT or devices.
"""

from __future__ import annotations

import contextlib
import json
import logging
import threading
from collections import OrderedDict
from collections.abc import Iterator
from contextvars import ContextVar
from typing import Any

from pydantic import BaseModel, SecretStr

__all__ = [
    "ContextFilter",
    "JsonFormatter",
    "TextFormatter",
    "current",
    "install",
    "register_secret",
    "register_secrets_in",
    "request_context",
    "scrub",
]

#: Keys of the request context, in the order text lines show them.
CONTEXT_KEYS = ("method", "tid", "device")
MASK = "***"
_MIN_SECRET = 4  # shorter values would mask ordinary words; nobody's password is that short
#: Secrets that arrive in requests (a DRC password per session) are kept for the last this many: a gateway
#: that runs for months must not slow every log line down with thousands of expired tokens.
RECENT_SECRETS = 256

_context: ContextVar[dict[str, str] | None] = ContextVar("djigw_request_context", default=None)
_secrets: set[str] = set()  # from the settings: for the life of the process
_recent: OrderedDict[str, None] = OrderedDict()  # from requests: bounded, oldest forgotten first
_secrets_lock = threading.Lock()
_ordered: tuple[str, ...] = ()  # both, longest first (one secret may contain another); rebuilt on change


def current() -> dict[str, str]:
    """The context of the request being handled in this task (empty outside requests)."""
    return dict(_context.get() or {})


def set_context(**values: object) -> None:
    """Add to the current task's context (the dispatcher calls it once per request task; a task
    copies its parent's context when created, so this never leaks into another request)."""
    merged = {**(_context.get() or {}), **{k: str(v) for k, v in values.items() if v is not None}}
    _context.set(merged)


@contextlib.contextmanager
def request_context(**values: object) -> Iterator[None]:
    """The context for a block of code (synchronous callers and tests)."""
    token = _context.set(
        {**(_context.get() or {}), **{k: str(v) for k, v in values.items() if v is not None}}
    )
    try:
        yield
    finally:
        _context.reset(token)


def register_secret(value: str | SecretStr | None, *, permanent: bool = True) -> None:
    """Never print ``value`` again in a log line of this process (``permanent=False``: while it is
    among the :data:`RECENT_SECRETS` latest request secrets)."""
    global _ordered
    if isinstance(value, SecretStr):
        value = value.get_secret_value()
    if not value or len(value) < _MIN_SECRET:
        return
    with _secrets_lock:
        if permanent:
            _secrets.add(value)
        else:
            _recent[value] = None
            _recent.move_to_end(value)
            while len(_recent) > RECENT_SECRETS:
                _recent.popitem(last=False)
        _ordered = tuple(sorted(_secrets.union(_recent), key=len, reverse=True))


def register_secrets_in(model: Any, *, permanent: bool = True) -> None:
    """Register every ``SecretStr`` inside a pydantic model (recursively: settings; requests with
    ``permanent=False``)."""
    if isinstance(model, SecretStr):
        register_secret(model, permanent=permanent)
    elif isinstance(model, BaseModel):
        for name in type(model).model_fields:
            register_secrets_in(getattr(model, name, None), permanent=permanent)
    elif isinstance(model, list | tuple):
        for item in model:
            register_secrets_in(item, permanent=permanent)
    elif isinstance(model, dict):
        for item in model.values():
            register_secrets_in(item, permanent=permanent)


def scrub(text: str) -> str:
    """``text`` with every registered secret replaced by ``***``."""
    for secret in _ordered:
        if secret in text:
            text = text.replace(secret, MASK)
    return text


class ContextFilter(logging.Filter):
    """Copies the request context onto every record (``record.method`` …, absent keys are "")."""

    def filter(self, record: logging.LogRecord) -> bool:
        ctx = _context.get() or {}
        for key in CONTEXT_KEYS:
            if not hasattr(record, key):
                setattr(record, key, ctx.get(key, ""))
        return True


class TextFormatter(logging.Formatter):
    """``time LEVEL logger: message [method=… tid=… device=…]``, secrets masked."""

    def __init__(self) -> None:
        super().__init__("%(asctime)s %(levelname)-7s %(name)s: %(message)s")

    def format(self, record: logging.LogRecord) -> str:
        line = super().format(record)
        ctx = " ".join(f"{k}={getattr(record, k)}" for k in CONTEXT_KEYS if getattr(record, k, ""))
        if ctx:
            first, sep, rest = line.partition("\n")  # a traceback follows the first line
            line = f"{first} [{ctx}]{sep}{rest}"
        return scrub(line)


class JsonFormatter(logging.Formatter):
    """One JSON object per line: ts, level, logger, msg, the request context keys present, exc."""

    def format(self, record: logging.LogRecord) -> str:
        out: dict[str, Any] = {
            "ts": round(record.created, 3),
            "level": record.levelname,
            "logger": record.name,
            "msg": record.getMessage(),
        }
        for key in CONTEXT_KEYS:
            value = getattr(record, key, "")
            if value:
                out[key] = value
        audit = getattr(record, "audit", None)
        if isinstance(audit, dict):  # gateway.audit: the line's fields as an object
            out["audit"] = {k: scrub(v) if isinstance(v, str) else v for k, v in audit.items()}
        if record.exc_info:
            out["exc"] = self.formatException(record.exc_info)
        # masked before encoding: JSON escapes would hide a secret holding a quote or a backslash
        return json.dumps({k: scrub(v) if isinstance(v, str) else v for k, v in out.items()})


def install(handler: logging.Handler, as_json: bool) -> logging.Handler:
    """Give ``handler`` the chosen format and the request context."""
    handler.setFormatter(JsonFormatter() if as_json else TextFormatter())
    handler.addFilter(ContextFilter())
    return handler
