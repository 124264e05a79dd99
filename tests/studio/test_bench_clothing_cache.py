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


def test_pair_records_are_kept_beside_the_results_not_among_them(tmp_path, monkeypatch):
    """`pairs` keeps its batches in the ledger's pairs/ folder, where `table` (which reads every
    *.json of the ledger's folder as a subject's result) does not see them; each subject lends at
    most K of its batch frames, spread over them."""
    monkeypatch.setattr(clothing, "LEDGER", tmp_path / "ledger")
    monkeypatch.setitem(clothing.RUN, "ledger", True)
    monkeypatch.setitem(clothing.RUN, "name", "full")
    rec = tmp_path / "subject_000+subject_001_loose.json"
    rec.write_text(json.dumps({"code": "fit1"}))
    clothing.keep_in_ledger(rec, "pairs")
    assert (tmp_path / "ledger" / "full" / "pairs" / rec.name).read_text() == rec.read_text()
    assert list((tmp_path / "ledger" / "full").glob("*.json")) == []
    assert clothing._pair_frames(list(range(11)), 4) == [0, 3, 7, 10]
    assert clothing._pair_frames([2, 5], 4) == [2, 5] and clothing._pair_frames([1, 4, 9], 1) == [1]
