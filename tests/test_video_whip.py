"""Live video over WebRTC (WHIP, ``url_type`` 4) end to end: ``run --simulate``'s gimbal streams its test
pattern through the gateway's publisher (``gateway/video/whip.py``: ffmpeg encodes, aiortc sends) to a
real WHIP endpoint started here (``tests/whip_receiver.py``: aiohttp + aiortc), which decodes every frame.

WebRTC's ICE offers every interface's address but loopback's, so the gateway and the endpoint run in a
network namespace this module makes (a veth pair: the namespace's end is the only address either can
offer); the broker and the cloud stay on the host. Skipped with the reason where namespaces cannot be
made, or ffmpeg or aiortc is missing (``make test`` installs both).
"""

from __future__ import annotations

import importlib.util
import shutil
import time
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import pytest

from tests.netlab import VethLink, netns_problem
from tests.support import wait_until
from tests.video_rig import GIMBAL_VIDEO, Rig, whip_rig, whip_start

if TYPE_CHECKING:
    from tests.whip_receiver import WhipReceiver

pytestmark = [
    pytest.mark.broker,
    pytest.mark.netns,
    pytest.mark.skipif(
        shutil.which("ffmpeg") is None, reason="ffmpeg not installed (make ffmpeg: apt-get install ffmpeg)"
    ),
    pytest.mark.skipif(
        importlib.util.find_spec("aiortc") is None, reason="aiortc not installed (the webrtc extra)"
    ),
]


def result(reply: dict[str, Any]) -> int:
    return int(reply["data"]["result"])


class _Whip:
    def __init__(self, link: VethLink, rig: Rig, rx: WhipReceiver) -> None:
        self.link, self.rig, self.rx = link, rig, rx

    def start(self, name: str) -> dict[str, Any]:
        return whip_start(self.rig, self.rx.url(name))


@pytest.fixture(scope="module")
def whip(tmp_path_factory: pytest.TempPathFactory) -> Iterator[_Whip]:
    problem = netns_problem()
    if problem is not None:
        pytest.skip(problem)
    with whip_rig(tmp_path_factory.mktemp("whip")) as (link, rig, rx):
        yield _Whip(link, rig, rx)


@pytest.fixture(autouse=True)
def _stopped(whip: _Whip) -> Iterator[None]:
    """Each test ends with its stream stopped, passed or failed: a stream left running would answer the
    next test's start 399011 (one failure, not three)."""
    yield
    whip.rig.cloud.service("live_stop_push", {"video_id": GIMBAL_VIDEO})


def test_whip_streams_720p_decoded_by_the_endpoint_and_stop_deletes_the_session(whip: _Whip) -> None:
    rx, rig = whip.rx, whip.rig
    asked = time.monotonic()
    assert result(whip.start("gimbal")) == 0
    # the start's 0 came after the peer connection was up: live_status says live only then
    wait_until(lambda: (1, 0) in rig.status(GIMBAL_VIDEO), 10, what="live_status 1")
    wait_until(lambda: rx.frames >= 60, 25, what="60 decoded frames")
    session = rx.last
    assert session is not None and session.first_frame_at is not None
    print(f"\nWHIP first frame {session.first_frame_at - asked:.2f} s after the request (loaded suite)")
    assert session.sizes == {(1280, 720)} and session.codec.lower() == "video/h264", session
    # what was offered: H.264 only (the publisher sends what ffmpeg encoded, no second encode), send-only,
    # and host candidates on the namespace's address alone (no STUN server asked)
    sdp = session.offer
    assert "a=sendonly" in sdp and "H264/90000" in sdp and "VP8" not in sdp, sdp
    candidates = [line for line in sdp.splitlines() if line.startswith("a=candidate")]
    assert candidates and all(whip.link.gw_ip in c and " typ host" in c for c in candidates), candidates
    # a second start to the same endpoint: 0, the same session (no new offer); another endpoint: 399011
    posts = rx.posts
    assert result(whip.start("gimbal")) == 0 and rx.posts == posts and rx.last is session
    assert result(whip.start("elsewhere")) == 399011
    stopped = time.monotonic()
    assert result(rig.cloud.service("live_stop_push", {"video_id": GIMBAL_VIDEO})) == 0
    wait_until(lambda: session.deleted and session.ended_at is not None, 2.0, what="the session's DELETE")
    assert session.ended_at is not None and session.ended_at - stopped < 2.0
    wait_until(lambda: rig.status(GIMBAL_VIDEO)[-1] == (0, 0), 3, what="live_status 0")
    frames = session.frames
    time.sleep(0.5)
    assert rx.frames == frames  # nothing more arrives


