"""Settings shared by every device family (pydantic, validated once at start-up by the gateway).

Device families keep their own settings model next to their adapter; the gateway's settings
collect them in one discriminated union on ``type``.
"""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, SecretStr

__all__ = ["DEVICE_MODEL_CONFIG", "ProductSettings"]

DEVICE_MODEL_CONFIG = ConfigDict(extra="forbid", frozen=True)


class ProductSettings(BaseModel):
    """What ``update_topo`` says about a device: the Cloud API product enumeration."""

    model_config = DEVICE_MODEL_CONFIG
    domain: str = "3"
    type: int = 1001
    sub_type: int = 0
    thing_version: str = "1.1.2"
    device_secret: SecretStr | None = None
