"""The command-line front ends, and the ``dji-gateway`` console script: one entry point, one sub-command
per tool (``python -m gateway.cli`` runs it too).

This package is the operator's side of the gateway: ``run``/``simulate`` (:mod:`gateway.cli.run`),
the MQTT console ``send``/``monitor`` (:mod:`gateway.cli.console`), ``methods``/``check``
(:mod:`gateway.cli.contract`), ``fly`` (:mod:`gateway.cli.fly`), ``status`` (:mod:`gateway.cli.status`),
``control-auth`` (:mod:`gateway.cli.control_auth`),
``check-config`` (:mod:`gateway.cli.config`), ``decode``/``encode`` (:mod:`gateway.cli.codec`) and
``make run``'s launcher (:mod:`gateway.cli.devrun`). The service (``gateway/`` outside this package)
never imports it (``tests/test_import_graph.py``).

This module owns argument parsing only; each sub-command's work lives in its module, and what it needs
of the service is imported when it runs, so ``dji-gateway decode`` starts fast and works without MQTT
settings.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from gateway.cli import codec, config, console, contract, control_auth, fly, run, status
from gateway.wayline import console_files as wayline_console


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="dji-gateway",
        description="Bridge DJI R SDK gimbals, RoboMaster robots and Onboard SDK aircraft to the Cloud API.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    run.add_parsers(sub)
    console.add_parsers(sub)
    contract.add_parsers(sub)
    fly.add_parsers(sub)
    status.add_parsers(sub)
    control_auth.add_parsers(sub)
    config.add_parsers(sub)
    codec.add_parsers(sub)
    wayline_console.add_parsers(sub)

    schema = sub.add_parser("schema", help="Cloud API contract tools")
    schema_sub = schema.add_subparsers(dest="schema_command", required=True)
    export = schema_sub.add_parser(
        "export",
        help="write JSON Schemas and the AsyncAPI document",
        description="Write one JSON Schema per message, the bundle, the result codes and AsyncAPI 3.0 to "
        "DIR. Without DIR: schemas/json/ of the source checkout this command runs from (the committed "
        "contract); an installed package is never written into (exit 2: give a DIR).",
    )
    export.add_argument(
        "directory", nargs="?", default=None, metavar="DIR",
        help="where to write (default: schemas/json/ of the source checkout)",
    )  # fmt: skip
    export.set_defaults(handler=_schema_export)
    return parser


def source_checkout_json_dir(package_dir: Path) -> Path | None:
    """``schemas/json`` when the ``schemas`` package at ``package_dir`` sits in a source checkout of this
    project (its parent holds our pyproject.toml), else None: an installed package is not ours to write."""
    pyproject = package_dir.parent / "pyproject.toml"
    try:
        text = pyproject.read_text()
    except OSError:
        return None
    return package_dir / "json" if 'name = "dji-gateway"' in text else None


def _schema_export(ns: argparse.Namespace) -> int:
    import schemas
    from gateway.app import build_registry
    from schemas import export

    directory = ns.directory
    if directory is None:
        target = source_checkout_json_dir(Path(schemas.__file__).resolve().parent)
        if target is None:
            print(
                "dji-gateway schema export: give a folder (e.g. dji-gateway schema export ./contract): "
                "without one it writes schemas/json/ of a source checkout, and this is an installed package",
                file=sys.stderr,
            )
            return 2
        directory = str(target)
    return export.main([directory], registry=build_registry())


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    ns, extra = parser.parse_known_args(argv)
    trailing = getattr(ns, "trailing", None)
    if extra and trailing is not None:
        # argparse stops filling a trailing list once an option interrupts it: `encode rsdk cmd --seq 5
        # a=1 b=2` still means fields a and b, `decode robomaster --season 2026 A5 05 …` still means
        # those bytes. Options may stand anywhere, as a user writes them.
        name, belongs = trailing
        more = [e for e in extra if belongs(e)]
        extra = [e for e in extra if not belongs(e)]
        setattr(ns, name, [*getattr(ns, name), *more])
    if extra:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    try:
        return int(ns.handler(ns))
    except BrokenPipeError:
        # `dji-gateway methods | head`: the reader has gone; say nothing more (Python's own advice:
        # point stdout at devnull so the interpreter's final flush does not raise again)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
