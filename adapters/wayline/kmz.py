"""KMZ wayline files (DJI WPML 1.0.x): the fingerprint check, the zip-bomb-safe unpacking of
``wpmz/waylines.wpml`` and its namespace-aware parse into a :class:`Route` of plain frozen values.

Sans-I/O: bytes in, values out (no sockets, files, clocks or threads); the download is
``gateway/wayline/fetch.py``'s. Knows nothing of MQTT, flight controllers or tasks; what a device can fly
is decided by its family's mapping (e.g. ``adapters/osdk/wayline.py``).

The file is untrusted: it comes from a URL the cloud names.

* Unpacking limits (:class:`Limits`): entry count, each entry's and the total uncompressed size (read
  with a bound, never trusting the sizes the archive declares), the compression ratio, and names: an
  absolute path, a drive, a backslash or a ``..`` component refuses the whole archive (a KMZ is never
  extracted to disk, but a file with such names was not made by a route editor).
* XML through ``defusedxml`` with DTDs forbidden: no entities (billion laughs, external entities), no
  external DTDs.
* Namespaces, not prefixes (WAYLINE-NOTES §7.1, §8.13): the root must be KML 2.2's ``kml``; WPML
  elements are those whose namespace URI is ``http://www.dji.com/wpmz/1.0.<n>`` (1.0.0, 1.0.2 and 1.0.6
  occur); elements in no WPML namespace or of an unknown name are ignored; a file whose WPML
  namespace is any other version is refused.
* A waypoint cap (:data:`MAX_WAYPOINTS`) counted while parsing.

Every refusal is a :class:`KmzError` with the Cloud API result code (314002 empty fingerprint, 314005
MD5 mismatch, 314003 anything about the file) and a short reason that names what was wrong.
"""

from __future__ import annotations

import hashlib
import io
import re
import zipfile
import zlib
from dataclasses import dataclass, field
from typing import Any
from xml.etree.ElementTree import Element, ParseError

from defusedxml import DefusedXmlException
from defusedxml.ElementTree import fromstring

from adapters.errors import KmzError

__all__ = [
    "KML_NS",
    "MAX_WAYPOINTS",
    "WAYLINES_PATH",
    "Action",
    "ActionGroup",
    "Limits",
    "MissionConfig",
    "Placemark",
    "Route",
    "Wayline",
    "check_fingerprint",
    "load_route",
    "parse_wpml",
    "unpack_wpml",
]

KML_NS = "http://www.opengis.net/kml/2.2"
_WPML_NS = re.compile(r"^http://www\.dji\.com/wpmz/1\.0\.[0-9]{1,3}$")
WAYLINES_PATH = "wpmz/waylines.wpml"
#: More waypoints than any route editor makes (Pilot 2 caps a route at 65535 indexes, real routes have
#: hundreds); 5000 chained ground-station missions of 255 would already fly for many hours.
MAX_WAYPOINTS = 5000
#: Result codes (schemas.results.ResultCode; numbers here: adapters do not import the contract's codes).
MD5_EMPTY, FILE_FORMAT, MD5_MISMATCH = 314002, 314003, 314005


@dataclass(frozen=True, slots=True)
class Limits:
    max_entries: int = 256
    max_entry_bytes: int = 16 * 1024 * 1024
    max_total_bytes: int = 64 * 1024 * 1024
    max_ratio: float = 200.0


@dataclass(frozen=True, slots=True)
class Action:
    action_id: int
    func: str  # wpml:actionActuatorFunc
    params: dict[str, str] = field(default_factory=dict)  # wpml:actionActuatorFuncParam children, as text


@dataclass(frozen=True, slots=True)
class ActionGroup:
    group_id: int
    start_index: int
    end_index: int
    mode: str
    trigger: str
    trigger_param: float | None
    actions: tuple[Action, ...]


@dataclass(frozen=True, slots=True)
class Placemark:
    index: int
    latitude: float
    longitude: float
    execute_height: float
    speed: float | None
    heading_mode: str | None
    heading_angle: float | None
    heading_path_mode: str | None
    turn_mode: str | None
    turn_damping: float | None
    use_straight_line: int | None
    action_groups: tuple[ActionGroup, ...] = ()


@dataclass(frozen=True, slots=True)
class Wayline:
    wayline_id: int
    template_id: int
    auto_flight_speed: float
    execute_height_mode: str
    placemarks: tuple[Placemark, ...]
    start_actions: tuple[ActionGroup, ...] = ()


