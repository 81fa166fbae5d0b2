"""Settings of one R SDK gimbal (what the gateway's config file says about it)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field, field_validator, model_validator

from adapters.config import DEVICE_MODEL_CONFIG, ProductSettings, with_family_defaults

__all__ = ["RsdkDeviceSettings"]


#: The family's Cloud API identity (docs/cloud-api.md "Device identity").
RSDK_PRODUCT = ProductSettings(domain="1", type=20, sub_type=0)


class RsdkDeviceSettings(BaseModel):
    """A DJI R SDK gimbal (RS 2 / RS 3 / RS 4) on a CAN bus, exposed as a camera payload."""

    model_config = DEVICE_MODEL_CONFIG
    type: Literal["rsdk"] = "rsdk"
    sn: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")
    product: ProductSettings = Field(
        RSDK_PRODUCT,
        description="Cloud API identity (domain 1, a payload); default Zenmuse Z30 (1-20-0): no DJI type "
        "exists for an R SDK gimbal; the Z30 is the gimbal camera in DJI's enum whose methods it serves",
    )
    gimbal_index: int = Field(
        0, ge=0, le=99999, description="the payload position (DJI: 0 front left, 1 front right, 2 top, 7 FPV)"
    )
    payload_index: str | None = Field(
        None,
        pattern=r"^\d{1,5}-\d{1,5}-\d{1,5}$",
        description="{type}-{sub_type}-{gimbal_index} of product and gimbal_index (default: derived); "
        "a value that says otherwise is refused",
    )

    carried_by: str | None = Field(
        None,
        pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$",
        description="sn of the aircraft (an osdk device here) that carries this gimbal: reported as its "
        "payload (inside its osd and state, not in update_topo); unset: a stand-alone payload",
    )

    @model_validator(mode="after")
    def _carried(self) -> RsdkDeviceSettings:
        if self.carried_by is not None and self.product.announce != "sub_device":
            raise ValueError(
                "a carried gimbal is reported by its aircraft: product.announce must stay sub_device"
            )
        return self

    @model_validator(mode="after")
    def _payload_index(self) -> RsdkDeviceSettings:
        derived = f"{self.product.type}-{self.product.sub_type}-{self.gimbal_index}"
        if self.payload_index is None:
            object.__setattr__(self, "payload_index", derived)  # frozen model: set once, here
        elif self.payload_index != derived:
            raise ValueError(
                f"payload_index {self.payload_index!r} is not {{type}}-{{sub_type}}-{{gimbal_index}} "
                f"= {derived!r}"
            )
        return self

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

    @field_validator("product", mode="before")
    @classmethod
    def _family_product(cls, value: Any) -> Any:
        return with_family_defaults(RSDK_PRODUCT, value)
