"""Live streaming as the cloud sees it: the ``live_*`` services, ``live_capacity`` and ``live_status``, and
the supervised ffmpeg processes that carry the streams.

Owns the configured video sources (``[video]``, :class:`gateway.settings.VideoSettings`), one
:class:`~gateway.video.machine.StreamMachine` per ``video_id`` (every decision: start, retry with backoff,
stall, stop), and the thin transport that carries the machines' actions out: one asyncio subprocess per
pipeline (``nice`` + ``prlimit --as``: bounded CPU priority and memory; for WHIP the publisher
``python -m gateway.video.whip`` with the ffmpeg as its child), its ``-progress`` lines read as they
come (never blocking the loop), SIGTERM then SIGKILL to stop it. Publishes the gateway's state through a
callback (``live_capacity`` on connect, ``live_status`` on every change). Knows nothing about MQTT topics,
envelopes or the dispatcher's rules; knows devices only as the :class:`~gateway.devices.DeviceTable`
says whether they are online (a stream stops when its device goes offline).

Answers (docs/video.md has the table): unknown ``video_id`` 399012; url types other than RTMP and WHIP
399010 (WHIP too when aiortc is not installed: the ``webrtc`` extra);
a second start of a running video to the same target 0 (its quality applied), to another target 399011;
a stop of a video that is not streaming 0; a start whose pipeline died before its first frame 399015.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib.util
import logging
import os
import shutil
import sys
import tempfile
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gateway.clock import Clock
from gateway.devices import DeviceTable
from gateway.metrics import Metrics
from gateway.settings import VideoSettings, VideoSource
from gateway.video.engine import Pipeline, build_command, describe, redact_url
from gateway.video.machine import Backoff, Kill, Phase, Spawn, StreamMachine, Target
from gateway.video.preview import PreviewFeed
from gateway.video.process import KILL_GRACE, PipelineProcess
from schemas.live import LiveLensChange, LiveSetQuality, LiveStartPush, LiveStopPush, UrlType
from schemas.results import ResultCode

log = logging.getLogger(__name__)

__all__ = ["METHODS", "LiveService"]

METHODS = frozenset({"live_start_push", "live_stop_push", "live_set_quality", "live_lens_change"})
TICK = 0.25  # s: retries, stalls, device-offline checks, the osd text of test patterns
STOP_WAIT = 2.0  # s a live_stop_push waits for the pipeline to end before answering

Result = tuple[int, dict[str, Any] | None]

_REFUSED_TYPES = {
    UrlType.AGORA: "Agora needs Agora's proprietary SDK: not supported (use RTMP, url_type 1)",
    UrlType.RTSP: "RTSP (the gateway as an RTSP server) is not supported (use RTMP, url_type 1)",
    UrlType.GB28181: "GB28181 has no maintained library here: not supported (use RTMP, url_type 1)",
}
#: url_type → the schemes its url may have
_SCHEMES = {UrlType.RTMP: ("rtmp://", "rtmps://"), UrlType.WHIP: ("http://", "https://")}
_SCHEME_ERROR = {
    UrlType.RTMP: "an RTMP url starts with rtmp:// or rtmps://",
    UrlType.WHIP: "a WHIP url is the endpoint's http:// or https:// URL",
}


def _whip_missing() -> str | None:
    """Why WHIP cannot run here (None when it can): aiortc (PyAV with it) is the ``webrtc`` extra."""
    if importlib.util.find_spec("aiortc") is None:
        return "WebRTC (WHIP) needs aiortc: pip install 'dji-gateway[webrtc]' (or use RTMP, url_type 1)"
    return None


@dataclass
class _Video:
    source: VideoSource
    machine: StreamMachine
    preview: PreviewFeed = field(default_factory=PreviewFeed)
    osd_file: Path | None = None
    changed: asyncio.Event | None = None  # set on every progress/exit (a start waiting for its outcome)


class LiveService:
    methods = METHODS

    def __init__(
        self,
        *,
        settings: VideoSettings,
        devices: DeviceTable,
        clock: Clock,
        metrics: Metrics,
        publish_state: Callable[[dict[str, Any]], None],
    ) -> None:
        self.settings = settings
        self.devices = devices
        self.clock = clock
        self.metrics = metrics
        self.publish_state = publish_state
        backoff = Backoff(settings.backoff_initial, settings.backoff_max)
        sources = list(settings.sources)
        if settings.test_pattern:  # run --simulate: every device shows a moving pattern, beside its sources
            have = {s.video_id for s in sources}
            for a in devices:
                pattern = VideoSource(
                    sn=a.info.sn, camera_index=a.info.payload_index or "0-0-0", source="test:"
                )
                if pattern.video_id not in have:
                    sources.append(pattern)
        self.videos: dict[str, _Video] = {
            s.video_id: _Video(
                s,
                StreamMachine(
                    s.video_id,
                    backoff=backoff,
                    stall_timeout=settings.stall_timeout,
                    start_timeout=settings.start_timeout,
                ),
            )
            for s in sources
        }
        self._procs: dict[tuple[str, int], PipelineProcess] = {}
        self._published: list[dict[str, Any]] | None = None
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        self._wrapper = self._wrapper_prefix()

    # -- what the cloud sees ----------------------------------------------------------------------
    def lenses(self, source: VideoSource) -> list[str]:
        if source.source.startswith("test:"):
            return ["normal", "ir"]
        return ["normal", *sorted(source.lenses)]

    def capacity(self) -> dict[str, Any]:
        """The ``live_capacity`` state property."""
        coexist = self.settings.max_streams
        by_device: dict[str, dict[str, list[VideoSource]]] = {}
        for video in self.videos.values():
            s = video.source
            by_device.setdefault(s.sn, {}).setdefault(s.camera_index, []).append(s)
        devices = []
        for sn, cameras in by_device.items():
            camera_list = []
            for index, sources in cameras.items():
                videos = [
                    {
                        "video_index": s.video_index,
                        "video_type": "normal",
                        "switchable_video_types": self.lenses(s),
                    }
                    for s in sources
                ]
                camera_list.append({"camera_index": index, "available_video_number": len(videos),
                                    "coexist_video_number_max": min(len(videos), coexist),
                                    "video_list": videos})  # fmt: skip
            n = sum(len(sources) for sources in cameras.values())
            most = min(n, coexist)
            devices.append({"sn": sn, "available_video_number": n, "coexist_video_number_max": most,
                            "camera_list": camera_list})  # fmt: skip
        return {"available_video_number": len(self.videos), "coexist_video_number_max": coexist,
                "device_list": devices}  # fmt: skip

    def status(self) -> list[dict[str, Any]]:
        """The ``live_status`` state property: every configured video."""
        out = []
        for vid, video in self.videos.items():
            m = video.machine
            status, error = m.status()
            target = m.target
            out.append({"video_id": vid, "video_type": target.lens if target else "normal",
                        "video_quality": target.quality if target else 0,
                        "status": status, "error_status": error})  # fmt: skip
        return out

    def state(self) -> dict[str, Any]:
        """The whole state body (on connect)."""
        if not self.videos:
            return {}
        self._published = self.status()
        return {"live_capacity": self.capacity(), "live_status": self._published}

    def _publish_if_changed(self) -> None:
        current = self.status()
        if current != self._published:
            self._published = current
            for entry in current:
                self.metrics.set("live_streaming", entry["status"], video=entry["video_id"])
            self.publish_state({"live_status": current})

    # -- services ---------------------------------------------------------------------------------
    async def call(self, method: str, data: Any) -> Result:
        if method == "live_start_push":
            return await self._start(data)
        if method == "live_stop_push":
            return await self._stop(data)
        if method == "live_set_quality":
            return self._set_quality(data)
        if method == "live_lens_change":
            return self._lens_change(data)
        return ResultCode.METHOD_NOT_SUPPORTED, {"reason": f"{method} is not a live method"}

    def _video(self, video_id: str) -> _Video | None:
        return self.videos.get(video_id)

    def _unknown(self, video_id: str) -> Result:
        known = ", ".join(self.videos) or "none configured ([video] sources)"
        return ResultCode.LIVE_UNKNOWN_VIDEO, {"reason": f"no video {video_id[:128]} (known: {known[:200]})"}

    async def _start(self, data: LiveStartPush) -> Result:
        video = self._video(data.video_id)
        if video is None:
            return self._unknown(data.video_id)
        url_type = UrlType(data.url_type)
        if url_type in _REFUSED_TYPES:
            return ResultCode.LIVE_URL_TYPE_UNSUPPORTED, {"reason": _REFUSED_TYPES[url_type]}
        missing = _whip_missing() if url_type is UrlType.WHIP else None
        if missing is not None:
            return ResultCode.LIVE_URL_TYPE_UNSUPPORTED, {"reason": missing}
        url = data.url.get_secret_value().strip()
        if not url.lower().startswith(_SCHEMES[url_type]):
            return ResultCode.INVALID_PARAMETERS, {"reason": _SCHEME_ERROR[url_type]}
        adapter = self.devices.by_sn(video.source.sn)
        if adapter is None or not adapter.online:
            return ResultCode.DEVICE_NOT_CONNECTED, {"reason": f"device {video.source.sn} is not connected"}
        m = video.machine
        now = self.clock.monotonic()
        if m.active and m.target is not None:
            if (m.target.url_type, m.target.url) != (int(url_type), url):
                return ResultCode.LIVE_ALREADY_STREAMING, {
                    "reason": f"{data.video_id} already streams to {redact_url(m.target.url)}: stop it first"
                }
            if m.target.quality != int(data.video_quality):
                self._act(video, m.reconfigure(now, quality=int(data.video_quality)))
            self._publish_if_changed()
            return ResultCode.SUCCESS, None
        if sum(1 for v in self.videos.values() if v.machine.active) >= self.settings.max_streams:
            return ResultCode.LIVE_TOO_MANY, {"reason": f"{self.settings.max_streams} streams already live"}
        target = Target(int(url_type), url, int(data.video_quality), "normal")
        log.info("live %s → %s (quality %d)", data.video_id, redact_url(url), target.quality)
        self.metrics.inc("live_starts_total", video=data.video_id)
        self._act(video, m.start(target, now, fail_fast=True))
        self._publish_if_changed()
        await self._await_outcome(video, lambda: m.phase is not Phase.STARTING, self.settings.start_wait)
        m.fail_fast = False  # from now on a failure is retried (live_status reports it)
        if m.phase is Phase.IDLE and m.error:
            self._publish_if_changed()
            return ResultCode.LIVE_START_FAILED, {"reason": m.last_reason[:300]}
        return ResultCode.SUCCESS, None

    async def _stop(self, data: LiveStopPush) -> Result:
        video = self._video(data.video_id)
        if video is None:
            return self._unknown(data.video_id)
        m = video.machine
        self._act(video, m.stop(self.clock.monotonic()))
        self._publish_if_changed()
        await self._await_outcome(video, lambda: m.running is None, STOP_WAIT)
        self._publish_if_changed()
        return ResultCode.SUCCESS, None

    def _set_quality(self, data: LiveSetQuality) -> Result:
        video = self._video(data.video_id)
        if video is None:
            return self._unknown(data.video_id)
        m = video.machine
        if not m.active:
            return ResultCode.LIVE_NOT_STREAMING, {"reason": f"{data.video_id} is not streaming"}
        self._act(video, m.reconfigure(self.clock.monotonic(), quality=int(data.video_quality)))
        self._publish_if_changed()
        return ResultCode.SUCCESS, None

    def _lens_change(self, data: LiveLensChange) -> Result:
        video = self._video(data.video_id)
        if video is None:
            return self._unknown(data.video_id)
        lens = str(data.video_type)
        lenses = self.lenses(video.source)
        if lens not in lenses:
            return ResultCode.LIVE_LENS_UNAVAILABLE, {
                "reason": f"{data.video_id} has lenses {', '.join(lenses)}"
            }
        m = video.machine
        if not m.active:
            return ResultCode.LIVE_NOT_STREAMING, {"reason": f"{data.video_id} is not streaming"}
        self._act(video, m.reconfigure(self.clock.monotonic(), lens=lens))
        self._publish_if_changed()
        return ResultCode.SUCCESS, None

    async def _await_outcome(self, video: _Video, done: Callable[[], bool], timeout: float) -> None:
        video.changed = video.changed or asyncio.Event()
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout):  # real time: ffmpeg runs in real time, whatever the clock
                while not done():
                    video.changed.clear()
                    await video.changed.wait()

    # -- the web console's preview (called on this loop by gateway/web/video.py) -------------------
    def previews(self) -> list[dict[str, Any]]:
        """Every video and whether it can be watched now."""
        return [
            {"video_id": vid, "sn": v.source.sn, "live": v.machine.phase is Phase.LIVE,
             "preview": v.preview.init is not None}
            for vid, v in self.videos.items()
        ]  # fmt: skip

    def subscribe(self, video_id: str, send: Callable[[bytes], None]) -> Callable[[], None] | None:
        """``send`` gets the video's preview (init segment, then fragments; ``b""`` at its end); None when
        the video is unknown or not streaming."""
        video = self.videos.get(video_id)
        if video is None or not video.machine.active or not self.settings.preview:
            return None
        return video.preview.subscribe(send)

    # -- the transport ----------------------------------------------------------------------------
    def _wrapper_prefix(self) -> list[str]:
        prefix: list[str] = []
        if self.settings.nice and shutil.which("nice"):
            prefix += ["nice", "-n", str(self.settings.nice)]
        if shutil.which("prlimit"):
            prefix += ["prlimit", f"--as={self.settings.memory_mb * 2**20}", "--"]
        return prefix

    def _source_for(self, video: _Video, lens: str) -> str:
        s = video.source
        return s.lenses.get(lens, s.source) if lens != "normal" else s.source  # type: ignore[call-overload]

    def _act(self, video: _Video, actions: list[Spawn | Kill]) -> None:
        vid = video.source.video_id
        for action in actions:
            if isinstance(action, Kill):
                proc = self._procs.get((vid, action.generation))
                if proc is not None:
                    proc.kill()
                if not video.machine.active:
                    video.preview.restart()  # the pages watching are told the stream ended
                continue
            target = action.target
            source = self._source_for(video, target.lens)
            if source.startswith("test:") and video.osd_file is None:
                video.osd_file = self._osd_path(vid)
                self._write_osd(video)
            pipeline = Pipeline(
                source=source,
                source_codec=video.source.codec if source == video.source.source else "other",
                url_type=target.url_type,
                url=target.url,
                quality=target.quality,
                lens=target.lens,
                label=video.source.sn,
                osd_file=str(video.osd_file)
                if video.osd_file is not None and source.startswith("test:")
                else None,
                threads=self.settings.threads,
                preview=self.settings.preview,
            )
            gen = action.generation
            preview = None
            if self.settings.preview:
                video.preview.restart()
                preview = video.preview

            def build(progress_fd: int, p: Pipeline = pipeline, vid: str = vid, gen: int = gen) -> list[str]:
                cmd = build_command(self.settings.ffmpeg, p, progress_fd)
                if p.url_type == UrlType.WHIP:  # the publisher runs the ffmpeg and sends what it encodes
                    ice = [arg for server in self.settings.ice_servers for arg in ("--ice-server", server)]
                    cmd = [sys.executable, "-m", "gateway.video.whip", "--url", p.url, *ice, "--", *cmd]
                cmd = self._wrapper + cmd
                log.debug("pipeline %s #%d: %s", vid, gen, describe(cmd, p.url))
                return cmd

            name = "the WHIP publisher" if target.url_type == UrlType.WHIP else "ffmpeg"
            callbacks = self._callbacks(video, gen)
            proc = PipelineProcess(build, target.url, *callbacks, preview=preview, name=name)
            self._procs[(vid, gen)] = proc
            proc.start()

    def _callbacks(self, video: _Video, gen: int) -> tuple[Callable[[int], None], Callable[[str], None]]:
        """What one process of ``video``, generation ``gen``, reports to."""

        def progress(frames: int) -> None:
            self._on_progress(video, gen, frames)

        def exited(reason: str) -> None:
            self._on_exit(video, gen, reason)

        return progress, exited

    def _on_progress(self, video: _Video, generation: int, frames: int) -> None:
        video.machine.progress(generation, frames, self.clock.monotonic())
        self._changed(video)

    def _on_exit(self, video: _Video, generation: int, reason: str) -> None:
        vid = video.source.video_id
        self._procs.pop((vid, generation), None)
        m = video.machine
        was = m.phase
        self._act(video, m.exited(generation, self.clock.monotonic(), reason))
        if m.phase is Phase.RETRYING and was is not Phase.RETRYING:
            self.metrics.inc("live_failures_total", video=vid)
            log.warning("live %s failed (%s); retrying in %.1f s", vid, reason,
                        (m.retry_at or 0) - self.clock.monotonic())  # fmt: skip
        elif m.phase is Phase.IDLE and m.error:
            log.warning("live %s could not start: %s", vid, reason)
        self._changed(video)

    def _changed(self, video: _Video) -> None:
        if video.changed is not None:
            video.changed.set()
        self._publish_if_changed()

    # -- the test pattern's osd text --------------------------------------------------------------
    def _osd_path(self, vid: str) -> Path:
        if self._tmp is None:  # removed on shutdown; tmpfs where /tmp is one (docs/video.md)
            self._tmp = tempfile.TemporaryDirectory(prefix="djigw-video-")
        return Path(self._tmp.name) / (vid.replace("/", "_") + ".txt")

    def _write_osd(self, video: _Video) -> None:
        if video.osd_file is None:
            return
        adapter = self.devices.by_sn(video.source.sn)
        snapshot: Mapping[str, Any] = (adapter.osd_snapshot() if adapter is not None else None) or {}
        parts = []
        for key, value in snapshot.items():
            if isinstance(value, int | float) and not isinstance(value, bool):
                parts.append(f"{key} {value:.6g}")
            if len(parts) == 4:
                break
        text = "  ".join(parts) or "no osd"
        tmp = video.osd_file.with_suffix(".new")
        tmp.write_text(text)  # ~50 bytes on /tmp once a second: not worth a thread
        os.replace(tmp, video.osd_file)  # ffmpeg re-reads it every frame: never a half-written file

    # -- life cycle -------------------------------------------------------------------------------
    async def run(self, stop: asyncio.Event) -> None:
        """Retries, stalls, devices gone offline, the osd text; until ``stop``."""
        beat = 0
        while not stop.is_set():
            now = self.clock.monotonic()
            for video in self.videos.values():
                m = video.machine
                adapter = self.devices.by_sn(video.source.sn)
                if m.active and (adapter is None or not adapter.online):
                    log.warning("live %s stopped: device %s went offline", video.source.video_id,
                                video.source.sn)  # fmt: skip
                    self._act(video, m.stop(now, "device offline"))
                    m.error = int(ResultCode.DEVICE_NOT_CONNECTED)
                    continue
                self._act(video, m.tick(now))
                if beat % 4 == 0 and m.active and video.osd_file is not None:
                    self._write_osd(video)
            self._publish_if_changed()
            beat += 1
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), TICK)

    async def shutdown(self) -> None:
        """Stop every pipeline (SIGTERM, then SIGKILL) and wait for them; remove the osd texts."""
        now = self.clock.monotonic()
        for video in self.videos.values():
            self._act(video, video.machine.stop(now, "shutdown"))
        procs = list(self._procs.values())
        if procs:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(asyncio.gather(*(p.wait() for p in procs)), KILL_GRACE + 1.0)
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None
