"""A toy fourth device family, "vane": a motorised pointer on a serial port, defined entirely here.

It proves the registry (adapters/families.py): registered with :func:`adapters.families.register`, it
runs through the real gateway and a real mosquitto without any file under gateway/ naming it. It has
what a real family has, each part tiny:

- a frame: ``5A len cmd seq payload… sum`` (``sum``: the low byte of the sum of every byte before
  it), cut from the byte stream by :class:`adapters.wire.stream.StreamDecoder` with :class:`VaneRules`;
  commands ``01`` point (u16 LE heading in 0.1°, 0..3599), its reply ``81`` (u8 status 0 ok / 1 out of
  range, u16 heading now) and the device's push ``02`` (u16 heading) every 0.1 s;
- settings (:class:`VaneSettings`), one extension service ``x_vane_point`` (request and reply models),
  an adapter on :class:`adapters.serial_link.SerialLink` supervised by
  :class:`adapters.supervision.SupervisedAdapter`, a describe module's functions for ``dji-gateway
  decode/encode vane`` and the console's frame inspector;
- a simulator (:class:`VaneSim`, a :class:`adapters.simio.StreamDevice`) on a loopback TCP port.
"""

from __future__ import annotations

import asyncio
import logging
import struct
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import BaseModel, Field

from adapters.base import CallResult, DeviceInfo, TelemetrySink
from adapters.clock import SYSTEM_CLOCK, Clock
from adapters.config import DEVICE_MODEL_CONFIG, ProductSettings
from adapters.errors import DeviceNotConnected, DeviceTimeout, InvalidParameters
from adapters.families import Family
from adapters.serial_link import SerialLink
from adapters.simio import TcpEndpoint
from adapters.supervision import SupervisedAdapter
from adapters.wire.stream import BadFrame, StreamDecoder
from schemas.base import Float, InboundModel, OutboundModel, SerialNumber
from schemas.envelope import ErrorOutput
from schemas.results import ResultValue

log = logging.getLogger(__name__)

SOF = 0x5A
POINT, POINT_REPLY, STATUS = 0x01, 0x81, 0x02
COMMANDS = {"point": POINT, "point_reply": POINT_REPLY, "status": STATUS}
_NAMES = {v: k for k, v in COMMANDS.items()}


# -- the frame (sans-I/O) -------------------------------------------------------------------------------
@dataclass(frozen=True, slots=True)
class VaneFrame:
    cmd: int
    seq: int
    payload: bytes


def encode(cmd: int, seq: int, payload: bytes = b"") -> bytes:
    body = bytes([SOF, len(payload), cmd, seq & 0xFF]) + payload
    return body + bytes([sum(body) & 0xFF])


class VaneRules:
    sof = SOF
    header_len = 2

    def frame_length(self, header: bytes) -> int | str:
        return 5 + header[1]

    def parse(self, frame: bytes) -> VaneFrame | str:
        if sum(frame[:-1]) & 0xFF != frame[-1]:
            return "checksum crc"
        return VaneFrame(frame[2], frame[3], frame[4:-1])


# -- settings and the Cloud API side ----------------------------------------------------------------------
class VaneSettings(BaseModel):
    """A toy motorised vane on a serial port (tests/toy_family.py)."""

    model_config = DEVICE_MODEL_CONFIG
    type: Literal["vane"] = "vane"
    sn: str = Field(min_length=1, description="serial number")
    product: ProductSettings = Field(ProductSettings(domain="2", type=9901), description="Cloud API product")
    url: str = Field(description="serial port or socket://host:port")
    baudrate: int = Field(115200, description="bits per second")
    osd_period: float | None = Field(None, gt=0, description="osd period (s); none: the gateway's")
    request_timeout: float = Field(0.5, gt=0, description="wait for a reply (s)")
    silence_timeout: float = Field(1.0, gt=0, description="no frame this long: offline (s)")
    reopen_interval: float = Field(0.2, gt=0, description="retry a closed port (s)")


class PointRequest(InboundModel):
    """Turn the vane to ``heading`` (° clockwise from north)."""

    sn: SerialNumber
    heading: float = Field(ge=0, lt=360)


class PointOut(OutboundModel):
    heading: Float


class PointReply(OutboundModel):
    result: ResultValue
    output: PointOut | ErrorOutput | None = None


EXTENSIONS = (("x_vane_point", PointRequest, PointReply, "Vane: turn to a heading"),)


