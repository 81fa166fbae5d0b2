"""Sans-I/O is a rule, not a hope: protocol and command modules import the standard library and
``adapters.wire`` only, and ``adapters.errors`` (the one error tree, itself standard library only): no
python-can, pyserial, paho, pydantic, sockets or threads."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FORBIDDEN_STDLIB = {"socket", "threading", "asyncio", "select", "selectors", "subprocess", "time"}


def _sans_io_modules() -> list[Path]:
    files = list((ROOT / "adapters" / "wire").glob("*.py"))
    for pattern in ("protocol.py", "commands.py", "telemetry.py", "subscription.py", "can.py"):
        files += (ROOT / "adapters").glob(f"*/{pattern}")
    files.append(ROOT / "adapters" / "absence.py")  # what supervision says about an absent link
    files.append(ROOT / "adapters" / "errors.py")  # the one error tree: codecs raise it
    # live video's decisions and command lines: no processes, no loop (gateway/video/service.py has those)
    files += [ROOT / "gateway" / "video" / name for name in ("machine.py", "engine.py", "preview.py")]
    return sorted(files)


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative import: stays inside its own package
                pkg = ".".join(path.relative_to(ROOT).with_suffix("").parts[: -node.level])
                names.add(f"{pkg}.{node.module}" if node.module else pkg)
            elif node.module:
                names.add(node.module)
    return names


def test_there_are_modules_to_check() -> None:
    assert len(_sans_io_modules()) >= 4


def _offenders(paths: list[Path]) -> list[str]:
    offenders: list[str] = []
    for path in paths:
        family = path.parent.name
        for name in _imports(path):
            top = name.split(".")[0]
            if name.startswith("adapters.wire") or name == "adapters.errors" or top == "__future__":
                continue
            if name.startswith(f"adapters.{family}") and path.parent.name != "wire":
                own = ROOT / Path(*name.split("."))
                # another sans-I/O module of the same family is fine; anything else (a link, a sim) is not
                if own.with_suffix(".py") in _sans_io_modules():
                    continue
            if top in sys.stdlib_module_names and top not in FORBIDDEN_STDLIB:
                continue
            offenders.append(f"{path.relative_to(ROOT)} imports {name}")
    return offenders


def test_protocol_modules_import_only_stdlib_and_wire() -> None:
    assert _offenders(_sans_io_modules()) == []


def test_the_rule_catches_an_offender(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    # in a copy of the layout under tmp_path, never in the source tree (tests running beside this one
    # walk adapters/ and would find the probe)
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    bad = tmp_path / "adapters" / "wire" / "_probe_offender.py"
    bad.parent.mkdir(parents=True)
    bad.write_text("import can\nimport socket\nfrom adapters.rsdk import link\nfrom . import stream\n")
    found = _offenders([bad])
    assert len(found) == 3, found
