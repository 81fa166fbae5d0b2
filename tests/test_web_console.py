"""The web console over HTTP and WebSocket (no browser): who may act, how actions run and are audited, what
the push carries and how fast, the frame inspector's decoding and downloads, and the settings that guard it.

A real gateway (GatewayApp on its own loop) with a simulated R SDK gimbal on a virtual CAN bus and a real
mosquitto; requests go over loopback HTTP like a browser's or a script's.
"""

from __future__ import annotations

import asyncio
import itertools
import json
import logging
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import aiohttp
import pytest
import serial

from adapters.rsdk.describe import decode_can_lines, encode_can
from adapters.rsdk.sim import GimbalCanSim
from adapters.serial_link import SerialLink
from gateway.audit import LOGGER_NAME as AUDIT_LOGGER
from gateway.local_broker import LocalBroker
from gateway.settings import ConfigError, load_settings
from gateway.web.actions import moves
from gateway.web.frames import LinkInspector
from gateway.web.journal import Journal
from tests.support import (
    GatewayThread,
    RecordingOutbox,
    drc_controller,
    gateway_settings,
    live_drc_session,
    wait_until,
)

pytestmark = pytest.mark.broker

GW = "GW-WEB-1"
SN = "RSDK-WEB-1"
TOKEN = "web-console-token-0123456789"


def request(
    port: int,
    method: str,
    path: str,
    body: Any = None,
    headers: dict[str, str] | None = None,
) -> tuple[int, Any, Any]:
    """(status, JSON body or text, response headers)."""
    data = json.dumps(body).encode() if body is not None else None
    req = urllib.request.Request(f"http://127.0.0.1:{port}{path}", data=data, method=method)
    req.add_header("Content-Type", "application/json")
    for key, value in (headers or {}).items():
        req.add_header(key, value)
    try:
        with urllib.request.urlopen(req, timeout=10) as resp:
            raw, status, got = resp.read(), resp.status, resp.headers
    except urllib.error.HTTPError as exc:
        raw, status, got = exc.read(), exc.code, exc.headers
    try:
        return status, json.loads(raw), got
    except ValueError:
        return status, raw.decode(), got


def bearer(port: int) -> dict[str, str]:
    return {"Authorization": f"Bearer {TOKEN}", "Origin": f"http://127.0.0.1:{port}"}


def start_gateway(broker: LocalBroker, can_channel: str, **console: Any) -> GatewayThread:
    settings = gateway_settings(
        broker.port,
        [
            {
                "type": "rsdk",
                "sn": SN,
                "payload_index": "20-0-0",
                "interface": "virtual",
                "channel": can_channel,
            }
        ],
        gateway_sn=GW,
        metrics={"enabled": True, "port": 0},
        console=console,
    )
    gw = GatewayThread(settings).start()
    wait_until(lambda: gw.app.devices.by_sn(SN).online, 5, what="gimbal online")
    return gw


@pytest.fixture
def rig(private_broker: LocalBroker, can_channel: str) -> Iterator[dict[str, Any]]:
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    gw = start_gateway(private_broker, can_channel, token=TOKEN)
    try:
        assert gw.app.observability is not None and gw.app.observability.port
        yield {"gw": gw, "port": gw.app.observability.port, "sim": sim}
    finally:
        gw.stop()
        sim.stop()


def audit_records(caplog: pytest.LogCaptureFixture) -> list[dict[str, Any]]:
    return [json.loads(r.getMessage()) for r in caplog.records if r.name == AUDIT_LOGGER]


