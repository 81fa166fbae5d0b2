"""The contract between the gateway and a device adapter.

An adapter owns one device: its link, its codec, its simulator-facing behaviour, and the mapping
from Cloud API methods to device commands and from device pushes to ``osd`` / ``state`` /
``events``. It raises the small exception tree below instead of returning sentinel values, so the
dispatcher maps every failure to one Cloud API result code in one place. Adapters never see MQTT
or JSON: they get validated pydantic ``data`` models and report through a :class:`TelemetrySink`.

Error tree (adapter side; the gateway's own errors live in ``gateway.errors``)::

    DeviceError
     ├── DeviceNotConnected   → 325012  link down or device silent
     ├── DeviceTimeout        → 325004  no answer before the deadline
     ├── MethodNotSupported   → 314404  the device cannot do this method (e.g. zoom on a gimbal)
     ├── InvalidParameters    → 325001  in range for the contract, out of range for this device
     └── DeviceRejected       → the result code it carries (the device answered "no")
"""

from __future__ import annotations

import abc
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

__all__ = [
    "Adapter",
    "CallResult",
    "DeviceError",
    "DeviceInfo",
    "DeviceNotConnected",
    "DeviceRejected",
    "DeviceTimeout",
    "InvalidParameters",
    "MethodNotSupported",
    "TelemetrySink",
]


class DeviceError(Exception):
    """Base of every adapter failure; the message is safe to send to the cloud (no secrets)."""


class DeviceNotConnected(DeviceError):
    pass


class DeviceTimeout(DeviceError):
    pass


class MethodNotSupported(DeviceError):
    pass


class InvalidParameters(DeviceError):
    pass


class DeviceRejected(DeviceError):
    """The device answered with an error; ``result`` is the Cloud API code it maps to."""

    def __init__(self, result: int, message: str, detail: Mapping[str, Any] | None = None) -> None:
        super().__init__(message)
        self.result = result
        self.detail = dict(detail or {})


@dataclass(frozen=True, slots=True)
class DeviceInfo:
    """What ``update_topo`` announces for this device."""

    sn: str
    domain: str
    type: int
    sub_type: int
    thing_version: str = "1.1.2"
    payload_index: str | None = None

    @classmethod
    def of(cls, sn: str, product: Any, payload_index: str | None = None) -> DeviceInfo:
        """From a device's settings: its serial number, ``product`` fields and payload index."""
        return cls(sn, product.domain, product.type, product.sub_type, product.thing_version, payload_index)


@dataclass(frozen=True, slots=True)
class CallResult:
    result: int = 0
    output: Mapping[str, Any] | None = field(default=None)


class TelemetrySink(Protocol):
    """How an adapter reports upward; implemented by the gateway (publishes JSON to MQTT)."""

    def osd(self, sn: str, data: Mapping[str, Any]) -> None: ...

    def state(self, sn: str, data: Mapping[str, Any]) -> None: ...

    def event(self, sn: str, method: str, data: Mapping[str, Any], need_reply: bool = False) -> None: ...

    def online_changed(self, sn: str, online: bool) -> None: ...

    def authority_lost(self, sn: str) -> None:
        """The device took flight control back (RC take-over): the cloud no longer holds it."""
        ...


Handler = Callable[[Any], Awaitable[CallResult]]


class Adapter(abc.ABC):
    """One device. Subclasses fill :attr:`handlers` (Cloud API method → coroutine taking the
    validated ``data`` model) and implement the life cycle and the failsafe."""

    info: DeviceInfo
    handlers: Mapping[str, Handler]
    #: this device's request deadline (seconds); None: the dispatcher's default
    deadline: float | None = None

    @property
    @abc.abstractmethod
    def online(self) -> bool:
        """True while the link is open and the device has spoken within its silence timeout."""

    @abc.abstractmethod
    async def start(self, sink: TelemetrySink) -> None:
        """Open the link and begin reporting; must not raise if the device is absent (it comes
        online later)."""

    @abc.abstractmethod
    async def stop(self) -> None:
        """Stop motion, close the link."""

    @abc.abstractmethod
    async def stop_motion(self) -> None:
        """Failsafe: stop every motion this device can make, without waiting for the cloud."""

    @abc.abstractmethod
    def osd_snapshot(self) -> Mapping[str, Any] | None:
        """The current periodic ``osd`` body, or None when nothing is known yet."""

    # -- live control (DRC): called from the DRC streaming thread, so these must be thread-safe and
    # must not wait for the event loop or for a device reply: they encode one frame and queue it.
    def drive(self, forward: float, right: float, up: float, yaw_rate: float) -> bool:
        """Send one live-control frame for this set-point (body frame, m/s and °/s clockwise).
        Returns False when this device is not driven by live control."""
        return False

    def emergency_stop(self) -> None:
        """Stop every motion at once (brake / stop / zero speed). Thread-safe, fire-and-forget."""
        return None

    def state_snapshot(self) -> Mapping[str, Any] | None:
        """The current ``state`` body (published after every connect), or None."""
        return None

    def supports(self, method: str) -> bool:
        return method in self.handlers

    async def call(self, method: str, data: Any) -> CallResult:
        handler = self.handlers.get(method)
        if handler is None:
            raise MethodNotSupported(f"{method} is not supported by device {self.info.sn}")
        return await handler(data)
