"""The method registry: (topic kind, method) → request and reply models, and one-call validation.

Owns the table of every method in seed 003 (``SEED_METHODS``), the device telemetry profiles
(``TELEMETRY``) and ``Registry``, which turns them into discriminated unions so a dispatcher validates a raw
payload with one call. Knows nothing about devices: adapters register their extension methods
(``x_<family>_<name>``) through ``Registry.register`` instead of editing these tables.

Dispatcher use::

    registry = default_registry()                       # built once at start-up, passed down
    kind, sn = parse_topic(topic_name)
    try:
        request = registry.validate(kind, payload)      # bytes → e.g. ServicesFlyToPoint (typed .data)
    except ValidationError as exc:
        reply = error_reply_from_validation(kind, payload, exc, timestamp=now_ms, gateway=gateway_sn)
        ...                                             # publish reply (if not None) on reply_kind(kind)
    ...
    reply = reply_for(request, ResultCode.SUCCESS, timestamp=now_ms, gateway=gateway_sn)
    publish(topic(reply_kind(kind), sn), reply.model_dump_json())
"""

from __future__ import annotations

import enum
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Annotated, Any, Union

from pydantic import Field, PlainValidator, TypeAdapter
from pydantic_core import PydanticCustomError

from .base import EXTENSION_PREFIX, ContractModel, InboundModel, OutboundModel
from .cloud_control import (
    CloudControlAuthNotify,
    CloudControlAuthRequest,
    CloudControlRelease,
    CloudControlReply,
)
from .drc import (
    DelayInfoPush,
    DrcBatteriesInfoPush,
    DrcDroneStatePush,
    DrcGimbalReset,
    DroneControl,
    DroneControlReply,
    DroneEmergencyStop,
    HeartBeat,
    HeartBeatEcho,
    HsiInfoPush,
    OsdInfoPush,
    StickControl,
)
from .envelope import (
    METHOD_BASES,
    Envelope,
    InboundResult,
    PropertySetMessage,
    PropertySetReplyMessage,
    ResultReply,
    TelemetryMessage,
    message_class,
    telemetry_class,
)
from .events import DrcStatusNotify, FlyToPointProgress, JoystickInvalidNotify, TakeoffToPointProgress
from .live import LiveLensChange, LiveSetQuality, LiveStartPush, LiveStopPush
from .osd import AircraftOsd, GatewayOsd, GimbalOsd, RobotOsd
from .services import (
    CameraAim,
    CameraFocalLengthSet,
    CameraModeSwitch,
    CameraPhotoTake,
    CameraRecordingStart,
    CameraRecordingStop,
    CameraScreenDrag,
    DrcModeEnter,
    DrcModeEnterReply,
    DrcModeExit,
    FlightAuthorityGrab,
    FlyToPoint,
    FlyToPointStop,
    GimbalReset,
    PayloadAuthorityGrab,
    TakeoffToPoint,
)
from .state import AircraftState, AuthorityState, GatewayState, RobotState
from .status import UpdateTopo
from .topics import TOPICS, Direction, TopicKind, reply_kind
from .wayline import (
    FlighttaskExecute,
    FlighttaskPause,
    FlighttaskPrepare,
    FlighttaskPrepareReply,
    FlighttaskProgress,
    FlighttaskReady,
    FlighttaskRecovery,
    FlighttaskResourceGet,
    FlighttaskResourceGetReply,
    FlighttaskUndo,
    ReturnHome,
    ReturnHomeCancel,
    ReturnHomeInfo,
)


class Profile(enum.StrEnum):
    """Which body a device publishes on osd/state."""

    GATEWAY = "gateway"
    AIRCRAFT = "aircraft"
    GIMBAL = "gimbal"
    ROBOT = "robot"


@dataclass(frozen=True, slots=True)
class MethodSpec:
    """One method: the kind its request travels on, its body, its reply's body (None: nobody answers)."""

    kind: TopicKind
    method: str
    data: type[ContractModel]
    reply: type[ContractModel] | None
    summary: str
    source: str = "extension"

    @property
    def direction(self) -> Direction:
        return TOPICS[self.kind].direction

    @property
    def reply_kind(self) -> TopicKind | None:
        return reply_kind(self.kind) if self.reply is not None else None

    @property
    def message(self) -> type[Envelope]:
        """The request envelope class (``method`` is a Literal, ``data`` is ``self.data``)."""
        return message_class(self.kind, self.method, self.data, self.reply)

    @property
    def reply_message(self) -> type[Envelope] | None:
        """The reply envelope class, or None."""
        if self.reply is None:
            return None
        return message_class(reply_kind(self.kind), self.method, self.reply)