def test_actions_need_the_token_and_every_refusal_is_audited(
    rig: dict[str, Any], caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger=AUDIT_LOGGER)
    port = rig["port"]
    grab = {"method": "payload_authority_grab", "data": {"payload_index": "20-0-0"}}
    own = f"http://127.0.0.1:{port}"
    # no token at all, a wrong one, a right one from another site
    assert request(port, "POST", "/api/action", grab)[0] == 401
    assert (
        request(port, "POST", "/api/action", grab, {"Authorization": "Bearer wrong-token-000000000"})[0]
        == 401
    )
    assert request(port, "POST", "/api/estop", {})[0] == 401
    status, body, _ = request(
        port, "POST", "/api/action", grab, {**bearer(port), "Origin": "http://evil.example"}
    )
    assert status == 403 and "cross-origin" in body["error"]
    # a signed-in session: the cookie alone is not enough (CSRF token, and an Origin, are required)
    status, body, headers = request(port, "POST", "/api/session", {"token": TOKEN}, {"Origin": own})
    assert status == 200 and TOKEN not in json.dumps(body)
    cookie = headers["Set-Cookie"].split(";", 1)[0]
    assert "HttpOnly" in headers["Set-Cookie"] and "SameSite=Strict" in headers["Set-Cookie"]
    csrf = body["csrf"]
    assert request(port, "POST", "/api/action", grab, {"Cookie": cookie, "Origin": own})[0] == 403
    assert request(port, "POST", "/api/action", grab, {"Cookie": cookie, "X-CSRF-Token": csrf})[0] == 403
    forged = {"Cookie": cookie, "X-CSRF-Token": "forged", "Origin": own}
    assert request(port, "POST", "/api/action", grab, forged)[0] == 403
    assert (
        request(port, "POST", "/api/session", {"token": "not-the-token-00000000"}, {"Origin": own})[0] == 401
    )

    refused = [r for r in audit_records(caplog) if r["result"] == "refused"]
    assert [r.get("status") for r in refused if r["event"] == "console_action"] == [
        401,
        401,
        403,
        403,
        403,
        403,
    ]
    assert [r["event"] for r in refused].count("console_emergency_stop") == 1
    assert [r["event"] for r in refused].count("console_sign_in") == 1
    assert all(r["method"] == "payload_authority_grab" for r in refused if r["event"] == "console_action")
    # the same session with its CSRF token from its own page: accepted, run, audited with who and result
    good = {"Cookie": cookie, "X-CSRF-Token": csrf, "Origin": own}
    status, body, _ = request(port, "POST", "/api/action", grab, good)
    assert status == 200 and body["result"] == 0
    (done,) = [r for r in audit_records(caplog) if r["event"] == "console_action" and r["result"] == 0]
    assert done["who"].startswith("session:") and done["who"].endswith("@127.0.0.1")
    assert done["method"] == "payload_authority_grab" and done["data"] == {"payload_index": "20-0-0"}
    assert rig["gw"].app.devices.authority.payloads == {"20-0-0"}
    # signed out: the cookie is worth nothing
    request(port, "DELETE", "/api/session", None, good)
    assert request(port, "POST", "/api/action", grab, good)[0] == 401
    assert TOKEN not in caplog.text


def test_moving_a_device_needs_a_confirmation_and_the_gateway_validates_again(
    rig: dict[str, Any], caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger=AUDIT_LOGGER)
    port, gw = rig["port"], rig["gw"]
    auth = bearer(port)
    assert (
        request(
            port,
            "POST",
            "/api/action",
            {"method": "payload_authority_grab", "data": {"payload_index": "20-0-0"}},
            auth,
        )[1]["result"]
        == 0
    )
    aim = {"payload_index": "20-0-0", "camera_type": "wide", "locked": False, "x": 0.9, "y": 0.5}
    status, body, _ = request(port, "POST", "/api/action", {"method": "camera_aim", "data": aim}, auth)
    assert status == 428 and "confirm" in body["error"]
    assert gw.app.devices.by_sn(SN).osd_snapshot()["gimbal_yaw"] == pytest.approx(0.0, abs=0.5)
    # out of the contract's range: the page would have said so; the gateway says it too (325001)
    status, body, _ = request(
        port, "POST", "/api/action", {"method": "camera_aim", "data": {**aim, "x": 2}, "confirm": True}, auth
    )
    assert status == 200 and body["result"] == 325001
    # a field the console does not read is refused, not ignored
    status, body, _ = request(
        port, "POST", "/api/action", {"method": "camera_aim", "data": aim, "sn": SN}, auth
    )
    assert status == 400 and "sn" in body["error"]
    # a method no device here offers
    status, body, _ = request(port, "POST", "/api/action", {"method": "takeoff_to_point", "data": {}}, auth)
    assert status == 400
    # confirmed: the gimbal turns by 0.4 of its 70° field of view
    status, body, _ = request(
        port, "POST", "/api/action", {"method": "camera_aim", "data": aim, "confirm": True}, auth
    )
    assert status == 200 and body["result"] == 0, body
    wait_until(
        lambda: abs(gw.app.devices.by_sn(SN).osd_snapshot()["gimbal_yaw"] - 28.0) < 0.5, 5, what="yaw 28"
    )
    records = audit_records(caplog)
    assert [r["status"] for r in records if r.get("result") == "refused"] == [428, 400, 400]
    console = [r for r in records if r["event"] == "console_action" and r["method"] == "camera_aim"]
    assert [r["result"] for r in console if "status" not in r] == [325001, 0]
    # the dispatcher's own audit line for the same services names the console as their source
    service = [r for r in records if r["event"] == "service" and r["method"] == "camera_aim"]
    assert [(r["source"], r["result"]) for r in service] == [("console", 0)]  # 325001: refused before
    # console actions are counted as services, never published as replies the cloud did not ask for
    metrics = gw.app.metrics.counters
    assert metrics[("services_total", (("method", "camera_aim"), ("result", "0")))] == 1
    assert moves("camera_aim") and moves("takeoff_to_point") and moves("drc_mode_enter")
    assert (
        not moves("payload_authority_grab")
        and not moves("fly_to_point_stop")
        and not moves("x_rsdk_version_get")
    )


