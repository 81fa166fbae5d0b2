"""Every JSON example of seed 003, in document order, with the decision that applies to each.

Owns test and documentation data only (the AsyncAPI document shows them as message examples); knows
nothing else. The JSON is copied from the seed as is, with its tab indentation turned into spaces.
``patch`` holds keys the contract requires that the seed's example omits, ``renames`` the ``data`` keys the
gateway emits under another name, ``note`` the decision; both are empty where the example is used as is.

Why this module is longer than 500 lines: it is data: every JSON example of seed 003 with its decision, in
document order.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .topics import TopicKind


@dataclass(frozen=True, slots=True)
class SeedExample:
    """One example: its seed section, topic kind, method (None on state), the JSON text and the decision."""

    section: str
    topic: str
    kind: TopicKind
    method: str | None
    text: str
    patch: dict[str, Any] = field(default_factory=dict)
    renames: dict[str, str] = field(default_factory=dict)
    note: str = ""


SEED_003: tuple[SeedExample, ...] = (
    SeedExample(
        section="Update the flight control autority state",
        topic="thing/product/{device_sn}/state",
        kind=TopicKind.STATE,
        method=None,
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "gateway": "4BKBJ4R1010TGD",
    "data": {
        "control_source": "B",
        "locked": true,
        "payloads": [
            {
                "control_source": "B",
                "payload_index": "53-0-0",
                "sn": "1581F5BMD228Q00A82XX"
            }
        ]
    }
}
""",
    ),
    SeedExample(
        section="Event notification of flyto result",
        topic="thing/product/{device_sn}/events",
        kind=TopicKind.EVENTS,
        method="fly_to_point_progress",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 16540709686556,
    "need_reply": 1,
    "data": {
        "fly_to_id": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
        "status": "wayline_progress",
        "result": 0,
        "way_point_index": 0
    }
}
""",
        patch={"method": "fly_to_point_progress"},
        note=(
            "The example omits method; the table names it and the gateway always sends it (patched in). "
            "Its timestamp has 14 digits (a typo); it is still a valid ms value."
        ),
    ),
    SeedExample(
        section="Event notification of one-key taking off result",
        topic="thing/product/{device_sn}/events",
        kind=TopicKind.EVENTS,
        method="takeoff_to_point_progress",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 16540709686556,
    "need_reply": 1,
    "data": {
        "result": 0,
        "status": "wayline_ok",
        "flight_id": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
        "track_id": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
        "way_point_index": 1
    }
}
""",
        patch={"method": "takeoff_to_point_progress"},
        note=(
            "The example omits method; the table names it and the gateway always sends it (patched in). "
            "Its timestamp has 14 digits (a typo); it is still a valid ms value."
        ),
    ),
    SeedExample(
        section="Notification of DRC link state",
        topic="thing/product/{device_sn}/events",
        kind=TopicKind.EVENTS,
        method="drc_status_notify",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "need_reply": 1,
    "data": {
        "result": 0,
        "drc_state": 2
    }
}
""",
        patch={"method": "drc_status_notify"},
        note=("The example omits method; the table names it and the gateway always sends it (patched in)."),
    ),
    SeedExample(
        section="Reason notification of invalid Joystick control",
        topic="thing/product/{device_sn}/events",
        kind=TopicKind.EVENTS,
        method="joystick_invalid_notify",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "need_reply": 1,
    "data": {
        "reason": 0
    }
}
""",
        patch={"method": "joystick_invalid_notify"},
        note=("The example omits method; the table names it and the gateway always sends it (patched in)."),
    ),
    SeedExample(
        section="Flight control authority grabbing",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="flight_authority_grab",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "flight_authority_grab",
    "data": {}
}
""",
    ),
    SeedExample(
        section="Flight control authority grabbing",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="flight_authority_grab",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "flight_authority_grab",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="Payload control authority grabbing",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="payload_authority_grab",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "payload_authority_grab",
    "data": {
        "payload_index": "39-0-7"
    }
}
""",
    ),
    SeedExample(
        section="Payload control authority grabbing",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="payload_authority_grab",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "payload_authority_grab",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="Enter the live flight controls mode",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="drc_mode_enter",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "drc_mode_enter",
    "data": {
        "mqtt_broker": {
            "address": "mqtt.dji.com:8883",
            "client_id": "sn_a",
            "username": "sn_a_username",
            "password": "jwt_token",
            "expire_time": 1672744922,
            "enable_tls": true
        },
        "osd_frequency": 10,
        "hsi_frequency": 1
    }
}
""",
        note=("password is a secret: the round trip dumps it with context={'reveal_secrets': True}."),
    ),
    SeedExample(
        section="Enter the live flight controls mode",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="drc_mode_enter",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "drc_mode_enter",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="Exit the live flight controls mode",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="drc_mode_exit",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "drc_mode_exit",
    "data": {}
}
""",
    ),
    SeedExample(
        section="Exit the live flight controls mode",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="drc_mode_exit",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "drc_mode_exit",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="One-key taking off",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="takeoff_to_point",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "takeoff_to_point",
    "data": {
        "target_latitude": 12.23,
        "target_longitude": 12.32,
        "target_height": 100,
        "security_takeoff_height": 100,
        "flight_id": "ABDEAC21DCADDA",
        "rth_altitude": 100,
        "max_speed": 12
    }
}
""",
    ),
    SeedExample(
        section="One-key taking off",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="takeoff_to_point",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "takeoff_to_point",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="flyto target point",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="fly_to_point",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "fly_to_point",
    "data": {
        "fly_to_id": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
        "max_speed": 12,
        "points": [
            {
                "latitude": 12.23,
                "longitude": 12.23,
                "height": 100
            },
            {
                "latitude": 12.23,
                "longitude": 12.23,
                "height": 100
            }
        ]
    }
}
""",
        note=(
            "Two points although the table says one is supported: accepted (1..16 points, flown in order)."
        ),
    ),
    SeedExample(
        section="flyto target point",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="fly_to_point",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "fly_to_point",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="End the task of flying to target point",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="fly_to_point_stop",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "fly_to_point_stop",
    "data": {}
}
""",
    ),
    SeedExample(
        section="End the task of flying to target point",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="fly_to_point_stop",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "fly_to_point_stop",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="Payload control - switch the camera mode",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="camera_mode_switch",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_mode_switch",
    "data": {
        "payload_index": "39-0-7",
        "camera_mode": 0
    }
}
""",
    ),
    SeedExample(
        section="Payload control - switch the camera mode",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="camera_mode_switch",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_mode_switch",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="Payload control - take single photo",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="camera_photo_take",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_photo_take",
    "data": {
        "payload_index": "39-0-7"
    }
}
""",
    ),
    SeedExample(
        section="Payload control - take single photo",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="camera_photo_take",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_photo_take",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="Payload control - start recording",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="camera_recording_start",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_recording_start",
    "data": {
        "payload_index": "39-0-7"
    }
}
""",
    ),
    SeedExample(
        section="Payload control - start recording",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="camera_recording_start",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_recording_start",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="Payload control - stop recording",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="camera_recording_stop",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_recording_stop",
    "data": {
        "payload_index": "39-0-7"
    }
}
""",
    ),
    SeedExample(
        section="Payload control - stop recording",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="camera_recording_stop",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_recording_stop",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="Payload control - drag screen",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="camera_screen_drag",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_screen_drag",
    "data": {
        "payload_index": "39-0-7",
        "locked": true,
        "pitch_speed": 0.1,
        "yaw_speed": 0.1
    }
}
""",
    ),
    SeedExample(
        section="Payload control - drag screen",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="camera_screen_drag",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_screen_drag",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="Payload control - double tab to become AIM",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="camera_aim",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_aim",
    "data": {
        "payload_index": "39-0-7",
        "camera_type": "zoom",
        "locked": true,
        "x": 0.5,
        "y": 0.5
    }
}
""",
    ),
    SeedExample(
        section="Payload control - double tab to become AIM",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="camera_aim",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_aim",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="Payload control - zoom",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="camera_focal_length_set",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_focal_length_set",
    "data": {
        "payload_index": "39-0-7",
        "camera_type": "zoom",
        "zoom_factor": 5
    }
}
""",
    ),
    SeedExample(
        section="Payload control - zoom",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="camera_focal_length_set",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "camera_focal_length_set",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="Payload control - reset the gimbal",
        topic="thing/product/{gateway_sn}/services",
        kind=TopicKind.SERVICES,
        method="gimbal_reset",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "gimbal_reset",
    "data": {
        "payload_index": "39-0-7",
        "reset_mode": 0
    }
}
""",
    ),
    SeedExample(
        section="Payload control - reset the gimbal",
        topic="thing/product/{gateway_sn}/services_reply",
        kind=TopicKind.SERVICES_REPLY,
        method="gimbal_reset",
        text="""\
{
    "bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx",
    "timestamp": 1654070968655,
    "method": "gimbal_reset",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="DRC-flight control",
        topic="thing/product/{gateway_sn}/drc/down",
        kind=TopicKind.DRC_DOWN,
        method="drone_control",
        text="""\
{
    "method": "drone_control",
    "data": {
        "seq": 1,
        "x": 2.34,
        "y": -2.45,
        "h": 2.76,
        "w": 2.86
    }
}
""",
        note=("h=2.76 is inside -4..5 (the table's 'min 5, max -4' read as -4..5)."),
    ),
    SeedExample(
        section="DRC-flight control",
        topic="thing/product/{gateway_sn}/drc/up",
        kind=TopicKind.DRC_UP,
        method="drone_control",
        text="""\
{
    "method": "drone_control",
    "data": {
        "result": 0,
        "output": {
            "seq": 1
        }
    }
}
""",
    ),
    SeedExample(
        section="DRC-drone emergency stop",
        topic="thing/product/{gateway_sn}/drc/down",
        kind=TopicKind.DRC_DOWN,
        method="drone_emergency_stop",
        text="""\
{
    "method": "drone_emergency_stop",
    "data": {}
}
""",
    ),
    SeedExample(
        section="DRC-drone emergency stop",
        topic="thing/product/{gateway_sn}/drc/up",
        kind=TopicKind.DRC_UP,
        method="drone_emergency_stop",
        text="""\
{
    "method": "drone_emergency_stop",
    "data": {
        "result": 0
    }
}
""",
    ),
    SeedExample(
        section="DRC-heart beat",
        topic="thing/product/{gateway_sn}/drc/down",
        kind=TopicKind.DRC_DOWN,
        method="heart_beat",
        text="""\
{
    "method": "heart_beat",
    "data": {
        "seq": 10,
        "timestamp": 1670415891013
    }
}
""",
    ),
    SeedExample(
        section="DRC-heart beat",
        topic="thing/product/{gateway_sn}/drc/up",
        kind=TopicKind.DRC_UP,
        method="heart_beat",
        text="""\
{
    "method": "heart_beat",
    "data": {
        "seq": 10,
        "timestamp": 1670415891013
    }
}
""",
    ),
    SeedExample(
        section="DRC-obstacle avoidance information pushing",
        topic="thing/product/{gateway_sn}/drc/up",
        kind=TopicKind.DRC_UP,
        method="hsi_info_push",
        text="""\
{
    "method": "hsi_info_push",
    "timestamp": 1670415891013,
    "data": {
        "up_distance": 10,
        "down_distance": 10,
        "around_distance": [
            10,
            8,
            9,
            16,
            2
        ],
        "up_enable": true,
        "up_work": true,
        "down_enable": true,
        "down_work": true,
        "left_enable": true,
        "left_work": true,
        "right_enable": true,
        "right_work": true,
        "front_enable": true,
        "front_work": true,
        "back_enable": true,
        "back_work": true,
        "vertical_enable": true,
        "vertical_work": true,
        "horizontal_enable": true,
        "horizontal_work": true
    }
}
""",
        renames={"around_distance": "around_distances"},
        note=(
            "The example names the array around_distance (table: around_distances) and carries flags "
            "the table lacks: accepted in, emitted as around_distances; the flags are optional fields."
        ),
    ),
    SeedExample(
        section="DRC-delay information pushing of image transmission link",
        topic="thing/product/{gateway_sn}/drc/up",
        kind=TopicKind.DRC_UP,
        method="delay_info_push",
        text="""\
{
    "method": "delay_info_push",
    "timestamp": 1670415891013,
    "data": {
        "sdr_cmd_delay": 10,
        "liveview_delay_list": [
            {
                "video_id": "1581BN210004555439234/52-0-0/normal-0",
                "liveview_delay_time": 60
            },
            {
                "video_id": "1581BN210004555439234/53-0-0/normal-0",
                "liveview_delay_time": 80
            }
        ]
    }
}
""",
    ),
    SeedExample(
        section="DRC-high frequency osd information pushing",
        topic="thing/product/{gateway_sn}/drc/up",
        kind=TopicKind.DRC_UP,
        method="osd_info_push",
        text="""\
{
    "method": "osd_info_push",
    "timestamp": 1670415891013,
    "data": {
        "attitude_head": 60,
        "latitude": 10,
        "longitude": 10,
        "height": 10,
        "speed_x": 10,
        "speed_y": 10,
        "speed_z": 10,
        "gimbal_pitch": 60,
        "gimbal_roll": 60,
        "gimbal_yaw": 60
    }
}
""",
    ),
)