def test_an_endpoint_that_refuses_the_offer_is_a_failed_start_with_its_status(whip: _Whip) -> None:
    rig = whip.rig
    whip.rx.status = 403
    try:
        posts = whip.rx.posts
        reply = whip.start("refused-secret-token")
        machine = rig.gw.app.live.videos[GIMBAL_VIDEO].machine
        if result(reply) == 0:  # a loaded machine: the publisher had not failed within video.start_wait
            wait_until(lambda: (0, 399015) in rig.status(GIMBAL_VIDEO), 20, what="live_status 399015")
            reason = machine.last_reason
        else:
            assert result(reply) == 399015, reply
            reason = reply["data"]["output"]["reason"]
        assert "403" in reason and "secret-token" not in reason, reason  # the path may be a credential
        assert whip.rx.posts > posts
    finally:
        whip.rx.status = 201
        assert result(rig.cloud.service("live_stop_push", {"video_id": GIMBAL_VIDEO})) == 0


def test_a_lost_peer_connection_restarts_the_publisher_and_status_shows_it(whip: _Whip) -> None:
    rx, rig = whip.rx, whip.rig
    before = len(rx.sessions)
    assert result(whip.start("drops")) == 0
    wait_until(lambda: len(rx.sessions) > before and rx.sessions[-1].frames >= 15, 25, what="frames")
    mark = len(rig.status(GIMBAL_VIDEO))
    first = rx.sessions[-1]
    rx.drop(first)  # the endpoint closes the peer connection (DTLS close_notify), no DELETE asked
    wait_until(lambda: (0, 399015) in rig.status(GIMBAL_VIDEO)[mark - 1 :], 20, what="live_status failure")
    wait_until(lambda: rx.sessions[-1] is not first and rx.sessions[-1].frames >= 15, 30,
               what="frames in a new session")  # fmt: skip
    wait_until(lambda: rig.status(GIMBAL_VIDEO)[-1] == (1, 0), 5, what="live_status recovered")
    assert result(rig.cloud.service("live_stop_push", {"video_id": GIMBAL_VIDEO})) == 0
    wait_until(lambda: rx.sessions[-1].deleted, 3, what="the new session's DELETE")


def test_a_quality_change_republishes_at_the_new_size_and_ends_the_old_session(whip: _Whip) -> None:
    """``live_set_quality`` replaces the pipeline: for WHIP a new offer (a new session at the endpoint, the
    picture at DJI's size for the quality) and the old session DELETEd, not left to time out."""
    rx, rig = whip.rx, whip.rig
    assert result(whip.start("quality")) == 0
    wait_until(lambda: rx.last is not None and rx.last.frames >= 15, 30, what="frames at quality 0")
    old = rx.last
    assert old is not None and old.sizes == {(1280, 720)}
    reply = rig.cloud.service("live_set_quality", {"video_id": GIMBAL_VIDEO, "video_quality": 1})
    assert result(reply) == 0
    wait_until(lambda: rx.last is not old and rx.last.frames >= 15, 30, what="frames at quality 1")
    assert rx.last is not None and rx.last.sizes == {(960, 540)}, rx.last
    wait_until(lambda: old.deleted and old.ended_at is not None, 5, what="the old session's DELETE")


@pytest.mark.browser
def test_chromium_as_the_endpoint_decodes_what_the_publisher_sends(whip: _Whip) -> None:
    """Fidelity: the endpoint above is aiortc, the publisher's own library; here the peer is Debian's
    Chromium (libwebrtc, as in the browsers and SFUs WHIP endpoints are built on): it must accept the
    offer (H.264 packetization-mode 1, constrained baseline), connect and decode 1280×720."""
    from tests.test_console_browser import CHROMIUM
    from tests.whip_receiver import ChromiumWhipReceiver

    if not CHROMIUM.exists():
        pytest.skip(f"{CHROMIUM} is missing: install Debian's chromium (make test does, as root)")
    pytest.importorskip("playwright", reason="playwright is not installed: pip install -e '.[dev]'")
    rig = whip.rig
    port = whip.rx.port + 1  # the namespace is this module's: nothing else listens there
    rx = ChromiumWhipReceiver(whip.link.gw_ip, port, netns=whip.link.ns, chromium=str(CHROMIUM))
    try:
        assert result(whip_start(rig, rx.url("browser"))) == 0
        wait_until(lambda: rx.frames >= 60, 30, what="60 frames decoded by Chromium")
        session = rx.last
        assert session is not None and session.sizes == {(1280, 720)}, session
        assert session.codec.startswith("video/H264") and "packetization-mode=1" in session.codec, session
        assert result(rig.cloud.service("live_stop_push", {"video_id": GIMBAL_VIDEO})) == 0
        wait_until(lambda: session.deleted, 3, what="the DELETE")
    finally:
        rx.close()
