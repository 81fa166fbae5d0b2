"""The gateway's name for the one injected clock: :mod:`adapters.clock` owns it (the adapters take the
same clock and must not import ``gateway/``); this module re-exports it so gateway code and tests say
``gateway.clock``. ``GatewayApp(clock=)`` hands it to the dispatcher, the northbound, live control, every
adapter (through its family's ``build``), the broker connection and the web console.
"""

from __future__ import annotations

from adapters.clock import SYSTEM_CLOCK, Clock, ManualClock, SystemClock

__all__ = ["SYSTEM_CLOCK", "Clock", "ManualClock", "SystemClock"]