def test_the_push_carries_the_devices_at_no_more_than_push_hz(rig: dict[str, Any]) -> None:
    port, gw = rig["port"], rig["gw"]

    async def watch(seconds: float, frames_of: str | None = None) -> list[dict[str, Any]]:
        got: list[dict[str, Any]] = []
        async with (
            aiohttp.ClientSession() as session,
            session.ws_connect(
                f"http://127.0.0.1:{port}/api/ws", headers={"Origin": f"http://127.0.0.1:{port}"}
            ) as ws,
        ):
            if frames_of:
                await ws.send_str(json.dumps({"type": "frames", "sn": frames_of}))
            end = time.monotonic() + seconds
            while (left := end - time.monotonic()) > 0:
                try:
                    msg = await ws.receive(timeout=left)
                except TimeoutError:
                    break
                if msg.type == aiohttp.WSMsgType.TEXT:
                    got.append({"at": time.monotonic(), **json.loads(msg.data)})
        return got

    messages = asyncio.run(watch(3.0, frames_of=SN))
    states = [m for m in messages if m["type"] == "state"]
    assert 10 <= len(states) <= 32, len(states)  # 10 Hz for 3 s, with slack for a busy machine
    gaps = [b["at"] - a["at"] for a, b in itertools.pairwise(states)]
    assert sum(gaps) / len(gaps) >= 0.09  # never faster than push_hz
    (device,) = states[-1]["devices"]
    assert device["sn"] == SN and device["online"] and device["link"]["kind"] == "can"
    assert device["link"]["frames_in"] > 0 and "gimbal_yaw" in device["osd"]
    assert states[-1]["gateway"]["brokers"][0]["connected"] is True
    assert states[-1]["drc"]["state"] == 0
    frames = [r for m in messages if m["type"] == "frames" for r in m["records"]]
    pushes = [r for r in frames if r["command"] == "param_push" and r["dir"] == "rx"]
    assert pushes and pushes[-1]["valid"] and "yaw_angle" in pushes[-1]["fields"]
    assert pushes[-1]["hex"].startswith("aa")

    # a page from another site may not open the push
    async def foreign() -> int:
        async with aiohttp.ClientSession() as session:
            try:
                async with session.ws_connect(
                    f"http://127.0.0.1:{port}/api/ws", headers={"Origin": "http://evil.example"}
                ):
                    return 101
            except aiohttp.WSServerHandshakeError as exc:
                return exc.status

    assert asyncio.run(foreign()) == 403
    del gw


