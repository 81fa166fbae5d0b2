"""What the live-video tests and ``bench/video.py`` share: an RTMP receiver (an ffmpeg listening on a free
loopback port), an "IP camera" (an ffmpeg serving H.264 over TCP), ffprobe, and a gateway whose simulated
aircraft has a test pattern and that camera as video sources."""

from __future__ import annotations

import contextlib
import random
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from bench.partitions import NetnsGateway
from gateway.cli.run import (
    SIM_AIRCRAFT_SN,
    SIM_GIMBAL_PAYLOAD_INDEX,
    SIM_GIMBAL_SN,
    simulated_settings,
    start_simulators,
)
from gateway.local_broker import LocalBroker
from gateway.settings import load_settings
from tests.netlab import VethLink
from tests.support import CloudClient, GatewayThread, wait_until

if TYPE_CHECKING:
    from tests.whip_receiver import WhipReceiver

VIDEO = f"{SIM_AIRCRAFT_SN}/0-0-0/normal-0"  # the simulated aircraft's test pattern
GIMBAL_VIDEO = f"{SIM_GIMBAL_SN}/{SIM_GIMBAL_PAYLOAD_INDEX}/normal-0"  # the gimbal's (a Rig with a link)
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
        try:
            wait_until(
                lambda: listening(port) or self.proc.poll() is not None, 10, what=f"the receiver on {port}"
            )
            if self.proc.poll() is not None:
                raise AssertionError(f"the RTMP receiver on {port} exited ({self.proc.returncode})")
        except AssertionError:
            self.close()
            raise

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


class Listener:
    """An RTMP server for one publish after another (a pipeline replaced by a quality or lens change
    publishes again): a Receiver per publish, ``name-<n>.flv``."""

    def __init__(self, port: int, tmp: Path, name: str) -> None:
        self.port, self.tmp, self.name = port, tmp, name
        self.receivers: list[Receiver] = []
        self._stop = threading.Event()
        self.receivers.append(Receiver(port, tmp / f"{name}-0.flv"))
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while not self._stop.is_set():
            self.receivers[-1].proc.wait()
            while not self._stop.is_set():
                try:
                    rx = Receiver(self.port, self.tmp / f"{self.name}-{len(self.receivers)}.flv")
                except AssertionError:  # the port not free again yet: listen once more
                    time.sleep(0.1)
                    continue
                self.receivers.append(rx)
                break

    @property
    def url(self) -> str:
        return self.receivers[0].url

    def close(self) -> None:
        self._stop.set()
        for rx in list(self.receivers):  # wakes the loop from its wait
            rx.close()
        self._thread.join(5)
        for rx in list(self.receivers):  # one it may have started meanwhile
            rx.close()


def probe(path: Path) -> dict[str, str]:
    out = subprocess.run(
        ["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v:0", "-show_entries",
         "stream=codec_name,width,height,nb_read_frames", "-of", "default=noprint_wrappers=1", str(path)],
        capture_output=True, text=True, timeout=60, check=True,
    ).stdout  # fmt: skip
    return dict(line.split("=", 1) for line in out.split())


