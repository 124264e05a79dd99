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
