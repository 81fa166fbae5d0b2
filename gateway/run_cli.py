"""``dji-gateway run`` and ``dji-gateway simulate``: start the service (optionally with in-process
simulated devices) or one device simulator as its own process.

Owns process concerns only: settings loading with one clear error line, logging set-up, signal
handling (SIGTERM/SIGINT stop motion, publish offline, exit 0) and the ``--simulate`` wiring.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import logging
import signal
import sys
from collections.abc import Sequence
from typing import Any

from gateway.settings import ConfigError, GatewaySettings, load_settings

log = logging.getLogger(__name__)

#: Serial numbers and payload index of the simulated devices behind ``--simulate`` (documented in the README).
SIM_GATEWAY_SN = "DJIGW-SIM-0001"
SIM_GIMBAL_SN = "RSDK-SIM-0001"
SIM_GIMBAL_PAYLOAD_INDEX = "1001-0-0"
SIM_ROBOT_SN = "RM-SIM-0001"
SIM_ROBOT_PAYLOAD_INDEX = "1002-0-0"  # the simulated robot's gimbal (camera_screen_drag, gimbal_reset)
#: Placeholder url of the simulated robot; ``_run`` replaces it with its in-process simulator's socket:// url.
SIM_ROBOT_URL = "sim://robomaster"
SIM_AIRCRAFT_SN = "OSDK-SIM-0001"
#: Placeholder url of the simulated aircraft; ``_run`` replaces it with its simulator's socket:// url.
SIM_AIRCRAFT_URL = "sim://osdk"


def setup_logging(level: str, as_json: bool) -> None:
    """Text (default) or JSON lines on stderr, with the request context and secrets masked
    (``gateway.logcontext``)."""
    from gateway.logcontext import install

    handler = install(logging.StreamHandler(sys.stderr), as_json)
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)


def simulated_settings(base: dict[str, Any]) -> dict[str, Any]:
    """Add the in-process simulators' devices (virtual CAN bus) to a settings document."""
    doc = dict(base)
    doc.setdefault("gateway_sn", SIM_GATEWAY_SN)
    devices = list(doc.get("devices", []))
    devices.append(
        {
            "type": "rsdk",
            "sn": SIM_GIMBAL_SN,
            "payload_index": SIM_GIMBAL_PAYLOAD_INDEX,
            "interface": "virtual",
            "channel": f"djigw-sim-{SIM_GIMBAL_SN}",
            "drc_drive": True,  # live-control sticks turn it (with payload authority): docs/drc.md
        }
    )
    devices.append(
        {
            "type": "robomaster",
            "sn": SIM_ROBOT_SN,
            "payload_index": SIM_ROBOT_PAYLOAD_INDEX,
            "url": SIM_ROBOT_URL,
        }
    )
    devices.append({"type": "osdk", "sn": SIM_AIRCRAFT_SN, "url": SIM_AIRCRAFT_URL})
    doc["devices"] = devices
    return doc


def add_parsers(sub: argparse._SubParsersAction) -> None:
    run = sub.add_parser("run", help="run the gateway service")
    run.add_argument("--config", "-c", help="TOML config file (DJIGW_* environment variables override it)")
    run.add_argument(
        "--broker",
        action="append",
        help="broker URL, overrides the config (mqtt://host:port, mqtts://, ws://); repeat it for the "
        "nodes of a cluster (the first that answers is used, the next on loss)",
    )
    run.add_argument("--simulate", action="store_true", help="add in-process simulated devices")
    run.add_argument("--gateway-sn", help="gateway serial number, overrides the config")
    run.add_argument("--log-json", action="store_true", help="one JSON object per log line")
    run.add_argument("--log-level", choices=("DEBUG", "INFO", "WARNING", "ERROR"))
    run.add_argument(
        "--metrics-port", type=int, help="/metrics, /healthz, /status port (default 9108; 0: any)"
    )
    run.add_argument("--metrics-host", help="their listen address (default 127.0.0.1)")
    run.add_argument("--no-metrics", action="store_true", help="no HTTP endpoint at all")
    run.set_defaults(handler=cmd_run)

    sim = sub.add_parser("simulate", help="run one device simulator as its own process")
    sim.add_argument("device", choices=("rsdk", "robomaster", "osdk"))
    sim.add_argument("args", nargs=argparse.REMAINDER, help="simulator options (see: simulate rsdk --help)")
    sim.set_defaults(handler=cmd_simulate)


