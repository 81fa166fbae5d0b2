"""The composition root: the only place that builds adapters from settings (each through the family its
``type`` names in :mod:`adapters.families`; this module knows no family) and wires the broker connection,
the dispatcher, the northbound publisher, live control and the devices together: objects first, then the
typed callbacks between them.

Owns the service's life cycle: start devices (absent hardware is not an error: it comes online
later), connect to the broker, hand every received message to the dispatcher, publish telemetry,
and on stop: stop every motion first, then publish the clean offline topology, then disconnect.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Sequence

from adapters import families
from adapters.base import Adapter
from gateway import logcontext
from gateway.clock import SYSTEM_CLOCK, Clock
from gateway.cloud_control import CloudControl
from gateway.cloud_requests import CloudRequests
from gateway.devices import DeviceTable
from gateway.dispatcher import Dispatcher
from gateway.drc import DrcController
from gateway.farewell import left_doing
from gateway.metrics import Metrics
from gateway.mqtt import MqttBridge
from gateway.northbound import Northbound
from gateway.observability import Observability
from gateway.settings import GatewaySettings
from gateway.store import StateStore
from gateway.twins import TwinWatch
from gateway.video.service import LiveService
from gateway.wayline.service import WaylineService
from gateway.web.server import WebServer, bind_problem
from schemas import TopicKind, default_registry, subscriptions, topic
from schemas.registry import Registry

log = logging.getLogger(__name__)

__all__ = ["GatewayApp", "build_adapters", "build_registry"]


def build_adapters(settings: GatewaySettings, clock: Clock = SYSTEM_CLOCK) -> list[Adapter]:
    """One adapter per ``[[devices]]`` entry, built by the family its ``type`` names, on ``clock``."""
    return [families.get(device.type).build(device, clock) for device in settings.devices]


def build_registry() -> Registry:
    """The seed's methods plus every registered device family's extension methods (the documented
    contract; a method whose device is not configured is answered 399001)."""
    registry = default_registry()
    for family in families.all_families():
        for method, data, reply, summary in family.service_extensions():
            registry.register(TopicKind.SERVICES, method, data, reply, summary=summary)
    for family in families.all_families():
        for method, data, reply, summary in family.event_extensions():
            registry.register(TopicKind.EVENTS, method, data, reply, summary=summary)
    return registry


class GatewayApp:
    def __init__(
        self,
        settings: GatewaySettings,
        *,
        adapters: Sequence[Adapter] | None = None,
        clock: Clock | None = None,
        metrics: Metrics | None = None,
    ) -> None:
        self.settings = settings
        #: the one clock: the dispatcher, the northbound, live control, every adapter built here, the
        #: broker connection and the web console keep time on it (a test passes a ManualClock)
        self.clock: Clock = clock or SYSTEM_CLOCK
        self.metrics = metrics or Metrics()
        logcontext.register_secrets_in(settings)  # broker password, device secrets: masked in every log line
        self.registry = build_registry()
        self.devices = DeviceTable(adapters if adapters is not None else build_adapters(settings, self.clock))
        self.stop_event = asyncio.Event()
        self.started = asyncio.Event()
        self.bridge: MqttBridge | None = None
        self.dispatcher: Dispatcher | None = None
        self.northbound: Northbound | None = None
        self.drc: DrcController | None = None
        self.wayline: WaylineService | None = None  # flighttask_* / return_home* (gateway/wayline)
        self.cloud_control: CloudControl | None = None  # cloud_control_auth_request / _release
        self.store: StateStore | None = None  # what must outlive the process (gateway/store.py)
        self.live: LiveService | None = None  # live_* and the ffmpeg pipelines (gateway/video)
        self._background: set[asyncio.Task[None]] = set()  # fire-and-forget work kept referenced
        self.observability: Observability | None = None  # /metrics, /healthz, /status, / (None: off)
        self.web: WebServer | None = None  # the aiohttp server (its own thread) that serves them
        #: what ``dji-gateway run`` exits with: 2 when the HTTP endpoint could not be bound
        self.exit_code = 0
        #: another gateway publishing under this one's serial number (gateway/twins.py)
        self.twins = TwinWatch()
        self.own_osd = ""
        self._twin_logged = float("-inf")
        #: told (topic, payload) of every message the northbound and the dispatcher publish, and of every
        #: message the dispatcher is handed (not drc/down, answered inline): the web console's log
        self.published: list[Callable[[str, bytes], None]] = []
        self.received: list[Callable[[str, bytes], None]] = []

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        s = self.settings
        gw = s.gateway_sn
        subs = [(name, 1) for name in subscriptions(gw)]
        # a device announced as its own gateway (docs/cloud-api.md "Device tree") takes services on its own
        # topic too: a cloud that reads it as a gateway sends them there
        own = [a.info.sn for a in self.devices if a.info.announce == "gateway"]
        subs += [(topic(TopicKind.SERVICES, sn), 1) for sn in own]
        # and its own osd topic, at QoS 0: an osd there that this gateway did not send is another gateway's
        # with the same serial number (gateway/twins.py)
        self.own_osd = topic(TopicKind.OSD, gw)
        subs += [(self.own_osd, 0)]
        # build the objects, then connect them with typed callbacks (as paho's are assigned)
        bridge = self.bridge = MqttBridge(
            s.broker.for_live_control(s.drc.heartbeat_timeout),
            client_id=s.broker.client_id or f"djigw-{gw}",
            subscriptions=subs,
            loop=loop,
            metrics=self.metrics,
            clock=self.clock,
            buffered=lambda name: name.endswith("/osd"),  # osd waits out an outage (bounded), in order
        )
        outbox = _ObservedOutbox(bridge, self.published, self.own_osd, self.twins)
        nb = self.northbound = Northbound(
            settings=s,
            registry=self.registry,
            devices=self.devices,
            outbox=outbox,
            clock=self.clock,
            metrics=self.metrics,
        )
        drc = self.drc = DrcController(
            settings=s,
            registry=self.registry,
            devices=self.devices,
            metrics=self.metrics,
            loop=loop,
            main_bridge=bridge,
            publish_event=lambda method, data, need_reply: nb.event(gw, method, data, need_reply),
            publish_gateway_osd=nb.gateway_osd,
            clock=self.clock,
        )
        bridge.on_connected = nb.on_connected
        bridge.inline = drc.inline_main
        bridge.on_disconnected = drc.main_link_lost
        nb.gateway_osd_data = drc.osd_data
        nb.on_authority_lost = lambda sn: drc.refresh_targets()
        drc.start()
        requests = CloudRequests(gateway_sn=gw, registry=self.registry, outbox=outbox, clock=self.clock,
                                 metrics=self.metrics)  # fmt: skip
        store = self.store = StateStore(s.state_dir, now_ms=self.clock.time_ms)
        for adapter in self.devices:
            adapter.journal = store  # the task a device starts outlives this process
        if s.state_dir is None:
            log.info("no state_dir: wayline tasks in flight are kept in memory only (not across a restart)")
        else:
            log.info("state kept in %s", store.path)
        wayline = self.wayline = WaylineService(
            gateway_sn=gw,
            devices=self.devices,
            event=nb.event,
            requests=requests,
            clock=self.clock,
            metrics=self.metrics,
            store=store,
            strict_actions=s.wayline.strict_actions,
        )
        cloud_control = self.cloud_control = CloudControl(
            settings=s.cloud_control,
            clock=self.clock,
            publish_event=lambda method, data, need_reply, bid: nb.event(
                gw, method, data, need_reply, bid=bid
            ),
            metrics=self.metrics,
            on_change=lambda: self._cloud_control_changed(loop),
        )
        drc.cloud_control = cloud_control.auth
        live = self.live = LiveService(
            settings=s.video, devices=self.devices, clock=self.clock, metrics=self.metrics,
            publish_state=nb.gateway_state,
        )  # fmt: skip
        nb.gateway_state_data = live.state
        # the will and the clean goodbye have one shape: a topology with no sub-devices (all offline); the
        # will is fixed at connect (MQTT), so the clean stop builds a fresh one (_shutdown)
        offline = (topic(TopicKind.STATUS, gw), nb.topology(offline=True))
        bridge.set_will(*offline)
        self.dispatcher = Dispatcher(
            gateway_sn=gw,
            own_gateways=frozenset(own),
            registry=self.registry,
            devices=self.devices,
            outbox=outbox,
            settings=s.dispatcher,
            clock=self.clock,
            metrics=self.metrics,
            on_authority_change=self._authority_changed,
            on_events_reply=nb.events_reply,
            drc=drc,
            wayline=wayline,
            on_requests_reply=requests.answer,
            cloud_control=cloud_control,
            journal=store,  # replies outlive the process: a tid resent after a restart is not acted on again
            live=live,
        )
        self.drc.call_service = self.dispatcher.call_local  # drc_gimbal_reset runs as gimbal_reset
        for adapter in self.devices:
            await adapter.start(nb)
        bridge.start()
        periodic = loop.create_task(nb.run(self.stop_event), name="northbound")
        waylines = loop.create_task(wayline.run(self.stop_event), name="wayline")
        streams = loop.create_task(live.run(self.stop_event), name="live")
        consumer = loop.create_task(self._consume(), name="inbound")
        if s.metrics.enabled:
            self._serve_web(Observability(self, loop, clock=self.clock), loop)
        self.started.set()
        log.info("gateway %s running with %d device(s)", gw, len(self.devices))
        try:
            await self.stop_event.wait()
        finally:
            await self._shutdown(periodic, consumer, offline)
            await waylines  # ends with stop_event
            await streams

    def _cloud_control_changed(self, loop: asyncio.AbstractEventLoop) -> None:
        """The cloud-control grant changed hands or ended: live control re-checks its session; a new
        holder gets the aircraft's flight authority (the grant is the RC's hand-over: no grab follows)."""
        assert self.drc is not None and self.cloud_control is not None
        self.drc.cloud_control_changed()
        holder = self.cloud_control.auth.holder
        if holder is not None and self.dispatcher is not None:
            task = loop.create_task(self.dispatcher.grant_flight(f"cloud control granted to {holder!r}"))
            self._background.add(task)
            task.add_done_callback(self._background.discard)

    def _serve_web(self, observability: Observability, loop: asyncio.AbstractEventLoop) -> None:
        """Serve the views (``/metrics``, ``/healthz``, ``/status``, the console unless disabled) on the
        metrics port; on the gateway's loop. A port that cannot be bound stops the gateway (exit code 2,
        the port and the setting named): an address printed for it would be answered by whatever holds
        it, another gateway's console or status (issue #35). ``dji-gateway run`` tries the port before
        anything starts; this is the race after that check."""
        s = self.settings
        server = WebServer(observability, s.console, loop)
        web = server.start(s.metrics.host, s.metrics.port)
        if web is not None:
            observability.port = web.port
            self.observability, self.web = observability, web
            return
        log.error("%s", bind_problem(s.metrics.host, s.metrics.port, server.bind_error or "no answer"))
        self.exit_code = 2
        self.stop_event.set()

    def stop(self) -> None:
        self.stop_event.set()

    def _authority_changed(self) -> None:
        if self.drc is not None:
            self.drc.refresh_targets()
        if self.northbound is None:
            return
        for adapter in self.devices:
            if adapter.online:
                self.northbound.publish_state(adapter)

    async def _consume(self) -> None:
        assert self.bridge is not None and self.dispatcher is not None
        queue = self.bridge.queue
        while True:
            item = await queue.get()
            if item.topic == self.own_osd:  # our own osd coming back, or another gateway's with our SN
                self._own_osd_heard(item.payload)
                continue
            for observer in self.received:
                _tell(observer, item.topic, item.payload)
            self.dispatcher.submit(item.topic, item.payload, item.oversize)

    def _own_osd_heard(self, payload: bytes) -> None:
        now = self.clock.monotonic()
        if not self.twins.heard(payload, now):
            return
        self.metrics.inc("gateway_sn_conflicts_total")
        if now - self._twin_logged >= 60.0:  # once a minute while it lasts
            self._twin_logged = now
            log.warning(
                "another gateway publishes as %s on this broker (an osd under this serial number that this "
                "gateway did not send; %d so far): a cloud takes the two for one. Give each gateway its own "
                "gateway_sn",
                self.settings.gateway_sn,
                self.twins.count,
            )

    async def _shutdown(
        self, periodic: asyncio.Task[None], consumer: asyncio.Task[None], offline: tuple[str, bytes]
    ) -> None:
        log.info("stopping: halting every motion first")
        if self.drc is not None:
            try:
                await self.drc.shutdown()
            except Exception:
                self.metrics.inc("drc_stop_failures_total", reason="shutdown", device="-")
                log.exception("stopping live control failed; stopping every device directly")
        await asyncio.gather(*(a.stop_motion() for a in self.devices), return_exceptions=True)
        if self.wayline is not None:
            await self.wayline.stop()
        if self.live is not None:  # every pipeline ends (its stream closes) before the goodbye
            await self.live.shutdown()
        if self.cloud_control is not None:
            self.cloud_control.stop()
        for adapter in self.devices:  # what the operator who pressed Ctrl-C needs to know
            log.info("%s", left_doing(adapter))
        consumer.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await consumer
        await periodic
        if self.dispatcher is not None:
            with contextlib.suppress(TimeoutError):
                # real time: a stopping gateway stops even when nobody advances a test's clock
                await asyncio.wait_for(self.dispatcher.drain(), 2.0)
        if self.bridge is not None:
            if self.northbound is not None:
                # a fresh goodbye: the will was fixed at connect (its tid and timestamp are the connect's);
                # a clean stop tells the time it went offline (issue #38)
                offline = (offline[0], self.northbound.topology(offline=True))
                self.northbound.publish_own_offline()  # queued before the goodbye, delivered in order
            await asyncio.to_thread(self.bridge.stop, offline)
        await asyncio.gather(*(a.stop() for a in self.devices), return_exceptions=True)
        if self.web is not None:
            await asyncio.to_thread(self.web.stop)
        if self.store is not None:
            self.store.close()
        log.info("stopped")


def _tell(observer: Callable[[str, bytes], None], topic_name: str, payload: bytes) -> None:
    try:
        observer(topic_name, payload)
    except Exception:  # an observer's bug must not stop the bridge
        log.exception("a message observer failed")


class _ObservedOutbox:
    """The broker connection as the northbound and the dispatcher publish to it, telling ``observers``
    (the web console's log) what went out, after it was handed to the bridge."""

    def __init__(
        self,
        bridge: MqttBridge,
        observers: list[Callable[[str, bytes], None]],
        own_osd: str = "",
        twins: TwinWatch | None = None,
    ) -> None:
        self._bridge = bridge
        self._observers = observers
        self._own_osd = own_osd
        self._twins = twins

    def publish(self, topic: str, payload: bytes, qos: int = 1, retain: bool = False) -> bool:
        if self._twins is not None and topic == self._own_osd:
            self._twins.sent(payload)  # before the broker can echo it back
        ok = self._bridge.publish(topic, payload, qos, retain)
        for observer in self._observers:
            _tell(observer, topic, payload)
        return ok
