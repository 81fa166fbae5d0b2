"""A WHIP endpoint for the tests (RFC 9725's server side): an aiohttp server and an aiortc peer connection
per session, on a thread of its own, that decodes every frame it receives (PyAV, through aiortc) and
counts them, with their size, the first frame's time and the session's end.

It can run inside a network namespace (``netns``): aiortc's ICE gathers host candidates from every
interface but loopback, so a test keeps all of WebRTC inside a namespace it made (the veth end the
namespace holds is its only address), never on the host's real interfaces. No STUN server: candidates
are host candidates only.
"""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
import uuid
from dataclasses import dataclass, field
from typing import Any

from aiohttp import web
from aiortc import RTCConfiguration, RTCPeerConnection, RTCSessionDescription
from aiortc.mediastreams import MediaStreamError

from gateway.video.engine import TIMECODE_BITS, read_timecode
from tests.netlab import enter_netns

__all__ = ["WhipReceiver"]


def _latency_ms(frame: Any) -> float:
    """Now minus the millisecond the test pattern drew into ``frame`` (engine.read_timecode)."""
    now_ms = time.time() * 1000
    gray = frame.reformat(format="gray")
    plane, w, h = gray.planes[0], gray.width, gray.height
    data = bytes(plane)
    if plane.line_size != w:  # rows padded: the timecode reader takes them packed
        data = b"".join(data[y * plane.line_size : y * plane.line_size + w] for y in range(h))
    return (int(now_ms) - read_timecode(data, w, h)) % 2**TIMECODE_BITS + now_ms % 1


@dataclass
class Session:
    pc: Any  # aiortc's RTCPeerConnection, or the Chromium page that holds the peer connection
    offer: str
    sid: str = field(default_factory=lambda: uuid.uuid4().hex[:12])
    frames: int = 0
    sizes: set[tuple[int, int]] = field(default_factory=set)
    codec: str = ""
    first_frame_at: float | None = None
    ended_at: float | None = None
    deleted: bool = False


