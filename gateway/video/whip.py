"""WHIP publishing (WebRTC-HTTP Ingestion Protocol, RFC 9725): the program the video service runs in place
of a bare ffmpeg for ``url_type`` 4.

``python -m gateway.video.whip --url URL [--ice-server stun:…] -- FFMPEG-ARGV`` runs FFMPEG-ARGV (the
pipeline :func:`gateway.video.engine.build_command` made, whose target is MPEG-TS H.264 on the placeholder
:data:`~gateway.video.engine.WHIP_PIPE`) as its child, demuxes what it writes with PyAV, and sends the
H.264 as it is (no second encode: aiortc packetizes the encoded packets) to the WHIP endpoint over a
WebRTC peer connection made with aiortc: one SDP offer POSTed, the answer taken from the 201, the
resource DELETEd when the stream stops.

Owns: the ffmpeg child (killed with this process: ``PR_SET_PDEATHSIG``), the peer connection, the WHIP
resource, and the ``-progress`` lines: ffmpeg's go to a pipe of this program, and are passed on to the
progress fd the supervisor gave only once the peer connection is *connected*, so the video service's
``live_status`` says live when the endpoint really receives, not when the encoder starts. Exits non-zero
with one line on stderr (what failed: the POST's status, ICE/DTLS, ffmpeg) so the supervisor restarts it
with backoff. Knows nothing about MQTT, the Cloud API or which device the video belongs to.

ICE: host candidates, and server-reflexive/relayed ones only when ``--ice-server`` names STUN/TURN servers
(none by default: aiortc would otherwise ask stun.l.google.com). A WHIP endpoint is normally reachable
from the edge computer (ICE-lite servers on public addresses), which host candidates are enough for.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import ctypes
import os
import signal
import sys
import threading
from collections.abc import Sequence
from typing import Any
from urllib.parse import urljoin

import aiohttp
import av
from aiortc import (
    MediaStreamTrack,
    RTCConfiguration,
    RTCIceServer,
    RTCPeerConnection,
    RTCRtpSender,
    RTCSessionDescription,
)
from aiortc.mediastreams import MediaStreamError

from gateway.video.engine import WHIP_PIPE, redact_url

__all__ = ["main"]

#: how long the POST and then ICE + DTLS may take before the attempt fails (the supervisor retries)
CONNECT_TIMEOUT = 15.0
#: encoded packets waiting for the sender (1 s at 30 fps); the oldest go first when it falls behind
QUEUE = 30
PR_SET_PDEATHSIG = 1


class _Failed(Exception):
    """One line for the supervisor: why this attempt ended."""


class PacketTrack(MediaStreamTrack):
    """H.264 packets as a video track: aiortc's sender packetizes an ``av.Packet`` without decoding it.
    The first packet handed out is a keyframe (a receiver cannot start on anything else)."""

    kind = "video"

    def __init__(self) -> None:
        super().__init__()
        self.queue: asyncio.Queue[av.Packet[Any] | None] = asyncio.Queue(QUEUE)
        self._started = False

    def put(self, packet: av.Packet[Any] | None) -> None:
        """On the loop: a packet from the demuxer (None: the stream ended)."""
        if self.queue.full():
            self.queue.get_nowait()  # the oldest goes: a live stream never waits on a late sender
        self.queue.put_nowait(packet)

    async def recv(self) -> av.Packet[Any]:
        while True:
            packet = await self.queue.get()
            if packet is None:
                self.stop()
                raise MediaStreamError  # aiortc's end of a track
            if self._started or packet.is_keyframe:
                self._started = True
                return packet


def _pdeathsig() -> None:
    """In the ffmpeg child, before exec: SIGKILL it when this program dies (even by SIGKILL)."""
    libc = ctypes.CDLL("libc.so.6", use_errno=True)
    libc.prctl(PR_SET_PDEATHSIG, signal.SIGKILL)


def _demux(fd: int, loop: asyncio.AbstractEventLoop, track: PacketTrack, errors: list[str]) -> None:
    """On a thread of its own (PyAV reads block): MPEG-TS from ffmpeg → H.264 packets to the track."""
    try:
        # unbuffered: a buffered reader would wait for a whole buffer (~130 ms of video at 2 Mbps)
        with os.fdopen(fd, "rb", buffering=0) as pipe, av.open(pipe, format="mpegts", mode="r") as container:
            stream = container.streams.video[0]
            for packet in container.demux(stream):
                if packet.size and packet.pts is not None:
                    loop.call_soon_threadsafe(track.put, packet)
    except (av.FFmpegError, OSError, ValueError, IndexError) as exc:
        errors.append(f"reading the encoder's stream: {exc}")
    finally:
        with contextlib.suppress(RuntimeError):  # the loop may be closed already
            loop.call_soon_threadsafe(track.put, None)


def _h264_only(pc: RTCPeerConnection, track: PacketTrack) -> None:
    """One send-only transceiver offering H.264 alone: the packets are H.264, nothing is re-encoded."""
    transceiver = pc.addTransceiver(track, direction="sendonly")
    codecs = [c for c in RTCRtpSender.getCapabilities("video").codecs if c.mimeType.lower() == "video/h264"]
    transceiver.setCodecPreferences(codecs)


class Publisher:
    """One WHIP session: ffmpeg started, offer posted, connected, progress passed on, torn down."""

    def __init__(self, url: str, ffmpeg: Sequence[str], ice_servers: Sequence[str]) -> None:
        self.url = url
        self.ffmpeg = list(ffmpeg)
        self.ice_servers = list(ice_servers)
        self.resource: str | None = None
        self.proc: asyncio.subprocess.Process | None = None
        self.errors: list[str] = []
        self.connected = asyncio.Event()
        self.failed = asyncio.Event()

    def _command(self, video_w: int, progress_w: int) -> tuple[list[str], int]:
        """The ffmpeg argv with its target on ``video_w`` and its progress on ``progress_w``; and the
        progress fd the supervisor gave (-1: none)."""
        cmd = [arg.replace(WHIP_PIPE, f"pipe:{video_w}") for arg in self.ffmpeg]
        forward = -1
        if "-progress" in cmd:
            i = cmd.index("-progress") + 1
            if cmd[i].startswith("pipe:"):
                forward = int(cmd[i][len("pipe:") :])
            cmd[i] = f"pipe:{progress_w}"
        if not any(f"pipe:{video_w}" in arg for arg in cmd):
            raise _Failed(f"the ffmpeg command has no {WHIP_PIPE} target")
        return cmd, forward

    async def run(self, stop: asyncio.Event) -> int:
        loop = asyncio.get_running_loop()
        video_r, video_w = os.pipe()
        progress_r, progress_w = os.pipe()
        cmd, forward = self._command(video_w, progress_w)
        track = PacketTrack()
        servers = [RTCIceServer(s) for s in self.ice_servers]
        pc = RTCPeerConnection(RTCConfiguration(iceServers=servers))

        @pc.on("connectionstatechange")
        def _state() -> None:
            if pc.connectionState == "connected":
                self.connected.set()
            elif pc.connectionState in ("failed", "closed"):
                self.failed.set()

        try:
            self.proc = await asyncio.create_subprocess_exec(
                *cmd, stdin=asyncio.subprocess.DEVNULL, pass_fds=(video_w, progress_w), preexec_fn=_pdeathsig
            )
        except FileNotFoundError:
            raise _Failed(f"{cmd[0]} not found (apt-get install ffmpeg)") from None
        finally:
            os.close(video_w)
            os.close(progress_w)
        threading.Thread(target=_demux, args=(video_r, loop, track, self.errors), daemon=True).start()
        progress = loop.create_task(self._progress(progress_r, forward))
        try:
            _h264_only(pc, track)
            await pc.setLocalDescription(await pc.createOffer())  # aiortc gathers every candidate here
            async with asyncio.timeout(CONNECT_TIMEOUT):
                answer = await self._post(pc.localDescription.sdp)
                await pc.setRemoteDescription(RTCSessionDescription(sdp=answer, type="answer"))
                await _first(self.connected.wait(), self.failed.wait(), stop.wait())
            if not self.connected.is_set() and not stop.is_set():
                raise _Failed(f"WebRTC with {redact_url(self.url)}: ICE/DTLS {pc.connectionState}")
            ended = loop.create_task(self.proc.wait())
            await _first(ended, self.failed.wait(), stop.wait())
            if stop.is_set():
                return 0
            if self.failed.is_set():
                raise _Failed(f"WebRTC with {redact_url(self.url)}: connection {pc.connectionState}")
            code = await ended
            raise _Failed(f"ffmpeg exited {code}" + (f": {self.errors[-1]}" if self.errors else ""))
        except TimeoutError:
            raise _Failed(
                f"WHIP {redact_url(self.url)}: not connected within {CONNECT_TIMEOUT:g} s "
                f"(ICE {pc.iceConnectionState})"
            ) from None
        finally:
            await self._teardown(pc)
            progress.cancel()

    async def _post(self, offer: str) -> str:
        headers = {"Content-Type": "application/sdp"}
        try:
            async with aiohttp.ClientSession() as http, http.post(self.url, data=offer, headers=headers) as r:
                body = await r.text()
                if r.status != 201:
                    raise _Failed(f"WHIP {redact_url(self.url)} answered {r.status} {r.reason} to the offer")
                if "location" in r.headers:
                    self.resource = urljoin(str(r.url), r.headers["location"])
                return body
        except aiohttp.ClientError as exc:
            raise _Failed(f"WHIP {redact_url(self.url)}: {type(exc).__name__}: {exc}") from None

    async def _progress(self, fd: int, forward: int) -> None:
        """ffmpeg's -progress lines, passed on to ``forward`` from the moment the peer is connected."""
        loop = asyncio.get_running_loop()
        reader = asyncio.StreamReader()
        transport, _ = await loop.connect_read_pipe(
            lambda: asyncio.StreamReaderProtocol(reader), os.fdopen(fd, "rb", buffering=0)
        )
        try:
            async for line in reader:
                if forward >= 0 and self.connected.is_set():
                    with contextlib.suppress(BlockingIOError, BrokenPipeError):
                        os.write(forward, line)
        finally:
            transport.close()

    async def _teardown(self, pc: RTCPeerConnection) -> None:
        """The session DELETEd first (the endpoint frees it now, not at its ICE timeout; the supervisor's
        SIGKILL comes KILL_GRACE, 1.5 s, after its SIGTERM), then the peer connection and ffmpeg."""
        if self.resource is not None:
            with contextlib.suppress(aiohttp.ClientError, TimeoutError):
                async with asyncio.timeout(1.0), aiohttp.ClientSession() as http:
                    await http.delete(self.resource)
        if self.proc is not None and self.proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                self.proc.send_signal(signal.SIGTERM)
        await pc.close()
        if self.proc is not None and self.proc.returncode is None:
            try:
                async with asyncio.timeout(0.3):
                    await self.proc.wait()
            except TimeoutError:
                with contextlib.suppress(ProcessLookupError):
                    self.proc.kill()


