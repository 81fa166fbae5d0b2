"""The live-video state machine and command lines, without processes: time is a ManualClock's value."""

from __future__ import annotations

import pytest

from adapters.clock import ManualClock
from gateway.video.engine import (
    PREVIEW_MP4,
    WHIP_PIPE,
    Pipeline,
    ProgressParser,
    build_command,
    describe,
    read_timecode,
    redact_url,
)
from gateway.video.machine import Backoff, Kill, Phase, Spawn, StreamMachine, Target
from gateway.video.preview import BoxSplitter, PreviewFeed
from schemas import TopicKind, default_registry
from schemas.live import parse_video_id

T = Target(1, "rtmp://127.0.0.1:1935/live/secret-key", 0, "normal")


def machine(clock: ManualClock) -> StreamMachine:
    return StreamMachine("SN/0-0-0/normal-0", backoff=Backoff(0.5, 4.0, stable_after=10.0), stall_timeout=5.0)


def test_start_first_frames_then_stop() -> None:
    clock = ManualClock()
    m = machine(clock)
    (spawn,) = m.start(T, clock.monotonic())
    assert isinstance(spawn, Spawn) and spawn.generation == 1 and m.phase is Phase.STARTING
    assert m.status() == (0, 0)
    clock.advance(0.8)
    m.progress(1, 12, clock.monotonic())
    assert m.phase is Phase.LIVE and m.status() == (1, 0) and m.first_frame_at == clock.monotonic()
    assert m.stop(clock.monotonic()) == [Kill(1)] and m.phase is Phase.STOPPING and m.status() == (0, 0)
    assert m.exited(1, clock.monotonic(), "exited 255") == [] and m.phase is Phase.IDLE
    assert m.stop(clock.monotonic()) == []  # stopping a stopped stream: nothing to do, not an error


def test_a_start_that_dies_before_its_first_frame_fails_fast() -> None:
    clock = ManualClock()
    m = machine(clock)
    m.start(T, clock.monotonic(), fail_fast=True)
    m.exited(1, clock.monotonic(), "Connection refused")
    assert m.phase is Phase.IDLE and m.status() == (0, 399015) and m.last_reason == "Connection refused"
    assert m.tick(clock.monotonic() + 100) == []  # nothing retries a start the cloud was told failed


def test_failures_retry_with_doubling_backoff_then_reset_after_a_stable_run() -> None:
    clock = ManualClock()
    m = machine(clock)
    m.start(T, clock.monotonic(), fail_fast=False)
    m.progress(1, 5, clock.monotonic())
    gen = 1
    delays = []
    for _ in range(5):  # the source drops right after each restart
        m.exited(gen, clock.monotonic(), "source gone")
        assert m.phase is Phase.RETRYING and m.status() == (0, 399015)
        assert m.retry_at is not None
        delays.append(round(m.retry_at - clock.monotonic(), 3))
        clock.advance(delays[-1] - 0.01)
        assert m.tick(clock.monotonic()) == []  # not yet
        clock.advance(0.01)
        (spawn,) = m.tick(clock.monotonic())
        assert isinstance(spawn, Spawn) and spawn.target == T
        gen = spawn.generation
        m.progress(gen, 3, clock.monotonic())
        assert m.status() == (1, 0)  # recovered
    assert delays == [0.5, 1.0, 2.0, 4.0, 4.0]
    clock.advance(10.0)  # live for stable_after: the next failure starts the backoff again
    m.exited(gen, clock.monotonic(), "source gone")
    assert m.retry_at == pytest.approx(clock.monotonic() + 0.5)
    assert m.restarts == 5


def test_stale_generations_are_ignored() -> None:
    clock = ManualClock()
    m = machine(clock)
    m.start(T, clock.monotonic(), fail_fast=False)
    m.progress(1, 30, clock.monotonic())
    actions = m.reconfigure(clock.monotonic(), quality=2)
    assert actions == [Kill(1), Spawn(2, Target(T.url_type, T.url, 2, "normal"))]
    assert m.exited(1, clock.monotonic(), "killed") == [] and m.phase is Phase.STARTING  # the old one
    m.progress(1, 99, clock.monotonic())  # a late line of the killed process
    assert m.phase is Phase.STARTING
    m.progress(2, 1, clock.monotonic())
    assert m.phase is Phase.LIVE and m.target is not None and m.target.quality == 2


