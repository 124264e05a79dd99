"""Morphology (§5.5.1) on real frames: the box-filter median equals OpenCV's median filter bit for bit."""

from itertools import islice

import cv2
import numpy as np
import pytest

from calibration.sampling import iter_video_frames
from studio.segment import PERSON, SHADOW, BackgroundModel, Morphology, clean_labels
from studio.segment import morphology as morph
from studio.segment.morphology import binary_median


@pytest.fixture(scope="module")
def raw_labels(shared_data):
    """Raw (before morphology) labels of real UU frames, fixed and adaptive model, two cameras."""
    root = shared_data / "multiview" / "uu_infomcv_4cam_person"
    if not root.is_dir():
        pytest.skip(f"{root} not found")
    out = []
    for cam in ("cam2", "cam3"):
        model = BackgroundModel.fit([f for _, f in islice(iter_video_frames(root / cam / "background.avi"), 4)])
        for _, frame in islice(iter_video_frames(root / cam / "video.avi", step=50), 2, 5):  # frames 100, 150, 200
            out += [model.classify_raw(frame), model.apply(frame, clean=False)]
    return out


def test_binary_median_is_opencvs_median_on_real_masks(raw_labels):
    for labels in raw_labels:
        for mask in ((labels > 0).view(np.uint8), (labels == PERSON).view(np.uint8)):
            for aperture in (3, 5, 7, 17):  # 17² > 255: the 16-bit count
                np.testing.assert_array_equal(binary_median(mask, aperture), cv2.medianBlur(mask, aperture))
    assert 0.01 < np.mean([(lab == PERSON).mean() for lab in raw_labels]) < 0.2  # masks with a person in them


@pytest.mark.parametrize("settings", [Morphology(), Morphology(median=7, open_radius=2, close_radius=0)])
def test_clean_labels_equals_the_median_blur_reference(raw_labels, settings, monkeypatch):
    fast = [clean_labels(lab, settings) for lab in raw_labels]
    monkeypatch.setattr(morph, "binary_median", cv2.medianBlur)
    for lab, got in zip(raw_labels, fast):
        np.testing.assert_array_equal(got, clean_labels(lab, settings))
    shares = np.array([[(g == v).mean() for v in (PERSON, SHADOW)] for g in fast])
    assert (shares[:, 0] > 0.01).all() and (shares[:, 1] > 0.001).any()  # person and shadow both present


def test_binary_median_by_hand():
    mask = np.zeros((7, 7), np.uint8)
    mask[2:5, 2:5] = 1  # 9 ones: a 5×5 window centred on the block holds 9 < 13
    assert binary_median(mask, 5).sum() == 0
    assert binary_median(mask, 3).sum() == 9 - 4  # the 3×3 median erodes the block's corners
    mask[0, :] = 1  # an edge row: replicated, as medianBlur does
    np.testing.assert_array_equal(binary_median(mask, 3), cv2.medianBlur(mask, 3))


def _hand(width: int, gap: int, noise: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Labels of a palm (disc of radius 14 px) with four fingers ``width`` px wide, ``gap`` px apart and 16 px
    above the palm; the masks of those fingers' part above the palm and of the gaps between them."""
    labels = np.zeros((80, 80), np.uint8)
    cv2.circle(labels, (40, 50), 14, int(PERSON), -1)
    fingers = np.zeros((80, 80), bool)
    for k in range(4):
        fingers[18:37, 30 + k * (width + gap) : 30 + k * (width + gap) + width] = True
    labels[fingers] = PERSON
    above = np.zeros_like(fingers)
    above[18:34, 30 : 30 + 4 * width + 3 * gap] = True
    if noise:  # isolated pixels of sensor noise away from the hand
        rng = np.random.default_rng(0)
        labels[rng.integers(0, 12, 30), rng.integers(0, 80, 30)] = PERSON
    return labels, fingers & above, above & ~fingers


def test_studio_morphology_keeps_the_fingers_the_default_rounds_off():
    from studio.segment import STUDIO_MORPHOLOGY

    def person(labels, m):
        return clean_labels(labels, m) == PERSON

    labels, fingers, _ = _hand(width=2, gap=3)  # fingers of a person ~3 m from a 656×490 camera
    assert not (person(labels, Morphology()) & fingers).any()  # the 5 px median erases them
    assert (person(labels, STUDIO_MORPHOLOGY) & fingers).sum() / fingers.sum() > 0.9
    labels, fingers, gaps = _hand(width=3, gap=2)
    assert (person(labels, Morphology()) & gaps).sum() / gaps.sum() > 0.8  # ... or fills the gaps between them
    assert not (person(labels, STUDIO_MORPHOLOGY) & gaps).any()
    assert (person(labels, STUDIO_MORPHOLOGY) & fingers).sum() / fingers.sum() > 0.9
    noisy, _, _ = _hand(width=2, gap=3, noise=True)
    for m in (Morphology(), STUDIO_MORPHOLOGY):  # isolated noise goes either way
        assert not person(noisy, m)[:12].any()
