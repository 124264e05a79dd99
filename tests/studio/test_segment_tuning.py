"""Operating-point protocol helpers (studio.segment.tuning): per-frame CDnet counts, blocked folds
with a gap, and the pick rule — on numbers worked out by hand."""

import numpy as np
import pytest

from studio.segment import SegmentationError
from studio.segment.metrics import cdnet_scores
from studio.segment.tuning import (
    blocked_folds,
    cdnet_counts,
    fold_tuning_frames,
    pick_operating_point,
    scores_from_counts,
)


def test_blocked_folds_cdnet_evaluation_split():
    """700–1200 in blocks of 50: ten blocks (1200 joins 1150–1199), alternating."""
    a, b = blocked_folds(range(700, 1201), block=50)
    assert (len(a), len(b)) == (250, 251)
    assert a[:2] == [700, 701] and a[49:51] == [749, 800] and a[-1] == 1149
    assert b[0] == 750 and b[-51:][0] == 1150 and b[-1] == 1200
    # every 4th frame: the same blocks by frame number
    a4, b4 = blocked_folds(range(700, 1201, 4), block=50)
    assert a4[:3] == [700, 704, 708] and 748 in a4 and 752 in b4 and b4[-1] == 1200
    assert len(a4) + len(b4) == 126


def test_blocked_folds_tail_and_three_folds():
    # 0..119: the 20-frame tail (< half a block) joins block 1
    assert [len(f) for f in blocked_folds(range(120), block=50)] == [50, 70]
    # 0..129: a 30-frame tail is a block of its own (fold 0 again)
    assert [len(f) for f in blocked_folds(range(130), block=50)] == [80, 50]
    assert [f[0] for f in blocked_folds(range(90), block=10, n_folds=3)] == [0, 10, 20]


def test_blocked_folds_rejects_bad_input():
    with pytest.raises(SegmentationError, match="block >= 1"):
        blocked_folds(range(10), block=0)
    with pytest.raises(SegmentationError, match="cannot make 2 folds"):
        blocked_folds([5])
    with pytest.raises(SegmentationError, match="leave a fold empty"):
        blocked_folds(range(30), block=50)


def test_fold_tuning_frames_gap():
    """Base 470–699 plus the other fold, without frames within 10 of a scored frame."""
    folds = blocked_folds(range(700, 1201), block=50)
    t0 = fold_tuning_frames(range(470, 700), folds, 0, gap=10)
    # base loses 690-699; fold 2's blocks 750-799 ... keep 760-789 (30 each), 1150-1200 keeps 1160-1200
    assert len(t0) == 220 + 4 * 30 + 41
    assert 689 in t0 and 690 not in t0 and 759 not in t0 and 760 in t0 and 789 in t0 and 790 not in t0
    assert not set(t0) & set(folds[0])
    t1 = fold_tuning_frames(range(470, 700), folds, 1, gap=10)
    assert len(t1) == 230 + 40 + 4 * 30
    assert 739 in t1 and 740 not in t1 and 810 in t1 and 1139 in t1 and 1140 not in t1
    # no gap: base and the whole other fold
    assert len(fold_tuning_frames(range(470, 700), folds, 0)) == 230 + 251


def test_pick_operating_point_rule():
    pts = [("a", 0.97, 0.44), ("b", 0.95, 0.30), ("c", 0.96, 0.31), ("d", 0.95, 0.10), ("e", 0.90, 0.0)]
    assert pick_operating_point(pts, 0.30) == ("b", 0.95, 0.30)  # limit inclusive, tie to the first listed
    assert pick_operating_point(pts) == ("a", 0.97, 0.44)
    assert pick_operating_point(pts, 0.05) == ("e", 0.90, 0.0)
    assert pick_operating_point(pts, -0.1) is None
    assert pick_operating_point([("n", 0.99, float("nan"))], 0.3) is None


def test_counts_sum_to_cdnet_scores():
    """Counts summed over frames give cdnet_scores' figures on the same frames."""
    rng = np.random.default_rng(3)
    truths = [rng.choice(np.array([0, 50, 85, 170, 255], np.uint8), size=(30, 40), p=[0.5, 0.15, 0.05, 0.05, 0.25])
              for _ in range(3)]  # fmt: skip
    labels = [rng.integers(0, 3, size=(30, 40), dtype=np.uint8) for _ in range(3)]
    roi = np.zeros((30, 40), bool)
    roi[2:, 5:] = True
    counts = np.stack([cdnet_counts(lab, t, roi) for lab, t in zip(labels, truths)])
    got, want = scores_from_counts(counts), cdnet_scores(labels, truths, roi)
    for key in ("recall", "precision", "f_measure", "fpr_shadow", "shadow_pixels", "shadow_precision", "shadow_recall"):
        assert got[key] == pytest.approx(want[key], abs=1e-12)
    assert 0.2 < got["f_measure"] < 0.6 and got["shadow_pixels"] > 300
    # one hand-made frame: 2 motion pixels found, 1 missed, 1 static labelled person, 1 of 2 shadows as person
    t = np.array([[255, 255, 255, 0, 50, 50, 170]], np.uint8)
    lab = np.array([[1, 1, 0, 1, 1, 2, 1]], np.uint8)
    c = cdnet_counts(lab, t)
    assert c.tolist() == [2, 2, 1, 2, 1, 1, 0, 1]  # the shadow labelled person counts as a false positive too
    s = scores_from_counts(c)
    assert (s["recall"], s["precision"], s["fpr_shadow"]) == pytest.approx((2 / 3, 0.5, 0.5))
    with pytest.raises(SegmentationError, match="expected"):
        scores_from_counts(np.zeros(5))
    with pytest.raises(SegmentationError, match="differ in shape"):
        cdnet_counts(lab, t[:, :3])
