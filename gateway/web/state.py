"""What the web console shows of the gateway, read in one place.

Owns :class:`ConsoleState`: the JSON document the page is pushed (every device with its link, online
flag, traffic, errors, last-heard age, authority, firmware, ``osd``/``state`` bodies; the broker
connection(s); the live-control session with its heartbeat history; the fly-to target; the wayline
task's progress and break point), the tracks and home points and the wayline route (built once per
task/version, decimated to ROUTE_POINTS, fetched by the page, never pushed) the map draws, the frame
inspectors and the journal. :meth:`ConsoleState.gather` runs **on the gateway's event loop** (the web
server asks for it once per push tick, with a deadline), so it reads the live objects without locks; it
must stay cheap (no I/O, no decoding).

Reads adapters through their contract (:class:`adapters.base.Adapter`: ``link_stats()``,
``observe_link()`` for the frame tap, ``last_heard``, the ``osd``/``state`` snapshots); the firmware
version shown is the ``state`` body's, or an adapter's public ``firmware_version``/``version``. Must not
know HTTP or the page.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import asdict
from typing import Any

from adapters.base import Adapter
from gateway.clock import SYSTEM_CLOCK, Clock
from gateway.observability import VERSION, safe_url
from gateway.web.frames import LinkInspector, inspectable
from gateway.web.journal import Journal

__all__ = ["ConsoleState"]

#: track points kept per device (the map's trail); a point is added when the device moved this far (m)
TRACK_POINTS = 600
TRACK_STEP_M = 0.5
#: heartbeats sent with each push (the DRC panel's chart)
HEARTBEAT_POINTS = 60
#: waypoints of a wayline route sent to the page for drawing (a longer route is decimated: every k-th
#: waypoint, the first and the last kept, each with its index in the route)
ROUTE_POINTS = 2000
NO_WAYLINE = 65535
_EARTH_M = 6_371_000.0


def _distance_m(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Metres between two WGS84 points (equirectangular: exact enough for a trail)."""
    lat = math.radians((a[0] + b[0]) / 2)
    dy = math.radians(b[0] - a[0]) * _EARTH_M
    dx = math.radians(b[1] - a[1]) * _EARTH_M * math.cos(lat)
    return math.hypot(dx, dy)


