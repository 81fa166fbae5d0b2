"""Everything the gateway publishes on its own initiative: topology, state, periodic osd, events.

Owns the Cloud API shape of device reports (validated against the contract before they leave, so
an adapter bug cannot put an undefined field on the wire), the osd schedule (0.5 Hz by default, per
device override), ``update_topo`` on every (re)connect and on every online/offline change, and
the re-sending of events that asked for an ``events_reply``. Implements the adapters'
:class:`~adapters.base.TelemetrySink`. Knows nothing about bytes or paho.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import secrets
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from pydantic import ValidationError

from adapters.base import Adapter, DeviceInfo, Domain
from gateway.clock import Clock
from gateway.devices import DeviceTable
from gateway.dispatcher import Outbox
from gateway.metrics import Metrics
from gateway.settings import GatewaySettings
from schemas import Profile, TopicKind, topic
from schemas.registry import Registry

log = logging.getLogger(__name__)

__all__ = ["Northbound", "profile_of"]


def profile_of(adapter: Adapter) -> Profile:
    """The osd/state body a device publishes, from its Cloud API domain and family."""
    if adapter.info.domain == Domain.AIRCRAFT:
        return Profile.AIRCRAFT
    if adapter.info.domain == Domain.PAYLOAD:
        return Profile.GIMBAL
    return Profile.ROBOT


@dataclass
class _PendingEvent:
    topic: str
    payload: bytes
    attempts_left: int
    next_at: float


class Northbound:
    def __init__(
        self,
        *,
        settings: GatewaySettings,
        registry: Registry,
        devices: DeviceTable,
        outbox: Outbox,
        clock: Clock,
        metrics: Metrics,
    ) -> None:
        self.settings = settings
        self.gateway_sn = settings.gateway_sn
        self.registry = registry
        self.devices = devices
        self.outbox = outbox
        self.clock = clock
        self.metrics = metrics
        self._events: dict[str, _PendingEvent] = {}
        self._rng = random.Random(secrets.randbits(64))
        self._next_osd: dict[str, float] = {}
        #: the gateway's own osd body (drc_state, the live-control failsafe); set by the app
        self.gateway_osd_data: Callable[[], dict[str, Any]] = lambda: {"drc_state": 0}
        #: the gateway's state body on every (re)connect (live_capacity, live_status); None: nothing
        self.gateway_state_data: Callable[[], dict[str, Any]] | None = None
        #: called when a device takes flight authority back (the app hands it to live control)
        self.on_authority_lost: Callable[[str], None] | None = None
        self._next_gateway_osd = 0.0
        self._osd_period = {d.sn: (d.osd_period or settings.osd_period) for d in settings.devices}

    # -- envelopes --------------------------------------------------------------------------------
    def _ids(self) -> dict[str, Any]:
        # random v4 UUIDs from a seeded PRNG: uuid4() reads os.urandom, a system call per id, which
        # showed up first in a profile of 200 devices at 10 Hz; these ids need uniqueness, not secrecy
        rng = self._rng
        return {
            "tid": str(uuid.UUID(int=rng.getrandbits(128), version=4)),
            "bid": str(uuid.UUID(int=rng.getrandbits(128), version=4)),
            "timestamp": self.clock.time_ms(),
        }

    def _telemetry(self, kind: TopicKind, adapter: Adapter, data: Mapping[str, Any]) -> bytes | None:
        cls = self.registry.telemetry_class(kind, profile_of(adapter))
        try:
            msg = cls.model_validate({**self._ids(), "gateway": self.gateway_sn, "data": dict(data)})
        except ValidationError as exc:
            self.metrics.inc("outbound_invalid_total", kind=kind.slug)
            log.error("dropped an invalid %s from %s: %s", kind.value, adapter.info.sn, exc.errors()[:2])
            return None
        return msg.model_dump_json().encode()

    # -- TelemetrySink ----------------------------------------------------------------------------
    def osd(self, sn: str, data: Mapping[str, Any]) -> None:
        adapter = self.devices.by_sn(sn)
        if adapter is None or adapter.info.carried_by is not None:
            return  # a carried payload's values travel inside its aircraft's osd (below)
        if adapter.info.domain == Domain.AIRCRAFT:
            data = {**data, **self._carried_osd(sn)}
        raw = self._telemetry(TopicKind.OSD, adapter, data)
        if raw is not None:
            self.outbox.publish(topic(TopicKind.OSD, sn), raw, qos=0)
            self.metrics.inc("osd_published_total", device=sn)

    def _carried_osd(self, aircraft_sn: str) -> dict[str, Any]:
        """``{payload_index: {payload_index, gimbal_pitch, gimbal_roll, gimbal_yaw}}`` of the payloads the
        aircraft carries: DJI reports an aircraft's gimbals this way (AircraftOsd's payload keys)."""
        out: dict[str, Any] = {}
        for payload in self.carried(aircraft_sn):
            index = payload.info.payload_index
            body = payload.osd_snapshot() or {}
            if index is None:
                continue
            angles = {k: body[k] for k in ("gimbal_pitch", "gimbal_roll", "gimbal_yaw") if k in body}
            out[index] = {"payload_index": index, **angles}
        return out

    def state(self, sn: str, data: Mapping[str, Any]) -> None:
        adapter = self.devices.by_sn(sn)
        if adapter is None:
            return
        raw = self._telemetry(TopicKind.STATE, adapter, data)
        if raw is not None:
            self.outbox.publish(topic(TopicKind.STATE, sn), raw, qos=1)

    def event(
        self,
        sn: str,
        method: str,
        data: Mapping[str, Any],
        need_reply: bool = False,
        *,
        bid: str | None = None,
    ) -> None:
        """Publish one event (``bid``: the business id, e.g. a wayline's flight_id; else a fresh one)."""
        ids = self._ids()
        if bid is not None:
            ids["bid"] = bid
        try:
            msg = self.registry.build(
                TopicKind.EVENTS,
                method,
                dict(data),
                gateway=self.gateway_sn,
                need_reply=1 if need_reply else 0,
                **ids,
            )
        except (ValidationError, KeyError) as exc:
            self.metrics.inc("outbound_invalid_total", kind="events")
            log.error("dropped an invalid %s event from %s: %s", method, sn, exc)
            return
        raw = msg.model_dump_json().encode()
        name = topic(TopicKind.EVENTS, self.gateway_sn)
        self.outbox.publish(name, raw, qos=1)
        self.metrics.inc("events_published_total", method=method)
        if need_reply and self.settings.dispatcher.event_retries > 0:
            interval = self.settings.dispatcher.event_retry_interval
            self._events[ids["tid"]] = _PendingEvent(
                name, raw, self.settings.dispatcher.event_retries, self.clock.monotonic() + interval
            )

    def gateway_osd(self, data: Mapping[str, Any]) -> None:
        """The gateway's own osd (``drc_state``), under the gateway's serial number."""
        cls = self.registry.telemetry_class(TopicKind.OSD, Profile.GATEWAY)
        try:
            msg = cls.model_validate({**self._ids(), "gateway": self.gateway_sn, "data": dict(data)})
        except ValidationError as exc:
            self.metrics.inc("outbound_invalid_total", kind="osd")
            log.error("dropped an invalid gateway osd: %s", exc.errors()[:2])
            return
        self.outbox.publish(topic(TopicKind.OSD, self.gateway_sn), msg.model_dump_json().encode(), qos=0)

    def gateway_state(self, data: Mapping[str, Any]) -> None:
        """The gateway's own state (``live_capacity``, ``live_status``), under the gateway's serial number."""
        if not data:
            return
        cls = self.registry.telemetry_class(TopicKind.STATE, Profile.GATEWAY)
        try:
            msg = cls.model_validate({**self._ids(), "gateway": self.gateway_sn, "data": dict(data)})
        except ValidationError as exc:
            self.metrics.inc("outbound_invalid_total", kind="state")
            log.error("dropped an invalid gateway state: %s", exc.errors()[:2])
            return
        self.outbox.publish(topic(TopicKind.STATE, self.gateway_sn), msg.model_dump_json().encode(), qos=1)

    def online_changed(self, sn: str, online: bool) -> None:
        self.metrics.set("device_online", 1 if online else 0, device=sn)
        log.info("device %s is %s", sn, "online" if online else "offline")
        self.publish_topology()
        adapter = self.devices.by_sn(sn)
        if adapter is not None and adapter.info.carried_by is not None:
            carrier = self.devices.by_sn(adapter.info.carried_by)
            if carrier is not None and carrier.online:  # its payloads list gains or loses this one
                self.publish_state(carrier)
        elif online and adapter is not None:  # what it is (firmware, authority) as soon as it is there
            self.publish_state(adapter)

    def authority_lost(self, sn: str, *, requested: bool = False) -> None:
        auth = self.devices.authority
        if sn in auth.flight:
            auth.flight.discard(sn)
            if requested:
                log.info("device %s: flight authority released, as the cloud asked", sn)
            else:
                log.warning("device %s took flight authority back", sn)
            adapter = self.devices.by_sn(sn)
            if adapter is not None:
                self.publish_state(adapter)
            if self.on_authority_lost is not None:
                self.on_authority_lost(sn)

    # -- events_reply -----------------------------------------------------------------------------
    def events_reply(self, tid: str, result: int) -> None:
        if self._events.pop(tid, None) is not None and result != 0:
            log.warning("cloud answered event %s with result %s", tid, result)

    def retry_events(self) -> None:
        now = self.clock.monotonic()
        interval = self.settings.dispatcher.event_retry_interval
        for tid, ev in list(self._events.items()):
            if now < ev.next_at:
                continue
            if ev.attempts_left <= 0:
                del self._events[tid]
                self.metrics.inc("events_unanswered_total")
                log.warning("event %s was never answered", tid)
                continue
            ev.attempts_left -= 1
            ev.next_at = now + interval
            self.outbox.publish(ev.topic, ev.payload, qos=1)
            self.metrics.inc("events_resent_total")

    # -- topology and state -----------------------------------------------------------------------
    def _sub_device(self, i: int, info: DeviceInfo) -> dict[str, Any]:
        return {
            "sn": info.sn,
            "domain": info.domain,
            "type": info.type,
            "sub_type": info.sub_type,
            "index": channel_index(i),
            "device_secret": _device_secret(self.settings, info.sn),
            "nonce": secrets.token_hex(8),
            "thing_version": info.thing_version,
        }

    def _update_topo(self, sn: str, head: dict[str, Any], subs: list[dict[str, Any]]) -> bytes:
        body = {**head, "nonce": secrets.token_hex(8), "sub_devices": subs}
        msg = self.registry.build(TopicKind.STATUS, "update_topo", body, gateway=sn, **self._ids())
        return msg.model_dump_json(context={"reveal_secrets": True}).encode()

    def topology(self, *, offline: bool = False) -> bytes:
        """``update_topo`` with the online devices this gateway lists (none when ``offline``: the gateway is
        leaving). Not listed: a payload carried by an aircraft (reported inside its osd/state) and a device
        announced as its own gateway (:meth:`own_topology`); docs/cloud-api.md "Device tree"."""
        p = self.settings.product
        secret = p.device_secret.get_secret_value() if p.device_secret else ""
        subs = []
        if not offline:
            for i, adapter in enumerate(self.devices):
                info = adapter.info
                if adapter.online and info.announce == "sub_device" and info.carried_by is None:
                    subs.append(self._sub_device(i, info))
            # aircraft first: DJI's reference cloud reads only ``sub_devices[0]`` (a DJI gateway carries one
            # aircraft); each keeps the channel index of its place in the settings
            subs.sort(key=lambda d: d["domain"] != Domain.AIRCRAFT)
        head = {
            "domain": p.domain,
            "type": p.type,
            "sub_type": p.sub_type,
            "device_secret": secret,
            "thing_version": p.thing_version,
        }
        return self._update_topo(self.gateway_sn, head, subs)

    def own_gateways(self) -> list[Adapter]:
        """The devices announced as gateways of their own (``product.announce = "gateway"``)."""
        return [a for a in self.devices if a.info.announce == "gateway"]

    def own_topology(self, adapter: Adapter, *, offline: bool = False) -> tuple[str, bytes]:
        """A device that is its own gateway: ``update_topo`` on ``sys/product/{its sn}/status`` with its own
        product fields, listing itself while it is online (channel "A") and nothing once it is not; so its
        online state travels the way a sub-device's does, and the dock's ``update_topo`` holds only what
        DJI's model knows (docs/cloud-api.md "Device tree")."""
        info = adapter.info
        head = {
            "domain": info.domain,
            "type": info.type,
            "sub_type": info.sub_type,
            "device_secret": _device_secret(self.settings, info.sn),
            "thing_version": info.thing_version,
        }
        subs = [self._sub_device(0, info)] if adapter.online and not offline else []
        return topic(TopicKind.STATUS, info.sn), self._update_topo(info.sn, head, subs)

    def publish_topology(self) -> None:
        """Called from device callbacks: a topology that cannot be built is logged, never raised into them."""
        try:
            messages = [(topic(TopicKind.STATUS, self.gateway_sn), self.topology())]
            messages += [self.own_topology(a) for a in self.own_gateways()]
        except ValidationError as exc:
            self.metrics.inc("outbound_invalid_total", kind="status")
            log.error("dropped an invalid update_topo: %s", exc.errors()[:2])
            return
        for name, raw in messages:
            self.outbox.publish(name, raw, qos=1)
            self.metrics.inc("topology_published_total")

    def publish_own_offline(self) -> None:
        """A clean stop: every device announced as its own gateway is offline too (the MQTT will covers
        only the gateway's own topic)."""
        for adapter in self.own_gateways():
            try:
                name, raw = self.own_topology(adapter, offline=True)
            except ValidationError as exc:
                log.error("dropped an invalid update_topo: %s", exc.errors()[:2])
                continue
            self.outbox.publish(name, raw, qos=1)

    def carried(self, aircraft_sn: str) -> list[Adapter]:
        """The online payloads an aircraft carries (``carried_by``), reported inside its osd and state."""
        return [a for a in self.devices if a.info.carried_by == aircraft_sn and a.online]

    def publish_state(self, adapter: Adapter) -> None:
        if adapter.info.carried_by is not None:  # its state is a line of its aircraft's payloads list
            carrier = self.devices.by_sn(adapter.info.carried_by)
            if carrier is not None and carrier.online:
                self.publish_state(carrier)
            return
        body = dict(adapter.state_snapshot() or {})
        if profile_of(adapter) in (Profile.GIMBAL, Profile.AIRCRAFT):
            auth = self.devices.authority
            payloads = [adapter] if adapter.info.payload_index else []
            if profile_of(adapter) is Profile.AIRCRAFT:
                payloads += self.carried(adapter.info.sn)
            if payloads:
                body["payloads"] = [
                    {
                        "control_source": "A" if p.info.payload_index in auth.payloads else "",
                        "payload_index": p.info.payload_index,
                        "sn": p.info.sn,
                    }
                    for p in payloads
                ]
            if profile_of(adapter) is Profile.AIRCRAFT:
                body.setdefault("control_source", "A" if adapter.info.sn in auth.flight else "")
        if body:
            self.state(adapter.info.sn, body)

    def on_connected(self) -> None:
        """After every (re)connect: topology first, then state, then osd (cloud stacks drop
        telemetry from gateways they have not registered)."""
        self.publish_topology()
        for adapter in self.devices:
            if adapter.online and adapter.info.carried_by is None:
                self.publish_state(adapter)
        if self.gateway_state_data is not None:  # live_capacity / live_status (gateway/video)
            self.gateway_state(self.gateway_state_data())
        self._next_osd.clear()

    def publish_due_osd(self) -> None:
        """Fixed-rate osd per device; devices are spread over their period (not all at one instant), so
        hundreds of devices make a steady trickle of small bursts rather than one big one per period."""
        now = self.clock.monotonic()
        if now >= self._next_gateway_osd:
            self._next_gateway_osd = now + self.settings.osd_period
            self.gateway_osd(self.gateway_osd_data())
        count = len(self.devices)
        for i, adapter in enumerate(self.devices):
            sn = adapter.info.sn
            period = self._osd_period.get(sn, self.settings.osd_period)
            due = self._next_osd.get(sn)
            if due is None:  # first time, or after a reconnect: the device's phase in the period
                due = self._next_osd[sn] = now + period * i / count
            if not adapter.online or now < due or adapter.info.carried_by is not None:
                continue
            due += period
            self._next_osd[sn] = due if due > now else now + period  # fell behind: skip, never burst
            body = adapter.osd_snapshot()
            if body:
                self.osd(sn, body)

    def tick_interval(self) -> float:
        """How often :meth:`run` looks at the schedule: 50 ms, finer when an osd period is short."""
        periods = [*self._osd_period.values(), self.settings.osd_period]
        return max(0.01, min(0.05, min(periods) / 5))

    async def run(self, stop: asyncio.Event) -> None:
        """The periodic part: the osd schedule and event re-sends."""
        tick = self.tick_interval()
        while not stop.is_set():
            try:
                self.publish_due_osd()
                self.retry_events()
            except Exception:
                self.metrics.inc("handler_exceptions_total", where="northbound")
                log.exception("periodic publishing failed")
            with contextlib.suppress(TimeoutError):
                await self.clock.wait_for(stop.wait(), tick)


def channel_index(i: int) -> str:
    """The sub-device's channel letter: A … Z, then AA, AB … (spreadsheet columns), unique per device."""
    out = ""
    i += 1
    while i:
        i, r = divmod(i - 1, 26)
        out = chr(ord("A") + r) + out
    return out


def _device_secret(settings: GatewaySettings, sn: str) -> str:
    for d in settings.devices:
        if d.sn == sn and d.product.device_secret is not None:
            secret: str = d.product.device_secret.get_secret_value()
            return secret
    return ""
