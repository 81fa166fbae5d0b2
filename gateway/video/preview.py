"""The web console's preview of a running stream: fragmented MP4 cut into what a browser's Media Source
Extensions take (an init segment, then ``moof``+``mdat`` fragments), fanned out to the pages watching.

Owns the MP4 box splitting (sans-I/O: bytes in, segments out) and the subscriber list of one video. Knows
nothing about ffmpeg, HTTP or threads: a subscriber is a callable the web side makes thread-safe itself;
it is called on the gateway's loop with each segment, and with ``b""`` when the stream ended (a new
pipeline starts a new init segment: the page starts over).
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable

__all__ = ["BoxSplitter", "PreviewFeed"]

Send = Callable[[bytes], None]
#: A preview that sends more than this in one box is broken (a fragment of 100 ms at 3 Mbps is ~40 kB).
MAX_BOX = 8 * 1024 * 1024


class BoxSplitter:
    """Fragmented MP4 bytes → ``("init", bytes)`` once (``ftyp`` + ``moov``), then ``("fragment", bytes)``
    per ``moof`` + ``mdat`` (boxes between them stay with their fragment)."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self._init = bytearray()
        self._fragment = bytearray()
        self.init_done = False

    def feed(self, data: bytes) -> list[tuple[str, bytes]]:
        self._buf += data
        out: list[tuple[str, bytes]] = []
        while len(self._buf) >= 8:
            size = int.from_bytes(self._buf[0:4], "big")
            kind = bytes(self._buf[4:8])
            if size == 1:
                if len(self._buf) < 16:
                    break
                size = int.from_bytes(self._buf[8:16], "big")
            if size < 8 or size > MAX_BOX:
                raise ValueError(f"bad MP4 box {kind!r} of {size} bytes")
            if len(self._buf) < size:
                break
            box = bytes(self._buf[:size])
            del self._buf[:size]
            if not self.init_done:
                self._init += box
                if kind == b"moov":
                    self.init_done = True
                    out.append(("init", bytes(self._init)))
                continue
            self._fragment += box
            if kind == b"mdat":
                out.append(("fragment", bytes(self._fragment)))
                self._fragment.clear()
        return out


class PreviewFeed:
    """One video's preview: the current init segment and who watches."""

    def __init__(self) -> None:
        self.init: bytes | None = None
        self.subscribers: list[Send] = []
        self.fragments = 0
        self._splitter = BoxSplitter()

    def restart(self) -> None:
        """A new pipeline: its MP4 starts over; pages watching the old one are told it ended."""
        self.init = None
        self._splitter = BoxSplitter()
        for send in list(self.subscribers):
            _safe(send, b"")
        self.subscribers.clear()

    def feed(self, data: bytes) -> None:
        for kind, segment in self._splitter.feed(data):
            if kind == "init":
                self.init = segment
            else:
                self.fragments += 1
            for send in list(self.subscribers):
                _safe(send, segment)

    def subscribe(self, send: Send) -> Callable[[], None]:
        """``send`` gets the init segment now (if there is one) and every fragment after it; the callable
        returned unsubscribes."""
        if self.init is not None:
            _safe(send, self.init)
        self.subscribers.append(send)

        def unsubscribe() -> None:
            with contextlib.suppress(ValueError):
                self.subscribers.remove(send)

        return unsubscribe


def _safe(send: Send, data: bytes) -> None:
    with contextlib.suppress(Exception):  # a page's hand-off must not stop the pipeline's reader
        send(data)
