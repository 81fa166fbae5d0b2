"""``make run``: the gateway with simulated devices against a local broker, in one command.

Uses the broker given by ``BROKER`` (``mqtt://host:port``) when set; otherwise the one already
listening on 127.0.0.1:``PORT`` (default 1883, the port ``dji-gateway send``/``monitor`` use by
default), or else starts a private mosquitto there (``PORT=0``: any free port) and stops it on exit.
Prints where to publish and the console commands that drive the simulated devices, each with the
addresses this run answers on (issue #35): the HTTP endpoint (console, ``/status``) is on 9108, or on a
free port chosen here when 9108 is taken (said so); a port given with ``--metrics-port`` or
``DJIGW_METRICS__PORT`` is used as it is (the gateway refuses to start, naming it, when it is taken).
The web console's token (unless ``DJIGW_CONSOLE__TOKEN`` or ``DJIGW_CONSOLE__TOKEN_FILE`` names one) is
made fresh for the run and written to ``.console-token`` (``.console-token-PORT`` when the console is not
on 9108; mode 0600), never printed, never rewritten while a gateway answers on its port, and removed when
the run ends: sign in with what that file holds.
"""

from __future__ import annotations

import os
import secrets
import sys
from collections.abc import Sequence
from pathlib import Path

from gateway.cli import main as cli_main
from gateway.cli.run import (
    SIM_AIRCRAFT_SN,
    SIM_GATEWAY_SN,
    SIM_GIMBAL_PAYLOAD_INDEX,
    SIM_GIMBAL_SN,
    SIM_ROBOT_SN,
)
from gateway.local_broker import LocalBroker, free_port, port_open

DEFAULT_PORT = 1883
DEFAULT_HTTP_PORT = 9108
TOKEN_FILE = Path(".console-token")
_ANY = ("0.0.0.0", "::", "")


def _local(host: str) -> str:
    """The address a local client reaches ``host`` on (a wildcard bind: loopback)."""
    return "127.0.0.1" if host in _ANY else host


def _option(argv: Sequence[str], name: str) -> str | None:
    """The value of ``--name V`` or ``--name=V`` among the arguments passed on to ``dji-gateway run``."""
    for i, word in enumerate(argv):
        if word == name and i + 1 < len(argv):
            return argv[i + 1]
        if word.startswith(name + "="):
            return word.split("=", 1)[1]
    return None


def http_endpoint(argv: Sequence[str]) -> tuple[str, int, list[str]]:
    """Where the console and ``/status`` will answer, and the arguments to add so that they do: a port
    given (``--metrics-port``, ``$DJIGW_METRICS__PORT``) as it is; else 9108 when nothing listens there,
    or a free port chosen here (and said so); port 0: one chosen here, so it can be printed."""
    host = _option(argv, "--metrics-host") or os.environ.get("DJIGW_METRICS__HOST") or "127.0.0.1"
    given = _option(argv, "--metrics-port") or os.environ.get("DJIGW_METRICS__PORT")
    if given is not None and given.strip() not in ("", "0"):
        return host, int(given), []
    if given is None and not port_open(_local(host), DEFAULT_HTTP_PORT):
        return host, DEFAULT_HTTP_PORT, []
    port = free_port(_local(host))
    if given is None:
        print(f"port {DEFAULT_HTTP_PORT} is taken (another gateway?): this console and /status use {port}")
    return host, port, ["--metrics-port", str(port)]


#: the token file this run wrote (removed when the gateway has stopped: it served no one else)
_made: list[Path] = []


def token_file(http_port: int) -> Path:
    """This instance's token file: ``.console-token`` on the default port, ``.console-token-PORT`` on any
    other, so a second ``make run`` (serving on another port) never locks the first one's pages out."""
    return TOKEN_FILE if http_port == DEFAULT_HTTP_PORT else Path(f"{TOKEN_FILE}-{http_port}")


