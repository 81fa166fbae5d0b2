"""``dji-gateway fly`` (issue #22 item 13): keys → sticks (sans-I/O), then the real thing — the command in a
real pty against ``dji-gateway run --simulate`` and a real mosquitto: the aircraft, hovering after a
take-off, moves while ``w`` is held, and Esc (or the terminal losing focus, or Ctrl-C) stops it and
leaves DRC."""

from __future__ import annotations

import fcntl
import math
import os
import pty
import select
import signal
import struct
import subprocess
import sys
import termios
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest

from gateway.cli.fly import ESC_WAIT, KeyDecoder, Sticks
from gateway.local_broker import LocalBroker
from tests.support import CloudClient, wait_until

GW, AIRCRAFT = "GW-FLY-1", "OSDK-SIM-0001"


# ------------------------------------------------------------------------------------------ sans-I/O
def test_the_key_decoder_reads_letters_arrows_focus_and_a_lone_esc() -> None:
    d = KeyDecoder()
    assert d.feed(b"wA \x03", 0.0) == ["w", "a", "space", "ctrl-c"]
    assert d.feed(b"\x1b[A\x1bOD\x1b[O\x1b[I", 0.0) == ["up", "left", "focus_out", "focus_in"]
    assert d.feed(b"\x1b[1;5C", 0.0) == []  # a sequence we do not use: swallowed whole
    assert d.feed(b"\x1b", 1.0) == [] and d.flush(1.0 + ESC_WAIT / 2) == []  # maybe a sequence
    assert d.flush(1.0 + ESC_WAIT) == ["esc"]
    assert d.feed(b"\x1b[", 2.0) == [] and d.flush(3.0) == []  # an incomplete sequence is not Esc
    assert d.feed(b"B", 3.0) == ["down"]


def test_sticks_hold_while_a_key_repeats_and_lapse_after_it() -> None:
    s = Sticks(speed=2.0, climb=1.0, yaw_rate=30.0, hold=0.6)
    s.press("w", 0.0)
    s.press("q", 0.0)
    assert s.values(0.1) == {"x": 0.0, "y": 2.0, "h": 0.0, "w": -30.0}
    s.press("w", 0.5)  # auto-repeat renews it
    assert s.values(1.0)["y"] == 2.0 and s.values(1.0)["w"] == 0.0  # q lapsed
    s.press("down", 1.05)  # the opposite key takes over at once
    assert s.values(1.1)["y"] == -2.0
    s.press("d", 1.1)
    s.press("r", 1.1)
    assert s.values(1.2) == {"x": -2.0, "y": -2.0, "h": 1.0, "w": 0.0}
    s.press("space", 1.2)
    assert s.values(1.2) == {"x": 0.0, "y": 0.0, "h": 0.0, "w": 0.0}


