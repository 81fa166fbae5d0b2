"""Config mistakes are found before anything starts: every file the config names is checked by
``check-config`` and by ``run`` (one line naming the key and the file, exit 2, never a traceback); a
broker list and a repeated ``--broker`` are read as the nodes of one cluster."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from gateway.settings import ConfigError, check_files, load_settings
from tests.certs import TestCA

ROOT = Path(__file__).resolve().parents[1]


def cli(*args: str, timeout: float = 30) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("DJIGW_")}
    return subprocess.run([sys.executable, "-m", "gateway.cli", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout, env=env)  # fmt: skip


def write(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "gw.toml"
    path.write_text('gateway_sn = "GW-CFG-1"\n' + body)
    return path


@pytest.mark.parametrize("command", ["check-config", "run"])
def test_a_missing_ca_file_is_named_before_anything_starts(tmp_path: Path, command: str) -> None:
    missing = tmp_path / "nowhere" / "ca.pem"
    config = write(tmp_path, f'[broker]\nurl = "mqtts://127.0.0.1:1"\nca_file = "{missing}"\n')
    args = (
        [command, str(config)]
        if command == "check-config"
        else [command, "--config", str(config), "--no-metrics"]
    )
    proc = cli(*args)
    assert proc.returncode == 2, proc
    assert f"config error at broker.ca_file: {missing}: not found" in proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1, proc.stderr


def test_every_tls_file_is_checked(tmp_path: Path) -> None:
    ca = TestCA(tmp_path)
    client = ca.issue("gw", client=True)
    garbage = tmp_path / "garbage.pem"
    garbage.write_text("not a certificate\n")
    files = {"ca_file": str(ca.pair.cert), "cert_file": str(client.cert), "key_file": str(client.key)}
    ok = load_settings(None, gateway_sn="G", broker={"url": "mqtts://h:8883", **files})
    assert check_files(ok) == []
    nowhere = str(tmp_path / "c.pem")
    cases = {
        "broker.ca_file: " + str(garbage) + ": not a PEM CA certificate": {"ca_file": str(garbage)},
        "broker.cert_file: " + nowhere + ": not found": {"cert_file": nowhere},
        "broker.key_file: " + str(tmp_path): {"cert_file": str(client.cert), "key_file": str(tmp_path)},
        "broker.key_file: given without broker.cert_file": {"key_file": str(client.key)},
        "broker.cert_file: " + str(client.cert) + ": certificate and key do not load": {
            "cert_file": str(client.cert), "key_file": str(ca.pair.cert)},
    }  # fmt: skip
    for expected, broker in cases.items():
        settings = load_settings(None, gateway_sn="G", broker={"url": "mqtts://h:8883", **broker})
        with pytest.raises(ConfigError) as caught:
            check_files(settings)
        assert str(caught.value).startswith(f"config error at {expected}"), (expected, str(caught.value))


def test_serial_device_paths(tmp_path: Path) -> None:
    """A path that is not a device is an error; a device not plugged in yet is a warning (it comes
    online when it appears: absent hardware is not an error)."""

    def device(url: str) -> dict[str, object]:
        return {"type": "osdk", "sn": "OSDK-CFG-1", "url": url}

    absent = load_settings(None, gateway_sn="G", devices=[device("/dev/serial/by-id/usb-none-if00")])
    assert check_files(absent) == [
        "devices[0].url: /dev/serial/by-id/usb-none-if00: not present (yet): "
        "the device comes online when it appears"
    ]
    for not_a_device in (str(tmp_path), str(write(tmp_path, ""))):
        with pytest.raises(ConfigError, match=r"config error at devices\[0\]\.url: .*: not a serial device"):
            check_files(load_settings(None, gateway_sn="G", devices=[device(not_a_device)]))
    assert (
        check_files(load_settings(None, gateway_sn="G", devices=[device("/dev/null")])) == []
    )  # a char device
    assert check_files(load_settings(None, gateway_sn="G", devices=[device("socket://127.0.0.1:1")])) == []
    config = write(tmp_path, f'[[devices]]\ntype = "osdk"\nsn = "O1"\nurl = "{tmp_path}"\n')
    proc = cli("check-config", str(config))
    assert (
        proc.returncode == 2
        and "config error at devices[0].url" in proc.stderr
        and "Traceback" not in proc.stderr
    )


def test_a_broker_list_and_a_repeated_broker_flag(tmp_path: Path) -> None:
    config = write(
        tmp_path, '[broker]\nurl = ["mqtt://n1:1883", "mqtt://n2", "mqtt://n3:2883"]\nprotocol = "3.1.1"\n'
    )
    proc = cli("check-config", str(config))
    assert proc.returncode == 0, proc.stderr
    s = load_settings(config)
    assert [(e.host, e.port) for e in s.broker.endpoints] == [("n1", 1883), ("n2", 1883), ("n3", 2883)]
    assert s.broker.is_node("n2", 1883, False) and not s.broker.is_node("n2", 1883, True)
    for bad, why in ((["mqtt://a", "mqtts://b"], "same scheme"), ([], "at least one"),
                     (["mqtt://a", "mqtt://a:1883"], "listed twice"), (["http://a"], "scheme")):  # fmt: skip
        with pytest.raises(ConfigError, match=why):
            load_settings(None, gateway_sn="G", broker={"url": bad})

    from gateway.cli import build_parser
    from gateway.cli.run import _settings_from

    ns = build_parser().parse_args(
        ["run", "--broker", "mqtt://a:1", "--broker", "mqtt://b:2", "--gateway-sn", "G"]
    )
    assert _settings_from(ns).broker.urls == ("mqtt://a:1", "mqtt://b:2")
    ns = build_parser().parse_args(["run", "--broker", "mqtt://a:1", "--gateway-sn", "G"])
    assert _settings_from(ns).broker.urls == ("mqtt://a:1",)


def test_a_stalled_link_is_given_up_before_the_drc_heartbeat_times_out() -> None:
    """A partition longer than the heartbeat timeout must end live control, never hold and resume: the
    connection is given up after at most 2/3 of drc.heartbeat_timeout, whatever stall_timeout says."""
    s = load_settings(None, gateway_sn="G", drc={"heartbeat_timeout": 1.0}, broker={"stall_timeout": 5.0})
    assert s.broker.for_live_control(s.drc.heartbeat_timeout).stall_timeout == pytest.approx(0.667)
    d = load_settings(None, gateway_sn="G")
    assert d.broker.for_live_control(d.drc.heartbeat_timeout).stall_timeout == 2.0  # the default fits


def test_device_identity_defaults_and_payload_index() -> None:
    """Issue #17: identities from DJI's enum (docs/cloud-api.md), a partial product table keeps the family's
    type, and a gimbal's payload_index is {type}-{sub_type}-{gimbal_index} of its product."""
    from adapters.osdk.config import OsdkDeviceSettings
    from adapters.robomaster.config import RobomasterDeviceSettings
    from adapters.rsdk.config import RsdkDeviceSettings
    from gateway.settings import GatewaySettings

    gimbal = RsdkDeviceSettings(sn="G1")
    assert (gimbal.product.domain, gimbal.product.type, gimbal.payload_index) == ("1", 20, "20-0-0")
    assert RsdkDeviceSettings(sn="G1", gimbal_index=2).payload_index == "20-0-2"
    partial = RsdkDeviceSettings(sn="G1", product={"domain": "1", "device_secret": "s"})
    assert (partial.product.type, partial.payload_index) == (20, "20-0-0")
    with pytest.raises(ValueError, match="is not"):
        RsdkDeviceSettings(sn="G1", payload_index="1001-0-0")
    aircraft = OsdkDeviceSettings(sn="A1", url="/dev/null").product
    robot = RobomasterDeviceSettings(sn="R1", url="/dev/null").product
    gateway = GatewaySettings(gateway_sn="GW").product
    assert [(p.domain, p.type, p.sub_type, p.announce) for p in (aircraft, robot, gateway)] == [
        ("0", 60, 0, "sub_device"),
        ("100", 1, 0, "gateway"),  # issue #38: its own gateway, in a domain no DJI device claims
        ("3", 1, 0, "sub_device"),
    ]
    # the earlier identity stays available to an integrator whose cloud must see the robot as an RC
    old = RobomasterDeviceSettings(
        sn="R1", url="/dev/null", product={"domain": "2", "type": 56, "announce": "sub_device"}
    )
    assert (old.product.domain, old.product.type, old.product.announce) == ("2", 56, "sub_device")


