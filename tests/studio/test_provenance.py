"""Code digests keep caches honest: a stored fit from other fitting code is not kept."""

import json

import ast
import importlib
from pathlib import Path

from studio.fit.units import FIT_CODE, FRAME_FIT_EXCLUDES, fit_code_digest, frame_fit_code_digest, stored_fit
from studio.provenance import code_digest, source_key
from studio.workspace.layout import Layout


def test_source_key_ignores_docstrings_comments_and_layout_not_code():
    base = b'"""Module."""\n\ndef f(x):\n    """Twice x."""\n    return 2 * x  # doubled\n\n\nclass C:\n    "C."\n    A = "a"\n'
    same = b'"""Module, reworded."""\ndef f(x):\n    """Two times x."""\n    # a comment\n    return 2*x\nclass C:\n    A = "a"\n'
    assert source_key(base) == source_key(same)
    for changed in (base.replace(b"2 * x", b"3 * x"), base.replace(b'A = "a"', b'A = "b"'),
                    base.replace(b"def f(x)", b"def f(y)")):
        assert source_key(changed) != source_key(base)
    only_doc = b'def g():\n    """Nothing else."""\n'
    assert source_key(only_doc) == source_key(b"def g():\n    pass\n")
    assert source_key(b"def (:\n") == b"def (:\n"  # what does not parse counts as its bytes


def test_code_digest_covers_every_source_of_a_package(tmp_path, monkeypatch):
    pkg = tmp_path / "pkgx"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "deep.py").write_text("A = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    first = code_digest("pkgx")
    (pkg / "sub" / "deep.py").write_text("A = 2\n")
    code_digest.cache_clear()
    second = code_digest("pkgx")
    assert len(first) == len(second) == 16 and first != second  # a change deep inside the package counts
    assert code_digest("pkgx", files=(tmp_path / "absent.npz",)) == second  # a missing file counts as empty
    assert code_digest("pkgx", exclude=("pkgx.sub.deep",)) != second
    (pkg / "sub" / "deep.py").write_text("A = 3\n")
    code_digest.cache_clear()
    assert code_digest("pkgx", exclude=("pkgx.sub.deep",)) == code_digest("pkgx", exclude=("pkgx.sub.deep",))
    left_out = code_digest("pkgx", exclude=("pkgx.sub.deep",))
    (pkg / "sub" / "deep.py").write_text("A = 4\n")
    code_digest.cache_clear()
    assert code_digest("pkgx", exclude=("pkgx.sub.deep",)) == left_out  # an excluded module does not count
    assert code_digest("pkgx") not in (second, left_out)
    (tmp_path / "model.npz").write_bytes(b"weights")
    assert code_digest("pkgx", files=(tmp_path / "model.npz",)) != second


def test_a_fit_stored_by_other_fitting_code_is_fitted_again(tmp_path):
    layout = Layout(tmp_path)
    layout.fit_dir.mkdir()
    run = {"gender": "female", "seed": 0, "key_frame": 0, "options": {"tau": 20.0}, "code": fit_code_digest()}
    layout.fit_json(0).write_text(json.dumps({"frame": 0, "run": run}))
    assert stored_fit(layout, 0, run) == {"frame": 0, "run": run}
    assert stored_fit(layout, 0, {**run, "code": "0" * 16}) is None
    assert "studio.fit" in FIT_CODE and "studio.cost" in FIT_CODE


def test_the_single_frame_digest_leaves_out_only_modules_a_single_frame_fit_never_imports():
    assert frame_fit_code_digest() != fit_code_digest()
    for name in FRAME_FIT_EXCLUDES:
        importlib.import_module(name)  # every excluded module exists (a renamed one would be digested again)
    excluded = set(FRAME_FIT_EXCLUDES)
    for package in FIT_CODE:
        root = Path(importlib.import_module(package).__file__).parent
        for src in root.rglob("*.py"):
            dotted = ".".join((package, *src.relative_to(root).with_suffix("").parts))
            if dotted in excluded or dotted.endswith("__init__"):
                continue  # a package's __init__ re-exports; excluded modules may import each other
            for node in ast.walk(ast.parse(src.read_text())):
                names = ([node.module or ""] if isinstance(node, ast.ImportFrom)
                         else [a.name for a in node.names] if isinstance(node, ast.Import) else [])
                if isinstance(node, ast.ImportFrom) and node.level:
                    base = dotted.rsplit(".", node.level)[0]
                    names = [f"{base}.{node.module}" if node.module else base]
                    names += [f"{names[0]}.{a.name}" for a in node.names]
                elif isinstance(node, ast.ImportFrom):
                    names += [f"{node.module}.{a.name}" for a in node.names]
                assert not excluded & set(names), f"{dotted} imports {excluded & set(names)}: its digest must count it"


def test_fit_run_names_the_segmentation(tmp_path):
    """A frame fitted on masks since relabelled (other settings or other segmentation code) is not kept."""
    from studio.fit.units import segmentation_identity
    from studio.segment.session import segmentation_code_digest
    from studio.workspace import Layout

    layout = Layout(tmp_path)
    assert segmentation_identity(layout) is None  # no segmentation recorded
    layout.segmentation_summary.parent.mkdir(parents=True)
    settings = {"voting": True, "bridges": True, "code": segmentation_code_digest()}
    layout.segmentation_summary.write_text(json.dumps({"settings": settings}))
    first = segmentation_identity(layout)
    assert len(first) == 16
    layout.segmentation_summary.write_text(json.dumps({"settings": {**settings, "code": "0" * 16}}))
    assert segmentation_identity(layout) not in (None, first)
