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
from typing import Any

from adapters import families
from adapters.families import InProcessSim
from gateway.settings import ConfigError, GatewaySettings, load_settings

log = logging.getLogger(__name__)

#: The gateway serial number behind ``--simulate`` (documented in the README).
SIM_GATEWAY_SN = "DJIGW-SIM-0001"


def _tour(family: str, key: str) -> str:
    """A field of the device entry ``--simulate`` adds for ``family`` (``Family.tour``)."""
    return str((families.get(family).tour or {})[key])


#: The simulated devices' serial numbers and payload indexes (documented in the README; ``make run`` prints
#: them), as the families' tour entries give them.
SIM_GIMBAL_SN = _tour("rsdk", "sn")
SIM_GIMBAL_PAYLOAD_INDEX = _tour("rsdk", "payload_index")
SIM_ROBOT_SN = _tour("robomaster", "sn")
SIM_ROBOT_PAYLOAD_INDEX = _tour("robomaster", "payload_index")  # the robot's gimbal (camera_screen_drag …)
#: Placeholder url of the simulated robot; ``_run`` replaces it with its in-process simulator's socket:// url.
SIM_ROBOT_URL = _tour("robomaster", "url")
SIM_AIRCRAFT_SN = _tour("osdk", "sn")
#: Placeholder url of the simulated aircraft; ``_run`` replaces it with its simulator's socket:// url.
SIM_AIRCRAFT_URL = _tour("osdk", "url")


def setup_logging(level: str, as_json: bool) -> None:
    """Text (default) or JSON lines on stderr, with the request context and secrets masked
    (``gateway.logcontext``)."""
    from gateway.logcontext import install

    handler = install(logging.StreamHandler(sys.stderr), as_json)
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)


def simulated_settings(base: dict[str, Any]) -> dict[str, Any]:
    """Add every registered family's tour device (:attr:`adapters.families.Family.tour`) to a settings
    document: the devices ``start_simulators`` then simulates in-process."""
    doc = dict(base)
    doc.setdefault("gateway_sn", SIM_GATEWAY_SN)
    devices = list(doc.get("devices", []))
    tour = [dict(family.tour) for family in families.all_families() if family.tour is not None]
    devices += tour
    doc["devices"] = devices
    # every simulated device streams a test pattern (its sn, the time, osd values drawn in: docs/video.md)
    video = dict(doc.get("video", {}))
    video.setdefault("test_pattern", True)
    video.setdefault("max_streams", len(tour))
    doc["video"] = video
    return doc


def add_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
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
    run.add_argument(
        "--log-level", choices=("DEBUG", "INFO", "WARNING", "ERROR"), help="overrides the config's log_level"
    )
    run.add_argument(
        "--metrics-port", type=int, help="/metrics, /healthz, /status port (default 9108; 0: any)"
    )
    run.add_argument("--metrics-host", help="their listen address (default 127.0.0.1)")
    run.add_argument("--no-metrics", action="store_true", help="no HTTP endpoint at all")
    run.set_defaults(handler=cmd_run)

    sim = sub.add_parser("simulate", help="run one device simulator as its own process")
    sim.add_argument("device", choices=families.names(), help="the device family to simulate")
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
    problem = http_port_problem(settings)
    if problem is not None:  # before anything starts: no device touched, no topology published
        print(f"dji-gateway: {problem}", file=sys.stderr)
        return 2
    setup_logging(settings.log_level, settings.log_json)
    from gateway.environment import warnings

    for warning in warnings(GatewaySettings):  # a misspelt DJIGW_* variable would be ignored silently
        log.warning("%s", warning)
    for line in file_warnings:
        log.warning("%s", line)
    return asyncio.run(serve(settings, simulate=ns.simulate))


def http_port_problem(settings: GatewaySettings) -> str | None:
    """Why the HTTP endpoint's port cannot be bound now (None when it can, or when none is asked for):
    tried before the gateway starts, so a taken port stops the start instead of leaving an address
    printed that another process answers (issue #35). The server's own bind is still checked (a race)."""
    import socket

    from gateway.web.server import bind_problem

    m = settings.metrics
    if not m.enabled or m.port == 0:
        return None
    family = socket.AF_INET6 if ":" in m.host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as aiohttp binds: TIME_WAIT is free
        try:
            probe.bind((m.host, m.port))
        except OSError as exc:
            return bind_problem(m.host, m.port, exc.strerror or str(exc))
    return None


async def serve(settings: GatewaySettings, *, simulate: bool) -> int:
    """The service until SIGTERM/SIGINT: ``settings``' gateway, with its entries' simulators started in
    this process when ``simulate`` (the settings are used as given: no tour devices are added here)."""
    from gateway.app import GatewayApp

    sims: list[InProcessSim] = []
    if simulate:
        settings = start_simulators(settings, sims)
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
    return app.exit_code


def start_simulators(settings: GatewaySettings, sims: list[InProcessSim]) -> GatewaySettings:
    """Start, for every device entry its family's simulator module takes (``in_process``: a gimbal on
    a virtual CAN bus, a robot or an aircraft whose url is its ``sim://`` placeholder), a simulator in
    this process, appended to ``sims``; the settings returned point those entries at them."""
    devices = []
    for device in settings.devices:
        module = families.get(device.type).simulator_module()
        in_process = getattr(module, "in_process", None)
        started = in_process(device) if in_process is not None else None
        if started is not None:
            sim, device = started
            sims.append(sim)
        devices.append(device)
    return settings.model_copy(update={"devices": devices})


def cmd_simulate(ns: argparse.Namespace) -> int:
    setup_logging("INFO", False)
    module = families.get(ns.device).simulator_module()
    if module is None:
        print(f"dji-gateway: family {ns.device} has no simulator", file=sys.stderr)
        return 2
    result: int = module.main(ns.args)
    return result
