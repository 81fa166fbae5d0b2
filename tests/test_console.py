"""The cloud console: ``dji-gateway send`` publishes a service through a real mosquitto, matches the reply
by tid and bid and maps it to an exit code; ``dji-gateway monitor`` shows a live gateway (plain lines and
the rich view, including the DRC session) and can answer events as the cloud would."""

from __future__ import annotations

import io
import json
import re
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
from rich.console import Console

from adapters.rsdk.sim import GimbalCanSim
from gateway.cli import main
from gateway.cli.console import _FAILSAFE_TEXT, MonitorState, build_message, parse_fields, render
from gateway.local_broker import LocalBroker, free_port
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until

GW = "GW-CON-1"
SN = "RSDK-CON-1"
PI = "20-0-0"


# ------------------------------------------------------------------------------------------ pure parts
def test_field_values_are_json_when_they_parse_and_dots_nest() -> None:
    assert parse_fields(["x=0.9", "locked=false", "camera_type=wide", "payload_index=20-0-0"]) == {
        "x": 0.9,
        "locked": False,
        "camera_type": "wide",
        "payload_index": "20-0-0",
    }
    assert parse_fields(
        ["mqtt_broker.address=127.0.0.1:1883", "mqtt_broker.enable_tls=false", 'sn="123"']
    ) == {
        "mqtt_broker": {"address": "127.0.0.1:1883", "enable_tls": False},
        "sn": "123",
    }
    with pytest.raises(ValueError, match="field=value"):
        parse_fields(["oops"])
    with pytest.raises(ValueError, match="already a value"):
        parse_fields(["a=1", "a.b=2"])


def test_a_message_has_fresh_ids() -> None:
    a, b = build_message("camera_aim", {"x": 1}), build_message("camera_aim", {"x": 1})
    assert a["tid"] != b["tid"] and a["bid"] != b["bid"] and a["data"] == {"x": 1}
    assert build_message("m", {}, tid="t-7")["tid"] == "t-7"


def _feed(state: MonitorState, topic: str, body: dict[str, Any], now: float) -> list[str]:
    return state.feed(topic, json.dumps(body).encode(), now)


def test_the_monitor_state_follows_topology_osd_events_and_the_drc_session() -> None:
    st = MonitorState(GW)
    topo = {"method": "update_topo", "data": {"sub_devices": [{"sn": SN, "domain": "1"}]}}
    assert "RSDK-CON-1(domain 1)" in _feed(st, f"sys/product/{GW}/status", topo, 1.0)[0]
    (line,) = _feed(
        st, f"thing/product/{SN}/osd", {"gateway": GW, "data": {"gimbal_yaw": 28.0, "cameras": []}}, 1.1
    )
    assert line.endswith(f"osd    {SN} gimbal_yaw=28")
    assert _feed(st, "thing/product/OTHER-1/osd", {"gateway": "GW-OTHER", "data": {"x": 1}}, 1.2) == []
    # DRC: heartbeat round trip as seen on the broker, sticks, a failsafe
    _feed(
        st, f"thing/product/{GW}/drc/down", {"method": "heart_beat", "data": {"seq": 4, "timestamp": 1}}, 2.0
    )
    (hb,) = _feed(
        st, f"thing/product/{GW}/drc/up", {"method": "heart_beat", "data": {"seq": 4, "timestamp": 1}}, 2.004
    )
    assert "rtt=4.0ms" in hb and st.drc.rtt_ms == pytest.approx(4.0)
    _feed(st, f"thing/product/{GW}/drc/down", {"method": "drone_control", "data": {"seq": 9, "y": 1.5}}, 2.1)
    _feed(st, f"thing/product/{GW}/osd", {"data": {"drc_state": 2}}, 2.2)
    notify = {"method": "drc_status_notify", "need_reply": 1, "data": {"result": 514301, "drc_state": 2}}
    _feed(st, f"thing/product/{GW}/events", notify, 2.3)
    assert st.drc.failsafe is not None and st.drc.failsafe.startswith("514301")
    first = st.drc.failsafe_at
    _feed(st, f"thing/product/{GW}/events", notify, 2.6)  # the same failsafe again: first time kept
    assert st.drc.failsafe_at == first == 2.3
    # and the device going away
    _feed(st, f"sys/product/{GW}/status", {"method": "update_topo", "data": {"sub_devices": []}}, 3.0)
    assert not st.devices[SN].online

    console = Console(record=True, width=140, color_system=None)
    console.print(render(st, 3.5, "mqtt://127.0.0.1:1883"))
    view = console.export_text()
    for expected in (
        GW,
        SN,
        "offline",
        "gimbal_yaw=28",
        "2 (in live control)",
        "rtt 4.0 ms",
        "seq=9",
        "y=1.5",
        "514301 DRC link: heartbeat timed out",
        "drc_status_notify",
    ):
        assert expected in view, (expected, view)


