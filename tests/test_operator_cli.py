"""The first hour of a new user (issue #22): options stand anywhere, ``send`` checks a request against the
contract before it publishes (and publishes nothing when it refuses), ``methods`` lists the contract, a
wrong ``--gateway-sn`` is answered with the serial numbers on the broker, ``schema export`` never writes
into an installed package."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import paho.mqtt.client as paho
import pytest
from paho.mqtt.enums import CallbackAPIVersion

from gateway.cli import main, source_checkout_json_dir
from gateway.contract_cli import check_request, closest
from gateway.local_broker import LocalBroker
from gateway.mqtt import close_client
from tests.support import gateway_settings, wait_until

REPO = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------------------------------ options anywhere
def test_decode_and_encode_take_their_options_anywhere(capsys: pytest.CaptureFixture[str]) -> None:
    hello = ["A5", "05", "00", "00", "F6", "00", "00", "68", "65", "6C", "6C", "6F", "56", "34"]
    assert main(["decode", "robomaster", "--season", "2026", *hello]) == 0
    after = capsys.readouterr().out
    assert main(["decode", "robomaster", *hello, "--season", "2026"]) == 0
    assert capsys.readouterr().out == after and json.loads(after)["valid"] is True
    args = ["yaw_angle=32", "roll_angle=48", "pitch_angle=64", "ctrl_byte=1", "time_for_action=20"]
    assert main(["encode", "rsdk", "position_control", "--seq", "0x1122", *args]) == 0
    assert capsys.readouterr().out.startswith("AA 1A 00 03")
    with pytest.raises(SystemExit):  # an unknown option is still an error
        main(["decode", "rsdk", "--bogus", "AA"])


# ------------------------------------------------------------------------------------------ the contract
def test_check_request_types_values_by_the_contract_and_names_every_problem() -> None:
    ok = check_request(
        "camera_aim", ["payload_index=1001-0-0", "camera_type=wide", "locked=false", "x=0.9", "y=0.5"]
    )
    assert ok.ok and ok.data == {
        "payload_index": "1001-0-0",
        "camera_type": "wide",
        "locked": False,
        "x": 0.9,
        "y": 0.5,
    }
    # a string field keeps its text: 1001 is "1001" (and then fails the pattern, which says so)
    bad = check_request("payload_authority_grab", ["payload_index=1001"])
    assert bad.data == {"payload_index": "1001"}
    assert bad.problems and bad.problems[0].startswith("data.payload_index: String should match pattern")
    # the reason in full, with the field's path
    out = check_request(
        "camera_aim", ["payload_index=1001-0-0", "camera_type=wide", "locked=false", "x=3", "y=0.5"]
    )
    assert out.problems == ("data.x: Input should be less than or equal to 1",)
    unknown = check_request("drc_mode_enter", ["mqtt_broker.adress=h:1"])
    assert unknown.problems[0].startswith(
        "unknown field mqtt_broker.adress (did you mean mqtt_broker.address?)"
    )
    assert check_request("camera_aimm", []).hint == "did you mean camera_aim?"
    assert check_request("drone_control", ["seq=1"]).hint == "add --drc"
    assert check_request("drone_control", ["seq=1", "y=2"], drc=True).ok
    assert check_request("drone_control", ["seq=1", "y=20"], drc=True).problems == (
        "data.y: Input should be less than or equal to 17",
    )
    assert closest("takeof_to_point", ["takeoff_to_point", "fly_to_point"])[0] == "takeoff_to_point"


def test_methods_lists_the_registry_and_one_methods_fields(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["methods"]) == 0
    out = capsys.readouterr().out
    for method in ("camera_aim", "takeoff_to_point", "x_rsdk_position_set", "heart_beat"):
        assert f"  {method} " in out
    assert main(["methods", "camera_aim"]) == 0
    out = capsys.readouterr().out
    (x_row,) = [ln for ln in out.splitlines() if ln.startswith("  x ")]
    assert x_row.split() == ["x", "number", "required", "0", "≤", "x", "≤", "1"]
    assert main(["methods", "drc_mode_enter"]) == 0
    assert "mqtt_broker.address" in capsys.readouterr().out
    assert main(["methods", "camera_aimm"]) == 2
    assert "did you mean camera_aim?" in capsys.readouterr().err


class Recorder:
    """A cloud-side subscriber that keeps every message on the gateway's topics."""

    def __init__(self, broker: LocalBroker, topics: list[str]) -> None:
        self.messages: list[tuple[str, bytes]] = []
        self.client = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"rec-{uuid.uuid4().hex[:8]}")
        done = threading.Event()
        self.client.on_subscribe = lambda *a: done.set()
        self.client.on_message = lambda c, u, m: self.messages.append((m.topic, bytes(m.payload)))
        self.client.connect(broker.host, broker.port)
        self.client.loop_start()
        self.client.subscribe([(t, 1) for t in topics])
        assert done.wait(5)

    def close(self) -> None:
        self.client.disconnect()
        self.client.loop_stop()
        close_client(self.client)


