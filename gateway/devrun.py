"""``make run``: the gateway with simulated devices against a local broker, in one command.

Uses the broker given by ``BROKER`` (``mqtt://host:port``) when one answers there; otherwise
starts a private mosquitto on ``PORT`` (default 1883, or a free port when 1883 is taken by
something that is not an MQTT broker we may use) and stops it on exit. Prints where to publish.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence

from gateway.local_broker import LocalBroker, free_port, port_open
from gateway.run_cli import SIM_GATEWAY_SN, SIM_GIMBAL_PAYLOAD_INDEX, SIM_GIMBAL_SN


def main(argv: Sequence[str] | None = None) -> int:
    from gateway.cli import main as cli_main

    url = os.environ.get("BROKER")
    broker: LocalBroker | None = None
    if url is None:
        port = int(os.environ.get("PORT", "0")) or free_port()
        if port_open("127.0.0.1", port):
            url = f"mqtt://127.0.0.1:{port}"
            print(f"using the broker already listening on 127.0.0.1:{port}")
        else:
            broker = LocalBroker(port).start()
            url = broker.url
            print(f"started mosquitto on 127.0.0.1:{broker.port} (stopped when the gateway exits)")
    host_port = url.split("://", 1)[1]
    host, _, port_text = host_port.partition(":")
    print(
        f"""
dji-gateway with simulated devices
  broker          {url}
  gateway sn      {SIM_GATEWAY_SN}
  gimbal          sn {SIM_GIMBAL_SN}, payload_index {SIM_GIMBAL_PAYLOAD_INDEX}
publish Cloud API services to  thing/product/{SIM_GATEWAY_SN}/services
replies arrive on              thing/product/{SIM_GATEWAY_SN}/services_reply
telemetry                      thing/product/{SIM_GIMBAL_SN}/osd, sys/product/{SIM_GATEWAY_SN}/status
e.g.  mosquitto_sub -h {host} -p {port_text or 1883} -t 'thing/product/#' -t 'sys/product/#' -v
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
