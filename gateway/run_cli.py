"""Compatibility alias of :mod:`gateway.cli.run` (moved there with the other command-line front ends).

Owns nothing. It exists only because tests another branch is editing right now (tests/test_drc_races.py,
tests/test_drc_interop.py) import the simulated serial numbers from here.
TODO(issue 31 branch): delete once those imports read ``gateway.cli.run`` after the merge.
"""

from __future__ import annotations

from gateway.cli.run import (
    SIM_AIRCRAFT_SN,
    SIM_AIRCRAFT_URL,
    SIM_GATEWAY_SN,
    SIM_GIMBAL_PAYLOAD_INDEX,
    SIM_GIMBAL_SN,
    SIM_ROBOT_PAYLOAD_INDEX,
    SIM_ROBOT_SN,
    SIM_ROBOT_URL,
    simulated_settings,
    start_simulators,
)

__all__ = [
    "SIM_AIRCRAFT_SN",
    "SIM_AIRCRAFT_URL",
    "SIM_GATEWAY_SN",
    "SIM_GIMBAL_PAYLOAD_INDEX",
    "SIM_GIMBAL_SN",
    "SIM_ROBOT_PAYLOAD_INDEX",
    "SIM_ROBOT_SN",
    "SIM_ROBOT_URL",
    "simulated_settings",
    "start_simulators",
]
