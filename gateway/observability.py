"""The gateway's HTTP window for operators: ``/metrics`` (Prometheus), ``/healthz`` and ``/status`` (JSON).

Owns the translation of :class:`gateway.metrics.Metrics` (counters, gauges, histograms that every layer
fills without knowing Prometheus) and of the live objects (devices, their links, the DRC session, the
broker connection) into Prometheus families and one JSON document. They are served on
``metrics.host:metrics.port`` (127.0.0.1:9108 by default) by the same aiohttp server as the web console
(:mod:`gateway.web.server`, on a thread and loop of its own), which the composition root
(:mod:`gateway.app`) starts with these views: the web package reads this module, never the reverse.

Every request reads the gateway through one :meth:`Observability.snapshot`, taken **on the event loop**
(with a deadline): a loop that cannot answer within :data:`LOOP_DEADLINE` makes ``/healthz`` fail, which
is exactly what a container health check or a supervisor should notice. Link statistics come from the
adapters' contract (:meth:`adapters.base.Adapter.link_stats`, implemented once by the supervisor for
every linked family); counters that restart with a new decoder are kept monotonic here.
Never exposes a secret: the broker URL is reduced to scheme, host and port; settings are not served.
Knows nothing of paho, bytes or Cloud API methods.
"""

from __future__ import annotations

import concurrent.futures
import importlib.metadata
import logging
import threading
from collections.abc import Iterator
from dataclasses import asdict
from typing import TYPE_CHECKING, Any
from urllib.parse import urlsplit

from prometheus_client import CollectorRegistry
from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
)
from prometheus_client.registry import Collector

from adapters.base import LinkStats
from gateway.clock import SYSTEM_CLOCK, Clock

if TYPE_CHECKING:  # read through the app, never built here
    from gateway.drc import DrcController

log = logging.getLogger(__name__)

__all__ = ["LOOP_DEADLINE", "PREFIX", "VERSION", "LinkStats", "Observability", "safe_url"]

PREFIX = "djigw_"
#: How long the event loop may take to hand over a snapshot before the gateway counts as unhealthy.
LOOP_DEADLINE = 2.0

