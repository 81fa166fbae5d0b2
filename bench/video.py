"""Live video: what a stream costs and how late its picture is (issue #36).

The gateway is ``run --simulate``'s (its aircraft only, in this process) with two video sources: the
aircraft's test pattern (1280×720 at 30 fps, drawn and encoded by the pipeline) and an "IP camera" (an
ffmpeg of its own serving 1280×720 30 fps H.264 over TCP). Receivers are ffmpeg RTMP listeners on loopback.

* **start to first frame**: ``live_start_push`` published → the receiver's first frame (the receiver's own
  0.3 s probe included: a listening RTMP input announces audio and video), repeated, p50 and max.
* **stop to the end**: ``live_stop_push`` published → the receiver's ffmpeg has seen the stream end.
* **glass to glass**: the test pattern carries the wall-clock millisecond as 24 black/white blocks drawn
  as each frame is made (ffmpeg's ``time(0)``); a receiver decodes every frame to 8-bit luma and reads the
  blocks back when the frame arrives: latency = arrival − drawn. Both clocks are this machine's.
* **CPU per 720p30 stream** (the camera's rows in a full run only): the pipeline process's user+system
  time from ``/proc/<pid>/stat`` over a window: the test pattern (draw + encode), the camera re-encoded
  (``video_quality`` 2: decode, scale, encode at 1 Mbps) and the camera passed through (``video_quality``
  0, codec h264: ``-c:v copy``).
* **WHIP** (``url_type`` 4): the same start, stop and glass-to-glass figures through WebRTC to an aiortc
  WHIP endpoint, with the gateway in a network namespace (WebRTC never offers loopback), and the CPU of
  the publisher process apart from its ffmpeg.
"""

from __future__ import annotations

import os
import statistics
import subprocess
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from bench.run import Config, Row
from gateway.local_broker import LocalBroker
from gateway.video.engine import TIMECODE_BITS, read_timecode
from tests.support import wait_until
from tests.video_rig import CAMERA, VIDEO, Receiver, Rig, free_port, listening

W, H = 1280, 720
TICKS = os.sysconf("SC_CLK_TCK")


def _cpu_seconds(pid: int) -> float:
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS  # utime, stime


