"""Settings of one RoboMaster robot (what the gateway's config file says about it).

The gateway sits on one UART with the robot's main board (e.g. a Taproot ``DJISerial`` subclass),
which passes the referee system's frames through and obeys the gateway's control messages
(``adapters.robomaster.commands`` documents that wire contract).

Product fields: the Cloud API has no ground-robot domain or type (DJI's domains: 0 aircraft, 1 payload, 2
remote controller, 3 dock). The default is ``100-1-0`` announced as its own gateway (``announce =
"gateway"``): the robot publishes its own ``update_topo`` on ``sys/product/{robot_sn}/status``, listing
itself while its link is up, so a cloud that builds DJI's device tree shows it apart from the dock and its
aircraft, never as a remote controller, and a cloud on DJI's Java SDK, which refuses an ``update_topo``
holding a domain it does not know, still reads the dock's (docs/cloud-api.md "Device tree"). The
earlier default, ``{domain = "2", type = 56, announce = "sub_device"}``, makes DJI's Java SDK read the
robot as a DJI RC behind the dock; an integrator may choose it. ``"0"`` and ``"1"`` are refused: the
gateway would publish aircraft or gimbal bodies for them. The gimbal's ``payload_index`` is
``{type}-{sub_type}-{gimbal_index}`` of the payload type the cloud should load (e.g. ``39-0-7``, DJI's FPV
camera at the FPV position).
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field, field_validator, model_validator

from adapters.config import DEVICE_MODEL_CONFIG, ProductSettings, with_family_defaults
from adapters.robomaster.commands import DEFAULT_CONTROL_CMD_ID, DEFAULT_SEASON, ControlChannel
from adapters.robomaster.protocol import REFEREE_MAX_DATA_LEN

__all__ = ["ControlSettings", "RobomasterDeviceSettings"]

Season = Literal["2024", "2025", "2026"]


class ControlSettings(BaseModel):
    """Where the gateway's control messages travel and how long a velocity set-point lasts."""

    model_config = DEVICE_MODEL_CONFIG
    cmd_id: int = Field(
        DEFAULT_CONTROL_CMD_ID,
        ge=0,
        le=0xFFFF,
        description="team cmd_id of the control messages (0x0F01); 0x0301 wraps them in robot interaction",
    )
    data_cmd_id: int = Field(0x0200, ge=0, le=0xFFFF, description="0x0301 sub-header id (student range)")
    sender_id: int = Field(
        0, ge=0, le=0xFFFF, description="0x0301 sender; 0 = the robot id the referee reports (0x0201)"
    )
    receiver_id: int = Field(0, ge=0, le=0xFFFF, description="0x0301 receiver of wrapped control messages")
    rate_hz: float = Field(10.0, ge=10, le=50, description="chassis velocity resend rate while moving")
    hold: float = Field(
        0.5, gt=0, le=10, description="a velocity set-point lasts this long without a fresh one (s)"
    )

    @model_validator(mode="after")
    def _valid_channel(self) -> ControlSettings:
        self.channel()  # ValueError (DJI's ranges, student range) becomes a config error
        return self

    def channel(self, robot_id: int | None = None) -> ControlChannel:
        """The codec's channel; ``robot_id`` fills a zero ``sender_id`` (the referee wants our own id)."""
        sender = self.sender_id or robot_id or 0
        return ControlChannel(self.cmd_id, self.data_cmd_id, sender, self.receiver_id)


#: The family's Cloud API identity (docs/cloud-api.md "Device identity").
ROBOMASTER_PRODUCT = ProductSettings(domain="100", type=1, sub_type=0, announce="gateway")


class RobomasterDeviceSettings(BaseModel):
    """A RoboMaster robot: referee telemetry in, chassis/gimbal control out, on one serial port."""

    model_config = DEVICE_MODEL_CONFIG
    type: Literal["robomaster"] = "robomaster"
    sn: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")
    payload_index: str | None = Field(
        None,
        pattern=r"^\d{1,5}-\d{1,5}-\d{1,5}$",
        description="expose the robot's gimbal as this payload (camera_screen_drag, gimbal_reset)",
    )
    product: ProductSettings = Field(
        ROBOMASTER_PRODUCT,
        description="Cloud API identity; no DJI domain or type exists for a robot: default 100-1-0 announced "
        'as its own gateway (docs/cloud-api.md "Device tree")',
    )
    url: str = Field(
        min_length=1, description="pyserial URL: /dev/ttyUSB0, /dev/serial/by-id/…, socket://host:port, a pty"
    )
    baudrate: int = Field(115200, gt=0, description="the referee UART runs at 115200 8N1")
    season: Season = Field(DEFAULT_SEASON, description="referee protocol season: 2024, 2025 or 2026")
    max_data_len: int = Field(
        REFEREE_MAX_DATA_LEN, ge=16, le=1024, description="longest frame body accepted (referee link: 119)"
    )
    control: ControlSettings = ControlSettings()
    osd_period: float | None = Field(None, gt=0, description="default: the gateway's osd_period")
    silence_timeout: float = Field(2.0, gt=0, description="no valid frame for this long → offline")
    reopen_interval: float = Field(1.0, gt=0, description="how often a closed or failed port is reopened")
    max_vx: float = Field(3.0, gt=0, le=10, description="fastest forward/backward speed accepted (m/s)")
    max_vy: float = Field(3.0, ge=0, le=10, description="fastest sideways speed accepted (m/s)")
    max_wz: float = Field(6.0, gt=0, le=30, description="fastest chassis yaw rate accepted (rad/s)")
    pitch_min_deg: float = Field(-20.0, ge=-90, le=0, description="lowest gimbal pitch set-point (°)")
    pitch_max_deg: float = Field(30.0, ge=0, le=90, description="highest gimbal pitch set-point (°)")
    max_gimbal_speed_dps: float = Field(360.0, gt=0, le=720, description="fastest screen drag (°/s)")
    drag_hold: float = Field(0.5, gt=0, le=5, description="a drag lasts this long after its last message")
    drag_rate_hz: float = Field(20.0, ge=10, le=50, description="gimbal set-point rate while a drag lasts")

    @field_validator("product")
    @classmethod
    def _robot_domain(cls, v: ProductSettings) -> ProductSettings:
        if v.domain in ("0", "1"):
            raise ValueError("a robot's domain must not be 0 (aircraft) or 1 (payload)")
        return v

    @field_validator("product", mode="before")
    @classmethod
    def _family_product(cls, value: Any) -> Any:
        return with_family_defaults(ROBOMASTER_PRODUCT, value)