# -- the adapter ------------------------------------------------------------------------------------------
class VaneAdapter(SupervisedAdapter):
    noun = "vane"
    _log = log
    _link: SerialLink | None

    def __init__(self, settings: VaneSettings, *, clock: Clock = SYSTEM_CLOCK) -> None:
        self.settings = settings
        super().__init__(DeviceInfo.of(settings.sn, settings.product), settings, clock)
        self.deadline = settings.request_timeout + 0.2
        self._decoder: StreamDecoder[VaneFrame] = StreamDecoder(VaneRules())
        self._seq = 0
        self._waiting: dict[int, asyncio.Future[VaneFrame]] = {}
        self.heading: float | None = None
        self.handlers = {"x_vane_point": self._point}

    async def start(self, sink: TelemetrySink) -> None:
        self._sink = sink
        loop = asyncio.get_running_loop()
        self._link = SerialLink(
            url=self.settings.url,
            baudrate=self.settings.baudrate,
            loop=loop,
            on_bytes=self._on_bytes,
            on_down=self._on_link_down,
        )
        self._tasks.append(loop.create_task(self._supervise(), name=f"vane-{self.info.sn}"))

    async def stop(self) -> None:
        self._stopping = True
        await self._end_supervision()

    async def stop_motion(self) -> None:
        """A vane turns one step per command and holds: there is no motion left to stop."""

    def osd_snapshot(self) -> Mapping[str, Any] | None:
        if self.heading is None:
            return None
        return {"attitude_head": round((self.heading + 180.0) % 360.0 - 180.0, 1)}

    def _on_link_opened(self) -> None:
        self._decoder = StreamDecoder(VaneRules())

    def _on_bytes(self, data: bytes) -> None:
        for item in self._decoder.feed(data):
            if isinstance(item, BadFrame):
                continue
            self._last_heard = self._now()
            self._set_online(True)
            if item.cmd == STATUS:
                self.heading = struct.unpack("<H", item.payload)[0] / 10
            elif item.cmd == POINT_REPLY:
                waiter = self._waiting.pop(item.seq, None)
                if waiter is not None and not waiter.done():
                    waiter.set_result(item)

    async def _point(self, data: PointRequest) -> CallResult:
        if self._link is None or not self._link.up:
            raise DeviceNotConnected(f"vane {self.info.sn}: link down")
        self._seq = (self._seq + 1) & 0xFF
        seq = self._seq
        waiter: asyncio.Future[VaneFrame] = asyncio.get_running_loop().create_future()
        self._waiting[seq] = waiter
        try:
            self._link.write(encode(POINT, seq, struct.pack("<H", round(data.heading * 10) % 3600)))
            reply = await self._clock.wait_for(waiter, self.settings.request_timeout)
        except TimeoutError:
            raise DeviceTimeout(f"vane {self.info.sn} did not answer") from None
        finally:
            self._waiting.pop(seq, None)
        status, heading = struct.unpack("<BH", reply.payload)
        if status != 0:
            raise InvalidParameters("heading out of range for this vane")
        return CallResult(0, {"heading": heading / 10})


# -- describe (dji-gateway decode/encode vane, the frame inspector) ---------------------------------------
def _record(item: VaneFrame | BadFrame) -> dict[str, Any]:
    if isinstance(item, BadFrame):
        return {"protocol": "vane", "valid": False, "command": None, "fields": None, "error": item.reason}
    fields: dict[str, Any] = {}
    if item.cmd in (POINT, STATUS):
        fields["heading"] = struct.unpack("<H", item.payload)[0] / 10
    elif item.cmd == POINT_REPLY:
        status, heading = struct.unpack("<BH", item.payload)
        fields = {"status": status, "heading": heading / 10}
    return {
        "protocol": "vane",
        "valid": True,
        "seq": item.seq,
        "command": _NAMES.get(item.cmd),
        "fields": fields,
    }


def decode_bytes(data: bytes, **options: Any) -> list[dict[str, Any]]:
    decoder: StreamDecoder[VaneFrame] = StreamDecoder(VaneRules())
    return [_record(item) for item in [*decoder.feed(data), *decoder.flush()]]


def encode_command(command: str, seq: int, fields: dict[str, Any], **options: Any) -> bytes:
    if command not in COMMANDS:
        raise ValueError(f"unknown vane command {command!r}")
    return encode(COMMANDS[command], seq, struct.pack("<H", round(float(fields["heading"]) * 10)))


def frame_rules(options: Mapping[str, Any]) -> VaneRules:
    return VaneRules()


# -- the simulator ----------------------------------------------------------------------------------------
class VaneSim:
    """The device: answers ``point`` (turning at once), pushes its heading every 0.1 s."""

    def __init__(self) -> None:
        self.heading_tenths = 0
        self.points = 0
        self._decoder: StreamDecoder[VaneFrame] = StreamDecoder(VaneRules())
        self._next_push = 0.0

    def on_bytes(self, data: bytes, now: float) -> bytes:
        out = b""
        for item in self._decoder.feed(data):
            if isinstance(item, VaneFrame) and item.cmd == POINT and len(item.payload) == 2:
                (target,) = struct.unpack("<H", item.payload)
                status = 0 if target < 3600 else 1
                if status == 0:
                    self.heading_tenths = target
                    self.points += 1
                out += encode(POINT_REPLY, item.seq, struct.pack("<BH", status, self.heading_tenths))
        return out

    def tick(self, now: float) -> bytes:
        if now < self._next_push:
            return b""
        self._next_push = now + 0.1
        return encode(STATUS, 0, struct.pack("<H", self.heading_tenths))


def in_process(device: VaneSettings) -> tuple[TcpEndpoint, VaneSettings] | None:
    """``--simulate``: an entry whose url is ``sim://vane`` gets a simulator on a loopback port."""
    if device.url != "sim://vane":
        return None
    endpoint = TcpEndpoint(VaneSim())
    endpoint.start()
    return endpoint, device.model_copy(update={"url": endpoint.url})


def main(argv: Sequence[str] | None = None) -> int:
    """``dji-gateway simulate vane``: serve one vane on a loopback TCP port until interrupted."""
    endpoint = TcpEndpoint(VaneSim())
    endpoint.start()
    print(endpoint.url, flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        endpoint.stop()
    return 0


_THIS = sys.modules[__name__]

#: The family record a program registers (``adapters.families.register(FAMILY)``) or an installed
#: distribution names in its ``dji_gateway.families`` entry point.
FAMILY = Family(
    name="vane",
    settings=VaneSettings,
    adapter=VaneAdapter,
    describe=_THIS,
    simulator=_THIS,
    extensions=_THIS,
    tour={"type": "vane", "sn": "VANE-SIM-0001", "url": "sim://vane"},
)