@dataclass(frozen=True, slots=True)
class GatewayExample:
    """A valid message the seed shows no example of (osd/state bodies, topology, cloud answers)."""

    kind: TopicKind
    name: str  # method, device profile (osd/state) or "properties" (property/set)
    payload: dict[str, Any]
    summary: str


_ENV = {"tid": "6a7bfe89-c386-4043-b600-b518e10096cc", "bid": "42a19f36-5117-4520-bd13-fd61d818d52f"}
_TS = 1654070968655
_GW = "4BKBJ4R1010TGD"

#: Hand-written examples of the messages seed 003 has none for; each validates against its model.
GATEWAY_EXAMPLES: tuple[GatewayExample, ...] = (
    GatewayExample(
        TopicKind.OSD,
        "gateway",
        {**_ENV, "timestamp": _TS, "gateway": _GW, "data": {"drc_state": 2}},
        "The gateway's drc_state property.",
    ),
    GatewayExample(
        TopicKind.OSD,
        "aircraft",
        {
            **_ENV,
            "timestamp": _TS,
            "gateway": _GW,
            "data": {
                "latitude": 22.5431,
                "longitude": 113.9589,
                "height": 120.5,
                "elevation": 45.2,
                "attitude_pitch": -1.5,
                "attitude_roll": 0.4,
                "attitude_head": 87.0,
                "horizontal_speed": 3.2,
                "vertical_speed": -0.5,
                "mode_code": 17,
                "drc_state": 2,
                "battery": {
                    "capacity_percent": 76,
                    "remain_flight_time": 1260,
                    "batteries": [
                        {
                            "index": 0,
                            "capacity_percent": 76,
                            "voltage": 23100,
                            "temperature": 31.5,
                            "x_current": -8400,
                        }
                    ],
                },
                "39-0-7": {
                    "payload_index": "39-0-7",
                    "gimbal_pitch": -30.0,
                    "gimbal_roll": 0.0,
                    "gimbal_yaw": 12.5,
                    "zoom_factor": 2.0,
                },
            },
        },
        "Onboard SDK aircraft with a gimbal on payload index 39-0-7.",
    ),
    GatewayExample(
        TopicKind.OSD,
        "gimbal",
        {
            **_ENV,
            "timestamp": _TS,
            "gateway": _GW,
            "data": {
                "payload_index": "100-0-0",
                "gimbal_pitch": -12.3,
                "gimbal_roll": 0.1,
                "gimbal_yaw": 45.0,
                "cameras": [
                    {"payload_index": "100-0-0", "camera_mode": 1, "recording_state": 1, "zoom_factor": 1.0}
                ],
                "x_joint_angles": {"pitch": -12.0, "roll": 0.0, "yaw": 44.8},
                "x_angle_limits": {
                    "pitch_min": -90.0,
                    "pitch_max": 30.0,
                    "roll_min": -30.0,
                    "roll_max": 30.0,
                    "yaw_min": -180.0,
                    "yaw_max": 180.0,
                },
                "x_motor_stiffness": {"pitch": 40, "roll": 35, "yaw": 50},
            },
        },
        "R SDK gimbal (x_ fields are extensions).",
    ),
    GatewayExample(
        TopicKind.OSD,
        "robot",
        {
            **_ENV,
            "timestamp": _TS,
            "gateway": _GW,
            "data": {
                "attitude_head": -35.0,
                "x_robot_id": 3,
                "x_position": {"x": 4.25, "y": 7.5},
                "x_hp": 180,
                "x_max_hp": 200,
                "x_chassis_power": 42.5,
                "x_buffer_energy": 60,
                "x_shooter_heat": [20, 0],
                "x_stage_remain_time": 312,
            },
        },
        "RoboMaster ground robot from referee data (x_ fields are extensions).",
    ),
    GatewayExample(
        TopicKind.STATE,
        "gimbal",
        {
            **_ENV,
            "timestamp": _TS,
            "gateway": _GW,
            "data": {"payloads": [{"control_source": "A", "payload_index": "100-0-0", "sn": "RS3PRO0001"}]},
        },
        "Payload authority changed.",
    ),
    GatewayExample(
        TopicKind.STATE,
        "robot",
        {
            **_ENV,
            "timestamp": _TS,
            "gateway": _GW,
            "data": {"x_robot_id": 103, "x_game_type": 1, "x_game_progress": 4},
        },
        "Game stage changed.",
    ),
    GatewayExample(
        TopicKind.STATUS,
        "update_topo",
        {
            **_ENV,
            "timestamp": _TS,
            "gateway": _GW,
            "method": "update_topo",
            "data": {
                "domain": "3",
                "type": 1,
                "sub_type": 0,
                "device_secret": "secret",
                "nonce": "nonce",
                "thing_version": "1.1.2",
                "sub_devices": [
                    {
                        "sn": "1581F5BMD228Q00A82XX",
                        "domain": "0",
                        "type": 60,
                        "sub_type": 0,
                        "index": "A",
                        "device_secret": "secret",
                        "nonce": "nonce",
                        "thing_version": "1.1.2",
                    }
                ],
            },
        },
        "Gateway with one aircraft (PROTOCOL-NOTES § Topology first).",
    ),
    GatewayExample(
        TopicKind.STATUS_REPLY,
        "update_topo",
        {**_ENV, "timestamp": _TS, "method": "update_topo", "data": {"result": 0}},
        "The cloud accepted the topology.",
    ),
    GatewayExample(
        TopicKind.EVENTS_REPLY,
        "drc_status_notify",
        {**_ENV, "timestamp": _TS, "method": "drc_status_notify", "data": {"result": 0}},
        "The cloud acknowledges an event that had need_reply 1.",
    ),
    GatewayExample(
        TopicKind.PROPERTY_SET,
        "properties",
        {**_ENV, "timestamp": _TS, "data": {"rth_altitude": 100}},
        "The cloud writes a property.",
    ),
    GatewayExample(
        TopicKind.PROPERTY_SET_REPLY,
        "properties",
        {**_ENV, "timestamp": _TS, "gateway": _GW, "data": {"rth_altitude": {"result": 399001}}},
        "The property is not writable on this device.",
    ),
    GatewayExample(
        TopicKind.EVENTS,
        "cloud_control_auth_notify",
        {
            **_ENV,
            "timestamp": _TS,
            "gateway": _GW,
            "need_reply": 0,
            "method": "cloud_control_auth_notify",
            "data": {"result": 0, "output": {"status": "ok"}},
        },
        "The operator (or the allow-list) granted cloud control; bid is the request's (DJI RC Plus 2 page).",
    ),
)

