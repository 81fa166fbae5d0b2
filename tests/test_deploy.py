"""Deployment files: the compose stack parses and names only commands the package has, and the same
topology runs here as plain processes (mosquitto with config/mosquitto/ and its entrypoint, the three
simulators and the gateway with config/compose/gateway.toml; service names become 127.0.0.1 and free
ports, nothing else changes). The broker's ACL keeps a gateway under its own serial numbers. The
Dockerfile, the systemd unit and the example configs are checked against the CLI and the settings."""

from __future__ import annotations

import configparser
import getpass
import json
import os
import re
import shlex
import subprocess
import sys
import threading
import tomllib
import urllib.request
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import paho.mqtt.client as paho
import pytest
import yaml
from paho.mqtt.enums import CallbackAPIVersion
from prometheus_client.parser import text_string_to_metric_families

from gateway.cli import build_parser
from gateway.cli import main as cli_main
from gateway.local_broker import find_mosquitto, free_port, port_open
from gateway.mqtt import close_client
from gateway.settings import load_settings
from tests.support import CloudClient, Proc, wait_until
from tests.support import docker_compose as docker_compose_client

REPO = Path(__file__).resolve().parents[1]
COMPOSE_FILE = REPO / "docker-compose.yml"
GATEWAY_PW, CLOUD_PW = "gw-pw-test-4b1c", "cloud-pw-test-77e2"
GW = "DJIGW-0001"


def compose() -> dict[str, Any]:
    return yaml.safe_load(COMPOSE_FILE.read_text())


