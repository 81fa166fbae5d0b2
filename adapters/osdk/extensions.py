"""Extension services for the rest of seed 004 that the Cloud API cannot name: waypoint pause and idle
velocity, mission download, hotpoint, follow-me, landing, go-home and authority release.

``x_osdk_<name>``, routed by capability (the aircraft). Units are the Cloud API's: degrees, metres
relative to the take-off point (the ground-station convention), seconds; the adapter converts
degrees to the wire's radians.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import Field

from schemas.base import Bool, Float, InboundModel, Int, Latitude, Longitude, OutboundModel
from schemas.envelope import EmptyRequest, ErrorOutput, InboundResult, ResultReply
from schemas.results import ResultValue

__all__ = ["EVENT_EXTENSIONS", "EXTENSIONS", "SafetyNotify"]


class Pause(InboundModel):
    pause: Bool = Field(description="true: pause, false: resume")


class IdleVelocity(InboundModel):
    velocity: Float = Field(ge=-15, le=15, description="cruise speed (m/s)")


class IdleVelocityOut(OutboundModel):
    idle_velocity: Float


class IdleVelocityReply(OutboundModel):
    result: ResultValue
    output: IdleVelocityOut | ErrorOutput | None = None


class MissionOut(OutboundModel):
    length: Int
    idle_velocity: Float
    action_on_finish: Int
    points: list[dict[str, Any]]


class MissionReply(OutboundModel):
    result: ResultValue
    output: MissionOut | ErrorOutput | None = None


class HotpointStart(InboundModel):
    """Circle a point (seed 004 0x03 0x20)."""

    latitude: Latitude
    longitude: Longitude
    altitude: Float = Field(ge=5, le=500, description="above the take-off point (m)")
    radius: Float = Field(ge=5, le=500, description="m")
    angle_rate: Float = Field(ge=0, le=30, description="°/s")
    clockwise: Bool = True
    start_point: Int = Field(default=4, ge=0, le=4, description="0 N, 1 S, 2 W, 3 E, 4 nearest")
    yaw_mode: Int = Field(
        default=1, ge=0, le=4, description="0 velocity, 1 inside, 2 outside, 3 RC, 4 start yaw"
    )


class HotpointVelocity(InboundModel):
    clockwise: Bool = True
    velocity: Float = Field(ge=0, le=30, description="angular rate (°/s)")


class HotpointRadius(InboundModel):
    radius: Float = Field(ge=5, le=500, description="m")


class HotpointAutoRadius(InboundModel):
    enable: Bool
    rate: Int = Field(ge=-128, le=127, description="radius change rate")


class HotpointOut(OutboundModel):
    max_radius: Float | None = None


class HotpointReply(OutboundModel):
    result: ResultValue
    output: HotpointOut | ErrorOutput | None = None


class HotpointDownloadOut(OutboundModel):
    latitude: Float
    longitude: Float
    altitude: Float
    radius: Float
    angle_rate: Float
    clockwise: Bool


class HotpointDownloadReply(OutboundModel):
    result: ResultValue
    output: HotpointDownloadOut | ErrorOutput | None = None


class FollowMeStart(InboundModel):
    """Follow a target (seed 004 0x03 0x30), starting at its first known position."""

    latitude: Latitude
    longitude: Longitude
    altitude: Int = Field(ge=0, le=65535, description="m")
    point_to_target: Bool = True


class FollowMeTarget(InboundModel):
    """The target's new position (seed 004 0x03 0x33; no ACK)."""

    latitude: Latitude
    longitude: Longitude
    altitude: Int = Field(ge=0, le=65535, description="m")


