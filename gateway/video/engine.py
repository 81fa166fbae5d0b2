"""The media engine's command lines: what one ffmpeg pipeline runs, and how its progress reads.

Owns the translation of (source, target, quality, lens) into an ffmpeg argument vector (Debian 12's ffmpeg
5.1: docs/video.md says why ffmpeg as a supervised process), the pass-through rule (``-c:v copy`` when the
source is H.264, the quality adaptive and the target RTMP), DJI's quality table, the simulated test pattern
(serial number, wall time, osd values drawn in, and the wall-clock millisecond as a row of black/white
blocks a receiver decodes for glass-to-glass latency: :func:`read_timecode`), and the parsing of
``-progress`` output. Pure: no processes, no I/O. Knows nothing about MQTT or the Cloud API's envelopes.
"""

from __future__ import annotations

import shlex
from collections.abc import Sequence
from dataclasses import dataclass
from urllib.parse import urlsplit

__all__ = [
    "QUALITY",
    "TIMECODE_BITS",
    "WHIP_PIPE",
    "Pipeline",
    "ProgressParser",
    "build_command",
    "read_timecode",
    "redact_url",
    "timecode_filters",
]

#: DJI's live page: quality → (width, height, bitrate kbps); 0 (adaptive) keeps the source's size.
QUALITY: dict[int, tuple[int, int, int] | None] = {
    0: None,
    1: (960, 540, 512),
    2: (1280, 720, 1024),
    3: (1280, 720, 1536),
    4: (1920, 1080, 3072),
}
#: Bitrate of an adaptive-quality re-encode (the test pattern, V4L2, non-H.264 sources), kbps.
ADAPTIVE_KBPS = 2048
#: The test pattern's size and rate (1280×720 at 30 fps: the issue's "Done means").
TEST_SIZE = (1280, 720)
TEST_RATE = 30
FONT = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf"

#: The timecode: the wall clock in ms modulo 2**TIMECODE_BITS, one block per bit, least significant first.
TIMECODE_BITS = 24
TIMECODE_BLOCK = 32  # px, on a 1280-wide picture (scaled with it)
TIMECODE_PITCH = 40


@dataclass(frozen=True, slots=True)
class Pipeline:
    """One pipeline: the source, where it goes, and how."""

    source: str  # a URL, /dev/videoN, or test:[pattern]
    source_codec: str  # "h264" or "other"
    url_type: int  # 1 RTMP (ffmpeg pushes it), 4 WHIP (MPEG-TS to gateway/video/whip.py, which publishes it)
    url: str
    quality: int
    lens: str = "normal"
    label: str = ""  # drawn on a test pattern (the device's serial number)
    osd_file: str | None = None  # a text file ffmpeg re-reads each frame (osd values), test pattern only
    threads: int = 2
    preview: bool = False  # also fragmented MP4 on stdout (the web console's preview), besides the target

    @property
    def passthrough(self) -> bool:
        return (
            self.source_codec == "h264"
            and self.quality == 0
            and self.url_type == 1
            and not self.source.startswith(("test:", "/dev/"))
        )


def _escape(text: str) -> str:
    """Text safe inside a drawtext ``text='…'`` option of a filter graph."""
    out = []
    for ch in text:
        if ch in "\\':,;[]=%":
            out.append("\\" + ch)
        else:
            out.append(ch)
    return "".join(out)


def timecode_filters(width: int = TEST_SIZE[0], height: int = TEST_SIZE[1]) -> list[str]:
    """drawbox filters that write the wall-clock millisecond (ffmpeg's ``time(0)``, evaluated as each frame
    is filtered) as TIMECODE_BITS black/white blocks along the bottom of the picture."""
    scale = width / 1280
    block, pitch = round(TIMECODE_BLOCK * scale), round(TIMECODE_PITCH * scale)
    y = height - pitch
    row = pitch * TIMECODE_BITS
    filters = [f"drawbox=x=0:y={y - 4}:w={row + 8}:h={pitch + 4}:color=black:t=fill"]
    for bit in range(TIMECODE_BITS):
        on = f"gt(bitand(floor(mod(time(0)*1000\\,{2**TIMECODE_BITS}))\\,{2**bit})\\,0)"
        filters.append(
            f"drawbox=x={4 + bit * pitch}:y={y}:w={block}:h={block}:color=white:t=fill:enable='{on}'"
        )
    return filters


