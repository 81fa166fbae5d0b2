"""The SLCAN (Lawicel) ASCII protocol, adapter side: what a CANable / USB-CAN dongle speaks on its
serial port. Sans-I/O.

The gimbal simulator presents itself as such an adapter (on a pty or a TCP port), so the gateway
opens it with python-can's own ``slcan`` interface exactly as it would open real hardware. Only
what python-can sends is needed: ``O``/``L`` open, ``C`` close, ``Sn`` bitrate, ``V``/``N``
queries, ``tIIIL…``/``TIIIIIIIIL…`` transmit; each command line ends with CR and is answered with CR
(``z``/``Z`` + CR after a transmit) or BEL on error.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["SlcanAdapterState", "format_frame"]

_BITRATES = {
    "S0": 10_000,
    "S1": 20_000,
    "S2": 50_000,
    "S3": 100_000,
    "S4": 125_000,
    "S5": 250_000,
    "S6": 500_000,
    "S7": 750_000,
    "S8": 1_000_000,
    "S9": 83_300,
}
OK = b"\r"
ERROR = b"\a"


def format_frame(arb_id: int, data: bytes, extended: bool = False) -> bytes:
    """A received CAN frame as the adapter reports it to the host."""
    if extended:
        return f"T{arb_id:08X}{len(data):d}{data.hex().upper()}".encode() + OK
    return f"t{arb_id:03X}{len(data):d}{data.hex().upper()}".encode() + OK


@dataclass
class SlcanAdapterState:
    """Feed host bytes; get (answer bytes, CAN frames the host transmitted)."""

    is_open: bool = False
    bitrate: int | None = None
    _line: bytearray = field(default_factory=bytearray)

    def feed(self, data: bytes) -> tuple[bytes, list[tuple[int, bytes]]]:
        answer = bytearray()
        frames: list[tuple[int, bytes]] = []
        for byte in data:
            if byte != 0x0D:
                if len(self._line) < 64:
                    self._line.append(byte)
                continue
            line = self._line.decode("ascii", errors="replace")
            self._line.clear()
            reply, frame = self._command(line)
            answer += reply
            if frame is not None:
                frames.append(frame)
        return bytes(answer), frames

    def _command(self, line: str) -> tuple[bytes, tuple[int, bytes] | None]:
        if not line:
            return OK, None
        op = line[0]
        if op in "OL":
            self.is_open = True
            return OK, None
        if op == "C":
            self.is_open = False
            return OK, None
        if op == "S":
            rate = _BITRATES.get(line[:2])
            if rate is None:
                return ERROR, None
            self.bitrate = rate
            return OK, None
        if op == "Y" or op == "s":
            return OK, None
        if op == "V":
            return b"V1013" + OK, None
        if op == "N":
            return b"NSIM1" + OK, None
        if op == "F":
            return b"F00" + OK, None
        if op in "tT":
            if not self.is_open:
                return ERROR, None
            try:
                width = 3 if op == "t" else 8
                arb_id = int(line[1 : 1 + width], 16)
                dlc = int(line[1 + width])
                data = bytes.fromhex(line[2 + width : 2 + width + 2 * dlc])
            except (ValueError, IndexError):
                return ERROR, None
            if dlc > 8 or len(data) != dlc:
                return ERROR, None
            return (b"z" if op == "t" else b"Z") + OK, (arb_id, data)
        return ERROR, None
