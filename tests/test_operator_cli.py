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
from gateway.cli.contract import check_request, closest
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
        "camera_aim", ["payload_index=20-0-0", "camera_type=wide", "locked=false", "x=0.9", "y=0.5"]
    )
    assert ok.ok and ok.data == {
        "payload_index": "20-0-0",
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
        "camera_aim", ["payload_index=20-0-0", "camera_type=wide", "locked=false", "x=3", "y=0.5"]
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
    (y_row,) = [ln for ln in out.splitlines() if ln.startswith("  y ")]
    assert y_row.split() == ["y", "number", "required", "0", "≤", "y", "≤", "1"]  # the range names its field
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
        assert main(["send", "camera_aimm", "payload_index=20-0-0", *common]) == 2
        err = capsys.readouterr().err
        assert "unknown method camera_aimm" in err and "did you mean camera_aim?" in err
        aim = ["payload_index=20-0-0", "camera_type=wide", "locked=false", "x=0.9", "y=0.5"]
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

    def export(*args: str) -> subprocess.CompletedProcess[str]:
        argv = [sys.executable, "-m", "gateway.cli", "schema", "export", *args]
        return subprocess.run(argv, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60)

    done = export()
    assert done.returncode == 2, done.stderr
    assert "give a folder" in done.stderr
    assert sorted(p.name for p in (site / "schemas" / "json").iterdir()) == before
    assert (site / "schemas" / "json" / "bundle.json").stat().st_mtime_ns == stamp
    out = tmp_path / "contract"
    done = export(str(out))
    assert done.returncode == 0, done.stderr
    assert (out / "bundle.json").is_file()


# ------------------------------------------------------------------------------------------ environment
def test_a_bad_environment_value_names_the_variable(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("DJIGW_METRICS__PORT", "abc")
    assert main(["check-config", str(REPO / "config" / "gateway.example.toml")]) == 2
    err = capsys.readouterr().err
    assert "config error at metrics.port (from $DJIGW_METRICS__PORT): Input should be a valid integer" in err


def test_an_unknown_djigw_variable_is_warned_about(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from gateway.environment import settings_variables, unknown_variables
    from gateway.settings import GatewaySettings

    assert {"DJIGW_METRICS__PORT", "DJIGW_BROKER__PASSWORD", "DJIGW_DEVICES"} <= settings_variables(
        GatewaySettings
    )
    monkeypatch.setenv("DJIGW_LOG_LEVLE", "DEBUG")
    monkeypatch.setenv("DJIGW_CONSOLE_BROKER", "mqtt://127.0.0.1:1")  # the console's: known
    assert unknown_variables(GatewaySettings) == [("DJIGW_LOG_LEVLE", "DJIGW_LOG_LEVEL")]
    assert main(["check-config", str(REPO / "config" / "gateway.example.toml")]) == 0
    err = capsys.readouterr().err
    assert (
        "warning: environment variable DJIGW_LOG_LEVLE sets nothing (ignored); did you mean DJIGW_LOG_LEVEL?"
        in err
    )


# ------------------------------------------------------------------------------------------ help = README
def _readme_commands() -> dict[str, str]:
    """README's command-line table: sub-command → its usage cell."""
    import re

    section = (REPO / "README.md").read_text().split("## The command line", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| `dji-gateway ([a-z-]+(?: export)?)([^`]*)` \|", section, re.M)
    return {name: usage for name, usage in rows}


def test_every_command_and_option_is_in_the_readme_and_the_other_way_round() -> None:
    import argparse
    import re

    from gateway.cli import build_parser

    parser = build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    documented = _readme_commands()
    commands = {name: p for name, p in sub.choices.items() if name != "schema"}
    commands["schema export"] = next(
        a for a in sub.choices["schema"]._actions if isinstance(a, argparse._SubParsersAction)
    ).choices["export"]
    assert sorted(documented) == sorted(commands), "README's command table and the CLI differ"
    for name, p in commands.items():
        if name == "simulate":  # its options are each simulator's own (simulate rsdk --help)
            continue
        options = {o for a in p._actions for o in a.option_strings if o.startswith("--") and o != "--help"}
        in_readme = set(re.findall(r"--[a-z][a-z-]*", documented[name]))
        assert options == in_readme, (
            name,
            "only in --help:",
            options - in_readme,
            "only in README:",
            in_readme - options,
        )
    send_help = commands["send"].format_help()
    for code in ("0 on result 0", "1 on an error result", "2 when", "3 when"):
        assert code in " ".join(send_help.split()), code
    status_help = " ".join(commands["status"].format_help().split())
    assert "Exit 0 healthy, 1 unhealthy, 2 when no gateway answers" in status_help


def test_every_argument_of_every_command_has_a_help_text() -> None:
    """`--help` explains every option and positional (README's table is not the only place that does:
    issue #22 item 12 found `encode --seq` bare)."""
    import argparse

    from gateway.cli import build_parser

    bare: list[str] = []

    def walk(parser: argparse.ArgumentParser, name: str) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub_name, sub in action.choices.items():
                    walk(sub, f"{name} {sub_name}")
            elif not action.help and action.help != argparse.SUPPRESS:
                bare.append(f"{name} {'/'.join(action.option_strings) or action.dest}")

    walk(build_parser(), "dji-gateway")
    assert not bare, f"arguments without a help text: {bare}"


@pytest.mark.broker
def test_status_in_a_pipe_is_not_cut_to_80_columns(broker: LocalBroker, can_channel: str) -> None:
    from adapters.rsdk.sim import GimbalCanSim
    from tests.support import GatewayThread

    sim = GimbalCanSim(interface="virtual", channel=can_channel).start()
    device = {"type": "rsdk", "sn": "RSDK-A-VERY-LONG-SERIAL-NUMBER-0001", "interface": "virtual",
              "channel": can_channel}  # fmt: skip
    settings = gateway_settings(broker.port, [device], metrics={"enabled": True, "port": 0})
    try:
        with GatewayThread(settings) as gw:
            wait_until(lambda: gw.app.devices.by_sn(device["sn"]).online, 5, what="gimbal online")
            env = {k: v for k, v in os.environ.items() if k != "COLUMNS"}
            done = subprocess.run(
                [sys.executable, "-m", "gateway.cli", "status", "--url", f"http://127.0.0.1:{gw.app.observability.port}"],
                env=env, capture_output=True, text=True, timeout=30,
            )  # fmt: skip
    finally:
        sim.stop()
    assert done.returncode == 0, done.stderr
    (row,) = [ln for ln in done.stdout.splitlines() if device["sn"] in ln]
    assert "…" not in done.stdout and len(row) > 80
    assert "frames in/out" in done.stdout


# ------------------------------------------------------------------------------------------ make
@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
def test_make_run_installs_the_runtime_only_and_make_test_the_dev_extras(tmp_path: Path) -> None:
    def pip_lines(target: str) -> list[str]:
        # -n: print the recipes, run nothing; -B: as on a fresh clone (no stamp is up to date)
        argv = ["make", "-n", "-B", target, f"VENV={tmp_path / 'venv'}"]
        done = subprocess.run(argv, cwd=REPO, capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr
        return [ln for ln in done.stdout.splitlines() if "pip install" in ln and "--upgrade pip" not in ln]

    # the runtime and its webrtc extra (WHIP live video: aiortc), nothing of the dev extras
    assert [ln.split("pip install", 1)[1].split() for ln in pip_lines("run")] == [
        ["--quiet", "-e", "'.[webrtc]'"]
    ]
    assert any("'.[dev]'" in ln for ln in pip_lines("test"))
    assert not any("[dev]" in ln for ln in pip_lines("run"))
    assert (
        "LICENSE" in (REPO / "pyproject.toml").read_text() and "MIT License" in (REPO / "LICENSE").read_text()
    )
