"""One ffmpeg pipeline as a process: spawned, read and stopped without ever blocking the event loop.

Owns the asyncio subprocess of one pipeline: its ``-progress`` lines (a pipe of their own), its stderr
(the last lines kept, the target URL redacted, secrets masked: a failure's reason), its stdout (the
console preview's fragmented MP4, handed to a :class:`~gateway.video.preview.PreviewFeed`), and its stop
(SIGTERM, then SIGKILL after ``KILL_GRACE``). Knows nothing about what the pipeline is for: the command
line comes from a callable, and what happened goes to two callbacks.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import signal
from collections import deque
from collections.abc import Callable

from gateway import logcontext
from gateway.video.engine import ProgressParser, redact_url
from gateway.video.preview import PreviewFeed

log = logging.getLogger(__name__)

__all__ = ["KILL_GRACE", "PipelineProcess"]

KILL_GRACE = 1.5  # s between SIGTERM (ffmpeg closes the stream cleanly) and SIGKILL


class PipelineProcess:
    """One running ffmpeg: spawned, read, stopped. Reports to ``on_progress`` / ``on_exit``; its stdout (the
    preview's fragmented MP4, when ``preview`` is given) goes to ``preview``."""

    def __init__(
        self,
        build: Callable[[int], list[str]],
        secret: str,
        on_progress: Callable[[int], None],
        on_exit: Callable[[str], None],
        preview: PreviewFeed | None = None,
        name: str = "ffmpeg",
    ) -> None:
        self.build = build  # progress fd → the command line
        self.name = name  # what the failure's reason calls the process (the WHIP publisher for url_type 4)
        self.cmd: list[str] = []
        self.secret = secret
        self.on_progress = on_progress
        self.on_exit = on_exit
        self.preview = preview
        self.proc: asyncio.subprocess.Process | None = None
        self.errors: deque[str] = deque(maxlen=5)
        self.task: asyncio.Task[None] | None = None
        self.killed = False

    def start(self) -> None:
        self.task = asyncio.get_running_loop().create_task(self._run(), name="ffmpeg")

    async def _run(self) -> None:
        reason = "exited"
        progress_r, progress_w = os.pipe()  # -progress on a pipe of its own: stdout carries the preview
        try:
            self.cmd = self.build(progress_w)
            self.proc = await asyncio.create_subprocess_exec(
                *self.cmd,
                stdin=asyncio.subprocess.DEVNULL,
                stdout=asyncio.subprocess.PIPE if self.preview is not None else asyncio.subprocess.DEVNULL,
                stderr=asyncio.subprocess.PIPE,
                pass_fds=(progress_w,),
                start_new_session=True,  # a Ctrl-C to the gateway is not the pipeline's to handle
            )
            os.close(progress_w)
            progress_w = -1
            if self.killed:
                self._signal(signal.SIGKILL)
            progress = await _pipe_reader(progress_r)
            progress_r = -1  # owned by the reader's transport now
            await asyncio.gather(self._read_progress(progress), self._read_errors(), self._read_preview())
            code = await self.proc.wait()
            last = self.errors[-1] if self.errors else ""
            reason = f"{self.name} exited {code}" + (f": {last}" if last else "")
        except FileNotFoundError:
            reason = f"{self.cmd[0]} not found (apt-get install ffmpeg)"
        except OSError as exc:
            reason = f"could not start the pipeline: {exc.strerror}"
        except asyncio.CancelledError:
            self._signal(signal.SIGKILL)
            raise
        finally:
            for fd in (progress_r, progress_w):
                if fd >= 0:
                    os.close(fd)
        self.on_exit(reason)

    async def _read_progress(self, reader: tuple[asyncio.StreamReader, asyncio.BaseTransport]) -> None:
        stream, transport = reader
        parser = ProgressParser()
        try:
            async for raw in stream:
                frames = parser.feed(raw.decode("ascii", "replace"))
                if frames is not None:
                    self.on_progress(frames)
        finally:
            transport.close()

    async def _read_preview(self) -> None:
        if self.preview is None or self.proc is None or self.proc.stdout is None:
            return
        while chunk := await self.proc.stdout.read(65536):
            try:
                self.preview.feed(chunk)
            except ValueError as exc:  # a broken MP4: the preview stops, the stream goes on
                log.warning("preview stopped: %s", exc)
                self.preview = None
                while await self.proc.stdout.read(65536):  # keep draining: ffmpeg must never block on it
                    pass
                return

    async def _read_errors(self) -> None:
        assert self.proc is not None and self.proc.stderr is not None
        async for raw in self.proc.stderr:
            line = raw.decode("utf-8", "replace").strip()
            if line:
                if self.secret:
                    line = line.replace(self.secret, redact_url(self.secret))
                self.errors.append(logcontext.scrub(line)[:200])

    def _signal(self, sig: int) -> None:
        if self.proc is not None and self.proc.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                self.proc.send_signal(sig)

    def kill(self) -> None:
        """SIGTERM (ffmpeg ends the stream cleanly), SIGKILL if it is still there after KILL_GRACE."""
        self.killed = True
        self._signal(signal.SIGTERM)
        loop = asyncio.get_running_loop()
        loop.call_later(KILL_GRACE, self._signal, signal.SIGKILL)

    async def wait(self) -> None:
        if self.task is not None:
            await asyncio.wait({self.task})


async def _pipe_reader(fd: int) -> tuple[asyncio.StreamReader, asyncio.BaseTransport]:
    """A StreamReader over the read end of a pipe, on the running loop (never a blocking read)."""
    loop = asyncio.get_running_loop()
    reader = asyncio.StreamReader(limit=2**16)
    transport, _ = await loop.connect_read_pipe(
        lambda: asyncio.StreamReaderProtocol(reader), os.fdopen(fd, "rb", buffering=0)
    )
    return reader, transport