def test_frames_download_as_candump_that_decode_reads_back(rig: dict[str, Any]) -> None:
    port = rig["port"]
    request(
        port,
        "POST",
        "/api/action",
        {"method": "x_rsdk_version_get", "data": {"payload_index": "20-0-0"}},
        bearer(port),
    )
    status, text, headers = request(port, "GET", f"/api/frames/{SN}?format=candump")
    assert status == 200 and "attachment" in headers["Content-Disposition"]
    lines = text.splitlines()
    assert lines and all(line.startswith("(") and "#" in line for line in lines)
    decoded = decode_can_lines(text)  # the CLI's own decoder reads the download back
    commands = {d["command"] for d in decoded if d["valid"]}
    assert {"param_push", "get_version"} <= commands
    status, text, _ = request(port, "GET", f"/api/frames/{SN}?format=hex&dir=tx")
    assert status == 200 and text.splitlines() and all(line.startswith("AA") for line in text.splitlines())
    assert request(port, "GET", "/api/frames/NOPE?format=hex")[0] == 404


def test_the_console_refuses_a_foreign_host_and_serves_no_secret(rig: dict[str, Any]) -> None:
    port = rig["port"]
    status, _, _ = request(port, "GET", "/", headers={"Host": "evil.example"})  # DNS rebinding
    assert status == 403
    status, page, headers = request(port, "GET", "/")
    assert status == 200 and "EMERGENCY STOP" in page and TOKEN not in page
    assert "default-src 'none'" in headers["Content-Security-Policy"]
    assert "frame-ancestors 'none'" in headers["Content-Security-Policy"]
    status, catalog, _ = request(port, "GET", "/api/catalog")
    assert status == 200 and TOKEN not in json.dumps(catalog)
    (device,) = catalog["devices"]
    methods = {m["method"]: m for m in device["methods"]}
    assert {"payload_authority_grab", "camera_aim", "gimbal_reset", "x_rsdk_position_set"} <= set(methods)
    aim = methods["camera_aim"]["schema"]
    assert aim["properties"]["x"]["maximum"] == 1 and "payload_index" in aim["required"]
    assert device["prefill"]["payload_index"] == "20-0-0"
    # the static files come from the package; the page's modules are plain ES modules
    status, js, _ = request(port, "GET", "/static/js/app.js")
    assert status == 200 and "import" in js
    assert request(port, "GET", "/static/../settings.py")[0] == 404
    # the observability endpoints are unchanged
    assert request(port, "GET", "/healthz")[0] == 200
    assert request(port, "GET", "/nothing-here")[0] == 404
    # a wayline route the gateway does not have (no task here): 404 saying so; a foreign Host: 403
    status, body, _ = request(port, "GET", "/api/wayline/route-1")
    assert status == 404 and "route-1" in body["reason"]
    assert request(port, "GET", "/api/wayline/route-1", headers={"Host": "evil.example"})[0] == 403


def test_read_only_and_tokenless_consoles(private_broker: LocalBroker, can_channel: str) -> None:
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    try:
        gw = start_gateway(private_broker, can_channel, token=TOKEN, read_only=True)
        try:
            port = gw.app.observability.port
            grab = {"method": "payload_authority_grab", "data": {"payload_index": "20-0-0"}}
            status, body, _ = request(port, "POST", "/api/action", grab, bearer(port))
            assert status == 403 and "read-only" in body["error"]
            status, body, _ = request(port, "POST", "/api/estop", {}, bearer(port))  # a stop only stops
            assert status == 200 and body["stopped"] == [SN]
        finally:
            gw.stop()
        gw = start_gateway(private_broker, can_channel)  # no token configured: nobody acts
        try:
            port = gw.app.observability.port
            status, body, _ = request(port, "POST", "/api/estop", {}, bearer(port))
            assert status == 403 and "no console.token" in body["error"]
            assert request(port, "GET", "/api/session")[1]["token_configured"] is False
        finally:
            gw.stop()
        gw = start_gateway(private_broker, can_channel, enabled=False)  # no console: metrics only
        try:
            port = gw.app.observability.port
            assert request(port, "GET", "/")[0] == 404
            assert request(port, "GET", "/api/catalog")[0] == 404
            assert request(port, "GET", "/status")[0] == 200
        finally:
            gw.stop()
    finally:
        sim.stop()


