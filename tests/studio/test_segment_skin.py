"""Hue–Saturation histogram skin classifier (thesis §6.3.4, eq. 6.10)."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from studio.segment import SegmentationError, SkinClassifier, ycrcb_skin
from studio.segment.metrics import binary_scores

SKIN = (205, 150, 120)  # hue ≈ 0.06, saturation ≈ 0.41: inside the thesis box
CLOTH = [(40, 60, 160), (30, 130, 60), (200, 200, 190), (20, 20, 20)]


def _images(n=4, seed=0):
    rng = np.random.default_rng(seed)
    images, masks = [], []
    for _ in range(n):
        img = np.zeros((48, 64, 3), np.float64)
        img[:] = CLOTH[rng.integers(len(CLOTH))]
        mask = np.zeros((48, 64), bool)
        for color in CLOTH:
            r, c = rng.integers(0, 36), rng.integers(0, 52)
            img[r : r + 12, c : c + 12] = color
        r, c = rng.integers(0, 28), rng.integers(0, 44)
        img[r : r + 20, c : c + 20] = SKIN
        mask[r : r + 20, c : c + 20] = True
        images.append(np.clip(img + rng.normal(0, 3, img.shape), 0, 255).astype(np.uint8))
        masks.append(mask)
    return images, masks


def test_trained_model_finds_skin_and_survives_a_round_trip(tmp_path):
    images, masks = _images(6)
    model = SkinClassifier().train(images[:4], masks[:4])
    assert model.trained and model.rule == "posterior"
    scores = binary_scores([model.predict(im) for im in images[4:]], masks[4:])
    assert scores["f1"] > 0.95
    path = model.save(tmp_path / "skin.npz")
    back = SkinClassifier.load(path)
    for im in images:
        np.testing.assert_array_equal(back.predict(im), model.predict(im))
    assert back.threshold == model.threshold and back.rule == model.rule


def test_density_rule_is_eq_6_10():
    images, masks = _images(4)
    model = SkinClassifier().train(images, masks, rule="density")
    np.testing.assert_array_equal(model.score, model.histogram)
    assert model.histogram.sum() == pytest.approx(1.0)
    assert binary_scores([model.predict(im) for im in images], masks)["f1"] > 0.95


def test_self_training_from_person_masks_and_dilation_inside_the_person():
    images, masks = _images(4, seed=1)
    # "minimal clothing": the person is the skin patch plus a dark garment strip next to it
    persons = []
    for m in masks:
        p = m.copy()
        rows = np.nonzero(m.any(axis=1))[0]
        p[rows[-1] + 1 : rows[-1] + 6, :] = m.any(axis=0)
        persons.append(p)
    model = SkinClassifier().self_train(images, persons)
    for im, m, p in zip(images, masks, persons):
        pred = model.predict(im, p)
        assert not (pred & ~p).any()  # never outside the silhouette
        assert binary_scores(pred, m)["recall"] > 0.95


def test_ycrcb_baseline_on_a_skin_colour():
    img = np.array([[SKIN, (40, 60, 160)]], np.uint8)
    np.testing.assert_array_equal(ycrcb_skin(img), [[True, False]])


def test_skin_errors(tmp_path):
    images, masks = _images(2)
    with pytest.raises(SegmentationError, match="not trained"):
        SkinClassifier().predict(images[0])
    with pytest.raises(SegmentationError, match="cannot save .*not trained"):
        SkinClassifier().save(tmp_path / "x.npz")
    with pytest.raises(SegmentationError, match="need as many masks as images"):
        SkinClassifier().train(images, masks[:1])
    with pytest.raises(SegmentationError, match="the masks contain no skin pixels"):
        SkinClassifier().train(images, [np.zeros_like(m) for m in masks])
    with pytest.raises(SegmentationError, match=r"training mask 0: mask is \(4, 4\)"):
        SkinClassifier().train(images[:1], [np.zeros((4, 4), bool)])
    with pytest.raises(SegmentationError, match="rule must be 'density' or 'posterior'"):
        SkinClassifier().train(images, masks, rule="magic")
    with pytest.raises(SegmentationError, match="SkinClassifier.rule"):
        SkinClassifier(rule="magic")
    with pytest.raises(SegmentationError, match="score table"):
        SkinClassifier(np.zeros((8, 8)), score=np.zeros((4, 4)))
    with pytest.raises(SegmentationError, match="histogram must be"):
        SkinClassifier(np.zeros(8))
    with pytest.raises(SegmentationError, match="need one person mask per image"):
        SkinClassifier().self_train(images, [])
    with pytest.raises(SegmentationError, match="coverage must be in"):
        SkinClassifier().self_train(images, masks, coverage=0)
    with pytest.raises(SegmentationError, match="no foreground pixel falls in the skin box"):
        SkinClassifier().self_train(images, [np.zeros_like(m) for m in masks])
    with pytest.raises(SegmentationError, match="skin model file not found"):
        SkinClassifier.load(tmp_path / "missing.npz")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(SegmentationError, match="not a skin model file"):
        SkinClassifier.load(tmp_path / "bad.npz")
    np.savez(tmp_path / "other.npz", histogram=np.zeros((4, 4)), score=np.zeros((4, 4)),
             settings=np.array('{"format": "x", "version": 1}'))  # fmt: skip
    with pytest.raises(SegmentationError, match="expected 'studio.skin-model' version 1"):
        SkinClassifier.load(tmp_path / "other.npz")


def _load_pairs(folder: Path, names: list[str]):
    images, masks = [], []
    for name in names:
        im = cv2.cvtColor(cv2.imread(str(folder / "skin_val2019" / f"{name}.jpeg")), cv2.COLOR_BGR2RGB)
        m = cv2.imread(str(folder / "annotations" / f"{name}_skin_{name}.png"), cv2.IMREAD_GRAYSCALE)
        images.append(im)
        masks.append(m >= 128)
    return images, masks


def test_real_abdomen_masks_held_out(shared_data):
    """Train on 12 abdomen images, test on 12 others (227×227): F1 well above chance."""
    folder = shared_data / "skin" / "sfa_abd_val" / "coco-abdomen" / "val"
    names = sorted(p.stem for p in (folder / "skin_val2019").glob("*.jpeg"))[:24]
    images, masks = _load_pairs(folder, names)
    model = SkinClassifier().train(images[0::2], masks[0::2])
    scores = binary_scores([model.predict(im) for im in images[1::2]], masks[1::2])
    assert scores["f1"] > 0.75