def console_token(http_host: str = "127.0.0.1", http_port: int = DEFAULT_HTTP_PORT) -> str:
    """Where the console token comes from: the environment's, or a fresh one in this instance's token
    file (never rewritten while a gateway answers on its port: that one's sign-ins still use it)."""
    if os.environ.get("DJIGW_CONSOLE__TOKEN"):
        return "the token in $DJIGW_CONSOLE__TOKEN"
    if os.environ.get("DJIGW_CONSOLE__TOKEN_FILE"):
        return f"the token in {os.environ['DJIGW_CONSOLE__TOKEN_FILE']}"
    path = token_file(http_port)
    if port_open(_local(http_host), http_port):  # this run will not start: the gateway there keeps its file
        return f"{path}, left as it is: a gateway already answers on port {http_port}"
    path.unlink(missing_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as out:
        out.write(secrets.token_urlsafe(24) + "\n")
    os.environ["DJIGW_CONSOLE__TOKEN_FILE"] = str(path.resolve())
    _made.append(path)
    return f"the token in {path} (new for this run, removed when it ends)"


def main(argv: Sequence[str] | None = None) -> int:
    url = os.environ.get("BROKER")
    broker: LocalBroker | None = None
    args = list(argv or [])
    http_host, http_port, extra = http_endpoint(args)
    args += extra
    if url is None:
        port = int(os.environ.get("PORT", str(DEFAULT_PORT))) or free_port()
        if port_open("127.0.0.1", port):
            url = f"mqtt://127.0.0.1:{port}"
            print(f"using the broker already listening on 127.0.0.1:{port}")
        else:
            broker = LocalBroker(port).start()
            url = broker.url
            print(f"started mosquitto on 127.0.0.1:{broker.port} (stopped when the gateway exits)")
    token = console_token(http_host, http_port)
    host_port = url.split("://", 1)[1]
    host, _, port_text = host_port.partition(":")
    port_text = port_text or str(DEFAULT_PORT)
    console_broker = "" if url == f"mqtt://127.0.0.1:{DEFAULT_PORT}" else f" --broker {url}"
    web = f"http://{_local(http_host)}:{http_port}"
    default_web = web == f"http://127.0.0.1:{DEFAULT_HTTP_PORT}"
    status_url = "" if default_web else f" --url {web}"
    monitor_url = "" if default_web else f" --status-url {web}"
    print(
        f"""
dji-gateway with simulated devices
  broker          {url}
  gateway sn      {SIM_GATEWAY_SN}
  gimbal          sn {SIM_GIMBAL_SN}, payload_index {SIM_GIMBAL_PAYLOAD_INDEX}
  robot           sn {SIM_ROBOT_SN}
  aircraft        sn {SIM_AIRCRAFT_SN}
publish Cloud API services to  thing/product/{SIM_GATEWAY_SN}/services
replies arrive on              thing/product/{SIM_GATEWAY_SN}/services_reply
telemetry                      thing/product/<device sn>/osd, sys/product/{SIM_GATEWAY_SN}/status
watch it:      dji-gateway monitor --gateway-sn {SIM_GATEWAY_SN}{console_broker}{monitor_url}
drive it:      dji-gateway send payload_authority_grab payload_index={SIM_GIMBAL_PAYLOAD_INDEX} \
--gateway-sn {SIM_GATEWAY_SN}{console_broker}
fly it:        dji-gateway fly --gateway-sn {SIM_GATEWAY_SN}{console_broker}   (or the console's DRC panel)
live control:  drc_mode_enter mqtt_broker.address={host}:{port_text} (this broker)
raw MQTT:      mosquitto_sub -h {host} -p {port_text} -t 'thing/product/#' -t 'sys/product/#' -v
status:        dji-gateway status{status_url}   (metrics on {web}/metrics)
web console:   {web}/   (actions: sign in with {token})
Ctrl-C stops the gateway (motion first, then the offline topology).
""",
        flush=True,
    )
    try:
        return cli_main(["run", "--simulate", "--broker", url, *args])
    finally:
        for path in _made:
            path.unlink(missing_ok=True)
        if broker is not None:
            broker.stop()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
