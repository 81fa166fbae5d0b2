"""Settings of one R SDK gimbal (what the gateway's config file says about it)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field

from adapters.config import DEVICE_MODEL_CONFIG, ProductSettings

__all__ = ["RsdkDeviceSettings"]


class RsdkDeviceSettings(BaseModel):
    """A DJI R SDK gimbal (RS 2 / RS 3 / RS 4) on a CAN bus, exposed as a camera payload."""

    model_config = DEVICE_MODEL_CONFIG
    type: Literal["rsdk"] = "rsdk"
    sn: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")
    payload_index: str = Field("1001-0-0", pattern=r"^\d{1,5}-\d{1,5}-\d{1,5}$")
    product: ProductSettings = ProductSettings(domain="1", type=1001, sub_type=0)
    interface: str = Field("virtual", description="python-can interface: socketcan, slcan, pcan, virtual, …")
    channel: str = Field("djigw", description="can0, /dev/ttyACM0, socket://127.0.0.1:PORT, …")
    bitrate: int = Field(1_000_000, description="R SDK gimbals run at 1 Mbit/s")
    bus_options: dict[str, Any] = Field(
        default_factory=dict, description="extra python-can Bus arguments (e.g. sleep_after_open for slcan)"
    )
    tx_id: int = Field(0x223, ge=0, le=0x7FF, description="host → gimbal CAN id")
    rx_id: int = Field(0x222, ge=0, le=0x7FF, description="gimbal → host CAN id")
    osd_period: float | None = Field(None, gt=0, description="default: the gateway's osd_period")
    request_timeout: float = Field(
        0.3, gt=0, le=2.0, description="one R SDK command (gimbals answer in ~5 ms)"
    )
    silence_timeout: float = Field(2.0, gt=0, description="no push or reply for this long → offline")
    reopen_interval: float = Field(2.0, gt=0, description="how often a closed or failed CAN link is reopened")
    fov_h_deg: float = Field(70.0, gt=0, lt=180, description="camera horizontal field of view for camera_aim")
    fov_v_deg: float = Field(45.0, gt=0, lt=180, description="camera vertical field of view for camera_aim")
    aim_time_s: float = Field(0.5, ge=0.1, le=25.5, description="camera_aim move duration")
    drag_hold: float = Field(0.5, gt=0, le=5, description="a drag lasts this long after its last message")
    drag_rate_hz: float = Field(10.0, ge=10, le=50, description="speed control refresh while a drag lasts")
    max_speed_dps: float = Field(360.0, gt=0, le=360, description="fastest drag accepted (°/s)")
    legacy_angle_order: Literal["yaw_roll_pitch", "yaw_pitch_roll"] = Field(
        "yaw_roll_pitch",
        description=(
            "order of the angles in a legacy-firmware (pre-2.2.0.5 reply form) 0x0E 0x02 reply: seed 000's"
            " yaw_roll_pitch, or yaw_pitch_roll as ArduPilot's RS2 driver reads older gimbal firmware"
        ),
    )
    drc_drive: bool = Field(
        False, description="live control (DRC) sticks drive this gimbal: w → yaw, h → pitch"
    )
    drc_pitch_gain: float = Field(10.0, gt=0, le=72, description="DRC: gimbal pitch °/s per m/s of h")