class _Decoder:
    """An RTMP listener that decodes every frame to gray and reads its timecode on arrival."""

    def __init__(self, port: int) -> None:
        self.url = f"rtmp://127.0.0.1:{port}/live/g2g"
        self.latencies: list[float] = []
        self.proc = subprocess.Popen(
            ["ffmpeg", "-hide_banner", "-loglevel", "error", "-analyzeduration", "300000",
             "-fflags", "nobuffer", "-flags", "low_delay", "-listen", "1", "-f", "flv", "-i", self.url,
             "-f", "rawvideo",
             "-pix_fmt", "gray", "pipe:1"],
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        self._thread = threading.Thread(target=self._read, daemon=True)
        self._thread.start()
        wait_until(lambda: listening(port), 10, what="the decoding receiver")

    def _read(self) -> None:
        assert self.proc.stdout is not None
        size = W * H
        modulus = 2**TIMECODE_BITS
        while True:
            frame = self.proc.stdout.read(size)
            if len(frame) < size:
                break
            now_ms = time.time() * 1000
            drawn = read_timecode(frame, W, H)
            self.latencies.append((int(now_ms) - drawn) % modulus + (now_ms % 1))
        self.proc.stdout.close()

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait()
        self._thread.join(5)


def _ok(reply: dict[str, Any]) -> None:
    if reply["data"]["result"] != 0:
        raise AssertionError(f"{reply['method']} answered {reply['data']}")


def _first_frames(rig: Rig, tmp: Path, runs: int) -> tuple[list[float], list[float]]:
    out, ends = [], []
    for i in range(runs):
        rx = Receiver(free_port(), tmp / f"first-{i}.flv")
        try:
            asked = time.monotonic()
            _ok(rig.cloud.service("live_start_push", {"url_type": 1, "url": rx.url, "video_id": VIDEO}))
            wait_until(lambda rx=rx: rx.first_frame_at is not None, 20, what="the first frame")
            assert rx.first_frame_at is not None
            out.append((rx.first_frame_at - asked) * 1000)
            stop = time.monotonic()
            _ok(rig.cloud.service("live_stop_push", {"video_id": VIDEO}))
            wait_until(lambda rx=rx: rx.ended_at is not None, 3, what="the stream's end")
            assert rx.ended_at is not None
            ends.append((rx.ended_at - stop) * 1000)
        finally:
            rx.close()
    return out, ends


#: Frames a measuring window must hold, per second of it. The full bench asks for most of the 30 fps the
#: source draws (a stream that decodes at half rate would make its figures a lie); make test's smoke run
#: (--quick, beside a loaded parallel suite) only checks that frames flow and the figures are computed.
FLOOR_FPS = {"full": (20.0, 15.0), "quick": (2.0, 2.0)}


def _floor(seconds: float, quick: bool, preview: bool = False) -> float:
    return seconds * FLOOR_FPS["quick" if quick else "full"][1 if preview else 0]


def _glass_to_glass(rig: Rig, seconds: float, quick: bool) -> list[float]:
    dec = _Decoder(free_port())
    try:
        _ok(rig.cloud.service("live_start_push", {"url_type": 1, "url": dec.url, "video_id": VIDEO}))
        wait_until(lambda: len(dec.latencies) >= 30, 20, what="decoded frames")
        dec.latencies.clear()  # the first second: the receiver's probe burst
        time.sleep(seconds)
        samples = list(dec.latencies)
        _ok(rig.cloud.service("live_stop_push", {"video_id": VIDEO}))
    finally:
        dec.close()
    if len(samples) < _floor(seconds, quick):
        raise AssertionError(f"only {len(samples)} frames decoded in {seconds} s")
    return samples


def _preview_glass_to_glass(rig: Rig, seconds: float, quick: bool) -> list[float]:
    """The console's preview (WebSocket fMP4) decoded as it arrives: drawn → decoded, ms."""
    import asyncio

    import aiohttp

    rx = Receiver(free_port(), Path(tempfile.mkdtemp(prefix="bench-video-")) / "g2g-preview.flv")
    dec = subprocess.Popen(
        ["ffmpeg", "-hide_banner", "-loglevel", "error", "-fflags", "nobuffer", "-flags", "low_delay",
         "-probesize", "32", "-analyzeduration", "0", "-f", "mp4", "-i", "pipe:0", "-f", "rawvideo",
         "-pix_fmt", "gray", "pipe:1"],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    latencies: list[float] = []

    def frames() -> None:
        assert dec.stdout is not None
        while len(frame := dec.stdout.read(W * H)) == W * H:
            now_ms = time.time() * 1000
            latencies.append((int(now_ms) - read_timecode(frame, W, H)) % 2**TIMECODE_BITS + now_ms % 1)

    reader = threading.Thread(target=frames, daemon=True)
    reader.start()

    async def feed() -> None:
        url = f"http://127.0.0.1:{rig.web_port}/api/video?id={VIDEO}"
        async with aiohttp.ClientSession() as session, session.ws_connect(url) as ws:
            assert dec.stdin is not None
            deadline = time.monotonic() + seconds + 2.0
            while time.monotonic() < deadline:
                msg = await asyncio.wait_for(ws.receive(), 5)
                if msg.type != aiohttp.WSMsgType.BINARY:
                    break
                dec.stdin.write(msg.data)
                dec.stdin.flush()
                if len(latencies) >= 30 and not measuring:
                    measuring.append(len(latencies))

    measuring: list[int] = []
    try:
        _ok(rig.cloud.service("live_start_push", {"url_type": 1, "url": rx.url, "video_id": VIDEO}))
        asyncio.run(feed())
        _ok(rig.cloud.service("live_stop_push", {"video_id": VIDEO}))
    finally:
        if dec.stdin is not None:
            dec.stdin.close()
        dec.wait(5)
        reader.join(5)
        rx.close()
    samples = latencies[measuring[0] if measuring else 0 :]
    if len(samples) < _floor(seconds, quick, preview=True):
        raise AssertionError(f"only {len(samples)} preview frames decoded in {seconds} s")
    return samples


def _cpu(rig: Rig, tmp: Path, video: str, quality: int, seconds: float, quick: bool) -> tuple[float, int]:
    rx = Receiver(free_port(), tmp / f"cpu-{quality}.flv")
    try:
        _ok(rig.cloud.service("live_start_push", {"url_type": 1, "url": rx.url, "video_id": video,
                                                  "video_quality": quality}))  # fmt: skip
        wait_until(lambda: rx.frames >= 30, 20, what="frames")
        pid = rig.pipeline_pids()[video]
        before, frames0, t0 = _cpu_seconds(pid), rx.frames, time.monotonic()
        time.sleep(seconds)
        used, frames, wall = _cpu_seconds(pid) - before, rx.frames - frames0, time.monotonic() - t0
        _ok(rig.cloud.service("live_stop_push", {"video_id": video}))
    finally:
        rx.close()
    if frames < _floor(seconds, quick):
        raise AssertionError(f"only {frames} frames in {seconds} s")
    return used / wall * 100, frames


def _children_cpu(pid: int) -> float:
    """CPU seconds of ``pid``'s children (the WHIP publisher's ffmpeg)."""
    total = 0.0
    for task in Path(f"/proc/{pid}/task").iterdir():
        for child in (task / "children").read_text().split():
            total += _cpu_seconds(int(child))
    return total


def _whip(cfg: Config, tmp: Path, runs: int, window: float) -> list[Row]:
    """The WHIP rows: ``run --simulate``'s gimbal to an aiortc WHIP endpoint, both in a network namespace
    (tests/video_rig.whip_rig): start to first decoded frame, stop to the session's DELETE, glass to glass
    through WebRTC, and the CPU of the publisher (aiortc: packetize + SRTP) apart from its ffmpeg."""
    import importlib.util

    from tests.netlab import netns_problem
    from tests.video_rig import GIMBAL_VIDEO, whip_rig, whip_start

    problem = netns_problem() or (None if importlib.util.find_spec("aiortc") else "aiortc is not installed")
    if problem is not None:
        print(f"  .. WHIP rows skipped: {problem}", flush=True)
        return []
    rows: list[Row] = []
    first, ends, g2g = [], [], []
    with whip_rig(tmp, timecode=True) as (_, rig, rx):
        stop = {"video_id": GIMBAL_VIDEO}
        for i in range(runs):
            asked = time.monotonic()
            _ok(whip_start(rig, rx.url(f"first-{i}")))
            wait_until(lambda: rx.last is not None and rx.last.first_frame_at is not None, 20, what="a frame")
            session = rx.last
            assert session is not None and session.first_frame_at is not None
            first.append((session.first_frame_at - asked) * 1000)
            stopped = time.monotonic()
            _ok(rig.cloud.service("live_stop_push", stop))
            wait_until(lambda s=session: s.deleted and s.ended_at is not None, 3, what="the DELETE")
            assert session.ended_at is not None
            ends.append((session.ended_at - stopped) * 1000)
        _ok(whip_start(rig, rx.url("g2g")))
        wait_until(lambda: len(rx.latencies) >= 30, 20, what="decoded frames")
        pid = rig.pipeline_pids()[GIMBAL_VIDEO]
        rx.latencies.clear()
        own, ffmpeg, t0 = _cpu_seconds(pid), _children_cpu(pid), time.monotonic()
        time.sleep(window)
        g2g = sorted(rx.latencies)
        wall = time.monotonic() - t0
        own, ffmpeg = (_cpu_seconds(pid) - own) / wall * 100, (_children_cpu(pid) - ffmpeg) / wall * 100
        _ok(rig.cloud.service("live_stop_push", stop))
    if len(g2g) < _floor(window, cfg.quick):
        raise AssertionError(f"only {len(g2g)} WHIP frames decoded in {window} s")
    p95 = g2g[int(len(g2g) * 0.95)]
    rows.append(Row("video", "WHIP start to first frame p50 (ms)", runs, statistics.median(first), unit="ms",
                    note=f"live_start_push → first frame decoded at an aiortc WHIP endpoint (POST, ICE, "
                    f"DTLS included); max {max(first):.0f} ms"))  # fmt: skip
    rows.append(Row("video", "WHIP stop to the session's end p50 (ms)", runs, statistics.median(ends),
                    unit="ms",
                    note=f"live_stop_push → the endpoint's DELETE; max {max(ends):.0f} ms"))  # fmt: skip
    rows.append(Row("video", "WHIP glass to glass p50 (ms)", len(g2g), statistics.median(g2g), unit="ms",
                    note=f"timecode drawn → decoded by aiortc; p95 {p95:.0f} ms"))  # fmt: skip
    rows.append(Row("video", "CPU, WHIP publisher (% core)", len(g2g), own, unit="% core",
                    note=f"aiortc: demux + packetize + SRTP, no second encode; its ffmpeg (test pattern, "
                    f"encode) {ffmpeg:.1f} % more"))  # fmt: skip
    return rows


def run(cfg: Config) -> list[Row]:
    runs, window = (1, 1.5) if cfg.quick else (5, 8.0)
    rows: list[Row] = []
    with tempfile.TemporaryDirectory(prefix="bench-whip-") as tmpdir:
        rows += _whip(cfg, Path(tmpdir), runs, window)
    with LocalBroker() as broker, tempfile.TemporaryDirectory(prefix="bench-video-") as tmpdir:
        tmp = Path(tmpdir)
        rig = Rig(broker, tmp, camera_size=f"{W}x{H}")
        try:
            first, ends = _first_frames(rig, tmp, runs)
            rows.append(Row("video", "start to first frame p50 (ms)", runs, statistics.median(first),
                            unit="ms",
                            note=f"live_start_push → RTMP receiver; max {max(first):.0f} ms; target < 5000 "
                            "(receiver's 0.3 s probe included)"))  # fmt: skip
            rows.append(Row("video", "stop to the stream's end p50 (ms)", runs, statistics.median(ends),
                            unit="ms", note=f"live_stop_push → the receiver's ffmpeg ends; "
                            f"max {max(ends):.0f} ms; target < 2000"))  # fmt: skip
            g2g = sorted(_glass_to_glass(rig, window, cfg.quick))
            p95 = g2g[int(len(g2g) * 0.95)]
            rows.append(Row("video", "glass to glass p50 (ms)", len(g2g), statistics.median(g2g), unit="ms",
                            note=f"timecode drawn → decoded at the receiver; p95 {p95:.0f} ms, "
                            f"min {g2g[0]:.0f} ms"))  # fmt: skip
            preview = sorted(_preview_glass_to_glass(rig, window, cfg.quick))
            p95 = preview[int(len(preview) * 0.95)]
            rows.append(Row("video", "console preview glass to glass p50 (ms)", len(preview),
                            statistics.median(preview), unit="ms",
                            note=f"WebSocket fMP4 (100 ms fragments) → decoded; p95 {p95:.0f} ms"),
                        )  # fmt: skip
            cpu, frames = _cpu(rig, tmp, VIDEO, 0, window, cfg.quick)
            rows.append(Row("video", "CPU, 720p30 test pattern, encoded (% core)", frames, cpu, unit="% core",
                            note="testsrc2 + drawtext + timecode + libx264 ultrafast 2 Mbps"))  # fmt: skip
            if cfg.quick:  # make test's smoke run: the camera's two rows cost two more encoders
                return rows
            rig.camera.start()
            cpu, frames = _cpu(rig, tmp, CAMERA, 2, window, cfg.quick)
            rows.append(Row("video", "CPU, 720p30 H.264 camera, re-encoded (% core)", frames, cpu,
                            unit="% core",
                            note="video_quality 2: decode + scale + libx264 ultrafast 1 Mbps"))  # fmt: skip
            rig.camera.kill()
            rig.camera.start()
            cpu, frames = _cpu(rig, tmp, CAMERA, 0, window, cfg.quick)
            rows.append(Row("video", "CPU, 720p30 H.264 camera, passed through (% core)", frames, cpu,
                            unit="% core", note="video_quality 0, codec h264: -c:v copy"))  # fmt: skip
        finally:
            rig.close()
    return rows