def test_the_console_guards_its_settings(tmp_path: Path) -> None:
    base = {"gateway_sn": GW}
    with pytest.raises(ConfigError, match=r"console\.token"):
        load_settings(None, **base, metrics={"host": "0.0.0.0"})
    assert (
        load_settings(None, **base, metrics={"host": "0.0.0.0"}, console={"enabled": False}).console.token
        is None
    )
    assert load_settings(None, **base, metrics={"host": "::1"}).console.token is None  # loopback: fine
    secret = tmp_path / "token"
    secret.write_text(TOKEN + "\n")
    loaded = load_settings(None, **base, metrics={"host": "0.0.0.0"}, console={"token_file": str(secret)})
    assert loaded.console.token is not None and loaded.console.token.get_secret_value() == TOKEN
    assert TOKEN not in repr(loaded) and TOKEN not in str(loaded.console)
    with pytest.raises(ConfigError, match="at least 16"):
        load_settings(None, **base, console={"token": "short"})
    with pytest.raises(ConfigError, match="push_hz"):
        load_settings(None, **base, console={"push_hz": 20})
    with pytest.raises(ConfigError, match="tile_url"):
        load_settings(None, **base, console={"tile_url": "file:///etc/passwd"})


# ------------------------------------------------------------------------------------------------ units
def test_the_inspector_keeps_memory_bounded_and_decodes_replies_by_their_command() -> None:
    inspector = LinkInspector(family="rsdk", kind="can", where="can0", keep=10)
    aim = {"yaw_angle": 280, "roll_angle": 0, "pitch_angle": 0, "ctrl_byte": 1, "time_for_action": 5}
    for seq in range(40):
        for arb, data in encode_can("position_control", seq, aim):
            inspector.tap("tx", arb, data)
    assert len(inspector.tap.records) == 10  # the tap holds its last 10 CAN frames
    frames = inspector.poll()
    assert len(inspector.frames) <= 10 and all(
        f["command"] == "position_control" for f in frames if f["valid"]
    )
    # in order again: a command, then its reply (a legacy reply has no CmdSet/CmdID: matched by seq)
    inspector = LinkInspector(family="rsdk", kind="can", where="can0", keep=100)
    for arb, data in encode_can("position_control", 0x42, aim):
        inspector.tap("tx", arb, data)
    for arb, data in encode_can("position_control", 0x42, {"return_code": 0}, reply=True, legacy=True):
        inspector.tap("rx", arb, data)
    sent, reply = inspector.poll()
    assert sent["dir"] == "tx" and reply["dir"] == "rx"
    assert reply["command"] == "position_control" and reply["fields"] == {"return_code": 0}, reply
    # records missed by a slow reader are counted and the streams restart cleanly
    inspector = LinkInspector(family="rsdk", kind="can", where="can0", keep=3)
    for arb, data in encode_can("position_control", 1, aim):
        inspector.tap("tx", arb, data)
    inspector.poll()
    for seq in (2, 3):
        for arb, data in encode_can("position_control", seq, aim):
            inspector.tap("tx", arb, data)
    inspector.poll()
    assert inspector.gaps == 2  # the tap had dropped records both times
    # a flood: the live view decodes the newest records only (the skipped ones are counted), and the
    # tail of a frame whose start was skipped is not shown as a bad frame
    inspector = LinkInspector(family="rsdk", kind="can", where="can0", keep=500)
    for seq in range(100):
        for arb, data in encode_can("position_control", seq, aim):
            inspector.tap("tx", arb, data)
    frames = inspector.poll(catch_up=10)  # 10 CAN frames: the last two whole frames and a tail
    assert inspector.skipped == 390 and [f["seq"] for f in frames] == [98, 99]
    assert all(f["valid"] for f in frames)
    sliced = LinkInspector(family="rsdk", kind="can", where="can0", keep=500)
    for arb, data in encode_can("position_control", 7, aim) * 3:
        sliced.tap("tx", arb, data)
    got = sliced.poll(limit=5)
    while sliced.behind:
        got += sliced.poll(limit=5)
    assert [f["seq"] for f in got] == [7, 7, 7]