@dataclass(frozen=True, slots=True)
class MissionConfig:
    fly_to_wayline_mode: str
    finish_action: str
    exit_on_rc_lost: str
    execute_rc_lost_action: str | None
    take_off_security_height: float
    global_transitional_speed: float
    global_rth_height: float | None


@dataclass(frozen=True, slots=True)
class Route:
    namespace: str
    config: MissionConfig
    waylines: tuple[Wayline, ...]

    @property
    def waypoint_count(self) -> int:
        return sum(len(w.placemarks) for w in self.waylines)


# ------------------------------------------------------------------------------------------ fingerprint


def check_fingerprint(kmz: bytes, fingerprint: str) -> str:
    """The lowercase MD5 of ``kmz`` when it equals ``fingerprint`` (compared in lowercase, WAYLINE-NOTES §6);
    KmzError 314002 for an empty fingerprint, 314005 for a mismatch."""
    if not fingerprint.strip():
        raise KmzError(MD5_EMPTY, "the task's fingerprint (MD5) is empty")
    digest = hashlib.md5(kmz, usedforsecurity=False).hexdigest()
    if digest != fingerprint.strip().lower():
        raise KmzError(MD5_MISMATCH, "the KMZ's MD5 does not match the task's fingerprint")
    return digest


# ------------------------------------------------------------------------------------------------- zip


#: What zipfile raises for a damaged or unsupported archive (NotImplementedError: a compression method or
#: zip version it does not know; RuntimeError: encrypted entries; zlib.error: corrupt deflate data).
_ZIP_ERRORS = (
    zipfile.BadZipFile,
    zlib.error,
    OSError,
    ValueError,
    EOFError,
    NotImplementedError,
    RuntimeError,
)


def _bad_name(name: str) -> bool:
    if name.startswith(("/", "\\")) or "\\" in name or re.match(r"^[A-Za-z]:", name) or "\x00" in name:
        return True
    return any(part == ".." for part in name.split("/"))


def unpack_wpml(kmz: bytes, limits: Limits = Limits()) -> bytes:
    """The bytes of ``wpmz/waylines.wpml`` from a KMZ, within ``limits``; KmzError 314003 otherwise."""
    try:
        archive = zipfile.ZipFile(io.BytesIO(kmz))
    except _ZIP_ERRORS as exc:
        raise KmzError(FILE_FORMAT, f"not a KMZ (zip) file: {type(exc).__name__}") from None
    with archive:
        infos = archive.infolist()
        if len(infos) > limits.max_entries:
            raise KmzError(FILE_FORMAT, f"KMZ has {len(infos)} entries (limit {limits.max_entries})")
        declared = 0
        for info in infos:
            if _bad_name(info.filename):
                raise KmzError(FILE_FORMAT, "KMZ entry with a path outside the archive")
            declared += info.file_size
            if info.file_size > limits.max_entry_bytes or declared > limits.max_total_bytes:
                raise KmzError(FILE_FORMAT, "KMZ too large when unpacked (zip bomb?)")
            if info.compress_size and info.file_size / info.compress_size > limits.max_ratio:
                raise KmzError(FILE_FORMAT, "KMZ compression ratio too high (zip bomb?)")
        wanted = [i for i in infos if i.filename == WAYLINES_PATH]
        if not wanted:
            raise KmzError(FILE_FORMAT, f"KMZ without {WAYLINES_PATH}")
        info = wanted[0]
        try:
            with archive.open(info) as stream:
                # declared sizes can lie: read at most the limit + 1 and refuse what goes past it
                data = stream.read(limits.max_entry_bytes + 1)
        except _ZIP_ERRORS as exc:
            raise KmzError(FILE_FORMAT, f"unreadable {WAYLINES_PATH}: {type(exc).__name__}") from None
        if len(data) > limits.max_entry_bytes:
            raise KmzError(FILE_FORMAT, "KMZ too large when unpacked (zip bomb?)")
        return data


# ------------------------------------------------------------------------------------------------- XML


def _local(tag: Any) -> tuple[str, str]:
    if not isinstance(tag, str) or not tag.startswith("{"):
        return "", tag if isinstance(tag, str) else ""
    ns, _, name = tag[1:].partition("}")
    return ns, name