class WhipReceiver:
    """POST /whip/{name} takes an offer and answers 201 with a Location; DELETE on that location ends it.
    ``status``: answer this instead of 201 (a failing endpoint)."""

    def __init__(self, host: str, port: int, *, netns: str | None = None, timecode: bool = False) -> None:
        self.host, self.port, self.netns = host, port, netns
        self.timecode = timecode  # read each frame's drawn millisecond: latencies (ms), drawn → decoded here
        self.latencies: list[float] = []
        self.sessions: list[Session] = []
        self.posts = 0
        self.status = 201
        self._tasks: set[asyncio.Future[None]] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._ready = threading.Event()
        self._stop: asyncio.Event | None = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._main, name="whip-receiver", daemon=True)
        self._thread.start()
        if not self._ready.wait(15) or self._error is not None:
            raise RuntimeError(f"the WHIP receiver did not start: {self._error}")

    def url(self, name: str = "live") -> str:
        return f"http://{self.host}:{self.port}/whip/{name}"

    # -- what the tests read -------------------------------------------------------------------------
    @property
    def frames(self) -> int:
        return sum(s.frames for s in self.sessions)

    @property
    def first_frame_at(self) -> float | None:
        times = [s.first_frame_at for s in self.sessions if s.first_frame_at is not None]
        return min(times) if times else None

    @property
    def last(self) -> Session | None:
        return self.sessions[-1] if self.sessions else None

    # -- the server ------------------------------------------------------------------------------------
    def _main(self) -> None:
        try:
            if self.netns is not None:
                enter_netns(self.netns)  # this thread and its loop's sockets live in the namespace
            asyncio.run(self._serve())
        except BaseException as exc:  # reported to the constructor
            self._error = exc
            self._ready.set()

    async def _serve(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._stop = asyncio.Event()
        app = web.Application()
        app.router.add_post("/whip/{name}", self._offer)
        app.router.add_delete("/whip/{name}/{session}", self._delete)
        runner = web.AppRunner(app)
        await runner.setup()
        await web.TCPSite(runner, self.host, self.port).start()
        self._ready.set()
        try:
            await self._stop.wait()
        finally:
            for s in self.sessions:
                await self._close(s)
            await runner.cleanup()

    async def _offer(self, request: web.Request) -> web.Response:
        self.posts += 1
        if self.status != 201:
            return web.Response(status=self.status, text="refused by the test")
        if request.content_type != "application/sdp":
            return web.Response(status=415, text="application/sdp expected")
        session, answer = await self._answer(await request.text())
        location = f"/whip/{request.match_info['name']}/{session.sid}"
        return web.Response(
            status=201, text=answer, content_type="application/sdp", headers={"Location": location}
        )

    async def _answer(self, offer: str) -> tuple[Session, str]:
        """A session for ``offer`` and the SDP answer (aiortc here; :class:`ChromiumWhipReceiver`)."""
        pc = RTCPeerConnection(RTCConfiguration(iceServers=[]))
        session = Session(pc, offer)
        self.sessions.append(session)

        @pc.on("track")
        def on_track(track: Any) -> None:
            self._tasks.add(asyncio.ensure_future(self._consume(session, track)))

        await pc.setRemoteDescription(RTCSessionDescription(sdp=offer, type="offer"))
        await pc.setLocalDescription(await pc.createAnswer())
        for t in pc.getTransceivers():
            if t.receiver and t._codecs:  # the negotiated codec (aiortc keeps it on the transceiver)
                session.codec = t._codecs[0].mimeType
        return session, str(pc.localDescription.sdp)

    async def _consume(self, session: Session, track: Any) -> None:
        try:
            while True:
                frame = await track.recv()
                if self.timecode:
                    self.latencies.append(_latency_ms(frame))
                if session.first_frame_at is None:
                    session.first_frame_at = time.monotonic()
                session.frames += 1
                session.sizes.add((frame.width, frame.height))
        except MediaStreamError:
            pass
        finally:
            session.ended_at = time.monotonic()

    async def _delete(self, request: web.Request) -> web.Response:
        sid = request.match_info["session"]
        for s in self.sessions:
            if s.sid == sid:
                s.deleted = True
                await self._close(s)
                return web.Response(status=200)
        return web.Response(status=404)

    async def _close(self, session: Session) -> None:
        await session.pc.close()

    def drop(self, session: Session) -> None:
        """The endpoint ends ``session`` by itself (its peer connection closed, no DELETE asked)."""
        assert self._loop is not None
        asyncio.run_coroutine_threadsafe(self._close(session), self._loop).result(10)

    def close(self) -> None:
        if self._loop is not None and self._stop is not None:
            with contextlib.suppress(RuntimeError):
                self._loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(10)


#: In the page: take the offer, answer it, wait for every candidate, return the answer's SDP.
_JS_ANSWER = """async (offer) => {
  const pc = new RTCPeerConnection({iceServers: []});
  window.pc = pc;
  pc.ontrack = (e) => {
    const v = document.createElement('video');
    v.muted = true; v.autoplay = true; v.srcObject = new MediaStream([e.track]);
    document.body.appendChild(v); v.play().catch(() => {});
  };
  await pc.setRemoteDescription({type: 'offer', sdp: offer});
  await pc.setLocalDescription(await pc.createAnswer());
  if (pc.iceGatheringState !== 'complete') {
    await new Promise((done) => pc.addEventListener('icegatheringstatechange',
      () => pc.iceGatheringState === 'complete' && done()));
  }
  return pc.localDescription.sdp;
}"""
#: In the page: what the browser's WebRTC says of the video it receives.
_JS_STATS = """async () => {
  const out = {state: window.pc.connectionState, frames: 0, w: 0, h: 0, codec: ''};
  const stats = await window.pc.getStats();
  for (const r of stats.values()) {
    if (r.type === 'inbound-rtp' && r.kind === 'video') {
      Object.assign(out, {frames: r.framesDecoded || 0, w: r.frameWidth || 0, h: r.frameHeight || 0});
      const codec = r.codecId && stats.get(r.codecId);
      if (codec) out.codec = codec.mimeType + ' ' + (codec.sdpFmtpLine || '');
    }
  }
  return out;
}"""


class ChromiumWhipReceiver(WhipReceiver):
    """The same endpoint with Debian's Chromium (libwebrtc, through Playwright) as the peer: a page per
    session answers the offer and decodes the video; its ``getStats`` (frames decoded, size, codec) are
    read every 0.1 s into the session. Another WebRTC implementation than the publisher's aiortc: what
    both misread alike would pass an aiortc endpoint, not this one. Chromium runs in the namespace too
    (launched from the receiver's thread), with mDNS host-candidate hiding off (no multicast)."""

    ARGS = ("--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
            "--disable-component-update", "--disable-sync",
            "--disable-features=WebRtcHideLocalIpsWithMdns")  # fmt: skip

    def __init__(self, host: str, port: int, *, netns: str | None = None, chromium: str) -> None:
        self.chromium = chromium
        self._browser: Any = None
        super().__init__(host, port, netns=netns)

    async def _serve(self) -> None:
        from playwright.async_api import async_playwright

        async with async_playwright() as pw:
            self._browser = await pw.chromium.launch(
                executable_path=self.chromium, headless=True, args=list(self.ARGS)
            )
            try:
                await super()._serve()
            finally:
                await self._browser.close()

    async def _answer(self, offer: str) -> tuple[Session, str]:
        page = await self._browser.new_page()
        session = Session(page, offer)
        self.sessions.append(session)
        answer = await page.evaluate(_JS_ANSWER, offer)
        self._tasks.add(asyncio.ensure_future(self._watch(session)))
        return session, str(answer)

    async def _watch(self, session: Session) -> None:
        page = session.pc
        while session.ended_at is None:
            try:
                stats = await page.evaluate(_JS_STATS)
            except Exception:  # the page closed: the session is over
                break
            if stats["frames"] and session.first_frame_at is None:
                session.first_frame_at = time.monotonic()
            session.frames = int(stats["frames"])
            if stats["w"]:
                session.sizes.add((int(stats["w"]), int(stats["h"])))
            session.codec = str(stats["codec"])
            if stats["state"] in ("failed", "closed"):
                break
            await asyncio.sleep(0.1)
        if session.ended_at is None:
            session.ended_at = time.monotonic()

    async def _close(self, session: Session) -> None:
        page = session.pc
        with contextlib.suppress(Exception):
            await page.evaluate("() => window.pc && window.pc.close()")
        if session.ended_at is None:
            session.ended_at = time.monotonic()
        with contextlib.suppress(Exception):
            await page.close()
