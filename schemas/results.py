"""Cloud API result codes: the table, their meanings and the six-digit rule.

Owns every ``result`` value the gateway may put in a reply or an event. Knows nothing about devices.

The rule (PROTOCOL-NOTES): 0 is success; an error is six digits led by 3 or 5. A common cloud SDK throws
on any other leading digit, so -1, 1 or 4xxxxx must never be sent. ``ResultValue`` enforces the rule in
every outbound model; ``ResultCode`` names the codes this project uses.

Codes this project reserves (DJI's catalogue does not use the 399xxx block or 599xxx):

- 399001 ``METHOD_NOT_SUPPORTED``: the method is in the contract, but this device cannot do it (a gimbal
  asked to take off).
- 399002 ``UNKNOWN_METHOD``: no model for this method on this topic (neither the seed nor an extension).
- 399003 ``CLOUD_CONTROL_NOT_GRANTED``: live control needs cloud control (``cloud_control_auth_request``
  accepted by the allow-list or the operator) and this cloud user does not hold it (docs/cloud-api.md).
- 399004 ``OUTCOME_UNKNOWN``: a request resent with a tid that an earlier gateway process started acting on
  and stopped (killed) before keeping its reply: not acted on again, since whether the device acted is
  unknown; the cloud reads the device's state (docs/brokers.md, "Exactly once across restarts").
- 399010..399016: live streaming (``live_*``, docs/video.md): 399010 ``LIVE_URL_TYPE_UNSUPPORTED`` (Agora,
  RTSP, GB28181: no maintained engine here; WHIP without aiortc, the ``webrtc`` extra), 399011
  ``LIVE_ALREADY_STREAMING`` (this video already streams to another target), 399012 ``LIVE_UNKNOWN_VIDEO``
  (no configured source for this video id),
  399013 ``LIVE_LENS_UNAVAILABLE``, 399014 ``LIVE_NOT_STREAMING``, 399015 ``LIVE_START_FAILED`` (the media
  engine could not start or lost the source; also ``live_status.error_status``), 399016 ``LIVE_TOO_MANY``.
- 599001 ``INTERNAL_ERROR``: the gateway failed (a bug or an unexpected exception); never a device error.
- 336000 + ack: the Onboard SDK ground-station ACK family (seed 004), reported as ``ground_station_ack(ack)``
  so the raw ACK survives the trip to the cloud (ack 0 is success and maps to 0).
"""

from __future__ import annotations

import enum
from typing import Annotated, Any

from pydantic import AfterValidator, Strict, WithJsonSchema