#: (method, request model, reply model, summary)
EXTENSIONS: tuple[tuple[str, type[InboundModel], type[OutboundModel], str], ...] = (
    ("x_osdk_waypoint_pause", Pause, ResultReply, "OSDK: pause or resume the waypoint mission (0x03 0x13)"),
    (
        "x_osdk_waypoint_idle_velocity_set",
        IdleVelocity,
        IdleVelocityReply,
        "OSDK: mission cruise speed (0x03 0x16)",
    ),
    (
        "x_osdk_waypoint_idle_velocity_get",
        EmptyRequest,
        IdleVelocityReply,
        "OSDK: read cruise speed (0x03 0x17)",
    ),
    (
        "x_osdk_mission_download",
        EmptyRequest,
        MissionReply,
        "OSDK: download the waypoint mission (0x03 0x14/0x15)",
    ),
    ("x_osdk_hotpoint_start", HotpointStart, HotpointReply, "OSDK: upload and start a hotpoint (0x03 0x20)"),
    ("x_osdk_hotpoint_stop", EmptyRequest, ResultReply, "OSDK: stop the hotpoint (0x03 0x21)"),
    ("x_osdk_hotpoint_pause", Pause, ResultReply, "OSDK: pause or resume the hotpoint (0x03 0x22)"),
    (
        "x_osdk_hotpoint_velocity_set",
        HotpointVelocity,
        ResultReply,
        "OSDK: hotpoint angular rate (0x03 0x23)",
    ),
    ("x_osdk_hotpoint_radius_set", HotpointRadius, ResultReply, "OSDK: hotpoint radius (0x03 0x24)"),
    ("x_osdk_hotpoint_reset_yaw", EmptyRequest, ResultReply, "OSDK: reset the hotpoint yaw (0x03 0x25)"),
    (
        "x_osdk_hotpoint_download",
        EmptyRequest,
        HotpointDownloadReply,
        "OSDK: download the hotpoint (0x03 0x26)",
    ),
    (
        "x_osdk_hotpoint_auto_radius",
        HotpointAutoRadius,
        ResultReply,
        "OSDK: hotpoint auto radius (0x03 0x27)",
    ),
    ("x_osdk_followme_start", FollowMeStart, ResultReply, "OSDK: start follow-me (0x03 0x30)"),
    ("x_osdk_followme_stop", EmptyRequest, ResultReply, "OSDK: stop follow-me (0x03 0x31)"),
    ("x_osdk_followme_pause", Pause, ResultReply, "OSDK: pause or resume follow-me (0x03 0x32)"),
    ("x_osdk_followme_target", FollowMeTarget, ResultReply, "OSDK: follow-me target position (0x03 0x33)"),
    ("x_osdk_land", EmptyRequest, ResultReply, "OSDK: land now (0x01 0x01 task 2)"),
    ("x_osdk_go_home", EmptyRequest, ResultReply, "OSDK: return to home (0x01 0x01 task 6)"),
    ("x_osdk_authority_release", EmptyRequest, ResultReply, "OSDK: release SDK control (0x01 0x00 0)"),
)


class SafetyNotify(OutboundModel):
    """What the gateway found the flight controller doing, against what it believed, and what it did:
    ``stopped`` (in the air under SDK control with nothing driving it, after a restart or a reconnect:
    zero velocity and the brake were sent), ``mission_adopted`` (a waypoint mission was flying that this
    process had not started: it is followed and reported), ``mission_ended`` (the flight controller ended
    a task's mission: an emergency stop, the RC taking over, a mission it dropped), ``landing`` and
    ``returning_home`` (a task failed after the take-off: the aircraft is not left where it failed)."""

    action: Literal["stopped", "mission_adopted", "mission_ended", "landing", "returning_home"] = Field(
        description="What happened."
    )
    reason: str = Field(max_length=300, description="What the flight controller reported, in words.")
    task_id: str = Field(max_length=64, description="The task's flight_id or fly_to_id; empty if none.")


EVENT_EXTENSIONS: tuple[tuple[str, type[OutboundModel], type[InboundModel], str], ...] = (
    ("x_osdk_safety_notify", SafetyNotify, InboundResult, "OSDK: the flight controller's truth won"),
)
