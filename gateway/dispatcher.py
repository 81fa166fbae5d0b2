"""The dispatcher: every message from the cloud gets exactly one well-formed answer, or a counted,
logged reason why none is possible.

Owns the Cloud API request flow: topic → kind, validation through the contract's registry, the
duplicate-``tid`` reply cache, routing to the adapter that owns the device, the control-authority
rules, the per-request deadline, and the mapping of adapter failures to result codes. It knows
Cloud API methods, never bytes; it publishes through an :class:`Outbox` and never blocks on it.
A handler that raises is caught here, counted, and answered with 599001; nothing propagates to
the MQTT thread or stops the loop (a peer gateway is known to go deaf after one such exception).

Why this module is longer than 500 lines: it is the one request flow (validate, de-duplicate, route, check
authority, run under a deadline, map the failure, answer once); its parts share the reply cache and the in-
flight table, and splitting them would spread the "exactly one answer" rule over several files.
"""

from __future__ import annotations

import asyncio
import contextlib
import contextvars
import logging
import re
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from pydantic import BaseModel, ValidationError

from adapters.base import Adapter, CallResult
from adapters.errors import (
    DeviceError,
    DeviceNotConnected,
    DeviceRejected,
    DeviceTimeout,
    InvalidParameters,
    MethodNotSupported,
)
from gateway import logcontext
from gateway.audit import audit, audited
from gateway.clock import Clock
from gateway.devices import DeviceTable
from gateway.metrics import Metrics
from gateway.settings import DispatcherSettings
from schemas import (
    ResultCode,
    TopicError,
    TopicKind,
    error_reply_from_validation,
    parse_topic,
    property_set_reply,
    reply_for,
    topic,
)
from schemas.base import InboundModel
from schemas.envelope import ErrorOutput, ResultReply, ServicesReplyMessage
from schemas.registry import Registry
from schemas.services import DrcModeEnter, FlightAuthorityGrab, PayloadAuthorityGrab

log = logging.getLogger(__name__)

__all__ = ["FLIGHT_METHODS", "Dispatcher", "Outbox"]

#: Services that move the aircraft: they need flight authority when ``require_authority`` is on.
FLIGHT_METHODS = frozenset({"takeoff_to_point", "fly_to_point", "fly_to_point_stop"})
#: Live flight control: answered by the DRC controller (which checks authority itself).
_DRC_METHODS = frozenset({"drc_mode_enter", "drc_mode_exit"})
#: No device may hold a reply longer than this: the reference cloud SDK resends after 3 s.
MAX_DEADLINE = 2.8
#: Services that stop motion: never refused for a parsing reason. When their ``data`` cannot be parsed
#: (a cloud that sends ``"data": 5``), they run as if sent without parameters and are answered normally
#: (``"data": {}``, ``""``, ``null`` and no ``data`` are already the same: schemas.envelope).
STOP_METHODS = frozenset(
    {
        "drc_mode_exit",
        "fly_to_point_stop",
        "x_osdk_hotpoint_stop",
        "x_osdk_followme_stop",
        "x_robomaster_stop",
    }
)
#: Services handled by the dispatcher itself rather than routed to one adapter's handler.
_AUTHORITY_METHODS = frozenset({"flight_authority_grab", "payload_authority_grab"})

_TID = re.compile(rb'"tid"\s*:\s*"([^"\\]{1,128})"')
_BID = re.compile(rb'"bid"\s*:\s*"([^"\\]{1,128})"')
_METHOD = re.compile(rb'"method"\s*:\s*"([a-z][a-z0-9_]{0,63})"')


class Outbox(Protocol):
    def publish(self, topic: str, payload: bytes, qos: int = 1, retain: bool = False) -> bool: ...


class LiveControl(Protocol):
    """What the dispatcher asks of live control (:class:`gateway.drc.DrcController`): the two services
    that enter and leave it, answered as (result code, output)."""

    async def enter(self, data: DrcModeEnter) -> tuple[int, dict[str, Any] | None]: ...

    async def exit(self) -> tuple[int, dict[str, Any] | None]: ...


