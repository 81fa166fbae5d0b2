"""The contract between the gateway and a device adapter.

An adapter owns one device: its link, its codec, its simulator-facing behaviour, and the mapping
from Cloud API methods to device commands and from device pushes to ``osd`` / ``state`` /
``events``. It raises the ``DeviceError`` tree of :mod:`adapters.errors` instead of returning
sentinel values, so the dispatcher maps every failure to one Cloud API result code in one place.
Adapters never see MQTT or JSON: they get validated pydantic ``data`` models and report through a
:class:`TelemetrySink`.

Besides the methods and the failsafe, the contract says what the gateway may read of an adapter, so it
never reaches into one: :meth:`Adapter.link_stats` (the link as an operator sees it,
:class:`LinkStats`), :meth:`Adapter.observe_link` (the console's frame tap), :attr:`Adapter.last_heard`,
and the typed snapshots live control needs (:meth:`Adapter.aircraft_pose`, :meth:`Adapter.gimbal_attitude`).
:class:`Domain` names the Cloud API domains the gateway tells devices apart by.
"""

from __future__ import annotations

import abc
import enum
from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass, field
from typing import Any, Protocol

from adapters.errors import MethodNotSupported
from schemas.base import InboundModel

__all__ = [
    "Adapter",
    "AircraftPose",
    "CallResult",
    "DeviceInfo",
    "Domain",
    "FrameObserver",
    "GimbalAttitude",
    "Handler",
    "LinkStats",
    "TaskJournal",
    "TelemetrySink",
]


class Domain(enum.StrEnum):
    """The Cloud API device domain (``update_topo``'s ``domain``): what kind of device this is."""

    AIRCRAFT = "0"
    PAYLOAD = "1"  # a gimbal or camera of its own
    RC = "2"  # a remote controller
    DOCK = "3"
    #: not DJI's (its domains are 0-3): a ground robot, announced as its own gateway so that a cloud
    #: reading DJI's model neither takes it for a remote controller nor drops the dock's update_topo
    #: (docs/cloud-api.md "Device tree")
    ROBOT = "100"


@dataclass(frozen=True, slots=True)
class DeviceInfo:
    """What ``update_topo`` announces for this device."""

    sn: str
    domain: str
    type: int
    sub_type: int
    thing_version: str = "1.1.2"
    payload_index: str | None = None
    #: ``update_topo``: "sub_device" (listed by this gateway) or "gateway" (announced under its own sn)
    announce: str = "sub_device"
    #: the aircraft (sn) that carries this payload: reported inside that aircraft's osd/state, not announced
    carried_by: str | None = None

    @classmethod
    def of(
        cls, sn: str, product: Any, payload_index: str | None = None, carried_by: str | None = None
    ) -> DeviceInfo:
        """From a device's settings: its serial number, ``product`` fields and payload index."""
        return cls(
            sn,
            product.domain,
            product.type,
            product.sub_type,
            product.thing_version,
            payload_index,
            getattr(product, "announce", "sub_device"),
            carried_by,
        )


@dataclass(frozen=True, slots=True)
class CallResult:
    result: int = 0
    output: Mapping[str, Any] | None = field(default=None)


@dataclass(frozen=True, slots=True)
class LinkStats:
    """One device link as an operator sees it (EMQX Neuron's per-link model: state, traffic, errors)."""

    kind: str  # "can" or "serial"
    where: str  # CAN channel or serial URL (never credentials: neither carries any)
    up: bool
    opens: int  # successful opens: the first and every reconnect
    frames_in: int  # CAN frames on the device's id, or decoded protocol frames on a serial link
    frames_out: int  # CAN frames sent, or frames written to the serial port
    bytes_in: int | None
    bytes_out: int | None
    crc_errors: int
    framing_errors: int  # bad frames that are not CRC failures: garbage, bad headers, truncation
    send_errors: int
    unmatched_replies: int  # late, duplicated or wrong-seq replies/ACKs: dropped, never misapplied


#: A link's frame tap: ``observer("rx" | "tx", can_id or None, data)``, called from the link's threads.
FrameObserver = Callable[[str, int | None, bytes], None]