def _seed(kind: TopicKind, method: str, data: type, reply: type | None, section: str) -> MethodSpec:
    return MethodSpec(TopicKind(kind), method, data, reply, section, f"seed 003 § {section}")


def _dji(kind: TopicKind, method: str, data: type, reply: type | None, section: str) -> MethodSpec:
    """A method of DJI's public Cloud API docs beyond seed 003 (docs/cloud-api.md has the pages)."""
    return MethodSpec(TopicKind(kind), method, data, reply, section, f"DJI Cloud API docs § {section}")


_S, _E, _DD, _DU = TopicKind.SERVICES, TopicKind.EVENTS, TopicKind.DRC_DOWN, TopicKind.DRC_UP

#: Every method of seed 003 (plus update_topo from PROTOCOL-NOTES and the newer DRC methods of DJI's docs):
#: kind, method, body, reply body, section.
SEED_METHODS: tuple[MethodSpec, ...] = (
    _seed(
        _E, "fly_to_point_progress", FlyToPointProgress, InboundResult, "Event notification of flyto result"
    ),
    _seed(
        _E,
        "takeoff_to_point_progress",
        TakeoffToPointProgress,
        InboundResult,
        "Event notification of one-key taking off result",
    ),
    _seed(_E, "drc_status_notify", DrcStatusNotify, InboundResult, "Notification of DRC link state"),
    _seed(
        _E,
        "joystick_invalid_notify",
        JoystickInvalidNotify,
        InboundResult,
        "Reason notification of invalid Joystick control",
    ),
    _seed(_S, "flight_authority_grab", FlightAuthorityGrab, ResultReply, "Flight control authority grabbing"),
    _seed(
        _S, "payload_authority_grab", PayloadAuthorityGrab, ResultReply, "Payload control authority grabbing"
    ),
    _seed(_S, "drc_mode_enter", DrcModeEnter, DrcModeEnterReply, "Enter the live flight controls mode"),
    _seed(_S, "drc_mode_exit", DrcModeExit, ResultReply, "Exit the live flight controls mode"),
    _seed(_S, "takeoff_to_point", TakeoffToPoint, ResultReply, "One-key taking off"),
    _seed(_S, "fly_to_point", FlyToPoint, ResultReply, "flyto target point"),
    _seed(_S, "fly_to_point_stop", FlyToPointStop, ResultReply, "End the task of flying to target point"),
    _seed(
        _S, "camera_mode_switch", CameraModeSwitch, ResultReply, "Payload control - switch the camera mode"
    ),
    _seed(_S, "camera_photo_take", CameraPhotoTake, ResultReply, "Payload control - take single photo"),
    _seed(
        _S, "camera_recording_start", CameraRecordingStart, ResultReply, "Payload control - start recording"
    ),
    _seed(_S, "camera_recording_stop", CameraRecordingStop, ResultReply, "Payload control - stop recording"),
    _seed(_S, "camera_screen_drag", CameraScreenDrag, ResultReply, "Payload control - drag screen"),
    _seed(_S, "camera_aim", CameraAim, ResultReply, "Payload control - double tab to become AIM"),
    _seed(_S, "camera_focal_length_set", CameraFocalLengthSet, ResultReply, "Payload control - zoom"),
    _seed(_S, "gimbal_reset", GimbalReset, ResultReply, "Payload control - reset the gimbal"),
    _seed(_DD, "drone_control", DroneControl, DroneControlReply, "DRC-flight control"),
    _seed(_DD, "drone_emergency_stop", DroneEmergencyStop, ResultReply, "DRC-drone emergency stop"),
    _seed(_DD, "heart_beat", HeartBeat, HeartBeatEcho, "DRC-heart beat"),
    _seed(_DU, "hsi_info_push", HsiInfoPush, None, "DRC-obstacle avoidance information pushing"),
    _seed(
        _DU,
        "delay_info_push",
        DelayInfoPush,
        None,
        "DRC-delay information pushing of image transmission link",
    ),
    _seed(_DU, "osd_info_push", OsdInfoPush, None, "DRC-high frequency osd information pushing"),
    _dji(_DD, "stick_control", StickControl, DroneControlReply, "DRC-stick control (Dock 3, RC Plus 2)"),
    _dji(_DD, "drc_gimbal_reset", DrcGimbalReset, ResultReply, "Reset the gimbal (RC Plus 2)"),
    _dji(_DU, "drc_drone_state_push", DrcDroneStatePush, None, "Report aircraft state (Dock 2/3, RC Plus 2)"),
    _dji(_DU, "drc_batteries_info_push", DrcBatteriesInfoPush, None, "Battery push (RC Plus clients)"),
    MethodSpec(
        TopicKind.STATUS,
        "update_topo",
        UpdateTopo,
        InboundResult,
        "Device topology update",
        "PROTOCOL-NOTES § Topology first",
    ),
)


