"""Background model (eq. 5.4), per-pixel classification (eq. 5.5–5.6) and morphology."""

import json

import numpy as np
import pytest

from studio.segment import (
    BACKGROUND,
    PERSON,
    SHADOW,
    BackgroundModel,
    Morphology,
    SegmentationError,
    Thresholds,
    fill_holes,
    remove_small_components,
)
from studio.segment.metrics import binary_scores

H, W = 60, 80


def _backgrounds(n=8, seed=0):
    """Textured, moderately saturated empty scene with sensor noise (σ = 2 levels)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W]
    base = np.stack([140 + 20 * np.sin(xx / 7), 120 + 15 * np.cos(yy / 5), 80 + 0 * xx], -1)
    frames = [np.clip(base + rng.normal(0, 2, base.shape), 0, 255).astype(np.uint8) for _ in range(n)]
    return base, frames


def _scene(base, seed=1):
    """A saturated 'person' patch, a darkened 'shadow' patch, the rest unchanged."""
    rng = np.random.default_rng(seed)
    img = base.copy()
    img[10:40, 10:30] = (30, 60, 200)  # person: strong saturation/hue change
    img[35:55, 40:75] *= 0.55  # cast shadow: darker, same chromaticity
    truth = np.zeros((H, W), np.uint8)
    truth[10:40, 10:30] = PERSON
    truth[35:55, 40:75] = SHADOW
    return np.clip(img + rng.normal(0, 2, img.shape), 0, 255).astype(np.uint8), truth


def test_fit_statistics_match_the_frames():
    base, frames = _backgrounds()
    model = BackgroundModel.fit(frames, robust=False)
    # V = max(R, G, B)/255 for this texture; σ of V ≈ 2/255 (noise), floored at 0.01
    v = base.max(axis=-1) / 255
    err = np.abs(model.mean[..., 2] - v)
    assert err.mean() < 0.005 and err.max() < 0.02  # 8 noisy frames (max of R, G biases up)
    assert np.median(model.std[..., 2]) == pytest.approx(0.01, abs=0.002)
    assert model.frames_used == 8 and model.shape == (H, W)


def test_fit_hue_mean_across_the_red_wrap():
    a = np.full((4, 4, 3), (250, 0, 40), np.uint8)  # hue 1 - 40/250/6 ≈ 0.973
    b = np.full((4, 4, 3), (250, 40, 0), np.uint8)  # hue ≈ 0.027
    model = BackgroundModel.fit([a, b, a, b], robust=False)
    hue = model.mean[..., 0]
    assert np.all(np.minimum(hue, 1 - hue) < 1e-3)
    assert np.allclose(model.std[..., 0], 40 / 250 / 6, atol=0.001)  # not ≈ 0.47 (naive)


def test_robust_fit_ignores_frames_with_motion():
    base, frames = _backgrounds(10)
    clean = BackgroundModel.fit(frames)
    moving = [f.copy() for f in frames]
    moving[3][5:30, 5:30] = (20, 200, 40)  # someone walked through in two frames
    moving[7][20:50, 30:60] = (250, 250, 250)
    robust = BackgroundModel.fit(moving)
    naive = BackgroundModel.fit(moving, robust=False)
    assert np.abs(robust.mean - clean.mean).max() < 0.02
    assert np.abs(robust.std - clean.std).max() < 0.02
    assert np.abs(naive.mean - clean.mean).max() > 0.04
    assert np.abs(naive.std - clean.std).max() > 0.1


def test_classification_of_synthetic_pixels_before_and_after_morphology():
    base, frames = _backgrounds()
    model = BackgroundModel.fit(frames)
    image, truth = _scene(base)
    raw = model.classify_raw(image)
    assert (raw[15:35, 15:25] == PERSON).all()
    assert (raw[40:50, 45:70] == SHADOW).mean() > 0.97  # a few noisy pixels before morphology
    assert (raw[0:8] == BACKGROUND).mean() > 0.97
    labels = model.classify(image)
    assert labels.dtype == np.uint8 and labels.shape == (H, W)
    for value, target in ((PERSON, 0.97), (SHADOW, 0.97)):
        assert binary_scores(labels == value, truth == value)["f1"] > target
    assert (labels[truth == BACKGROUND] == BACKGROUND).mean() > 0.999


def test_plain_eq_5_5_labels_a_brightened_patch_shadow_the_value_gate_person():
    base, frames = _backgrounds()
    image = base.copy()
    image[10:30, 10:30] *= 1.5  # brighter, same chromaticity: not a cast shadow
    image = np.clip(image, 0, 255).astype(np.uint8)
    gated = BackgroundModel.fit(frames)
    plain = gated.with_settings(Thresholds(value_ratio=(0.0, np.inf)))
    assert (gated.classify_raw(image)[12:28, 12:28] == PERSON).all()
    assert (plain.classify_raw(image)[12:28, 12:28] == SHADOW).all()


def test_save_load_round_trip(tmp_path):
    _, frames = _backgrounds()
    model = BackgroundModel.fit(frames, thresholds=Thresholds(5.0, 3.5, (0.2, 0.8)), morphology=Morphology(median=3))
    model.save(tmp_path / "bg")
    assert sorted(p.name for p in (tmp_path / "bg").iterdir()) == ["mean.exr", "model.json", "std.exr"]
    back = BackgroundModel.load(tmp_path / "bg")
    np.testing.assert_array_equal(back.mean, model.mean)
    np.testing.assert_array_equal(back.std, model.std)
    assert back.thresholds == model.thresholds and back.morphology == model.morphology
    assert back.frames_used == 8


def test_load_errors_name_the_file(tmp_path):
    with pytest.raises(SegmentationError, match="no background model here"):
        BackgroundModel.load(tmp_path)
    _, frames = _backgrounds(3)
    BackgroundModel.fit(frames).save(tmp_path)
    meta = json.loads((tmp_path / "model.json").read_text())
    (tmp_path / "model.json").write_text(json.dumps({**meta, "version": 7}))
    with pytest.raises(SegmentationError, match="version 7 is not supported"):
        BackgroundModel.load(tmp_path)
    (tmp_path / "model.json").write_text(json.dumps({**meta, "format": "other"}))
    with pytest.raises(SegmentationError, match="format is 'other'"):
        BackgroundModel.load(tmp_path)
    (tmp_path / "model.json").write_text(json.dumps({**meta, "size": [10, 10]}))
    with pytest.raises(SegmentationError, match="model.json says 10x10"):
        BackgroundModel.load(tmp_path)
    (tmp_path / "model.json").write_text("{")
    with pytest.raises(SegmentationError, match="not valid JSON"):
        BackgroundModel.load(tmp_path)


def test_input_errors():
    _, frames = _backgrounds(3)
    with pytest.raises(SegmentationError, match="need at least 2 empty-scene frames, got 1"):
        BackgroundModel.fit(frames[:1])
    with pytest.raises(SegmentationError, match=r"background frame 1 is \(30, 80, 3\)"):
        BackgroundModel.fit([frames[0], frames[1][:30]])
    model = BackgroundModel.fit(frames)
    with pytest.raises(SegmentationError, match="image is 40x60, the background model is 80x60"):
        model.classify(np.zeros((60, 40, 3), np.uint8))
    with pytest.raises(SegmentationError, match=r"mean and std must both be \(H, W, 3\)"):
        BackgroundModel(np.zeros((4, 4, 3)), np.zeros((4, 4)))
    with pytest.raises(SegmentationError, match="Thresholds.hsv: expected a positive number"):
        Thresholds(hsv=-1)
    with pytest.raises(SegmentationError, match="Thresholds.value_ratio"):
        Thresholds(value_ratio=(0.9, 0.5))
    with pytest.raises(SegmentationError, match="Morphology.median"):
        Morphology(median=4)
    with pytest.raises(SegmentationError, match="Morphology radii"):
        Morphology(open_radius=-1)


def test_small_components_and_holes():
    mask = np.zeros((50, 50), np.uint8)
    mask[5:25, 5:25] = 1
    mask[10:13, 10:13] = 0  # small hole (9 px)
    mask[40:43, 40:43] = 1  # speck (9 px)
    out = remove_small_components(mask, 20, max_hole=20)
    assert out[40:43, 40:43].sum() == 0
    assert out[5:25, 5:25].all()
    big_hole = mask.copy()
    big_hole[8:20, 8:20] = 0
    kept = fill_holes(big_hole, max_area=50)
    assert kept[10:18, 10:18].sum() == 0  # 144-px hole left open
    assert fill_holes(big_hole)[8:20, 8:20].all()
