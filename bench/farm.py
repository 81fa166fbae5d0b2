"""A farm of simulated RoboMaster robots (referee + main board) on loopback TCP ports, in its own process,
for the scale benchmark: ``python -m bench.farm N`` prints one socket:// url per line, then serves until
stdin closes. Keeping the simulators out of the gateway's process keeps its CPU figure honest; one select
loop serves them all (:class:`~adapters.simio.TcpFarm`), so the farm itself stays light at N = 200."""

from __future__ import annotations

import sys

from adapters.robomaster.sim import RefereeMatch, RobomasterSim
from adapters.simio import TcpFarm


def main() -> int:
    n = int(sys.argv[1])
    farm = TcpFarm([RobomasterSim(RefereeMatch(hit_period=0.0)) for _ in range(n)], tick_interval=0.05)
    farm.start()
    for url in farm.urls:
        print(url, flush=True)
    sys.stdin.read()  # until the benchmark closes our stdin
    farm.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
