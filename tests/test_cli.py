"""The byte-level tools an integrator debugs with: ``dji-gateway decode`` / ``encode`` / ``schema export``."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from gateway.cli import main

SEED_000_SAMPLE = "AA 1A 00 03 00 00 00 00 22 11 A2 42 0E 00 20 00 30 00 40 00 01 14 7B 40 97 BE"
SEED_002_HELLO = "A5 05 00 00 F6 00 00 68 65 6C 6C 6F 56 34"
REQUIRED = {"protocol", "valid", "seq", "command", "fields", "error"}


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, list[str]]:
    code = main(list(args))
    return code, [line for line in capsys.readouterr().out.splitlines() if line]


def test_decode_seed_sample(capsys: pytest.CaptureFixture[str]) -> None:
    code, lines = run(capsys, "decode", "rsdk", *SEED_000_SAMPLE.split())
    assert code == 0 and len(lines) == 1
    rec = json.loads(lines[0])
    assert REQUIRED | {"cmd_set", "cmd_id", "is_reply"} <= set(rec)
    assert rec["valid"] and rec["seq"] == 0x1122 and rec["command"] == "position_control"
    assert (rec["cmd_set"], rec["cmd_id"], rec["is_reply"]) == (0x0E, 0x00, False)
    assert rec["fields"] == {
        "yaw_angle": 32,
        "roll_angle": 48,
        "pitch_angle": 64,
        "ctrl_byte": 1,
        "time_for_action": 20,
    }


def test_bad_frames_never_stop_the_stream(capsys: pytest.CaptureFixture[str]) -> None:
    corrupt = SEED_000_SAMPLE.split()
    corrupt[-1] = "00"  # CRC32 broken
    code, lines = run(capsys, "decode", "rsdk", "01", "02", *corrupt, *SEED_000_SAMPLE.split())
    recs = [json.loads(x) for x in lines]
    assert code == 0
    assert [r["valid"] for r in recs] == [False, False, True]
    assert recs[0]["error"] == "garbage" and recs[1]["error"] and recs[2]["command"] == "position_control"


def test_decode_candump_lines_from_stdin() -> None:
    text = (
        "  can0  223   [8]  AA 1A 00 03 00 00 00 00\n"
        "  can0  223   [8]  22 11 A2 42 0E 00 20 00\n"
        " (1.0) can0 223#3000400001147B40\n"
        " (1.1) can0 223#97BE\n"
    )
    proc = subprocess.run(
        [sys.executable, "-m", "gateway.cli", "decode", "rsdk", "-"],
        input=text,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert proc.returncode == 0, proc.stderr
    (rec,) = [json.loads(x) for x in proc.stdout.splitlines()]
    assert rec["command"] == "position_control" and rec["seq"] == 0x1122


def test_decode_robomaster_and_osdk(capsys: pytest.CaptureFixture[str]) -> None:
    code, lines = run(capsys, "decode", "robomaster", SEED_002_HELLO)
    rec = json.loads(lines[0])
    assert code == 0 and rec["valid"] and rec["cmd_id"] == 0 and rec["seq"] == 0 and "command" in rec
    code, lines = run(capsys, "encode", "osdk", "wp_start_stop", "--seq", "5", "start=1")
    assert code == 0
    code, lines = run(capsys, "decode", "osdk", *lines[0].split())
    rec = json.loads(lines[0])
    assert REQUIRED | {"cmd_set", "cmd_id", "is_ack", "session"} <= set(rec)
    assert (rec["command"], rec["fields"], rec["seq"], rec["is_ack"]) == (
        "wp_start_stop",
        {"start": 1},
        5,
        False,
    )


def test_encode_reproduces_the_seed_sample(capsys: pytest.CaptureFixture[str]) -> None:
    fields = ["yaw_angle=32", "roll_angle=48", "pitch_angle=64", "ctrl_byte=1", "time_for_action=20"]
    code, lines = run(capsys, "encode", "rsdk", "position_control", "--seq", "0x1122", *fields)
    assert code == 0 and lines == [SEED_000_SAMPLE]
    code, lines = run(capsys, "encode", "rsdk", "position_control", "--can", "--seq", "0x1122", *fields)
    assert lines == ["223#AA1A000300000000", "223#2211A2420E002000", "223#3000400001147B40", "223#97BE"]


def test_encode_robomaster_hello_shape(capsys: pytest.CaptureFixture[str]) -> None:
    code, lines = run(
        capsys, "encode", "robomaster", "chassis_velocity", "--seq", "3", "vx=1.0", "vy=0", "wz=0"
    )
    assert code == 0
    code, out = run(capsys, "decode", "robomaster", *lines[0].split())
    rec = json.loads(out[0])
    assert rec["command"] == "chassis_velocity" and rec["fields"]["vx"] == 1.0 and rec["seq"] == 3


def test_encode_errors_are_clear(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["encode", "rsdk", "no_such_command"]) == 2
    err = capsys.readouterr().err
    assert "unknown command" in err and "position_control" in err
    rest = ["roll_angle=0", "pitch_angle=0", "ctrl_byte=1", "time_for_action=20"]
    assert main(["encode", "rsdk", "position_control", "yaw_angle=99999", *rest]) == 2
    assert "yaw_angle" in capsys.readouterr().err
    assert main(["encode", "rsdk", "position_control", "yaw_angle=0"]) == 2
    assert "missing field" in capsys.readouterr().err


def test_schema_export_writes_the_committed_documents(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["schema", "export", str(tmp_path)]) == 0
    written = {p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*") if p.is_file()}
    committed_dir = Path(__file__).resolve().parent.parent / "schemas" / "json"
    committed = {p.relative_to(committed_dir).as_posix() for p in committed_dir.rglob("*") if p.is_file()}
    assert written == committed
    assert "messages/services.x_rsdk_stiffness_set.json" in written


def test_bench_quick_runs_and_checks_itself() -> None:
    """Not a timed test: the benchmark's own sanity checks (frames really decoded) must pass."""
    root = Path(__file__).resolve().parent.parent
    proc = subprocess.run(
        [sys.executable, "bench/run.py", "--quick", "--only", "codecs"],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "frames/s" in proc.stdout


def test_decode_rsdk_legacy_angle_order(capsys: pytest.CaptureFixture[str]) -> None:
    from adapters.rsdk import commands as cmds

    ask = cmds.encode_command("get_angle", 9, {"ctrl_byte": 1}).hex()
    fields = {"return_code": 0, "data_type": 1, "yaw": 300, "roll": 50, "pitch": 200}
    reply = cmds.encode_command("get_angle", 9, fields, reply=True, legacy=True).hex()
    code, lines = run(capsys, "decode", "rsdk", ask, reply)
    seed = json.loads(lines[1])
    assert code == 0 and seed["legacy"] and (seed["fields"]["roll"], seed["fields"]["pitch"]) == (50, 200)
    code, lines = run(capsys, "decode", "rsdk", "--angle-order", "yaw_pitch_roll", ask, reply)
    other = json.loads(lines[1])
    assert code == 0 and (other["fields"]["roll"], other["fields"]["pitch"]) == (200, 50)
