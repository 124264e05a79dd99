"""Code digests keep caches honest: a stored fit from other fitting code is not kept."""

import json

from studio.fit.units import FIT_CODE, fit_code_digest, stored_fit
from studio.provenance import code_digest
from studio.workspace.layout import Layout


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
