"""The compiled view numerators (studio.cost.view_terms) against the exact definition and the
OpenCV reference path."""

import math

import numpy as np
import pytest
from scipy import ndimage

from studio.cost import SilhouetteTarget, silhouette_cost
from studio.cost import silhouette as S
from studio.cost.view_terms import view_numerators


def blobs(rng, shape, n, r):
    """Union of ``n`` random ellipses of semi-axes up to ``r`` (some cut by the border)."""
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    out = np.zeros(shape, bool)
    for _ in range(n):
        cy, cx = rng.uniform(-5, shape[0] + 5), rng.uniform(-5, shape[1] + 5)
        a, b = rng.uniform(1.5, r, 2)
        out |= ((yy - cy) / a) ** 2 + ((xx - cx) / b) ** 2 < 1
    return out


def exact_numerators(model, observed, dist_obs, tau):
    """Eq. 4.4's numerators from the exact Euclidean transform of the whole image (SciPy),
    each distance correctly rounded to float32 and truncated at τ as the cost does."""
    if not model.any():
        return 0.0, tau * int(observed.sum()), 0
    d = np.sqrt(np.rint(ndimage.distance_transform_edt(~model) ** 2)).astype(np.float32)
    d = np.minimum(d, np.float32(tau))
    forward = float(np.sum(dist_obs, where=model, dtype=np.float64))
    backward = float(np.sum(d, where=observed, dtype=np.float64))
    return forward, backward, int(model.sum())


@pytest.mark.parametrize("seed", range(6))
def test_numerators_equal_the_exact_transform(seed):
    """Random blobs, τ from 1.5 to 33 px: every term equals the whole-image exact transform
    (to the order of the float64 sums)."""
    rng = np.random.default_rng(seed)
    checked = 0
    for _ in range(25):
        shape = (int(rng.integers(8, 120)), int(rng.integers(8, 120)))
        observed = blobs(rng, shape, int(rng.integers(0, 5)), 25)
        model = blobs(rng, shape, int(rng.integers(0, 5)), 25)
        tau = float(rng.choice([1.5, 4.0, 7.25, 20.0, 33.0]))  # float32-exact: beyond the window τ counts in float64
        target = SilhouetteTarget.build([observed], tau=tau)
        got = view_numerators(model, target.masks[0], target.distance_maps[0], tau, target.counts[0])
        want = exact_numerators(model, observed, target.distance_maps[0], tau)
        assert got[2] == want[2]
        np.testing.assert_allclose(got[:2], want[:2], rtol=1e-12, atol=1e-9)
        checked += want[1] > 0
    assert checked >= 10  # most draws had observed pixels to explain


def test_a_pixel_exactly_tau_away_and_one_beyond():
    """Observed pixels at 3, 5 (= τ) and 6 px from a one-pixel model: 3 + 5 + 5."""
    model = np.zeros((20, 30), bool)
    model[10, 10] = True
    observed = np.zeros_like(model)
    observed[10, 13] = observed[13, 14] = observed[10, 16] = True  # 3, 5, 6 px away
    target = SilhouetteTarget.build([observed], tau=5.0)
    fwd, bwd, n = view_numerators(model, target.masks[0], target.distance_maps[0], 5.0, 3)
    assert (fwd, bwd, n) == (3.0, 13.0, 1)
    # an observed pixel outside the model's window (> ceil(τ) away) counts τ
    observed[2, 28] = True
    target = SilhouetteTarget.build([observed], tau=5.0)
    assert view_numerators(model, target.masks[0], target.distance_maps[0], 5.0, 4)[1] == 18.0


def test_empty_model_and_empty_observation():
    rng = np.random.default_rng(3)
    observed = blobs(rng, (40, 50), 3, 12)
    target = SilhouetteTarget.build([observed], tau=7.0)
    n_obs = target.counts[0]
    assert n_obs > 0
    assert view_numerators(np.zeros((40, 50), bool), target.masks[0], target.distance_maps[0], 7.0, n_obs) \
        == (0.0, 7.0 * n_obs, 0)
    empty = SilhouetteTarget.build([np.zeros((40, 50), bool)], tau=7.0)
    fwd, bwd, n = view_numerators(observed, empty.masks[0], empty.distance_maps[0], 7.0, 0)
    assert (fwd, bwd, n) == (7.0 * n_obs, 0.0, n_obs)  # every model pixel τ from nothing


@pytest.mark.parametrize("level", [0, 1, 2])
def test_silhouette_cost_equals_the_opencv_reference_path(level, monkeypatch):
    """silhouette_cost through the kernel equals the NumPy/OpenCV path: OpenCV's precise
    transform rounds some distances one float32 ulp off (its square root is approximate), so
    the sums agree to 1e-7 relative, not to the last bit."""
    rng = np.random.default_rng(10 + level)
    observed = [blobs(rng, (150, 170), 4, 40) for _ in range(3)]
    target = SilhouetteTarget.build(observed, tau=20.0, level=level, names=["a", "b", "c"])
    models = [blobs(rng, target.image_size, 4, 40 >> level) for _ in range(3)]
    fast = silhouette_cost(target, models)
    monkeypatch.setattr(S, "_score_view", S._score_view_reference)
    ref = silhouette_cost(target, models)
    assert ref.total > 1.0
    np.testing.assert_array_equal(fast.model_counts, ref.model_counts)
    np.testing.assert_allclose(fast.model_to_observed, ref.model_to_observed, rtol=1e-7)
    np.testing.assert_allclose(fast.observed_to_model, ref.observed_to_model, rtol=1e-7)


def test_other_distance_masks_keep_the_reference_path():
    """The 5×5 chamfer mask is approximate: the kernel (exact) is not used for it."""
    rng = np.random.default_rng(7)
    observed, model = blobs(rng, (60, 70), 3, 15), blobs(rng, (60, 70), 3, 15)
    target = SilhouetteTarget.build([observed], tau=9.0, mask_size=5)
    assert S._score_view(target, 0, model) == S._score_view_reference(target, 0, model)
    exact = SilhouetteTarget.build([observed], tau=9.0)
    assert S._score_view(exact, 0, model) != S._score_view_reference(target, 0, model)
    assert math.isfinite(S._score_view(exact, 0, model)[1])


def test_box_by_words_equals_box_by_pixels():
    """The model's box scanned 8 pixels at a time (width a multiple of 8) equals the
    pixel-by-pixel scan, for masks whose extreme pixels sit at every byte of a word."""
    from studio.cost.view_terms import _NO_WORDS, _bbox

    rng = np.random.default_rng(4)
    for _ in range(200):
        mask = np.zeros((int(rng.integers(1, 30)), 8 * int(rng.integers(1, 12))), bool)
        for _ in range(int(rng.integers(0, 4))):
            mask[rng.integers(0, mask.shape[0]), rng.integers(0, mask.shape[1])] = True
        got = _bbox(mask, mask.view(np.uint64))
        assert got == _bbox(mask, _NO_WORDS)
        if mask.any():
            rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
            assert got == (rows[0], rows[-1] + 1, cols[0], cols[-1] + 1)
        else:
            assert got == (0, 0, 0, 0)
