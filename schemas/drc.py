"""``data`` of the DRC (live flight control) messages of seed 003: ``drc/down`` and ``drc/up``, and the
newer ones of DJI's Cloud API docs for Dock 2/3 and RC Plus 2 (``stick_control``, ``drc_gimbal_reset``,
``drc_drone_state_push``, ``drc_batteries_info_push``; docs/cloud-api.md).

Owns stick commands, emergency stop, heartbeats and the high-rate pushes (obstacle distances, link delay,
osd, aircraft state, battery). Knows nothing about watchdogs or devices: the seq rules (reject older,
accept repeats) belong to the DRC session; this module only types the values.
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from pydantic import AliasChoices, Field

from .base import (
    Bool,
    Float,
    InboundModel,
    Int,
    IntEnumField,
    Latitude,
    Longitude,
    OutboundModel,
    Reason,
    Seq,
    Text,
    TimestampMs,
)
from .envelope import EmptyRequest
from .osd import Battery, ModeCode
from .results import ResultValue
from .services import GimbalReset

Distance = Annotated[int, Field(strict=True, ge=0, json_schema_extra={"x-unit": "mm"})]
DelayMs = Annotated[int, Field(strict=True, ge=0, json_schema_extra={"x-unit": "ms"})]


class DroneControl(InboundModel):
    """Stick command (seed 003 § DRC-flight control), sent at 5..10 Hz (web clients up to 20 Hz).

    Decisions: an absent axis is 0 (PROTOCOL-NOTES: "axes absent = 0"), so ``{"seq": 3}`` means "hover";
    ``seq`` may sit beside ``data`` (folded in by the envelope). Seed contradiction: ``h`` is written
    "min 5, max -4"; read as -4..5 m/s (climb up to 5, descend up to 4: DJI's own vertical limits).
    x, y: ±17 m/s; w: ±90 °/s. Out-of-range values are rejected (325001), never clamped.
    """

    envelope_fields: ClassVar[dict[str, tuple[str, ...]]] = {"seq": ("seq",)}

    seq: Seq = Field(description="Increasing; restarts at 0 when the operator changes axes.")
    x: Float = Field(
        default=0.0,
        ge=-17,
        le=17,
        json_schema_extra={"x-unit": "m/s"},
        description="Left/right speed (m/s); positive is left as seen from above, nose forward.",
    )
    y: Float = Field(
        default=0.0,
        ge=-17,
        le=17,
        json_schema_extra={"x-unit": "m/s"},
        description="Forward/backward speed (m/s); positive is forward.",
    )
    h: Float = Field(
        default=0.0,
        ge=-4,
        le=5,
        json_schema_extra={"x-unit": "m/s"},
        description="Vertical speed (m/s); positive is up. Seed's 'min 5, max -4' read as -4..5.",
    )
    w: Float = Field(
        default=0.0,
        ge=-90,
        le=90,
        json_schema_extra={"x-unit": "°/s"},
        description="Yaw rate (°/s); positive is clockwise.",
    )
    # DJI's Java Cloud SDK (DroneControlRequest) adds these two; its own ranges. Accepted and not used:
    # the gateway streams the set-point at drc.stream_hz and zeroes it after drc.stick_timeout itself.
    freq: Int | None = Field(
        default=None,
        ge=2,
        le=10,
        json_schema_extra={"x-unit": "Hz"},
        description="Java Cloud SDK: the rate the cloud sends sticks at. Accepted, not used (drc.stream_hz).",
    )
    delay_time: Int | None = Field(
        default=None,
        ge=100,
        le=1000,
        json_schema_extra={"x-unit": "ms"},
        description="Java Cloud SDK: how long one stick holds. Accepted, not used (drc.stick_timeout).",
    )


#: RC channel values of ``stick_control`` (DJI Cloud API, Dock 3 / RC Plus 2 "DRC-杆量控制"): 1024 ± 660.
STICK_MIN, STICK_NEUTRAL, STICK_MAX = 364, 1024, 1684
Channel = Annotated[
    int,
    Field(strict=True, ge=STICK_MIN, le=STICK_MAX, json_schema_extra={"x-unit": "RC channel value"}),
]


class StickControl(InboundModel):
    """Stick channels (DJI Cloud API docs, Dock 3 and RC Plus 2 § DRC-stick control, method
    ``stick_control``; docs/cloud-api.md has the links). Sent at 5..10 Hz; DJI's device sends no reply.

    Each channel is an RC value in 364..1684, 1024 neutral (1024 ± 660): ``roll`` (A channel) larger is
    right, ``pitch`` (E) larger is forward, ``throttle`` (T) larger is up, ``yaw`` (R) larger is clockwise.
    ``seq`` beside ``data`` is required (the same seq rules as ``drone_control``). An absent channel is
    neutral. ``gimbal_pitch`` appears in DJI's Dock 3 example but not in its table: accepted at 1024 only
    (the gimbal's pitch follows ``throttle`` on a gateway gimbal, docs/drc.md), any other value is refused
    (325001) rather than ignored.
    """

    envelope_fields: ClassVar[dict[str, tuple[str, ...]]] = {"seq": ("seq",)}

    seq: Seq = Field(description="Increasing; 0 restarts the sequence (as drone_control).")
    roll: Channel = Field(default=STICK_NEUTRAL, description="A channel: lateral; > 1024 right.")
    pitch: Channel = Field(default=STICK_NEUTRAL, description="E channel: longitudinal; > 1024 forward.")
    throttle: Channel = Field(default=STICK_NEUTRAL, description="T channel: vertical; > 1024 up.")
    yaw: Channel = Field(default=STICK_NEUTRAL, description="R channel: yaw; > 1024 clockwise.")
    gimbal_pitch: Annotated[int, Field(strict=True, ge=STICK_NEUTRAL, le=STICK_NEUTRAL)] | None = Field(
        default=None,
        description="In DJI's Dock 3 example only: accepted at the neutral 1024; other values are refused.",
    )


#: drc/down methods a device does not answer when it accepts them (DJI: "this protocol has no reply");
#: a refusal is answered.
SILENT_WHEN_ACCEPTED = frozenset({"stick_control"})


class DrcGimbalReset(GimbalReset):
    """Reset the gimbal over DRC (DJI Cloud API docs, RC Plus 2 § payload control - reset the gimbal,
    method ``drc_gimbal_reset``): the same ``payload_index`` and ``reset_mode`` as the ``gimbal_reset``
    service, ``seq`` beside ``data``; answered on drc/up with ``result``."""

    envelope_fields: ClassVar[dict[str, tuple[str, ...]]] = {"seq": ("seq",)}

    seq: Seq | None = None


class DroneControlOutput(OutboundModel):
    """``output`` of a drone_control reply: the seq it answers (and a reason on error)."""

    seq: Seq | None = None
    reason: Reason | None = None


class DroneControlReply(OutboundModel):
    """Reply to drone_control on drc/up. Non-0 when there is no flight/stick authority or the seq is too old
    (319033, with ``output.seq``)."""

    result: ResultValue
    output: DroneControlOutput | None = None


class DroneEmergencyStop(EmptyRequest):
    """Emergency stop: brake and hover (seed 003 § DRC-drone emergency stop). No parameters."""


class HeartBeat(InboundModel):
    """DRC heartbeat from the cloud (seed 003 § DRC-heart beat), about 1 Hz.

    Decisions (PROTOCOL-NOTES: real clouds differ): the send time may be ``timestamp`` or ``ts``, inside
    ``data`` or beside it (inside wins); ``seq`` inside (seed 003) or beside (the newer envelope, which wins
    when both are given). ``seq`` is optional (a heartbeat's job is liveness; some web clients send none).
    The gateway echoes both in ``data`` and, when the request had ``seq`` beside ``data``, ``seq`` there too.
    """

    envelope_fields: ClassVar[dict[str, tuple[str, ...]]] = {
        "seq": ("seq",),
        "timestamp": ("timestamp", "ts"),
    }

    seq: Seq | None = None
    timestamp: TimestampMs = Field(
        validation_alias=AliasChoices("timestamp", "ts"),
        description="The cloud's send time (ms); accepted as timestamp or ts.",
    )


class HeartBeatEcho(OutboundModel):
    """The gateway's heartbeat echo on drc/up: the received seq and send time, unchanged (the cloud computes
    the delay from them)."""

    seq: Seq | None = None
    timestamp: TimestampMs


class HsiInfoPush(OutboundModel):
    """Obstacle distances (seed 003 § DRC-obstacle avoidance information pushing), at hsi_frequency.

    Seed contradictions: the table names the array ``around_distances`` (360 points clockwise from the nose,
    mm) and the example ``around_distance`` with 5 points. Decision: accept both names in, always emit
    ``around_distances``; any length up to 360, points evenly spread clockwise over [0, 360) from the nose.
    The example also carries ``left/right/front/back/vertical/horizontal_enable/_work`` flags the table
    lacks: they are defined here as optional (DJI's later docs have them), so they may be sent.
    """

    up_distance: Distance
    down_distance: Distance
    around_distances: list[Distance] = Field(
        max_length=360,
        validation_alias=AliasChoices("around_distances", "around_distance"),
        description="Horizontal obstacle distances (mm), clockwise from the nose over [0, 360).",
    )
    up_enable: Bool
    up_work: Bool
    down_enable: Bool
    down_work: Bool
    left_enable: Bool | None = None
    left_work: Bool | None = None
    right_enable: Bool | None = None
    right_work: Bool | None = None
    front_enable: Bool | None = None
    front_work: Bool | None = None
    back_enable: Bool | None = None
    back_work: Bool | None = None
    vertical_enable: Bool | None = None
    vertical_work: Bool | None = None
    horizontal_enable: Bool | None = None
    horizontal_work: Bool | None = None


class LiveviewDelay(OutboundModel):
    """Delay of one video stream."""

    video_id: Text = Field(description="Stream id, e.g. 1581BN210004555439234/52-0-0/normal-0.")
    liveview_delay_time: DelayMs


class DelayInfoPush(OutboundModel):
    """Image-transmission link delays (seed 003 § DRC-delay information pushing)."""

    sdr_cmd_delay: DelayMs = Field(description="Command link delay (ms).")
    liveview_delay_list: list[LiveviewDelay] = Field(max_length=16)


Angle = Annotated[
    float, Field(strict=True, allow_inf_nan=False, ge=-180, le=180, json_schema_extra={"x-unit": "°"})
]
GimbalAngle = Annotated[
    float, Field(strict=True, allow_inf_nan=False, ge=-360, le=360, json_schema_extra={"x-unit": "°"})
]
Speed = Annotated[float, Field(strict=True, allow_inf_nan=False, json_schema_extra={"x-unit": "m/s"})]


class OsdInfoPush(OutboundModel):
    """High-rate osd during DRC (seed 003 § DRC-high frequency osd information pushing), at osd_frequency.

    The seed gives ``height`` the unit "degree": a typo; it is metres (the same ``height`` as in the osd).
    """

    attitude_head: Angle = Field(description="Heading (°), -180..180.")
    latitude: Latitude
    longitude: Longitude
    height: Float = Field(
        description="Altitude (m); the seed's unit 'degree' is a typo.", json_schema_extra={"x-unit": "m"}
    )
    speed_x: Speed
    speed_y: Speed
    speed_z: Speed
    gimbal_pitch: GimbalAngle
    gimbal_roll: GimbalAngle
    gimbal_yaw: GimbalAngle
    elevation: Float | None = Field(
        default=None,
        description="Height above the take-off point (m): the osd's elevation, read by RC Plus clients.",
        json_schema_extra={"x-unit": "m"},
    )


class DrcDroneStatePush(OutboundModel):
    """Aircraft state during DRC (DJI Cloud API docs, Dock 2/3 and RC Plus 2 § report aircraft state,
    method ``drc_drone_state_push`` on drc/up), at ``drc.drone_state_hz``.

    ``mode_code`` is the osd's. DJI's table also lists ``stealth_state``, ``night_lights_state``,
    ``landing_type`` and ``landing_protection_type``: optional here, and left out by a device that has no
    such thing to report (the Onboard SDK flight controller has no stealth mode, night lights or landing
    protection), never invented.
    """

    mode_code: IntEnumField[ModeCode] = Field(description="Aircraft state, as in the osd.")
    stealth_state: Bool | None = None
    night_lights_state: Bool | None = None
    landing_type: Annotated[int, Field(strict=True, ge=0, le=4)] | None = None
    landing_protection_type: Annotated[int, Field(strict=True, ge=0, le=3)] | None = None


class DrcBatteriesInfoPush(Battery):
    """Battery during DRC (method ``drc_batteries_info_push`` on drc/up), at ``drc.batteries_hz``.

    DJI's public Cloud API pages do not define this push (docs/cloud-api.md says where we looked); clients
    written for RC Plus read ``data.capacity_percent``. Decision: the aircraft osd's ``battery`` struct
    (``capacity_percent``, ``remain_flight_time``, ``batteries[]``), the Cloud API's own names.
    """


__all__ = [
    "SILENT_WHEN_ACCEPTED",
    "STICK_MAX",
    "STICK_MIN",
    "STICK_NEUTRAL",
    "DelayInfoPush",
    "DrcBatteriesInfoPush",
    "DrcDroneStatePush",
    "DrcGimbalReset",
    "DroneControl",
    "DroneControlOutput",
    "DroneControlReply",
    "DroneEmergencyStop",
    "HeartBeat",
    "HeartBeatEcho",
    "HsiInfoPush",
    "LiveviewDelay",
    "OsdInfoPush",
    "StickControl",
]