#: HELP text of every metric the gateway counts today; a metric counted elsewhere but missing here is
#: still exported (with a generic help), so a new counter never needs this table to be seen.
HELP: dict[str, str] = {
    "services_total": "Cloud API services answered, by method and result code",
    "services_latency_seconds": "Time from a valid services request to its reply, by method",
    "services_duplicates_total": "Services requests with an already seen tid (answered from the cache)",
    "device_timeouts_total": "Device requests that missed their deadline (325004)",
    "inbound_rejected_total": "Inbound MQTT messages refused before dispatch, by reason",
    "handler_exceptions_total": "Unexpected exceptions caught (answered 599001 or logged), by where",
    "mqtt_connects_total": "Successful broker connections (the first and every reconnect), by link",
    "mqtt_disconnects_total": "Unexpected broker disconnections, by link",
    "mqtt_connect_failures_total": "Broker connection attempts that failed, by link",
    "mqtt_connect_refused_total": "Broker connections refused (bad credentials, not authorised), by link",
    "mqtt_takeovers_total": "Connections taken over by another client with our client id, by link",
    "mqtt_client_id_conflict": "1 while another client seems to use our client id (see the ERROR log)",
    "mqtt_stalls_total": "Connections whose data TCP kept retransmitting (path down), by link",
    "mqtt_deaf_total": "Links found deaf (subscribed, but the liveness probe did not come back), by link",
    "mqtt_deaf": "1 while a link is deaf (its liveness probe has not come back), by link",
    "mqtt_resubscribes_total": "Subscriptions made again because a liveness probe did not come back, by link",
    "telemetry_buffered": "osd messages held while the broker is unreachable, by link",
    "telemetry_dropped_total": "Buffered osd dropped (the oldest first), by reason: overflow or age",
    "telemetry_delivered_late_total": "Buffered osd delivered after the broker came back, by link",
    "telemetry_requeued_total": "osd written to a connection given up after its last ACK, buffered again",
    "mqtt_subscribe_refused_total": "Subscriptions the broker refused (ACL), by link",
    "gateway_sn_conflicts_total": "osd under this gateway's serial number that it did not send (another "
    "gateway with its gateway_sn on the broker)",
    "mqtt_messages_in_total": "MQTT messages received, by link",
    "mqtt_messages_out_total": "MQTT messages published, by link",
    "mqtt_publish_errors_total": "MQTT publishes paho could not queue, by link",
    "mqtt_inbound_dropped_total": "Received messages dropped because the inbound queue was full, by link",
    "mqtt_connected": "1 while connected to the broker, by link",
    "osd_published_total": "osd messages published, by device",
    "live_starts_total": "live_start_push requests that started a pipeline, by video",
    "live_failures_total": "live pipelines that failed after streaming (then retried), by video",
    "live_streaming": "1 while a live video streams (frames flow), by video",
    "events_published_total": "events published, by method",
    "events_resent_total": "events re-sent because no events_reply came",
    "events_unanswered_total": "events given up after every re-send",
    "outbound_invalid_total": "outbound bodies dropped because they broke the contract, by kind",
    "topology_published_total": "update_topo messages published",
    "drc_sessions_total": "Live flight control (DRC) sessions entered",
    "drc_heartbeats_total": "DRC heart_beat messages echoed",
    "drc_sticks_total": "DRC drone_control and stick_control set-points accepted",
    "drc_rejected_total": "DRC messages refused, by reason",
    "drc_failsafe_stops_total": "Motion stopped by a DRC failsafe, by reason "
    "(sticks, heartbeat, link_lost, emergency_stop, authority)",
    "drc_stop_failures_total": "Stop frames (zero set-point, emergency stop) a device could not be sent, "
    "by device and reason",
    "drc_drive_failures_total": "Live-control frames a device could not be sent, by device and reason",
    "services_stops_obeyed_total": "Stop services obeyed although their data could not be parsed, by method",
    "requests_published_total": "Requests to the cloud published (flighttask_resource_get), by method",
    "requests_unanswered_total": "Requests to the cloud given up after every re-send, by method",
    "wayline_tasks_total": "Wayline tasks ended, by status (ok, failed, canceled, timeout)",
    "cloud_control_decisions_total": "cloud_control_auth_notify sent, by status and why (allow-list, "
    "holder, operator, timeout, replaced)",
}
#: Per-link counters (``djigw_link_<name>_total{device, kind}``), read from the links and decoders.
_LINK_COUNTERS = {
    "opens": "Link opens: the first and every reconnect",
    "frames_in": "Frames received (CAN frames on CAN links, protocol frames on serial links)",
    "frames_out": "Frames sent (CAN frames, or frames written to the serial port)",
    "bytes_in": "Bytes received (serial links)",
    "bytes_out": "Bytes sent (serial links)",
    "crc_errors": "Frames dropped for a bad CRC",
    "framing_errors": "Drops that are not CRC failures: garbage, bad headers, truncated frames",
    "send_errors": "Sends that failed and closed the link",
    "unmatched_replies": "Replies or ACKs that matched no request in flight: late, duplicated, wrong seq",
}
#: Unlabelled counters exported at 0 before they first count (dashboards and alerts need the series).
_ZERO_COUNTERS = (
    "services_duplicates_total",
    "events_resent_total",
    "events_unanswered_total",
    "topology_published_total",
    "drc_sessions_total",
    "drc_heartbeats_total",
    "drc_sticks_total",
)
#: Gauges the exporter computes from the live objects instead (the Metrics copy is event-driven only).
_COMPUTED_GAUGES = frozenset({"device_online"})

try:
    VERSION = importlib.metadata.version("dji-gateway")
except importlib.metadata.PackageNotFoundError:  # pragma: no cover - running from a bare checkout
    VERSION = "0+unknown"


# ------------------------------------------------------------------------------------------ link statistics
# LinkStats is the adapters' contract (adapters.base); every adapter answers ``link_stats()`` itself.


class _Monotonic:
    """Keeps counters monotonic across sources that restart at zero (a decoder replaced on reopen)."""

    def __init__(self) -> None:
        self._seen: dict[tuple[str, str], tuple[float, float]] = {}  # key -> (base, last raw value)
        self._lock = threading.Lock()

    def __call__(self, device: str, name: str, raw: float) -> float:
        with self._lock:
            base, last = self._seen.get((device, name), (0.0, 0.0))
            if raw < last:  # the source restarted: what it had counted stays counted
                base += last
            self._seen[(device, name)] = (base, raw)
            return base + raw


