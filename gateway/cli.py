"""The ``dji-gateway`` console script: one entry point, one sub-command per tool.

Owns argument parsing only; each sub-command lives in its own module and is imported lazily so
``dji-gateway decode`` starts fast and works without MQTT settings.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from gateway import codec_cli, config_cli, console, run_cli, status_cli


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="dji-gateway",
        description="Bridge DJI R SDK gimbals, RoboMaster robots and Onboard SDK aircraft to the Cloud API.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    run_cli.add_parsers(sub)
    console.add_parsers(sub)
    status_cli.add_parsers(sub)
    config_cli.add_parsers(sub)
    codec_cli.add_parsers(sub)

    schema = sub.add_parser("schema", help="Cloud API contract tools")
    schema_sub = schema.add_subparsers(dest="schema_command", required=True)
    export = schema_sub.add_parser("export", help="write JSON Schemas and the AsyncAPI document")
    export.add_argument("directory", nargs="?", default=None)
    export.set_defaults(handler=_schema_export)
    return parser


def _schema_export(ns: argparse.Namespace) -> int:
    from gateway.app import build_registry
    from schemas import export

    return export.main([ns.directory] if ns.directory else [], registry=build_registry())


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    ns, extra = parser.parse_known_args(argv)
    if extra and getattr(ns, "accepts_fields", False):
        # argparse stops filling a trailing positional once an option interrupts it:
        # `encode rsdk cmd --seq 5 a=1 b=2` still means fields a and b
        fields = [e for e in extra if "=" in e and not e.startswith("-")]
        extra = [e for e in extra if e not in fields]
        ns.fields = [*ns.fields, *fields]
    if extra:
        parser.error(f"unrecognized arguments: {' '.join(extra)}")
    return int(ns.handler(ns))


if __name__ == "__main__":
    sys.exit(main())
