"""A small MQTT-aware TCP proxy for tests: it listens on a loopback port, opens a connection to the
upstream broker for every client it accepts, and splits each direction's byte stream into whole MQTT
control packets (the fixed header's remaining length; a packet cut across reads waits in that
direction's buffer, several in one read come out one by one). A filter per direction sees every packet
and says whether it passes (True) or is dropped (False); it may note packets meanwhile. A direction
with no filter is passed on as raw bytes, unparsed.

It owns the sockets, the selector loop on its own thread and the framing. It must not know anything
about the gateway, its topics or its payloads: which packets are dropped, and when, is its filters'
business (``DeafProxy`` in test_liveness, ``CutProxy`` in test_exactly_once_kill).
"""

from __future__ import annotations

import selectors
import socket
import threading
from collections.abc import Callable, Iterator

#: MQTT control packet type of a PUBLISH (the fixed header's high nibble)
PUBLISH = 3

#: Decides for one whole packet whether it passes (True) or is dropped (False)
Filter = Callable[[bytes], bool]


def mqtt_packets(buf: bytearray) -> Iterator[bytes]:
    """Whole MQTT control packets at the front of ``buf`` (removed from it); a partial one stays."""
    while len(buf) >= 2:
        length, multiplier, i = 0, 1, 1
        while True:
            if i >= len(buf):
                return
            byte = buf[i]
            length += (byte & 0x7F) * multiplier
            multiplier *= 128
            i += 1
            if not byte & 0x80:
                break
        if len(buf) < i + length:
            return
        packet = bytes(buf[: i + length])
        del buf[: i + length]
        yield packet


def packet_type(packet: bytes) -> int:
    """The control packet type of a whole packet (``PUBLISH`` for a PUBLISH)."""
    return packet[0] >> 4


class MqttProxy:
    """TCP proxy on 127.0.0.1 (``port``) to ``upstream``. ``to_server`` filters the packets each client
    sends towards the broker, ``to_client`` those the broker sends back; None passes that direction's
    bytes as they come. ``close()`` stops it and closes every socket."""

    def __init__(
        self,
        upstream: tuple[str, int],
        *,
        to_server: Filter | None = None,
        to_client: Filter | None = None,
        name: str = "mqtt-proxy",
    ) -> None:
        self.upstream = upstream
        self._to_server, self._to_client = to_server, to_client
        self._listener = socket.create_server(("127.0.0.1", 0))
        self.port: int = self._listener.getsockname()[1]
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        sel = selectors.DefaultSelector()
        self._listener.setblocking(False)
        sel.register(self._listener, selectors.EVENT_READ, None)
        # sock -> (its peer, the filter of what it sends, that direction's buffer)
        pairs: dict[socket.socket, tuple[socket.socket, Filter | None, bytearray]] = {}
        while not self._stop.is_set():
            for key, _ in sel.select(0.05):
                sock = key.fileobj
                assert isinstance(sock, socket.socket)
                if sock is self._listener:
                    client, _ = self._listener.accept()
                    try:
                        server = socket.create_connection(self.upstream, timeout=2)
                    except OSError:
                        client.close()
                        continue
                    for s in (client, server):
                        s.setblocking(True)
                        s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                        sel.register(s, selectors.EVENT_READ, None)
                    pairs[client] = (server, self._to_server, bytearray())
                    pairs[server] = (client, self._to_client, bytearray())
                    continue
                peer, passes, buf = pairs[sock]
                try:
                    data = sock.recv(65536)
                except OSError:
                    data = b""
                if not data:
                    for s in (sock, peer):
                        sel.unregister(s)
                        pairs.pop(s, None)
                        s.close()
                    continue
                try:
                    if passes is None:
                        peer.sendall(data)
                        continue
                    buf.extend(data)
                    for packet in mqtt_packets(buf):
                        if passes(packet):
                            peer.sendall(packet)
                except OSError:
                    pass
        for s in list(pairs):
            s.close()
        self._listener.close()
        sel.close()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(5)
