"""The installable package (issue #35): an sdist and a wheel built from the sources, the wheel built from
the sdist (so the sdist holds everything) and installed into a fresh virtual environment, whose
``dji-gateway`` then runs from the installed files (the console's page and scripts included).

Cheap and offline: setuptools' own PEP 517 hooks run in a subprocess on a copy of the sources (no build
isolation: the setuptools of this venv, no download), the wheel is installed with ``--no-deps`` by this
venv's pip into a venv made without pip, and the installed program finds its dependencies on
``PYTHONPATH`` (this venv's site-packages; its editable install is a ``.pth`` file, which ``PYTHONPATH``
entries never run, so ``gateway`` can only come from the fresh venv). ``pipx install .`` does the same
with the dependencies downloaded.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import sysconfig
import tarfile
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SOURCES = ("pyproject.toml", "README.md", "LICENSE", "schemas", "adapters", "gateway")

pytestmark = pytest.mark.timeout(120)


def _hook(where: Path, hook: str, out: Path) -> Path:
    """One setuptools build hook (``build_sdist``/``build_wheel``) run in ``where``; the file it made."""
    code = f"import sys; from setuptools import build_meta as b; print(b.{hook}(sys.argv[1]))"
    done = subprocess.run(
        [sys.executable, "-c", code, str(out)], cwd=where, capture_output=True, text=True, timeout=90
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return out / done.stdout.strip().splitlines()[-1]


def test_the_sdist_builds_a_wheel_that_installs_and_runs_in_a_fresh_venv(tmp_path: Path) -> None:
    src = tmp_path / "src"
    src.mkdir()
    for name in SOURCES:
        path = REPO / name
        if path.is_dir():
            shutil.copytree(path, src / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
        else:
            shutil.copy2(path, src / name)
    dist = tmp_path / "dist"
    dist.mkdir()
    sdist = _hook(src, "build_sdist", dist)
    assert sdist.name == "dji_gateway-0.1.0.tar.gz", sdist.name
    with tarfile.open(sdist) as tar:
        tar.extractall(tmp_path / "unpacked", filter="data")
    unpacked = next((tmp_path / "unpacked").iterdir())
    wheel = _hook(unpacked, "build_wheel", dist)  # from the sdist alone
    with zipfile.ZipFile(wheel) as zf:
        names = set(zf.namelist())
    for needed in (
        "gateway/web/static/index.html",
        "gateway/web/static/js/app.js",
        "gateway/web/static/js/pilot.js",
        "gateway/web/static/console.css",
        "gateway/py.typed",
    ):
        assert needed in names, needed
    assert any(n.startswith("schemas/json/") for n in names)

    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=60)
    python = venv / "bin" / "python"
    subprocess.run(
        [sys.executable, "-m", "pip", "--python", str(python), "install", "--quiet", "--no-deps",
         "--no-index", "--disable-pip-version-check", str(wheel)],
        check=True, timeout=60, capture_output=True,
    )  # fmt: skip
    env = {"PATH": f"{venv / 'bin'}:/usr/bin:/bin", "PYTHONPATH": sysconfig.get_paths()["purelib"]}
    where = subprocess.run(
        [str(python), "-c", "import gateway, gateway.web.server as s; print(gateway.__file__); "
         "print((s.STATIC / 'index.html').is_file(), (s.STATIC / 'js' / 'pilot.js').is_file())"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert where.returncode == 0, where.stderr
    lines = where.stdout.split("\n")
    assert lines[0].startswith(str(venv)), lines  # the installed copy, not this checkout
    assert lines[1] == "True True"
    version = subprocess.run(
        [str(venv / "bin" / "dji-gateway"), "methods"], cwd=tmp_path, env=env, capture_output=True,
        text=True, timeout=60,
    )  # fmt: skip
    assert version.returncode == 0 and "drc_mode_enter" in version.stdout, version.stderr[-2000:]