class Camera:
    """An IP camera: H.264 (``size``, 30 fps) served over TCP to one client at a time, until killed."""

    def __init__(self, port: int, size: str = "640x360") -> None:
        self.port, self.size = port, size
        self.proc: subprocess.Popen[bytes] | None = None

    def start(self) -> None:
        self.proc = subprocess.Popen(
            ["ffmpeg", "-hide_banner", "-loglevel", "quiet", "-re", "-f", "lavfi", "-i",
             f"testsrc2=size={self.size}:rate=30", "-c:v", "libx264", "-preset", "ultrafast",
             "-tune", "zerolatency", "-g", "15", "-f", "mpegts", f"tcp://127.0.0.1:{self.port}?listen=1"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )  # fmt: skip
        wait_until(lambda: listening(self.port), 10, what="the camera")

    def kill(self) -> None:
        if self.proc is not None:
            self.proc.kill()
            self.proc.wait()


class Rig:
    """``run --simulate``'s gateway with its aircraft only, a cloud client, and a camera (not started)."""

    def __init__(
        self, broker: LocalBroker, tmp: Path, camera_size: str = "640x360", *, link: VethLink | None = None
    ) -> None:
        """``link``: the gateway runs in that namespace (WHIP: WebRTC never on the host's interfaces) and
        reaches ``broker`` at the veth's host end, where the broker must listen too."""
        self.tmp = tmp
        self.camera = Camera(free_port(), camera_size)
        host = link.host_ip if link is not None else "127.0.0.1"
        doc = simulated_settings({"broker": {"url": f"mqtt://{host}:{broker.port}"}, "osd_period": 1.0})
        # in a namespace the gimbal (a virtual CAN bus: in-process, no address) stands in for the aircraft,
        # whose simulator listens on the host's loopback, out of the namespace's reach; so does the camera
        family = "osdk" if link is None else "rsdk"
        doc["devices"] = [d for d in doc["devices"] if d["type"] == family]
        doc["metrics"] = {"enabled": True, "host": "127.0.0.1", "port": 0}  # the console's video preview
        doc["video"]["sources"] = [  # beside the aircraft's test pattern (video.test_pattern)
            {"sn": SIM_AIRCRAFT_SN, "camera_index": "0-0-1", "codec": "h264",
             "source": f"tcp://127.0.0.1:{self.camera.port}"},
        ] if link is None else []  # fmt: skip
        doc["video"].update(max_streams=2, backoff_initial=0.3, backoff_max=1.0, stall_timeout=3.0)
        self.sims: list[Any] = []
        self.settings = start_simulators(load_settings(None, **doc), self.sims)
        self.cloud = CloudClient(broker.host, broker.port, self.settings.gateway_sn)
        gw = GatewayThread(self.settings) if link is None else NetnsGateway(self.settings, link.ns)
        self.gw = gw.start()
        self.gw_state = f"{self.settings.gateway_sn}/state"

    def entry(self, video_id: str) -> dict[str, Any] | None:
        """The last ``live_status`` entry published for ``video_id``."""
        for body in reversed(self.cloud.find(self.gw_state, lambda b: "live_status" in b["data"])):
            for entry in body["data"]["live_status"]:
                if entry["video_id"] == video_id:
                    return dict(entry)
        return None

    def status(self, video_id: str) -> list[tuple[int, int]]:
        """Every (status, error_status) the gateway has published for ``video_id``, in order."""
        out = []
        for body in self.cloud.find(self.gw_state, lambda b: "live_status" in b["data"]):
            for entry in body["data"]["live_status"]:
                pair = (entry["status"], entry["error_status"])
                if entry["video_id"] == video_id and (not out or out[-1] != pair):
                    out.append(pair)
        return out

    @property
    def web_port(self) -> int:
        obs = self.gw.app.observability if self.gw.app is not None else None
        assert obs is not None and obs.port
        return int(obs.port)

    def preview(self, video_id: str, fragments: int, out: Path, timeout: float = 10.0) -> float:
        """Read ``fragments`` fragments of the console's preview of ``video_id`` into ``out`` (init segment
        first); returns the seconds until the first fragment arrived."""
        import asyncio

        import aiohttp

        async def read() -> float:
            url = f"http://127.0.0.1:{self.web_port}/api/video?id={video_id}"
            started = time.monotonic()
            first = 0.0
            async with aiohttp.ClientSession() as session, session.ws_connect(url) as ws:
                with out.open("wb") as f:
                    n = -1  # the init segment first
                    while n < fragments:
                        msg = await asyncio.wait_for(ws.receive(), timeout)
                        if msg.type != aiohttp.WSMsgType.BINARY:
                            raise AssertionError(f"preview ended early: {msg.type}")
                        f.write(msg.data)
                        n += 1
                        if n == 1:
                            first = time.monotonic() - started
            return first

        return asyncio.run(read())

    def pipeline_pids(self) -> dict[str, int]:
        """The running ffmpeg processes of the gateway's live service, by video id."""
        live = self.gw.app.live if self.gw.app is not None else None
        assert live is not None
        out = {}
        for (vid, _), proc in list(live._procs.items()):
            if proc.proc is not None and proc.proc.returncode is None:
                out[vid] = proc.proc.pid
        return out

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.gw.stop()
        self.cloud.close()
        self.camera.kill()
        for sim in self.sims:
            sim.stop()


@contextlib.contextmanager
def whip_rig(tmp: Path, *, timecode: bool = False) -> Iterator[tuple[VethLink, Rig, WhipReceiver]]:
    """A network namespace with ``run --simulate``'s gateway (its gimbal's test pattern: GIMBAL_VIDEO) and a
    WHIP endpoint in it, a broker on the host listening on loopback and on the veth's host end, a cloud
    on loopback. WebRTC's ICE offers every address but loopback's: in the namespace the veth's end is the
    only one, so nothing reaches the host's real interfaces. The caller skips first where
    ``netlab.netns_problem()`` says namespaces cannot be made. ``timecode``: the endpoint reads each
    frame's drawn millisecond (glass to glass)."""
    from tests.whip_receiver import WhipReceiver

    with VethLink() as link:
        port = free_port()
        listeners = f"listener {port} 127.0.0.1\nlistener {port} {link.host_ip}"
        broker = LocalBroker(port, listener_lines=listeners).start()
        rig: Rig | None = None
        rx: WhipReceiver | None = None
        try:
            rig = Rig(broker, tmp, link=link)
            wait_until(lambda: rig.gw.app.devices.by_sn(SIM_GIMBAL_SN).online, 15, what="the gimbal online")
            # a fresh namespace: every port in it is free
            rx = WhipReceiver(link.gw_ip, random.randrange(20000, 60000), netns=link.ns, timecode=timecode)
            yield link, rig, rx
        finally:
            if rx is not None:
                rx.close()
            if rig is not None:
                rig.close()
            broker.stop()


def whip_start(rig: Rig, url: str, quality: int = 0) -> dict[str, Any]:
    """``live_start_push`` of the gimbal's test pattern to a WHIP endpoint; the reply."""
    body = {"url_type": 4, "url": url, "video_id": GIMBAL_VIDEO, "video_quality": quality}
    return rig.cloud.service("live_start_push", body, timeout=15)
