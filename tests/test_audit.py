"""The audit log (issue #22 item 9): every motion and authority command leaves one JSON-friendly INFO
line on ``dji_gateway.audit`` — method, tid, source, result — through a real mosquitto and a simulated
gimbal; reads and repeated tids leave none; DRC sessions and emergency stops are audited too."""

from __future__ import annotations

import json
import logging
import uuid

import pytest

from adapters.rsdk.sim import GimbalCanSim
from gateway.audit import LOGGER_NAME, audit, audited
from gateway.local_broker import LocalBroker
from gateway.logcontext import JsonFormatter, TextFormatter, register_secret
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until

GW, SN, PI = "GW-AUDIT-1", "RSDK-AUDIT-1", "20-0-0"


def _lines(caplog: pytest.LogCaptureFixture) -> list[dict[str, object]]:
    return [json.loads(r.getMessage()) for r in caplog.records if r.name == LOGGER_NAME]


def test_an_audit_line_is_one_json_object_in_both_log_formats() -> None:
    register_secret("audit-secret-xyz")
    record = logging.LogRecord(LOGGER_NAME, logging.INFO, __file__, 1, "", (), None)
    record.msg = json.dumps({"event": "service", "method": "takeoff_to_point", "note": "audit-secret-xyz"})
    record.audit = {"event": "service", "method": "takeoff_to_point", "note": "audit-secret-xyz"}
    line = json.loads(JsonFormatter().format(record))
    assert line["logger"] == LOGGER_NAME and line["audit"]["method"] == "takeoff_to_point"
    assert "audit-secret-xyz" not in json.dumps(line)  # masked like every other line
    text = TextFormatter().format(record)
    assert json.loads(text.split(f"{LOGGER_NAME}: ", 1)[1])["event"] == "service"
    assert audited("takeoff_to_point") and audited("flight_authority_grab") and audited("camera_aim")
    assert not audited("x_rsdk_version_get") and not audited("x_osdk_mission_download")


def test_audit_leaves_out_absent_fields(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger=LOGGER_NAME)
    audit("web_action", method="x", tid=None, source="web:127.0.0.1")
    assert _lines(caplog) == [{"event": "web_action", "method": "x", "source": "web:127.0.0.1"}]


@pytest.mark.broker
def test_motion_and_authority_commands_are_audited_through_the_gateway(
    broker: LocalBroker, can_channel: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, logger=LOGGER_NAME)
    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {"type": "rsdk", "sn": SN, "interface": "virtual", "channel": can_channel, "drc_drive": True}
    settings = gateway_settings(broker.port, [device], gateway_sn=GW)
    cloud = CloudClient(broker.host, broker.port, GW)
    try:
        with GatewayThread(settings) as gw:
            wait_until(lambda: gw.app.devices.by_sn(SN).online, 5, what="gimbal online")
            grab = cloud.service("payload_authority_grab", {"payload_index": PI}, tid="grab-1")
            assert grab["data"]["result"] == 0
            aim = {"payload_index": PI, "camera_type": "wide", "locked": False, "x": 0.9, "y": 0.5}
            assert cloud.service("camera_aim", aim, tid="aim-1")["data"]["result"] == 0
            again = cloud.find("/services", lambda b: b["tid"] == "aim-1")[0]
            cloud.publish(f"thing/product/{GW}/services", again)  # a repeated tid: answered from the cache
            cloud.wait_for("services_reply", lambda b: b["tid"] == "aim-1", count=2)
            assert cloud.service("x_rsdk_version_get", {"payload_index": PI})["data"]["result"] == 0  # a read
            refused = cloud.service(
                "gimbal_reset", {"payload_index": "9-9-9", "reset_mode": 0}, tid="reset-1"
            )
            assert refused["data"]["result"] == 325001
            enter = {
                "mqtt_broker": {"address": f"127.0.0.1:{broker.port}", "client_id": uuid.uuid4().hex[:8],
                                "username": "u", "password": "p", "enable_tls": False,
                                "expire_time": 4102444800},
                "osd_frequency": 5,
                "hsi_frequency": 1,
            }  # fmt: skip
            assert cloud.service("drc_mode_enter", enter, tid="enter-1")["data"]["result"] == 0
            cloud.publish(
                f"thing/product/{GW}/drc/down", {"method": "drone_emergency_stop", "data": {}}, qos=0
            )
            wait_until(lambda: any(a["event"] == "emergency_stop" for a in _lines(caplog)), 5, what="estop")
            assert cloud.service("drc_mode_exit", {}, tid="exit-1")["data"]["result"] == 0
            wait_until(lambda: any(a["event"] == "drc_exit" for a in _lines(caplog)), 5, what="drc exit")
    finally:
        cloud.close()
        sim.stop()
    lines = _lines(caplog)
    services = [(a["method"], a["tid"], a["result"]) for a in lines if a["event"] == "service"]
    assert services == [
        ("payload_authority_grab", "grab-1", 0),
        ("camera_aim", "aim-1", 0),
        ("gimbal_reset", "reset-1", 325001),
        ("drc_mode_enter", "enter-1", 0),
        ("drc_mode_exit", "exit-1", 0),
    ]
    aim_line = next(a for a in lines if a.get("tid") == "aim-1")
    assert aim_line["source"] == "mqtt" and aim_line["device"] == SN and aim_line["bid"]
    events = [a["event"] for a in lines if a["event"] != "service"]
    assert events == ["drc_enter", "emergency_stop", "drc_exit"]
    assert "p" not in [v for a in lines for v in a.values()]  # no request values, no password