def _settings_from(ns: argparse.Namespace) -> GatewaySettings:
    overrides: dict[str, Any] = {}
    if ns.broker:
        overrides["broker"] = {"url": ns.broker[0] if len(ns.broker) == 1 else list(ns.broker)}
    if ns.gateway_sn:
        overrides["gateway_sn"] = ns.gateway_sn
    if ns.log_json:
        overrides["log_json"] = True
    if ns.log_level:
        overrides["log_level"] = ns.log_level
    metrics = {
        key: value
        for key, value in (("port", ns.metrics_port), ("host", ns.metrics_host))
        if value is not None
    }
    if ns.no_metrics:
        metrics["enabled"] = False
    if metrics:
        overrides["metrics"] = metrics
    if not ns.simulate:
        return load_settings(ns.config, **overrides)
    import tomllib
    from pathlib import Path

    base: dict[str, Any] = tomllib.loads(Path(ns.config).read_text()) if ns.config else {}
    doc = simulated_settings(base)
    for key, value in overrides.items():
        doc[key] = {**doc.get(key, {}), **value} if isinstance(value, dict) else value
    return load_settings(None, **doc)


def cmd_run(ns: argparse.Namespace) -> int:
    from gateway.settings import check_files

    try:
        settings = _settings_from(ns)
        file_warnings = check_files(settings)  # before anything starts: exit 2, not a traceback
    except ConfigError as exc:
        print(f"dji-gateway: {exc}", file=sys.stderr)
        return 2
    except (OSError, ValueError) as exc:
        print(f"dji-gateway: cannot read config: {exc}", file=sys.stderr)
        return 2
    setup_logging(settings.log_level, settings.log_json)
    from gateway.environment import warnings

    for warning in warnings(GatewaySettings):  # a misspelt DJIGW_* variable would be ignored silently
        log.warning("%s", warning)
    for line in file_warnings:
        log.warning("%s", line)
    return asyncio.run(_run(settings, simulate=ns.simulate))


async def _run(settings: GatewaySettings, *, simulate: bool) -> int:
    from gateway.app import GatewayApp

    sims: list[Any] = []
    if simulate:
        from adapters.rsdk.sim import GimbalCanSim

        for d in settings.devices:
            if d.type == "rsdk" and d.interface == "virtual":
                sims.append(GimbalCanSim(interface="virtual", channel=d.channel).start())
                log.info(
                    "simulated gimbal %s (payload %s) on virtual CAN %s", d.sn, d.payload_index, d.channel
                )
        settings = _simulate_robots(settings, sims)
        settings = _simulate_aircraft(settings, sims)
    app = GatewayApp(settings)
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        with contextlib.suppress(NotImplementedError):
            loop.add_signal_handler(sig, app.stop)
    try:
        await app.run()
    finally:
        for sim in sims:
            sim.stop()
    return 0


def _simulate_robots(settings: GatewaySettings, sims: list[Any]) -> GatewaySettings:
    """Start a referee + main board simulator on a loopback TCP port for every robot whose url is
    ``SIM_ROBOT_URL``, and point the robot's url at it."""
    import time

    from adapters.robomaster.sim import RefereeMatch, RobomasterSim
    from adapters.simio import TcpEndpoint

    devices = []
    for d in settings.devices:
        if d.type == "robomaster" and d.url == SIM_ROBOT_URL:
            match = RefereeMatch(season=d.season, unix_offset=time.time() - time.monotonic())
            endpoint = TcpEndpoint(RobomasterSim(match, control=d.control.channel())).start()
            sims.append(endpoint)
            d = d.model_copy(update={"url": endpoint.url})
            log.info("simulated robot %s (season %s) at %s", d.sn, d.season, endpoint.url)
        devices.append(d)
    return settings.model_copy(update={"devices": devices})


def _simulate_aircraft(settings: GatewaySettings, sims: list[Any]) -> GatewaySettings:
    """Start an Onboard SDK flight-controller simulator on a loopback TCP port for every aircraft
    whose url is ``SIM_AIRCRAFT_URL``, and point the aircraft's url at it."""
    from adapters.osdk.sim import OsdkFcDevice, OsdkFcModel
    from adapters.simio import TcpEndpoint

    devices = []
    for d in settings.devices:
        if d.type == "osdk" and d.url == SIM_AIRCRAFT_URL:
            # the simulated flight controller speaks the firmware the device entry says (new or m100)
            endpoint = TcpEndpoint(OsdkFcDevice(OsdkFcModel(firmware=d.firmware))).start()
            sims.append(endpoint)
            d = d.model_copy(update={"url": endpoint.url})
            log.info("simulated aircraft %s at %s", d.sn, endpoint.url)
        devices.append(d)
    return settings.model_copy(update={"devices": devices})


def cmd_simulate(ns: argparse.Namespace) -> int:
    setup_logging("INFO", False)
    if ns.device == "rsdk":
        from adapters.rsdk import sim

        return sim.main(ns.args)
    if ns.device == "osdk":
        from adapters.osdk import sim as osdk_sim

        return osdk_sim.main(ns.args)
    if ns.device == "robomaster":
        from adapters.robomaster import sim as robomaster_sim

        return robomaster_sim.main(ns.args)
    return 2  # pragma: no cover - argparse restricts the choices


def main(argv: Sequence[str] | None = None) -> int:  # pragma: no cover - thin alias for python -m
    from gateway.cli import main as cli_main

    return cli_main(argv)
