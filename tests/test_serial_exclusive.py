"""A serial port has one owner: the link opens a tty with ``exclusive=True`` (flock), and a port that
another process holds is reported as "in use by another process" with the command that finds it, not
silently shared (two readers of one UART each get half the bytes). Real ptys, a real second process."""

from __future__ import annotations

import asyncio
import subprocess
import sys
import textwrap

import pytest

from adapters.errors import LinkError
from adapters.serial_link import SerialLink
from adapters.simio import PtyEndpoint


class _Quiet:
    def on_bytes(self, data: bytes, now: float) -> bytes:
        return b""

    def tick(self, now: float) -> bytes:
        return b""


def _holder(path: str) -> subprocess.Popen[str]:
    """Another process (a second gateway, a terminal program that locks) holding the port."""
    code = textwrap.dedent(
        f"""
        import sys, serial
        port = serial.Serial({path!r}, 115200, exclusive=True)
        print("held", flush=True)
        sys.stdin.read()
        """
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout is not None and proc.stdout.readline().strip() == "held"
    return proc


def test_a_port_held_by_another_process_is_reported_as_in_use() -> None:
    pty = PtyEndpoint(_Quiet()).start()
    holder = _holder(pty.path)

    async def attempt() -> SerialLink:
        link = SerialLink(url=pty.path, baudrate=115200, loop=asyncio.get_running_loop(),
                          on_bytes=lambda b: None, on_down=lambda r: None)  # fmt: skip
        await link.open()
        return link

    try:
        with pytest.raises(LinkError) as caught:
            asyncio.run(attempt())
        message = str(caught.value)
        assert "in use by another process" in message and f"fuser -v {pty.path}" in message, message
    finally:
        assert holder.stdin is not None
        holder.stdin.close()
        holder.wait(10)
        if holder.stdout is not None:
            holder.stdout.close()

    async def then_free() -> None:
        link = await attempt()  # the other process is gone: the port is ours
        assert link.up
        # and now we hold it: the same other process is refused
        proc = subprocess.run(
            [sys.executable, "-c", f"import serial; serial.Serial({pty.path!r}, 115200, exclusive=True)"],
            capture_output=True, text=True, timeout=30,
        )  # fmt: skip
        assert proc.returncode != 0 and "Could not exclusively lock port" in proc.stderr
        link.close()

    try:
        asyncio.run(then_free())
    finally:
        pty.stop()
