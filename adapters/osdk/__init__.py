"""DJI Onboard SDK open protocol (flight controllers over UART): framing and sessions
(``protocol``), the command tables (``commands``: activation, control, pushes, ground-station
waypoint/hotpoint/follow-me from seed 004), the flight-data push (``telemetry``) and the CLI
contract (``describe``). Sans-I/O throughout; the link and the adapter drive it with bytes and a clock.
"""
