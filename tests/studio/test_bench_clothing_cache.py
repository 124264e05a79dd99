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


def test_a_finer_rig_is_the_same_rig_with_half_the_pixel(monkeypatch):
    """``--pixels 2``: the benchmark's scene spec on cameras of twice the pixels each way through the same
    lenses (the same places and jitter, the focal length in pixels doubled), in its own cache folder."""
    import numpy as np
    import yaml

    import clothing_pixel
    from studio.simulate import ring_cameras
    from studio.simulate.spec import load_spec

    monkeypatch.setattr(clothing, "RUN", dict(clothing.RUN))  # select_run below sets every field
    p = clothing.subjects(1, 4, quick=True)[0]
    rigs = {}
    for px in (1, 2):
        clothing.select_run(None, False, "dev", False, px)
        spec = load_spec(yaml.safe_load(clothing._spec(p, "tight")))
        rigs[px] = ring_cameras(spec["cameras"], np.random.default_rng(spec["seed"]))
    assert clothing.RUN["name"] == "dev-full-x2" and clothing.RUN["pixels"] == 2
    for coarse, fine in zip(rigs[1], rigs[2]):
        assert tuple(coarse.size) == (656, 490) and tuple(fine.size) == (1312, 980)
        np.testing.assert_allclose(fine.center, coarse.center, atol=1e-12)
        np.testing.assert_allclose(fine.K[0, 0], 2 * coarse.K[0, 0], rtol=1e-12)
    ratio = clothing_pixel.mm_per_pixel(rigs[2]) / clothing_pixel.mm_per_pixel(rigs[1])
    assert abs(ratio - 0.5) < 1e-9
    assert 6.0 < clothing_pixel.mm_per_pixel(rigs[1]) < 7.5  # the thesis rig's 6.8 mm at the person
