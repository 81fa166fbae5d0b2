"""The simulators' byte endpoints, on real pseudo-terminals: a device whose host stops reading keeps
running (as a flight controller keeps flying when the onboard computer's program exits) and talks
again as soon as a host reads."""

from __future__ import annotations

import serial

from adapters.simio import PtyEndpoint
from tests.support import wait_until


class Chatty:
    """200 bytes per tick, each tick's bytes carrying its number (mod 256)."""

    def __init__(self) -> None:
        self.ticks = 0

    def on_bytes(self, data: bytes, now: float) -> bytes:
        return b""

    def tick(self, now: float) -> bytes:
        self.ticks += 1
        return bytes([self.ticks & 0xFF]) * 200


def test_a_pty_nobody_reads_does_not_stop_the_device() -> None:
    device = Chatty()
    with PtyEndpoint(device, write_timeout=0.2) as pty:
        # far more than the pty buffer holds: the writes that do not fit are dropped, ticks go on
        wait_until(lambda: pty.dropped > 0 and device.ticks > 400, 30, what="ticks beyond a full buffer")
        port = serial.serial_for_url(pty.path, baudrate=230400, timeout=0.1)
        try:
            port.reset_input_buffer()
            seen_at = device.ticks
            fresh = wait_until(
                lambda: [b for b in port.read(4096) if b == (seen_at + 5) & 0xFF], 10, what="fresh bytes"
            )
            assert fresh and not pty._stalled
        finally:
            port.close()