def test_garbage_on_a_topic_is_shown_not_fatal() -> None:
    st = MonitorState(GW)
    assert "not JSON" in st.feed(f"thing/product/{GW}/events", b"\xff\x00", 0.0)[0]
    assert st.feed(f"thing/product/{GW}/events", b"[1, 2]", 0.0) == []


# ------------------------------------------------------------------------------------------ against mosquitto
@pytest.fixture
def rig(broker: LocalBroker, can_channel: str) -> Iterator[dict[str, Any]]:
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {"type": "rsdk", "sn": SN, "interface": "virtual", "channel": can_channel, "drc_drive": True}
    settings = gateway_settings(
        broker.port,
        [device],
        gateway_sn=GW,
        metrics={"enabled": False},
        dispatcher={"event_retry_interval": 0.3},
    )
    cloud = CloudClient(broker.host, broker.port, GW, answer_events=False)
    gw = GatewayThread(settings).start()
    try:
        wait_until(lambda: gw.app.devices.by_sn(SN).online, 5, what="gimbal online")
        yield {"gw": gw, "sim": sim, "cloud": cloud, "url": broker.url}
    finally:
        gw.stop()
        cloud.close()
        sim.stop()


def _send(capsys: pytest.CaptureFixture[str], url: str, *args: str) -> tuple[int, str, str]:
    code = main(["send", *args, "--gateway-sn", GW, "--broker", url])
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.broker
def test_send_prints_the_matching_reply_and_maps_the_result_to_the_exit_code(
    rig: dict[str, Any], capsys: pytest.CaptureFixture[str]
) -> None:
    url, sim, cloud = rig["url"], rig["sim"], rig["cloud"]
    code, out, _ = _send(capsys, url, "payload_authority_grab", f"payload_index={PI}")
    assert code == 0 and json.loads(out)["data"] == {"result": 0}
    # fields after an option still count; the reply carries our tid
    code, out, _ = _send(
        capsys,
        url,
        "camera_aim",
        "--tid",
        "aim-1",
        f"payload_index={PI}",
        "camera_type=wide",
        "locked=false",
        "x=0.9",
        "y=0.5",
    )
    reply = json.loads(out)
    assert code == 0 and reply["tid"] == "aim-1" and reply["method"] == "camera_aim"
    wait_until(lambda: abs(sim.model.yaw.angle - 28.0) < 0.5, 3, what="the gimbal turned to 28°")
    request = cloud.wait_for("/services", lambda b: b["tid"] == "aim-1")[0]
    assert request["bid"] == reply["bid"]
    # --data, merged with field=value; an error result exits 1 and says why on stderr
    code, out, err = _send(
        capsys,
        url,
        "camera_aim",
        "--data",
        json.dumps({"camera_type": "wide", "locked": False, "x": 0.5, "y": 0.5}),
        "payload_index=9-9-9",
    )
    assert code == 1 and json.loads(out)["data"]["result"] == 325001 and "325001" in err
    # nobody answers for this gateway: exit 3 after the timeout
    code = main(
        ["send", "camera_photo_take", f"payload_index={PI}", "--gateway-sn", "GW-NOBODY", "--broker", url,
         "--timeout", "0.3"]
    )  # fmt: skip
    assert code == 3 and "no reply" in capsys.readouterr().err
    # no broker there: exit 2
    code = main(
        ["send", "camera_photo_take", f"payload_index={PI}", "--gateway-sn", GW, "--broker",
         f"mqtt://127.0.0.1:{free_port()}"]
    )  # fmt: skip
    assert code == 2 and "cannot reach the broker" in capsys.readouterr().err
    assert main(["send", "x", "--broker", url]) == 2  # no --gateway-sn