_FLIGHT = "2b1e6a3c-1d0f-4a7e-9d7a-5b2f1c3e4d5f"
_KMZ_MD5 = "7a7cea5060c55920b7619a2a981f2223"

#: The wayline messages as DJI's reference cloud (DJI-Cloud-API-Demo) sends them: ``bid = flight_id`` for
#: prepare/execute and in every flighttask_progress, ``"data": ""`` for services without parameters
#: (WAYLINE-NOTES §1). Payloads that the contract normalises (``""`` → ``{}``) do not round-trip verbatim.
WAYLINE_EXAMPLES: tuple[GatewayExample, ...] = (
    GatewayExample(
        TopicKind.SERVICES,
        "flighttask_prepare",
        {
            "tid": "6f0c8a0e-2f4b-4c1e-9b59-0c8f5e0a7d11",
            "bid": _FLIGHT,
            "timestamp": 1717000000000,
            "method": "flighttask_prepare",
            "data": {
                "flight_id": _FLIGHT,
                "execute_time": 1717000030000,
                "task_type": 0,
                "wayline_type": 0,
                "file": {
                    "url": "https://bucket.example/wayline/demo.kmz?X-Amz-Expires=3600&X-Amz-Signature=abc",
                    "fingerprint": _KMZ_MD5,
                },
                "rth_altitude": 100,
                "rth_mode": 1,
                "out_of_control_action": 0,
                "exit_wayline_when_rc_lost": 1,
                "wayline_precision_type": 1,
            },
        },
        "The reference cloud prepares a task: bid = flight_id, fingerprint = lowercase MD5 of the KMZ.",
    ),
    GatewayExample(
        TopicKind.SERVICES,
        "flighttask_execute",
        {
            "tid": "0b7d3f0a-5a43-4f7e-8f0e-7f2d9f3c1a22",
            "bid": _FLIGHT,
            "timestamp": 1717000001000,
            "method": "flighttask_execute",
            "data": {"flight_id": _FLIGHT},
        },
        "The reference cloud starts the prepared task (bid = flight_id).",
    ),
    GatewayExample(
        TopicKind.SERVICES,
        "flighttask_pause",
        {**_ENV, "timestamp": _TS, "method": "flighttask_pause", "data": ""},
        'The reference cloud sends services without parameters with "data": "".',
    ),
    GatewayExample(
        TopicKind.SERVICES,
        "flighttask_recovery",
        {**_ENV, "timestamp": _TS, "method": "flighttask_recovery", "data": ""},
        'Resume the paused wayline ("data": "" as the reference cloud sends it).',
    ),
    GatewayExample(
        TopicKind.EVENTS,
        "flighttask_progress",
        {
            "tid": "9fb7c1d2-3e4f-4a5b-8c6d-7e8f9a0b1c2d",
            "bid": _FLIGHT,
            "timestamp": 1717000060000,
            "gateway": _GW,
            "need_reply": 1,
            "method": "flighttask_progress",
            "data": {
                "result": 0,
                "output": {
                    "ext": {
                        "flight_id": _FLIGHT,
                        "wayline_id": 0,
                        "current_waypoint_index": 1,
                        "wayline_mission_state": 6,
                        "media_count": 1,
                        "track_id": "",
                    },
                    "progress": {"current_step": 25, "percent": 66},
                    "status": "in_progress",
                },
            },
        },
        "Progress while flying: bid = flight_id, need_reply 1.",
    ),
    GatewayExample(
        TopicKind.REQUESTS,
        "flighttask_resource_get",
        {
            **_ENV,
            "timestamp": _TS,
            "gateway": _GW,
            "method": "flighttask_resource_get",
            "data": {"flight_id": _FLIGHT},
        },
        "The gateway asks for a fresh pre-signed URL of the task's KMZ before downloading it.",
    ),
    GatewayExample(
        TopicKind.REQUESTS_REPLY,
        "flighttask_resource_get",
        {
            **_ENV,
            "timestamp": _TS,
            "method": "flighttask_resource_get",
            "data": {
                "result": 0,
                "output": {
                    "file": {
                        "url": "https://xx.oss-cn-hangzhou.aliyuncs.com/xx.kmz?Expires=1&OSSAccessKeyId=x&Signature=y",
                        "fingerprint": _KMZ_MD5,
                    }
                },
            },
        },
        "The cloud's answer: a fresh URL and the stored MD5.",
    ),
)


