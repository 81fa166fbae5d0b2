"""The DRC session state machine alone (gateway/drc_session.py), on one core: events per second.

A live session's realistic mix, built before timing: per 40 ms control period one tick, two sticks
(50 Hz, increasing seq, the set-point alternating), and a heartbeat every 25th period (1 Hz), with a
repeated stick (clouds publish DRC messages several times) every tenth period. Every event carries its
timestamp; the machine is fed as the gateway feeds it (``handle`` per event, actions returned).

Target from the motion-safety issue: at least 200,000 events a second on one core.
"""

from __future__ import annotations

from bench.run import Config, Row, best_of
from gateway import drc_session as ds

MOVE = (1.0, -2.0, 0.5, 10.0)
BACK = (-1.0, 2.0, -0.5, -10.0)


def _events(periods: int) -> list[ds.Event]:
    events: list[ds.Event] = []
    seq = 0
    t = 1000.0
    for p in range(periods):
        t += 0.04
        events.append(ds.Tick(t))
        for k in range(2):
            seq += 1
            events.append(ds.Stick(t + 0.01 * k, 1, None, seq, MOVE if seq % 2 else BACK))
        if p % 10 == 0:
            events.append(ds.Stick(t + 0.015, 1, None, seq, BACK))  # a repeat
        if p % 25 == 0:
            events.append(ds.Heartbeat(t + 0.02, 1, None))
    return events


def _live() -> ds.DrcSession:
    m = ds.DrcSession()
    m.handle(ds.Enter(1000.0, None, ds.LinkSpec("main", False)))
    m.handle(ds.LinkUp(1000.0, 1))
    assert m.state is ds.State.ACTIVE
    return m


def run(cfg: Config) -> list[Row]:
    periods = 2_000 if cfg.quick else 20_000
    events = _events(periods)

    def feed() -> tuple[int, ds.DrcSession]:
        m = _live()
        handle = m.handle
        actions = 0
        for event in events:
            actions += len(handle(event))
        return actions, m

    seconds, (actions, machine) = best_of(feed, cfg.repeat, cfg.warmup)
    if machine.state is not ds.State.ACTIVE or machine.setpoint not in (MOVE, BACK):
        raise AssertionError(f"the session ended in {machine.state} / {machine.setpoint}: the mix is wrong")
    if actions < len(events):
        raise AssertionError(f"{actions} actions for {len(events)} events: sticks were not answered")
    return [
        Row(
            group="drc session",
            case="DrcSession.handle, live mix (tick, 2 sticks, repeats, 1 Hz heartbeat)",
            count=len(events),
            rate=len(events) / seconds,
            min_rate=200_000,
            unit="events/s",
            note=f"{actions} actions; one core",
        )
    ]
