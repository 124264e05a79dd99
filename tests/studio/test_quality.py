"""Quality gates (studio.fit.quality) on purpose-made bad inputs: each must be flagged with the
right reason, and clean silhouettes must pass."""

from pathlib import Path

import numpy as np
import pytest

from calibration import Camera
from calibration.rotation import rotvec_to_matrix
from studio.fit import FitError, fit_frame
from studio.fit.errors import UnusableFrame
from studio.fit.quality import (POPULATION_FILE, fit_quality, population, population_z, screen_masks, status_of,
                                summarise_ansur, summary_line)
from studio.render import silhouette

from test_fit_frame import SMALL, scene  # noqa: F401 (scene: a fixture)

ANSUR = Path(__file__).resolve().parents[3] / "shared" / "data" / "anthropometry" / "ansur2"


def _checks(result, severity=None):
    return {r["check"] for r in result["reasons"] if severity is None or r["severity"] == severity}


def _views(result, check):
    return {r["view"] for r in result["reasons"] if r["check"] == check}


def test_clean_silhouettes_pass_every_gate(scene):
    model, cams, shape, pose, V, masks = scene
    s = screen_masks(cams, masks)
    assert s["status"] == "ok", s["reasons"]
    assert all(v["hull_explained"] >= 0.95 and v["blobs"] == 1 for v in s["views"].values())
    costs = {"silhouette_per_view": {c.name: 0.1 for c in cams}}
    q = fit_quality(model, cams, masks, shape, pose, costs, s)
    assert q["status"] == "ok", q["reasons"]
    assert q["silhouette_precision"] > 0.99 and q["silhouette_recall"] > 0.99
    assert 0.5 < q["shape_sigma_max"] < 1.0  # the scene's first coefficient is 0.8 σ
    assert abs(q["population_z"]["stature"]) < 3


def test_all_person_masks_fail_before_any_fit(scene):
    model, cams, *_ = scene
    full = [np.ones((c.size[1], c.size[0]), bool) for c in cams]
    s = screen_masks(cams, full)
    assert s["status"] == "failed" and "views" in _checks(s, "failed")
    assert _views(s, "coverage") == {c.name for c in cams}
    with pytest.raises(UnusableFrame, match="0 usable view") as err:
        fit_frame(model, cams, full, options=SMALL)
    assert err.value.quality["status"] == "failed"


def test_one_bad_view_is_dropped_and_flagged(scene):
    model, cams, shape, pose, V, masks = scene
    bad = list(masks)
    bad[2] = np.ones_like(bad[2])
    s = screen_masks(cams, bad)
    assert s["status"] == "suspect" and s["dropped"] == ["cam2"]
    assert all(s["views"][c]["hull_explained"] >= 0.95 for c in ("cam0", "cam1", "cam3"))


def _turned(cams, k, degrees):
    """``cams`` with camera ``k`` turned ``degrees`` about its own vertical (y) axis, centre kept."""
    c = cams[k]
    R = rotvec_to_matrix(np.radians(degrees) * np.array([0.0, 1.0, 0.0])) @ c.R
    wrong = list(cams)
    wrong[k] = Camera(c.name, c.K, c.dist, R, -R @ (-c.R.T @ c.t), c.size)
    return wrong


def test_a_camera_rotated_10_degrees_fails(scene):
    model, cams, shape, pose, V, masks = scene
    s = screen_masks(_turned(cams, 1, 10.0), masks)
    assert s["status"] == "failed" and "hull" in _checks(s, "failed")


def test_a_camera_panned_3_degrees_is_flagged(scene):
    """3° of pan moves the image ~15 px sideways: the other views carve the hull away."""
    model, cams, shape, pose, V, masks = scene
    s = screen_masks(_turned(cams, 3, 3.0), masks)
    assert s["status"] != "ok" and "hull" in _checks(s)
    assert min(v["hull_explained"] for v in s["views"].values()) < 0.8


def test_person_half_outside_the_image_is_flagged(scene):
    model, cams, shape, pose, V, masks = scene
    c = cams[0]
    K = c.K.copy()
    K[0, 2] += 0.5 * c.size[0] + 10  # the body's centre now projects beyond the right edge
    shifted = list(cams)
    shifted[0] = Camera(c.name, K, c.dist, c.R, c.t, c.size)
    cut = list(masks)
    cut[0] = silhouette(shifted[0], V, model.faces)
    assert 0 < cut[0].sum() < 0.8 * masks[0].sum()
    s = screen_masks(shifted, cut)
    assert s["status"] != "ok"
    assert _views(s, "border") == {"cam0"}


def test_agreement_gate_at_its_threshold(scene):
    """The true body against its masks grown by k pixels: recall = |body| / |grown mask|,
    counted here independently; the gate says suspect exactly when that is below
    AGREEMENT[0] (0.93) and failed below AGREEMENT[1]."""
    import cv2

    from studio.fit.quality import AGREEMENT

    model, cams, shape, pose, V, masks = scene
    sils = [silhouette(c, V, model.faces) for c in cams]
    costs = {"silhouette_per_view": {c.name: 0.1 for c in cams}}
    seen = set()
    for k in (0, 1, 2, 3, 4, 6, 12):
        grown = [cv2.dilate(m.astype(np.uint8), np.ones((2 * k + 1, 2 * k + 1), np.uint8)) > 0 for m in masks]
        recall = sum(int((s & g).sum()) for s, g in zip(sils, grown)) / sum(int(g.sum()) for g in grown)
        q = fit_quality(model, cams, grown, shape, pose, costs, screen_masks(cams, grown))
        assert q["silhouette_recall"] == pytest.approx(recall, abs=1e-4)
        want = "failed" if recall < AGREEMENT[1] else "suspect" if recall < AGREEMENT[0] else None
        got = next((r["severity"] for r in q["reasons"] if r["check"] == "agreement"), None)
        assert got == want, (k, recall, q["reasons"])
        seen.add(want)
    assert seen == {None, "suspect", "failed"}  # both sides of both thresholds were crossed


