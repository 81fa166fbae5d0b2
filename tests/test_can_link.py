"""The CAN link's I/O paths on python-can's virtual bus (adapters/rsdk/link.py: LOOP_READ, NONBLOCKING_SEND).

On ``virtual`` the loop reads the bus itself (add_reader on a pipe the bus's receive queue signals) and
the sending thread writes it (no sender thread): frames reach ``on_frame`` in the loop's thread, with no
thread of the link's own; a command's frames stay together when several threads send at once; ``on_sent``
runs in the loop once they are on the bus; frames are received in order whatever their burst size.
"""

from __future__ import annotations

import asyncio
import os
import threading
import time
import uuid

import can
import pytest

from adapters.rsdk.link import (
    LOOP_READ,
    NONBLOCKING_SEND,
    CanLink,
    virtual_batch_sender,
    virtual_reader,
    virtual_sender,
)


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


ROUNDS = 6000


def test_frames_sent_one_by_one_are_never_stranded() -> None:
    """A peer answering like a device (one to three frames, then a wait for the link to take them), many
    times: the receive queue signals the loop once per batch, and no frame put while the loop is reading
    is left behind without a signal (a frame put between the loop emptying the pipe and re-arming would
    wait for the next frame that never comes)."""

    async def main() -> None:
        channel = f"link-{uuid.uuid4().hex[:6]}"
        peer = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        got: list[tuple[int, bytes, int]] = []
        link = _link(asyncio.get_running_loop(), channel, got)
        await link.open()
        stranded: list[int] = []

        def device() -> None:
            sent = 0
            for round_ in range(ROUNDS):
                burst = 1 + round_ % 3
                for _ in range(burst):
                    data = (sent % 65536).to_bytes(2, "big")
                    peer.send(can.Message(arbitration_id=0x222, data=data, is_extended_id=False))
                    sent += 1
                # the next burst as soon as the loop is reading this one (all of it, every 10th round)
                need = sent if round_ % 10 == 9 or round_ == ROUNDS - 1 else sent - burst + 1
                deadline = time.monotonic() + 2.0
                while len(got) < need:
                    if time.monotonic() > deadline:
                        stranded.append(round_)
                        return
                    time.sleep(0)

        try:
            await asyncio.to_thread(device)
        finally:
            link.close()
            peer.shutdown()
        assert not stranded, f"frames left in the queue without a signal at round {stranded[0]}"
        assert [int.from_bytes(d, "big") for _, d, _ in got] == [i % 65536 for i in range(len(got))]
        assert len(got) == sum(1 + r % 3 for r in range(ROUNDS))

    asyncio.run(main())


def _fields(msg: can.Message) -> tuple[object, ...]:
    return (msg.arbitration_id, bytes(msg.data), msg.dlc, msg.is_extended_id, msg.is_error_frame,
            msg.is_remote_frame, msg.is_fd, msg.is_rx, msg.channel)  # fmt: skip


def test_virtual_sender_delivers_what_python_can_delivers() -> None:
    """``virtual_sender`` (no deep copy per receiver) against python-can's own ``VirtualBus.send`` on the
    same channel layout: every receiver gets the same fields (``is_rx``, ``channel``, a fresh timestamp),
    its own object, and the sender's own queue a copy only with ``receive_own_messages``; a full receiver
    and a closed bus fail the same way."""
    for own in (False, True):
        channel = f"vs-{uuid.uuid4().hex[:6]}"
        sender = can.Bus(interface="virtual", channel=channel, receive_own_messages=own)
        peers = [can.Bus(interface="virtual", channel=channel) for _ in range(2)]
        put = virtual_sender(sender)
        assert put is not None
        try:
            theirs: list[tuple[object, ...]] = []
            ours: list[tuple[object, ...]] = []
            for send, out in ((lambda m, bus=sender: bus.send(m, timeout=0), theirs), (put, ours)):
                before = time.time()
                send(can.Message(arbitration_id=0x223, data=b"\x01\x02\x03", is_extended_id=False))
                got = [p.recv(1.0) for p in peers] + ([sender.recv(1.0)] if own else [])
                assert all(m is not None and m.timestamp >= before for m in got)
                assert len({id(m) for m in got}) == len(got)  # each receiver its own message
                out.extend(_fields(m) for m in got if m is not None)
                assert sender.recv(0) is None and all(p.recv(0) is None for p in peers)
            assert ours == theirs
        finally:
            for bus in (*peers, sender):
                bus.shutdown()

    channel = f"vs-{uuid.uuid4().hex[:6]}"
    sender = can.Bus(interface="virtual", channel=channel)
    full = can.Bus(interface="virtual", channel=channel, rx_queue_size=1)
    put = virtual_sender(sender)
    assert put is not None
    put(can.Message(arbitration_id=1, data=b"\x00"))
    with pytest.raises(can.CanOperationError):
        put(can.Message(arbitration_id=1, data=b"\x01"))
    with pytest.raises(can.CanOperationError):
        sender.send(can.Message(arbitration_id=1, data=b"\x02"), timeout=0)
    full.shutdown()
    sender.shutdown()
    with pytest.raises(can.CanOperationError):
        put(can.Message(arbitration_id=1, data=b"\x03"))
    assert virtual_sender(can.Bus(interface="virtual", channel=channel)) is not None


