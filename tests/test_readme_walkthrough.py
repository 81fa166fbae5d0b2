"""The README is executable: its five-minute walkthrough, extracted from README.md itself, runs here as a
new user would run it (``make run``, then ``dji-gateway monitor`` and ``dji-gateway send`` in other
terminals) and the monitor shows the simulated gimbal turn and the simulated aircraft climb. The
configuration reference, the result codes and the metric names in the README cannot drift from the code."""

from __future__ import annotations

import os
import re
import shlex
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from gateway.config_cli import BEGIN, END, reference_markdown
from gateway.local_broker import find_mosquitto, free_port, port_open
from gateway.observability import _LINK_COUNTERS, HELP
from schemas.results import ResultCode
from tests.support import wait_until

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text()


def walkthrough() -> dict[int, list[str]]:
    """The commands of the README's walkthrough block, per terminal, continuations joined."""
    block = README.split("<!-- walkthrough:begin", 1)[1].split("<!-- walkthrough:end -->", 1)[0]
    body = block.split("```sh\n", 1)[1].split("```", 1)[0]
    terminals: dict[int, list[str]] = {}
    current = 0
    for line in body.replace("\\\n", " ").splitlines():
        line = line.strip()
        if m := re.match(r"#\s*terminal (\d+)", line):
            current = int(m.group(1))
            continue
        line = re.sub(r"\s+#.*$", "", line)
        if line and not line.startswith("#"):
            terminals.setdefault(current, []).append(line)
    return terminals


def test_the_walkthrough_block_is_what_the_test_runs() -> None:
    terminals = walkthrough()
    assert terminals[1] == ["make run"]
    assert terminals[2][-1].startswith("dji-gateway monitor ")
    assert all(c.startswith(("dji-gateway send ", ". .venv/bin/activate")) for c in terminals[3])
    # `make run` is this recipe: the test runs it without make (which could reinstall the venv)
    recipe = re.search(r"^run:.*\n\t(.+)$", (REPO / "Makefile").read_text(), re.M)
    assert recipe is not None and recipe.group(1).strip() == "$(PY) -m gateway.devrun $(ARGS)"


class Terminal:
    """One shell of the walkthrough: runs README lines with the venv activated as the README says."""

    def __init__(self, env: dict[str, str]) -> None:
        self.env = env
        self.activated = False

    def argv(self, command: str) -> list[str]:
        if command == "make run":
            return [sys.executable, "-m", "gateway.devrun"]
        words = shlex.split(command)
        assert words[0] == "dji-gateway", command
        assert self.activated, "the README uses dji-gateway before activating the venv"
        return [str(Path(sys.executable).parent / "dji-gateway"), *words[1:]]

    def line(self, command: str) -> list[str] | None:
        if command == ". .venv/bin/activate":
            # what activation does for the next lines: the venv's bin first on PATH; the venv running
            # these tests is the one `make run` creates (.venv) in CI and for `make test`
            self.activated = True
            self.env = {**self.env, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{self.env['PATH']}"}
            return None
        return self.argv(command)


def _collect(proc: subprocess.Popen[str]) -> list[str]:
    lines: list[str] = []

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))

    threading.Thread(target=read, daemon=True).start()
    return lines


