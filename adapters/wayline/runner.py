"""What a wayline service asks of an aircraft family that flies routes, whichever family it is: the
runner an adapter exposes as its ``wayline`` attribute (:class:`WaylineRunner`), and the values and
refusals that cross that boundary.

Owns the contract only (no I/O). Knows nothing of MQTT or of any one flight controller: the Onboard SDK's
runner is ``adapters/osdk/wayline.py``, its mapping ``adapters/osdk/wayline_plan.py``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

from adapters.errors import NOT_FLYABLE
from adapters.wayline.kmz import Route

__all__ = ["NOT_FLYABLE", "Reached", "WaylineRunner"]

#: Result code for a route the aircraft cannot fly (314003: "wayline file format not supported").


@dataclass(frozen=True, slots=True)
class Reached:
    """A route waypoint done (its actions run): (wayline_id, index), and photos taken there."""

    ref: tuple[int, int]
    photos: int


class WaylineRunner(Protocol):
    """The ``wayline`` attribute of an adapter whose aircraft flies routes."""

    mission_running: bool
    #: the device flies its own return home, whoever started it (e.g. a process before a restart)
    fc_going_home: bool

    def plan(
        self,
        route: Route,
        *,
        rth_altitude: float | None = None,
        exit_wayline_when_rc_lost: int | None = None,
        break_point: tuple[int, int, int] | None = None,
    ) -> Any:
        """The family's missions for ``route`` from where the aircraft is; RouteRefused if it cannot."""
        ...

    async def ensure_control(self) -> None: ...

    async def take_off(self, timeout: float) -> None: ...

    async def fly(
        self, plan: Any, flight_id: str, on_reached: Callable[[Reached], None], on_entered: Callable[[], None]
    ) -> None: ...

    async def pause(self) -> None: ...

    async def resume(self) -> None: ...

    async def cancel(self) -> None: ...

    async def go_home_altitude(self, rth_altitude: float | None) -> float | None:
        """Set the aircraft's own return-home height to ``rth_altitude`` where it can (None: keep it);
        the height it will return at, when known."""
        ...

    def go_home_path(self, altitude: float | None) -> list[tuple[float, float, float]]: ...

    async def go_home(self, flight_id: str) -> None: ...
