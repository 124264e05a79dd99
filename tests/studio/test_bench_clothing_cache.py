"""benchmarks/clothing.py: a cached result counts only for the fitting code and the masks it was fitted on."""

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

import clothing  # noqa: E402


def test_results_fitted_on_other_masks_are_redone(tmp_path, monkeypatch):
    monkeypatch.setattr(clothing, "LEDGER", tmp_path)
    monkeypatch.setitem(clothing.RUN, "ledger", True)
    monkeypatch.setitem(clothing.RUN, "name", "full")
    (tmp_path / "full").mkdir()
    kept = {"code": "fit1", "segmentation": "seg1", "subject": "person_000"}
    (tmp_path / "full" / "a.json").write_text(json.dumps(kept))
    (tmp_path / "full" / "b.json").write_text(json.dumps({"code": "fit1"}))  # before the masks' digest was kept
    assert clothing.ledger_result("a.json", "fit1", "seg1") == kept
    assert clothing.ledger_result("a.json", "fit1", "seg2") is None  # the same fits on other masks
    assert clothing.ledger_result("a.json", "fit2", "seg1") is None
    assert clothing.ledger_result("b.json", "fit1", "seg1") is None
    monkeypatch.setitem(clothing.RUN, "ledger", False)
    assert clothing.ledger_result("a.json", "fit1", "seg1") is None