# ------------------------------------------------------------------------------------------ a real pty
class Pty:
    """A process on a pty of its own (its controlling terminal, so Ctrl-C is a signal), read by a thread."""

    def __init__(self, argv: list[str], env: dict[str, str]) -> None:
        master, slave = pty.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 40, 140, 0, 0))

        def controlling_tty() -> None:
            signal.signal(signal.SIGINT, signal.SIG_DFL)
            os.setsid()
            fcntl.ioctl(0, termios.TIOCSCTTY, 0)

        self.proc = subprocess.Popen(
            argv, stdin=slave, stdout=slave, stderr=slave, env=env, preexec_fn=controlling_tty, close_fds=True
        )
        os.close(slave)
        self.master = master
        self.output = bytearray()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        while True:
            try:
                ready, _, _ = select.select([self.master], [], [], 0.2)
                if ready:
                    chunk = os.read(self.master, 65536)
                    if not chunk:
                        return
                    self.output += chunk
                elif self.proc.poll() is not None:
                    return
            except OSError:
                return

    def text(self) -> str:
        return self.output.decode("utf-8", "replace")

    def type(self, data: bytes) -> None:
        os.write(self.master, data)

    def hold(self, key: bytes, seconds: float, rate: float = 20.0) -> None:
        """A held key: the terminal's auto-repeat, ``rate`` times a second."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.type(key)
            time.sleep(1.0 / rate)

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(5)
        self._reader.join(2)
        os.close(self.master)


def _metres(a: dict[str, Any], b: dict[str, Any]) -> float:
    north = (b["latitude"] - a["latitude"]) * 111_320.0
    east = (b["longitude"] - a["longitude"]) * 111_320.0 * math.cos(math.radians(a["latitude"]))
    return math.hypot(north, east)


@pytest.fixture(scope="module")
def airborne(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """``dji-gateway run --simulate`` on its own mosquitto, its aircraft hovering 20 m up after a take-off
    (one flight for the module's tests: each flies it again from where the last one left it)."""
    broker = LocalBroker().start()
    config = tmp_path_factory.mktemp("fly") / "gateway.toml"
    config.write_text(f'gateway_sn = "{GW}"\nosd_period = 0.2\n[metrics]\nenabled = false\n')
    env = {k: v for k, v in os.environ.items() if not k.startswith("DJIGW_")}
    env.update(PYTHONUNBUFFERED="1", DJIGW_CONSOLE_BROKER=broker.url, TERM="xterm-256color")
    run = ["run", "--simulate", "--config", str(config), "--broker", broker.url]
    gateway = subprocess.Popen(
        [sys.executable, "-m", "gateway.cli", *run],
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    cloud = CloudClient(broker.host, broker.port, GW)
    try:
        cloud.wait_for(f"{AIRCRAFT}/osd", timeout=20)
        assert cloud.service("flight_authority_grab")["data"]["result"] == 0
        home = cloud.wait_for(f"{AIRCRAFT}/osd")[-1]["data"]
        takeoff = {
            "target_latitude": home["latitude"] + 0.0001, "target_longitude": home["longitude"],
            "target_height": home["height"] + 20, "security_takeoff_height": 20, "rth_altitude": 30,
            "max_speed": 5, "flight_id": "fly-test",
        }  # fmt: skip
        assert cloud.service("takeoff_to_point", takeoff)["data"]["result"] == 0
        cloud.wait_for("/events", lambda b: (b.get("data") or {}).get("status") == "task_finish", timeout=40)
        yield {"broker": broker, "cloud": cloud, "env": env}
    finally:
        cloud.close()
        gateway.send_signal(signal.SIGTERM)
        gateway.wait(20)
        broker.stop()


def _position(cloud: CloudClient) -> dict[str, Any]:
    cloud.clear()
    return cloud.wait_for(f"{AIRCRAFT}/osd", timeout=5)[-1]["data"]


def _has_speed(body: dict[str, Any]) -> bool:
    return "horizontal_speed" in body.get("data", {})


def _fly(env: dict[str, str]) -> Pty:
    term = Pty([sys.executable, "-m", "gateway.cli", "fly", "--gateway-sn", GW], env)
    wait_until(lambda: "in live control of" in term.text() or term.proc.poll() is not None, 20, what="fly")
    assert term.proc.poll() is None, term.text()
    return term


@pytest.mark.broker
@pytest.mark.slow
@pytest.mark.parametrize(
    ("quit_key", "why"),
    [(b"\x1b", "Esc"), (b"\x1b[O", "the terminal lost focus"), (b"\x03", "Ctrl-C")],
    ids=["esc", "focus-out", "ctrl-c"],
)
def test_fly_moves_the_aircraft_while_a_key_is_held_and_stops_it_on_quit(
    airborne: dict[str, Any], quit_key: bytes, why: str
) -> None:
    cloud = airborne["cloud"]
    term = _fly(airborne["env"])
    try:
        wait_until(lambda: "\x1b[?1004h" in term.text(), 5, what="focus reporting asked of the terminal")
        cloud.wait_for(
            "/events", lambda b: b["method"] == "drc_status_notify" and b["data"]["drc_state"] == 2
        )
        start = _position(cloud)
        term.hold(b"w", 3.0)
        sticks = cloud.find("/drc/down", lambda b: b["method"] == "drone_control")
        hearts = cloud.find("/drc/down", lambda b: b["method"] == "heart_beat")
        # a stream (10 Hz and 1 Hz for 3 s; a late tick is skipped, never made up in a burst)
        assert 10 <= len(sticks) <= 45 and 1 <= len(hearts) <= 5
        assert any(s["data"]["y"] == 2.0 for s in sticks)
        # flying while the key was held (read from the osd of the hold: on a loaded machine the next osd
        # may come after the release, when the aircraft has braked)
        speeds = [b["data"]["horizontal_speed"] for b in cloud.find(f"{AIRCRAFT}/osd", _has_speed)]
        moved = _position(cloud)
        assert _metres(start, moved) > 2.0, (start, moved)
        assert max(speeds, default=0.0) > 0.5, speeds
        # the quit key: sticks zeroed, DRC left, the command exits 0 and says why
        cloud.clear()
        term.type(quit_key)
        assert term.proc.wait(15) == 0, term.text()[-2000:]
        # the reader thread drains the pty after the exit: the last line may come a moment later
        wait_until(
            lambda: f"{why}: sticks zeroed" in term.text(), 3, what=f"{why!r} in {term.text()[-600:]!r}"
        )
        assert "\x1b[?1004l" in term.text()  # focus reporting turned off again
        cloud.wait_for(
            "/events", lambda b: b["method"] == "drc_status_notify" and b["data"]["drc_state"] == 0
        )
        wait_until(lambda: _position(cloud)["horizontal_speed"] < 0.3, 10, what="the aircraft stopped")
        here = _position(cloud)
        time.sleep(1.0)
        assert _metres(here, _position(cloud)) < 0.5  # hovering where it stopped
    finally:
        term.close()