@pytest.mark.broker
def test_send_drives_a_drc_session(rig: dict[str, Any], capsys: pytest.CaptureFixture[str]) -> None:
    url, sim = rig["url"], rig["sim"]
    assert _send(capsys, url, "payload_authority_grab", f"payload_index={PI}")[0] == 0
    host_port = url.split("://", 1)[1]
    enter = [
        f"mqtt_broker.address={host_port}",
        "mqtt_broker.client_id=drc-console",
        "mqtt_broker.username=u",
        "mqtt_broker.password=unused",
        "mqtt_broker.enable_tls=false",
        "mqtt_broker.expire_time=4102444800",
        "osd_frequency=5",
        "hsi_frequency=1",
    ]
    # before live control: a stick reaches no session, and send says so instead of exiting 0
    code, out, err = _send(capsys, url, "--drc", "stick_control", "seq=1", "yaw=1354")
    assert code == 3 and "reached no live-control session" in err and "nothing moved" in err, (code, err)
    assert _send(capsys, url, "drc_mode_enter", *enter)[0] == 0
    code, out, _ = _send(capsys, url, "--drc", "heart_beat", "seq=7", "timestamp=1700000000000")
    assert code == 0 and json.loads(out)["data"] == {"seq": 7, "timestamp": 1700000000000}
    code, out, _ = _send(capsys, url, "--drc", "drone_control", "seq=1", "w=20")
    assert code == 0 and json.loads(out)["data"] == {"result": 0, "output": {"seq": 1}}
    wait_until(lambda: sim.model.yaw.speed == 20.0, 3, what="sticks turn the gimbal")
    assert _send(capsys, url, "--drc", "drone_control", "seq=2", "w=5")[0] == 0
    code, out, _ = _send(capsys, url, "--drc", "drone_control", "seq=2", "w=6", "--timeout", "0.3")
    assert code == 3  # a repeated seq is ignored by the gateway (clouds repeat DRC messages): no answer
    # in live control on this broker: an accepted stick (not answered) is reported as reaching it
    code, out, _ = _send(capsys, url, "--drc", "stick_control", "seq=3", "yaw=1354")
    assert code == 0 and "rides this broker" in out, out
    assert _send(capsys, url, "drc_mode_exit")[0] == 0


def _spawn_monitor(url: str, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "gateway.cli", "monitor", "--gateway-sn", GW, "--broker", url, *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def _lines(proc: subprocess.Popen[str]) -> list[str]:
    lines: list[str] = []

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))

    threading.Thread(target=read, daemon=True).start()
    return lines


