"""State bodies (``thing/product/{device_sn}/state``, published on change) and the ``drc_state`` property.

Owns the seed's flight/payload authority state, the DRC link state enum, and the ground robot's state
(extension). Knows nothing about when a device changes state.

State messages carry only what changed (DJI devices publish a state key when it changes), so every field
is optional and a body must carry at least one.
"""

from __future__ import annotations

import enum

from pydantic import Field, model_validator

from .base import Bool, Int, IntEnumField, OutboundModel, PayloadIndex, SerialNumber, Text, enum_description
from .live import LiveCapacity, LiveStatusEntry


class DrcState(enum.IntEnum):
    """State of the DRC link (seed 003 § Property ``drc_state``)."""

    DISCONNECTED = 0
    CONNECTING = 1
    CONNECTED = 2


_DRC_STATE = enum_description(
    DrcState,
    {
        DrcState.DISCONNECTED: "Disconnected",
        DrcState.CONNECTING: "Connecting",
        DrcState.CONNECTED: "Connected",
    },
)
#: A ``drc_state`` field: 0 disconnected, 1 connecting, 2 connected (integers only).
DrcStateField = IntEnumField[DrcState]


class ControlSource(enum.StrEnum):
    """Who holds an authority: A control, B control, or nobody (empty string)."""

    A = "A"
    B = "B"
    NONE = ""


def require_any(model: OutboundModel) -> None:
    """Raise when no field of ``model`` is set: a state or osd body must say something."""
    if all(getattr(model, name) is None for name in type(model).model_fields) and not model.model_extra:
        raise ValueError("at least one property must be present")


class PayloadAuthority(OutboundModel):
    """Who controls one payload (seed 003 § State, ``payloads[]``)."""

    control_source: ControlSource = Field(description="A, B, or '' (not obtained).")
    payload_index: PayloadIndex
    sn: SerialNumber = Field(description="Payload serial number.")


class AuthorityState(OutboundModel):
    """Flight and payload control authority (seed 003 § State: Update the flight control authority state).

    Used by the aircraft (all fields) and the gimbal (``payloads`` only). The payload authority cannot be
    locked; ``locked`` is about flight authority.
    """

    control_source: ControlSource | None = Field(default=None, description="Flight authority: A, B or ''.")
    locked: Bool | None = Field(default=None, description="Whether the flight authority is locked.")
    payloads: list[PayloadAuthority] | None = Field(default=None, max_length=16)

    @model_validator(mode="after")
    def _not_empty(self) -> AuthorityState:
        require_any(self)
        return self


class AircraftState(AuthorityState):
    """The aircraft's state: its authority, and what its flight controller says it is (the version reply)."""

    firmware_version: Text | None = Field(
        default=None, description="Flight controller firmware, e.g. 03.03.100.00 (Cloud API property name)."
    )
    x_hardware: Text | None = Field(
        default=None,
        description="Extension. Flight controller hardware (from its version name): A3, N3, M100, ...",
    )


class GatewayState(OutboundModel):
    """The gateway's own state (``thing/product/{gateway_sn}/state``): its live-streaming capability and the
    state of every stream, as a dock reports them (DJI dock properties page: ``live_capacity``,
    ``live_status``, pushMode 1)."""

    live_capacity: LiveCapacity | None = Field(default=None, description="Which videos can stream.")
    live_status: list[LiveStatusEntry] | None = Field(
        default=None, max_length=64, description="Every stream: status 1 live, 0 not; error_status."
    )

    @model_validator(mode="after")
    def _not_empty(self) -> GatewayState:
        require_any(self)
        return self


class DrcStateProperty(OutboundModel):
    """The read-only ``drc_state`` property (seed 003 § Property): pushMode 0, so it rides on the osd."""

    drc_state: DrcStateField = Field(description=_DRC_STATE)


class GameProgress(enum.IntEnum):
    """RoboMaster referee ``game_progress`` (0x0001)."""

    NOT_STARTED = 0
    PREPARATION = 1
    SELF_CHECK = 2
    COUNTDOWN = 3
    IN_GAME = 4
    SETTLING = 5


class RobotState(OutboundModel):
    """Ground robot state (extension: the Cloud API has no ground robots; every field is ``x_``).

    Names follow the RoboMaster referee protocol (seed 002 / PROTOCOL-NOTES).
    """

    x_robot_id: Int | None = Field(
        default=None, ge=1, le=255, description="Extension. Referee robot id: red 1-11, blue 101-111."
    )
    x_game_type: Int | None = Field(default=None, ge=0, le=15, description="Extension. Referee game_type.")
    x_game_progress: IntEnumField[GameProgress] | None = Field(
        default=None,
        description="Extension. Referee game_progress: 0 not started, 1 preparation, 2 self-check, "
        "3 countdown, 4 in game, 5 settling.",
    )

    @model_validator(mode="after")
    def _not_empty(self) -> RobotState:
        require_any(self)
        return self
