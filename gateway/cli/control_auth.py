"""``dji-gateway control-auth``: the operator's answer to a cloud's ``cloud_control_auth_request``, from a
shell, through the running gateway's web endpoint (the same one ``dji-gateway status`` reads).

``control-auth`` (or ``control-auth status``) prints who holds cloud control and which request waits;
``accept`` / ``deny`` answer the waiting request (``--user`` names the user the operator means: the answer
is refused if another user's request has replaced it); ``revoke`` ends the grant. Answers are console
actions: they need the console token (``--token``, else ``DJIGW_CONSOLE__TOKEN``), sent as a bearer
token. Exit 0 when it applied, 1 when there was nothing to answer or it was refused, 2 when no gateway
answers. Owns the HTTP client side only; the decision is :mod:`gateway.cloud_control`'s.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import urllib.error
import urllib.request
from typing import Any

from gateway.cli.status import EXIT_UNREACHABLE, default_url, fetch

__all__ = ["add_parsers", "cmd_control_auth"]


def add_parsers(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "control-auth",
        help="accept or deny a cloud's request for flight control (cloud_control_auth_request)",
        description="Show who holds cloud control and the request waiting for an answer, or answer it: "
        "accept, deny, or revoke the grant. Talks to the running gateway's web endpoint (as status does); "
        "answers need the console token. Exit 0 applied, 1 nothing to answer or refused, 2 no gateway.",
    )
    p.add_argument(
        "decision",
        nargs="?",
        default="status",
        choices=("status", "accept", "deny", "revoke"),
        help="status (default): show; accept / deny: answer the waiting request; revoke: end the grant",
    )
    p.add_argument("--user", help="the user_id you mean to answer (refused if another request replaced it)")
    p.add_argument("--url", help="default http://127.0.0.1:$DJIGW_METRICS__PORT (9108)")
    p.add_argument("--token", help="the console token (default: $DJIGW_CONSOLE__TOKEN)")
    p.add_argument("--json", action="store_true", help="print the gateway's answer as JSON")
    p.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the gateway (5)")
    p.set_defaults(handler=cmd_control_auth)


def _post(url: str, body: dict[str, Any], token: str, timeout: float) -> tuple[int, dict[str, Any]]:
    request = urllib.request.Request(
        url.rstrip("/") + "/api/cloud-control",
        data=json.dumps(body).encode(),
        method="POST",
        headers={"Content-Type": "application/json", "Authorization": f"Bearer {token}"},
    )
    try:
        with urllib.request.urlopen(request, timeout=timeout) as resp:
            return resp.status, json.loads(resp.read())
    except urllib.error.HTTPError as exc:
        raw = exc.read()
        try:
            return exc.code, json.loads(raw)
        except ValueError:
            return exc.code, {"error": raw.decode(errors="replace")[:200]}


def _describe(cc: dict[str, Any] | None) -> str:
    if cc is None:
        return "cloud control: not available (the gateway is not running yet)"
    lines = [
        f"cloud control: {'in force' if cc.get('in_force') else 'not in force (no cloud has asked yet)'}"
    ]
    holder, pending = cc.get("holder"), cc.get("pending")
    if holder:
        lines.append(
            f"held by {holder['user_callsign']} ({holder['user_id']}), granted by the {holder['by']} "
            f"{holder['held_s']:.0f} s ago"
        )
    else:
        lines.append("held by nobody")
    if pending:
        lines.append(
            f"waiting: {pending['user_callsign']} ({pending['user_id']}) asks for flight control; denied in "
            f"{pending['left_s']:.0f} s without an answer (dji-gateway control-auth accept|deny "
            f"--user {pending['user_id']})"
        )
    return "\n".join(lines)


def cmd_control_auth(ns: argparse.Namespace) -> int:
    url = ns.url or default_url()
    try:
        if ns.decision == "status":
            code, doc = fetch(url, "/api/cloud-control", ns.timeout)
        else:
            token = ns.token or os.environ.get("DJIGW_CONSOLE__TOKEN")
            if not token:
                print("dji-gateway control-auth: give the console token (--token or DJIGW_CONSOLE__TOKEN)",
                      file=sys.stderr)  # fmt: skip
                return 1
            body: dict[str, Any] = {"decision": ns.decision}
            if ns.user:
                body["user_id"] = ns.user
            code, doc = _post(url, body, token, ns.timeout)
    except (OSError, ValueError) as exc:
        reason = getattr(exc, "reason", exc)
        print(f"dji-gateway control-auth: no gateway answers at {url}: {reason}", file=sys.stderr)
        return EXIT_UNREACHABLE
    if ns.json:
        print(json.dumps(doc, indent=2))
    elif code == 200:
        done = "" if ns.decision == "status" else f"{ns.decision}: done\n"
        print(done + _describe(doc.get("cloud_control")))
    else:
        print(f"dji-gateway control-auth: {doc.get('reason') or doc.get('error') or code}", file=sys.stderr)
        if doc.get("cloud_control") is not None:
            print(_describe(doc["cloud_control"]))
    return 0 if code == 200 else 1