class _Reader:
    """Reads WPML children of one element by local name, in the file's WPML namespace only."""

    def __init__(self, ns: str) -> None:
        self.ns = ns

    def children(self, el: Element, name: str) -> list[Element]:
        tag = f"{{{self.ns}}}{name}"
        return [c for c in el if c.tag == tag]

    def child(self, el: Element, name: str) -> Element | None:
        found = el.find(f"{{{self.ns}}}{name}")
        return found

    def text(self, el: Element, name: str, where: str, *, required: bool = True) -> str | None:
        c = self.child(el, name)
        if c is None or c.text is None or not c.text.strip():
            if required:
                raise KmzError(FILE_FORMAT, f"{where}: wpml:{name} missing")
            return None
        return c.text.strip()

    def number(self, el: Element, name: str, where: str, *, required: bool = True) -> float | None:
        raw = self.text(el, name, where, required=required)
        if raw is None:
            return None
        try:
            value = float(raw)
        except ValueError:
            raise KmzError(FILE_FORMAT, f"{where}: wpml:{name} is not a number") from None
        if value != value or value in (float("inf"), float("-inf")):
            raise KmzError(FILE_FORMAT, f"{where}: wpml:{name} is not a finite number")
        return value

    def integer(self, el: Element, name: str, where: str, *, required: bool = True) -> int | None:
        raw = self.text(el, name, where, required=required)
        if raw is None:
            return None
        if not re.fullmatch(r"-?[0-9]{1,9}", raw):
            raise KmzError(FILE_FORMAT, f"{where}: wpml:{name} is not an integer")
        return int(raw)


def _wpml_namespace(root: Element) -> str:
    for el in root.iter():
        ns, _ = _local(el.tag)
        if ns.startswith("http://www.dji.com/wpmz/"):
            if not _WPML_NS.fullmatch(ns):
                raise KmzError(FILE_FORMAT, "unsupported WPML namespace (only wpmz/1.0.x)")
            return ns
    raise KmzError(FILE_FORMAT, "no WPML (http://www.dji.com/wpmz/1.0.x) elements")


def _action_group(r: _Reader, el: Element, where: str) -> ActionGroup:
    gid = r.integer(el, "actionGroupId", where)
    start = r.integer(el, "actionGroupStartIndex", where)
    end = r.integer(el, "actionGroupEndIndex", where)
    assert gid is not None and start is not None and end is not None
    where = f"{where} action group {gid}"
    trigger_el = r.child(el, "actionTrigger")
    if trigger_el is None:
        raise KmzError(FILE_FORMAT, f"{where}: wpml:actionTrigger missing")
    trigger = r.text(trigger_el, "actionTriggerType", where)
    trigger_param = r.number(trigger_el, "actionTriggerParam", where, required=False)
    actions = []
    for a in r.children(el, "action"):
        aid = r.integer(a, "actionId", where)
        func = r.text(a, "actionActuatorFunc", where)
        assert aid is not None and func is not None
        params: dict[str, str] = {}
        p = r.child(a, "actionActuatorFuncParam")
        if p is not None:
            for c in p:
                ns, name = _local(c.tag)
                if ns == r.ns and c.text is not None:
                    params[name] = c.text.strip()
        actions.append(Action(aid, func, params))
    if not actions:
        raise KmzError(FILE_FORMAT, f"{where}: no wpml:action")
    mode = r.text(el, "actionGroupMode", where, required=False) or "sequence"
    return ActionGroup(gid, start, end, mode, trigger or "", trigger_param, tuple(actions))


def _placemark(r: _Reader, el: Element, where: str) -> Placemark:
    index = r.integer(el, "index", where)
    assert index is not None
    where = f"waypoint {index}"
    point = el.find(f"{{{KML_NS}}}Point/{{{KML_NS}}}coordinates")
    if point is None or point.text is None:
        raise KmzError(FILE_FORMAT, f"{where}: Point/coordinates missing")
    parts = point.text.strip().split(",")
    try:
        lon, lat = float(parts[0]), float(parts[1])  # KML order: longitude first (WAYLINE-NOTES §8.1)
    except (ValueError, IndexError):
        raise KmzError(FILE_FORMAT, f"{where}: coordinates are not 'lon,lat'") from None
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        raise KmzError(FILE_FORMAT, f"{where}: coordinates out of range")
    height = r.number(el, "executeHeight", where)
    assert height is not None
    heading = r.child(el, "waypointHeadingParam")
    turn = r.child(el, "waypointTurnParam")
    groups = tuple(_action_group(r, g, where) for g in r.children(el, "actionGroup"))
    return Placemark(
        index=index,
        latitude=lat,
        longitude=lon,
        execute_height=height,
        speed=r.number(el, "waypointSpeed", where, required=False),
        heading_mode=r.text(heading, "waypointHeadingMode", where, required=False)
        if heading is not None
        else None,
        heading_angle=r.number(heading, "waypointHeadingAngle", where, required=False)
        if heading is not None
        else None,
        heading_path_mode=(
            r.text(heading, "waypointHeadingPathMode", where, required=False) if heading is not None else None
        ),
        turn_mode=r.text(turn, "waypointTurnMode", where, required=False) if turn is not None else None,
        turn_damping=r.number(turn, "waypointTurnDampingDist", where, required=False)
        if turn is not None
        else None,
        use_straight_line=r.integer(el, "useStraightLine", where, required=False),
        action_groups=groups,
    )


