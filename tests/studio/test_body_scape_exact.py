"""SCAPE algebra (App. C, eq. 3.17, 3.23) against hand-written and closed-form references.

The edge operator of two triangles is written out entry by entry; the pose regression's default
(ridge 1e-3, intercept fixed to I) is the ridge solution of the augmented least-squares system
``[X; √λ I] c = [Q − I; 0]`` (numpy.linalg.lstsq); batched Procrustes recovers known rotations.
"""

from __future__ import annotations

import numpy as np

from calibration.rotation import rotvec_to_matrix
from studio.body import scape


def test_edge_operator_written_out():
    """Two triangles (0, 1, 2), (0, 2, 3) of 5 vertices (4 unused): rows edge-major, ``k·F + f``."""
    G = scape.edge_operator(np.array([[0, 1, 2], [0, 2, 3]]), 5)
    want = np.array([
        [-1, 1, 0, 0, 0],  # edge 0 of triangle 0: y1 − y0
        [-1, 0, 1, 0, 0],  # edge 0 of triangle 1: y2 − y0
        [-1, 0, 1, 0, 0],  # edge 1 of triangle 0: y2 − y0
        [-1, 0, 0, 1, 0],  # edge 1 of triangle 1: y3 − y0
    ], float)
    assert G.shape == (4, 5)
    np.testing.assert_array_equal(G.toarray(), want)


def test_pose_regression_default_is_ridge_with_identity_intercept():
    rng = np.random.default_rng(11)
    F, J, N = 3, 15, 9
    pairs = rng.integers(0, J, size=(F, 2))
    rv = rng.normal(scale=0.3, size=(N, J, 3))
    Q = np.eye(3) + rng.normal(scale=0.2, size=(N, F, 3, 3))
    coef = scape.fit_pose_deformation(Q, rv, pairs)
    lam = 1e-3
    X = scape.pose_features(rv, pairs)[..., :6]  # (N, F, 6)
    for f in range(F):
        A = np.vstack([X[:, f], np.sqrt(lam) * np.eye(6)])
        b = np.vstack([Q[:, f].reshape(N, 9) - np.eye(3).ravel(), np.zeros((6, 9))])
        slopes = np.linalg.lstsq(A, b, rcond=None)[0]
        np.testing.assert_allclose(coef[f, :6], slopes, rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(coef[f, 6], np.eye(3).ravel())
    # the ridge is felt: without it the slopes differ
    assert np.abs(scape.fit_pose_deformation(Q, rv, pairs, ridge=0.0) - coef).max() > 1e-6


def test_procrustes_on_a_batch():
    rng = np.random.default_rng(12)
    src = rng.normal(size=(2, 20, 3))
    R = rotvec_to_matrix(np.array([[0.3, -1.2, 0.5], [-2.0, 0.4, 0.1]]))
    tgt = np.einsum("bij,bnj->bni", R, src) + np.array([[[1.0, 2.0, 3.0]], [[-4.0, 0.0, 5.0]]])
    np.testing.assert_allclose(scape.procrustes_rotation(src, tgt), R, atol=1e-10)