def test_a_stalled_pipeline_is_killed_once_and_retried() -> None:
    clock = ManualClock()
    m = machine(clock)
    m.start(T, clock.monotonic(), fail_fast=False)
    m.progress(1, 30, clock.monotonic())
    clock.advance(4.9)
    assert m.tick(clock.monotonic()) == []
    clock.advance(0.2)
    assert m.tick(clock.monotonic()) == [Kill(1)]
    assert m.tick(clock.monotonic()) == []  # one kill, not one per tick
    m.exited(1, clock.monotonic(), "killed")
    assert m.phase is Phase.RETRYING and "no frame" in m.last_reason


def test_a_process_has_start_timeout_for_its_first_frame_then_stall_timeout() -> None:
    """A WHIP publisher's first frame comes after Python, aiortc, the POST, ICE and DTLS (11.8 s once on a
    loaded CI machine): it is not a stall until ``start_timeout``; after a frame, ``stall_timeout`` again."""
    clock = ManualClock()
    m = StreamMachine("SN/0-0-0/normal-0", backoff=Backoff(0.5, 4.0), stall_timeout=3.0, start_timeout=20.0)
    m.start(T, clock.monotonic(), fail_fast=False)
    clock.advance(19.9)
    assert m.tick(clock.monotonic()) == [] and m.phase is Phase.STARTING
    m.progress(1, 1, clock.monotonic())
    clock.advance(2.9)
    assert m.tick(clock.monotonic()) == [] and m.phase is Phase.LIVE
    clock.advance(0.2)
    assert m.tick(clock.monotonic()) == [Kill(1)]
    m.exited(1, clock.monotonic(), "killed")
    assert m.last_reason == "no frame for 3 s (killed)"
    clock.advance(1.0)
    assert m.tick(clock.monotonic()) == [Spawn(2, T)]  # the retry: a new start, its own 20 s
    clock.advance(20.1)
    assert m.tick(clock.monotonic()) == [Kill(2)] and m.last_reason == "no frame for 20 s after its start"
    # a start_timeout below stall_timeout is raised to it
    low = StreamMachine("v", backoff=Backoff(0.5, 4.0), stall_timeout=5.0, start_timeout=1.0)
    assert low.start_timeout == 5


def test_stop_while_waiting_out_a_backoff() -> None:
    clock = ManualClock()
    m = machine(clock)
    m.start(T, clock.monotonic(), fail_fast=False)
    m.exited(1, clock.monotonic(), "refused")
    assert m.phase is Phase.RETRYING
    assert m.stop(clock.monotonic()) == [] and m.phase is Phase.IDLE and m.status() == (0, 0)
    assert m.tick(clock.monotonic() + 60) == []


def test_command_lines() -> None:
    test = Pipeline("test:", "other", 1, "rtmp://h:1/live/k", 0, label="SN-1", osd_file="/tmp/osd.txt")
    cmd = build_command("ffmpeg", test)
    assert cmd[cmd.index("-c:v") + 1] == "libx264" and "lavfi" in cmd and cmd[-1] == "rtmp://h:1/live/k"
    vf = cmd[cmd.index("-vf") + 1]
    assert "SN-1" in vf and "textfile=/tmp/osd.txt" in vf and "time(0)" in vf and "scale" not in vf
    copy = Pipeline("rtsp://cam/1", "h264", 1, "rtmp://h/live/k", 0)
    cmd = build_command("ffmpeg", copy)
    assert cmd[cmd.index("-c:v") + 1] == "copy" and "-vf" not in cmd and "tcp" in cmd  # rtsp over tcp
    sd = Pipeline("rtsp://cam/1", "h264", 1, "rtmp://h/live/k", 1)  # smooth: re-encoded to 960×540
    cmd = build_command("ffmpeg", sd)
    assert "scale=960:540" in cmd[cmd.index("-vf") + 1] and cmd[cmd.index("-b:v") + 1] == "512k"
    # WHIP: an H.264 source is re-encoded all the same (WebRTC wants baseline without B-frames, a keyframe
    # each second), MPEG-TS on the publisher's pipe; with the preview, a tee whose target gets SPS/PPS in band
    whip = Pipeline("rtsp://cam/1", "h264", 4, "https://h/whip/k", 0)
    cmd = build_command("ffmpeg", whip)
    assert not whip.passthrough and "https://h/whip/k" not in cmd
    assert cmd[-5:] == ["-flush_packets", "1", "-f", "mpegts", WHIP_PIPE]
    assert cmd[cmd.index("-profile:v") + 1] == "baseline" and cmd[cmd.index("-bf") + 1] == "0"
    tee = build_command("ffmpeg", Pipeline("test:", "other", 4, "https://h/whip/k", 0, preview=True))
    target = f"[f=mpegts:bsfs/v=dump_extra:flush_packets=1:onfail=abort]{WHIP_PIPE}"
    assert tee[-1] == f"{target}|[{PREVIEW_MP4}]pipe:1"
    assert redact_url("rtmp://u:pw@host:1935/live/stream-key") == "rtmp://host:1935/…"
    assert "stream-key" not in describe(cmd, "rtmp://h/live/k")


