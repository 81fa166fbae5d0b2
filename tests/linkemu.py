"""A userspace link emulator: a TCP relay that applies delay, jitter and loss to what crosses it, for
kernels without ``sch_netem`` (``tc qdisc add … netem`` → "Specified qdisc kind is unknown").

Run as its own process (``python -m tests.linkemu --listen HOST:PORT --to HOST:PORT --delay-ms 40
--jitter-ms 10 --loss 0.01``) between the gateway's network namespace and the broker. Each chunk read
from one side is written to the other after ``delay ± jitter`` (uniform), per direction, never
reordered (a chunk waits for the one before it, as TCP delivers). A byte stream cannot lose bytes, so
*loss* is emulated by its effect on TCP: a lost chunk (probability ``loss`` per chunk, each direction)
arrives one retransmission later (``--rto-ms``, 250 ms: Linux's 200 ms minimum RTO plus a round trip)
and holds up everything behind it (head-of-line blocking). TCP handshakes are not delayed (the relay's
kernel answers them); a partition is made on the veth itself (``ip link set … down``), not here.
What differs from netem is documented in docs/reliability.md. Standard library only.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import random
import signal
import sys
import time
from collections.abc import Sequence

__all__ = ["main"]


class _Direction:
    def __init__(self, delay: float, jitter: float, loss: float, rto: float, rng: random.Random) -> None:
        self.delay, self.jitter, self.loss, self.rto, self.rng = delay, jitter, loss, rto, rng
        self.last = 0.0

    def deliver_at(self, now: float) -> float:
        at = now + self.delay + self.rng.uniform(-self.jitter, self.jitter)
        if self.loss and self.rng.random() < self.loss:
            at += self.rto
        self.last = max(self.last, at)  # in order: never before the chunk ahead of it
        return self.last


async def _pump(reader: asyncio.StreamReader, writer: asyncio.StreamWriter, way: _Direction) -> None:
    queue: asyncio.Queue[tuple[float, bytes] | None] = asyncio.Queue()

    async def deliver() -> None:
        while True:
            item = await queue.get()
            if item is None:
                break
            at, data = item
            wait = at - time.monotonic()
            if wait > 0:
                await asyncio.sleep(wait)
            writer.write(data)
            await writer.drain()
        with contextlib.suppress(OSError):
            writer.write_eof()

    task = asyncio.create_task(deliver())
    try:
        while True:
            data = await reader.read(65536)
            if not data:
                break
            queue.put_nowait((way.deliver_at(time.monotonic()), data))
        queue.put_nowait(None)
        await task
    except (OSError, asyncio.IncompleteReadError):
        task.cancel()
    finally:
        with contextlib.suppress(OSError):
            writer.close()


async def _serve(listen: tuple[str, int], to: tuple[str, int], ns: argparse.Namespace) -> None:
    rng = random.Random(ns.seed)

    async def handle(down_r: asyncio.StreamReader, down_w: asyncio.StreamWriter) -> None:
        try:
            up_r, up_w = await asyncio.open_connection(*to)
        except OSError:
            down_w.close()
            return
        d, j, loss, rto = ns.delay_ms / 1000, ns.jitter_ms / 1000, ns.loss, ns.rto_ms / 1000
        await asyncio.gather(
            _pump(down_r, up_w, _Direction(d, j, loss, rto, rng)),
            _pump(up_r, down_w, _Direction(d, j, loss, rto, rng)),
            return_exceptions=True,
        )

    server = await asyncio.start_server(handle, *listen, reuse_address=True)
    print(f"linkemu listening on {listen[0]}:{listen[1]}", flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, stop.set)
    async with server:
        await stop.wait()


def _addr(text: str) -> tuple[str, int]:
    host, _, port = text.rpartition(":")
    return host, int(port)


def main(argv: Sequence[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="linkemu", description=__doc__.splitlines()[0])
    p.add_argument("--listen", required=True, type=_addr)
    p.add_argument("--to", required=True, type=_addr)
    p.add_argument("--delay-ms", type=float, default=40.0, help="one-way delay (each direction)")
    p.add_argument("--jitter-ms", type=float, default=10.0, help="± uniform, each direction")
    p.add_argument("--loss", type=float, default=0.01, help="per chunk, each direction")
    p.add_argument("--rto-ms", type=float, default=250.0, help="extra delay of a lost chunk")
    p.add_argument("--seed", type=int, default=None)
    ns = p.parse_args(argv)
    asyncio.run(_serve(ns.listen, ns.to, ns))
    return 0


if __name__ == "__main__":
    sys.exit(main())