def test_the_journal_hides_secrets_and_follows_the_fly_to_target() -> None:
    journal = Journal(keep=5)
    enter = {
        "tid": "t1",
        "bid": "b",
        "method": "drc_mode_enter",
        "data": {"mqtt_broker": {"password": "hunter2-secret", "username": "u"}},
    }
    journal.received(f"thing/product/{GW}/services", json.dumps(enter).encode())
    journal.published(f"thing/product/{SN}/osd", b'{"data": {}}')  # telemetry: not the journal's
    takeoff = {"tid": "t2", "bid": "b", "method": "takeoff_to_point", "data": {"target_latitude": 22.5}}
    journal.received(f"thing/product/{GW}/services", json.dumps(takeoff).encode())
    reply = {"tid": "t2", "bid": "b", "method": "takeoff_to_point", "data": {"result": 0}}
    journal.published(f"thing/product/{GW}/services_reply", json.dumps(reply).encode())
    progress = {
        "tid": "t3",
        "bid": "b",
        "method": "takeoff_to_point_progress",
        "data": {"status": "wayline_ok"},
    }
    journal.published(f"thing/product/{GW}/events", json.dumps(progress).encode())
    entries = journal.since(0)
    assert [e["method"] for e in entries] == [
        "drc_mode_enter",
        "takeoff_to_point",
        "takeoff_to_point",
        "takeoff_to_point_progress",
    ]
    assert "hunter2" not in json.dumps(entries) and '"password":"***"' in entries[0]["body"]
    assert journal.mission is not None and journal.mission["data"]["target_latitude"] == 22.5
    assert journal.mission["progress"] == {"status": "wayline_ok"}
    for i in range(10):
        journal.note("action", "x", n=i)
    assert len(journal.entries) == 5  # bounded


def test_a_failing_tap_never_touches_the_serial_link() -> None:
    async def scenario() -> tuple[list[bytes], list[tuple[str, bytes]]]:
        got: list[bytes] = []
        seen: list[tuple[str, bytes]] = []
        link = SerialLink(
            url="loop://",
            baudrate=115200,
            loop=asyncio.get_running_loop(),
            on_bytes=got.append,
            on_down=lambda reason: None,
        )

        def tap(direction: str, can_id: int | None, data: bytes) -> None:
            seen.append((direction, data))
            raise RuntimeError("a broken observer")

        link.observer = tap
        await link.open()
        link.write(b"\xa5hello")
        deadline = time.monotonic() + 5
        while b"".join(got) != b"\xa5hello" and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        link.close()
        return got, seen

    got, seen = asyncio.run(scenario())
    assert b"".join(got) == b"\xa5hello"
    assert ("tx", b"\xa5hello") in seen and b"".join(d for k, d in seen if k == "rx") == b"\xa5hello"
    assert serial  # pyserial's loop:// port: a real port object, no mock


def test_the_gateway_s_own_emergency_stop_holds_the_session_and_answers_nobody() -> None:
    async def scenario() -> tuple[Any, RecordingOutbox]:
        from gateway.devices import DeviceTable

        outbox = RecordingOutbox()
        drc = drc_controller(DeviceTable([]), outbox, asyncio.get_running_loop())
        live_drc_session(drc)
        drc.emergency_stop()
        await asyncio.sleep(0)
        return drc, outbox

    drc, outbox = asyncio.run(scenario())
    assert drc.snapshot()["emergency_stop"] is True and drc.failsafe[0] == "emergency_stop"
    assert not [p for p in outbox.payloads() if b"drone_emergency_stop" in p]


