"""The KMZ download (gateway/wayline/fetch.py) against a real HTTP server on 127.0.0.1: the pre-signed URL
goes out byte for byte, and a wrong answer, too many bytes, a bad scheme or a silent server are a
FetchError (the task's 314013), never a hang."""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

import pytest

from gateway.wayline.fetch import FetchError, fetch_kmz, safe_url


class _Server:
    def __init__(self) -> None:
        self.paths: list[str] = []
        self.body = b"PK-kmz"
        self.status = 200
        self.delay = 0.0
        self.declared: int | None = None
        server = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:
                server.paths.append(self.path)
                time.sleep(server.delay)
                self.send_response(server.status)
                if server.declared != -1:  # -1: none (HTTP/1.0: the body ends with the connection)
                    self.send_header("Content-Length", str(server.declared or len(server.body)))
                self.end_headers()
                self.wfile.write(server.body)

            def log_message(self, *args: Any) -> None:
                pass

        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.base = f"http://127.0.0.1:{self.httpd.server_port}"
        threading.Thread(target=self.httpd.serve_forever, daemon=True).start()


@pytest.fixture
def server() -> Iterator[_Server]:
    s = _Server()
    yield s
    s.httpd.shutdown()
    s.httpd.server_close()


def test_a_presigned_url_goes_out_byte_for_byte(server: _Server) -> None:
    path = (
        "/wayline/a%20b.kmz?Expires=1&OSSAccessKeyId=x&Signature=a%2Bb%2Fc%3D&X-Amz-Credential=k%2F2026%2Fus"
    )
    assert asyncio.run(fetch_kmz(server.base + path)) == b"PK-kmz"
    assert server.paths == [path]


def test_failures_are_fetch_errors(server: _Server) -> None:
    server.status = 403
    with pytest.raises(FetchError, match="HTTP 403"):
        asyncio.run(fetch_kmz(server.base + "/x.kmz?Signature=secret"))
    server.status, server.body = 200, b"x" * 5000
    with pytest.raises(FetchError, match="larger than"):
        asyncio.run(fetch_kmz(server.base + "/x.kmz", max_bytes=1000))
    server.declared = -1  # no length declared: the cap is kept by counting what arrives
    with pytest.raises(FetchError, match="larger than"):
        asyncio.run(fetch_kmz(server.base + "/x.kmz", max_bytes=1000))
    server.declared = 10  # a server that sends more than it declared: the declared body, or an error
    try:
        got = asyncio.run(fetch_kmz(server.base + "/x.kmz", max_bytes=1000))
    except FetchError:
        pass  # (the surplus arrived with the head: aiohttp's parser refuses the response)
    else:
        assert got == b"x" * 10  # (the surplus arrived later: never read, never more than declared)
    for bad in ("file:///etc/passwd", "ftp://127.0.0.1/x", "not a url", "http://"):
        with pytest.raises(FetchError, match="not http"):
            asyncio.run(fetch_kmz(bad))


def test_a_silent_server_times_out(server: _Server) -> None:
    server.delay = 2.0
    started = time.monotonic()
    with pytest.raises(FetchError, match="failed"):
        asyncio.run(fetch_kmz(server.base + "/x.kmz", timeout=0.5))
    assert time.monotonic() - started < 1.9


def test_log_lines_never_carry_the_signature() -> None:
    assert safe_url("https://u:p@bucket.example:9000/w/a.kmz?X-Amz-Signature=abc") == (
        "https://bucket.example:9000/w/a.kmz"
    )