@dataclass(frozen=True, slots=True)
class AircraftPose:
    """What live control reports of an aircraft whose position is known (``osd_info_push``,
    ``hsi_info_push``), Cloud API units."""

    latitude: float
    longitude: float | None
    altitude: float | None  # WGS84 (m)
    height: float | None  # above the take-off point (m)
    mode_code: int  # the Cloud API mode_code its osd reports
    velocity: tuple[float, float, float] | None  # north, east, up (m/s)
    attitude: tuple[float, float, float] | None  # roll, pitch, yaw (°)
    gimbal: tuple[float, float, float] | None  # its own gimbal's roll, pitch, yaw (°)
    #: obstacle distances (m) and sensor health by direction ("up", "down", "front" …), when reported
    obstacles: Mapping[str, tuple[float, bool]] | None = None


@dataclass(frozen=True, slots=True)
class GimbalAttitude:
    """A gimbal's attitude (°), as it last reported it."""

    yaw: float
    roll: float
    pitch: float


class TelemetrySink(Protocol):
    """How an adapter reports upward; implemented by the gateway (publishes JSON to MQTT)."""

    def osd(self, sn: str, data: Mapping[str, Any]) -> None: ...

    def state(self, sn: str, data: Mapping[str, Any]) -> None: ...

    def event(self, sn: str, method: str, data: Mapping[str, Any], need_reply: bool = False) -> None: ...

    def online_changed(self, sn: str, online: bool) -> None: ...

    def authority_lost(self, sn: str, *, requested: bool = False) -> None:
        """The cloud no longer holds flight control: the device took it back (an RC take-over), or
        ``requested``: it was released because the cloud asked (e.g. ``x_osdk_authority_release``)."""
        ...


class TaskJournal(Protocol):
    """Where a device keeps the task it started on the device (a fly-to, a take-off to point) so that a
    restarted gateway continues it under the same id: the gateway's crash-safe store. One live task per
    device."""

    def remember(self, sn: str, kind: str, task_id: str, data: Mapping[str, Any]) -> None: ...

    def forget(self, sn: str, task_id: str) -> None: ...

    def recall(self, sn: str) -> tuple[str, str, dict[str, Any]] | None:
        """The live task of ``sn``: (kind, task id, data), or None."""
        ...


#: a method's coroutine; it takes the request model its method is registered with (validated by the
#: dispatcher), which differs per method, hence ``Any`` here and the concrete model in each handler
Handler = Callable[[Any], Awaitable[CallResult]]


class Adapter(abc.ABC):
    """One device. Subclasses fill :attr:`handlers` (Cloud API method → coroutine taking the
    validated ``data`` model) and implement the life cycle and the failsafe."""

    info: DeviceInfo
    handlers: Mapping[str, Handler]
    #: this device's request deadline (seconds); None: the dispatcher's default
    deadline: float | None = None
    #: where it keeps the task it started on the device (set by the gateway before ``start``); None: nowhere
    journal: TaskJournal | None = None

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

    def autonomous_task(self) -> str | None:
        """What flies this device on its own now (a mission, a take-off, the device's own return home),
        in words, as the device reports it; None when nothing does. Live control refuses sticks while
        one does (the device would ignore them). Called from network threads: reads only."""
        return None

    def state_snapshot(self) -> Mapping[str, Any] | None:
        """The current ``state`` body (published after every connect), or None."""
        return None

    # -- what the gateway may read (metrics, the console, live control's pushes); on the loop -------
    def link_stats(self) -> LinkStats | None:
        """The device's link statistics, or None for a device without a link of its own."""
        return None

    def observe_link(self, observer: FrameObserver) -> bool:
        """Attach the console's frame tap to the link, once; False when there is no link to tap (yet)
        or a tap is attached already."""
        return False

    @property
    def last_heard(self) -> float | None:
        """When the device last sent a valid frame (the adapter's monotonic clock), None: never."""
        return None

    def aircraft_pose(self) -> AircraftPose | None:
        """An aircraft's pose once its position is known; None for every other device."""
        return None

    def gimbal_attitude(self) -> GimbalAttitude | None:
        """A gimbal's attitude once reported; None for every other device."""
        return None

    def supports(self, method: str) -> bool:
        return method in self.handlers

    async def call(self, method: str, data: InboundModel) -> CallResult:
        handler = self.handlers.get(method)
        if handler is None:
            raise MethodNotSupported(f"{method} is not supported by device {self.info.sn}")
        return await handler(data)