@pytest.mark.broker
def test_monitor_lines_show_the_gimbal_moving_and_it_answers_events(
    rig: dict[str, Any], capsys: pytest.CaptureFixture[str]
) -> None:
    url, gw, cloud = rig["url"], rig["gw"], rig["cloud"]
    proc = _spawn_monitor(url, "--duration", "30", "--reply-events")  # stdout is a pipe: plain lines
    lines = _lines(proc)
    try:
        wait_until(lambda: any("monitoring gateway" in ln for ln in lines), 10, what="monitor subscribed")
        yaw = re.compile(rf"osd    {SN} gimbal_yaw=(-?[\d.]+)")

        def yaws() -> list[float]:
            return [float(m.group(1)) for ln in list(lines) if (m := yaw.search(ln))]

        wait_until(yaws, 5, what="gimbal osd in the monitor")
        assert _send(capsys, url, "payload_authority_grab", f"payload_index={PI}")[0] == 0
        assert (
            _send(
                capsys,
                url,
                "x_rsdk_position_set",
                f"payload_index={PI}",
                "yaw=-40",
                "roll=0",
                "pitch=10",
                "duration=0.2",
            )[0]
            == 0
        )
        wait_until(lambda: any(abs(v + 40) < 0.5 for v in yaws()), 5, what="the monitor shows yaw -40")
        assert any("reply  x_rsdk_position_set result=0" in ln for ln in lines), lines

        # an event that wants a reply: the monitor answers it like a cloud, so the gateway stops re-sending
        host_port = url.split("://", 1)[1]
        enter = {
            "mqtt_broker": {
                "address": host_port,
                "client_id": "c",
                "username": "u",
                "password": "p",
                "enable_tls": False,
                "expire_time": 4102444800,
            },
            "osd_frequency": 5,
            "hsi_frequency": 1,
        }
        assert cloud.service("drc_mode_enter", enter)["data"]["result"] == 0
        notify = cloud.wait_for("/events", lambda b: b["method"] == "drc_status_notify")[0]
        cloud.wait_for("/events_reply", lambda b: b["tid"] == notify["tid"] and b["data"] == {"result": 0})
        wait_until(lambda: not gw.app.northbound._events, 3, what="the gateway saw the events_reply")
        assert any("event  drc_status_notify" in ln for ln in lines)
    finally:
        proc.terminate()
        proc.wait(5)
        if proc.stdout:
            proc.stdout.close()


