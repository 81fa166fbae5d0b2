"""Proof of the family registry: a fourth family defined under tests/ (tests/toy_family.py: its own frame,
adapter and simulator) is registered from outside the package and runs end to end — settings, the
topology, a service round trip to the device and back, its osd, ``--simulate``, ``decode``/``encode`` and
the frame inspector — through the real gateway and a real mosquitto, with no file under gateway/
naming it (tests/test_families.py checks that no gateway module names any family)."""

from __future__ import annotations

import gc
import io
import json
import os
import subprocess
import sys
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from adapters import families
from adapters.simio import TcpEndpoint
from gateway.cli import main as cli_main
from gateway.cli.run import simulated_settings, start_simulators
from gateway.local_broker import LocalBroker
from gateway.settings import load_settings
from gateway.web.frames import LinkInspector
from tests import toy_family
from tests.support import CloudClient, GatewayThread, gateway_settings, wait_until

SN = "VANE-T-1"
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def vane() -> Iterator[families.Family]:
    families.register(toy_family.FAMILY)
    try:
        yield toy_family.FAMILY
    finally:
        families.unregister("vane")


def _collect() -> None:
    with (
        warnings.catch_warnings()
    ):  # paho's socket pair, finalised with its client (see test_gateway_robomaster)
        warnings.simplefilter("ignore", ResourceWarning)
        gc.collect()


def _in_topology(cloud: CloudClient, sn: str) -> dict[str, Any]:
    topo = cloud.wait_for("status", lambda b: any(d["sn"] == sn for d in b["data"].get("sub_devices", [])))
    return next(d for d in topo[-1]["data"]["sub_devices"] if d["sn"] == sn)


def test_toy_family_end_to_end_through_the_gateway(broker: LocalBroker, vane: families.Family) -> None:
    sim = toy_family.VaneSim()
    endpoint = TcpEndpoint(sim)
    endpoint.start()
    settings = gateway_settings(broker.port, [{"type": "vane", "sn": SN, "url": endpoint.url}])
    assert isinstance(settings.devices[0], toy_family.VaneSettings)
    cloud = CloudClient(broker.host, broker.port, settings.gateway_sn)
    try:
        with GatewayThread(settings) as gw:
            sub = _in_topology(cloud, SN)
            wait_until(lambda: gw.app.devices.by_sn(SN).online, 5, what="the vane online")
            assert (sub["domain"], sub["type"], sub["sub_type"]) == ("2", 9901, 0)
            reply = cloud.service("x_vane_point", {"sn": SN, "heading": 123.4})
            assert reply["data"] == {"result": 0, "output": {"heading": 123.4}}, reply
            assert sim.heading_tenths == 1234 and sim.points == 1  # the device turned
            cloud.wait_for(f"{SN}/osd", lambda b: b["data"] == {"attitude_head": 123.4})
            cloud.service("x_vane_point", {"sn": SN, "heading": 270.0})
            cloud.wait_for(f"{SN}/osd", lambda b: b["data"] == {"attitude_head": -90.0})
            # the contract validates the toy's request like any other: no frame reaches the device
            bad = cloud.service("x_vane_point", {"sn": SN, "heading": 360})
            assert bad["data"]["result"] == 325001 and sim.points == 2, bad
            # the device falls silent: offline in the topology, the service answers "not connected"
            endpoint.paused = True
            wait_until(lambda: not gw.app.devices.by_sn(SN).online, 5, what="the vane offline")
            gone = cloud.service("x_vane_point", {"sn": SN, "heading": 10.0})
            assert gone["data"]["result"] == 325012, gone
    finally:
        cloud.close()
        endpoint.stop()
    _collect()


def test_toy_family_in_simulate(broker: LocalBroker, vane: families.Family) -> None:
    base = {
        "broker": {"url": f"mqtt://127.0.0.1:{broker.port}"},
        "osd_period": 0.2,
        "metrics": {"enabled": False},
    }
    doc = simulated_settings(base)
    doc["devices"] = [d for d in doc["devices"] if d["type"] == "vane"]
    assert doc["devices"] == [dict(toy_family.FAMILY.tour or {})]
    sims: list[Any] = []
    settings = start_simulators(load_settings(None, **doc), sims)
    (device,) = settings.devices
    assert device.url.startswith("socket://127.0.0.1:") and len(sims) == 1
    cloud = CloudClient(broker.host, broker.port, settings.gateway_sn)
    try:
        with GatewayThread(settings) as gw:
            wait_until(lambda: gw.app.devices.by_sn(device.sn).online, 5, what="the simulated vane online")
            reply = cloud.service("x_vane_point", {"sn": device.sn, "heading": 45.0})
            assert reply["data"]["result"] == 0, reply
            cloud.wait_for(f"{device.sn}/osd", lambda b: b["data"] == {"attitude_head": 45.0})
    finally:
        cloud.close()
        for s in sims:
            s.stop()
    _collect()


def test_toy_family_in_decode_encode_and_the_inspector(
    vane: families.Family, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli_main(["encode", "vane", "point", "--seq", "7", "heading=12.5"]) == 0
    frame = capsys.readouterr().out.split()
    assert frame == ["5A", "02", "01", "07", "7D", "00", "E1"]  # 5A+02+01+07+7D = 0xE1
    assert cli_main(["decode", "vane", *frame]) == 0
    (record,) = [json.loads(line) for line in io.StringIO(capsys.readouterr().out)]
    assert record == {
        "protocol": "vane",
        "valid": True,
        "seq": 7,
        "command": "point",
        "fields": {"heading": 12.5},
    }
    inspector = LinkInspector(family="vane", kind="serial", where="socket://x", keep=10)
    inspector.tap("rx", None, bytes.fromhex(" ".join(frame))[:3])
    inspector.tap("rx", None, bytes.fromhex(" ".join(frame))[3:])
    (seen,) = inspector.poll()
    assert seen["command"] == "point" and seen["hex"] == "5a0201077d00e1"


def test_toy_family_from_an_installed_entry_point(tmp_path: Path) -> None:
    """A distribution that declares the family in the ``dji_gateway.families`` entry-point group is found
    without any call: ``dji-gateway decode vane`` works in a fresh process."""
    dist = tmp_path / "toy_vane-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: toy-vane\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[dji_gateway.families]\nvane = tests.toy_family:FAMILY\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), str(ROOT)])}
    proc = subprocess.run(
        [sys.executable, "-m", "gateway.cli", "decode", "vane", "5A 02 01 07 7D 00 E1"],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["fields"] == {"heading": 12.5}
    plain = subprocess.run(  # without the distribution the family is unknown
        [sys.executable, "-m", "gateway.cli", "decode", "vane", "5A"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert plain.returncode == 2 and "invalid choice: 'vane'" in plain.stderr, plain.stderr
