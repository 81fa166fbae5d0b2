"""The CAN link's I/O paths on python-can's virtual bus (adapters/rsdk/link.py: LOOP_READ, NONBLOCKING_SEND).

On ``virtual`` the loop reads the bus itself (add_reader on a pipe the bus's receive queue signals) and
the sending thread writes it (no sender thread): frames reach ``on_frame`` in the loop's thread, with no
thread of the link's own; a command's frames stay together when several threads send at once; ``on_sent``
runs in the loop once they are on the bus; frames are received in order whatever their burst size.
"""

from __future__ import annotations

import asyncio
import threading
import uuid

import can

from adapters.rsdk.link import LOOP_READ, NONBLOCKING_SEND, CanLink


def _link(loop: asyncio.AbstractEventLoop, channel: str, got: list[tuple[int, bytes, int]]) -> CanLink:
    return CanLink(
        interface="virtual",
        channel=channel,
        bitrate=1_000_000,
        rx_id=0x222,
        loop=loop,
        on_frame=lambda arb, data: got.append((arb, data, threading.get_ident())),
        on_down=lambda reason: got.append((-1, reason.encode(), 0)),
    )


def test_virtual_is_read_by_the_loop_and_written_by_the_sender() -> None:
    assert "virtual" in LOOP_READ and "virtual" in NONBLOCKING_SEND
    assert "socketcan" not in NONBLOCKING_SEND  # a full socket buffer blocks: the sender thread writes it

    async def main() -> None:
        channel = f"link-{uuid.uuid4().hex[:6]}"
        peer = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        got: list[tuple[int, bytes, int]] = []
        loop = asyncio.get_running_loop()
        before = set(threading.enumerate())
        link = _link(loop, channel, got)
        await link.open()
        try:
            # no notifier, no sender thread (the executor's worker opened the bus: asyncio.to_thread)
            new = {t for t in set(threading.enumerate()) - before if not t.name.startswith("asyncio_")}
            assert new == set()

            # a flood from another thread, our id and another: ours arrive, in order, in the loop's thread
            def burst() -> None:
                for i in range(2000):
                    arb = 0x222 if i % 2 == 0 else 0x300
                    peer.send(can.Message(arbitration_id=arb, data=bytes([i % 256]), is_extended_id=False))

            await asyncio.to_thread(burst)
            for _ in range(200):
                if len(got) >= 1000:
                    break
                await asyncio.sleep(0.01)
            # (1000 of ours: more than READ_BATCH, so the loop reads them over several turns)
            assert [d[0] for _, d, _ in got] == [i % 256 for i in range(0, 2000, 2)]
            assert {t for _, _, t in got} == {threading.get_ident()}
            assert link.frames_in == 1000

            # sent from the loop and from another thread at once: each command's frames stay together
            sent = asyncio.Event()

            def commands(tag: int) -> None:
                for n in range(50):
                    link.send([(0x223, bytes([tag, n, k])) for k in range(4)])

            writer = threading.Thread(target=commands, args=(1,))
            writer.start()
            commands(2)
            link.send([(0x223, b"\xff")], on_sent=sent.set)
            writer.join()
            await asyncio.wait_for(sent.wait(), 5)
            frames = []
            while (msg := peer.recv(0.5)) is not None:
                frames.append(bytes(msg.data))
            commands_seen = [frames[i : i + 4] for i in range(0, 400, 4)]
            for command in commands_seen:
                assert len({(f[0], f[1]) for f in command}) == 1 and [f[2] for f in command] == [0, 1, 2, 3]
            assert link.frames_out == 401 and link.send_errors == 0
        finally:
            link.close()
            peer.shutdown()
        assert not [g for g in got if g[0] == -1]  # never reported down

    asyncio.run(main())


def test_virtual_link_reopens_and_reads_again() -> None:
    """close() undoes the loop reader (pipe closed, no reader left on the loop); a reopen reads again."""

    async def main() -> None:
        channel = f"link-{uuid.uuid4().hex[:6]}"
        peer = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        got: list[tuple[int, bytes, int]] = []
        link = _link(asyncio.get_running_loop(), channel, got)
        try:
            for round_ in range(3):
                await link.open()
                peer.send(can.Message(arbitration_id=0x222, data=bytes([round_]), is_extended_id=False))
                for _ in range(100):
                    if len(got) > round_:
                        break
                    await asyncio.sleep(0.01)
                link.close()
            assert [d for _, d, _ in got] == [b"\x00", b"\x01", b"\x02"]
        finally:
            peer.shutdown()

    asyncio.run(main())