def parse_wpml(xml: bytes, *, max_waypoints: int = MAX_WAYPOINTS) -> Route:
    """A :class:`Route` from the bytes of ``waylines.wpml``; KmzError 314003 for anything refused."""
    try:
        root = fromstring(xml, forbid_dtd=True, forbid_entities=True, forbid_external=True)
    except DefusedXmlException as exc:
        raise KmzError(FILE_FORMAT, f"WPML refused: {type(exc).__name__} (no DTDs or entities)") from None
    except (ParseError, ValueError, LookupError) as exc:  # LookupError: an unknown declared encoding
        raise KmzError(FILE_FORMAT, f"WPML is not well-formed XML: {str(exc)[:80]}") from None
    if root.tag != f"{{{KML_NS}}}kml":
        raise KmzError(FILE_FORMAT, "root element is not KML 2.2's kml")
    r = _Reader(_wpml_namespace(root))
    doc = root.find(f"{{{KML_NS}}}Document")
    if doc is None:
        raise KmzError(FILE_FORMAT, "no Document")
    mc = r.child(doc, "missionConfig")
    if mc is None:
        raise KmzError(FILE_FORMAT, "no wpml:missionConfig")
    w = "missionConfig"
    exit_on_rc_lost = r.text(mc, "exitOnRCLost", w)
    config = MissionConfig(
        fly_to_wayline_mode=r.text(mc, "flyToWaylineMode", w) or "",
        finish_action=r.text(mc, "finishAction", w) or "",
        exit_on_rc_lost=exit_on_rc_lost or "",
        execute_rc_lost_action=r.text(
            mc, "executeRCLostAction", w, required=exit_on_rc_lost == "executeLostAction"
        ),
        take_off_security_height=r.number(mc, "takeOffSecurityHeight", w) or 0.0,
        global_transitional_speed=r.number(mc, "globalTransitionalSpeed", w) or 0.0,
        global_rth_height=r.number(mc, "globalRTHHeight", w, required=False),
    )
    waylines = []
    count = 0
    for folder in doc.findall(f"{{{KML_NS}}}Folder"):
        wid = r.integer(folder, "waylineId", "Folder")
        where = f"wayline {wid}"
        placemarks = []
        for pm in folder.findall(f"{{{KML_NS}}}Placemark"):
            count += 1
            if count > max_waypoints:
                raise KmzError(FILE_FORMAT, f"route has more than {max_waypoints} waypoints")
            placemarks.append(_placemark(r, pm, where))
        if not placemarks:
            raise KmzError(FILE_FORMAT, f"{where}: no Placemark")
        placemarks.sort(key=lambda p: p.index)
        if [p.index for p in placemarks] != list(range(len(placemarks))):
            raise KmzError(FILE_FORMAT, f"{where}: wpml:index must start at 0 and be contiguous")
        speed = r.number(folder, "autoFlightSpeed", where)
        start = r.child(folder, "startActionGroup")
        waylines.append(
            Wayline(
                wayline_id=wid or 0,
                template_id=r.integer(folder, "templateId", where, required=False) or 0,
                auto_flight_speed=speed or 0.0,
                execute_height_mode=r.text(folder, "executeHeightMode", where) or "",
                placemarks=tuple(placemarks),
                start_actions=(_action_group(r, start, where),) if start is not None else (),
            )
        )
    if not waylines:
        raise KmzError(FILE_FORMAT, "no wayline (Folder)")
    return Route(r.ns, config, tuple(waylines))


def load_route(kmz: bytes, fingerprint: str, limits: Limits = Limits()) -> Route:
    """Fingerprint, unpack, parse: the whole check of a downloaded KMZ."""
    check_fingerprint(kmz, fingerprint)
    return parse_wpml(unpack_wpml(kmz, limits))