class ResultCode(enum.IntEnum):
    """The result codes the gateway sends, each with its meaning (``ResultCode.BUSY.meaning``)."""

    meaning: str

    def __new__(cls, value: int, meaning: str) -> ResultCode:
        member = int.__new__(cls, value)
        member._value_ = value
        member.meaning = meaning
        return member

    SUCCESS = 0, "Success."
    BUSY = 314000, "The device cannot do this now (busy, or in a state that forbids it)."
    WAYLINE_MD5_EMPTY = 314002, "Wayline task: the KMZ fingerprint (MD5) is empty."
    WAYLINE_FORMAT = 314003, "Wayline task: the KMZ/WPML file is not supported or not valid."
    WAYLINE_MD5_MISMATCH = 314005, "Wayline task: the KMZ's MD5 does not match its fingerprint."
    WAYLINE_PREPARE_TIMEOUT = 314008, "Wayline task: preparation timed out."
    WAYLINE_FILE_UNOBTAINABLE = 314013, "Wayline task: the KMZ file (or its URL) could not be obtained."
    WAYLINE_TASK_UNKNOWN = 319003, "Wayline task: no task with this flight_id."
    WAYLINE_TASK_EXPIRED = 319004, "Wayline task: expired (an immediate task more than 30 s from its time)."
    WAYLINE_TASK_RUNNING = 319006, "Wayline task: running, cannot be cancelled (undo)."
    WAYLINE_OTHER_TASK_RUNNING = 319016, "Wayline task: another task is running."
    WAYLINE_PAUSE_FAILED = 319020, "Wayline task: pause failed."
    WAYLINE_RESUME_FAILED = 319042, "Wayline task: resume failed."
    WAYLINE_COMPLETED = 319044, "Wayline task: completed, cannot be resumed."
    WAYLINE_NOT_RUNNING = 319046, "Wayline task: completed or paused, cannot be paused."
    WAYLINE_ALTITUDE_LIMIT = 321513, "Wayline task: the route is above the aircraft's altitude limit."
    WAYLINE_DISTANCE_LIMIT = 321514, "Wayline task: the route is beyond the aircraft's distance limits."
    INVALID_PARAMETERS = 325001, "Bad command parameters."
    DEVICE_TIMEOUT = 325004, "The device did not answer in time."
    DEVICE_NOT_CONNECTED = 325012, "The device is not connected."
    NO_FLIGHT_AUTHORITY = 319030, "No flight control authority."
    NO_PAYLOAD_AUTHORITY = 319031, "No payload control authority."
    DRC_SEQ_TOO_OLD = 319033, "DRC sequence number is smaller than the last one."
    DRC_PACKET_TIMEOUT = 319034, "DRC packet timed out."
    EMERGENCY_STOP_FAILED = 319035, "Emergency stop failed."
    SCREEN_DRAG_FAILED = 327004, "Camera screen drag failed."
    AIM_FAILED = 327005, "Camera aim failed."
    PHOTO_FAILED = 327006, "Taking a photo failed."
    RECORDING_START_FAILED = 327007, "Starting recording failed."
    RECORDING_STOP_FAILED = 327008, "Stopping recording failed."
    CAMERA_MODE_SWITCH_FAILED = 327009, "Camera mode switch failed."
    ZOOM_FAILED = 327010, "Setting the zoom (focal length) failed."
    GIMBAL_AT_LIMIT = 327014, "The gimbal is at its limit."
    DRC_MQTT_ERROR = 514300, "DRC link: MQTT error."
    DRC_HEARTBEAT_TIMEOUT = 514301, "DRC link: heartbeat timed out."
    DRC_CERTIFICATE_ERROR = 514302, "DRC link: certificate error."
    DRC_LINK_LOST = 514303, "DRC link lost."
    DRC_LINK_REFUSED = 514304, "DRC link refused."
    METHOD_NOT_SUPPORTED = 399001, "dji-gateway: this device does not support this method."
    UNKNOWN_METHOD = 399002, "dji-gateway: unknown method for this topic."
    CLOUD_CONTROL_NOT_GRANTED = 399003, "dji-gateway: cloud control is not granted to this cloud user."
    OUTCOME_UNKNOWN = (
        399004,
        "dji-gateway: an earlier gateway process started this request and stopped before answering; "
        "whether the device acted is unknown, and it was not repeated.",
    )
    LIVE_URL_TYPE_UNSUPPORTED = 399010, "dji-gateway: this live url_type is not supported here."
    LIVE_ALREADY_STREAMING = 399011, "dji-gateway: this video already streams to another target."
    LIVE_UNKNOWN_VIDEO = 399012, "dji-gateway: no video source is configured for this video_id."
    LIVE_LENS_UNAVAILABLE = 399013, "dji-gateway: this video cannot switch to that lens."
    LIVE_NOT_STREAMING = 399014, "dji-gateway: this video is not streaming."
    LIVE_START_FAILED = 399015, "dji-gateway: the stream failed (source/target unreachable, no engine)."
    LIVE_TOO_MANY = 399016, "dji-gateway: too many streams at once."
    INTERNAL_ERROR = 599001, "dji-gateway: internal error."


#: The Onboard SDK ground-station ACK family: 336000 + the raw ACK value (1..999).
GROUND_STATION_ACK_BASE = 336000


def is_valid_result(code: int) -> bool:
    """True for 0 and for six-digit codes led by 3 or 5 (the only values cloud SDKs accept)."""
    if type(code) is bool or not isinstance(code, int):
        return False
    return code == 0 or 300000 <= code <= 399999 or 500000 <= code <= 599999


def ground_station_ack(ack: int) -> int:
    """The result code for an Onboard SDK ground-station ACK value (seed 004): 0 stays 0, else 336000+ack."""
    if not 0 <= ack <= 999:
        raise ValueError(f"ground-station ACK {ack} outside 0..999")
    return 0 if ack == 0 else GROUND_STATION_ACK_BASE + ack


def meaning(code: int) -> str:
    """A short meaning for any result code, including the 336xxx family and codes not in the table."""
    try:
        return ResultCode(code).meaning  # type: ignore[call-arg]  # a lookup by value, not a new member
    except ValueError:
        pass
    if GROUND_STATION_ACK_BASE < code < GROUND_STATION_ACK_BASE + 1000:
        return f"Onboard SDK ground-station ACK {code - GROUND_STATION_ACK_BASE}."
    return (
        "Unknown result code." if is_valid_result(code) else "Invalid result code (not 0 nor 3xxxxx/5xxxxx)."
    )


def _check_result(code: Any) -> int:
    if not is_valid_result(code):
        raise ValueError("result must be 0 or six digits led by 3 or 5")
    return int(code)


#: An outbound ``result``: 0, 300000..399999 or 500000..599999.
ResultValue = Annotated[
    int,
    Strict(),
    AfterValidator(_check_result),
    WithJsonSchema(
        {
            "description": "0 on success, else six digits led by 3 or 5.",
            "anyOf": [
                {"type": "integer", "const": 0},
                {"type": "integer", "minimum": 300000, "maximum": 399999},
                {"type": "integer", "minimum": 500000, "maximum": 599999},
            ],
        }
    ),
]