@pytest.mark.broker
def test_monitor_once_draws_the_rich_view(rig: dict[str, Any]) -> None:
    url = rig["url"]
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "gateway.cli",
            "monitor",
            "--gateway-sn",
            GW,
            "--broker",
            url,
            "--once",
            "--duration",
            "2.5",
        ],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert proc.returncode == 0, proc.stderr
    for expected in ("dji-gateway monitor", SN, "gimbal_yaw=", "live control (DRC)", "drc_state"):
        assert expected in proc.stdout, proc.stdout
    # a gateway that is not there: the view says so, and the exit code is 1
    empty = subprocess.run(
        [
            sys.executable,
            "-m",
            "gateway.cli",
            "monitor",
            "--gateway-sn",
            "GW-NOBODY",
            "--broker",
            url,
            "--once",
            "--duration",
            "0.5",
        ],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert empty.returncode == 1 and "waiting for the gateway" in empty.stdout


def test_monitor_without_a_broker_fails_cleanly(capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["monitor", "--gateway-sn", GW, "--broker", f"mqtt://127.0.0.1:{free_port()}", "--plain"])
    assert code == 2 and "cannot reach the broker" in capsys.readouterr().err


def test_the_monitor_shows_the_failsafe_that_fired_and_clears_a_heartbeat_one() -> None:
    st = MonitorState(GW)
    osd = f"thing/product/{GW}/osd"
    since = int((time.time() - 2.0) * 1000)  # fired 2 s before the monitor saw it
    fired = {"data": {"drc_state": 2, "x_drc_failsafe": {"reason": "sticks", "since": since}}}
    _feed(st, osd, fired, 100.0)
    assert st.drc.failsafe is not None and st.drc.failsafe.startswith("stick timeout")
    assert st.drc.failsafe_at == pytest.approx(98.0, abs=0.5)  # its first occurrence, not the report's
    _feed(st, osd, fired, 101.0)
    assert st.drc.failsafe_at == pytest.approx(98.0, abs=0.5)
    _feed(st, osd, {"data": {"drc_state": 2, "x_drc_failsafe": {"reason": "none"}}}, 102.0)
    assert st.drc.failsafe is None
    # heartbeats lost (the event), then resumed (result 0): the monitor clears it
    events = f"thing/product/{GW}/events"
    lost = {"method": "drc_status_notify", "data": {"result": 514301, "drc_state": 2}}
    _feed(st, events, lost, 103.0)
    assert st.drc.failsafe is not None and st.drc.failsafe.startswith("514301")
    _feed(st, events, {"method": "drc_status_notify", "data": {"result": 0, "drc_state": 2}}, 104.0)
    assert st.drc.failsafe is None
    console = Console(record=True, width=140, color_system=None)
    _feed(st, osd, fired, 105.0)
    console.print(render(st, 106.0, "mqtt://127.0.0.1:1883"))
    assert "stick timeout" in console.export_text()


def test_the_monitor_shows_an_event_once_and_knows_which_still_want_an_answer() -> None:
    st = MonitorState(GW)
    event = {"tid": "e-1", "bid": "b", "method": "takeoff_to_point_progress", "need_reply": 1, "data": {}}
    assert len(_feed(st, f"thing/product/{GW}/events", event, 1.0)) == 1
    assert st.wants_answer("e-1")
    assert _feed(st, f"thing/product/{GW}/events", event, 4.0) == []  # the gateway's re-send: shown once
    assert st.resent == 1
    _feed(st, f"thing/product/{GW}/events_reply", {"tid": "e-1", "data": {"result": 0}}, 4.1)
    assert not st.wants_answer("e-1")  # another cloud answered it
    quiet = {**event, "tid": "e-2", "need_reply": 0}
    _feed(st, f"thing/product/{GW}/events", quiet, 5.0)
    assert not st.wants_answer("e-2")


def test_the_monitor_learns_the_topology_from_status_and_labels_mode_code() -> None:
    st = MonitorState(GW)
    doc = {"gateway_sn": GW, "devices": [{"sn": SN, "domain": "1", "online": True},
                                         {"sn": "OSDK-X", "domain": "0", "online": False}]}  # fmt: skip
    assert st.learn_status({**doc, "gateway_sn": "GW-OTHER"}, 1.0) == []  # another gateway's
    (line,) = st.learn_status(doc, 1.0)
    assert line.endswith(f"topo   {GW}: {SN}(domain 1) (from the gateway's /status)")
    assert st.devices[SN].online and not st.devices["OSDK-X"].online
    assert st.topology_source == "/status"
    # an update_topo on the broker is the better source from then on
    topo = {"method": "update_topo", "data": {"sub_devices": [{"sn": "OSDK-X", "domain": "0"}]}}
    _feed(st, f"thing/product/{GW}/status".replace("thing", "sys"), topo, 2.0)
    assert st.topology_source == "" and st.devices["OSDK-X"].online and not st.devices[SN].online
    (osd,) = _feed(
        st, "thing/product/OSDK-X/osd", {"gateway": GW, "data": {"mode_code": 5, "height": 80.0}}, 3.0
    )
    assert "mode_code=5(wayline)" in osd


def test_the_monitor_says_when_a_failsafe_fires_and_clears() -> None:
    st = MonitorState(GW)
    osd = {"data": {"drc_state": 2, "x_drc_failsafe": {"reason": "sticks", "since": int(time.time() * 1000)}}}
    lines = _feed(st, f"thing/product/{GW}/osd", osd, 1.0)
    assert any("FAILSAFE stick timeout" in ln for ln in lines)
    assert _feed(st, f"thing/product/{GW}/osd", osd, 1.5) == []  # the same failsafe, still holding
    cleared = _feed(
        st, f"thing/product/{GW}/osd", {"data": {"drc_state": 2, "x_drc_failsafe": {"reason": "none"}}}, 2.0
    )
    assert any("failsafe cleared" in ln for ln in cleared)
    assert [text for _, text in st.events][-2:] == [
        f"FAILSAFE {_FAILSAFE_TEXT['sticks']}",
        cleared[0].split("drc    ")[1],
    ]


def test_the_rich_view_fills_the_terminal_height_with_events() -> None:
    st = MonitorState(GW)
    for i in range(60):
        _feed(st, f"thing/product/{GW}/events", {"tid": f"t{i}", "method": f"ev_{i}", "data": {}}, float(i))

    def drawn(height: int) -> str:
        console = Console(width=120, height=height, record=True, file=io.StringIO())
        console.print(render(st, 100.0, height=height, width=120))
        return console.export_text()

    small, tall = drawn(30), drawn(60)
    assert len(small.splitlines()) <= 30 and len(tall.splitlines()) <= 60
    assert tall.count("event ev_") > small.count("event ev_") >= 3
    assert "event ev_59" in small  # the newest first


def test_the_rich_view_fits_80_by_24_with_the_drc_panel_and_the_newest_events() -> None:
    """Issue #35: the walkthrough's view (the gateway and three devices with osd, a DRC session, a
    failsafe, events) in a classic 80×24 terminal: nothing cut off below, the DRC state, the sticks and
    the newest event on screen; a taller terminal gets the full view back."""
    st = MonitorState(GW)
    devices = [("RSDK-SIM-0001", "1"), ("RM-SIM-0001", "2"), ("OSDK-SIM-0001", "0")]
    topo = {"method": "update_topo", "data": {"sub_devices": [{"sn": sn, "domain": d} for sn, d in devices]}}
    _feed(st, f"sys/product/{GW}/status", topo, 1.0)
    osd = {
        "RSDK-SIM-0001": {"gimbal_yaw": 28.0, "gimbal_pitch": -10.0, "gimbal_roll": 0.0,
                          "payload_index": "20-0-0"},
        "RM-SIM-0001": {"x_hp": 600, "x_max_hp": 600, "attitude_head": 90.0, "x_shooter_heat": 0},
        "OSDK-SIM-0001": {"latitude": 22.5431, "longitude": 113.958, "height": 80.0, "elevation": 30.0,
                          "mode_code": 5, "horizontal_speed": 9.8, "vertical_speed": 0.0,
                          "attitude_head": 1.0},
    }  # fmt: skip
    for sn, data in osd.items():
        _feed(st, f"thing/product/{sn}/osd", {"gateway": GW, "data": data}, 2.0)
    _feed(st, f"thing/product/{GW}/osd", {"data": {"drc_state": 2}}, 2.1)
    _feed(st, f"thing/product/{GW}/drc/down", {"method": "drone_control", "data": {"seq": 9, "y": 1.5}}, 2.2)
    notify = {"method": "drc_status_notify", "need_reply": 1, "data": {"result": 514301, "drc_state": 2}}
    _feed(st, f"thing/product/{GW}/events", notify, 2.3)
    for i in range(30):
        _feed(st, f"thing/product/{GW}/events", {"tid": f"t{i}", "method": f"ev_{i}", "data": {}}, 3.0 + i)

    def drawn(width: int, height: int) -> list[str]:
        console = Console(width=width, height=height, record=True, file=io.StringIO(), color_system=None)
        console.print(render(st, 40.0, "mqtt://127.0.0.1:1883", height=height, width=width))
        return console.export_text().splitlines()

    small = drawn(80, 24)
    text = "\n".join(small)
    assert len(small) <= 24 and all(len(line) <= 80 for line in small), text
    assert "DRC 2 (in live control)" in text and "514301" in text and "seq=9" in text, text
    assert "event ev_29" in text and "event ev_28" in text, text  # the newest two at least
    assert all(sn in text for sn, _ in devices), text  # four rows fit: no device is dropped at 80×24
    tall = "\n".join(drawn(120, 60))
    assert "live control (DRC)" in tall and "drc_state" in tall and "mode_code=5(wayline)" in tall
    tiny = drawn(80, 10)  # smaller still: devices are counted, never cut off mid-panel
    assert len(tiny) <= 10 and "more device(s)" in "\n".join(tiny) and "DRC 2" in "\n".join(tiny)