def read_timecode(gray: bytes, width: int, height: int) -> int:
    """The millisecond (mod 2**TIMECODE_BITS) a test-pattern frame carries: ``gray`` is the frame as 8-bit
    luma (``-pix_fmt gray``), ``width``×``height``."""
    scale = width / 1280
    block, pitch = round(TIMECODE_BLOCK * scale), round(TIMECODE_PITCH * scale)
    y = height - pitch + block // 2
    value = 0
    for bit in range(TIMECODE_BITS):
        x = 4 + bit * pitch + block // 2
        if gray[y * width + x] > 128:
            value |= 1 << bit
    return value


def _test_input(pattern: str, pipeline: Pipeline) -> tuple[list[str], list[str]]:
    w, h = TEST_SIZE
    name = pattern or "testsrc2"
    args = ["-re", "-f", "lavfi", "-i", f"{name}=size={w}x{h}:rate={TEST_RATE}"]
    text = [
        f"drawtext=fontfile={FONT}:text='{_escape(pipeline.label)} {_escape(pipeline.lens)}':"
        "x=20:y=20:fontsize=36:fontcolor=white:box=1:boxcolor=black@0.6",
        f"drawtext=fontfile={FONT}:text='%{{localtime\\:%Y-%m-%d %H\\\\\\:%M\\\\\\:%S}}':"
        "x=20:y=70:fontsize=36:fontcolor=white:box=1:boxcolor=black@0.6",
    ]
    if pipeline.osd_file is not None:
        text.append(
            f"drawtext=fontfile={FONT}:textfile={pipeline.osd_file}:reload=1:"
            "x=20:y=120:fontsize=28:fontcolor=yellow:box=1:boxcolor=black@0.6"
        )
    filters = []
    if pipeline.lens == "ir":
        filters.append("hue=s=0")
    return args, filters + text + timecode_filters(w, h)


def _network_input(source: str) -> list[str]:
    scheme = urlsplit(source).scheme.lower()
    # a short probe: ffmpeg's default analyzes 5 s of a live source before it passes the first frame on
    opts: list[str] = ["-analyzeduration", "500000", "-probesize", "1000000"]
    if scheme in ("rtsp", "rtsps"):
        opts += ["-rtsp_transport", "tcp", "-timeout", "5000000"]
    elif scheme in ("rtmp", "rtmps", "tcp", "http", "https"):
        opts += ["-rw_timeout", "5000000"]
    return [*opts, "-i", source]


#: Where a WHIP pipeline's ffmpeg writes its MPEG-TS: replaced by the publisher with the pipe it reads.
WHIP_PIPE = "@whip-pipe@"

#: The preview's fragments: one at least every 100 ms (each begins at a keyframe or not: MSE takes both).
MP4_FLAGS = "frag_keyframe+empty_moov+default_base_moof"
PREVIEW_MP4 = f"f=mp4:movflags={MP4_FLAGS}:frag_duration=100000:onfail=ignore"


def _tee_escape(url: str) -> str:
    """A URL as one tee slave: the tee muxer's special characters escaped."""
    return "".join("\\" + ch if ch in "|[]\\" else ch for ch in url)


