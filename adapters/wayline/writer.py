"""A small WPML/KMZ writer: ``wpmz/template.kml`` + ``wpmz/waylines.wpml`` in a zip, from plain values.

Owns the text of the KMZs the tests, the bench and ``dji-gateway send flighttask_prepare file=…`` use, in
the shape of WAYLINE-NOTES §7.8/§7.9 (WPML 1.0.2, DJI's element order). Knows nothing of parsing,
devices or MQTT. Sans-I/O: values in, bytes out.
"""

from __future__ import annotations

import hashlib
import io
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from xml.sax.saxutils import escape

__all__ = ["ActionSpec", "PointSpec", "kmz_bytes", "md5_hex", "waylines_wpml"]

WPML_NS_102 = "http://www.dji.com/wpmz/1.0.2"


@dataclass(frozen=True, slots=True)
class ActionSpec:
    func: str
    params: Mapping[str, str | float | int] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class PointSpec:
    latitude: float
    longitude: float
    height: float
    speed: float | None = None
    heading_mode: str = "followWayline"
    heading_angle: float | None = None
    heading_path_mode: str = "followBadArc"
    turn_mode: str = "toPointAndStopWithDiscontinuityCurvature"
    turn_damping: float = 0.0
    actions: Sequence[ActionSpec] = ()


def _el(name: str, value: object) -> str:
    return f"<wpml:{name}>{escape(str(value))}</wpml:{name}>"


def waylines_wpml(
    points: Sequence[PointSpec],
    *,
    speed: float = 6.0,
    height_mode: str = "relativeToStartPoint",
    finish_action: str = "noAction",
    fly_to_wayline_mode: str = "safely",
    exit_on_rc_lost: str = "executeLostAction",
    rc_lost_action: str = "goBack",
    take_off_security_height: float = 20.0,
    transitional_speed: float = 8.0,
    namespace: str = WPML_NS_102,
    extra_config: str = "",
) -> str:
    """The text of ``waylines.wpml``: one wayline (waylineId 0) through ``points``."""
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<kml xmlns="http://www.opengis.net/kml/2.2" xmlns:wpml="{escape(namespace)}">',
        "<Document><wpml:missionConfig>",
        _el("flyToWaylineMode", fly_to_wayline_mode),
        _el("finishAction", finish_action),
        _el("exitOnRCLost", exit_on_rc_lost),
        _el("executeRCLostAction", rc_lost_action),
        _el("takeOffSecurityHeight", take_off_security_height),
        _el("globalTransitionalSpeed", transitional_speed),
        _el("globalRTHHeight", 100),
        "<wpml:droneInfo><wpml:droneEnumValue>67</wpml:droneEnumValue>"
        "<wpml:droneSubEnumValue>0</wpml:droneSubEnumValue></wpml:droneInfo>",
        "<wpml:payloadInfo><wpml:payloadEnumValue>52</wpml:payloadEnumValue>"
        "<wpml:payloadPositionIndex>0</wpml:payloadPositionIndex></wpml:payloadInfo>",
        extra_config,
        "</wpml:missionConfig><Folder>",
        _el("templateId", 0),
        _el("executeHeightMode", height_mode),
        _el("waylineId", 0),
        _el("autoFlightSpeed", speed),
    ]
    group = 0
    for i, p in enumerate(points):
        out += [
            "<Placemark>",
            f"<Point><coordinates>{p.longitude:.8f},{p.latitude:.8f}</coordinates></Point>",
            _el("index", i),
            _el("executeHeight", p.height),
            _el("waypointSpeed", p.speed if p.speed is not None else speed),
            "<wpml:waypointHeadingParam>",
            _el("waypointHeadingMode", p.heading_mode),
            _el("waypointHeadingAngle", p.heading_angle) if p.heading_angle is not None else "",
            _el("waypointHeadingPathMode", p.heading_path_mode),
            "</wpml:waypointHeadingParam><wpml:waypointTurnParam>",
            _el("waypointTurnMode", p.turn_mode),
            _el("waypointTurnDampingDist", p.turn_damping),
            "</wpml:waypointTurnParam>",
        ]
        if p.actions:
            out += [
                "<wpml:actionGroup>",
                _el("actionGroupId", group),
                _el("actionGroupStartIndex", i),
                _el("actionGroupEndIndex", i),
                _el("actionGroupMode", "sequence"),
                "<wpml:actionTrigger>",
                _el("actionTriggerType", "reachPoint"),
                "</wpml:actionTrigger>",
            ]
            for aid, action in enumerate(p.actions):
                params = "".join(_el(k, v) for k, v in action.params.items())
                out += [
                    "<wpml:action>",
                    _el("actionId", aid),
                    _el("actionActuatorFunc", action.func),
                    f"<wpml:actionActuatorFuncParam>{params}</wpml:actionActuatorFuncParam>",
                    "</wpml:action>",
                ]
            out.append("</wpml:actionGroup>")
            group += 1
        out.append("</Placemark>")
    out.append("</Folder></Document></kml>")
    return "\n".join(x for x in out if x)


def _template_kml(namespace: str, height_mode: str) -> str:
    return (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<kml xmlns="http://www.opengis.net/kml/2.2" xmlns:wpml="{escape(namespace)}"><Document>'
        "<wpml:missionConfig><wpml:droneInfo><wpml:droneEnumValue>67</wpml:droneEnumValue>"
        "<wpml:droneSubEnumValue>0</wpml:droneSubEnumValue></wpml:droneInfo><wpml:payloadInfo>"
        "<wpml:payloadEnumValue>52</wpml:payloadEnumValue><wpml:payloadSubEnumValue>0</wpml:payloadSubEnumValue>"
        "<wpml:payloadPositionIndex>0</wpml:payloadPositionIndex></wpml:payloadInfo></wpml:missionConfig>"
        "<Folder><wpml:templateType>waypoint</wpml:templateType><wpml:templateId>0</wpml:templateId>"
        f"<wpml:waylineCoordinateSysParam><wpml:coordinateMode>WGS84</wpml:coordinateMode>"
        f"<wpml:heightMode>{escape(height_mode)}</wpml:heightMode></wpml:waylineCoordinateSysParam>"
        "</Folder></Document></kml>\n"
    )


def kmz_bytes(
    wpml: str | bytes, *, extra: Mapping[str, bytes] | None = None, height_mode: str = "relativeToStartPoint"
) -> bytes:
    """A KMZ: ``wpmz/template.kml``, ``wpmz/waylines.wpml`` (and ``extra`` entries as given, for tests)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("wpmz/template.kml", _template_kml(WPML_NS_102, height_mode))
        z.writestr("wpmz/waylines.wpml", wpml if isinstance(wpml, bytes) else wpml.encode())
        for name, data in (extra or {}).items():
            z.writestr(name, data)
    return buf.getvalue()


def md5_hex(data: bytes) -> str:
    """The fingerprint DJI's reference cloud computes: lowercase hex MD5 of the file's bytes."""
    return hashlib.md5(data, usedforsecurity=False).hexdigest()