def test_a_long_wayline_route_is_decimated_for_the_map_and_built_once() -> None:
    """A 100,000-waypoint route: the page gets at most ROUTE_POINTS waypoints (first and last kept, each
    with its index in the route), once per task/version; the push carries only the progress."""
    from types import SimpleNamespace

    from adapters.wayline.kmz import MissionConfig, Placemark, Route, Wayline
    from gateway.wayline.task import TaskBook
    from gateway.web.state import ROUTE_POINTS, ConsoleState

    def point(i: int) -> Placemark:
        return Placemark(i, 22.5 + i * 1e-6, 113.9, 30.0, None, None, None, None, None, None, None)

    lines = tuple(
        Wayline(w, 0, 10.0, "relativeToStartPoint", tuple(point(w * 50_000 + i) for i in range(50_000)))
        for w in range(2)
    )
    config = MissionConfig("safely", "goHome", "goContinue", None, 20.0, 10.0, None)
    route = Route("wpml", config, lines)
    book = TaskBook()
    task, _ = book.prepare(SimpleNamespace(flight_id="long-1"), 0.0)
    calls: list[str] = []

    class Service:  # the two queries ConsoleState makes of gateway.wayline.service.WaylineService
        def __init__(self) -> None:
            self.book = book

        def aircraft_sn(self) -> str:
            return "OSDK-1"

        def route_of(self, flight_id: str) -> tuple[str, Route] | None:
            calls.append(flight_id)
            return ("abc", route) if flight_id == "long-1" else None

    console = ConsoleState(SimpleNamespace(wayline=Service()), frames=1, journal=1)
    view = console.route_view("long-1")
    assert view is not None and view["total"] == 100_000 and view["decimated"]
    indices = [w[0] for w in view["waypoints"]]
    assert len(indices) <= ROUTE_POINTS and indices[0] == 0 and indices[-1] == 99_999
    assert indices == sorted(indices) and view["offsets"] == {"0": 0, "1": 50_000}
    assert view["waypoints"][-1][1:] == [22.5 + 99_999 * 1e-6, 113.9, 30.0]
    assert console.route_view("long-1") is view  # built once per key
    book.execute("long-1", 1.0)
    book.planned(task, 100_000)
    book.entered(task)
    book.reached(task, 1, 9, 0)  # the 10th waypoint of the second wayline
    shown = console._wayline()
    assert shown is not None and shown["reached"] == 50_010 and shown["total"] == 100_000
    assert len(json.dumps(shown)) < 1000  # what is pushed at push_hz stays small
    assert console.route_view("other") is None


def test_the_inspector_keeps_the_gateways_own_commands_through_a_flood_of_pushes() -> None:
    """Issue #35: the frame inspector opened after the send (the README's order) still shows the
    command the gateway sent, though the device's pushes have filled the ring of all records since."""
    inspector = LinkInspector(family="rsdk", kind="can", where="can0", keep=20)
    aim = {"yaw_angle": 280, "roll_angle": 0, "pitch_angle": 0, "ctrl_byte": 1, "time_for_action": 5}
    for arb, data in encode_can("position_control", 0x42, aim):
        inspector.tap("tx", arb, data)
    for seq in range(60):  # the gimbal's pushes: far more records than the ring holds
        for arb, data in encode_can("position_control", seq, {"return_code": 0}, reply=True, legacy=True):
            inspector.tap("rx", arb, data)
    assert all(r[2] == "rx" for r in inspector.tap.records)  # the command has left the ring of all records
    frames = inspector.poll()
    sent = [f for f in frames if f["dir"] == "tx"]
    assert [(f["command"], f["seq"], f["valid"]) for f in sent] == [("position_control", 0x42, True)]
    assert any(f["dir"] == "rx" for f in frames)  # and the newest pushes after it
    assert inspector.poll() == []  # each record is decoded once