class CloudControlCalls(Protocol):
    """What the dispatcher asks of cloud-control authorisation (:class:`gateway.cloud_control.CloudControl`):
    the services it answers, each with the request's ``bid`` (its notify event carries it)."""

    methods: frozenset[str]

    async def call(self, method: str, data: Any, bid: str) -> tuple[int, dict[str, Any] | None]: ...


class WaylineCalls(Protocol):
    """What the dispatcher asks of wayline tasks (:class:`gateway.wayline.service.WaylineService`): the
    services it answers, each as (result code, output)."""

    methods: frozenset[str]

    async def call(self, method: str, data: Any) -> tuple[int, dict[str, Any] | None]: ...


class LiveCalls(Protocol):
    """What the dispatcher asks of live streaming (:class:`gateway.video.service.LiveService`): the
    ``live_*`` services, each as (result code, output)."""

    methods: frozenset[str]

    async def call(self, method: str, data: Any) -> tuple[int, dict[str, Any] | None]: ...


class ReplyJournal(Protocol):
    """Where replies outlive the process (:class:`gateway.store.StateStore`): a request resent with the
    same tid after a restart is answered from here, not acted on again."""

    def reply_recorded(self, tid: str, payload: bytes, *, durable: bool = True) -> None: ...

    def recorded_reply(self, tid: str, max_age_ms: int) -> bytes | None: ...

    def request_started(self, tid: str, method: str) -> None: ...

    def started_request(self, tid: str, max_age_ms: int) -> str | None: ...


@dataclass
class _Cached:
    expires: float
    payload: bytes | None  # None while the first copy is still in flight
    waiters: list[asyncio.Future[bytes]]


#: the device whose own ``services`` topic the request in hand came on (it is announced as a gateway of its
#: own, docs/cloud-api.md "Device tree"); None: the gateway's topic. Set per message task, read when routing
#: and replying.
_VIA: contextvars.ContextVar[str | None] = contextvars.ContextVar("dispatcher_via", default=None)


