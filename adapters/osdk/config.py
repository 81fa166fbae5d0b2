"""Settings of one Onboard SDK flight controller (what the gateway's config file says about it)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, Field, field_validator

from adapters.config import DEVICE_MODEL_CONFIG, ProductSettings, with_family_defaults

__all__ = ["DEFAULT_FREQUENCIES", "OsdkDeviceSettings"]

#: 0x00 0x10 rate codes per flight-data item (0 off, 1 = 1 Hz, 2 = 10 Hz, 3 = 50 Hz, 4 = 100 Hz):
#: timestamp, quaternion, acceleration, velocity, angular rate, position, GPS, RTK, magnetometer, RC,
#: gimbal, status, battery, control device — 10 Hz for what the osd and DRC use, the rest off or 1 Hz.
DEFAULT_FREQUENCIES = [1, 2, 0, 2, 0, 2, 0, 0, 0, 0, 2, 2, 1, 1, 0, 0]


#: The family's Cloud API identity (docs/cloud-api.md "Device identity").
OSDK_PRODUCT = ProductSettings(domain="0", type=60, sub_type=0)


class OsdkDeviceSettings(BaseModel):
    """A DJI flight controller (A3, N3, M600, M210, M100) on the Onboard SDK UART, exposed as an aircraft."""

    model_config = DEVICE_MODEL_CONFIG
    type: Literal["osdk"] = "osdk"
    sn: str = Field(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]{0,63}$")
    product: ProductSettings = Field(
        OSDK_PRODUCT,
        description="Cloud API identity; default M300 RTK (0-60-0), an Onboard-SDK airframe DJI's enum lists",
    )
    url: str = Field(description="pyserial URL: /dev/ttyUSB0, /dev/serial/by-id/…, socket://host:port, a pty")
    baudrate: Literal[115200, 230400, 921600, 1000000] = 230400
    serial_options: dict[str, Any] = Field(default_factory=dict, description="extra pyserial arguments")
    firmware: Literal["new", "m100"] = Field("new", description="new: OSDK 3.3+ (A3/N3/M600/M210); m100")
    app_id: int = Field(0, ge=0, le=0xFFFFFFFF, description="the app id registered with DJI")
    api_level: int = Field(2, ge=0, le=0xFFFFFFFF)
    activation_version: int = Field(
        0x03030000, ge=0, le=0xFFFFFFFF, description="firmware version sent at activation"
    )
    frequencies: list[int] = Field(
        default_factory=lambda: list(DEFAULT_FREQUENCIES),
        min_length=16,
        max_length=16,
        description="0x00 0x10",
    )
    osd_period: float | None = Field(None, gt=0, description="default: the gateway's osd_period")
    silence_timeout: float = Field(2.0, gt=0, description="no telemetry for this long → offline")
    reopen_interval: float = Field(2.0, gt=0, description="how often a closed or failed port is reopened")
    deadline: float = Field(2.5, gt=0, le=2.8, description="a Cloud API request's device deadline (< 3 s)")
    mission_vel_cmd_range: float = Field(
        15.0, ge=2, le=15, description="waypoint mission joystick speed range"
    )
    takeoff_timeout: float = Field(
        30.0, gt=0, description="takeoff_to_point: time to reach the take-off height"
    )
    on_stop: Literal["hover", "land", "go_home"] = Field(
        "hover", description="what stop_motion leaves the aircraft doing after the brake"
    )
    release_on_stop: bool = Field(True, description="release SDK control authority when the gateway stops")
    rc_lost_action: Literal["hover", "land", "return_home"] = Field(
        "return_home",
        description=(
            "the RC-loss failsafe configured on the flight controller (DJI Assistant 2); the Onboard SDK"
            " protocol cannot change it, so a takeoff_to_point asking for another rc_lost_action is"
            " refused (325001)"
        ),
    )
    go_home_altitude: int | None = Field(
        None,
        ge=20,
        le=500,
        description=(
            "m100 only: the go-home altitude (m) configured in DJI Assistant; legacy firmware has no"
            " command to write it, so takeoff_to_point's rth_altitude must equal it (unset: refused with"
            " 325001). New firmware is sent rth_altitude with 0x01 0x42 instead"
        ),
    )
    max_height: float = Field(
        500.0,
        gt=0,
        le=500,
        description="the flight controller's height limit above take-off (m): higher targets are refused",
    )
    max_distance: float = Field(
        2000.0,
        ge=15,
        le=100_000,
        description=(
            "the farthest (m) a mission point may be from home, and the first from the aircraft: the flight"
            " controller's radius limit (DJI Assistant 2), whose missions beyond it it refuses (0xC7, 0xC9);"
            " take-off, fly-to and wayline targets farther away are refused before anything moves"
        ),
    )

    @field_validator("product", mode="before")
    @classmethod
    def _family_product(cls, value: Any) -> Any:
        return with_family_defaults(OSDK_PRODUCT, value)