def test_live_control_from_the_page_needs_a_session_and_its_lost_websocket_zeroes_the_sticks(
    private_broker: LocalBroker, can_channel: str, caplog: pytest.LogCaptureFixture
) -> None:
    """Issue #35, the gateway side of flying from the page: a page's ``{"type": "drc"}`` message is fed to
    the live-control session only from a signed-in page with its CSRF token (else ``drc_refused``,
    audited once); its sticks drive the session as a cloud's drc/down would (the gateway numbers its seq);
    and when its WebSocket closes the set-point is zeroed at once, long before ``drc.stick_timeout``
    (5 s here) would."""
    caplog.set_level(logging.INFO, logger=AUDIT_LOGGER)
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {
        "type": "rsdk",
        "sn": SN,
        "payload_index": "20-0-0",
        "interface": "virtual",
        "channel": can_channel,
    }
    http = {"enabled": True, "port": 0}
    settings = gateway_settings(private_broker.port, [device], gateway_sn=GW, metrics=http,
                                console={"token": TOKEN}, drc={"stick_timeout": 5.0})  # fmt: skip
    gw = GatewayThread(settings).start()
    try:
        wait_until(lambda: gw.app.devices.by_sn(SN).online, 5, what="gimbal online")
        assert gw.app.observability is not None
        port = gw.app.observability.port
        origin = {"Origin": f"http://127.0.0.1:{port}"}
        _, catalog, _ = request(port, "GET", "/api/catalog")
        enter = catalog["gateway"]["prefill"]
        enter["mqtt_broker"]["password"] = "-"
        for method, data in (
            ("payload_authority_grab", {"payload_index": "20-0-0"}),
            ("drc_mode_enter", enter),
        ):
            body = {"method": method, "data": data, "confirm": True}
            status, out, _ = request(port, "POST", "/api/action", body, bearer(port))
            assert status == 200 and out["result"] == 0, (method, out)
        drc = gw.app.drc
        assert drc is not None

        async def page() -> tuple[dict[str, Any], float]:
            # unsafe: the jar keeps the session cookie of an IP address (127.0.0.1), as a browser does
            async with aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as session:
                url = f"http://127.0.0.1:{port}/api/ws"
                # not signed in: refused, never fed
                async with session.ws_connect(url, headers=origin) as ws:
                    await ws.send_str(json.dumps({"type": "drc", "csrf": "x", "method": "drone_control",
                                                  "data": {"x": 0, "y": 0.5, "h": 0, "w": 0}}))  # fmt: skip
                    refused = await _next(ws, "drc_refused")
                assert "sign in" in refused["reason"] and drc.session.snapshot(drc.now())["last_seq"] is None
                async with session.post(f"http://127.0.0.1:{port}/api/session", json={"token": TOKEN},
                                        headers=origin) as resp:  # fmt: skip
                    csrf = (await resp.json())["csrf"]
                async with session.ws_connect(url, headers=origin) as ws:
                    beat = {"timestamp": int(time.time() * 1000)}
                    await ws.send_str(
                        json.dumps({"type": "drc", "csrf": "no", "method": "heart_beat", "data": beat})
                    )
                    assert "CSRF" in (await _next(ws, "drc_refused"))["reason"]
                    for _ in range(3):
                        beat = {"timestamp": int(time.time() * 1000)}
                        await ws.send_str(
                            json.dumps({"type": "drc", "csrf": csrf, "method": "heart_beat", "data": beat})
                        )
                        stick = {"x": 0, "y": 0.5, "h": 0, "w": 0}
                        await ws.send_str(
                            json.dumps(
                                {"type": "drc", "csrf": csrf, "method": "drone_control", "data": stick}
                            )
                        )
                        await asyncio.sleep(0.1)
                    flying = drc.snapshot()
                closed = time.monotonic()
                await asyncio.to_thread(
                    wait_until, lambda: drc.snapshot()["setpoint"]["forward"] == 0.0, 2, what="zeroed"
                )
                return flying, time.monotonic() - closed

        flying, zeroed_after = asyncio.run(page())
        assert flying["setpoint"]["forward"] == 0.5 and flying["last_seq"] == 2, flying  # seq 0, 1, 2
        assert zeroed_after < 1.0  # the WebSocket's loss, not the 5 s stick timeout
        records = [r for r in audit_records(caplog) if r["event"] == "console_drc"]
        assert [r["result"] for r in records] == ["refused", "refused", "piloting"], records
        assert records[-1]["who"].startswith("session:")
    finally:
        gw.stop()
        sim.stop()


async def _next(ws: aiohttp.ClientWebSocketResponse, kind: str, timeout: float = 5.0) -> dict[str, Any]:
    """The next message of that type on a console WebSocket (the state pushes in between are skipped)."""
    end = time.monotonic() + timeout
    while (left := end - time.monotonic()) > 0:
        msg = await ws.receive(timeout=left)
        if msg.type == aiohttp.WSMsgType.TEXT and json.loads(msg.data).get("type") == kind:
            return dict(json.loads(msg.data))
    raise AssertionError(f"no {kind} message within {timeout} s")
