"""The device-family registry (adapters/families.py) and the boundary it draws: no module under gateway/
names a device family package, every gateway site lists the families from the registry."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

from adapters import families
from gateway.app import build_registry
from gateway.cli import codec as codec_cli
from gateway.cli import run as run_cli
from gateway.cli.config import reference_markdown
from gateway.settings import ConfigError, load_settings
from schemas import TopicKind
from tests import toy_family

ROOT = Path(__file__).resolve().parents[1]
FAMILY_PACKAGES = ("adapters.rsdk", "adapters.osdk", "adapters.robomaster")
MODULE_PATH = re.compile(r"[A-Za-z_][\w.]*(:\w+)?")


def _named_family(name: str) -> bool:
    return any(name == p or name.startswith(p + ".") for p in FAMILY_PACKAGES)


def family_references(source: str) -> list[str]:
    """Every place a module's source names a family package: an import (``import adapters.rsdk``,
    ``from adapters.rsdk.x import y``, ``from adapters import rsdk``), a string that is such a module
    path (what ``importlib.import_module`` would be given), or an f-string building one by family name
    (``f"adapters.{family}.describe"``: the registry is bypassed)."""
    found: list[str] = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [f"import {a.name}" for a in node.names if _named_family(a.name)]
        elif isinstance(node, ast.ImportFrom) and node.module is not None:
            if _named_family(node.module):
                found.append(f"from {node.module} import …")
            elif node.module == "adapters":
                found += [
                    f"from adapters import {a.name}"
                    for a in node.names
                    if _named_family(f"adapters.{a.name}")
                ]
        elif (
            isinstance(node, ast.Constant)
            and isinstance(node.value, str)
            and MODULE_PATH.fullmatch(node.value)
        ):
            if _named_family(node.value.partition(":")[0]):
                found.append(f"string {node.value!r}")
        elif isinstance(node, ast.JoinedStr) and node.values:
            head = node.values[0]
            if isinstance(head, ast.Constant) and str(head.value).startswith("adapters."):
                found.append(f"f-string {ast.unparse(node)}")
    return found


def test_the_checker_sees_every_way_of_naming_a_family() -> None:
    source = (
        "import adapters.rsdk.sim\n"
        "from adapters.osdk.adapter import AircraftAdapter\n"
        "from adapters import robomaster\n"
        "import importlib\n"
        "importlib.import_module('adapters.rsdk.describe')\n"
        "importlib.import_module(f'adapters.{family}.describe')\n"
        "'a docstring naming adapters.rsdk.sim is fine'\n"
        "from adapters import families, base\n"
        "from adapters.wire.stream import StreamDecoder\n"
    )
    assert family_references(source) == [
        "import adapters.rsdk.sim",
        "from adapters.osdk.adapter import …",
        "from adapters import robomaster",
        "string 'adapters.rsdk.describe'",
        "f-string f'adapters.{family}.describe'",
    ]


def test_no_gateway_module_names_a_device_family() -> None:
    offenders = {
        str(path.relative_to(ROOT)): refs
        for path in sorted((ROOT / "gateway").rglob("*.py"))
        if (refs := family_references(path.read_text()))
    }
    assert offenders == {}


def test_builtin_families_are_listed_without_importing_them() -> None:
    code = (
        "import sys\n"
        "from adapters import families\n"
        "assert families.names()[:3] == ('rsdk', 'osdk', 'robomaster'), families.names()\n"
        f"loaded = [m for m in sys.modules if m.startswith({FAMILY_PACKAGES!r})]\n"
        "assert loaded == [], loaded\n"
    )
    subprocess.run([sys.executable, "-c", code], cwd=ROOT, check=True, timeout=60)


def test_every_site_iterates_the_registry() -> None:
    names = families.names()
    registry = build_registry()
    for family in families.all_families():
        for method, *_ in family.service_extensions():
            assert registry.spec(TopicKind.SERVICES, method) is not None, method
        for method, *_ in family.event_extensions():
            assert registry.spec(TopicKind.EVENTS, method) is not None, method
        assert f'`[[devices]]` with `type = "{family.name}"`' in reference_markdown()
    doc = run_cli.simulated_settings({})
    assert [d["type"] for d in doc["devices"]] == [f.name for f in families.all_families() if f.tour]
    assert set(names) >= {"rsdk", "osdk", "robomaster"}
    assert codec_cli._describe("rsdk").COMMANDS


def test_unknown_type_and_registration_rules() -> None:
    with pytest.raises(
        ConfigError, match="does not match any of the expected tags: 'rsdk', 'osdk', 'robomaster'"
    ):
        load_settings(None, gateway_sn="G", devices=[{"type": "lamp", "sn": "L1"}])
    with pytest.raises(families.UnknownFamily, match="no device family 'lamp'"):
        families.get("lamp")
    with pytest.raises(ValueError, match="already registered"):
        families.register(families.Family(name="rsdk", settings="x:y", adapter="x:z"))
    with pytest.raises(ValueError, match="built in"):
        families.unregister("osdk")
    wrong = families.Family(name="lamp", settings=toy_family.VaneSettings, adapter=toy_family.VaneAdapter)
    with pytest.raises(TypeError, match=r"family 'lamp': VaneSettings.type must be Literal\['lamp'\]"):
        wrong.settings_model()
    with pytest.raises(ValueError, match="identifier"):
        families.register(families.Family(name="no way", settings="x:y", adapter="x:z"))
