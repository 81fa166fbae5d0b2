"""Download a KMZ from the URL the cloud names: aiohttp's client on the gateway's loop, with a total
and a per-read timeout and a size cap; only http and https.

Owns the HTTP side of a wayline file and nothing else: the bytes go to ``adapters.wayline.kmz`` for the
fingerprint and the parse. Never logs the URL's query (a pre-signed URL's signature is a credential).
"""

from __future__ import annotations

from urllib.parse import urlsplit

import aiohttp
from yarl import URL

__all__ = ["MAX_KMZ_BYTES", "FetchError", "fetch_kmz", "safe_url"]

#: A route KMZ is kilobytes; DJI's own with reference photos stay well under this.
MAX_KMZ_BYTES = 32 * 1024 * 1024


class FetchError(Exception):
    """The file could not be obtained (the task fails with 314013)."""


def safe_url(url: str) -> str:
    """The URL without its query and credentials, for log lines and reasons."""
    parts = urlsplit(url)
    host = parts.hostname or "?"
    port = f":{parts.port}" if parts.port else ""
    return f"{parts.scheme}://{host}{port}{parts.path}"


async def fetch_kmz(url: str, *, timeout: float = 30.0, max_bytes: int = MAX_KMZ_BYTES) -> bytes:
    """The bytes at ``url``; FetchError for a bad scheme, a non-200 answer, a time-out or too many bytes."""
    try:
        parts = urlsplit(url)
        scheme = parts.scheme.lower()
        ok = scheme in ("http", "https") and bool(parts.hostname)
    except ValueError:
        ok = False
    if not ok:
        raise FetchError("the file URL is not http(s)")
    limits = aiohttp.ClientTimeout(
        total=timeout, sock_connect=min(10.0, timeout), sock_read=min(15.0, timeout)
    )
    try:
        # encoded=True: the URL goes out byte for byte as the cloud wrote it. A pre-signed URL's query is part
        # of its signature (WAYLINE-NOTES §6); yarl would otherwise re-quote it (%2F → /).
        target = URL(url, encoded=True)
        async with aiohttp.ClientSession(timeout=limits) as session, session.get(target) as resp:
            if resp.status != 200:
                raise FetchError(f"HTTP {resp.status} from {safe_url(url)}")
            if resp.content_length is not None and resp.content_length > max_bytes:
                raise FetchError(f"file larger than {max_bytes} bytes")
            data = bytearray()
            async for chunk in resp.content.iter_chunked(65536):
                data += chunk
                if len(data) > max_bytes:
                    raise FetchError(f"file larger than {max_bytes} bytes")
            return bytes(data)
    except FetchError:
        raise
    except (aiohttp.ClientError, TimeoutError, OSError, ValueError) as exc:
        raise FetchError(f"download from {safe_url(url)} failed: {type(exc).__name__}") from None
