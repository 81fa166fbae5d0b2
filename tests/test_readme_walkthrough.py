"""The README is executable: its five-minute walkthrough, extracted from README.md itself, runs here as a
new user would run it (``make run``, then ``dji-gateway monitor`` and ``dji-gateway send`` in other
terminals) and the monitor shows the simulated gimbal turn and the simulated aircraft climb. The
configuration reference, the result codes and the metric names in the README cannot drift from the code."""

from __future__ import annotations

import json
import os
import re
import shlex
import signal
import subprocess
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

import pytest

from gateway.cli.config import BEGIN, END, reference_markdown
from gateway.local_broker import find_mosquitto, free_port, port_open
from gateway.observability import _LINK_COUNTERS, HELP
from schemas.results import ResultCode
from tests.support import wait_until

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text()
COMMAND_LANGS = frozenset({"sh", "bash", "shell"})
SKIP = re.compile(r"<!--\s*readme-test:\s*skip\s*\((.+)\)\s*-->")
WAIT_FOR = "@wait-for-monitor:"  # a "# once the monitor shows X" comment: wait until the monitor shows X


@dataclass(frozen=True)
class Block:
    line: int  # 1-based line of the opening fence
    lang: str
    body: str
    skip: str | None  # the reason, when opted out

    def terminals(self) -> list[tuple[int | None, str]]:
        """(terminal, command) in order; continuations joined, comments dropped; None: no terminal named."""
        out: list[tuple[int | None, str]] = []
        current: int | None = None
        for raw in self.body.replace("\\\n", " ").splitlines():
            line = raw.strip()
            if m := re.match(r"#\s*terminal (\d+)", line):
                current = int(m.group(1))
                continue
            if m := re.match(r"#\s*once the monitor shows (\w+)", line):
                out.append((current, f"{WAIT_FOR}{m.group(1)}"))  # the reader waits for it: so does the test
                continue
            line = re.sub(r"\s+#.*$", "", line)
            if line and not line.startswith("#"):
                out.append((current, line))
        return out


def blocks(markdown: str = README) -> list[Block]:
    """Every fenced block of ``markdown`` with its label and opt-out."""
    found: list[Block] = []
    lines = markdown.splitlines()
    i = 0
    while i < len(lines):
        fence = re.match(r"^(```+)(\S*)\s*$", lines[i])
        if fence is None:
            i += 1
            continue
        end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith(fence.group(1)))
        skip = SKIP.search(lines[i - 1]) if i else None
        found.append(
            Block(i + 1, fence.group(2), "\n".join(lines[i + 1 : end]) + "\n", skip and skip.group(1))
        )
        i = end + 1
    return found


def command_blocks() -> list[Block]:
    return [b for b in blocks() if b.lang in COMMAND_LANGS]


def test_every_fence_is_labelled_and_every_opt_out_says_why() -> None:
    fences = blocks()
    unlabelled = [b.line for b in fences if not b.lang]
    assert not unlabelled, (
        f"README fences without a label at lines {unlabelled}: sh (run here) or text/toml/…"
    )
    assert all(b.skip is None or b.skip.strip() for b in fences)
    marks = README.count("readme-test:")
    documented = README.count("`<!-- readme-test: skip (why) -->`")  # the README explains the marker once
    assert marks - documented == sum(1 for b in fences if b.skip), "a readme-test marker not before a fence"
    # the walkthrough is there and what the rest of this file expects of it
    runs = [b for b in command_blocks() if b.skip is None]
    walk = next(b for b in runs if any(t == 1 for t, _ in b.terminals()))
    cmds = walk.terminals()
    assert cmds[0] == (1, "make run")
    assert any(t == 2 and c.startswith("dji-gateway monitor ") for t, c in cmds)
    # `make run` is this recipe: the test runs it without make (which could reinstall the venv)
    recipe = re.search(r"^run:.*\n\t(.+)$", (REPO / "Makefile").read_text(), re.M)
    assert recipe is not None and recipe.group(1).strip() == "$(PY) -m gateway.cli.devrun $(ARGS)"


def test_the_block_parser_finds_labels_terminals_and_opt_outs() -> None:
    text = (
        "x\n```sh\n# terminal 1: a\nmake run\n# terminal 2\nls -l \\\n  /tmp   # list\n```\n"
        "<!-- readme-test: skip (needs can0) -->\n```sh\ncandump can0\n```\n```toml\na = 1\n```\n"
    )
    a, b, c = blocks(text)
    assert (a.line, a.lang, a.skip) == (2, "sh", None)
    assert a.terminals() == [(1, "make run"), (2, "ls -l    /tmp")]
    assert (b.skip, b.terminals()) == ("needs can0", [(None, "candump can0")])
    assert c.lang == "toml"


def _is_service(command: str) -> bool:
    words = shlex.split(command)
    if words[:2] == ["make", "run"] or words[:2] == ["dji-gateway", "run"]:
        return True
    return words[:2] == ["dji-gateway", "monitor"] and not {"--once", "--duration"} & set(words)