def test_progress_and_timecode() -> None:
    p = ProgressParser()
    assert [p.feed(line) for line in ("frame=12", "fps=30", "progress=continue")] == [None, None, 12]
    assert p.feed("frame=garbage") is None
    width, height = 1280, 720
    value = 0b1010_0000_1111_0000_1100_0101
    frame = bytearray(width * height)
    for bit in range(24):
        if value >> bit & 1:
            y, x = height - 40 + 16, 4 + bit * 40 + 16
            frame[y * width + x] = 255
    assert read_timecode(bytes(frame), width, height) == value


def test_the_contract_reads_tolerantly_and_refuses_nonsense() -> None:
    registry = default_registry()

    def start(data: dict[str, object]) -> object:
        msg = {"tid": "t", "bid": "b", "method": "live_start_push", "data": data}
        return registry.validate(TopicKind.SERVICES, msg).data

    ok = {"url_type": "1", "url": "rtmp://h/live/k", "video_id": " SN/39-0-7/normal-0 ", "video_quality": 3.0}
    data = start(ok)
    assert data.url_type == 1 and data.video_quality == 3 and data.video_id == "SN/39-0-7/normal-0"  # type: ignore[attr-defined]
    assert "rtmp://h/live/k" not in repr(data)  # a stream key is a secret
    for bad in ({"video_quality": 5}, {"video_id": "SN/normal-0"}, {"url_type": 9}, {"url": 5}):
        with pytest.raises(ValueError):
            start({**ok, **bad})
    assert parse_video_id("1ZNDH1D0010098/39-0-7/normal-0") == ("1ZNDH1D0010098", "39-0-7", "normal-0")


def _box(kind: bytes, body: bytes = b"") -> bytes:
    return (8 + len(body)).to_bytes(4, "big") + kind + body


def test_preview_segments_split_at_any_offset() -> None:
    init = _box(b"ftyp", b"isom") + _box(b"moov", b"avcC\x01\x42\xc0\x1f")
    frags = [_box(b"moof", bytes([i])) + _box(b"mdat", bytes(50 + i)) for i in range(3)]
    stream = init + b"".join(frags)
    for cut in range(1, len(stream)):
        splitter = BoxSplitter()
        out = splitter.feed(stream[:cut]) + splitter.feed(stream[cut:])
        assert out == [("init", init)] + [("fragment", f) for f in frags]
    with pytest.raises(ValueError):
        BoxSplitter().feed(b"\x00\x00\x00\x02moov")  # a box shorter than its header


def test_preview_feed_gives_late_pages_the_init_and_ends_them_on_restart() -> None:
    feed = PreviewFeed()
    init = _box(b"ftyp") + _box(b"moov")
    frag = _box(b"moof") + _box(b"mdat", b"x")
    early: list[bytes] = []
    feed.subscribe(early.append)
    feed.feed(init + frag)
    late: list[bytes] = []
    unsubscribe = feed.subscribe(late.append)
    feed.feed(frag)
    assert early == [init, frag, frag] and late == [init, frag]
    unsubscribe()
    feed.feed(frag)
    assert late == [init, frag]
    feed.restart()
    assert early[-1] == b"" and feed.init is None and feed.subscribers == []