def test_ignored_pixels_count_neither_way(scene):
    """The cost's don't-care region (a prop) is left out of the agreement on both sides: the
    body's lower half ignored and the masks' lower half emptied (as a stool would be seen) is
    still a perfect fit, while without ``ignore`` the body's own lower half reads as extra."""
    model, cams, shape, pose, V, masks = scene
    costs = {"silhouette_per_view": {c.name: 0.1 for c in cams}}
    lower = []
    for m in masks:
        ys = np.nonzero(m)[0]
        low = np.zeros_like(m)
        low[(ys.min() + ys.max()) // 2:] = True
        lower.append(low)
    cut = [m & ~lo for m, lo in zip(masks, lower)]
    q = fit_quality(model, cams, cut, shape, pose, costs, screen_masks(cams, masks), ignore=lower)
    assert q["silhouette_precision"] > 0.99 and q["silhouette_recall"] > 0.99 and q["status"] == "ok", q["reasons"]
    plain = fit_quality(model, cams, cut, shape, pose, costs, screen_masks(cams, masks))
    assert plain["silhouette_precision"] < 0.7 and "agreement" in _checks(plain)


def test_stray_blobs_are_flagged(scene):
    model, cams, shape, pose, V, masks = scene
    blobs = list(masks)
    blobs[1] = masks[1].copy()
    blobs[1][5:45, 5:45] = True
    s = screen_masks(cams, blobs)
    assert "blobs" in _checks(s, "suspect") and _views(s, "blobs") == {"cam1"}


def test_an_empty_view_is_fitted_from_the_others_and_flagged(scene):
    model, cams, shape, pose, V, masks = scene
    empty = [masks[0], np.zeros_like(masks[1])] + masks[2:]
    fit = fit_frame(model, cams, empty, options=SMALL, seed=0)
    assert fit.status == "suspect"
    assert fit.quality["dropped_views"] == ["cam1"]
    assert _views(fit.quality, "coverage") == {"cam1"}
    assert fit.quality["silhouette_precision"] > 0.9  # the three other views still fit


def test_a_rig_scaled_by_0_8_is_not_ok(scene):
    """A calibration in the wrong units is consistent between views: only the body it implies
    (1.3 m, at the bound of the shape space) gives it away."""
    model, cams, shape, pose, V, masks = scene
    scaled = [Camera(c.name, c.K, c.dist, c.R, 0.8 * c.t, c.size) for c in cams]
    assert screen_masks(scaled, masks)["status"] == "ok"
    fit = fit_frame(model, scaled, masks, options=SMALL, seed=0)
    assert fit.status != "ok", fit.quality
    assert {"population", "shape_prior", "agreement"} & _checks(fit.quality)


def test_population_z_scores_and_flags(scene):
    model, cams, shape, pose, V, masks = scene
    pop = population()["sexes"]
    assert pop["female"]["stature"]["mean"] == pytest.approx(1.629, abs=0.002)  # SOURCE.md: F 1629 ± 64 mm
    assert pop["male"]["stature"]["std"] == pytest.approx(0.069, abs=0.002)
    z = population_z({"stature": 2.099, "mass": 153.0}, "female")
    assert z["stature"] > 7 and z["mass"] > 5  # the 2.1 m, 153 kg "slim adult" of the real recording
    assert population_z({"stature": 1.756}, "neutral")["stature"] == pytest.approx(0.0, abs=0.05)  # the male mean
    costs = {"silhouette_per_view": {}}
    q = fit_quality(model, cams, masks, shape, pose, costs, measurements={"stature": 2.099, "mass": 153.0})
    assert q["status"] == "failed" and _checks(q, "failed") == {"population"}
    assert "2099 mm" in " ".join(r["message"] for r in q["reasons"])


@pytest.mark.skipif(not ANSUR.is_dir(), reason="ANSUR II CSVs (../shared/data) not present")
def test_shipped_population_summary_is_rebuilt_from_ansur():
    import json

    assert summarise_ansur(ANSUR) == json.loads(POPULATION_FILE.read_text())


def test_status_and_summary_line():
    assert status_of([]) == "ok"
    assert status_of([{"severity": "suspect"}, {"severity": "failed"}]) == "failed"
    line = summary_line({0: {"status": "ok", "reasons": []},
                         3: {"status": "failed", "reasons": [{"view": "c1", "message": "boom"}]}})
    assert line == "1 ok, 1 failed — frame 3 failed: c1: boom"


def test_unusable_frame_is_a_fit_error():
    err = UnusableFrame(7, {"status": "failed", "reasons": [{"severity": "failed", "view": "c", "message": "m"}]})
    assert isinstance(err, FitError) and "frame 7" in str(err) and "c: m" in str(err)