class ConsoleState:
    """The console's view of one :class:`gateway.app.GatewayApp`."""

    def __init__(self, app: Any, *, frames: int, journal: int, clock: Clock = SYSTEM_CLOCK) -> None:
        self.app = app
        self.journal = Journal(journal, clock=clock)
        self._keep_frames = frames
        self._wall = clock
        self._clock = clock.monotonic
        self._started = self._clock()
        self.inspectors: dict[str, LinkInspector] = {}
        self.tracks: dict[str, deque[tuple[float, float]]] = {}
        self.home: dict[str, tuple[float, float]] = {}
        self._route: dict[str, Any] | None = None  # the drawn route of the shown wayline task (one kept)

    def attach(self) -> None:
        """Start observing the app (on its loop, before it publishes): the journal hears every message,
        every link gets its frame tap."""
        self.app.published.append(self.journal.published)
        self.app.received.append(self.journal.received)
        for adapter in self.app.devices:
            self._inspector(adapter)

    # -- the frame inspector --------------------------------------------------------------------------
    def _inspector(self, adapter: Adapter) -> LinkInspector | None:
        sn = adapter.info.sn
        inspector = self.inspectors.get(sn)
        if inspector is None:
            settings = getattr(adapter, "settings", None)
            family = str(getattr(settings, "type", ""))
            stats = adapter.link_stats()
            describe = inspectable(family)
            if describe is None or stats is None:
                return None
            options_for = getattr(describe, "options_for", None)
            inspector = LinkInspector(
                clock=self._wall,
                family=family,
                kind=stats.kind,
                where=stats.where,
                keep=self._keep_frames,
                options=options_for(settings) if options_for is not None else {},
            )
            self.inspectors[sn] = inspector
        adapter.observe_link(inspector.tap)  # the link exists from start(); a tap is attached once
        return inspector

    # -- the pushed document (the gateway's loop) ------------------------------------------------------
    def gather(self) -> dict[str, Any]:
        app = self.app
        now = self._clock()
        auth = app.devices.authority
        devices = [self._device(adapter, auth, now) for adapter in app.devices]
        drc = getattr(app, "drc", None)
        return {
            "gateway": {
                "sn": app.settings.gateway_sn,
                "version": VERSION,
                "uptime_s": round(now - self._started, 1),
                "started": bool(app.started.is_set()),
                "brokers": self._brokers(),
                "requests_in_flight": int(getattr(app.dispatcher, "in_flight", 0) or 0),
                # another gateway publishing under this serial number (gateway/twins.py)
                "sn_conflict": app.twins.snapshot(now) if hasattr(app, "twins") else None,
            },
            "devices": devices,
            "drc": self._drc(drc),
            "cloud_control": app.cloud_control.snapshot() if getattr(app, "cloud_control", None) else None,
            "mission": self.journal.mission,
            "wayline": self._wayline(),
            "t": self._wall.time_ms(),
        }

    def _device(self, adapter: Adapter, auth: Any, now: float) -> dict[str, Any]:
        info = adapter.info
        settings = getattr(adapter, "settings", None)
        self._inspector(adapter)
        stats = adapter.link_stats()
        heard = adapter.last_heard
        osd = _plain(adapter.osd_snapshot())
        state = _plain(adapter.state_snapshot())
        firmware = (state or {}).get("firmware_version") or getattr(adapter, "firmware_version", None)
        firmware = firmware or getattr(adapter, "version", None)
        self._track(info.sn, osd)
        flight = info.sn in auth.flight
        payload = bool(info.payload_index and info.payload_index in auth.payloads)
        return {
            "sn": info.sn,
            "family": str(getattr(settings, "type", type(adapter).__name__)),
            "domain": info.domain,
            "payload_index": info.payload_index,
            "online": bool(adapter.online),
            "last_heard_s": round(now - heard, 2)
            if isinstance(heard, float) and math.isfinite(heard)
            else None,
            "link": asdict(stats) if stats is not None else None,
            "authority": {
                "flight": flight,
                "payload": payload,
                "holder": "gateway" if flight or payload else None,
            },
            "firmware": firmware,
            "osd": osd,
            "state": state,
            "home": self.home.get(info.sn),
        }

    def _track(self, sn: str, osd: dict[str, Any] | None) -> None:
        """The trail and the home point: where the aircraft was last seen on the ground."""
        if not osd:
            return
        if isinstance(osd.get("latitude"), float | int) and isinstance(osd.get("longitude"), float | int):
            point = (float(osd["latitude"]), float(osd["longitude"]))
            if float(osd.get("elevation") or 0.0) < 0.3:
                self.home[sn] = point
            step = _distance_m
        elif isinstance(osd.get("x_position"), dict):
            pos = osd["x_position"]
            point = (float(pos.get("x", 0.0)), float(pos.get("y", 0.0)))

            def step(a: tuple[float, float], b: tuple[float, float]) -> float:
                return math.hypot(a[0] - b[0], a[1] - b[1])
        else:
            return
        track = self.tracks.setdefault(sn, deque(maxlen=TRACK_POINTS))
        if not track or step(track[-1], point) >= TRACK_STEP_M:
            track.append(point)

    def _brokers(self) -> list[dict[str, Any]]:
        """The main broker connection (with its nodes when the broker is a cluster: the node it is on),
        and a DRC session's own connection when it has one."""
        app = self.app
        out = []
        bridge = app.bridge
        if bridge is not None:
            nodes = [safe_url(u) for u in app.settings.broker.urls]
            current = getattr(bridge, "current", None)
            out.append(
                {
                    "name": "main",
                    "url": safe_url(current.url) if current is not None else nodes[0],
                    "nodes": nodes,
                    "connected": bool(bridge.connected),
                    "subscribed": bool(bridge.subscribed),
                    "deaf": bool(getattr(bridge, "deaf", False)),
                }
            )
        drc = getattr(app, "drc", None)
        dedicated = drc.dedicated_link if drc is not None else None
        if dedicated is not None:
            out.append(
                {
                    "name": "drc",
                    "url": "(drc_mode_enter)",
                    "connected": bool(dedicated.connected),
                    "subscribed": bool(dedicated.subscribed),
                    "deaf": bool(getattr(dedicated, "deaf", False)),
                }
            )
        return out

    def _drc(self, drc: Any) -> dict[str, Any]:
        if drc is None:
            return {"state": 0, "active": False, "heartbeats": []}
        view = dict(drc.snapshot())
        beats = list(drc.heartbeats)[-HEARTBEAT_POINTS:]
        view["heartbeats"] = [[received, received - sent] for received, sent in beats]
        view["failsafe_at"] = drc.failsafe[1] if drc.failsafe is not None else None
        view["failsafe_reason"] = drc.failsafe[0] if drc.failsafe is not None else None
        return view

    # -- the wayline task (the route itself is fetched once per task/version: route_view) -------------
    def _shown_task(self) -> Any:
        """The running or paused task, else the one started (or prepared) last; None without one."""
        service = getattr(self.app, "wayline", None)
        if service is None or not service.book.tasks:
            return None
        active = service.book.active
        if active is not None:
            return active
        return max(service.book.tasks.values(), key=lambda t: t.started_at or t.prepared_at)

    def _wayline(self) -> dict[str, Any] | None:
        """The shown task's progress (small: pushed every tick); ``route`` names the route to fetch."""
        task = self._shown_task()
        if task is None:
            return None
        route = self.route_view(task.flight_id)
        reached = 0
        if route is not None:
            if task.status == "ok":
                reached = route["total"]
            elif task.wayline_id != NO_WAYLINE:
                offset = route["offsets"].get(str(task.wayline_id), 0)
                reached = min(route["total"], offset + task.waypoint_index)
        return {
            "sn": self.app.wayline.aircraft_sn(),
            "flight_id": task.flight_id,
            "status": task.status,
            "result": task.result,
            "reason": task.reason,
            "percent": task.percent,
            "step": task.step,
            "wayline_id": task.wayline_id,
            "waypoint_index": task.waypoint_index,
            "reached": reached,
            "total": route["total"] if route is not None else None,
            "break_point": task.break_point,
            "route": route["key"] if route is not None else None,
        }

    def route_view(self, flight_id: str) -> dict[str, Any] | None:
        """The task's route for drawing: ``waypoints`` as ``[index, lat, lon, height]`` (at most
        ROUTE_POINTS of them), ``total``, ``offsets`` (a wayline's first index), ``key`` (flight id and
        file fingerprint: the page fetches again when it changes). Built once per key."""
        service = getattr(self.app, "wayline", None)
        found = service.route_of(flight_id) if service is not None else None
        if found is None:
            return None
        fingerprint, route = found
        key = f"{flight_id}:{fingerprint}"
        if self._route is not None and self._route["key"] == key:
            return self._route
        points: list[tuple[float, float, float]] = []
        offsets: dict[str, int] = {}
        for wayline in route.waylines:
            offsets[str(wayline.wayline_id)] = len(points)
            points += [(p.latitude, p.longitude, p.execute_height) for p in wayline.placemarks]
        stride = max(1, math.ceil(len(points) / ROUTE_POINTS))
        kept = list(range(0, len(points), stride))
        if points and kept[-1] != len(points) - 1:
            kept[-1] = len(points) - 1  # the last waypoint is drawn (ROUTE_POINTS stays the bound)
        self._route = {
            "key": key,
            "flight_id": flight_id,
            "total": len(points),
            "decimated": stride > 1,
            "height_mode": route.waylines[0].execute_height_mode if route.waylines else None,
            "offsets": offsets,
            "waypoints": [[i, *points[i]] for i in kept],
        }
        return self._route

    def track_view(self) -> dict[str, Any]:
        """The trails and home points (the page asks once; pushes keep it current)."""
        return {"tracks": {sn: list(t) for sn, t in self.tracks.items()}, "home": dict(self.home)}


def _plain(body: Any) -> dict[str, Any] | None:
    return dict(body) if body else None