@dataclass(frozen=True, slots=True)
class CloudShape:
    """A request shape a real cloud sends that differs from seed 003's examples, with its source named:
    what arrives on the wire (``text``, verbatim JSON) and what the contract reads from it (``reads``: the
    request's ``data`` as the model dumps it). The contract tests validate every one."""

    kind: TopicKind
    method: str
    text: str
    reads: dict[str, Any]
    source: str


_JAVA_SDK = "DJI-Cloud-API-Demo cloud-sdk (Java Cloud SDK)"
#: An RC-side client used with real remote controllers (commit d53db04f37cefa0e36b79c7a88238f802e30416e).
_RC_CLIENT = "github wudizhr/DJI_Cloud_API_demo CluodAPI_Terminal_Client"
_JAVA_ENV = (
    '"tid": "0a3c4f9e-5b0d-4a41-9c8e-2d7f1b6e3a10", "bid": "7b1e9d2c-3f4a-4e5b-8c6d-9e0f1a2b3c4d", '
    '"timestamp": 1700000000000'
)

#: Every request shape a real cloud sends beyond the seed's examples (issue #17). "data": "" is what the Java
#: SDK's Jackson mapper writes for a method without parameters; Float fields come out as 60.0.
CLOUD_SHAPES: tuple[CloudShape, ...] = (
    *(
        CloudShape(
            TopicKind.SERVICES,
            method,
            f'{{{_JAVA_ENV}, "method": "{method}", "data": ""}}',
            {},
            f"{_JAVA_SDK}: services without parameters are published with an empty-string data",
        )
        for method in ("flight_authority_grab", "fly_to_point_stop", "drc_mode_exit")
    ),
    CloudShape(
        TopicKind.SERVICES,
        "flight_authority_grab",
        f'{{{_JAVA_ENV}, "method": "flight_authority_grab", "data": null}}',
        {},
        "paho clouds that serialise an absent body as null",
    ),
    CloudShape(
        TopicKind.SERVICES,
        "takeoff_to_point",
        "{"
        + _JAVA_ENV
        + ', "method": "takeoff_to_point", "data": {"flight_id": "6a1b2c3d-4e5f-4a7b-8c9d-0e1f2a3b4c5d", '
        '"target_latitude": 22.5436, "target_longitude": 113.958, "target_height": 90.0, '
        '"security_takeoff_height": 30.0, "rth_altitude": 60.0, "rc_lost_action": 2, '
        '"exit_wayline_when_rc_lost": 1, "max_speed": 10, "rth_mode": 1, "commander_mode_lost_action": 1, '
        '"commander_flight_mode": 1, "commander_flight_height": 60.0, '
        '"simulate_mission": {"is_enable": 0, "latitude": 22.5436, "longitude": 113.958}}}',
        {
            "flight_id": "6a1b2c3d-4e5f-4a7b-8c9d-0e1f2a3b4c5d",
            "target_latitude": 22.5436,
            "target_longitude": 113.958,
            "target_height": 90.0,
            "security_takeoff_height": 30.0,
            "rth_altitude": 60,
            "rc_lost_action": 2,
            "exit_wayline_when_rc_lost": 1,
            "max_speed": 10,
            "rth_mode": 1,
            "commander_mode_lost_action": 1,
            "commander_flight_mode": 1,
            "commander_flight_height": 60.0,
            "simulate_mission": {"is_enable": 0, "latitude": 22.5436, "longitude": 113.958},
        },
        f"{_JAVA_SDK} TakeoffToPointRequest: Float rthAltitude written as 60.0, and the Cloud API 1.x fields",
    ),
    CloudShape(
        TopicKind.SERVICES,
        "fly_to_point",
        "{"
        + _JAVA_ENV
        + ', "method": "fly_to_point", "data": {"fly_to_id": "3f2e1d0c-9b8a-4765-8432-10fedcba9876", '
        '"max_speed": 12.0, "points": [{"latitude": 22.5440, "longitude": 113.9585, "height": 2500.0}]}}',
        {
            "fly_to_id": "3f2e1d0c-9b8a-4765-8432-10fedcba9876",
            "max_speed": 12,
            "points": [{"latitude": 22.544, "longitude": 113.9585, "height": 2500.0}],
        },
        f"{_JAVA_SDK} FlyToPointRequest/Point: heights up to 10000 m, one point (the M30 series flies one)",
    ),
    CloudShape(
        TopicKind.SERVICES,
        "drc_mode_enter",
        "{"
        + _JAVA_ENV
        + ', "method": "drc_mode_enter", "data": {"mqtt_broker": {"address": "mqtt.example.com:8883", '
        '"client_id": "drc-4J4R101", "username": "drc", "password": "jwt", "expire_time": 1700003600, '
        '"enable_tls": true}, "osd_frequency": 10.0, "hsi_frequency": 1.0}}',
        {
            "mqtt_broker": {
                "address": "mqtt.example.com:8883",
                "client_id": "drc-4J4R101",
                "username": "drc",
                "password": "jwt",
                "expire_time": 1700003600,
                "enable_tls": True,
            },
            "osd_frequency": 10,
            "hsi_frequency": 1,
        },
        f"{_JAVA_SDK} DrcModeEnterRequest/DrcModeMqttBroker: expire_time 1234567890..9999999999",
    ),
    CloudShape(
        TopicKind.SERVICES,
        "cloud_control_auth_request",
        '{"bid": "5d0c3c9e-3f51-4a8e-9a8f-7c1f0e2d4b6a", "data": {"control_keys": ["flight"], '
        '"user_callsign": "WUDIZHR", "user_id": "123456"}, "method": "cloud_control_auth_request", '
        '"tid": "8e2f6a1b-0c3d-4e5f-9a7b-1c2d3e4f5a6b", "timestamp": 1654070968655}',
        {"user_id": "123456", "user_callsign": "WUDIZHR", "control_keys": ["flight"]},
        "wudizhr/DJI_Cloud_API_demo (an RC Plus 2 client): sent before drc_mode_enter, no gateway field",
    ),
    CloudShape(
        TopicKind.SERVICES,
        "cloud_control_release",
        '{"bid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx", "data": {"control_keys": ["flight"]}, '
        '"method": "cloud_control_release", "tid": "xxxxxxxx-xxxx-xxxx-xxxx-xxxxxxxxxx", '
        '"timestamp": 1704038400000}',
        {"control_keys": ["flight"]},
        "DJI Cloud API docs, RC Plus 2 / RC Pro DRC page: the release example as published",
    ),
    CloudShape(
        TopicKind.SERVICES,
        "return_home",
        '{"bid": "f9f07aad-d1f1-4dc1-8ad0-a3417fd365cc", "data": "null", "method": "return_home", '
        '"tid": "b103b00a-3fcc-476e-9cb6-bc5e27d2defd", "timestamp": 1734425015702}',
        {},
        f'{_RC_CLIENT} services_publisher.py: return_home with the JSON string "null" as data',
    ),
    CloudShape(
        TopicKind.SERVICES,
        "drc_mode_enter",
        '{"bid": "5e4d3c2b-1a09-4f8e-9d7c-6b5a49382716", "data": {"hsi_frequency": 1, "mqtt_broker": '
        '{"address": "mqtt.example.com:1883", "client_id": "sn_a", "enable_tls": "false", '
        '"expire_time": 1999999999, "password": "jwt_token", "username": "sn_a_username"}, '
        '"osd_frequency": 50}, "tid": "6f5e4d3c-2b1a-4098-8e7d-6c5b4a392817", "timestamp": 1654070968655, '
        '"method": "drc_mode_enter"}',
        {
            "mqtt_broker": {
                "address": "mqtt.example.com:1883",
                "client_id": "sn_a",
                "username": "sn_a_username",
                "password": "jwt_token",
                "expire_time": 1999999999,
                "enable_tls": False,
            },
            "osd_frequency": 50,
            "hsi_frequency": 1,
        },
        f'{_RC_CLIENT} services_publisher.py: enable_tls as the string "false", osd_frequency 50 (pushed '
        "at 30 Hz, said in the reply's output); its literal expire_time of 2023 is refused as expired",
    ),
)