def build_command(ffmpeg: str, p: Pipeline, progress_fd: int = 1) -> list[str]:
    """The ffmpeg argument vector of pipeline ``p``: progress on ``progress_fd``, errors on stderr, the
    preview (when asked; then ``progress_fd`` must not be 1) as fragmented MP4 on stdout."""
    cmd = [ffmpeg, "-hide_banner", "-nostdin", "-loglevel", "error", "-nostats",
           "-progress", f"pipe:{progress_fd}", "-stats_period", "0.25"]  # fmt: skip
    filters: list[str] = []
    if p.source.startswith("test:"):
        args, filters = _test_input(p.source[len("test:") :], p)
        cmd += args
    elif p.source.startswith("/dev/"):
        cmd += ["-f", "v4l2", "-i", p.source]
    else:
        cmd += _network_input(p.source)
    cmd += ["-map", "0:v:0", "-an"]
    if p.passthrough:
        cmd += ["-c:v", "copy"]
    else:
        size = QUALITY.get(p.quality)
        if size is not None:
            filters.append(f"scale={size[0]}:{size[1]}")
            kbps = size[2]
        else:
            kbps = ADAPTIVE_KBPS
        if p.lens == "ir" and not p.source.startswith("test:"):
            filters.append("hue=s=0")
        filters.append("format=yuv420p")
        cmd += ["-vf", ",".join(filters), "-filter_threads", "1"]
        cmd += ["-c:v", "libx264", "-preset", "ultrafast", "-tune", "zerolatency", "-profile:v", "baseline",
                "-g", str(TEST_RATE), "-bf", "0", "-b:v", f"{kbps}k", "-maxrate", f"{kbps}k",
                "-bufsize", f"{kbps // 2}k", "-threads", str(p.threads)]  # fmt: skip
    if p.url_type == 4:  # WHIP: MPEG-TS on a pipe the publisher (gateway/video/whip.py) reads
        # flush_packets: each packet leaves at once (the pipe's 32 kB buffer is ~130 ms of 2 Mbps video)
        if not p.preview:
            return [*cmd, "-flush_packets", "1", "-f", "mpegts", WHIP_PIPE]
        cmd += ["-flags", "+global_header"]
        # dump_extra: the SPS/PPS before every keyframe, in band, as a WebRTC receiver needs them
        target = f"[f=mpegts:bsfs/v=dump_extra:flush_packets=1:onfail=abort]{WHIP_PIPE}"
        return [*cmd, "-f", "tee", f"{target}|[{PREVIEW_MP4}]pipe:1"]
    flv = [*cmd, "-flvflags", "no_duration_filesize", "-f", "flv", p.url]
    if not p.preview:
        return flv
    if p.passthrough:  # a copy goes to two outputs as is (the tee muxer is for sharing one encoder)
        return [*flv, "-map", "0:v:0", "-c:v", "copy", "-movflags", MP4_FLAGS, "-frag_duration", "100000",
                "-f", "mp4", "pipe:1"]  # fmt: skip
    cmd += ["-flags", "+global_header"]  # both outputs take the encoder's headers out of band
    # the target first: its failure ends the pipeline (onfail=abort); the preview's is ignored
    target = f"[f=flv:flvflags=no_duration_filesize:onfail=abort]{_tee_escape(p.url)}"
    return [*cmd, "-f", "tee", f"{target}|[{PREVIEW_MP4}]pipe:1"]


def redact_url(url: str) -> str:
    """``scheme://host:port/…``: where a stream goes, without its path (an RTMP stream key) or password."""
    try:
        parts = urlsplit(url)
    except ValueError:
        return "(unparseable url)"
    host = parts.hostname or "?"
    port = f":{parts.port}" if parts.port else ""
    return f"{parts.scheme}://{host}{port}/…" if parts.scheme else "(not a url)"


def describe(cmd: Sequence[str], secret: str) -> str:
    """A command line for a log: the target URL (a credential) replaced."""
    return " ".join(shlex.quote(arg if arg != secret else redact_url(secret)) for arg in cmd)


class ProgressParser:
    """Reads ffmpeg's ``-progress`` key=value lines; :meth:`feed` returns the frame count at a block's end."""

    def __init__(self) -> None:
        self.frames = 0
        self._pending = 0

    def feed(self, line: str) -> int | None:
        key, _, value = line.strip().partition("=")
        if key == "frame":
            try:
                self._pending = int(value)
            except ValueError:
                return None
        elif key == "progress":
            self.frames = max(self.frames, self._pending)
            return self.frames
        return None