def safe_url(url: str) -> str:
    """scheme://host:port only: a URL may carry user:password@."""
    parts = urlsplit(url)
    host = parts.hostname or ""
    try:
        port = f":{parts.port}" if parts.port else ""
    except ValueError:
        port = ""
    return f"{parts.scheme}://{host}{port}"


# ------------------------------------------------------------------------------------------------ snapshot
class Observability:
    """Snapshots of one running :class:`gateway.app.GatewayApp`, as Prometheus families and JSON.
    ``port`` is where the web server that serves them listens (set by the composition root once bound)."""

    def __init__(self, app: Any, loop: Any = None, *, clock: Clock = SYSTEM_CLOCK) -> None:
        self.app = app
        self.loop = loop
        #: the gateway's clock (the web console keeps its sessions, uptime and timestamps on it too)
        self.clock = clock
        self._clock = clock.monotonic
        self._started_at = self._clock()
        self.loop_deadline = LOOP_DEADLINE
        self._monotonic = _Monotonic()
        self.registry = CollectorRegistry(auto_describe=False)
        self.registry.register(_Collector(self))
        #: the port the web server (:class:`gateway.web.server.WebServer`) serves these views on
        self.port: int | None = None

    # -- data -------------------------------------------------------------------------------------
    def snapshot(self) -> dict[str, Any]:
        """Everything /metrics and /status show, gathered on the event loop; ``loop_responsive`` is
        False (and the data read from this thread instead) when the loop misses ``loop_deadline``."""
        loop, deadline = self.loop, self.loop_deadline
        if loop is not None and not loop.is_closed():
            done: concurrent.futures.Future[dict[str, Any]] = concurrent.futures.Future()

            def gather() -> None:
                try:
                    done.set_result(self._gather())
                except BaseException as exc:  # handed to the waiting thread
                    done.set_exception(exc)

            try:
                loop.call_soon_threadsafe(gather)
                snap = done.result(deadline)
                snap["loop_responsive"] = True
                return snap
            except (concurrent.futures.TimeoutError, RuntimeError):
                pass
        snap = self._gather()
        snap["loop_responsive"] = loop is None
        return snap

    def _gather(self) -> dict[str, Any]:
        app = self.app
        metrics = app.metrics
        bridge = getattr(app, "bridge", None)
        dispatcher = getattr(app, "dispatcher", None)
        auth = app.devices.authority
        devices = []
        for adapter in app.devices:
            info = adapter.info
            stats = adapter.link_stats()
            link = None
            if stats is not None:
                link = asdict(stats)
                for name in _LINK_COUNTERS:
                    if link[name] is not None:
                        link[name] = int(self._monotonic(info.sn, name, link[name]))
            devices.append(
                {
                    "sn": info.sn,
                    "type": str(getattr(getattr(adapter, "settings", None), "type", type(adapter).__name__)),
                    "domain": info.domain,
                    "payload_index": info.payload_index,
                    "online": bool(adapter.online),
                    "flight_authority": info.sn in auth.flight,
                    "payload_authority": bool(info.payload_index and info.payload_index in auth.payloads),
                    "link": link,
                }
            )
        with metrics.lock:  # other threads count too (gateway/metrics.py)
            counters, gauges = list(metrics.counters.items()), list(metrics.gauges.items())
            histograms = [
                (n, dict(lab), h.bounds, list(h.counts), h.total, h.count)
                for (n, lab), h in metrics.histograms.items()
            ]
        return {
            "gateway_sn": app.settings.gateway_sn,
            "version": VERSION,
            "uptime_s": round(self._clock() - self._started_at, 3),
            "started": bool(getattr(app, "started", None) and app.started.is_set()),
            "broker": {
                "url": ", ".join(safe_url(u) for u in app.settings.broker.urls),
                "connected": bool(bridge is not None and bridge.connected),
                "subscribed": bool(bridge is not None and bridge.subscribed),
                "inbound_queue": bridge.queue.qsize() if bridge is not None else 0,
                "node": safe_url(bridge.current.url) if bridge is not None and bridge.current else None,
                "stalled": bool(bridge is not None and bridge.stalled),
                # connected (maybe) but our own probe did not come back: the link does not receive
                "deaf": bool(bridge is not None and getattr(bridge, "deaf", False)),
                "drc_link_deaf": self._drc_link_deaf(),
                "telemetry_buffered": bridge.buffered if bridge is not None else 0,
                # another client uses our client id (MQTT 5 0x8E, or 3.1.1 immediate disconnects)
                "client_id_conflict": bool(bridge is not None and bridge.takeover_suspected),
                # another gateway publishes under this gateway's serial number (gateway/twins.py)
                "gateway_sn_conflict": app.twins.snapshot(self._clock()) if hasattr(app, "twins") else None,
            },
            "requests_in_flight": int(getattr(dispatcher, "in_flight", 0)) if dispatcher is not None else 0,
            "devices": devices,
            "drc": self._drc(),
            "cloud_control": self.app.cloud_control.snapshot()
            if getattr(self.app, "cloud_control", None)
            else None,
            "counters": [(n, dict(lab), v) for (n, lab), v in counters],
            "gauges": [(n, dict(lab), v) for (n, lab), v in gauges],
            "histograms": histograms,
        }

    def _drc_link_deaf(self) -> bool:
        drc: DrcController | None = getattr(self.app, "drc", None)
        link = drc.dedicated_link if drc is not None else None
        return bool(link is not None and getattr(link, "deaf", False))

    def _drc(self) -> dict[str, Any]:
        drc: DrcController | None = getattr(self.app, "drc", None)
        if drc is None:
            return {"state": 0, "active": False}
        return drc.snapshot()

    # -- views ------------------------------------------------------------------------------------
    def status(self, snap: dict[str, Any] | None = None) -> dict[str, Any]:
        """The ``/status`` document: live state plus counter totals (no label detail, no settings)."""
        snap = snap or self.snapshot()
        totals: dict[str, float] = {}
        for name, _labels, value in snap["counters"]:
            totals[name] = totals.get(name, 0.0) + value
        results: dict[str, float] = {}
        for name, labels, value in snap["counters"]:
            if name == "services_total":
                results[str(labels.get("result"))] = results.get(str(labels.get("result")), 0.0) + value
        health, checks = self.health(snap)
        return {
            "gateway_sn": snap["gateway_sn"],
            "version": snap["version"],
            "healthy": health,
            "checks": checks,
            "uptime_s": snap["uptime_s"],
            "broker": snap["broker"],
            "requests_in_flight": snap["requests_in_flight"],
            "services_by_result": results,
            "devices": snap["devices"],
            "drc": snap["drc"],
            "cloud_control": snap.get("cloud_control"),
            "counters": dict(sorted(totals.items())),
        }

    @staticmethod
    def health(snap: dict[str, Any]) -> tuple[bool, dict[str, bool]]:
        """Healthy: started, the loop answers, the broker connection is up and receives (its liveness
        probe comes back; a DRC session's own link too). Offline devices do not count (absent hardware
        is not a fault of the gateway; restarting it would not help)."""
        checks = {
            "started": bool(snap["started"]),
            "event_loop": bool(snap["loop_responsive"]),
            "broker": bool(snap["broker"]["connected"]),
            "broker_receives": not snap["broker"].get("deaf", False),
            "drc_broker_receives": not snap["broker"].get("drc_link_deaf", False),
            "client_id_unique": not snap["broker"].get("client_id_conflict", False),
        }
        return all(checks.values()), checks

    @staticmethod
    def broker_state(snap: dict[str, Any]) -> str:
        """One word for the main broker link: ``disconnected``, ``deaf`` (connected or not, its probe has
        not come back since it missed) or ``connected``."""
        broker = snap["broker"]
        if broker.get("deaf", False):
            return "deaf"
        return "connected" if broker["connected"] else "disconnected"

    def families(self, snap: dict[str, Any] | None = None) -> Iterator[Metric]:
        snap = snap or self.snapshot()
        yield from _families(snap)


