"""The console's video preview endpoint: ``GET /api/video`` lists the videos, ``GET /api/video?id=VIDEO_ID``
(a WebSocket) sends a running stream's preview as binary messages (the MP4 init segment, then fragments),
which ``static/js/video.js`` appends to a Media Source Extensions buffer.

Owns the hand-off from the gateway's loop (where :class:`gateway.video.service.LiveService` feeds the
segments) to the web thread (a bounded queue per page: a page that falls 100 segments, ~10 s, behind is
closed and reconnects at the live edge). Knows the console server only through the few calls it is
given (:class:`VideoRoutes`); knows nothing about ffmpeg.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Awaitable, Callable
from typing import Any

from aiohttp import web

from gateway.web.security import Denied

__all__ = ["QUEUE", "VideoRoutes"]

QUEUE = 100  # segments a page may be behind before it is closed


class VideoRoutes:
    def __init__(
        self,
        *,
        live: Callable[[], Any],  # the gateway's LiveService, or None
        viewer: Callable[[web.Request], Denied | None],
        refuse: Callable[[Denied], web.Response],
        same_origin: Callable[[web.Request], bool],
        on_gateway: Callable[[Callable[[], Any]], Awaitable[Any]],
    ) -> None:
        self.live = live
        self.viewer = viewer
        self.refuse = refuse
        self.same_origin = same_origin
        self.on_gateway = on_gateway

    def add_to(self, router: web.UrlDispatcher) -> None:
        router.add_get("/api/video", self.handle)

    async def handle(self, request: web.Request) -> web.StreamResponse:
        denied = self.viewer(request)
        if denied is not None:
            return self.refuse(denied)
        live = self.live()
        if live is None:
            return self.refuse(Denied(404, "no live video on this gateway"))
        video_id = request.query.get("id")
        if video_id is None:
            return web.json_response({"videos": await self.on_gateway(live.previews)})
        if not self.same_origin(request):
            return self.refuse(Denied(403, "cross-origin WebSocket refused"))
        loop = asyncio.get_running_loop()
        queue: asyncio.Queue[bytes] = asyncio.Queue(QUEUE + 1)

        def offer(segment: bytes) -> None:  # on the web loop
            if queue.full():
                while not queue.empty():
                    queue.get_nowait()
                queue.put_nowait(b"")  # too far behind: the page reconnects at the live edge
            else:
                queue.put_nowait(segment)

        def send(segment: bytes) -> None:  # on the gateway's loop
            with contextlib.suppress(RuntimeError):  # the web loop is closing
                loop.call_soon_threadsafe(offer, segment)

        unsubscribe = await self.on_gateway(lambda: live.subscribe(video_id, send))
        if unsubscribe is None:
            return self.refuse(Denied(404, f"{video_id[:128]} is not streaming"))
        ws = web.WebSocketResponse(heartbeat=20.0, max_msg_size=4096)
        try:
            await ws.prepare(request)
            reader = loop.create_task(self._drain(ws))
            try:
                while True:
                    getter = loop.create_task(queue.get())
                    await asyncio.wait({getter, reader}, return_when=asyncio.FIRST_COMPLETED)
                    if not getter.done():  # the page left
                        getter.cancel()
                        break
                    segment = getter.result()
                    if not segment:  # the stream ended (or the page fell behind)
                        break
                    await ws.send_bytes(segment)
            finally:
                reader.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await reader
                await ws.close()
        finally:
            with contextlib.suppress(Exception):
                await self.on_gateway(unsubscribe)
        return ws

    @staticmethod
    async def _drain(ws: web.WebSocketResponse) -> None:
        async for _ in ws:  # the page sends nothing; this notices it leave
            pass