class Dispatcher:
    def __init__(
        self,
        *,
        gateway_sn: str,
        registry: Registry,
        devices: DeviceTable,
        outbox: Outbox,
        settings: DispatcherSettings,
        clock: Clock,
        metrics: Metrics,
        on_authority_change: Callable[[], None] | None = None,
        on_events_reply: Callable[[str, int], None] | None = None,
        drc: LiveControl | None = None,
        wayline: WaylineCalls | None = None,
        on_requests_reply: Callable[[Any], None] | None = None,
        cloud_control: CloudControlCalls | None = None,
        journal: ReplyJournal | None = None,
        own_gateways: frozenset[str] = frozenset(),
        live: LiveCalls | None = None,
    ) -> None:
        self.gateway_sn = gateway_sn
        #: devices announced as gateways of their own: their ``services`` topic is served too
        self.own_gateways = own_gateways
        #: replies kept across restarts (written before they are published); None: in memory only
        self.journal = journal
        self.registry = registry
        self.devices = devices
        self.outbox = outbox
        self.settings = settings
        self.clock = clock
        self.metrics = metrics
        self.on_authority_change = on_authority_change
        self.on_events_reply = on_events_reply
        self.drc = drc  # gateway.drc.DrcController (enter/exit), None: live control unavailable
        #: gateway.wayline.service.WaylineService (flighttask_*, return_home*), None: no wayline tasks
        self.wayline = wayline
        self.cloud_control = cloud_control  # gateway.cloud_control.CloudControl, None: not offered
        self.live = live  # gateway.video.service.LiveService (live_*), None: no live video
        #: told every valid requests_reply (gateway.cloud_requests.CloudRequests.answer)
        self.on_requests_reply = on_requests_reply
        self._replies: OrderedDict[str, _Cached] = OrderedDict()
        self._pending = 0
        self._tasks: set[asyncio.Task[None]] = set()

    @property
    def in_flight(self) -> int:
        """Requests being executed now (``max_pending`` bounds it)."""
        return self._pending

    # -- entry points ---------------------------------------------------------------------------
    def submit(self, topic_name: str, payload: bytes, oversize: bool = False) -> None:
        """Start handling one message in its own task, so a slow device delays nobody else."""
        task = asyncio.get_running_loop().create_task(self.handle(topic_name, payload, oversize))
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    async def drain(self) -> None:
        """Wait for every message in flight (shutdown, tests)."""
        while self._tasks:
            await asyncio.gather(*list(self._tasks), return_exceptions=True)

    async def handle(self, topic_name: str, payload: bytes, oversize: bool = False) -> None:
        """Handle one message; never raises."""
        token = _VIA.set(None)  # _handle names the device topic; never left over for the caller
        try:
            await self._handle(topic_name, payload, oversize)
        except Exception:
            self.metrics.inc("handler_exceptions_total", where="dispatcher")
            log.exception("unexpected error while handling a message on %s", topic_name[:200])
            with contextlib.suppress(Exception):
                self._reply_raw(payload, ResultCode.INTERNAL_ERROR, "internal error in the gateway")
        finally:
            _VIA.reset(token)

    async def _handle(self, topic_name: str, payload: bytes, oversize: bool) -> None:
        try:
            kind, sn = parse_topic(topic_name)
        except TopicError as exc:
            self.metrics.inc("inbound_rejected_total", reason="topic")
            log.warning("ignored a message on an unknown topic: %s", exc)
            return
        if sn != self.gateway_sn:
            if not (kind is TopicKind.SERVICES and sn in self.own_gateways):
                self.metrics.inc("inbound_rejected_total", reason="foreign_sn")
                log.warning("ignored %s for another gateway", kind.value)
                return
            _VIA.set(sn)  # reset by handle()
        if oversize:
            self.metrics.inc("inbound_rejected_total", reason="oversize")
            log.warning("refused an oversize %s payload", kind.value)
            if kind is TopicKind.SERVICES:
                self._reply_raw(payload, ResultCode.INVALID_PARAMETERS, "payload too large")
            return
        if kind is TopicKind.SERVICES:
            await self._services(payload)
        elif kind is TopicKind.EVENTS_REPLY:
            self._events_reply(payload)
        elif kind is TopicKind.PROPERTY_SET:
            self._property_set(payload)
        elif kind is TopicKind.DRC_DOWN:  # live control answers drc/down in the network thread, not here
            self.metrics.inc("inbound_rejected_total", reason="drc_not_entered")
        elif kind in (TopicKind.STATUS_REPLY, TopicKind.REQUESTS_REPLY):
            self._cloud_answer(kind, payload)
        else:
            self.metrics.inc("inbound_rejected_total", reason="direction")
            log.warning("ignored a message on %s (the gateway publishes there)", kind.value)

    # -- services -------------------------------------------------------------------------------
    async def call_local(self, payload: bytes) -> bytes:
        """One services request from the gateway's own web console: validated, routed, authority-checked,
        time-limited and counted exactly like one from the cloud; its reply is returned to the caller
        instead of published (the cloud did not ask). Never raises: a bug answers 599001."""
        replies: list[bytes] = []
        try:
            await self._services(payload, replies.append)
        except Exception:
            self.metrics.inc("handler_exceptions_total", where="dispatcher")
            log.exception("unexpected error while handling a console request")
            with contextlib.suppress(Exception):
                self._reply_raw(
                    payload, ResultCode.INTERNAL_ERROR, "internal error in the gateway", replies.append
                )
        return replies[0] if replies else b""

    async def _services(self, payload: bytes, reply_to: Callable[[bytes], None] | None = None) -> None:
        try:
            request = self.registry.validate(TopicKind.SERVICES, payload)
        except ValidationError as exc:
            request = self._stop_despite(payload)
            if request is not None:
                await self._run_services(request, reply_to)
                return
            reply = error_reply_from_validation(
                TopicKind.SERVICES, payload, exc, timestamp=self.clock.time_ms(), gateway=self._answering()
            )
            method = _peek(_METHOD, payload) or "?"
            logcontext.set_context(method=_metric_method(method), tid=_peek(_TID, payload))
            self.metrics.inc("services_total", method=_metric_method(method), result=_result_of(reply))
            if reply is None:
                if not self._reply_raw(payload, ResultCode.INVALID_PARAMETERS, "malformed message", reply_to):
                    self.metrics.inc("inbound_rejected_total", reason="unanswerable")
                    log.warning("services message without a readable tid/bid/method: not answered")
            else:
                log.info("rejected %s: %s", method, _reason_of(reply))
                self._publish_reply(reply.model_dump_json().encode(), None, reply_to)
            return
        await self._run_services(request, reply_to)

    def _stop_despite(self, payload: bytes) -> Any:
        """A stop service whose ``data`` broke the contract, read as one without parameters (None when
        the message is not such a stop, or its tid/bid cannot be read)."""
        method = _peek(_METHOD, payload)
        if method not in STOP_METHODS:
            return None
        tid, bid = _peek(_TID, payload), _peek(_BID, payload)
        if not (tid and bid):
            return None
        try:
            request = self.registry.validate(
                TopicKind.SERVICES, {"tid": tid, "bid": bid, "method": method, "data": {}}
            )
        except ValidationError:
            return None
        self.metrics.inc("services_stops_obeyed_total", method=method)
        log.warning("obeyed %s although its data could not be parsed (a stop is never refused)", method)
        return request

    async def _run_services(self, request: Any, reply_to: Callable[[bytes], None] | None = None) -> None:
        tid = request.tid
        # this task's log lines (the adapter's too) carry method and tid; a secret that arrived in the
        # request (drc_mode_enter's broker password) is masked in every log line from now on
        logcontext.set_context(method=request.method, tid=tid)
        logcontext.register_secrets_in(request.data, permanent=False)
        cached = self._cache_lookup(tid)
        if cached is not None:
            self.metrics.inc("services_duplicates_total")
            if cached.payload is not None:
                self._publish_reply(cached.payload, None, reply_to)
            else:
                fut: asyncio.Future[bytes] = asyncio.get_running_loop().create_future()
                cached.waiters.append(fut)
                self._publish_reply(await fut, None, reply_to)
            return
        if self.journal is not None:  # answered by an earlier process (it acted, maybe died before replying)
            stored = self.journal.recorded_reply(tid, int(self.settings.reply_cache_seconds * 1000))
            if stored is not None:
                self.metrics.inc("services_duplicates_total")
                log.info("%s tid %s: answered from the reply journal (acted on before a restart)",
                         request.method, tid)  # fmt: skip
                self._publish_reply(stored, self._cache_open(tid), reply_to)
                return
            if self._started_before(request):
                self._answer_unknown_outcome(request, reply_to)
                return
        entry = self._cache_open(tid)

        started = self.clock.monotonic()
        if self.journal is not None and audited(request.method):  # before acting (see _started_before)
            try:
                self.journal.request_started(tid, request.method)
            except Exception:  # a full disk must not cost the request
                self.metrics.inc("handler_exceptions_total", where="reply_journal")
                log.exception("could not mark %s as started in the state store", tid)
        result, output = await self._execute(request)
        reply = reply_for(
            request, int(result), output, timestamp=self.clock.time_ms(), gateway=self._answering()
        )
        raw = reply.model_dump_json().encode()
        elapsed = self.clock.monotonic() - started
        self.metrics.inc("services_total", method=_metric_method(request.method), result=int(result))
        self.metrics.observe("services_latency_seconds", elapsed, method=_metric_method(request.method))
        log.log(
            logging.DEBUG if result == 0 else logging.INFO,
            "answered %s with %s in %.1f ms",
            request.method,
            int(result),
            elapsed * 1000,
        )
        if audited(request.method):  # who moved what (a repeated tid is answered from the cache, not here)
            device = logcontext.current().get("device")
            source = "mqtt" if reply_to is None else "console"
            audit("service", method=request.method, tid=tid, bid=request.bid, source=source,
                  result=int(result), device=device)  # fmt: skip
        if self.journal is not None:  # before publishing: a crash after this point still knows it acted
            try:  # a read's reply is kept without waiting for the disk (a read again changes nothing)
                self.journal.reply_recorded(tid, raw, durable=audited(request.method))
            except Exception:  # a full disk must not cost the reply
                self.metrics.inc("handler_exceptions_total", where="reply_journal")
                log.exception("could not keep the reply to %s in the state store", tid)
        self._publish_reply(raw, entry, reply_to)

    def _started_before(self, request: Any) -> bool:
        """A request with a visible effect is marked started in the store before it is acted on, and the
        mark goes with its reply. A mark without a reply means an earlier process died between acting
        (or starting to) and keeping the reply: whether the device acted is unknown."""
        assert self.journal is not None
        try:
            method = self.journal.started_request(request.tid, int(self.settings.reply_cache_seconds * 1000))
        except Exception:
            self.metrics.inc("handler_exceptions_total", where="reply_journal")
            log.exception("could not read the state store for %s", request.tid)
            return False
        return method is not None

    def _answer_unknown_outcome(self, request: Any, reply_to: Callable[[bytes], None] | None) -> None:
        """Answer a resend of a request an earlier process started and never answered: 399004, not acted
        on again (the cloud reads the device's state to learn what happened). Kept like any reply."""
        tid = request.tid
        entry = self._cache_open(tid)
        reason = ("an earlier gateway process started this request and stopped before answering it: "
                  "whether the device acted is unknown; not repeated")  # fmt: skip
        reply = reply_for(
            request,
            int(ResultCode.OUTCOME_UNKNOWN),
            {"reason": reason},
            timestamp=self.clock.time_ms(),
            gateway=self.gateway_sn,
        )
        raw = reply.model_dump_json().encode()
        self.metrics.inc("services_duplicates_total")
        self.metrics.inc("services_outcome_unknown_total", method=_metric_method(request.method))
        self.metrics.inc(
            "services_total", method=_metric_method(request.method), result=int(ResultCode.OUTCOME_UNKNOWN)
        )
        log.warning("%s tid %s: started by an earlier process that stopped before answering: "
                    "answered %d (outcome unknown), not acted on again",
                    request.method, tid, int(ResultCode.OUTCOME_UNKNOWN))  # fmt: skip
        assert self.journal is not None
        try:
            self.journal.reply_recorded(tid, raw)
        except Exception:
            self.metrics.inc("handler_exceptions_total", where="reply_journal")
            log.exception("could not keep the reply to %s in the state store", tid)
        self._publish_reply(raw, entry, reply_to)

    async def _execute(self, request: Any) -> tuple[int, dict[str, Any] | None]:
        method: str = request.method
        data = request.data
        if self._pending >= self.settings.max_pending:
            return ResultCode.BUSY, {"reason": "too many requests in flight"}
        self._pending += 1
        try:
            via = _VIA.get()
            if via is not None and method not in _AUTHORITY_METHODS:
                return await self._on_own_topic(via, method, data)
            if method in _AUTHORITY_METHODS:
                return await self._grab_authority(method, data)
            if self.cloud_control is not None and method in self.cloud_control.methods:
                return await self.cloud_control.call(method, data, request.bid)
            if method in _DRC_METHODS and self.drc is not None:
                return await (self.drc.enter(data) if method == "drc_mode_enter" else self.drc.exit())
            if self.wayline is not None and method in self.wayline.methods:
                try:
                    return await self.clock.wait_for(self.wayline.call(method, data), MAX_DEADLINE)
                except TimeoutError:
                    return ResultCode.DEVICE_TIMEOUT, {"reason": f"{method} did not finish in time"}
            if self.live is not None and method in self.live.methods:
                try:
                    return await self.clock.wait_for(self.live.call(method, data), MAX_DEADLINE)
                except TimeoutError:
                    return ResultCode.DEVICE_TIMEOUT, {"reason": f"{method} did not finish in time"}
            adapter, problem = self._route(method, data)
            if adapter is None:
                return problem
            denied = self._authority_check(method, data, adapter)
            if denied is not None:
                return denied
            return await self._call(adapter, method, data)
        finally:
            self._pending -= 1

    async def _on_own_topic(
        self, sn: str, method: str, data: InboundModel
    ) -> tuple[int, dict[str, Any] | None]:
        """A request on the ``services`` topic of a device announced as its own gateway: that device serves
        it, or it is refused saying where to send it (live control, wayline tasks and cloud control belong
        to this gateway, whose serial number the reason names)."""
        adapter = self.devices.by_sn(sn)
        if adapter is None or not adapter.supports(method):
            return ResultCode.METHOD_NOT_SUPPORTED, {
                "reason": f"{method} is not served by {sn}: send it to the gateway {self.gateway_sn}"
            }
        index = getattr(data, "payload_index", None)
        if isinstance(index, str) and index != adapter.info.payload_index:
            return ResultCode.INVALID_PARAMETERS, {"reason": f"no payload {index} on {sn}"}
        other = getattr(data, "sn", None)
        if isinstance(other, str) and other != sn:
            return ResultCode.INVALID_PARAMETERS, {"reason": f"sn {other} is not {sn}"}
        denied = self._authority_check(method, data, adapter)
        if denied is not None:
            return denied
        return await self._call(adapter, method, data)

    def _route(
        self, method: str, data: InboundModel
    ) -> tuple[Adapter | None, tuple[int, dict[str, Any] | None]]:
        index = getattr(data, "payload_index", None)
        if isinstance(index, str):
            adapter = self.devices.by_payload(index)
            if adapter is None:
                known = ", ".join(self.devices.payload_indexes()) or "none"
                return None, (
                    ResultCode.INVALID_PARAMETERS,
                    {"reason": f"no payload {index} (known: {known})"},
                )
            if not adapter.supports(method):
                return None, (
                    ResultCode.METHOD_NOT_SUPPORTED,
                    {"reason": f"{method} not supported by {index}"},
                )
            return adapter, (0, None)
        sn = getattr(data, "sn", None)
        if isinstance(sn, str):
            adapter = self.devices.by_sn(sn)
            if adapter is None:
                return None, (ResultCode.INVALID_PARAMETERS, {"reason": "unknown device sn"})
            return adapter, (0, None)
        serving = self.devices.serving(method)
        if not serving:
            return None, (ResultCode.METHOD_NOT_SUPPORTED, {"reason": f"no device here supports {method}"})
        return serving[0], (0, None)

    def _authority_check(
        self, method: str, data: InboundModel, adapter: Adapter
    ) -> tuple[int, dict[str, Any]] | None:
        if not self.settings.require_authority:
            return None
        if method in FLIGHT_METHODS and adapter.info.sn not in self.devices.authority.flight:
            return ResultCode.NO_FLIGHT_AUTHORITY, {"reason": "grab flight authority first"}
        index = getattr(data, "payload_index", None)
        if isinstance(index, str) and index not in self.devices.authority.payloads:
            return ResultCode.NO_PAYLOAD_AUTHORITY, {"reason": "grab payload authority first"}
        return None

    async def grant_flight(self, why: str) -> None:
        """Flight authority for the cloud without a ``flight_authority_grab``: an RC Plus 2 / RC Pro client
        asks ``cloud_control_auth_request`` (control key "flight") instead, and its grant is the hand-over
        of the aircraft (DJI's RC DRC page: the pilot accepts, then the cloud flies). The aircraft is asked
        for control as by a grab; a refusal is logged (live control stays refused with the reason)."""
        if not self.devices.serving("flight_authority_grab"):
            return
        result, output = await self._grab_authority("flight_authority_grab", FlightAuthorityGrab())
        if result != 0:
            reason = (output or {}).get("reason")
            log.warning("%s: the aircraft refused control (%s): %s", why, result, reason)
        else:
            log.info("%s: flight authority held for the cloud", why)

    async def _grab_authority(self, method: str, data: InboundModel) -> tuple[int, dict[str, Any] | None]:
        auth = self.devices.authority
        if isinstance(data, PayloadAuthorityGrab):  # the model payload_authority_grab is validated to
            index = data.payload_index
            adapter = self.devices.by_payload(index)
            if adapter is None:
                known = ", ".join(self.devices.payload_indexes()) or "none"
                return ResultCode.INVALID_PARAMETERS, {"reason": f"no payload {index} (known: {known})"}
            if adapter.supports(method):  # a device that must be asked (e.g. an aircraft's gimbal)
                result, output = await self._call(adapter, method, data)
                if result != 0:
                    return result, output
            changed = index not in auth.payloads
            auth.payloads.add(index)
        else:
            serving = self.devices.serving(method)
            if not serving:
                return ResultCode.METHOD_NOT_SUPPORTED, {"reason": "no aircraft on this gateway"}
            adapter = serving[0]
            result, output = await self._call(adapter, method, data)
            if result != 0:
                return result, output
            changed = adapter.info.sn not in auth.flight
            auth.flight.add(adapter.info.sn)
        if changed and self.on_authority_change is not None:
            self.on_authority_change()
        return ResultCode.SUCCESS, None

    async def _call(
        self, adapter: Adapter, method: str, data: InboundModel
    ) -> tuple[int, dict[str, Any] | None]:
        sn = adapter.info.sn
        logcontext.set_context(device=sn)
        if not adapter.online:
            return ResultCode.DEVICE_NOT_CONNECTED, {"reason": f"device {sn} is not connected"}
        try:
            deadline = min(adapter.deadline or self.settings.request_timeout, MAX_DEADLINE)
            outcome: CallResult = await self.clock.wait_for(adapter.call(method, data), deadline)
        except TimeoutError:
            self.metrics.inc("device_timeouts_total", device=sn)
            return ResultCode.DEVICE_TIMEOUT, {"reason": f"device {sn} did not answer in time"}
        except DeviceRejected as exc:
            return exc.result, {"reason": str(exc)[:300]}
        except DeviceNotConnected as exc:
            return ResultCode.DEVICE_NOT_CONNECTED, {"reason": str(exc)[:300]}
        except DeviceTimeout as exc:
            self.metrics.inc("device_timeouts_total", device=sn)
            return ResultCode.DEVICE_TIMEOUT, {"reason": str(exc)[:300]}
        except InvalidParameters as exc:
            return ResultCode.INVALID_PARAMETERS, {"reason": str(exc)[:300]}
        except MethodNotSupported as exc:
            return ResultCode.METHOD_NOT_SUPPORTED, {"reason": str(exc)[:300]}
        except DeviceError as exc:
            return ResultCode.BUSY, {"reason": str(exc)[:300]}
        except Exception:
            self.metrics.inc("handler_exceptions_total", where=f"adapter:{sn}")
            log.exception("adapter %s failed on %s", sn, method)
            return ResultCode.INTERNAL_ERROR, {"reason": "internal error in the device adapter"}
        output = dict(outcome.output) if outcome.output is not None else None
        return outcome.result, output

    # -- duplicate tid cache --------------------------------------------------------------------
    def _cache_lookup(self, tid: str) -> _Cached | None:
        now = self.clock.monotonic()
        while self._replies:
            oldest_tid, oldest = next(iter(self._replies.items()))
            if oldest.expires > now or oldest.payload is None:
                break
            del self._replies[oldest_tid]
        return self._replies.get(tid)

    def _cache_open(self, tid: str) -> _Cached:
        entry = _Cached(self.clock.monotonic() + self.settings.reply_cache_seconds, None, [])
        self._replies[tid] = entry
        while len(self._replies) > 10_000:
            self._replies.popitem(last=False)
        return entry

    def _publish_reply(
        self, raw: bytes, entry: _Cached | None, reply_to: Callable[[bytes], None] | None = None
    ) -> None:
        """Complete the cache entry and send the reply: to the broker, or to ``reply_to`` (a console call)."""
        if entry is not None:
            entry.payload = raw
            entry.expires = self.clock.monotonic() + self.settings.reply_cache_seconds
            for fut in entry.waiters:
                if not fut.done():
                    fut.set_result(raw)
            entry.waiters.clear()
        if reply_to is not None:
            reply_to(raw)
            return
        self.outbox.publish(topic(TopicKind.SERVICES_REPLY, self._answering()), raw, qos=1)

    def _answering(self) -> str:
        """The serial number a services reply goes out under: the topic's the request came on."""
        return _VIA.get() or self.gateway_sn

    def _reply_raw(
        self, payload: bytes, result: int, reason: str, reply_to: Callable[[bytes], None] | None = None
    ) -> bool:
        """Answer a message that could not be parsed, when tid, bid and method can still be read."""
        tid, bid, method = _peek(_TID, payload), _peek(_BID, payload), _peek(_METHOD, payload)
        if not (tid and bid and method):
            return False
        reply = ServicesReplyMessage(
            tid=tid,
            bid=bid,
            timestamp=self.clock.time_ms(),
            gateway=self._answering(),
            method=method,
            data=ResultReply(result=result, output=ErrorOutput(reason=reason)),
        )
        self._publish_reply(reply.model_dump_json().encode(), None, reply_to)
        return True

    # -- other kinds ----------------------------------------------------------------------------
    def _events_reply(self, payload: bytes) -> None:
        try:
            msg = self.registry.validate(TopicKind.EVENTS_REPLY, payload)
        except ValidationError as exc:
            self.metrics.inc("inbound_rejected_total", reason="events_reply")
            log.warning("ignored a malformed events_reply (%d problems)", exc.error_count())
            return
        if self.on_events_reply is not None:
            self.on_events_reply(msg.tid, msg.data.result)

    def _property_set(self, payload: bytes) -> None:
        try:
            msg = self.registry.validate(TopicKind.PROPERTY_SET, payload)
        except ValidationError as exc:
            reply = error_reply_from_validation(
                TopicKind.PROPERTY_SET, payload, exc, timestamp=self.clock.time_ms(), gateway=self.gateway_sn
            )
            if reply is not None:
                self.outbox.publish(
                    topic(TopicKind.PROPERTY_SET_REPLY, self.gateway_sn), reply.model_dump_json().encode()
                )
            return
        # The seed's only property, drc_state, is read-only; nothing here is writable yet.
        results = {name: int(ResultCode.INVALID_PARAMETERS) for name in msg.data}
        reply = property_set_reply(msg, results, timestamp=self.clock.time_ms(), gateway=self.gateway_sn)
        self.outbox.publish(
            topic(TopicKind.PROPERTY_SET_REPLY, self.gateway_sn), reply.model_dump_json().encode()
        )

    def _cloud_answer(self, kind: TopicKind, payload: bytes) -> None:
        try:
            msg = self.registry.validate(kind, payload)
        except ValidationError:
            self.metrics.inc("inbound_rejected_total", reason=kind.slug)
            return
        if msg.data.result != 0:
            log.warning("cloud answered %s %s with result %s", kind.value, msg.method, msg.data.result)
        if kind is TopicKind.REQUESTS_REPLY and self.on_requests_reply is not None:
            self.on_requests_reply(msg)


def _peek(pattern: re.Pattern[bytes], payload: bytes) -> str | None:
    m = pattern.search(payload[:4096])
    if m is None:
        return None
    try:
        return m.group(1).decode()
    except UnicodeDecodeError:
        return None


def _metric_method(method: str) -> str:
    # unknown methods come from the cloud: bound the label set
    return method if len(method) <= 64 and method.replace("_", "").isalnum() else "?"


def _result_of(reply: BaseModel | None) -> int:
    if reply is None:
        return int(ResultCode.INVALID_PARAMETERS)
    data = getattr(reply, "data", None)
    return int(getattr(data, "result", ResultCode.INVALID_PARAMETERS))


def _reason_of(reply: BaseModel) -> str:
    data = getattr(reply, "data", None)
    output = getattr(data, "output", None)
    return str(getattr(output, "reason", ""))
