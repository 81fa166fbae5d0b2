"""``gateway.local_broker.free_port``: the ports the tests' brokers listen on, and listen on again after
a restart, come from outside the kernel's ephemeral range, so no connection's local end can take one
while its broker is down (a NATS node once could not listen again on its own port: "address already in
use" for a port the kernel had meanwhile given to a connection)."""

from __future__ import annotations

import socket
from pathlib import Path

from gateway.local_broker import LocalBroker, free_port


def _ephemeral_low() -> int:
    return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])


def test_free_ports_are_bindable_and_outside_the_ephemeral_range() -> None:
    low = _ephemeral_low()
    ports = [free_port() for _ in range(50)]
    if low > 20001:  # (a machine whose ephemeral range starts lower leaves no room: any free port then)
        assert all(20000 <= p < low for p in ports), ports
    assert len(set(ports)) > 40  # chosen at random, not one port handed out again and again
    for port in ports[:5]:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind(("127.0.0.1", port))


def test_a_port_in_use_is_never_handed_out() -> None:
    held = []
    try:
        for _ in range(20):
            s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            port = free_port()
            s.bind(("127.0.0.1", port))  # raises if free_port handed out a port in use
            s.listen()
            held.append(s)
    finally:
        for s in held:
            s.close()


def test_a_broker_restarts_on_its_free_port() -> None:
    with LocalBroker() as broker:
        port = broker.port
        broker.stop()
        broker.start()
        assert broker.port == port
        with socket.create_connection(("127.0.0.1", port), timeout=2):
            pass