def _wayline(kind: TopicKind, method: str, data: type, reply: type | None, summary: str) -> MethodSpec:
    return MethodSpec(TopicKind(kind), method, data, reply, summary, "Cloud API wayline (WAYLINE-NOTES)")


#: The wayline (route) methods of a dock-like gateway: DJI's dock pages, not seed 003 (schemas/wayline.py).
WAYLINE_METHODS: tuple[MethodSpec, ...] = (
    _wayline(_S, "flighttask_prepare", FlighttaskPrepare, FlighttaskPrepareReply, "Issue a wayline task"),
    _wayline(_S, "flighttask_execute", FlighttaskExecute, ResultReply, "Execute a prepared wayline task"),
    _wayline(_S, "flighttask_undo", FlighttaskUndo, ResultReply, "Cancel wayline tasks not yet started"),
    _wayline(_S, "flighttask_pause", FlighttaskPause, ResultReply, "Pause the running wayline"),
    _wayline(_S, "flighttask_recovery", FlighttaskRecovery, ResultReply, "Resume the paused wayline"),
    _wayline(_S, "return_home", ReturnHome, ResultReply, "Return to home"),
    _wayline(_S, "return_home_cancel", ReturnHomeCancel, ResultReply, "Cancel the return to home"),
    _wayline(_E, "flighttask_progress", FlighttaskProgress, InboundResult, "Wayline task progress"),
    _wayline(_E, "flighttask_ready", FlighttaskReady, InboundResult, "Conditional tasks ready"),
    _wayline(_E, "return_home_info", ReturnHomeInfo, InboundResult, "Planned path home"),
    _wayline(
        TopicKind.REQUESTS,
        "flighttask_resource_get",
        FlighttaskResourceGet,
        FlighttaskResourceGetReply,
        "Ask the cloud for a fresh KMZ URL",
    ),
)

#: Cloud-control authorisation of the RC Plus 2 / RC Pro (DJI Pilot 2 "DRC" page; docs/cloud-api.md).
CLOUD_CONTROL_METHODS: tuple[MethodSpec, ...] = (
    _dji(
        _S,
        "cloud_control_auth_request",
        CloudControlAuthRequest,
        CloudControlReply,
        "Request cloud control authorization (RC Plus 2)",
    ),
    _dji(
        _S,
        "cloud_control_release",
        CloudControlRelease,
        CloudControlReply,
        "Release cloud control (RC Plus 2)",
    ),
    _dji(
        _E,
        "cloud_control_auth_notify",
        CloudControlAuthNotify,
        InboundResult,
        "Authorization result notification (RC Plus 2)",
    ),
)

#: Live streaming (DJI's live page, Cloud-API-Doc ``.../20.dock/10.dock2/30.live.md``; schemas/live.py).
LIVE_METHODS: tuple[MethodSpec, ...] = (
    _dji(_S, "live_start_push", LiveStartPush, ResultReply, "Start live streaming"),
    _dji(_S, "live_stop_push", LiveStopPush, ResultReply, "Stop live streaming"),
    _dji(_S, "live_set_quality", LiveSetQuality, ResultReply, "Set live streaming quality"),
    _dji(_S, "live_lens_change", LiveLensChange, ResultReply, "Set live streaming lens"),
)

#: The osd/state body each device profile publishes.
TELEMETRY: dict[tuple[TopicKind, Profile], type[ContractModel]] = {
    (TopicKind.OSD, Profile.GATEWAY): GatewayOsd,
    (TopicKind.OSD, Profile.AIRCRAFT): AircraftOsd,
    (TopicKind.OSD, Profile.GIMBAL): GimbalOsd,
    (TopicKind.OSD, Profile.ROBOT): RobotOsd,
    (TopicKind.STATE, Profile.GATEWAY): GatewayState,
    (TopicKind.STATE, Profile.AIRCRAFT): AircraftState,
    (TopicKind.STATE, Profile.GIMBAL): AuthorityState,
    (TopicKind.STATE, Profile.ROBOT): RobotState,
}

#: Kinds a method may be registered on (replies are derived from their request's entry).
REQUEST_KINDS = frozenset(
    {
        TopicKind.SERVICES,
        TopicKind.EVENTS,
        TopicKind.REQUESTS,
        TopicKind.STATUS,
        TopicKind.DRC_DOWN,
        TopicKind.DRC_UP,
    }
)


