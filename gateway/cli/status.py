"""``dji-gateway status``: the live state of a running gateway, from its local ``/status`` endpoint.

Prints devices (online, link traffic and errors), the broker connection, the DRC session and the
request counters; ``--json`` prints the document as it came; ``--check`` asks ``/healthz`` only and
exits 0 when healthy, 1 when not and 2 when nothing answers (the container and systemd health check).
Owns the HTTP client side only; the document is :meth:`gateway.observability.Observability.status`.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import urllib.error
import urllib.request
from typing import Any

__all__ = ["add_parsers", "cmd_status", "default_url", "fetch"]

EXIT_OK, EXIT_UNHEALTHY, EXIT_UNREACHABLE = 0, 1, 2


def default_url() -> str:
    """``http://127.0.0.1:$DJIGW_METRICS__PORT`` (9108): the same variable the gateway reads."""
    port = os.environ.get("DJIGW_METRICS__PORT") or "9108"
    return f"http://127.0.0.1:{port}"


def add_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "status",
        help="print the live state of a running gateway (devices, links, DRC)",
        description="Read a running gateway's /status endpoint (or /healthz with --check) and print its "
        "devices, links, broker and DRC session (full width in a pipe). Exit 0 healthy, 1 unhealthy, 2 when "
        "no gateway answers.",
    )
    p.add_argument("--url", help="default http://127.0.0.1:$DJIGW_METRICS__PORT (9108)")
    p.add_argument("--json", action="store_true", help="print the status document as JSON")
    p.add_argument(
        "--check", action="store_true", help="health check only (/healthz): one line and the exit code"
    )
    p.add_argument("--timeout", type=float, default=3.0, help="seconds to wait for the gateway (3)")
    p.set_defaults(handler=cmd_status)


def fetch(url: str, path: str, timeout: float = 3.0) -> tuple[int, dict[str, Any]]:
    """GET ``url + path`` and decode its JSON (HTTP errors with a JSON body are returned, not raised)."""
    try:
        with urllib.request.urlopen(url.rstrip("/") + path, timeout=timeout) as resp:
            return resp.status, json.loads(resp.read())
    except urllib.error.HTTPError as exc:
        body = exc.read()
        try:
            return exc.code, json.loads(body)
        except ValueError:
            return exc.code, {"error": body.decode(errors="replace")[:200]}


def cmd_status(ns: argparse.Namespace) -> int:
    url = ns.url or default_url()
    path = "/healthz" if ns.check else "/status"
    try:
        code, doc = fetch(url, path, ns.timeout)
    except (OSError, ValueError) as exc:
        reason = getattr(exc, "reason", exc)
        print(f"dji-gateway status: no gateway answers at {url}: {reason}", file=sys.stderr)
        return EXIT_UNREACHABLE
    if ns.check:
        failed = [name for name, ok in doc.get("checks", {}).items() if not ok]
        print(f"{doc.get('status', code)}" + (f": {', '.join(failed)} failing" if failed else ""))
        return EXIT_OK if code == 200 else EXIT_UNHEALTHY
    if ns.json:
        print(json.dumps(doc, indent=2))
    else:
        _print(doc)
    return EXIT_OK if doc.get("healthy") else EXIT_UNHEALTHY


def _print(doc: dict[str, Any]) -> None:
    from rich.console import Console
    from rich.table import Table

    # a pipe or a file gets every column (rich would cut it to 80); a terminal its own width
    console = Console() if sys.stdout.isatty() else Console(width=int(os.environ.get("COLUMNS") or 200))
    broker = doc.get("broker", {})
    health = "[green]healthy[/]" if doc.get("healthy") else "[red]unhealthy[/]"
    failing = [name for name, ok in doc.get("checks", {}).items() if not ok]
    console.print(
        f"gateway [bold]{doc.get('gateway_sn')}[/] {doc.get('version')} · {health}"
        + (f" ({', '.join(failing)} failing)" if failing else "")
        + f" · up {doc.get('uptime_s', 0):.0f}s"
    )
    console.print(
        f"broker {broker.get('url')} · "
        + ("[green]connected[/]" if broker.get("connected") else "[red]disconnected[/]")
        + f" · inbound queue {broker.get('inbound_queue', 0)}"
        + f" · requests in flight {doc.get('requests_in_flight')}"
    )
    twin = broker.get("gateway_sn_conflict") or {}
    if twin.get("count"):
        now = "now" if twin.get("active") else f"last {twin.get('last_age_s')} s ago"
        console.print(
            f"[bold red]ANOTHER GATEWAY publishes as {doc.get('gateway_sn')} on this broker[/] ({now}, "
            f"{twin.get('count')} osd it did not send): a cloud takes the two for one; give each its own "
            "gateway_sn"
        )
    table = Table(title="devices", title_justify="left")
    for name in ("sn", "type", "online", "authority", "link", "frames in/out", "crc/framing errors", "opens"):
        table.add_column(name)
    for d in doc.get("devices", []):
        link = d.get("link") or {}
        authority = ",".join(n for n, held in (("flight", d.get("flight_authority")),
                                               ("payload", d.get("payload_authority"))) if held)  # fmt: skip
        table.add_row(
            d.get("sn", "?"),
            d.get("type", "?"),
            "[green]yes[/]" if d.get("online") else "[red]no[/]",
            authority or "—",
            f"{link.get('kind', '—')} {link.get('where', '')} {'up' if link.get('up') else 'down'}"
            if link
            else "—",
            f"{link.get('frames_in', 0)}/{link.get('frames_out', 0)}" if link else "—",
            f"{link.get('crc_errors', 0)}/{link.get('framing_errors', 0)}" if link else "—",
            str(link.get("opens", 0)) if link else "—",
        )
    console.print(table)
    drc = doc.get("drc", {})
    if drc.get("active"):
        sp = drc.get("setpoint", {})
        console.print(
            f"DRC: state {drc.get('state')} on the {drc.get('broker')} broker · heartbeat "
            f"{drc.get('heartbeat_age_s')}s ago · sticks seq {drc.get('last_seq')} "
            f"(forward {sp.get('forward')}, right {sp.get('right')}, up {sp.get('up')}, "
            f"yaw {sp.get('yaw_rate')})"
            + (" · [red]EMERGENCY STOP[/]" if drc.get("emergency_stop") else "")
            + (" · [red]stopped: heartbeat lost[/]" if drc.get("stopped_for_heartbeat") else "")
        )
    else:
        console.print(f"DRC: state {drc.get('state', 0)} (no live-control session)")
    results = doc.get("services_by_result", {})
    if results:
        console.print("services by result: " + ", ".join(f"{k}: {v:.0f}" for k, v in sorted(results.items())))
