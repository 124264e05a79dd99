"""Truncated chamfer distance (eq. 4.4, 4.5) against a brute-force computation."""

import numpy as np
import pytest

from studio.cost import as_mask, symmetric_chamfer, truncated_chamfer, truncated_distance_map


def brute_distance_map(target: np.ndarray, tau: float) -> np.ndarray:
    """C^τ(T) by brute force: min Euclidean distance to any pixel of T, capped at τ."""
    h, w = target.shape
    yy, xx = np.mgrid[:h, :w]
    ty, tx = np.nonzero(target)
    if ty.size == 0:
        return np.full((h, w), tau)
    d = np.sqrt((yy[..., None] - ty) ** 2 + (xx[..., None] - tx) ** 2).min(axis=-1)
    return np.minimum(d, tau)


def brute_chamfer(s: np.ndarray, t: np.ndarray, tau: float, xi: float) -> float:
    n = s.sum()
    return 0.0 if n == 0 else float((brute_distance_map(t, tau) * s).sum() / n**xi)


def random_blobs(rng, shape=(24, 31), n=3) -> np.ndarray:
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    mask = np.zeros(shape, dtype=bool)
    for _ in range(n):
        cy, cx = rng.uniform(0, shape[0]), rng.uniform(0, shape[1])
        a, b = rng.uniform(2, 7, 2)
        mask |= ((yy - cy) / a) ** 2 + ((xx - cx) / b) ** 2 < 1
    return mask


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("xi", [1.0, 1.5])
def test_truncated_chamfer_matches_brute_force(seed, xi):
    rng = np.random.default_rng(seed)
    s, t = random_blobs(rng), random_blobs(rng)
    tau = 6.5
    assert truncated_chamfer(s, t, tau, xi) == pytest.approx(brute_chamfer(s, t, tau, xi), rel=1e-5, abs=1e-6)
    assert symmetric_chamfer(s, t, tau, xi) == pytest.approx(
        brute_chamfer(s, t, tau, xi) + brute_chamfer(t, s, tau, xi), rel=1e-5
    )


def test_distance_map_is_exact_euclidean_and_capped():
    rng = np.random.default_rng(7)
    t = random_blobs(rng)
    dist = truncated_distance_map(t, 5.0)
    assert dist.dtype == np.float32
    np.testing.assert_allclose(dist, brute_distance_map(t, 5.0), atol=1e-5)
    assert dist[t].max() == 0.0
    assert dist.max() == pytest.approx(5.0)


def test_mask5_is_close_to_precise():
    rng = np.random.default_rng(3)
    t = random_blobs(rng, (60, 80))
    exact = brute_distance_map(t, 20.0)
    approx = truncated_distance_map(t, 20.0, mask_size=5)
    # OpenCV's 5x5 chamfer mask is within ~2 % of the Euclidean distance.
    np.testing.assert_allclose(approx, exact, rtol=0.025, atol=1e-5)


def test_known_values():
    s = np.zeros((5, 10), dtype=bool)
    t = np.zeros((5, 10), dtype=bool)
    t[:, :2] = True
    s[2, 5] = True  # 4 px from column 1
    s[2, 9] = True  # 8 px away, capped at tau = 6
    assert truncated_chamfer(s, t, 6.0) == pytest.approx((4 + 6) / 2)
    assert truncated_chamfer(s, t, 6.0, 1.5) == pytest.approx((4 + 6) / 2**1.5)
    # reverse: the 10 T pixels (rows 0-4, columns 0-1) measured to the nearer pixel (2, 5)
    rows = np.arange(5)[:, None]
    cols = np.array([0, 1])[None, :]
    expected = np.sqrt((rows - 2) ** 2 + (cols - 5) ** 2).mean()
    assert truncated_chamfer(t, s, 6.0) == pytest.approx(expected, rel=1e-6)
    # inside pixels cost nothing
    assert truncated_chamfer(t, t, 6.0) == 0.0


def test_empty_masks():
    t = np.zeros((8, 8), dtype=bool)
    s = np.zeros((8, 8), dtype=bool)
    s[3, 3] = True
    # empty source: 0 by convention; empty target: every source pixel costs tau
    assert truncated_chamfer(t, s, 4.0) == 0.0
    assert truncated_chamfer(s, t, 4.0) == 4.0
    np.testing.assert_array_equal(truncated_distance_map(t, 4.0), np.full((8, 8), 4.0, np.float32))


def test_integer_masks_are_accepted():
    rng = np.random.default_rng(1)
    s, t = random_blobs(rng), random_blobs(rng)
    assert truncated_chamfer(s.astype(np.uint8) * 255, t.astype(np.int32), 5.0) == truncated_chamfer(s, t, 5.0)


def test_bad_inputs():
    m = np.zeros((4, 5), dtype=bool)
    with pytest.raises(ValueError, match=r"target: mask size \(4, 6\) .* expected \(4, 5\)"):
        truncated_chamfer(m, np.zeros((4, 6), bool), 3.0)
    with pytest.raises(ValueError, match="source: expected a bool .* got dtype float64; threshold"):
        truncated_chamfer(m.astype(float), m, 3.0)
    with pytest.raises(ValueError, match=r"mask: expected a 2-D \(H, W\) mask"):
        as_mask(np.zeros((2, 3, 3), bool))
    with pytest.raises(ValueError, match="tau: .* finite positive"):
        truncated_chamfer(m, m, float("nan"))
    with pytest.raises(ValueError, match="tau: .* finite positive"):
        truncated_distance_map(m, 0.0)
    with pytest.raises(ValueError, match="xi: .* finite and positive"):
        truncated_chamfer(m, m, 3.0, xi=-1.0)
    with pytest.raises(ValueError, match="mask_size: expected one of"):
        truncated_distance_map(m, 3.0, mask_size=7)
