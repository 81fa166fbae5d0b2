"""The console's actions: which Cloud API methods each device offers, as forms, and running them.

Owns the catalogue (for every device, the services it serves — its adapter's handlers plus the authority
grab the dispatcher answers for it — and the gateway's own live-control methods, each with the JSON Schema
of its ``data`` from the contract's registry, the same schema ``schemas/json/`` exports), which methods
move a device (they need an explicit confirmation, in the page and again here), and how an action runs:
as a services request through :meth:`gateway.dispatcher.Dispatcher.call_local`, so it is validated,
routed, authority-checked, time-limited and counted exactly like one from the cloud. The emergency stop
is the DRC session's emergency stop (every device's ``emergency_stop``, a session holds) followed by every
adapter's ``stop_motion`` (missions cancelled, loops ended), as at shutdown. The operator's answer to a
cloud-control request (accept, deny, revoke) goes to :meth:`gateway.cloud_control.CloudControl.decide`.
Live control from a page (:class:`PagePilot`): which DRC messages a page may send and the ``drc/down``
body each becomes, with the seq counted for that page.

Everything here but :func:`catalogue` and :class:`PagePilot` (the web thread's, one per page) runs on the
gateway's event loop. Must not know HTTP, sessions or the page.
"""

from __future__ import annotations

import asyncio
import json
import uuid
from typing import Any

from adapters.base import Adapter
from schemas import TopicKind
from schemas.export import ContractJsonSchema
from schemas.registry import Registry

__all__ = [
    "DECISIONS",
    "GATEWAY_METHODS",
    "PAGE_DRC",
    "PagePilot",
    "catalogue",
    "cloud_control_decision",
    "emergency_stop",
    "moves",
    "run_action",
]

#: the gateway's own services (live flight control), offered under the gateway's serial number
GATEWAY_METHODS = ("drc_mode_enter", "drc_mode_exit")
#: services that do not move anything; every other one asks for a confirmation first
_STILL = frozenset(
    {
        "payload_authority_grab",
        "flight_authority_grab",
        "camera_photo_take",
        "camera_recording_start",
        "camera_recording_stop",
        "camera_mode_switch",
        "camera_focal_length_set",
        "drc_mode_exit",
        "x_osdk_authority_release",
    }
)


def moves(method: str) -> bool:
    """True unless the method is known to move nothing (reads, stops, camera shutter, authority)."""
    return not (method in _STILL or method.endswith(("_get", "_stop", "_download")))


def _schema(registry: Registry, method: str) -> dict[str, Any] | None:
    spec = registry.spec(TopicKind.SERVICES, method)
    if spec is None:
        return None
    return spec.data.model_json_schema(schema_generator=ContractJsonSchema, mode="validation")


def _method(registry: Registry, method: str) -> dict[str, Any] | None:
    schema = _schema(registry, method)
    if schema is None:
        return None
    spec = registry.spec(TopicKind.SERVICES, method)
    assert spec is not None
    return {"method": method, "summary": spec.summary, "moves": moves(method), "schema": schema}


def catalogue(app: Any) -> dict[str, Any]:
    """Every device's methods with their schemas and the values the form fills in for it (its
    ``payload_index`` / ``sn``); the gateway's own under its serial number."""
    registry: Registry = app.registry
    devices = []
    for adapter in app.devices:
        names = set(adapter.handlers)
        if adapter.info.payload_index:
            names.add("payload_authority_grab")
        methods = [m for m in (_method(registry, name) for name in sorted(names)) if m is not None]
        prefill: dict[str, Any] = {"sn": adapter.info.sn}
        if adapter.info.payload_index:
            prefill["payload_index"] = adapter.info.payload_index
        devices.append({"sn": adapter.info.sn, "prefill": prefill, "methods": methods})
    broker = app.settings.broker
    gateway = {
        "sn": app.settings.gateway_sn,
        "prefill": {
            # the main broker: live control then rides the gateway's own connection (no credentials used)
            "mqtt_broker": {
                "address": f"{broker.host}:{broker.port}",
                "enable_tls": broker.tls,
                "client_id": f"drc-console-{app.settings.gateway_sn}",
                "username": "console",
                "expire_time": app.clock.time_ms() // 1000 + 3600,
            },
            "osd_frequency": 10,
            "hsi_frequency": 1,
        },
        "methods": [m for m in (_method(registry, name) for name in GATEWAY_METHODS) if m is not None],
    }
    return {"devices": devices, "gateway": gateway}


