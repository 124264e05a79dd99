"""Eq. 5.5–5.6 on hand-computed pixels, at the documented boundaries.

The thresholds are inclusive where the docstrings say so: background iff ``‖N‖ < t^HSV``,
person iff ``N^S ≥ t^S``, the shadow gate ``μ^V·lo ≤ I^V ≤ μ^V·hi`` (and, on the 8-bit ratio
``round(200 I^V/μ^V)``, ``ceil(200 lo) ≤ ratio ≤ floor(200 hi)``). Values are chosen exact in
float32 (powers of two) so each case sits on its boundary, not near it.
"""

from __future__ import annotations

import numpy as np
import pytest

from studio.segment import SegmentationError, circular_mean, circular_std, hue_distance
from studio.segment.classify import BACKGROUND, PERSON, SHADOW, Thresholds, classify_pixels, normalized_difference
from studio.segment.hsv import check_rgb, fold_hue

F = np.float32
MEAN = (0.5, 0.5, 0.5)
T = Thresholds(hsv=6.0, saturation=8.0, value_ratio=(0.4, 0.95))

# (observed hsv, background mean, 1/σ, label under T); N = |hsv − mean| · (1/σ), hue folded
CASES = [
    ((0.5, 0.5, 0.4375), MEAN, (1, 1, 96), SHADOW),  # N^V = 0.0625·96 = 6 = t^HSV: not background
    ((0.5, 0.5, 0.437744140625), MEAN, (1, 1, 96), BACKGROUND),  # N^V = 5.9765625, ‖N‖² = 35.72 < 36
    ((0.5, 0.625, 0.4375), MEAN, (1, 64, 1), PERSON),  # N^S = 0.125·64 = 8 = t^S: person
    ((0.5, 0.609375, 0.4375), MEAN, (1, 64, 1), SHADOW),  # N^S = 7 < t^S, darker: shadow
    ((0.5, 0.6875, 0.4375), MEAN, (1, 64, 1), PERSON),  # N^S = 12
    ((0.98, 0.5, 0.4375), (0.01, 0.5, 0.5), (100, 1, 1), BACKGROUND),  # hue 0.03 apart round the circle: N^H = 3
    ((0.4, 0.5, 0.4375), (0.9, 0.5, 0.5), (14, 1, 1), SHADOW),  # 0.5 apart either way: N^H = 7
    ((0.5, 0.5, float(F(0.4) * F(0.5))), MEAN, (1, 1, 100), SHADOW),  # I^V = μ^V·lo exactly: in the gate
    ((0.5, 0.5, float(F(0.95) * F(0.5))), MEAN, (1, 1, 400), SHADOW),  # I^V = μ^V·hi exactly: in the gate
    ((0.5, 0.5, 0.1875), MEAN, (1, 1, 100), PERSON),  # ratio 0.375 < lo: too dark for a shadow
    ((0.5, 0.5, 0.484375), MEAN, (1, 1, 400), PERSON),  # ratio 0.96875 > hi: not darker
]


def _stack(cases):
    hsv, mean, inv, labels = (np.array([[c[i] for c in cases]]) for i in range(4))
    return hsv.astype(F), mean.astype(F), inv.astype(F), labels.astype(np.uint8)


def _ratio8(hsv, mean):
    return np.minimum(np.round(200.0 * hsv[..., 2].astype(float) / mean[..., 2]), 255).astype(np.uint8)


def test_normalized_difference_hand_computed():
    hsv = np.array([[[0.98, 0.9, 0.25], [0.2, 0.1, 0.75]]], F)
    mean = np.array([[[0.01, 0.1, 0.5], [0.6, 0.9, 0.5]]], F)
    inv = np.array([[[10, 2, 4], [10, 2, 4]]], F)
    # hue 0.03 and 0.4 around the circle; saturation 0.8 (not folded: only hue is circular); value 0.25
    np.testing.assert_allclose(normalized_difference(hsv, mean, inv), [[[0.3, 1.6, 1.0], [4.0, 1.6, 1.0]]],
                               rtol=1e-5)


def test_fold_hue_is_the_one_wrap_around():
    d = np.array([0.0, 0.25, 0.5, 0.75, 1.0], F)
    np.testing.assert_array_equal(fold_hue(d), [0.0, 0.25, 0.5, 0.25, 0.0])
    out = d.copy()
    assert fold_hue(out, out=out) is out and out[3] == F(0.25)
    d = hue_distance(np.float64(0.98), np.array([0.01, 0.5]))  # float32 out whatever comes in
    assert d.dtype == np.float32
    np.testing.assert_allclose(d, [0.03, 0.48], atol=1e-6)
    assert hue_distance(np.array([0.3]), np.float64(0.9)).dtype == np.float32


