"""Live streaming: the ``live_*`` services' ``data``; the gateway's ``live_capacity`` / ``live_status`` state.

Owns the shapes of DJI's live-streaming pages (Cloud-API-Doc ``docs/en/60.api-reference/20.dock-to-cloud/
00.mqtt/20.dock/10.dock2/30.live.md`` for the services, ``.../10.dock2/00.properties.md`` for the two state
properties) and of DJI's reference cloud (DJI-Cloud-API-Demo ``cloudapi/livestream``: ``LiveTypeEnum``,
``VideoId``, ``LiveCapacity``): ``url_type``, ``video_id`` ``{sn}/{camera_index}/{video_index}``,
``video_quality`` 0-4, ``video_type`` (normal, wide, zoom, ir). Knows nothing about media engines.

Tolerant reader: ``url_type`` and ``video_quality`` are read as integers or integral strings (DJI's
reference cloud sends enums as JSON numbers, other clouds as strings); ``url`` is opaque text (for GB28181
and Agora it is ``&``-joined ``key=value`` pairs) and a secret (an RTMP stream key sits in it): it is masked
in every log line. Strict writer: what the gateway publishes is checked field by field.
"""

from __future__ import annotations

import enum
import re
from typing import Annotated, Any

from pydantic import Field, StringConstraints, field_validator

from .base import InboundModel, Int, IntEnumField, OutboundModel, PayloadIndex, Secret, SerialNumber

__all__ = [
    "LiveCapacity",
    "LiveCapacityCamera",
    "LiveCapacityDevice",
    "LiveCapacityVideo",
    "LiveLensChange",
    "LiveSetQuality",
    "LiveStartPush",
    "LiveStatusEntry",
    "LiveStopPush",
    "UrlType",
    "VideoId",
    "VideoQuality",
    "VideoType",
    "parse_video_id",
]


class UrlType(enum.IntEnum):
    """``url_type`` (DJI: 0 Agora, 1 RTMP, 3 GB28181, 4 WebRTC/WHIP on Dock 3; the pilot page adds 2 RTSP)."""

    AGORA = 0
    RTMP = 1
    RTSP = 2
    GB28181 = 3
    WHIP = 4


class VideoQuality(enum.IntEnum):
    """``video_quality``: 0 adaptive, 1 smooth (960×540, 512 kbps), 2 SD (1280×720, 1 Mbps), 3 HD
    (1280×720, 1.5 Mbps), 4 UHD (1920×1080, 3 Mbps): DJI's live page gives these sizes and rates."""

    ADAPTIVE = 0
    SMOOTH = 1
    STANDARD = 2
    HIGH = 3
    ULTRA = 4


class VideoType(enum.StrEnum):
    """A lens: ``live_lens_change``'s ``video_type`` and ``live_capacity``'s ``video_type``."""

    NORMAL = "normal"
    WIDE = "wide"
    ZOOM = "zoom"
    IR = "ir"


#: ``{video_type}-{n}``, e.g. ``normal-0`` (DJI's examples); any short token is accepted.
VideoIndex = Annotated[str, StringConstraints(pattern=r"^[A-Za-z0-9_]{1,16}(-[0-9]{1,3})?$", max_length=20)]
_VIDEO_ID = re.compile(
    r"^(?P<sn>[A-Za-z0-9][A-Za-z0-9._-]{0,63})/(?P<camera>[0-9]{1,5}-[0-9]{1,5}-[0-9]{1,5})"
    r"/(?P<video>[A-Za-z0-9_]{1,16}(-[0-9]{1,3})?)$"
)
#: ``{sn}/{camera_index}/{video_index}``, e.g. ``1ZNDH1D0010098/39-0-7/normal-0``.
VideoId = Annotated[
    str,
    StringConstraints(pattern=_VIDEO_ID.pattern, max_length=128),
    Field(description="{sn}/{camera_index}/{video_index}, e.g. 1ZNDH1D0010098/39-0-7/normal-0."),
]


