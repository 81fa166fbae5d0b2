"""The ``dji-gateway`` console script: one entry point, one sub-command per tool.

Owns argument parsing only; each sub-command lives in its own module and is imported lazily so
``dji-gateway decode`` starts fast and works without MQTT settings.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from gateway import codec_cli, config_cli, console, contract_cli, fly, run_cli, status_cli
from gateway.wayline import console_files as wayline_console


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="dji-gateway",
        description="Bridge DJI R SDK gimbals, RoboMaster robots and Onboard SDK aircraft to the Cloud API.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    run_cli.add_parsers(sub)
    console.add_parsers(sub)
    contract_cli.add_parsers(sub)
    fly.add_parsers(sub)
    status_cli.add_parsers(sub)
    config_cli.add_parsers(sub)
    codec_cli.add_parsers(sub)
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


if __name__ == "__main__":
    sys.exit(main())