def ours(services: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """The services built from this repository (the gateway and the simulators)."""
    return {name: svc for name, svc in services.items() if "build" in svc}


# ------------------------------------------------------------------------------------------ static checks
def test_the_compose_file_parses_and_wires_the_stack() -> None:
    docker_compose = docker_compose_client()
    if docker_compose is not None:  # the real parser, where the client is installed
        run = subprocess.run([*docker_compose, "-f", str(COMPOSE_FILE), "config", "-q"], capture_output=True)
        assert run.returncode == 0, run.stderr
    doc = compose()
    services = doc["services"]
    assert set(services) == {"mosquitto", "gateway", "gimbal-sim", "aircraft-sim", "robot-sim"}
    assert set(ours(services)) == {"gateway", "gimbal-sim", "aircraft-sim", "robot-sim"}
    for name, svc in services.items():
        for volume in svc.get("volumes", []):
            source = volume.split(":", 1)[0]
            if source.startswith("."):
                assert (REPO / source).exists(), f"{name} mounts a missing {source}"
            else:
                assert source in doc["volumes"], f"{name} uses an undeclared volume {source}"
        for port in svc.get("ports", []):
            assert port.startswith("127.0.0.1:"), f"{name} publishes {port} beyond this machine"
    assert all(svc["environment"]["DJIGW_SIM_HOST"] == "0.0.0.0" for n, svc in services.items() if "sim" in n)

    conf = _directives(REPO / "config/mosquitto/mosquitto.conf")
    assert conf["set_tcp_nodelay"] == ["true"] and conf["persistence"] == ["true"]
    assert conf["allow_anonymous"] == ["false"] and conf["password_file"] and conf["acl_file"]
    # the gateway's config names the simulators by service name, on the ports their commands listen on
    gateway_config = (REPO / "config/compose/gateway.toml").read_text()
    for name in ("gimbal-sim", "aircraft-sim", "robot-sim"):
        port = services[name]["command"][services[name]["command"].index("--tcp") + 1]
        assert f"socket://{name}:{port}" in gateway_config
    assert "mqtt://mosquitto:1883" in gateway_config


def _directives(path: Path) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for line in path.read_text().splitlines():
        line = line.strip()
        if line and not line.startswith("#"):
            key, _, rest = line.partition(" ")
            out.setdefault(key, []).append(rest.strip())
    return out


def test_every_command_in_the_deployment_files_exists_in_the_package() -> None:
    parser = build_parser()
    commands: list[list[str]] = [svc["command"] for svc in ours(compose()["services"]).values()]
    dockerfile = (REPO / "Dockerfile").read_text()
    entry = json.loads(re.search(r"^ENTRYPOINT (\[.*\])$", dockerfile, re.M).group(1))  # type: ignore[union-attr]
    assert entry == ["dji-gateway"]
    commands.append(json.loads(re.search(r"^CMD (\[.*\])$", dockerfile, re.M).group(1)))  # type: ignore[union-attr]
    health = re.search(r"CMD \[\"dji-gateway\", (.*)\]\s*$", dockerfile.split("HEALTHCHECK", 1)[1], re.M)
    assert health is not None
    commands.append(json.loads(f"[{health.group(1)}]"))
    unit = configparser.ConfigParser(strict=False, interpolation=None)
    unit.read(REPO / "config/systemd/dji-gateway.service")
    service = unit["Service"]
    assert service["Restart"] == "always" and service["KillSignal"] == "SIGTERM"
    for key in ("ExecStartPre", "ExecStart"):
        binary, *args = shlex.split(service[key])
        assert binary.endswith("/dji-gateway")
        commands.append(args)
    for command in commands:
        ns = parser.parse_args(command)
        assert callable(ns.handler), command
        if command[0] == "simulate":  # the family's own options, in its own process
            family_help = subprocess.run(
                [sys.executable, "-m", "gateway.cli", *command[:2], "--help"],
                capture_output=True,
                text=True,
                timeout=30,
            )
            assert family_help.returncode == 0 and "--tcp" in family_help.stdout, family_help.stderr
    # what the image copies is what the package is made of
    for source in re.findall(r"^COPY (?!--from)(\S+) ", dockerfile, re.M):
        assert (REPO / source).exists(), source


def test_example_configs_are_valid(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    paths = [REPO / "config/gateway.example.toml", *sorted((REPO / "config").glob("*/*.toml"))]
    assert {p.name for p in paths} >= {"gateway.example.toml", "gateway.toml", "hardware.toml"}
    for path in paths:
        load_settings(path)
    hardware = str(REPO / "config/examples/hardware.toml")
    # it names the deployment's CA file, which this machine does not have: check-config says so
    assert cli_main(["check-config", hardware]) == 2
    assert "config error at broker.ca_file: /etc/dji-gateway/ca.pem: not found" in capsys.readouterr().err
    from tests.certs import TestCA

    monkeypatch.setenv("DJIGW_BROKER__CA_FILE", str(TestCA(tmp_path).pair.cert))
    assert cli_main(["check-config", hardware]) == 0
    resolved = json.loads(capsys.readouterr().out)
    devices = {d["type"]: d for d in resolved["devices"]}
    assert devices["rsdk"]["interface"] == "socketcan" and devices["rsdk"]["channel"] == "can0"
    assert devices["osdk"]["url"].startswith("/dev/serial/by-id/")
    assert devices["robomaster"]["url"].startswith("/dev/serial/by-id/")


def test_check_config_masks_secrets_and_names_a_bad_field(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("DJIGW_BROKER__PASSWORD", "env-secret-123")
    cfg = tmp_path / "gw.toml"
    cfg.write_text('gateway_sn = "GW-1"\n[product]\ndevice_secret = "file-secret-456"\n')
    assert cli_main(["check-config", str(cfg)]) == 0
    out = capsys.readouterr()
    assert "env-secret-123" not in out.out + out.err and "file-secret-456" not in out.out + out.err
    doc = json.loads(out.out)
    assert doc["broker"]["password"] == "**********" and doc["product"]["device_secret"] == "**********"
    cfg.write_text('gateway_sn = "GW-1"\n[broker]\nkeepalive = 1\n')
    assert cli_main(["check-config", str(cfg)]) == 2
    assert "config error at broker.keepalive" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------ the stack, here
def _interpolate(value: str, env: dict[str, str]) -> str:
    """Compose's ${VAR:-default}, as `docker compose` would resolve it with ``env`` as the .env file."""
    return re.sub(r"\$\{(\w+):-([^}]*)\}", lambda m: env.get(m.group(1), m.group(2)), value)


@pytest.fixture
def stack(tmp_path: Path) -> Iterator[dict[str, Any]]:
    """config/mosquitto + the simulators + the gateway, as compose would start them, on loopback."""
    find_mosquitto()
    services = compose()["services"]
    dotenv = {"DJIGW_GATEWAY_PASSWORD": GATEWAY_PW, "DJIGW_CLOUD_PASSWORD": CLOUD_PW}
    ports: dict[tuple[str, int], int] = {}  # (service, container port) -> loopback port
    procs: list[Proc] = []
    base_env = {k: v for k, v in os.environ.items() if not k.startswith("DJIGW_")}
    try:
        # -- mosquitto: its entrypoint and config, with the mounts mapped to this machine's paths
        mosq = services["mosquitto"]
        mounts: dict[str, Path] = {}
        for volume in mosq["volumes"]:
            source, target = volume.split(":")[:2]
            mounts[target] = REPO / source if source.startswith(".") else tmp_path / source
            mounts[target].mkdir(parents=True, exist_ok=True)

        def host(path: str) -> str:
            for target, local in mounts.items():
                if path.startswith(target):
                    return str(local) + path[len(target) :]
            return path

        ports[("mosquitto", 1883)] = free_port()
        conf_lines = []
        for line in (REPO / "config/mosquitto/mosquitto.conf").read_text().splitlines():
            if line.startswith("listener "):
                line = f"listener {ports[('mosquitto', 1883)]} 127.0.0.1"
            conf_lines.append(re.sub(r"/mosquitto/\S+", lambda m: host(m.group(0)), line))
        conf_lines.append(f"user {getpass.getuser()}")  # as root, mosquitto would switch to its own user
        conf = tmp_path / "mosquitto.conf"
        conf.write_text("\n".join(conf_lines) + "\n")
        entry = [host(part) for part in mosq["entrypoint"]]
        env = {k: _interpolate(str(v), dotenv) for k, v in mosq["environment"].items()}
        path = os.pathsep.join([os.environ.get("PATH", ""), "/usr/sbin", "/usr/local/sbin"])
        mosq_env = {
            **base_env,
            **env,
            "PATH": path,
            "MOSQUITTO_CONF": str(conf),
            "PASSWD_FILE": host("/mosquitto/data/passwd"),
        }
        procs.append(Proc("mosquitto", entry, mosq_env))
        wait_until(lambda: port_open("127.0.0.1", ports[("mosquitto", 1883)]), 10, what="mosquitto listening")

        # -- the simulators, as their services' commands, on free loopback ports
        for name in ("gimbal-sim", "aircraft-sim", "robot-sim"):
            command = list(services[name]["command"])
            i = command.index("--tcp") + 1
            port = ports[(name, int(command[i]))] = free_port()
            command[i] = str(port)
            sim_env = {**base_env, **services[name]["environment"], "DJIGW_SIM_HOST": "127.0.0.1"}
            sim = Proc(name, [sys.executable, "-m", "gateway.cli", *command], sim_env)
            procs.append(sim)
            sim.wait_for_line(rf"socket://127\.0\.0\.1:{port}\b")

        # -- the gateway: its command and config file; service names resolve to loopback ports
        gateway = services["gateway"]
        (mounted,) = [v for v in gateway["volumes"] if v.startswith("./config/compose/")]
        source, target = mounted.split(":")[:2]
        text = (REPO / source).read_text()
        for (name, container_port), port in ports.items():
            text = text.replace(f"{name}:{container_port}", f"127.0.0.1:{port}")
        doc = tomllib.loads(text)
        addresses = [doc["broker"]["url"], *(d.get("url") or d["channel"] for d in doc["devices"])]
        assert all("://127.0.0.1:" in a for a in addresses), addresses  # every service name was mapped
        config = tmp_path / "gateway.toml"
        config.write_text(text)
        command = [str(config) if part == target else part for part in gateway["command"]]
        metrics_port = free_port()
        gw_env = {
            **base_env,
            **{k: _interpolate(str(v), dotenv) for k, v in gateway["environment"].items()},
            "DJIGW_METRICS__HOST": "127.0.0.1",
            "DJIGW_METRICS__PORT": str(metrics_port),
        }
        broker_port = ports[("mosquitto", 1883)]
        cloud = CloudClient("127.0.0.1", broker_port, GW, username="cloud", password=CLOUD_PW)
        gw = Proc("gateway", [sys.executable, "-m", "gateway.cli", *command], gw_env)
        procs.append(gw)
        yield {
            "cloud": cloud,
            "gateway": gw,
            "broker_port": broker_port,
            "metrics_port": metrics_port,
            "procs": procs,
            "data": mounts["/mosquitto/data"],
        }
        cloud.close()
    finally:
        for proc in reversed(procs):
            proc.stop()


def _login(port: int, username: str, password: str) -> tuple[paho.Client | None, str]:
    client = paho.Client(CallbackAPIVersion.VERSION2, client_id=f"probe-{uuid.uuid4().hex[:6]}")
    client.username_pw_set(username, password)
    outcome: list[str] = []
    done = threading.Event()

    def on_connect(c: paho.Client, u: Any, f: Any, reason: Any, p: Any) -> None:
        outcome.append("ok" if not reason.is_failure else str(reason))
        done.set()

    client.on_connect = on_connect
    client.connect("127.0.0.1", port)
    client.loop_start()
    assert done.wait(5), "no CONNACK"
    if outcome[0] != "ok":
        client.loop_stop()
        close_client(client)
        return None, outcome[0]
    return client, "ok"


@pytest.mark.broker
def _readme_stack_commands(
    broker_port: int, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Run the README's compose block: its exports, then each ``dji-gateway`` line; the service names
    become this stack's loopback port, as everywhere in this file (host port 1884 included)."""
    readme = (REPO / "README.md").read_text()
    block = next(b for b in readme.split("```sh\n")[1:] if "mqtt_broker.address=mosquitto:1883" in b)
    lines = block.split("```", 1)[0].replace("\\\n", " ").splitlines()
    sent = 0
    for line in (ln.strip() for ln in lines):
        line = line.replace("mosquitto:1883", f"127.0.0.1:{broker_port}").replace(":1884", f":{broker_port}")
        words = shlex.split(line)
        if words[:1] == ["export"]:
            for word in words[1:]:
                name, _, value = word.partition("=")
                monkeypatch.setenv(name, CLOUD_PW if name == "DJIGW_CONSOLE_PASSWORD" else value)
        elif words[:1] == ["dji-gateway"]:
            assert cli_main(words[1:]) == 0, (line, capsys.readouterr())
            sent += 1
    assert sent == 4
    capsys.readouterr()


def test_the_compose_topology_runs_as_plain_processes(
    stack: dict[str, Any], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    cloud: CloudClient = stack["cloud"]
    sns = {"RS-0001", "FC-0001", "RM-0001"}
    listed = {"RS-0001", "FC-0001"}  # the robot is its own gateway (docs/cloud-api.md "Device tree")
    cloud.wait_for(
        "DJIGW-0001/status", lambda b: {d["sn"] for d in b["data"]["sub_devices"]} == listed, timeout=20
    )
    cloud.wait_for(
        "RM-0001/status", lambda b: [d["sn"] for d in b["data"]["sub_devices"]] == ["RM-0001"], timeout=20
    )
    for sn in sns:
        cloud.wait_for(f"{sn}/osd", timeout=10)

    # the gimbal moves, through the SLCAN simulator in its own process
    assert cloud.service("payload_authority_grab", {"payload_index": "20-0-0"})["data"]["result"] == 0
    aim = {"payload_index": "20-0-0", "camera_type": "wide", "locked": False, "x": 0.9, "y": 0.5}
    assert cloud.service("camera_aim", aim)["data"]["result"] == 0
    cloud.wait_for("RS-0001/osd", lambda b: abs(b["data"].get("gimbal_yaw", 0) - 28.0) < 0.5, timeout=5)
    # the aircraft takes authority over its serial link; the console works with the broker's users
    monkeypatch.setenv("DJIGW_CONSOLE_PASSWORD", CLOUD_PW)
    url = f"mqtt://127.0.0.1:{stack['broker_port']}"
    assert (
        cli_main(
            ["send", "flight_authority_grab", "--gateway-sn", GW, "--broker", url, "--username", "cloud"]
        )
        == 0
    )
    assert json.loads(capsys.readouterr().out)["data"]["result"] == 0
    # the README's live-control commands for the stack, as written (the broker as the gateway reaches it)
    _readme_stack_commands(stack["broker_port"], capsys, monkeypatch)
    # and the robot obeys a control message on its serial link
    assert cloud.service("x_robomaster_stop", {"sn": "RM-0001"})["data"]["result"] == 0

    # the ACL: the gateway's user may publish under its devices' serial numbers, never under another's
    probe, outcome = _login(stack["broker_port"], GW, GATEWAY_PW)
    assert probe is not None, outcome
    try:
        probe.publish("thing/product/INTRUDER-1/osd", '{"data":{"acl":1}}', qos=1).wait_for_publish(5)
        probe.publish(f"thing/product/{GW}/services", '{"data":{"acl":1}}', qos=1).wait_for_publish(5)
        probe.publish("thing/product/RS-0001/state", '{"data":{"acl":1}}', qos=1).wait_for_publish(5)
        cloud.wait_for("RS-0001/state", lambda b: b["data"] == {"acl": 1})  # after the refused ones
        assert not cloud.find("INTRUDER-1/osd")
        assert not cloud.find(f"{GW}/services", lambda b: b["data"] == {"acl": 1})  # no forged commands
    finally:
        probe.disconnect()
        probe.loop_stop()
        close_client(probe)
    # ... and the cloud's user may send commands, never a gateway's replies or telemetry
    forger, outcome = _login(stack["broker_port"], "cloud", CLOUD_PW)
    assert forger is not None, outcome
    try:
        forger.publish(f"thing/product/{GW}/services_reply", '{"data":{"acl":2}}', qos=1).wait_for_publish(5)
        forger.publish("thing/product/RS-0001/osd", '{"data":{"acl":2}}', qos=1).wait_for_publish(5)
        forger.publish(f"thing/product/{GW}/events_reply", '{"data":{"acl":2}}', qos=1).wait_for_publish(5)
        cloud.wait_for(f"{GW}/events_reply", lambda b: b["data"] == {"acl": 2})
        assert not cloud.find(f"{GW}/services_reply", lambda b: b["data"] == {"acl": 2})
        assert not cloud.find("RS-0001/osd", lambda b: b["data"] == {"acl": 2})
    finally:
        forger.disconnect()
        forger.loop_stop()
        close_client(forger)
    assert _login(stack["broker_port"], GW, "wrong-password")[0] is None
    assert _login(stack["broker_port"], "cloud", GATEWAY_PW)[0] is None

    # the image's health check command, against the running gateway
    health = f"http://127.0.0.1:{stack['metrics_port']}"
    assert cli_main(["status", "--check", "--url", health]) == 0
    capsys.readouterr()
    # every link in the metrics: the CAN adapter over TCP and both serial ports, with traffic both ways
    with urllib.request.urlopen(f"{health}/metrics", timeout=5) as resp:
        samples = {
            (s.name, s.labels.get("device"), s.labels.get("kind")): s.value
            for family in text_string_to_metric_families(resp.read().decode())
            for s in family.samples
        }
    for device, kind in (("RS-0001", "can"), ("FC-0001", "serial"), ("RM-0001", "serial")):
        assert samples[("djigw_device_online", device, None)] == 1
        assert samples[("djigw_link_up", device, kind)] == 1
        assert samples[("djigw_link_frames_in_total", device, kind)] > 0
        assert samples[("djigw_link_frames_out_total", device, kind)] > 0

    # compose stop: SIGTERM, motion stopped, offline topology, exit 0; the broker keeps its state on disk
    cloud.clear()
    assert stack["gateway"].stop() == 0, stack["gateway"].output()[-2000:]
    assert cloud.wait_for("DJIGW-0001/status", timeout=5)[-1]["data"]["sub_devices"] == []
    assert cloud.wait_for("RM-0001/status", timeout=5)[-1]["data"]["sub_devices"] == []
    mosquitto = next(p for p in stack["procs"] if p.name == "mosquitto")
    assert mosquitto.stop() == 0
    assert (stack["data"] / "mosquitto.db").exists(), mosquitto.output()[-1000:]
    assert GATEWAY_PW not in stack["gateway"].output()