@pytest.mark.broker
def test_send_refuses_a_bad_request_without_publishing_it(
    broker: LocalBroker, capsys: pytest.CaptureFixture[str]
) -> None:
    gw = f"GW-CHK-{uuid.uuid4().hex[:6]}"
    rec = Recorder(broker, [f"thing/product/{gw}/#"])
    try:
        common = ["--gateway-sn", gw, "--broker", broker.url, "--timeout", "0.5"]
        assert main(["send", "camera_aimm", "payload_index=1001-0-0", *common]) == 2
        err = capsys.readouterr().err
        assert "unknown method camera_aimm" in err and "did you mean camera_aim?" in err
        aim = ["payload_index=1001-0-0", "camera_type=wide", "locked=false", "x=0.9", "y=0.5"]
        assert main(["send", "camera_aim", *aim, "foo=1", *common]) == 2
        assert "unknown field foo" in capsys.readouterr().err
        assert main(["send", "camera_aim", *aim[:-2], "x=3", "y=0.5", *common]) == 2
        assert "data.x: Input should be less than or equal to 1" in capsys.readouterr().err
        # nothing reached the broker; the same request checked and fixed is published (nobody answers: 3)
        time.sleep(0.3)  # what a refused send might have published would have arrived by now
        assert rec.messages == []
        assert main(["send", "camera_aim", *aim, *common]) == 3
        wait_until(lambda: rec.messages, 5, what="the good request on the broker")
        topic, payload = rec.messages[0]
        assert topic == f"thing/product/{gw}/services" and json.loads(payload)["data"]["x"] == 0.9
        # --no-check publishes what was typed, for trying a gateway's own validation
        assert main(["send", "camera_aimm", "x=3", "--no-check", *common]) == 3
        wait_until(lambda: len(rec.messages) == 2, 5, what="the unchecked request")
    finally:
        rec.close()


@pytest.mark.broker
def test_a_wrong_gateway_sn_is_answered_with_the_gateways_on_the_broker(
    broker: LocalBroker, capsys: pytest.CaptureFixture[str]
) -> None:
    from tests.support import GatewayThread

    settings = gateway_settings(broker.port, [], gateway_sn="GW-THERE-1", osd_period=0.2)
    with GatewayThread(settings):
        code = main(
            ["send", "flight_authority_grab", "--gateway-sn", "GW-TYPO-1", "--broker", broker.url,
             "--timeout", "1.5"]
        )  # fmt: skip
        err = capsys.readouterr().err
        assert code == 3
        assert "no reply to flight_authority_grab from GW-TYPO-1" in err
        assert "gateways seen on this broker: " in err and "GW-THERE-1" in err


# ------------------------------------------------------------------------------------------ schema export
def test_schema_export_without_a_folder_never_writes_into_an_installed_package(tmp_path: Path) -> None:
    assert source_checkout_json_dir(REPO / "schemas") == REPO / "schemas" / "json"
    site = tmp_path / "site-packages"
    for package in ("schemas", "adapters", "gateway"):
        shutil.copytree(REPO / package, site / package, ignore=shutil.ignore_patterns("__pycache__"))
    before = sorted(p.name for p in (site / "schemas" / "json").iterdir())
    stamp = (site / "schemas" / "json" / "bundle.json").stat().st_mtime_ns
    env = {**os.environ, "PYTHONPATH": str(site)}
    done = subprocess.run(
        [sys.executable, "-m", "gateway.cli", "schema", "export"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 2, done.stderr
    assert "give a folder" in done.stderr
    assert sorted(p.name for p in (site / "schemas" / "json").iterdir()) == before
    assert (site / "schemas" / "json" / "bundle.json").stat().st_mtime_ns == stamp
    out = tmp_path / "contract"
    done = subprocess.run(
        [sys.executable, "-m", "gateway.cli", "schema", "export", str(out)],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    assert (out / "bundle.json").is_file()
