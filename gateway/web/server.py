"""The gateway's HTTP endpoint: ``/metrics``, ``/healthz``, ``/status`` and the web console (aiohttp).

Owns the routes, the WebSocket push and the server's life cycle. Threads: aiohttp runs on an asyncio
loop of its own, in the thread ``web`` (:meth:`WebServer.start` / :meth:`WebServer.stop`), not on the
gateway's loop, because ``/healthz`` must answer 503 while the gateway's loop is stalled (a stalled loop
answers nothing) and no page, download or slow client may ever queue work on the loop that answers the
cloud. What the pages see is read **on the gateway's loop**, once per push tick for every open page
together (:meth:`gateway.web.state.ConsoleState.gather`, with the same deadline as ``/healthz``);
actions run there as coroutines (``run_coroutine_threadsafe``). The only things touched from this thread
are thread-safe by design: the frame taps (decoded here, off the gateway's loop) and the journal (locked).

Live control from a page (issue #35): a signed-in page's ``{"type": "drc"}`` WebSocket messages (sticks,
heartbeats, the stop) are handed to ``DrcController.inline_main`` from this thread, as a ``drc/down``
message on the main link would be; the page's seq is counted here; its WebSocket's loss zeroes its sticks.

Push: one JSON ``state`` message per tick (``console.push_hz``, at most 10 Hz: every device's state at
most ten times a second), encoded once and offered to every page; a page that reads slowly gets the
newest state and skips the ones it missed (its queue of journal and frame messages is bounded too).
Every action and every refusal is written to the audit log (``gateway.audit``) with who, what and the
result, and noted in the journal. Security rules: :mod:`gateway.web.security`.

Must not know device protocols, Cloud API methods (``actions`` does) or Prometheus (``observability``).

Time: the web thread's own loop paces pages, pauses and the sign-in delay in real time (browsers see
it); the gateway's clock (``Observability.clock``) keeps the console's sessions, uptime and timestamps.

Why this module is longer than 500 lines: one route handler per endpoint of the console's HTTP API and its
WebSocket push, on one server object whose life cycle and thread they share; the page's state and actions
already live in state.py and actions.py.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import json
import logging
import threading
from collections import deque
from collections.abc import Callable, Coroutine
from importlib import resources
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web
from prometheus_client import CONTENT_TYPE_LATEST, generate_latest

from gateway.audit import audit
from gateway.jsonsafe import json_safe
from gateway.observability import VERSION, Observability
from gateway.settings import ConsoleSettings
from gateway.web import actions
from gateway.web.frames import LinkInspector
from gateway.web.journal import redact
from gateway.web.security import COOKIE, CSRF_HEADER, Denied, Guard, Who
from gateway.web.state import ConsoleState
from gateway.web.video import VideoRoutes

log = logging.getLogger(__name__)

__all__ = ["STATIC", "WebServer", "bind_problem"]

STATIC = Path(str(resources.files("gateway.web") / "static"))
#: a page's queue of journal and frame messages; older ones are dropped first when it reads too slowly
CLIENT_QUEUE = 200
#: the longest an action may take on the gateway's loop (the dispatcher answers within 3 s)
ACTION_DEADLINE = 5.0
#: frame inspector: link records decoded between two yields of the web loop (each yield lets the
#: gateway's threads have the interpreter lock), and the most a push tick decodes per link (a flood's
#: older records are skipped in the live view; the downloads keep them)
DECODE_SLICE = 8
DECODE_PER_TICK = 120
DECODE_PAUSE = 0.001
_JSON = "application/json"
#: what ``/`` answers and the start logs when the console is off (never a bare 404: issue #35)
CONSOLE_OFF = (
    "the web console is off in this gateway (console.enabled = false): turn it on with "
    "DJIGW_CONSOLE__ENABLED=true and a token (DJIGW_CONSOLE__TOKEN, or DJIGW_CONSOLE__TOKEN_FILE naming a "
    "secret file); see docs/console.md"
)
_HEADERS = {
    "X-Content-Type-Options": "nosniff",
    "X-Frame-Options": "DENY",
    "Referrer-Policy": "same-origin",
    "Cache-Control": "no-store",
}


#: where the HTTP endpoint's port is set, named in the message when it cannot be bound
PORT_SETTING = "--metrics-port, DJIGW_METRICS__PORT or [metrics] port (0: any free port)"


def bind_problem(host: str, port: int, reason: str) -> str:
    """The one message for an HTTP port that cannot be bound: the address, why, and the setting."""
    return (
        f"cannot listen on {host}:{port} for the web console, /metrics, /healthz and /status ({reason}): "
        f"is another gateway running? Choose another port with {PORT_SETTING}, or turn the endpoint off "
        "(--no-metrics, metrics.enabled = false)"
    )


def _dumps(value: Any) -> str:
    try:
        return json.dumps(value, separators=(",", ":"), default=str, allow_nan=False)
    except ValueError:  # a NaN or infinity read off a wire: JSON has none, they travel as text
        return json.dumps(json_safe(value), separators=(",", ":"), default=str, allow_nan=False)


def _same_host(origin: str, request: web.Request) -> bool:
    return origin.split("://", 1)[-1].rstrip("/").lower() == request.headers.get("Host", "").lower()


class _Page:
    """One open page: the newest state waiting for it, and its bounded queue of other messages."""

    def __init__(self, ws: web.WebSocketResponse, who: Who) -> None:
        self.ws = ws
        self.who = who
        self.state: str | None = None
        self.queue: deque[str] = deque(maxlen=CLIENT_QUEUE)
        self.wake = asyncio.Event()
        self.frames_sn: str | None = None
        #: live control from this page (its seq, whether it has flown: actions.PagePilot)
        self.pilot = actions.PagePilot()

    def offer(self, message: str, *, state: bool = False) -> None:
        if state:
            self.state = message
        else:
            self.queue.append(message)
        self.wake.set()

    async def pump(self) -> None:
        """Send what is offered, newest state first; ends when the socket closes."""
        ws = self.ws
        while not ws.closed:
            await self.wake.wait()
            self.wake.clear()
            state, self.state = self.state, None
            if state is not None:
                await ws.send_str(state)
            while self.queue and not ws.closed:
                await ws.send_str(self.queue.popleft())


class WebServer:
    """The endpoint of one running gateway: ``start(host, port)`` binds it (or returns None with the
    reason in ``bind_error``: the app stops, naming the port), ``stop()`` closes it and every page."""

    def __init__(self, observability: Observability, console: ConsoleSettings, gateway_loop: Any) -> None:
        self.obs = observability
        self.app = observability.app
        self.console = console
        self.gateway_loop = gateway_loop
        self.state = ConsoleState(
            self.app, frames=console.frames, journal=console.journal, clock=observability.clock
        )
        self.guard: Guard | None = None
        self.port: int | None = None
        #: why ``start`` could not listen (the caller names the port and the setting)
        self.bind_error: str | None = None
        self.loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._runner: web.AppRunner | None = None
        self._pages: set[_Page] = set()
        self._has_pages: asyncio.Event | None = None
        self._pump_task: asyncio.Task[None] | None = None
        self._journal_n = 0

    # -- life cycle (the caller's thread) -------------------------------------------------------------
    def start(self, host: str, port: int) -> WebServer | None:
        self.guard = Guard(self.console, host, now=self.obs.clock.monotonic)
        if self.console.enabled:
            self.state.attach()  # on the gateway's loop (start() is called from it): journal and taps
        ready = threading.Event()
        failure: list[BaseException] = []
        self._thread = threading.Thread(
            target=self._main, args=(host, port, ready, failure), name="web", daemon=True
        )
        self._thread.start()
        ready.wait(15)
        if failure or self.port is None:
            exc = failure[0] if failure else TimeoutError("no answer")
            self.bind_error = getattr(exc, "strerror", None) or str(exc)
            if failure and self._thread is not None:
                self._thread.join(5)  # it closes its loop: nothing is left to shut down
            self.stop()
            return None
        log.info("metrics on http://%s:%d/metrics (also /healthz, /status)", host, self.port)
        if not self.console.enabled:
            log.info("%s", CONSOLE_OFF)
        if self.console.enabled:
            log.info(
                "web console on http://%s:%d/ (%s)",
                host,
                self.port,
                "read-only"
                if self.console.read_only
                else ("actions with the console token" if self.guard.has_token else "no token: view only"),
            )
        return self

    def stop(self) -> None:
        loop, thread = self.loop, self._thread
        if loop is not None and not loop.is_closed():
            with contextlib.suppress(RuntimeError, concurrent.futures.TimeoutError):
                asyncio.run_coroutine_threadsafe(self._shutdown(), loop).result(5)
            with contextlib.suppress(RuntimeError):
                loop.call_soon_threadsafe(loop.stop)
        if thread is not None:
            thread.join(5)
        self._thread = None

    def _main(self, host: str, port: int, ready: threading.Event, failure: list[BaseException]) -> None:
        loop = asyncio.new_event_loop()
        self.loop = loop
        try:
            try:
                loop.run_until_complete(self._serve(host, port))
            except BaseException as exc:  # reported by start()
                failure.append(exc)
                return
            finally:
                ready.set()
            loop.run_forever()
        finally:
            with contextlib.suppress(Exception):
                loop.run_until_complete(loop.shutdown_asyncgens())
            loop.close()

    async def _serve(self, host: str, port: int) -> None:
        app = web.Application(client_max_size=64 * 1024, middlewares=[self._headers])
        r = app.router
        r.add_get("/metrics", self._metrics)
        r.add_get("/healthz", self._healthz)
        r.add_get("/status", self._status)
        if self.console.enabled:
            r.add_get("/", self._index)
            r.add_static("/static/", STATIC, show_index=False, follow_symlinks=False)
            r.add_get("/api/session", self._session_get)
            r.add_post("/api/session", self._session_post)
            r.add_delete("/api/session", self._session_delete)
            r.add_get("/api/catalog", self._catalog)
            r.add_get("/api/tracks", self._tracks)
            r.add_get("/api/wayline/{flight_id}", self._wayline_route)
            r.add_post("/api/action", self._action)
            r.add_post("/api/estop", self._estop)
            r.add_get("/api/cloud-control", self._cloud_control_get)
            r.add_post("/api/cloud-control", self._cloud_control_post)
            r.add_get("/api/frames/{sn}", self._frames_download)
            r.add_get("/api/ws", self._ws)
            VideoRoutes(  # the live video preview (gateway/web/video.py, static/js/video.js)
                live=lambda: getattr(self.app, "live", None),
                viewer=self._viewer,
                refuse=self._refuse,
                same_origin=lambda req: "Origin" not in req.headers or _same_host(req.headers["Origin"], req),
                on_gateway=self._on_gateway,
            ).add_to(r)
        r.add_route("*", "/{tail:.*}", self._not_found)
        runner = web.AppRunner(app, access_log=None, handle_signals=False, shutdown_timeout=1.0)
        await runner.setup()
        site = web.TCPSite(runner, host, port, reuse_address=True)
        try:
            await site.start()
        except BaseException:
            await runner.cleanup()
            raise
        self._runner = runner
        # the bound port (port 0 picks a free one): aiohttp's public BaseRunner.addresses, one
        # getsockname() per listening socket of its sites
        addresses = runner.addresses
        self.port = int(addresses[0][1]) if addresses else port
        self._has_pages = asyncio.Event()
        self._pump_task = asyncio.get_running_loop().create_task(self._pump(), name="console-push")

    async def _shutdown(self) -> None:
        if self._pump_task is not None:
            self._pump_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._pump_task
        for page in list(self._pages):
            with contextlib.suppress(Exception):
                await page.ws.close()
        if self._runner is not None:
            await self._runner.cleanup()
            self._runner = None

    # -- the gateway's loop ---------------------------------------------------------------------------
    async def _on_gateway(self, fn: Callable[[], Any], timeout: float | None = None) -> Any:
        """``fn()`` run on the gateway's loop; TimeoutError when the loop does not get to it in time."""
        done: concurrent.futures.Future[Any] = concurrent.futures.Future()

        def run() -> None:
            if done.set_running_or_notify_cancel():
                try:
                    done.set_result(fn())
                except BaseException as exc:  # handed to the waiting coroutine
                    done.set_exception(exc)

        self.gateway_loop.call_soon_threadsafe(run)
        return await asyncio.wait_for(asyncio.wrap_future(done), timeout or self.obs.loop_deadline)

    async def _run_on_gateway(self, coro: Coroutine[Any, Any, Any], timeout: float) -> Any:
        future = asyncio.run_coroutine_threadsafe(coro, self.gateway_loop)
        return await asyncio.wait_for(asyncio.wrap_future(future), timeout)

    # -- middleware -------------------------------------------------------------------------------------
    @web.middleware
    async def _headers(self, request: web.Request, handler: Callable[..., Any]) -> web.StreamResponse:
        try:
            response: web.StreamResponse = await handler(request)
        except web.HTTPException as exc:
            response = exc
        except Exception:  # never let a bug here take the server down
            log.exception("HTTP request %s failed", request.path)
            response = web.Response(status=500, text="internal error\n")
        if not response.prepared:
            for key, value in _HEADERS.items():
                response.headers.setdefault(key, value)
            if request.path == "/" or request.path.startswith("/static/"):
                response.headers["Content-Security-Policy"] = self._csp()
        return response

    def _csp(self) -> str:
        img = "'self' data:"
        if self.console.tile_url:
            from urllib.parse import urlsplit

            parts = urlsplit(self.console.tile_url)
            img += f" {parts.scheme}://{parts.netloc}"
        return (
            "default-src 'none'; script-src 'self'; style-src 'self'; connect-src 'self'; media-src blob:; "
            f"img-src {img}; font-src 'self'; base-uri 'none'; form-action 'self'; frame-ancestors 'none'"
        )

    # -- the observability endpoints --------------------------------------------------------------------
    async def _metrics(self, request: web.Request) -> web.Response:
        body = await asyncio.get_running_loop().run_in_executor(None, generate_latest, self.obs.registry)
        return web.Response(body=body, headers={"Content-Type": CONTENT_TYPE_LATEST})

    async def _healthz(self, request: web.Request) -> web.Response:
        snap = await asyncio.get_running_loop().run_in_executor(None, self.obs.snapshot)
        healthy, checks = self.obs.health(snap)
        body = {
            "status": "ok" if healthy else "unhealthy",
            "broker": self.obs.broker_state(snap),
            "checks": checks,
        }
        return web.json_response(body, status=200 if healthy else 503)

    async def _status(self, request: web.Request) -> web.Response:
        return web.json_response(await asyncio.get_running_loop().run_in_executor(None, self.obs.status))

    async def _not_found(self, request: web.Request) -> web.Response:
        if self.console.enabled:
            return web.Response(status=404, text="try / (the console), /metrics, /healthz or /status\n")
        off = (
            f"{CONSOLE_OFF}\n"
            if request.path == "/" or request.path.startswith(("/api/", "/static/"))
            else ""
        )
        return web.Response(status=404, text=f"{off}try /metrics, /healthz or /status\n")

    # -- the console ------------------------------------------------------------------------------------
    def _guard(self) -> Guard:
        assert self.guard is not None
        return self.guard

    def _who(self, request: web.Request) -> Who:
        return self._guard().who(request.headers, request.cookies, request.remote or "?")

    def _viewer(self, request: web.Request) -> Denied | None:
        return self._guard().may_view(request.headers, request.cookies, request.remote or "?")

    @staticmethod
    def _refuse(denied: Denied) -> web.Response:
        return web.json_response({"error": denied.reason}, status=denied.status)

    async def _index(self, request: web.Request) -> web.StreamResponse:
        if not self._guard().host_ok(request.headers):
            return self._refuse(Denied(403, "unexpected Host"))
        return web.FileResponse(STATIC / "index.html", headers={"Cache-Control": "no-store"})

    async def _session_get(self, request: web.Request) -> web.Response:
        guard = self._guard()
        if not guard.host_ok(request.headers):
            return self._refuse(Denied(403, "unexpected Host"))
        session = guard.session(request.cookies.get(COOKIE))
        return web.json_response(
            {
                "signed_in": session is not None or self._who(request).via is not None,
                "csrf": session.csrf if session is not None else None,
                "token_configured": guard.has_token,
                "read_only": guard.read_only,
                "view_needs_token": guard.view_needs_token,
                "gateway_sn": self.app.settings.gateway_sn,
                "version": VERSION,
            }
        )

    async def _session_post(self, request: web.Request) -> web.Response:
        guard = self._guard()
        who = self._who(request)
        if not guard.host_ok(request.headers):
            return self._refuse(Denied(403, "unexpected Host"))
        origin = request.headers.get("Origin")
        if (
            origin is not None
            and origin.split("://", 1)[-1].lower() != request.headers.get("Host", "").lower()
        ):
            audit("console_sign_in", who=str(who), result="refused", reason="cross-origin")
            return self._refuse(Denied(403, "cross-origin request refused"))
        try:
            body = await request.json()
            token = body.get("token") if isinstance(body, dict) else None
        except ValueError:
            token = None
        issued = guard.sign_in(token if isinstance(token, str) else None)
        if issued is None:
            audit("console_sign_in", who=str(who), result="refused", reason="wrong token")
            await asyncio.sleep(0.5)  # a guesser waits
            return self._refuse(
                Denied(401, "wrong token" if guard.has_token else "no console.token is configured")
            )
        sid, csrf = issued
        audit("console_sign_in", who=f"session:{sid[:8]}@{request.remote}", result="ok")
        response = web.json_response({"csrf": csrf, "read_only": guard.read_only})
        response.set_cookie(
            COOKIE,
            sid,
            httponly=True,
            samesite="Strict",
            path="/",
            max_age=int(self.console.session_hours * 3600),
        )
        return response

    async def _session_delete(self, request: web.Request) -> web.Response:
        self._guard().sign_out(request.cookies.get(COOKIE))
        response = web.json_response({"signed_in": False})
        response.del_cookie(COOKIE, path="/")
        return response

    async def _catalog(self, request: web.Request) -> web.Response:
        denied = self._viewer(request)
        if denied is not None:
            return self._refuse(denied)
        catalog = await self._on_gateway(lambda: actions.catalogue(self.app))
        catalog["config"] = {
            "tile_url": self.console.tile_url,
            "push_hz": self.console.push_hz,
            "read_only": self.console.read_only,
            "frames": self.console.frames,
        }
        return web.json_response(catalog, dumps=_dumps)

    async def _tracks(self, request: web.Request) -> web.Response:
        denied = self._viewer(request)
        if denied is not None:
            return self._refuse(denied)
        return web.json_response(await self._on_gateway(self.state.track_view), dumps=_dumps)

    async def _wayline_route(self, request: web.Request) -> web.Response:
        """A wayline task's route for the map (fetched once per task/version, never pushed)."""
        denied = self._viewer(request)
        if denied is not None:
            return self._refuse(denied)
        flight_id = request.match_info["flight_id"]
        view = await self._on_gateway(lambda: self.state.route_view(flight_id))
        if view is None:
            return web.json_response({"reason": f"no route for wayline task {flight_id!r}"}, status=404)
        return web.json_response(view, dumps=_dumps)

    async def _frames_download(self, request: web.Request) -> web.Response:
        denied = self._viewer(request)
        if denied is not None:
            return self._refuse(denied)
        sn = request.match_info["sn"]
        inspector = self.state.inspectors.get(sn)
        if inspector is None:
            return self._refuse(Denied(404, f"no link inspected for {sn}"))
        directions = [d for d in request.query.get("dir", "rx,tx").split(",") if d in ("rx", "tx")]
        fmt = request.query.get("format", "candump" if inspector.kind == "can" else "hex")
        if fmt == "candump" and inspector.kind == "can":
            text, name = inspector.candump(directions), f"{sn}.candump.log"
        elif fmt == "hex":
            text, name = inspector.hex_lines(directions), f"{sn}.hex.txt"
        else:
            return self._refuse(Denied(400, "format: candump (CAN links) or hex"))
        return web.Response(
            text=text,
            content_type="text/plain",
            headers={"Content-Disposition": f'attachment; filename="{name}"'},
        )

    # -- actions ----------------------------------------------------------------------------------------
    async def _action(self, request: web.Request) -> web.Response:
        who = self._who(request)
        method = "?"

        def refuse(status: int, reason: str, **extra: Any) -> web.Response:
            audit(
                "console_action",
                who=str(who),
                method=method,
                result="refused",
                status=status,
                reason=reason,
                **extra,
            )
            self.state.journal.note("action", method, who=str(who), refused=reason, status=status)
            return web.json_response({"error": reason}, status=status)

        try:
            body = await request.json()
        except ValueError:
            body = None
        if isinstance(body, dict) and isinstance(body.get("method"), str):
            method = body["method"][:64]
        denied = self._guard().may_act(request.headers, request.cookies, request.remote or "?")
        if denied is not None:
            return refuse(denied.status, denied.reason)
        if not isinstance(body, dict) or not isinstance(body.get("method"), str):
            return refuse(400, "expected {method, data, confirm}")
        unknown = sorted(set(body) - {"method", "data", "confirm"})
        if unknown:  # nothing accepted is ignored: a field the console does not read is refused
            return refuse(400, f"unknown field(s) {unknown}: expected method, data, confirm")
        data = body.get("data", {})
        offered = await self._on_gateway(lambda: actions.offered(self.app))
        if method not in offered:
            return refuse(400, f"{method} is not offered by any device here")
        if actions.moves(method) and body.get("confirm") is not True:
            return refuse(428, f"{method} moves a device: confirm it (confirm: true)")
        shown = redact(data)
        try:
            outcome = await self._run_on_gateway(actions.run_action(self.app, method, data), ACTION_DEADLINE)
        except TimeoutError:
            return refuse(504, "the gateway did not answer in time", data=shown)
        audit(
            "console_action",
            who=str(who),
            method=method,
            data=shown,
            result=outcome["result"],
            tid=outcome.get("tid"),
            output=outcome.get("output"),
        )
        self.state.journal.note(
            "action", method, who=str(who), result=outcome["result"], output=outcome.get("output")
        )
        if isinstance(data, dict):
            self.state.journal.track_local(method, data, outcome["result"])
        return web.json_response(outcome, dumps=_dumps)

    async def _estop(self, request: web.Request) -> web.Response:
        who = self._who(request)
        denied = self._guard().may_act(request.headers, request.cookies, request.remote or "?", stop=True)
        if denied is not None:
            audit(
                "console_emergency_stop",
                who=str(who),
                result="refused",
                status=denied.status,
                reason=denied.reason,
            )
            self.state.journal.note("emergency_stop", "emergency_stop", who=str(who), refused=denied.reason)
            return self._refuse(denied)
        try:
            outcome = await self._run_on_gateway(actions.emergency_stop(self.app), ACTION_DEADLINE)
        except TimeoutError:
            audit("console_emergency_stop", who=str(who), result="timeout")
            return web.json_response({"error": "the gateway did not answer in time"}, status=504)
        audit(
            "console_emergency_stop",
            who=str(who),
            result="ok" if not outcome["failed"] else "partial",
            **outcome,
        )
        self.state.journal.note("emergency_stop", "emergency_stop", who=str(who), **outcome)
        return web.json_response(outcome)

    async def _cloud_control_get(self, request: web.Request) -> web.Response:
        """Who holds cloud control and which request waits for the operator (``dji-gateway control-auth``)."""
        denied = self._viewer(request)
        if denied is not None:
            return self._refuse(denied)
        cc = getattr(self.app, "cloud_control", None)
        snapshot = await self._on_gateway(lambda: cc.snapshot() if cc is not None else None)
        return web.json_response({"cloud_control": snapshot})

    async def _cloud_control_post(self, request: web.Request) -> web.Response:
        """The operator's answer: ``{"decision": "accept"|"deny"|"revoke", "user_id"?: str}`` (an action:
        the console token, as for services). 200 when it applied, 409 when there was nothing to answer."""
        who = self._who(request)
        try:
            body = await request.json()
        except ValueError:
            body = None
        decision = body.get("decision") if isinstance(body, dict) else None
        denied = self._guard().may_act(request.headers, request.cookies, request.remote or "?")
        if denied is None and (not isinstance(body, dict) or decision not in actions.DECISIONS):
            denied = Denied(400, "expected {decision: accept|deny|revoke, user_id}")
        if denied is None and (
            set(body) - {"decision", "user_id"} or not isinstance(body.get("user_id", ""), str)
        ):
            denied = Denied(
                400, "expected {decision: accept|deny|revoke, user_id}: a string user_id, nothing else"
            )
        if denied is not None:
            audit(
                "console_cloud_control",
                who=str(who),
                result="refused",
                status=denied.status,
                reason=denied.reason,
            )
            return self._refuse(denied)
        assert isinstance(body, dict)
        user_id = body.get("user_id")
        outcome = await self._on_gateway(
            lambda: actions.cloud_control_decision(self.app, str(decision), user_id, str(who))
        )
        self.state.journal.note("cloud_control", str(decision), who=str(who), user_id=user_id, **{
            k: v for k, v in outcome.items() if k != "cloud_control"})  # fmt: skip
        return web.json_response(outcome, status=200 if outcome["ok"] else 409, dumps=_dumps)

    # -- the push ---------------------------------------------------------------------------------------
    async def _ws(self, request: web.Request) -> web.StreamResponse:
        denied = self._viewer(request)
        origin = request.headers.get("Origin")
        if denied is None and origin is not None and not _same_host(origin, request):
            denied = Denied(403, "cross-origin WebSocket refused")
        if denied is not None:
            return self._refuse(denied)
        ws = web.WebSocketResponse(heartbeat=20.0, max_msg_size=4096)
        await ws.prepare(request)
        page = _Page(ws, self._who(request))
        self._pages.add(page)
        assert self._has_pages is not None
        self._has_pages.set()
        sender = asyncio.get_running_loop().create_task(page.pump(), name="console-page")
        page.offer(_dumps({"type": "journal", "entries": self.state.journal.since(0)[-100:]}))
        try:
            async for msg in ws:
                if msg.type != WSMsgType.TEXT:
                    continue
                try:
                    ask = json.loads(msg.data)
                except ValueError:
                    continue
                if isinstance(ask, dict) and ask.get("type") == "drc":
                    self._pilot(request, page, ask)
                    continue
                if isinstance(ask, dict) and ask.get("type") == "frames":
                    sn = ask.get("sn")
                    page.frames_sn = sn if isinstance(sn, str) and sn in self.state.inspectors else None
                    if page.frames_sn is not None:
                        inspector = self.state.inspectors[page.frames_sn]
                        await self._decode(inspector)
                        page.offer(
                            _dumps(
                                {
                                    "type": "frames",
                                    "sn": page.frames_sn,
                                    "reset": True,
                                    "kind": inspector.kind,
                                    "records": list(inspector.frames),
                                }
                            )
                        )
        finally:
            if page.pilot.flying:  # the dead-man of a lost WebSocket: the page's sticks zeroed at once
                self._down(page.pilot.zero())
            self._pages.discard(page)
            sender.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await sender
        return ws

    # -- live control from the page (the web thread) -----------------------------------------------------
    def _pilot(self, request: web.Request, page: _Page, ask: dict[str, Any]) -> None:
        """``{"type": "drc", "csrf", "method", "data"}``: the page's sticks, heartbeats or stop, fed to the
        live-control session as a ``drc/down`` message on the main link (``DrcController.inline_main``, the
        path a cloud's takes: its seq rules, stick and heartbeat timeouts, authority and cloud-control
        checks; answers go out on ``drc/up``). An action: the sign-in session's CSRF token, as for the forms
        (a stop also from a read-only console). Refused messages are answered to the page
        (``drc_refused``), audited once per refused stream, never fed."""
        method = ask.get("method")
        pilot = page.pilot
        stop = method == actions.STOP
        headers = {**request.headers, CSRF_HEADER: str(ask.get("csrf") or "")}
        denied = self._guard().may_act(headers, request.cookies, request.remote or "?", stop=stop)
        if denied is None and (
            method not in actions.PAGE_DRC or set(ask) - {"type", "csrf", "method", "data"}
        ):
            denied = Denied(400, f"expected {{type: drc, csrf, method: {'|'.join(actions.PAGE_DRC)}, data}}")
        data = ask.get("data", {})
        if denied is None and not isinstance(data, dict):
            denied = Denied(400, "data: an object")
        if denied is not None:
            if not pilot.refused:  # once per refused stream: ten sticks a second are one line
                audit("console_drc", who=str(page.who), method=str(method)[:32], result="refused",
                      status=denied.status, reason=denied.reason)  # fmt: skip
            pilot.refused = True
            page.offer(_dumps({"type": "drc_refused", "method": str(method)[:32], "reason": denied.reason}))
            return
        assert isinstance(method, str) and isinstance(data, dict)
        if stop:
            audit("console_drc", who=str(page.who), method=method, result="sent")
            self.state.journal.note("emergency_stop", method, who=str(page.who), source="page DRC")
        elif not pilot.flying:
            audit("console_drc", who=str(page.who), method=method, result="piloting")
            self.state.journal.note("action", "drc from the page", who=str(page.who))
        pilot.refused = False
        self._down(pilot.message(method, data))

    def _down(self, payload: bytes) -> None:
        drc = getattr(self.app, "drc", None)
        if drc is not None:
            drc.inline_main(drc.down_topic, payload)

    async def _pump(self) -> None:
        """Once per tick while pages are open: gather on the gateway's loop, offer to every page."""
        assert self._has_pages is not None
        loop = asyncio.get_running_loop()
        period = 1.0 / self.console.push_hz
        while True:
            if not self._pages:
                self._has_pages.clear()
                # no page: the journal is still read now and then (its fly-to target must not be missed)
                with contextlib.suppress(TimeoutError):
                    await asyncio.wait_for(self._has_pages.wait(), 1.0)
                self.state.journal.digest()
                continue
            # the web thread's own loop paces pages in real time (browsers see it); the gateway's clock
            # is not this loop's timer: a ManualClock would freeze every page
            started = loop.time()
            try:
                await self._tick()
            except Exception:
                log.exception("console push failed")
            await asyncio.sleep(max(0.0, period - (loop.time() - started)))

    @staticmethod
    async def _decode(inspector: LinkInspector) -> list[dict[str, Any]]:
        """The inspector's new frames, decoded a slice at a time (the loop yields between slices)."""
        new = inspector.poll(DECODE_SLICE, catch_up=DECODE_PER_TICK)
        for _ in range(DECODE_PER_TICK // DECODE_SLICE):  # what came meanwhile waits for the next tick
            if not inspector.behind:
                break
            # a real pause, not sleep(0): releasing the interpreter lock for an instant lets this thread
            # take it straight back; a millisecond lets the gateway's waiting threads have it
            await asyncio.sleep(DECODE_PAUSE)
            new += inspector.poll(DECODE_SLICE)
        return new

    async def _tick(self) -> None:
        self.state.journal.digest()  # here, not on the gateway's loop; gather reads the fly-to target
        try:
            snap = await self._on_gateway(self.state.gather)
            state = _dumps({"type": "state", **snap})
        except (TimeoutError, RuntimeError):
            state = _dumps({"type": "stalled", "reason": "the gateway's event loop did not answer in time"})
        pages = list(self._pages)
        for page in pages:
            page.offer(state, state=True)
        await asyncio.sleep(0)  # the pages' senders run; the gateway's threads get the interpreter lock
        entries = self.state.journal.since(self._journal_n)
        if entries:
            self._journal_n = entries[-1]["n"]
            message = _dumps({"type": "journal", "entries": entries})
            for page in pages:
                page.offer(message)
        for sn in {p.frames_sn for p in pages if p.frames_sn is not None}:
            inspector = self.state.inspectors[sn]
            new = await self._decode(inspector)
            if new:
                message = _dumps({"type": "frames", "sn": sn, "kind": inspector.kind, "records": new})
                for page in pages:
                    if page.frames_sn == sn:
                        page.offer(message)
