"""Live video end to end: the simulated aircraft of ``run --simulate`` streams to a real RTMP receiver (an
ffmpeg listening on a free loopback port, started here) that records what arrives; ffprobe decodes it.

One gateway and its cloud client are shared by the module (720p30 encoding is what costs: two real
streams in all). Skipped with the reason when ffmpeg/ffprobe are not installed (``make test`` installs them).
"""

from __future__ import annotations

import contextlib
import shutil
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from gateway.cli.run import SIM_AIRCRAFT_SN, simulated_settings, start_simulators
from gateway.local_broker import LocalBroker
from gateway.settings import load_settings
from tests.support import CloudClient, GatewayThread, wait_until

pytestmark = [
    pytest.mark.broker,
    pytest.mark.skipif(
        shutil.which("ffmpeg") is None or shutil.which("ffprobe") is None,
        reason="ffmpeg/ffprobe not installed (make ffmpeg: apt-get install ffmpeg fonts-dejavu-core)",
    ),
]

VIDEO = f"{SIM_AIRCRAFT_SN}/0-0-0/normal-0"  # the simulated aircraft's test pattern
CAMERA = f"{SIM_AIRCRAFT_SN}/0-0-1/normal-0"  # an "IP camera" (an ffmpeg serving H.264 over TCP)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def listening(port: int) -> bool:
    """Whether something listens on 127.0.0.1:port, read from /proc (a probe connection would be the one
    connection an ffmpeg ``-listen 1`` accepts)."""
    needle = f":{port:04X} "
    with open("/proc/net/tcp") as f:
        return any(needle in line and line.split()[3] == "0A" for line in f.readlines()[1:])


class Receiver:
    """An RTMP server for one publish: ``ffmpeg -listen 1`` copying what arrives into an FLV file, its
    progress read to time the first frame and count frames."""

    def __init__(self, port: int, out: Path) -> None:
        self.port, self.out = port, out
        self.url = f"rtmp://127.0.0.1:{port}/live/stream-key-{port}"
        self.first_frame_at: float | None = None
        self.frames = 0
        self.ended_at: float | None = None
        self.proc = subprocess.Popen(
            ["ffmpeg", "-hide_banner", "-loglevel", "error", "-nostats", "-progress", "pipe:1",
             # a listening RTMP input announces audio and video: without a short analyzeduration ffmpeg
             # probes 5 s for an audio stream that never comes before it passes anything on
             "-stats_period", "0.1", "-analyzeduration", "300000", "-listen", "1", "-f", "flv",
             "-i", self.url, "-c", "copy", "-f", "flv", "-y", str(out)],
            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
        )  # fmt: skip
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        wait_until(lambda: listening(port), 10, what=f"the RTMP receiver on {port}")

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            key, _, value = line.strip().partition("=")
            if key == "frame" and value.isdigit() and int(value) > 0:
                self.frames = int(value)
                if self.first_frame_at is None:
                    self.first_frame_at = time.monotonic()
        self.proc.stdout.close()
        self.proc.wait()
        self.ended_at = time.monotonic()

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self._reader.join(5)


def probe(path: Path) -> dict[str, str]:
    out = subprocess.run(
        ["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v:0", "-show_entries",
         "stream=codec_name,width,height,nb_read_frames", "-of", "default=noprint_wrappers=1", str(path)],
        capture_output=True, text=True, timeout=60, check=True,
    ).stdout  # fmt: skip
    return dict(line.split("=", 1) for line in out.split())