@pytest.mark.parametrize("with_ratio8", [False, True])
def test_classify_pixels_at_the_boundaries(with_ratio8):
    hsv, mean, inv, expected = _stack(CASES)
    ratio8 = _ratio8(hsv, mean) if with_ratio8 else None
    np.testing.assert_array_equal(classify_pixels(hsv, mean, inv, T, ratio8=ratio8), expected)


def test_ratio8_gate_bounds_are_inclusive_and_round_safely():
    """``ceil(200 lo)`` and ``floor(200 hi)`` although ``200·0.07 = 14.000000000000002`` and
    ``200·0.29 = 57.99999999999999`` in floating point; and an upper bound above 1 (brighter)."""
    n = 6
    hsv = np.full((1, n, 3), 0.5, F)
    hsv[..., 2] = 0.25  # N^V = 25 ≥ 6: never background; N^S = 0: shadow iff the gate passes
    mean = np.full((1, n, 3), 0.5, F)
    inv = np.full((1, n, 3), 100.0, F)
    ratio8 = np.array([[13, 14, 58, 59, 100, 100]], np.uint8)
    labels = classify_pixels(hsv, mean, inv, Thresholds(value_ratio=(0.07, 0.29)), ratio8=ratio8)
    np.testing.assert_array_equal(labels[0, :4], [PERSON, SHADOW, SHADOW, PERSON])
    ratio8 = np.array([[79, 80, 240, 241, 255, 0]], np.uint8)
    labels = classify_pixels(hsv, mean, inv, Thresholds(value_ratio=(0.4, 1.2)), ratio8=ratio8)
    np.testing.assert_array_equal(labels[0], [PERSON, SHADOW, SHADOW, PERSON, PERSON, PERSON])


def test_value_gate_switches():
    """(0, inf) is the plain eq. 5.5 (every non-background pixel without a saturation change is a
    shadow); (0.4, inf) keeps the lower gate only; (0, 0.95) the upper only."""
    hsv = np.array([[[0.5, 0.5, 0.1], [0.5, 0.5, 0.9], [0.5, 0.5, 0.3]]], F)
    mean = np.full_like(hsv, 0.5)
    inv = np.full_like(hsv, 100.0)
    for ratio8 in (None, _ratio8(hsv, mean)):
        got = [classify_pixels(hsv, mean, inv, Thresholds(value_ratio=vr), ratio8=ratio8)[0].tolist()
               for vr in [(0.0, np.inf), (0.4, np.inf), (0.0, 0.95)]]
        assert got == [[SHADOW, SHADOW, SHADOW], [PERSON, SHADOW, SHADOW], [SHADOW, PERSON, SHADOW]]


def test_threshold_validation_boundaries():
    assert Thresholds(hsv=0.5, saturation=0.25).hsv == 0.5  # any positive number, below 1 too
    with pytest.raises(SegmentationError, match=r"Thresholds.hsv: expected a positive number, got 0"):
        Thresholds(hsv=0)
    with pytest.raises(SegmentationError, match=r"Thresholds.saturation: expected a positive number"):
        Thresholds(saturation=0.0)
    assert Thresholds(value_ratio=(0.0, 0.01)).value_ratio == (0.0, 0.01)  # 0 <= lower < upper
    with pytest.raises(SegmentationError, match=r"expected 0 <= lower < upper, got \(0.5, 0.5\)"):
        Thresholds(value_ratio=(0.5, 0.5))


def test_check_rgb_names_the_argument_by_default():
    with pytest.raises(SegmentationError, match=r"^image: expected an \(H, W, 3\) RGB array"):
        check_rgb(np.zeros((4, 4)))


def test_circular_statistics_hand_computed():
    """Mean of 0.9 and 0.95 is 0.925 (atan2 gives −0.075, taken mod 1); float32 out; per pixel
    along ``axis``; weights summing below 1 are a weighted mean, not clamped to 1."""
    mean = circular_mean(np.array([0.9, 0.95]))
    assert mean.dtype == np.float32 and float(mean) == pytest.approx(0.925, abs=1e-6)
    hues = np.array([[0.1, 0.5], [0.2, 0.5]], F)
    std = circular_std(hues, np.array([0.15, 0.5], F), axis=0)
    assert std.dtype == np.float32 and std.shape == (2,)
    np.testing.assert_allclose(std, [0.05, 0.0], atol=1e-6)
    w = np.array([[0.25, 0.25], [0.25, 0.25]], F)
    std = circular_std(hues, np.array([0.15, 0.5], F), axis=0, weights=w)
    assert std.dtype == np.float32
    np.testing.assert_allclose(std, [0.05, 0.0], atol=1e-6)