def parse_video_id(video_id: str) -> tuple[str, str, str]:
    """``(sn, camera_index, video_index)`` of a video id; ``ValueError`` when it has not that form."""
    m = _VIDEO_ID.match(video_id.strip())
    if m is None:
        raise ValueError("video_id must be {sn}/{camera_index}/{video_index}")
    return m["sn"], m["camera"], m["video"]


def _int_enum(value: Any) -> Any:
    """An integral string ("1") or float (1.0) read as its integer: clouds differ in how they write enums."""
    if isinstance(value, str) and value.strip().isdigit():
        return int(value.strip())
    if isinstance(value, float) and value.is_integer():
        return int(value)
    return value


def _stripped(value: Any) -> Any:
    """A video id with the blanks some clouds leave around it removed."""
    return value.strip() if isinstance(value, str) else value


class LiveStartPush(InboundModel):
    """``live_start_push`` (DJI live page § Start live streaming)."""

    url_type: IntEnumField[UrlType] = Field(
        description="0 Agora, 1 RTMP, 2 RTSP, 3 GB28181, 4 WebRTC (WHIP)."
    )
    url: Secret = Field(
        description="RTMP: rtmp://host[:port]/app/stream; WHIP: the endpoint's http(s) URL; GB28181 and "
        "Agora: &-joined key=value pairs. Masked in logs (a stream key is a credential)."
    )
    video_id: VideoId
    video_quality: IntEnumField[VideoQuality] = Field(
        default=VideoQuality.ADAPTIVE, description="0 adaptive, 1 smooth, 2 SD, 3 HD, 4 UHD."
    )

    _ints = field_validator("url_type", "video_quality", mode="before")(_int_enum)
    _strip = field_validator("video_id", mode="before")(_stripped)


class LiveStopPush(InboundModel):
    """``live_stop_push`` (DJI live page § Stop live streaming)."""

    video_id: VideoId

    _strip = field_validator("video_id", mode="before")(_stripped)


class LiveSetQuality(InboundModel):
    """``live_set_quality`` (DJI live page § Set live streaming quality)."""

    video_id: VideoId
    video_quality: IntEnumField[VideoQuality] = Field(description="0 adaptive, 1 smooth, 2 SD, 3 HD, 4 UHD.")

    _ints = field_validator("video_quality", mode="before")(_int_enum)
    _strip = field_validator("video_id", mode="before")(_stripped)


class LiveLensChange(InboundModel):
    """``live_lens_change`` (DJI live page § Set live streaming lens)."""

    video_id: VideoId
    video_type: VideoType = Field(description="normal, wide, zoom or ir.")

    _strip = field_validator("video_id", mode="before")(_stripped)


# ------------------------------------------------------------------------------------------------ state

Count = Annotated[int, Field(ge=0, le=64)]


class LiveCapacityVideo(OutboundModel):
    video_index: VideoIndex
    video_type: VideoType
    switchable_video_types: list[VideoType] = Field(max_length=4)


class LiveCapacityCamera(OutboundModel):
    camera_index: PayloadIndex
    available_video_number: Count
    coexist_video_number_max: Count
    video_list: list[LiveCapacityVideo] = Field(max_length=8)


class LiveCapacityDevice(OutboundModel):
    sn: SerialNumber
    available_video_number: Count
    coexist_video_number_max: Count
    camera_list: list[LiveCapacityCamera] = Field(max_length=8)


class LiveCapacity(OutboundModel):
    """The gateway's ``live_capacity`` state property: which videos of which devices can stream."""

    available_video_number: Count
    coexist_video_number_max: Count
    device_list: list[LiveCapacityDevice] = Field(max_length=64)


class LiveStatusEntry(OutboundModel):
    """One ``live_status`` item: 1 streaming, 0 not; ``error_status`` 0 or the result code of the failure."""

    video_id: VideoId
    video_type: VideoType
    video_quality: IntEnumField[VideoQuality]
    status: Annotated[Int, Field(ge=0, le=1)]
    error_status: Annotated[Int, Field(ge=0, le=599999)]
