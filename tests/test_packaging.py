"""Packaging: the built wheel holds what ``studio demo`` needs, and its declared dependencies are
the ones the toolkit imports (workspace issue: ``pip install .`` then ``studio demo`` anywhere)."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())
#: distribution name → import name, where they differ
IMPORT_NAMES = {"opencv-contrib-python-headless": "cv2", "PyYAML": "yaml", "tomli-w": "tomli_w"}


def _imported_modules() -> set[str]:
    names = set()
    for package in ("rigs", "calibration", "studio"):
        for path in (REPO / package).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Import):
                    names |= {a.name.split(".")[0] for a in node.names}
                elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                    names.add(node.module.split(".")[0])
    return names


def test_every_core_dependency_is_imported_by_the_toolkit():
    imported = _imported_modules()
    for requirement in PYPROJECT["project"]["dependencies"]:
        dist = re.split(r"[<>=!~\[; ]", requirement, maxsplit=1)[0]
        assert IMPORT_NAMES.get(dist, dist) in imported, f"{dist} is a core dependency nothing imports: make it an extra"


def test_licence_file_matches_the_declared_licence():
    assert PYPROJECT["project"]["license"] == "Apache-2.0"
    text = (REPO / "LICENSE").read_text()
    assert "Apache License" in text and "Version 2.0, January 2004" in text


def test_wheel_contains_what_the_demo_needs(tmp_path):
    setuptools = pytest.importorskip("setuptools")
    if tuple(int(v) for v in setuptools.__version__.split(".")[:2]) < (77, 0):
        pytest.skip(f"setuptools {setuptools.__version__} < 77 (SPDX licence strings): run `make test` to install it")
    pytest.importorskip("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(REPO), "--no-deps", "--no-build-isolation",
                    "--no-index", "-q", "-w", str(tmp_path)], check=True, cwd=tmp_path, timeout=300)
    (wheel,) = tmp_path.glob("silhouette_shadow_studio-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    needed = ["studio/body/data/scape_models.npz", "studio/fit/data/ansur2_summary.json", "studio/report/data/ansur2_percentiles.json", "studio/samples/walk/spec.yaml", "studio/samples/walk/body.npz",
              "studio/samples/clothing_poses/spec.yaml", "studio/samples/mono_shadow/spec.yaml",
              "studio/samples/clothing_11/spec.yaml", "studio/samples/clothing_11/body.npz",
              "rigs/simulated.yaml", "calibration/boards/opencv_chessboard_9x6.yaml", "studio/cli/commands/demo.py"]
    missing = [n for n in needed if n not in names]
    assert not missing, f"the wheel lacks {missing}"
    assert any(n.endswith("licenses/LICENSE") for n in names)
    assert not [n for n in names if n.startswith("tests/") or "_render/" in n]