#: what a service prints once it is ready for the next command
READY = {"make run": "running with 3 device(s)", "dji-gateway monitor": "monitoring gateway"}


class Terminal:
    """One shell of the reader: runs README lines with bash, with what earlier lines set up."""

    def __init__(self, env: dict[str, str], port: int) -> None:
        self.env = env
        self.port = port
        self.setup: list[str] = []

    def script(self, command: str) -> str:
        if command == "make run":  # the Makefile's recipe (checked above), without make
            command = f"exec {shlex.quote(sys.executable)} -m gateway.cli.devrun"
        elif _is_service(command):
            command = "exec " + command
        command = command.replace("127.0.0.1:1883", f"127.0.0.1:{self.port}")
        return "\n".join(["set -eo pipefail", *self.setup, command])

    def take(self, command: str) -> bool:
        """Keep a line that sets the shell up (True), or say it is a command to run (False)."""
        if command == ". .venv/bin/activate":
            venv = Path(sys.executable).parent.parent
            if venv != REPO / ".venv":  # tests run from another venv: what activation does, for that one
                command = (
                    f"export VIRTUAL_ENV={shlex.quote(str(venv))} PATH={shlex.quote(str(venv / 'bin'))}:$PATH"
                )
            self.setup.append(command)
            return True
        if command.split()[0] in ("export", "cd", "source", "."):
            self.setup.append(command)
            return True
        return False


def _collect(proc: subprocess.Popen[str]) -> list[str]:
    lines: list[str] = []

    def read() -> None:
        assert proc.stdout is not None
        for line in proc.stdout:
            lines.append(line.rstrip("\n"))

    threading.Thread(target=read, daemon=True).start()
    return lines


