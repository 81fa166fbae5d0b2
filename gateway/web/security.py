"""Who may use the console, and how a request proves it.

Owns the rules (docs/console.md, "Security"):

* **actions** (services, the emergency stop) always need ``console.token``: as ``Authorization: Bearer``
  (scripts) or through a sign-in session (the page: an ``HttpOnly``, ``SameSite=Strict`` cookie plus a
  per-session CSRF token in the ``X-CSRF-Token`` header). A session-authenticated action must also come
  from the console's own origin (``Origin``, else ``Referer``, naming the ``Host`` it was sent to); a
  bearer request that names an origin must name this one. No token configured: no action at all.
* **read-only** mode refuses every action except the emergency stop (it only stops).
* **viewing** (the state push, the catalogue, frame downloads) is open on a loopback bind and needs the
  token (either way) on any other address — where the gateway refuses to start without one.
* on a loopback bind the ``Host`` must be a loopback name, so a page elsewhere cannot reach the console
  through DNS rebinding.

The token is compared in constant time and never stored in a session, a page or a log line; a session
id is random and shown (shortened) only as "who" in the audit log. Sessions are bounded and expire.
Must not know aiohttp: it reads headers from a mapping.
"""

from __future__ import annotations

import hmac
import secrets
import time
from collections import OrderedDict
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from urllib.parse import urlsplit

from gateway.settings import ConsoleSettings, is_loopback

__all__ = ["COOKIE", "CSRF_HEADER", "Denied", "Guard", "Who"]

COOKIE = "djigw_console"
CSRF_HEADER = "X-CSRF-Token"
#: sessions held at once; the oldest is signed out first
MAX_SESSIONS = 64


@dataclass(frozen=True, slots=True)
class Who:
    """Who sent a request, as the audit log names them (never how they proved it)."""

    remote: str
    via: str | None  # "bearer", "session" or None (not authenticated)
    session: str | None = None  # the session id's first 8 characters

    def __str__(self) -> str:
        if self.via == "session":
            return f"session:{self.session}@{self.remote}"
        return f"{self.via or 'anonymous'}@{self.remote}"


@dataclass(frozen=True, slots=True)
class Denied:
    """A refusal: 401 (who are you?) or 403 (not allowed), and why (safe to show and log)."""

    status: int
    reason: str


@dataclass(slots=True)
class _Session:
    csrf: str
    expires: float


class Guard:
    def __init__(
        self, settings: ConsoleSettings, host: str, *, now: Callable[[], float] = time.monotonic
    ) -> None:
        self._token = settings.token.get_secret_value() if settings.token is not None else None
        self.read_only = settings.read_only
        self.loopback = is_loopback(host)
        self.view_needs_token = not self.loopback
        self._lifetime = settings.session_hours * 3600.0
        self._sessions: OrderedDict[str, _Session] = OrderedDict()
        self._now = now

    @property
    def has_token(self) -> bool:
        return self._token is not None

    # -- sessions -----------------------------------------------------------------------------------
    def token_ok(self, presented: str | None) -> bool:
        if self._token is None or not presented:
            return False
        return hmac.compare_digest(presented.encode(), self._token.encode())

    def sign_in(self, presented: str | None) -> tuple[str, str] | None:
        """A new session (its id and CSRF token) for the right token; None otherwise."""
        if not self.token_ok(presented):
            return None
        sid, csrf = secrets.token_urlsafe(32), secrets.token_urlsafe(32)
        self._sessions[sid] = _Session(csrf, self._now() + self._lifetime)
        while len(self._sessions) > MAX_SESSIONS:
            self._sessions.popitem(last=False)
        return sid, csrf

    def sign_out(self, sid: str | None) -> None:
        if sid:
            self._sessions.pop(sid, None)

    def session(self, sid: str | None) -> _Session | None:
        if not sid:
            return None
        found = self._sessions.get(sid)
        if found is not None and found.expires < self._now():
            del self._sessions[sid]
            return None
        return found

    # -- requests -----------------------------------------------------------------------------------
    def who(self, headers: Mapping[str, str], cookies: Mapping[str, str], remote: str) -> Who:
        bearer = _bearer(headers)
        if bearer is not None and self.token_ok(bearer):
            return Who(remote, "bearer")
        sid = cookies.get(COOKIE)
        if self.session(sid) is not None:
            assert sid is not None
            return Who(remote, "session", sid[:8])
        return Who(remote, None)

    def host_ok(self, headers: Mapping[str, str]) -> bool:
        """On a loopback bind, only loopback host names (no DNS rebinding)."""
        if not self.loopback:
            return True
        host = urlsplit("//" + headers.get("Host", "")).hostname or ""
        return is_loopback(host)

    def may_view(self, headers: Mapping[str, str], cookies: Mapping[str, str], remote: str) -> Denied | None:
        if not self.host_ok(headers):
            return Denied(403, "unexpected Host")
        if self.view_needs_token and self.who(headers, cookies, remote).via is None:
            return Denied(401, "sign in with the console token")
        return None

    def may_act(
        self, headers: Mapping[str, str], cookies: Mapping[str, str], remote: str, *, stop: bool = False
    ) -> Denied | None:
        """None when this request may run an action (``stop``: the emergency stop)."""
        if not self.host_ok(headers):
            return Denied(403, "unexpected Host")
        if self._token is None:
            return Denied(403, "no console.token is configured: the console is read-only")
        who = self.who(headers, cookies, remote)
        if who.via is None:
            return Denied(401, "sign in with the console token")
        origin = _origin(headers)
        if who.via == "session":
            if origin is None:
                return Denied(403, "no Origin or Referer: refused (CSRF)")
            sid = cookies.get(COOKIE)
            session = self.session(sid)
            presented = headers.get(CSRF_HEADER, "")
            if session is None or not hmac.compare_digest(presented.encode(), session.csrf.encode()):
                return Denied(403, "missing or wrong CSRF token")
        if origin is not None and origin != headers.get("Host", "").lower():
            return Denied(403, "cross-origin request refused")
        if self.read_only and not stop:
            return Denied(403, "the console is read-only")
        return None


def _bearer(headers: Mapping[str, str]) -> str | None:
    value = headers.get("Authorization", "")
    scheme, _, token = value.partition(" ")
    return token.strip() if scheme.lower() == "bearer" and token.strip() else None


def _origin(headers: Mapping[str, str]) -> str | None:
    """The host[:port] the request says it comes from (``Origin``, else ``Referer``); the scheme is left
    out so a TLS reverse proxy that passes ``Host`` on still matches. ``null`` stays ``null``."""
    origin = headers.get("Origin") or headers.get("Referer")
    if not origin:
        return None
    if origin == "null":
        return "null"
    return urlsplit(origin).netloc.lower()