def test_a_frame_put_while_the_loop_empties_the_pipe_still_signals_the_next(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The race the stress test above can only hit by luck, made to happen: a device puts a frame just as
    the loop empties the signal pipe (os.read releases the GIL). That frame is read in the same pass, and
    the frame after it still wakes the loop: the receive queue must not be left marked as signalled with
    an empty pipe (the pipe is emptied before the queue is re-armed, not after)."""

    async def main() -> None:
        channel = f"link-{uuid.uuid4().hex[:6]}"
        peer = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        got: list[tuple[int, bytes, int]] = []
        link = _link(asyncio.get_running_loop(), channel, got)
        await link.open()
        reader = link._reader
        assert reader is not None

        def frame(n: int) -> can.Message:
            return can.Message(arbitration_id=0x222, data=bytes([n]), is_extended_id=False)

        real_read = os.read
        injected: list[int] = []

        def read(fd: int, n: int) -> bytes:
            if fd == reader.fd and not injected:
                injected.append(fd)
                peer.send(frame(1))  # from the device, in the middle of the loop's clear()
            return real_read(fd, n)

        async def until(count: int) -> bool:
            for _ in range(200):
                if len(got) >= count:
                    return True
                await asyncio.sleep(0.01)
            return False

        try:
            monkeypatch.setattr(os, "read", read)
            peer.send(frame(0))
            assert await until(2) and injected
            monkeypatch.undo()
            peer.send(frame(2))
            assert await until(3), "the frame after the race never woke the loop"
            assert [d for _, d, _ in got] == [b"\x00", b"\x01", b"\x02"]
        finally:
            monkeypatch.undo()
            link.close()
            peer.shutdown()

    asyncio.run(main())


def test_a_batch_reaches_a_signalled_reader_whole_with_one_signal() -> None:
    """``virtual_batch_sender`` (one command's frames): a reader of ``virtual_reader`` finds every frame
    of the batch, in order, behind one byte in its pipe (one wake-up, never half a command); a plain
    python-can receiver on the same channel gets them too; the sender's timestamps are fresh."""
    channel = f"vb-{uuid.uuid4().hex[:6]}"
    sender = can.Bus(interface="virtual", channel=channel)
    plain = can.Bus(interface="virtual", channel=channel)
    watched = can.Bus(interface="virtual", channel=channel)
    reader = virtual_reader(watched)
    send_all = virtual_batch_sender(sender)
    assert reader is not None and reader.take is not None and send_all is not None
    try:
        before = time.time()
        send_all([can.Message(arbitration_id=0x223, data=bytes([i]), is_extended_id=False) for i in range(3)])
        assert os.read(reader.fd, 100) == b"\0"  # one signal for the batch
        reader.clear()
        taken = [reader.take() for _ in range(4)]
        assert [bytes(m.data) for m in taken if m is not None] == [b"\x00", b"\x01", b"\x02"]
        assert taken[3] is None
        assert all(m is not None and m.timestamp >= before and m.is_rx for m in taken[:3])
        assert [bytes(m.data) for m in (plain.recv(1.0) for _ in range(3)) if m is not None] == [
            b"\x00", b"\x01", b"\x02"
        ]  # fmt: skip
        # python-can's own recv on the swapped queue still works (with and without a timeout)
        send_all([can.Message(arbitration_id=0x223, data=b"\x09", is_extended_id=False)])
        got = watched.recv(1.0)
        assert got is not None and bytes(got.data) == b"\x09" and watched.recv(0) is None
    finally:
        for bus in (sender, plain, watched):
            bus.shutdown()
        reader.close()


def test_a_bounded_receiver_stays_bounded_when_read_by_a_pipe() -> None:
    """A receiver opened with ``rx_queue_size`` keeps its bound after its queue is swapped for a
    signalled one: a batch that does not fit fails the send, as python-can's own send does."""
    channel = f"vq-{uuid.uuid4().hex[:6]}"
    sender = can.Bus(interface="virtual", channel=channel)
    small = can.Bus(interface="virtual", channel=channel, rx_queue_size=2)
    reader = virtual_reader(small)
    send_all = virtual_batch_sender(sender)
    assert reader is not None and reader.take is not None and send_all is not None
    try:
        with pytest.raises(can.CanOperationError):
            send_all([can.Message(arbitration_id=1, data=bytes([i])) for i in range(3)])
        taken = [reader.take() for _ in range(3)]
        assert [bytes(m.data) for m in taken if m is not None] == [b"\x00", b"\x01"] and taken[2] is None
    finally:
        sender.shutdown()
        small.shutdown()
        reader.close()
