"""What each device was left doing when the gateway stopped: one line per device for the operator who
pressed Ctrl-C mid-flight ("left OSDK-1 (aircraft) hovering at 22.54364 N 113.95800 E, 30.1 m above
home").

Owns only the wording, from what the gateway already knows: the device's Cloud API domain, whether it is
online, its last ``osd`` body (position, ``mode_code``, gimbal angles) and, for an aircraft, what its
``on_stop`` setting makes it do after the brake (hover, land, go home). Knows nothing of wires or MQTT;
the composition root logs these lines after every motion has been stopped.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from adapters.base import Adapter, Domain

__all__ = ["left_doing"]

_ON_GROUND_MODES = frozenset({0, 1, 2, 14})  # standby, take-off preparation (+ready), not connected
_AFTER_STOP = {"hover": "hovering", "land": "landing", "go_home": "returning home from"}


def _where(osd: Mapping[str, Any]) -> str:
    lat, lon = osd.get("latitude"), osd.get("longitude")
    if not isinstance(lat, int | float) or not isinstance(lon, int | float):
        return "an unknown position"
    text = f"{abs(lat):.5f} {'N' if lat >= 0 else 'S'} {abs(lon):.5f} {'E' if lon >= 0 else 'W'}"
    above = osd.get("elevation")
    if isinstance(above, int | float):
        text += f", {above:.1f} m above home"
    return text


def left_doing(adapter: Adapter) -> str:
    """One line: the device, its kind, and what it is doing now that the gateway has stopped it."""
    info = adapter.info
    kinds: dict[str, str] = {Domain.AIRCRAFT: "aircraft", Domain.PAYLOAD: "gimbal"}
    kind = kinds.get(info.domain, "robot")
    head = f"left {info.sn} ({kind})"
    if not adapter.online:
        return f"{head} offline: nothing was sent to it"
    osd = dict(adapter.osd_snapshot() or {})
    if kind == "aircraft":
        mode = osd.get("mode_code")
        if mode in _ON_GROUND_MODES:
            return f"{head} on the ground at {_where(osd)}"
        on_stop = str(getattr(getattr(adapter, "settings", None), "on_stop", "hover"))
        return f"{head} {_AFTER_STOP.get(on_stop, on_stop)} at {_where(osd)}, its task cancelled"
    if kind == "gimbal":
        angles = [f"{name} {osd[key]:.1f}°" for name, key in
                  (("yaw", "gimbal_yaw"), ("pitch", "gimbal_pitch"), ("roll", "gimbal_roll"))
                  if isinstance(osd.get(key), int | float)]  # fmt: skip
        return f"{head} holding {', '.join(angles)}" if angles else f"{head} holding still"
    pos = osd.get("x_position")
    where = f" at x {pos['x']:.2f} m, y {pos['y']:.2f} m" if isinstance(pos, dict) and "x" in pos else ""
    return f"{head} stopped{where}"
