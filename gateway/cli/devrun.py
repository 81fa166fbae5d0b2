"""``make run``: the gateway with simulated devices against a local broker, in one command.

Uses the broker given by ``BROKER`` (``mqtt://host:port``) when set; otherwise the one already
listening on 127.0.0.1:``PORT`` (default 1883, the port ``dji-gateway send``/``monitor`` use by
default), or else starts a private mosquitto there (``PORT=0``: any free port) and stops it on exit.
Prints where to publish and the console commands that drive the simulated devices. The web console's
token (unless ``DJIGW_CONSOLE__TOKEN`` or ``DJIGW_CONSOLE__TOKEN_FILE`` names one) is made fresh for the
run and written to ``.console-token`` (mode 0600), never printed: sign in with what that file holds.
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
TOKEN_FILE = Path(".console-token")


def console_token() -> str:
    """Where the console token comes from: the environment's, or a fresh one in ``.console-token``."""
    if os.environ.get("DJIGW_CONSOLE__TOKEN"):
        return "the token in $DJIGW_CONSOLE__TOKEN"
    if os.environ.get("DJIGW_CONSOLE__TOKEN_FILE"):
        return f"the token in {os.environ['DJIGW_CONSOLE__TOKEN_FILE']}"
    TOKEN_FILE.unlink(missing_ok=True)
    fd = os.open(TOKEN_FILE, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "w") as out:
        out.write(secrets.token_urlsafe(24) + "\n")
    os.environ["DJIGW_CONSOLE__TOKEN_FILE"] = str(TOKEN_FILE.resolve())
    return f"the token in {TOKEN_FILE} (new for this run)"


def main(argv: Sequence[str] | None = None) -> int:
    url = os.environ.get("BROKER")
    broker: LocalBroker | None = None
    if url is None:
        port = int(os.environ.get("PORT", str(DEFAULT_PORT))) or free_port()
        if port_open("127.0.0.1", port):
            url = f"mqtt://127.0.0.1:{port}"
            print(f"using the broker already listening on 127.0.0.1:{port}")
        else:
            broker = LocalBroker(port).start()
            url = broker.url
            print(f"started mosquitto on 127.0.0.1:{broker.port} (stopped when the gateway exits)")
    token = console_token()
    host_port = url.split("://", 1)[1]
    host, _, port_text = host_port.partition(":")
    console_broker = "" if url == f"mqtt://127.0.0.1:{DEFAULT_PORT}" else f" --broker {url}"
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
watch it:      dji-gateway monitor --gateway-sn {SIM_GATEWAY_SN}{console_broker}
drive it:      dji-gateway send payload_authority_grab payload_index={SIM_GIMBAL_PAYLOAD_INDEX} \
--gateway-sn {SIM_GATEWAY_SN}{console_broker}
raw MQTT:      mosquitto_sub -h {host} -p {port_text or 1883} -t 'thing/product/#' -t 'sys/product/#' -v
status:        dji-gateway status   (metrics on http://127.0.0.1:9108/metrics unless --metrics-port)
web console:   http://127.0.0.1:9108/   (actions: sign in with {token})
Ctrl-C stops the gateway (motion first, then the offline topology).
""",
        flush=True,
    )
    try:
        return cli_main(["run", "--simulate", "--broker", url, *(argv or [])])
    finally:
        if broker is not None:
            broker.stop()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