@pytest.mark.broker
def test_the_walkthrough_moves_the_gimbal_and_flies_the_drone() -> None:
    find_mosquitto()  # `make run` starts it
    terminals = walkthrough()
    port = free_port()
    # the port substitution: `make run` takes PORT, the console takes DJIGW_CONSOLE_BROKER; metrics on
    # any free port so a gateway already on this machine (9108) is not disturbed
    env = {k: v for k, v in os.environ.items() if not k.startswith("DJIGW_")}
    env.update(
        PORT=str(port),
        DJIGW_CONSOLE_BROKER=f"mqtt://127.0.0.1:{port}",
        DJIGW_METRICS__PORT="0",
        PYTHONUNBUFFERED="1",
    )
    procs: list[subprocess.Popen[str]] = []

    def start(argv: list[str], term_env: dict[str, str]) -> tuple[subprocess.Popen[str], list[str]]:
        # A terminal delivers Ctrl-C. A test run started in the background by a non-interactive shell
        # (`make test &`) inherits SIGINT *ignored*, and Python then installs no KeyboardInterrupt
        # handler in its children: each "terminal" starts with the default disposition, as a shell's
        # foreground job does.
        proc = subprocess.Popen(
            argv,
            cwd=REPO,
            env=term_env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
        procs.append(proc)
        return proc, _collect(proc)

    try:
        # terminal 1: make run
        t1 = Terminal(env)
        (server_argv,) = [a for c in terminals[1] if (a := t1.line(c))]
        server, server_out = start(server_argv, t1.env)
        wait_until(lambda: port_open("127.0.0.1", port), 15, what="make run's mosquitto")
        wait_until(lambda: any("running with 3 device(s)" in ln for ln in server_out), 15, what="the gateway")

        # terminal 2: the monitor (a pipe, not a terminal: one line per message)
        t2 = Terminal(env)
        (monitor_argv,) = [a for c in terminals[2] if (a := t2.line(c))]
        monitor, view = start(monitor_argv, t2.env)
        wait_until(lambda: any("monitoring gateway" in ln for ln in view), 10, what="the monitor")

        def values(sn: str, field: str) -> list[float]:
            pattern = re.compile(rf"osd    {sn} .*\b{field}=(-?[\d.]+)")
            return [float(m.group(1)) for ln in list(view) if (m := pattern.search(ln))]

        wait_until(lambda: values("RSDK-SIM-0001", "gimbal_yaw"), 10, what="the gimbal in the monitor")
        wait_until(lambda: values("OSDK-SIM-0001", "elevation"), 10, what="the aircraft in the monitor")
        assert values("RSDK-SIM-0001", "gimbal_yaw")[-1] == pytest.approx(0.0, abs=0.5)
        assert values("OSDK-SIM-0001", "elevation")[-1] == pytest.approx(0.0, abs=0.5)

        # terminal 3: the sends, one after the other, each must succeed
        t3 = Terminal(env)
        for command in terminals[3]:
            argv = t3.line(command)
            if argv is None:
                continue
            done = subprocess.run(argv, cwd=REPO, env=t3.env, capture_output=True, text=True, timeout=30)
            assert done.returncode == 0, (command, done.stdout, done.stderr)
            assert '"result": 0' in done.stdout, done.stdout

        # the monitor shows the gimbal turned to 28° and the aircraft climbing
        wait_until(
            lambda: any(abs(v - 28.0) < 0.5 for v in values("RSDK-SIM-0001", "gimbal_yaw")),
            10,
            what="gimbal_yaw 28 in the monitor",
        )
        wait_until(lambda: max(values("OSDK-SIM-0001", "elevation")) > 2.0, 15, what="the aircraft climbing")
        assert any("takeoff_to_point_progress" in ln for ln in view)

        # Ctrl-C in terminal 2 and terminal 1: both end cleanly, make run stops its mosquitto
        monitor.send_signal(signal.SIGINT)
        assert monitor.wait(10) == 0
        server.send_signal(signal.SIGINT)
        assert server.wait(20) == 0, "\n".join(server_out[-40:])
        assert not port_open("127.0.0.1", port)
        assert "Traceback" not in "\n".join(server_out + view)
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait(5)
                proc.wait(5)
            if proc.stdout:
                proc.stdout.close()


# ------------------------------------------------------------------------------------------ drift checks
def test_the_configuration_reference_matches_the_settings_models() -> None:
    section = README.split(BEGIN, 1)[1].split(END, 1)[0]
    assert section == "\n" + reference_markdown(), (
        "README's configuration reference is out of date: dji-gateway check-config --write-readme README.md"
    )


def test_every_result_code_is_in_the_readme() -> None:
    table = README.split("<!-- result-codes:", 1)[1].split("\n## ", 1)[0]
    missing = [f"{int(c)} {c.name}" for c in ResultCode if not re.search(rf"\b{int(c)}\b", table)]
    assert not missing, missing


def test_every_metric_is_in_the_readme() -> None:
    section = README.split("## Observability", 1)[1].split("\n## ", 1)[0]
    names = [f"djigw_{n}" for n in HELP] + [f"djigw_link_{n}_total" for n in _LINK_COUNTERS]
    missing = [n for n in names if f"`{n}`" not in section]
    assert not missing, missing
