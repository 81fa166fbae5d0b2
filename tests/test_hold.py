"""adapters/hold.py: the one held-set-point loop behind the gimbal drag and the robot's velocity and
drag, on a ManualClock (no sleeping: the test moves time and lets the loop take its steps)."""

from __future__ import annotations

import asyncio

import pytest

from adapters.clock import ManualClock
from adapters.hold import HeldSetpoint


async def _tick(clock: ManualClock, seconds: float) -> None:
    clock.advance(seconds)
    for _ in range(3):
        await asyncio.sleep(0)


def test_a_drag_refreshes_each_period_integrates_exactly_its_hold_then_ends() -> None:
    steps: list[float] = []
    ended: list[bool] = []

    async def run() -> None:
        clock = ManualClock()
        held = HeldSetpoint(
            "t", period=0.1, clock=clock, refresh=steps.append, on_end=lambda: ended.append(True),
            step_to_deadline=True,
        )  # fmt: skip
        assert held.hold(0.25) and held.running
        await _tick(clock, 0)
        await _tick(clock, 0.1)
        await _tick(clock, 0.1)
        assert steps == pytest.approx([0.1, 0.1]) and not ended
        assert not held.hold(0.25)  # extended from now (t = 0.2 → 0.45), no second loop
        for _ in range(3):
            await _tick(clock, 0.1)
        assert not held.running

    asyncio.run(run())
    assert steps == pytest.approx([0.1, 0.1, 0.1, 0.1, 0.05]) and ended == [True]  # last step to 0.45


def test_expire_ends_without_a_last_step_and_cancel_may_still_release() -> None:
    steps: list[float] = []
    ended: list[str] = []

    async def run() -> None:
        clock = ManualClock()
        held = HeldSetpoint("t", period=0.1, clock=clock, refresh=steps.append, step_to_deadline=True)
        held.hold(10.0)
        await _tick(clock, 0)
        held.expire()  # from "another thread": the loop sees it at its next wake-up
        await _tick(clock, 0.1)
        assert not held.running
        for name, when_cancelled in (("released", True), ("quiet", False)):
            held = HeldSetpoint(
                name, period=0.1, clock=clock, refresh=steps.append,
                on_end=lambda name=name: ended.append(name), end_when_cancelled=when_cancelled,
            )  # fmt: skip
            held.hold(10.0)
            task = held.task
            await _tick(clock, 0)
            held.cancel()
            assert task is not None
            with pytest.raises(asyncio.CancelledError):
                await task

    asyncio.run(run())
    assert steps == [] and ended == ["released"]
