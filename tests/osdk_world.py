"""The Onboard SDK adapter on the simulated flight controller, every timer on one :class:`ManualClock`:
the harness of test_osdk_truth_model, test_osdk_preflight and test_osdk_takeoff_reports.

It owns the in-memory serial line between the real ``AircraftAdapter`` and the real ``OsdkFcModel``
(:class:`Line`, :class:`LineLink`, :class:`MemoryAircraft`), a recording sink for the adapter's reports
(:class:`Sink`) and the world that turns them together (:class:`World`: a step of simulated seconds
costs milliseconds; no sleeping). It must not know what the tests assert, nor anything of the gateway
beyond the adapter's sink interface.
"""

from __future__ import annotations

import asyncio
from collections.abc import Awaitable, Callable, Mapping
from typing import Any, TypeVar

from adapters.base import FrameObserver
from adapters.clock import ManualClock
from adapters.errors import DeviceError, LinkError
from adapters.osdk.adapter import AircraftAdapter
from adapters.osdk.config import OsdkDeviceSettings
from adapters.osdk.sim import OsdkFcModel

T = TypeVar("T")
STEP = 0.05  # s of simulated time per turn of the world


class Sink:
    """The gateway's side of the adapter's reports, recorded."""

    def __init__(self) -> None:
        self.events: list[tuple[str, dict[str, Any]]] = []

    def osd(self, sn: str, data: Mapping[str, Any]) -> None: ...

    def state(self, sn: str, data: Mapping[str, Any]) -> None: ...

    def event(self, sn: str, method: str, data: Mapping[str, Any], need_reply: bool = False) -> None:
        self.events.append((method, dict(data)))

    def online_changed(self, sn: str, online: bool) -> None: ...

    def authority_lost(self, sn: str) -> None: ...


class Line:
    """The serial line: bytes the adapter writes reach the FC model at once, the FC's answers and pushes
    reach the adapter on the loop's next turn (as a real link's reader hands them over)."""

    def __init__(self, model: OsdkFcModel, clock: ManualClock, loop: asyncio.AbstractEventLoop) -> None:
        self.model, self.clock, self.loop = model, clock, loop
        self.adapter: AircraftAdapter | None = None
        self.cut = False  # the cable is out

    def to_fc(self, data: bytes) -> None:
        out = b"".join(self.model.feed(data, self.clock.monotonic()))
        if out:
            self.to_host(out)

    def to_host(self, data: bytes) -> None:
        adapter = self.adapter
        if adapter is not None and not self.cut:
            self.loop.call_soon(adapter._on_bytes, data)  # the emergency stop writes from off the loop


class LineLink:
    """The adapter's end of :class:`Line` (what supervision needs of a link)."""

    kind, where = "serial", "memory://fc"
    frames_in: int | None = None
    bytes_in: int | None = None
    bytes_out: int | None = None

    def __init__(self, line: Line, on_down: Callable[[str], None]) -> None:
        self.line, self.on_down = line, on_down
        self.observer: FrameObserver | None = None
        self.opens = self.frames_out = self.send_errors = 0
        self._up = False

    @property
    def up(self) -> bool:
        return self._up and not self.line.cut

    async def open(self) -> None:
        if self.line.cut:
            raise LinkError("the cable is out")
        self._up = True
        self.opens += 1

    def close(self) -> None:
        self._up = False

    def write(self, frame: bytes) -> None:
        if not self.up:
            raise LinkError("link down")
        self.frames_out += 1
        self.line.to_fc(frame)


class MemoryAircraft(AircraftAdapter):
    """The real adapter on :class:`LineLink` instead of a serial port."""

    def __init__(self, settings: OsdkDeviceSettings, clock: ManualClock, line: Line) -> None:
        super().__init__(settings, clock=clock)
        self._line = line

    async def start(self, sink: Any) -> None:
        self._sink = sink
        self._link = LineLink(self._line, self._on_link_down)  # type: ignore[assignment]
        self._line.adapter = self
        loop = asyncio.get_running_loop()
        self._tasks += [loop.create_task(self._supervise()), loop.create_task(self._retransmit())]

    def crash(self) -> None:
        """The process dies: its tasks stop, nothing is sent (no stop, no release)."""
        for task in [*self._tasks, self._mission_task]:
            if task is not None:
                task.cancel()
        self._line.adapter = None


class World:
    """The adapter (``sn``, on ``memory://fc``, keeping control when it stops, ``settings`` on top) on the
    simulated FC, started; every timer on one ManualClock that only :meth:`run` and :meth:`call` move."""

    def __init__(self, sn: str, model: OsdkFcModel | None = None, **settings: Any) -> None:
        self.loop = asyncio.new_event_loop()
        self.clock = ManualClock()
        self.model = model or OsdkFcModel()
        self.line = Line(self.model, self.clock, self.loop)
        self.sink = Sink()
        self.settings = OsdkDeviceSettings(
            type="osdk", sn=sn, url="memory://fc", release_on_stop=False, **settings
        )
        self.adapter = self.start_adapter()

    def start_adapter(self) -> MemoryAircraft:
        """A new adapter (a new gateway process) on the same line, started; it becomes ``adapter``."""
        self.adapter = MemoryAircraft(self.settings, self.clock, self.line)
        self.loop.run_until_complete(self.adapter.start(self.sink))
        return self.adapter

    def take_control(self) -> None:
        """A second of telemetry (the adapter activates), then SDK control obtained."""
        self.run(1.0)
        assert self.adapter.activated, "the adapter never activated"
        assert not isinstance(self.call(lambda: self.adapter.obtain_control(1)), DeviceError)

    async def _turn(self, each: Callable[[], None] | None = None) -> None:
        """``STEP`` of simulated time: the FC flies and pushes, ``each`` runs, then the adapter's tasks."""
        self.clock.advance(STEP)
        out = b"".join(self.model.tick(self.clock.monotonic()))
        if out:
            self.line.to_host(out)
        if each is not None:
            each()
        for _ in range(8):
            await asyncio.sleep(0)

    def run(
        self, seconds: float, until: Callable[[], bool] | None = None, each: Callable[[], None] | None = None
    ) -> None:
        """Let ``seconds`` of simulated time pass (less once ``until`` holds), ``each`` run every turn."""

        async def go() -> None:
            end = self.clock.monotonic() + seconds
            while self.clock.monotonic() < end - 1e-9 and not (until is not None and until()):
                await self._turn(each)

        self.loop.run_until_complete(go())

    def call(self, make: Callable[[], Awaitable[T]], limit: float = 10.0) -> T | DeviceError:
        """Run one of the adapter's coroutines to its end while the world turns (its ACKs take time)."""

        async def go() -> T | DeviceError:
            task = asyncio.ensure_future(make())
            waited = 0.0
            while not task.done() and waited < limit:
                await self._turn()
                waited += STEP
            if not task.done():
                task.cancel()
                raise AssertionError(f"a call did not end within {limit} s of simulated time")
            try:
                return task.result()
            except DeviceError as exc:
                return exc

        return self.loop.run_until_complete(go())

    def events(self, method: str) -> list[dict[str, Any]]:
        return [data for m, data in self.sink.events if m == method]

    def close(self) -> None:
        self.adapter.crash()
        pending = asyncio.all_tasks(self.loop)
        for task in pending:
            task.cancel()
        if pending:
            self.loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
        self.loop.close()