def offered(app: Any) -> frozenset[str]:
    """Every method some form offers."""
    names: set[str] = set(GATEWAY_METHODS)
    for adapter in app.devices:
        names.update(adapter.handlers)
        if adapter.info.payload_index:
            names.add("payload_authority_grab")
    return frozenset(names)


async def run_action(app: Any, method: str, data: Any) -> dict[str, Any]:
    """Run one service as the cloud would ask it; the reply's ``result`` and ``output``."""
    dispatcher = app.dispatcher
    if dispatcher is None:
        return {"result": 314000, "output": {"reason": "the gateway is not running yet"}}
    tid = str(uuid.uuid4())
    body = {
        "tid": tid,
        "bid": str(uuid.uuid4()),
        "timestamp": app.clock.time_ms(),
        "method": method,
        "data": data,
    }
    raw = await dispatcher.call_local(json.dumps(body).encode())
    try:
        reply = json.loads(raw)
        result = int(reply["data"]["result"])
        output = reply["data"].get("output")
    except (ValueError, KeyError, TypeError):
        return {"tid": tid, "result": 599001, "output": {"reason": "no reply from the dispatcher"}}
    return {"tid": tid, "result": result, "output": output}


async def emergency_stop(app: Any) -> dict[str, Any]:
    """Stop every motion of every device now; which devices were told and which failed."""
    drc = getattr(app, "drc", None)
    if drc is not None:
        drc.emergency_stop()
    adapters: list[Adapter] = list(app.devices)
    outcomes = await asyncio.gather(*(a.stop_motion() for a in adapters), return_exceptions=True)
    failed = {a.info.sn: f"{type(o).__name__}: {o}" for a, o in zip(adapters, outcomes, strict=True) if o}
    return {"stopped": [a.info.sn for a in adapters if a.info.sn not in failed], "failed": failed}


#: what a page may send on live control (``{"type": "drc", …}`` on its WebSocket): sticks, heartbeats, stop
PAGE_DRC = ("drone_control", "heart_beat", "drone_emergency_stop")
STOP = "drone_emergency_stop"


class PagePilot:
    """One page's live control (docs/console.md, "Flying from the page"): the ``drc/down`` message each
    of its WebSocket messages becomes, with the seq the gateway counts for it (one page, one increasing
    count; a reconnected page starts at 0), and whether it has flown (its WebSocket's loss then zeroes
    its sticks: :meth:`zero`)."""

    def __init__(self) -> None:
        self.flying = False
        self.refused = False
        self._seq = 0
        self._beats = 0

    def message(self, method: str, data: dict[str, Any]) -> bytes:
        """The drc/down body for one of :data:`PAGE_DRC` (already checked by the caller)."""
        if method == "drone_control":
            data = {**data, "seq": self._seq}
            self._seq += 1
            self.flying = True
        elif method == "heart_beat":
            data = {**data, "seq": self._beats}
            self._beats += 1
            self.flying = True
        elif method == STOP:
            self._seq = 0  # the stop holds until sticks start again at seq 0 (docs/drc.md)
        return json.dumps({"method": method, "data": data}, separators=(",", ":")).encode()

    def zero(self) -> bytes:
        """A zero stick (the dead-man of a lost WebSocket)."""
        return self.message("drone_control", {"x": 0.0, "y": 0.0, "h": 0.0, "w": 0.0})


#: the operator's answers to cloud-control authorisation (gateway/cloud_control.py)
DECISIONS = ("accept", "deny", "revoke")


def cloud_control_decision(app: Any, decision: str, user_id: str | None, who: str) -> dict[str, Any]:
    """Accept or deny the waiting ``cloud_control_auth_request`` (``user_id``: the one the operator saw),
    or revoke the grant: ``{"ok", "reason"?, "cloud_control"}``. On the gateway's loop."""
    cloud_control = getattr(app, "cloud_control", None)
    if cloud_control is None:
        return {"ok": False, "reason": "the gateway is not running yet", "cloud_control": None}
    outcome: dict[str, Any] = cloud_control.decide(decision, user_id, who=who)
    return outcome