@pytest.mark.broker
@pytest.mark.slow
@pytest.mark.timeout(240)  # some 40 fresh processes in a row: 45-60 s alone, twice that beside the suite
def test_every_readme_command_block_runs_as_a_reader_would() -> None:
    find_mosquitto()  # `make run` starts it
    port, metrics_port = free_port(), free_port()
    # the port substitution: `make run` takes PORT, the console DJIGW_CONSOLE_BROKER; metrics on a free port
    # (a gateway already on this machine keeps 9108), which the monitor and `status` find in the same variable
    env = {k: v for k, v in os.environ.items() if not k.startswith("DJIGW_")}
    env.update(
        PORT=str(port),
        DJIGW_CONSOLE_BROKER=f"mqtt://127.0.0.1:{port}",
        DJIGW_METRICS__PORT=str(metrics_port),
        # every README line is a fresh Python process; on a loaded machine (the suite runs in parallel) a
        # `dji-gateway send` can take longer to start than the 3 s by which a pasted stick must follow
        # its heartbeat (README: "paste the block"). The walkthrough checks the commands, not that
        # window: the heartbeat failsafe has its own tests (tests/test_drc*.py, with a clock)
        DJIGW_DRC__HEARTBEAT_TIMEOUT="30",
        PYTHONUNBUFFERED="1",
    )
    services: dict[str, tuple[subprocess.Popen[str], list[str]]] = {}
    terminals: dict[int | None, Terminal] = {}
    ran: list[tuple[str, subprocess.CompletedProcess[str]]] = []

    def start(name: str, script: str) -> None:
        # A terminal delivers Ctrl-C. A test run started in the background by a non-interactive shell
        # (`make test &`) inherits SIGINT *ignored*, and Python then installs no KeyboardInterrupt
        # handler in its children: each "terminal" starts with the default disposition, as a shell's
        # foreground job does.
        proc = subprocess.Popen(
            ["bash", "-c", script],
            cwd=REPO,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
        services[name] = (proc, _collect(proc))
        ready = next((text for prefix, text in READY.items() if name.startswith(prefix)), None)
        if ready is not None:
            out = services[name][1]
            wait_until(lambda: any(ready in ln for ln in out), 20, what=f"{name!r} ready")

    try:
        last: int | None = None
        for block in command_blocks():
            if block.skip is not None:
                continue
            for term, command in block.terminals():
                if command.startswith(WAIT_FOR):
                    _wait_for_monitor(services, command.removeprefix(WAIT_FOR))
                    continue
                term = last if term is None else term
                last = term
                shell = terminals.setdefault(term, Terminal(env, port))
                if shell.take(command):
                    continue
                if _is_service(command):
                    start(command, shell.script(command))
                    continue
                done = subprocess.run(
                    ["bash", "-c", shell.script(command)], cwd=REPO, env=env, capture_output=True, text=True,
                    timeout=60,
                )  # fmt: skip
                assert done.returncode == 0, (
                    f"README line {block.line}: {command}",
                    done.stdout,
                    done.stderr,
                )
                ran.append((command, done))

        server_out = services["make run"][1]
        (view,) = [out for name, (_, out) in services.items() if name.startswith("dji-gateway monitor")]
        _check_what_the_reader_saw(ran, view, server_out)
        # the walkthrough is clean by default: the monitor answered every event before the gateway re-sent it
        from gateway.cli.status import fetch

        counters = fetch(f"http://127.0.0.1:{metrics_port}", "/status")[1]["counters"]
        assert counters.get("events_published_total", 0) >= 3, counters
        assert counters.get("events_resent_total", 0) == 0, counters

        # Ctrl-C in the monitor's terminal and in make run's: both end cleanly, make run stops its mosquitto
        for name, (proc, out) in reversed(list(services.items())):
            proc.send_signal(signal.SIGINT)
            assert proc.wait(20) == 0, (name, "\n".join(out[-40:]))
        assert not port_open("127.0.0.1", port)
        everything = "\n".join(server_out + view)
        assert "Traceback" not in everything
        # the walkthrough is clean by default: the monitor answered the events, none was re-sent or lost
        assert "was never answered" not in everything
    finally:
        # after a failure too: Ctrl-C first, so `make run` stops the mosquitto it started (a SIGKILL left it
        # running, one orphaned broker per failed run), then kill what is still there
        for proc, _ in reversed(list(services.values())):
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(15)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(5)
            if proc.stdout:
                proc.stdout.close()


def _wait_for_monitor(services: dict[str, tuple[subprocess.Popen[str], list[str]]], text: str) -> None:
    """What a reader does at "# once the monitor shows X": watch the monitor's terminal until X is there."""
    (shown,) = [out for name, (_, out) in services.items() if name.startswith("dji-gateway monitor")]
    wait_until(lambda: any(text in ln for ln in shown), 60, what=f"{text} in the monitor")


def _wait_for_monitor(services: dict[str, tuple[subprocess.Popen[str], list[str]]], text: str) -> None:
    """What a reader does at "# once the monitor shows X": watch the monitor's terminal until X is there."""
    (shown,) = [out for name, (_, out) in services.items() if name.startswith("dji-gateway monitor")]
    wait_until(lambda: any(text in ln for ln in shown), 60, what=f"{text} in the monitor")


def _check_what_the_reader_saw(
    ran: list[tuple[str, subprocess.CompletedProcess[str]]], view: list[str], server_out: list[str]
) -> None:
    """What the README promises a reader sees, beyond every command exiting 0."""

    def values(sn: str, field: str) -> list[float]:
        pattern = re.compile(rf"osd    {sn} .*\b{field}=(-?[\d.]+)")
        return [float(m.group(1)) for ln in list(view) if (m := pattern.search(ln))]

    # every send got result 0 and printed its reply (stick_control: accepted, so not answered)
    for command, done in ran:
        if command.startswith("dji-gateway send --drc stick_control "):
            assert done.stdout.startswith("sent stick_control: not refused"), (command, done.stdout)
        elif command.startswith("dji-gateway send --drc heart_beat "):
            # a heartbeat is echoed, not answered with a result: the echo carries the same seq
            seq = re.search(r"\bseq=(\d+)", command)
            assert seq and f'"seq": {seq.group(1)}' in done.stdout, (command, done.stdout)
            assert '"method": "heart_beat"' in done.stdout, (command, done.stdout)
        elif command.startswith("dji-gateway send "):
            assert '"result": 0' in done.stdout, (command, done.stdout)
        if command.startswith("dji-gateway decode "):
            frames = [json.loads(ln) for ln in done.stdout.splitlines()]
            assert frames and all(f["valid"] for f in frames), (command, done.stdout)
    # the monitor, started after the gateway's update_topo, learnt the topology from /status
    assert any("topo   DJIGW-SIM-0001: " in ln and "OSDK-SIM-0001" in ln for ln in view), view[:20]
    # the gimbal turned to 28°, the aircraft climbed in a wayline (mode_code labelled)
    wait_until(
        lambda: any(abs(v - 28.0) < 0.5 for v in values("RSDK-SIM-0001", "gimbal_yaw")),
        10,
        what="gimbal_yaw 28 in the monitor",
    )
    wait_until(
        lambda: max(values("OSDK-SIM-0001", "elevation") or [0]) > 2.0, 20, what="the aircraft climbing"
    )
    assert any("mode_code=5(wayline)" in ln for ln in view)
    wait_until(lambda: any("takeoff_to_point_progress" in ln for ln in view), 10, what="progress events")
    # each event is shown once: the monitor answered it, the gateway did not re-send it. The same
    # drc_status_notify content may legitimately come twice as two events (a heartbeat failsafe fires,
    # clears when a heartbeat comes back, and fires again when the block's heartbeats end), so the
    # check is made on the task's progress events, whose content never repeats
    events = [ln.split("event  ", 1)[1] for ln in view if "event  " in ln]
    # (the robot's x_robomaster_hurt events repeat by nature: the simulated match hits armours 0-3 in turn)
    answered = [e for e in events if e.startswith("takeoff_to_point_progress ")]
    assert answered and len(answered) == len(set(answered)), "\n".join(events)


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
