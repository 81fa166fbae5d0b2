"""``data`` of ``update_topo`` (gateway → cloud on ``sys/product/{gateway_sn}/status``).

Owns the topology body: the gateway's product fields and its sub-devices. Knows nothing about which
devices are attached (the gateway's settings name them).

PROTOCOL-NOTES: publish it on every (re)connect before any osd/state/events; an empty ``sub_devices`` marks
every sub-device offline. ``domain`` is a string of digits ("0" aircraft, "1" payload, "2" remote
controller, "3" dock) as in DJI's current docs (older docs show an int; the gateway emits the string).
``type``/``sub_type`` are DJI product enums; devices DJI does not list get values from the settings.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, StringConstraints

from .base import Int, OutboundModel, SerialNumber, Text

Domain = Annotated[str, StringConstraints(strict=True, pattern=r"^[0-9]{1,3}$")]


#: Sub-devices one gateway may announce: the gateway's settings refuse more devices than this.
MAX_SUB_DEVICES = 1024


class SubDevice(OutboundModel):
    """One device behind the gateway."""

    sn: SerialNumber
    domain: Domain = Field(description="Namespace: '0' aircraft, '1' payload, '2' RC, '3' dock.")
    type: Int = Field(ge=0, le=65535, description="Product type.")
    sub_type: Int = Field(ge=0, le=65535, description="Product sub-type.")
    index: Annotated[str, StringConstraints(strict=True, min_length=1, max_length=8)] = Field(
        description="Channel index of the sub-device on the gateway, e.g. 'A'."
    )
    device_secret: Text
    nonce: Text
    thing_version: Text = Field(description="Thing model version, e.g. 1.1.2.")


class UpdateTopo(OutboundModel):
    """Topology update (PROTOCOL-NOTES § Topology first): the gateway's product fields and its sub-devices."""

    domain: Domain = Field(description="Namespace of the gateway: '2' RC, '3' dock.")
    type: Int = Field(ge=0, le=65535, description="Product type.")
    sub_type: Int = Field(ge=0, le=65535, description="Product sub-type.")
    device_secret: Text
    nonce: Text
    thing_version: Text = Field(description="Thing model version, e.g. 1.1.2.")
    sub_devices: list[SubDevice] = Field(
        max_length=MAX_SUB_DEVICES, description="Empty: every sub-device is offline."
    )