def test_a_carried_gimbal_names_an_aircraft_configured_here() -> None:
    """Issue #38: ``carried_by`` makes a gimbal its aircraft's payload; it must name a configured aircraft,
    and only a device (never the gateway itself) may be announced as a gateway of its own."""
    from gateway.settings import GatewaySettings

    aircraft = {"type": "osdk", "sn": "A1", "url": "/dev/null"}
    gimbal = {"type": "rsdk", "sn": "G1", "carried_by": "A1"}
    ok = GatewaySettings(gateway_sn="GW", devices=[aircraft, gimbal])
    assert ok.devices[1].carried_by == "A1"
    with pytest.raises(ValueError, match="no aircraft"):
        GatewaySettings(gateway_sn="GW", devices=[gimbal])
    with pytest.raises(ValueError, match="no aircraft"):  # a robot is no aircraft
        GatewaySettings(
            gateway_sn="GW", devices=[{"type": "robomaster", "sn": "A1", "url": "/dev/null"}, gimbal]
        )
    with pytest.raises(ValueError, match="announce"):
        GatewaySettings(gateway_sn="GW", product={"announce": "gateway"})
    with pytest.raises(ValueError, match="announce"):
        GatewaySettings(gateway_sn="GW", devices=[aircraft, {**gimbal, "product": {"announce": "gateway"}}])
    with pytest.raises(ValueError, match="serial number"):
        GatewaySettings(gateway_sn="A1", devices=[aircraft])