class _Collector(Collector):
    def __init__(self, owner: Observability) -> None:
        self.owner = owner

    def collect(self) -> Iterator[Metric]:
        return self.owner.families()


def _families(snap: dict[str, Any]) -> Iterator[Metric]:
    p = PREFIX
    info = GaugeMetricFamily(f"{p}info", "dji-gateway build and identity", labels=["gateway_sn", "version"])
    info.add_metric([snap["gateway_sn"], snap["version"]], 1)
    yield info
    healthy, _ = Observability.health(snap)
    yield GaugeMetricFamily(f"{p}healthy", "1 when /healthz passes", value=1 if healthy else 0)
    yield GaugeMetricFamily(
        f"{p}event_loop_responsive", "1 when the event loop answered the scrape in time",
        value=1 if snap["loop_responsive"] else 0,
    )  # fmt: skip
    yield GaugeMetricFamily(f"{p}uptime_seconds", "Seconds since the gateway started", value=snap["uptime_s"])
    yield GaugeMetricFamily(
        f"{p}requests_in_flight", "Services being executed now", value=snap["requests_in_flight"]
    )
    yield GaugeMetricFamily(
        f"{p}mqtt_inbound_queue_depth", "Received messages waiting for the dispatcher",
        value=snap["broker"]["inbound_queue"],
    )  # fmt: skip

    # -- counters, gauges and histograms the layers count themselves ------------------------------
    counters: dict[str, list[tuple[dict[str, str], float]]] = {name: [] for name in _ZERO_COUNTERS}
    for name, labels, value in snap["counters"]:
        counters.setdefault(name, []).append((labels, value))
    for name in HELP:
        if name.endswith("_total"):
            counters.setdefault(name, [])
    for name, series in sorted(counters.items()):
        keys = sorted({k for labels, _ in series for k in labels})
        family = CounterMetricFamily(
            p + name.removesuffix("_total"), HELP.get(name, name.replace("_", " ")), labels=keys
        )
        if not series and not keys:
            family.add_metric([], 0)
        for labels, value in series:
            family.add_metric([labels.get(k, "") for k in keys], value)
        yield family

    gauges: dict[str, list[tuple[dict[str, str], float]]] = {}
    for name, labels, value in snap["gauges"]:
        if name not in _COMPUTED_GAUGES:
            gauges.setdefault(name, []).append((labels, value))
    for name, series in sorted(gauges.items()):
        keys = sorted({k for labels, _ in series for k in labels})
        gauge = GaugeMetricFamily(p + name, HELP.get(name, name.replace("_", " ")), labels=keys)
        for labels, value in series:
            gauge.add_metric([labels.get(k, "") for k in keys], value)
        yield gauge

    histograms: dict[str, list[tuple[dict[str, str], Any, list[int], float]]] = {
        "services_latency_seconds": []
    }
    for name, labels, bounds, counts, total, _count in snap["histograms"]:
        histograms.setdefault(name, []).append((labels, bounds, counts, total))
    for name, histogram_series in sorted(histograms.items()):
        keys = sorted({k for labels, *_ in histogram_series for k in labels})
        histogram = HistogramMetricFamily(p + name, HELP.get(name, name.replace("_", " ")), labels=keys)
        for labels, bounds, counts, total in histogram_series:
            if not counts:
                continue
            buckets = [(repr(float(b)), counts[i]) for i, b in enumerate(bounds)] + [("+Inf", counts[-1])]
            histogram.add_metric([labels.get(k, "") for k in keys], buckets, total)
        yield histogram

    # -- devices and their links (read live, per scrape) --------------------------------------------
    online = GaugeMetricFamily(f"{p}device_online", "1 while the device is online", labels=["device", "type"])
    link_up = GaugeMetricFamily(f"{p}link_up", "1 while the device link is open", labels=["device", "kind"])
    per_link = {
        name: CounterMetricFamily(f"{p}link_{name}", text, labels=["device", "kind"])
        for name, text in _LINK_COUNTERS.items()
    }
    for device in snap["devices"]:
        online.add_metric([device["sn"], device["type"]], 1 if device["online"] else 0)
        link = device["link"]
        if link is None:
            continue
        labels = [device["sn"], link["kind"]]
        link_up.add_metric(labels, 1 if link["up"] else 0)
        for name, family in per_link.items():
            if link[name] is not None:
                family.add_metric(labels, link[name])
    yield online
    yield link_up
    yield from per_link.values()

    drc = snap["drc"]
    yield GaugeMetricFamily(f"{p}drc_state", "drc_state: 0 idle, 1 connecting, 2 in live control",
                            value=drc["state"])  # fmt: skip
    heartbeat_age = drc.get("heartbeat_age_s")
    yield GaugeMetricFamily(
        f"{p}drc_heartbeat_age_seconds", "Seconds since the last DRC heart_beat (0 outside a session)",
        value=heartbeat_age if heartbeat_age is not None else 0,
    )  # fmt: skip
    yield GaugeMetricFamily(
        f"{p}drc_command_delay_seconds", "Smoothed delay from a stick message to the device stream",
        value=drc.get("command_delay_ms", 0.0) / 1000.0,
    )  # fmt: skip
