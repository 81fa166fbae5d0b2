"""Settings shared by every device family (pydantic, validated once at start-up by the gateway).

Device families keep their own settings model next to their adapter; the gateway's settings
collect them in one discriminated union on ``type``.
"""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, SecretStr

__all__ = ["DEVICE_MODEL_CONFIG", "ProductSettings", "with_family_defaults"]

DEVICE_MODEL_CONFIG = ConfigDict(extra="forbid", frozen=True)


class ProductSettings(BaseModel):
    """What ``update_topo`` says about a device: the Cloud API product enumeration (domain, type,
    sub_type). The defaults are the gateway's own: DJI Dock, ``3-1-0``, the gateway whose services
    (wayline tasks, return home, live control on a broker of the cloud's choosing) this one serves, and
    the only kind DJI's reference cloud sends them to (docs/cloud-api.md "Device identity"); each family
    sets its own."""

    model_config = DEVICE_MODEL_CONFIG
    domain: str = "3"
    type: int = 1
    sub_type: int = 0
    thing_version: str = "1.1.2"
    device_secret: SecretStr | None = None
    announce: Literal["sub_device", "gateway"] = Field(
        "sub_device",
        description="where a device is announced: in this gateway's update_topo (sub_device), or on its own "
        "sys/product/{sn}/status as a gateway listing itself (gateway: a device DJI's model has no "
        'place for, docs/cloud-api.md "Device tree"); the gateway\'s own product: sub_device only',
    )


def with_family_defaults(default: ProductSettings, value: Any) -> Any:
    """A device's ``product`` table completed with its family's defaults: ``{domain = "1", device_secret =
    …}`` keeps the family's type and sub_type (not the gateway's, which ``ProductSettings()`` would give,
    silently changing a gimbal's derived ``payload_index``). Use in a ``mode="before"`` validator."""
    if isinstance(value, dict):
        base = {k: v for k, v in default.model_dump().items() if v is not None}
        return {**base, **value}
    return value