class Camera:
    """An IP camera: H.264 (640×360, 30 fps) served over TCP to one client at a time, until killed."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        self.proc = subprocess.Popen(
            ["ffmpeg", "-hide_banner", "-loglevel", "quiet", "-re", "-f", "lavfi", "-i",
             "testsrc2=size=640x360:rate=30", "-c:v", "libx264", "-preset", "ultrafast",
             "-tune", "zerolatency",
             "-g", "15", "-f", "mpegts", f"tcp://127.0.0.1:{self.port}?listen=1"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        wait_until(lambda: listening(self.port), 10, what="the camera")

    def kill(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()


class Rig:
    def __init__(self, broker: LocalBroker, tmp: Path) -> None:
        self.tmp = tmp
        self.camera = Camera(free_port())
        doc = simulated_settings({"broker": {"url": f"mqtt://127.0.0.1:{broker.port}"}, "osd_period": 1.0})
        doc["devices"] = [d for d in doc["devices"] if d["type"] == "osdk"]
        doc["metrics"] = {"enabled": False}
        doc["video"]["sources"] = [s for s in doc["video"]["sources"] if s["sn"] == SIM_AIRCRAFT_SN] + [
            {"sn": SIM_AIRCRAFT_SN, "camera_index": "0-0-1", "codec": "h264",
             "source": f"tcp://127.0.0.1:{self.camera.port}"},
        ]  # fmt: skip
        doc["video"].update(max_streams=2, backoff_initial=0.3, backoff_max=1.0, stall_timeout=3.0)
        self.sims: list[Any] = []
        self.settings = start_simulators(load_settings(None, **doc), self.sims)
        self.cloud = CloudClient(broker.host, broker.port, self.settings.gateway_sn)
        self.gw = GatewayThread(self.settings).start()
        self.gw_state = f"{self.settings.gateway_sn}/state"

    def status(self, video_id: str) -> list[tuple[int, int]]:
        """Every (status, error_status) the gateway has published for ``video_id``, in order."""
        out = []
        for body in self.cloud.find(self.gw_state, lambda b: "live_status" in b["data"]):
            for entry in body["data"]["live_status"]:
                pair = (entry["status"], entry["error_status"])
                if entry["video_id"] == video_id and (not out or out[-1] != pair):
                    out.append(pair)
        return out

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.gw.stop()
        self.cloud.close()
        self.camera.kill()
        for sim in self.sims:
            sim.stop()


@pytest.fixture(scope="module")
def rig(broker: LocalBroker, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Rig]:
    r = Rig(broker, tmp_path_factory.mktemp("video"))
    try:
        yield r
    finally:
        r.close()


def result(reply: dict[str, Any]) -> int:
    return int(reply["data"]["result"])


def test_capacity_in_the_gateway_state(rig: Rig) -> None:
    (body,) = rig.cloud.wait_for(rig.gw_state, lambda b: "live_capacity" in b["data"], timeout=10)[-1:]
    cap = body["data"]["live_capacity"]
    (device,) = cap["device_list"]
    assert device["sn"] == SIM_AIRCRAFT_SN and cap["coexist_video_number_max"] == 2
    cameras = {c["camera_index"]: c for c in device["camera_list"]}
    assert cameras["0-0-0"]["video_list"] == [
        {"video_index": "normal-0", "video_type": "normal", "switchable_video_types": ["normal", "ir"]}
    ]
    assert {e["video_id"]: (e["status"], e["error_status"]) for e in body["data"]["live_status"]} == {
        VIDEO: (0, 0),
        CAMERA: (0, 0),
    }


def test_refusals_are_documented_codes(rig: Rig) -> None:
    start = {"url_type": 1, "url": "rtmp://127.0.0.1:9/live/x", "video_id": VIDEO, "video_quality": 0}
    refused = [
        ({"url_type": 0, "url": "channel=a&sn=b"}, 399010),  # Agora
        ({"url_type": 4, "url": "http://h/whip"}, 399010),  # WHIP
        ({"url_type": 3, "url": "serverIP=1"}, 399010),  # GB28181
        ({"video_id": "NOPE/0-0-0/normal-0"}, 399012),
        ({"url": "http://not-rtmp/"}, 325001),
        ({"video_quality": 9}, 325001),
    ]
    for change, code in refused:
        assert result(rig.cloud.service("live_start_push", {**start, **change})) == code, change
    assert result(rig.cloud.service("live_stop_push", {"video_id": VIDEO})) == 0  # not running: not an error
    assert result(rig.cloud.service("live_set_quality", {"video_id": VIDEO, "video_quality": 1})) == 399014
    assert result(rig.cloud.service("live_lens_change", {"video_id": VIDEO, "video_type": "zoom"})) == 399013
    # a target nobody listens on: the pipeline dies before its first frame and the start says so
    reply = rig.cloud.service("live_start_push", start)
    assert result(reply) == 399015 and "stream-key" not in reply["data"]["output"]["reason"]
    published = [raw for topic, _, raw in rig.cloud.messages if not topic.endswith("/services")]
    assert b"live/x" not in b"".join(published)  # a stream key never leaves in a reply or a state


def test_simulated_aircraft_streams_720p_and_stops_within_2s(rig: Rig) -> None:
    rx = Receiver(free_port(), rig.tmp / "aircraft.flv")
    try:
        asked = time.monotonic()
        start = {"url_type": 1, "url": rx.url, "video_id": VIDEO, "video_quality": 0}
        assert result(rig.cloud.service("live_start_push", start)) == 0
        wait_until(lambda: rx.first_frame_at is not None, 5.0, what="the first frame")
        assert rx.first_frame_at is not None and rx.first_frame_at - asked < 5.0
        wait_until(lambda: (1, 0) in rig.status(VIDEO), 5, what="live_status 1")
        # a second start of the same video: the same target is answered 0, another target 399011
        assert result(rig.cloud.service("live_start_push", start)) == 0
        other = {**start, "url": "rtmp://127.0.0.1:9/live/other"}
        assert result(rig.cloud.service("live_start_push", other)) == 399011
        wait_until(lambda: rx.frames >= 30 * 5 + 15, 15, what="5 s of frames")
        stopped = time.monotonic()
        assert result(rig.cloud.service("live_stop_push", {"video_id": VIDEO})) == 0
        wait_until(lambda: rx.ended_at is not None, 2.0, what="the stream's end")
        assert rx.ended_at is not None and rx.ended_at - stopped < 2.0
        wait_until(lambda: rig.status(VIDEO)[-1] == (0, 0), 3, what="live_status 0")
    finally:
        rx.close()
    info = probe(rx.out)
    assert info["codec_name"] == "h264" and (info["width"], info["height"]) == ("1280", "720")
    assert int(info["nb_read_frames"]) >= 150, info


def test_source_killed_mid_stream_restarts_and_status_shows_it(rig: Rig) -> None:
    rig.camera.start()
    port = free_port()
    receivers = [Receiver(port, rig.tmp / "camera-0.flv")]
    start = {"url_type": 1, "url": receivers[0].url, "video_id": CAMERA, "video_quality": 0}
    try:
        assert result(rig.cloud.service("live_start_push", start)) == 0
        wait_until(lambda: receivers[0].frames >= 15, 8, what="the camera's frames (pass-through)")
        wait_until(lambda: (1, 0) in rig.status(CAMERA), 5, what="live_status 1")
        rig.camera.kill()
        wait_until(lambda: rig.status(CAMERA)[-1] == (0, 399015), 8, what="live_status failure")
        wait_until(lambda: receivers[-1].ended_at is not None, 5, what="the receiver's end")
        receivers.append(Receiver(port, rig.tmp / "camera-1.flv"))
        rig.camera.start()
        wait_until(lambda: receivers[-1].frames >= 15, 10, what="frames after the restart")
        wait_until(lambda: rig.status(CAMERA)[-1] == (1, 0), 5, what="live_status recovered")
        history = rig.status(CAMERA)
        assert history[history.index((0, 399015)) :][-1] == (1, 0), history
        assert result(rig.cloud.service("live_stop_push", {"video_id": CAMERA})) == 0
    finally:
        for rx in receivers:
            rx.close()
        rig.camera.kill()
    info = probe(rig.tmp / "camera-1.flv")
    assert info["codec_name"] == "h264" and info["width"] == "640"  # passed through, not re-encoded