async def _first(*waits: Any) -> None:
    """Until the first of ``waits`` (coroutines or tasks) is done; the others are cancelled."""
    tasks = [asyncio.ensure_future(w) for w in waits]
    try:
        await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for t in tasks:
            if not t.done():
                t.cancel()


def _parse(argv: Sequence[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m gateway.video.whip", description=__doc__.splitlines()[0])
    parser.add_argument("--url", required=True, help="the WHIP endpoint (http:// or https://)")
    parser.add_argument("--ice-server", action="append", default=[], help="stun:/turn: URL (repeatable)")
    parser.add_argument("ffmpeg", nargs=argparse.REMAINDER, help="-- then the ffmpeg argv")
    ns = parser.parse_args(argv)
    if ns.ffmpeg[:1] == ["--"]:
        ns.ffmpeg = ns.ffmpeg[1:]
    if not ns.ffmpeg:
        parser.error("no ffmpeg command after --")
    return ns


def main(argv: Sequence[str] | None = None) -> int:
    ns = _parse(sys.argv[1:] if argv is None else argv)

    async def run() -> int:
        stop = asyncio.Event()
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGTERM, signal.SIGINT):
            loop.add_signal_handler(sig, stop.set)
        return await Publisher(ns.url, ns.ffmpeg, ns.ice_server).run(stop)

    try:
        return asyncio.run(run())
    except _Failed as exc:
        print(str(exc), file=sys.stderr, flush=True)
        return 1


if __name__ == "__main__":
    sys.exit(main())
