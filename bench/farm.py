"""A farm of simulated RoboMaster robots (referee + main board) on loopback TCP ports, in its own process,
for the scale benchmark: ``python -m bench.farm N`` prints one socket:// url per line, then serves until
stdin closes. Keeping the simulators out of the gateway's process keeps its CPU figure honest."""

from __future__ import annotations

import sys

from adapters.robomaster.sim import RefereeMatch, RobomasterSim
from adapters.simio import TcpEndpoint


def main() -> int:
    n = int(sys.argv[1])
    endpoints = [
        TcpEndpoint(RobomasterSim(RefereeMatch(hit_period=0.0)), tick_interval=0.05).start() for _ in range(n)
    ]
    for e in endpoints:
        print(e.url, flush=True)
    sys.stdin.read()  # until the benchmark closes our stdin
    for e in endpoints:
        e.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
