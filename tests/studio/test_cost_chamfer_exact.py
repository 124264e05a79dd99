"""Eq. 4.4–4.5 on hand-computed masks: exact values, OpenCV's documented chamfer weights,
float64 accumulation and the documented argument limits.

OpenCV documents the 3×3 and 5×5 masks of ``DIST_L2`` (Borgefors): a = 0.955, b = 1.3693 for
3×3 and a = 1, b = 1.4, c = 2.1969 for 5×5 (a: edge step, b: diagonal, c: knight move);
``"precise"`` is the exact Euclidean distance (sqrt(5) = 2.2360680 for a knight move).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from studio.cost import symmetric_chamfer, truncated_chamfer, truncated_distance_map

#: a float32-exact τ whose repeated float32 accumulation rounds (ulp 2^-19 above 16):
#: a sum accumulated in float64 gives n·τ exactly, one accumulated in float32 does not.
TAU_EXACT = 1.0 + 2.0**-20


def _point(shape=(9, 9), at=(4, 4)) -> np.ndarray:
    m = np.zeros(shape, bool)
    m[at] = True
    return m


@pytest.mark.parametrize(
    "mask_size, edge, diagonal, knight",
    [(3, 0.955, 1.3693, 0.955 + 1.3693), (5, 1.0, 1.4, 2.1969), ("precise", 1.0, math.sqrt(2), math.sqrt(5))],
)
def test_distance_masks_give_opencvs_documented_weights(mask_size, edge, diagonal, knight):
    dist = truncated_distance_map(_point(), 10.0, mask_size=mask_size)
    assert dist[4, 4] == 0.0
    assert dist[4, 5] == pytest.approx(edge, abs=1e-6)
    assert dist[5, 5] == pytest.approx(diagonal, abs=1e-6)
    assert dist[5, 6] == pytest.approx(knight, abs=1e-6)
    # the same weights reach the chamfer terms (source: the knight-move pixel alone)
    source = _point(at=(5, 6))
    assert truncated_chamfer(source, _point(), 10.0, mask_size=mask_size) == pytest.approx(knight, abs=1e-6)
    assert symmetric_chamfer(source, _point(), 10.0, mask_size=mask_size) == pytest.approx(2 * knight, abs=1e-6)


def test_sums_are_accumulated_in_float64():
    """A 300×400 source, all of it beyond τ of a 2-pixel target: every pixel costs τ, so the
    mean is τ to the last bit (a float32 accumulation is off in the 7th digit)."""
    target = np.zeros((300, 400), bool)
    target[0, 0] = target[299, 399] = True
    source = np.zeros_like(target)
    source[50:250, 50:350] = True
    assert truncated_chamfer(source, target, TAU_EXACT) == TAU_EXACT
    # an empty target: C^τ is τ everywhere, as float32 (the documented dtype)
    empty = truncated_distance_map(np.zeros((300, 400), bool), 0.1)
    assert empty.dtype == np.float32
    assert truncated_chamfer(source, np.zeros_like(target), 0.1) == float(np.float32(0.1))


def test_tau_and_xi_limits():
    """τ: any finite positive number of pixels (sub-pixel included); ξ: finite and > 0 (0 refused)."""
    s, t = _point(at=(4, 5)), _point()
    assert truncated_chamfer(s, t, 0.5) == 0.5
    assert truncated_chamfer(s, t, 1.0) == 1.0
    with pytest.raises(ValueError, match=r"^xi: the normalisation exponent must be finite and positive"):
        truncated_chamfer(s, t, 3.0, xi=0.0)
    with pytest.raises(ValueError, match=r"^tau: the truncation threshold must be a finite positive number"):
        truncated_chamfer(s, t, 0.0)


def test_distance_map_names_its_argument():
    with pytest.raises(ValueError, match=r"^mask: expected a 2-D \(H, W\) mask"):
        truncated_distance_map(np.zeros((2, 3, 3), bool), 3.0)


def test_precise_distances_do_not_depend_on_opencv_threads():
    """OpenCV's exact transform rounds some pixels an ulp differently with its thread count
    (worker processes run one thread, a plain process all cores); the maps are snapped to the
    correctly rounded sqrt of the integer squared distance, scipy's exact EDT to the bit."""
    import cv2
    from scipy.ndimage import distance_transform_edt

    rng = np.random.default_rng(0)
    mask = rng.random((240, 320)) < 0.002
    before = cv2.getNumThreads()
    try:
        maps = []
        for n in (4, 1):
            cv2.setNumThreads(n)
            maps.append(truncated_distance_map(mask, 1e4))
    finally:
        cv2.setNumThreads(before)
    np.testing.assert_array_equal(maps[0], maps[1])
    np.testing.assert_array_equal(maps[1], distance_transform_edt(~mask).astype(np.float32))
    assert maps[1].max() > 20 and maps[1].dtype == np.float32
