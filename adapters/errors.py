"""Every exception an adapter package raises, in one tree.

Owns: the exception classes of ``adapters/`` (the adapter contract's failures, the links', the
codecs'), and what each one means. Must not know MQTT, the Cloud API's result codes beyond the
mapping noted below (``gateway/dispatcher.py`` does the mapping), sockets or threads: it imports the
standard library only, so sans-I/O codecs may use it (``tests/test_sans_io.py`` allows it).

::

    Exception
     ├── DeviceError               an adapter call failed; the message is safe to send to the cloud
     │    ├── DeviceNotConnected   → 325012  link down or device silent
     │    ├── DeviceTimeout        → 325004  no answer before the deadline
     │    ├── MethodNotSupported   → 314404  the device cannot do this method (e.g. zoom on a gimbal)
     │    ├── InvalidParameters    → 325001  in range for the contract, out of range for this device
     │    └── DeviceRejected       → the result code it carries (the device answered "no")
     ├── LinkError                 a serial port or CAN bus could not be opened, or failed in use
     ├── MissionStopped            a mission ended short of its last waypoint without a device error
     ├── RuntimeError
     │    └── SessionsExhausted    all 30 acknowledged DJI-frame sessions wait for their ACK
     └── ValueError
          ├── CodecError           bytes or fields that do not fit a protocol (sans-I/O codecs)
          │    ├── FrameError      framing: start byte, length, CRC, encryption, seq range
          │    ├── LayoutError     a payload against its layout: length, field type or range
          │    └── CommandError    a command table: no entry fits (wrong size, tag, selector)
          │         └── UnknownCommandError   no entry at all for a name, key or cmd_id
          └── Refused              input refused before any device sees it; ``code`` = its result
               ├── KmzError        a wayline KMZ (archive, WPML) the gateway will not read
               └── RouteRefused    a route the aircraft cannot fly (``break_reason``)

The family registry's ``UnknownFamily`` (a ``LookupError``, ``adapters/families.py``) is a
configuration error, not an adapter's, and stays there.

Codec errors are ``ValueError`` s (bad input, not a failing device): a caller that only cares that
the bytes were bad catches :class:`CodecError`. An adapter turns the ones a request can cause into
:class:`InvalidParameters`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

__all__ = [
    "CodecError",
    "CommandError",
    "DeviceError",
    "DeviceNotConnected",
    "DeviceRejected",
    "DeviceTimeout",
    "FrameError",
    "InvalidParameters",
    "KmzError",
    "LayoutError",
    "LinkError",
    "MethodNotSupported",
    "MissionStopped",
    "Refused",
    "RouteRefused",
    "SessionsExhausted",
    "UnknownCommandError",
]


class DeviceError(Exception):
    """Base of every adapter failure; the message is safe to send to the cloud (no secrets)."""


class DeviceNotConnected(DeviceError):
    """The link is down or the device went silent."""


class DeviceTimeout(DeviceError):
    """The device did not answer before the deadline."""


class MethodNotSupported(DeviceError):
    """The device cannot do this method."""


class InvalidParameters(DeviceError):
    """In range for the contract, out of range (or meaningless) for this device."""


class DeviceRejected(DeviceError):
    """The device answered with an error; ``result`` is the Cloud API code it maps to."""

    def __init__(self, result: int, message: str, detail: Mapping[str, Any] | None = None) -> None:
        super().__init__(message)
        self.result = result
        self.detail = dict(detail or {})


class LinkError(Exception):
    """A link (serial port, CAN bus) could not be opened or failed while in use."""


class CodecError(ValueError):
    """Bytes or fields that do not fit a protocol."""


class FrameError(CodecError):
    """A frame cannot be built or parsed (bad argument, CRC, length, encryption)."""


class LayoutError(CodecError):
    """A payload does not fit its layout (wrong length, value out of the type's range)."""


class CommandError(CodecError):
    """A payload fits no command-table entry, or fields do not fit the entry they name.

    ``cmd_id`` and ``name`` say which entry, where known."""

    def __init__(self, message: str, *, cmd_id: int | None = None, name: str | None = None) -> None:
        super().__init__(message)
        self.cmd_id = cmd_id
        self.name = name


class UnknownCommandError(CommandError):
    """No table entry for a name, a key or a cmd_id (for a frame: a valid frame we do not decode)."""


class SessionsExhausted(RuntimeError):
    """All 30 ACK-required sessions are waiting for their ACK."""


class MissionStopped(Exception):
    """The mission ended short of its last waypoint without a flight-controller error (cancelled, a stop)."""


class Refused(ValueError):
    """Input refused before any device sees it: ``code`` is the Cloud API result, ``reason`` says why
    in a few words."""

    def __init__(self, code: int, reason: str) -> None:
        super().__init__(reason)
        self.code = code
        self.reason = reason


class KmzError(Refused):
    """A refused KMZ (archive or WPML)."""


#: the result for a route that cannot be flown (WAYLINE-NOTES)
NOT_FLYABLE = 314003


class RouteRefused(Refused):
    """The route cannot be flown: ``break_reason`` (WAYLINE-NOTES §4.1), ``code`` the Cloud API result."""

    def __init__(self, break_reason: int, reason: str, code: int = NOT_FLYABLE) -> None:
        super().__init__(code, reason)
        self.break_reason = break_reason