_METHOD = re.compile(r"^[a-z][a-z0-9_]{0,63}$")


def _no_method(value: Any) -> Any:
    # The union of a kind with no registered method: every message is an unknown method.
    if not isinstance(value, dict):
        raise PydanticCustomError("model_type", "Input should be an object")
    if "method" not in value:
        raise PydanticCustomError("union_tag_not_found", "Unable to extract tag using discriminator 'method'")
    raise PydanticCustomError("union_tag_invalid", "No method is registered on this topic")


class Registry:
    """Methods by (kind, method); validates raw payloads of any kind with one call.

    Build it once (``default_registry()``), let adapters ``register`` their extension methods, then pass it to
    the dispatcher. Lookups are plain dict reads; the TypeAdapter of a kind is built on first use and rebuilt
    after a registration.
    """

    def __init__(self, specs: Iterable[MethodSpec] = ()) -> None:
        self._specs: dict[tuple[TopicKind, str], MethodSpec] = {}
        self._messages: dict[tuple[TopicKind, str], type[Envelope]] = {}
        self._adapters: dict[TopicKind, TypeAdapter[Any]] = {}
        self._telemetry_adapters: dict[tuple[TopicKind, Profile], TypeAdapter[Any]] = {}
        for spec in specs:
            self._add(spec, replace=False)

    # ------------------------------------------------------------------------------------------ building

    def register(
        self,
        kind: TopicKind,
        method: str,
        data: type[ContractModel],
        reply: type[ContractModel] | None = None,
        *,
        summary: str,
        replace: bool = False,
    ) -> MethodSpec:
        """Add an extension method.

        ``method`` must start with ``x_`` (``x_<family>_<name>``). ``data`` must be an ``InboundModel`` for
        kinds the cloud sends (services, drc/down) and an ``OutboundModel`` for kinds the gateway sends, and
        ``reply`` the other way round. Raises ``ValueError`` on a clash.
        """
        if not method.startswith(EXTENSION_PREFIX):
            raise ValueError(f"extension method {method!r} must start with {EXTENSION_PREFIX!r}")
        return self._add(
            MethodSpec(TopicKind(kind), method, data, reply, summary, "extension"), replace=replace
        )

    def _add(self, spec: MethodSpec, *, replace: bool) -> MethodSpec:
        if not _METHOD.fullmatch(spec.method):
            raise ValueError(f"method {spec.method!r} must be lower-case snake case (a-z, 0-9, _), 1-64 long")
        if spec.kind not in REQUEST_KINDS:
            raise ValueError(
                f"methods are registered on {sorted(k.value for k in REQUEST_KINDS)}, not {spec.kind!r}"
            )
        if spec.kind is TopicKind.DRC_UP and spec.reply is not None:
            raise ValueError("drc/up pushes have no reply")
        inbound = spec.direction is Direction.DOWN
        if not issubclass(spec.data, InboundModel if inbound else OutboundModel):
            raise ValueError(f"{spec.method}: data must be an {'Inbound' if inbound else 'Outbound'}Model")
        if spec.reply is not None and not issubclass(spec.reply, OutboundModel if inbound else InboundModel):
            raise ValueError(f"{spec.method}: reply must be an {'Outbound' if inbound else 'Inbound'}Model")
        entries: list[tuple[TopicKind, str, type[Envelope] | None]] = [(spec.kind, spec.method, spec.message)]
        if spec.reply is not None:
            entries.append((reply_kind(spec.kind), spec.method, spec.reply_message))
        old = self._specs.get((spec.kind, spec.method))
        replaceable = (old.message, old.reply_message) if (replace and old is not None) else ()
        for kind, method, _ in entries:
            taken = self._messages.get((kind, method))
            if taken is not None and taken not in replaceable:
                raise ValueError(f"{method!r} is already registered on {kind.value!r}")
        if old is not None:
            for old_kind in (old.kind, old.reply_kind):
                if old_kind is not None:
                    self._messages.pop((old_kind, old.method), None)
                    self._adapters.pop(old_kind, None)
        self._specs[(spec.kind, spec.method)] = spec
        for kind, method, cls in entries:
            assert cls is not None
            self._messages[(kind, method)] = cls
            self._adapters.pop(kind, None)
        return spec

    def copy(self) -> Registry:
        """An independent registry with the same entries."""
        return Registry(self._specs.values())

    # ------------------------------------------------------------------------------------------- lookups

    def specs(self, kind: TopicKind | None = None) -> tuple[MethodSpec, ...]:
        """Every spec, or those whose request travels on ``kind``, in registration order."""
        return tuple(s for s in self._specs.values() if kind is None or s.kind == kind)

    def spec(self, kind: TopicKind, method: str) -> MethodSpec | None:
        """The spec whose request travels on ``kind``, or None."""
        return self._specs.get((TopicKind(kind), method))

    def methods(self, kind: TopicKind) -> tuple[str, ...]:
        """Methods of every message that travels on ``kind`` (requests, replies and pushes)."""
        kind = TopicKind(kind)
        return tuple(method for (k, method) in self._messages if k == kind)

    def message_class(self, kind: TopicKind, method: str) -> type[Envelope]:
        """The envelope class of ``method`` on ``kind``; ``KeyError`` if not registered."""
        try:
            return self._messages[(TopicKind(kind), method)]
        except KeyError:
            raise KeyError(f"no method {method!r} on {TopicKind(kind).value!r}") from None

    def telemetry_class(self, kind: TopicKind, profile: Profile | str) -> type[TelemetryMessage]:
        """The osd/state envelope class of a device profile; ``KeyError`` if that profile has none."""
        profile = Profile(profile)
        body = TELEMETRY[(TopicKind(kind), profile)]
        return telemetry_class(TopicKind(kind), profile.value, body)

    # ------------------------------------------------------------------------------------------ validating

    def adapter(self, kind: TopicKind) -> TypeAdapter[Any]:
        """The TypeAdapter of every message on ``kind``, discriminated on ``method``."""
        kind = TopicKind(kind)
        adapter = self._adapters.get(kind)
        if adapter is None:
            if kind is TopicKind.PROPERTY_SET:
                adapter = TypeAdapter(PropertySetMessage)
            elif kind is TopicKind.PROPERTY_SET_REPLY:
                adapter = TypeAdapter(PropertySetReplyMessage)
            elif kind not in METHOD_BASES:
                raise ValueError(f"{kind.value!r} has no method; use telemetry_class(kind, profile)")
            else:
                classes = tuple(cls for (k, _), cls in self._messages.items() if k == kind)
                if classes:
                    union: Any = Annotated[Union[classes], Field(discriminator="method")]  # noqa: UP007
                    adapter = TypeAdapter(union)
                    # A union of models made by create_model in other modules can be left "not fully
                    # defined" by pydantic until rebuilt; rebuilding once here makes it usable at once.
                    adapter.rebuild(raise_errors=True)
                else:
                    adapter = TypeAdapter(Annotated[Any, PlainValidator(_no_method)])
            self._adapters[kind] = adapter
        return adapter

    def validate(
        self,
        kind: TopicKind,
        payload: bytes | bytearray | str | Mapping[str, Any],
        *,
        profile: Profile | str | None = None,
    ) -> Any:
        """Validate a raw payload (JSON bytes/str, or an already parsed mapping) of ``kind`` in one call.

        Returns the typed envelope (e.g. ``ServicesFlyToPoint`` with ``.data: FlyToPoint``). Any problem with
        the payload, including bad JSON and an unknown method, raises ``pydantic.ValidationError`` and only
        that. osd/state need ``profile`` (they carry no method); ``ValueError`` without it.
        """
        kind = TopicKind(kind)
        if kind in (TopicKind.OSD, TopicKind.STATE):
            if profile is None:
                raise ValueError(f"{kind.value!r} carries no method: pass profile=")
            key = (kind, Profile(profile))
            adapter = self._telemetry_adapters.get(key)
            if adapter is None:
                adapter = self._telemetry_adapters[key] = TypeAdapter(self.telemetry_class(kind, profile))
        else:
            adapter = self.adapter(kind)
        if isinstance(payload, (bytes, bytearray, str)):
            return adapter.validate_json(payload)
        return adapter.validate_python(payload)

    def build(self, kind: TopicKind, method: str, data: Any, **envelope: Any) -> Envelope:
        """Make an outbound message.

        ``build(EVENTS, "drc_status_notify", {...}, tid=, bid=, timestamp=, gateway=, need_reply=1)``.
        Raises ``ValidationError`` when ``data`` or the envelope break the contract.
        """
        cls = self.message_class(kind, method)
        return cls.model_validate({**envelope, "method": method, "data": data})


def default_registry() -> Registry:
    """A new registry holding every method of seed 003 (and update_topo), the wayline methods and
    cloud-control authorisation and live streaming."""
    return Registry((*SEED_METHODS, *WAYLINE_METHODS, *CLOUD_CONTROL_METHODS, *LIVE_METHODS))
