"""Lens distortion against independent derivations: OpenCV's projectPoints for the forward model,
central differences for the analytic Jacobian that Newton's inversion uses, closed forms for the
fisheye fold angle.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration.distortion import (
    _fisheye_poly,
    _fisheye_slope,
    _radial_tangential,
    distort_fisheye,
    distort_normalized,
    fisheye_fold_angle,
    fisheye_theta,
    undistort_fisheye,
    undistort_normalized,
)

# every coefficient non-zero: k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4 τx τy
FULL = np.array([-0.28, 0.09, 0.0012, -0.0021, -0.015, 0.05, -0.01, 0.004, 0.002, -0.001, 0.0015, -0.0007,
                 0.01, -0.015])


def _grid(n=7, half=0.45):
    g = np.linspace(-half, half, n)
    return np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)


@pytest.mark.parametrize("n", [4, 5, 8, 12, 14])
def test_distort_matches_opencv_project_points(n):
    xy = _grid()
    X = np.c_[xy, np.ones(len(xy))]
    uv, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), np.eye(3), FULL[:n])
    np.testing.assert_allclose(distort_normalized(xy, FULL[:n]), uv.reshape(-1, 2), rtol=0, atol=1e-12)


def test_analytic_jacobian_equals_central_differences():
    """``_radial_tangential(..., jacobian=True)`` returns ∂(xd, yd)/∂(x, y), the derivative
    Newton's inversion divides by: each entry against a central difference (h = 1e-6)."""
    xy = _grid(9, 0.6)
    d = FULL.copy()
    x, y = xy[:, 0], xy[:, 1]
    xd, yd, j11, j12, j21, j22 = _radial_tangential(x, y, d, jacobian=True)
    np.testing.assert_array_equal(np.stack([xd, yd]), np.stack(_radial_tangential(x, y, d)))
    h = 1e-6
    dxp, dyp = _radial_tangential(x + h, y, d)
    dxm, dym = _radial_tangential(x - h, y, d)
    np.testing.assert_allclose(j11, (dxp - dxm) / (2 * h), rtol=0, atol=1e-8)
    np.testing.assert_allclose(j21, (dyp - dym) / (2 * h), rtol=0, atol=1e-8)
    dxp, dyp = _radial_tangential(x, y + h, d)
    dxm, dym = _radial_tangential(x, y - h, d)
    np.testing.assert_allclose(j12, (dxp - dxm) / (2 * h), rtol=0, atol=1e-8)
    np.testing.assert_allclose(j22, (dyp - dym) / (2 * h), rtol=0, atol=1e-8)


def test_newton_inversion_converges_quadratically():
    """Strong distortion, five Newton steps: back to 1e-12 (a wrong Jacobian converges linearly
    at best). Agrees with ``cv2.undistortPoints`` run to the same tolerance."""
    xy = _grid(9, 0.6)
    dist = FULL[:8]
    xy_d = distort_normalized(xy, dist)
    np.testing.assert_allclose(undistort_normalized(xy_d, dist, iterations=5), xy, rtol=0, atol=1e-12)
    cv = cv2.undistortPoints(xy_d[:, None], np.eye(3), dist,
                             criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15))
    np.testing.assert_allclose(undistort_normalized(xy_d, dist), cv.reshape(-1, 2), rtol=0, atol=1e-9)
    np.testing.assert_allclose(undistort_normalized(distort_normalized(xy, FULL), FULL), xy, rtol=0, atol=1e-12)


def test_fisheye_slope_is_the_derivative_and_the_fold_is_where_it_vanishes():
    k = np.array([-0.5, 0.0, 0.0, 0.0])  # θ_d = θ − θ³/2: slope 1 − 1.5 θ², zero at θ = √(2/3)
    theta = np.linspace(0.0, 1.5, 31)
    np.testing.assert_allclose(_fisheye_slope(theta, k), 1.0 - 1.5 * theta**2, rtol=0, atol=1e-15)
    kk = np.array([0.1, -0.02, 0.003, -0.0004])
    h = 1e-6
    np.testing.assert_allclose(_fisheye_slope(theta, kk),
                               (_fisheye_poly(theta + h, kk) - _fisheye_poly(theta - h, kk)) / (2 * h), atol=1e-8)
    grid = np.linspace(0.0, np.pi, 4097)
    expected = grid[np.flatnonzero(1.0 - 1.5 * grid**2 > 0)[-1]]  # last grid angle before the turn
    assert fisheye_fold_angle(k) == expected
    assert expected < np.sqrt(2 / 3) <= expected + np.pi / 4096
    assert fisheye_fold_angle(np.zeros(4)) == np.pi


def test_fisheye_round_trip_and_opencv():
    k = np.array([-0.011603, 0.053991, -0.075427, 0.036664])  # a real lens (Kalibr EuRoC)
    xy = _grid(7, 1.5)
    xy_d = distort_fisheye(xy, k)
    ref = cv2.fisheye.distortPoints(xy[:, None], np.eye(3), k).reshape(-1, 2)
    np.testing.assert_allclose(xy_d, ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(undistort_fisheye(xy_d, k), xy, rtol=0, atol=1e-12)
    theta = np.arctan(np.hypot(xy[:, 0], xy[:, 1]))
    np.testing.assert_allclose(fisheye_theta(_fisheye_poly(theta, k), k), theta, rtol=0, atol=1e-14)
    # beyond the fold no angle maps there: NaN; equidistant (k = 0): θ = θ_d up to π
    kf = np.array([-0.5, 0.0, 0.0, 0.0])
    top = _fisheye_poly(np.array(fisheye_fold_angle(kf)), kf)
    assert np.isnan(fisheye_theta(np.array([top * 1.01]), kf)[0])
    assert fisheye_theta(np.array([top]), kf)[0] == pytest.approx(fisheye_fold_angle(kf), abs=1e-3)
    np.testing.assert_array_equal(fisheye_theta(np.array([0.5, np.pi, 3.2]), np.zeros(4)), [0.5, np.pi, np.nan])


@pytest.mark.parametrize("tau", [(0.02, 0.0), (0.0, -0.03)])
def test_a_sensor_tilt_about_one_axis_only(tau):
    """τx alone or τy alone is a tilt too (OpenCV's 14-coefficient model)."""
    xy = _grid()
    dist = np.r_[FULL[:12], tau]
    X = np.c_[xy, np.ones(len(xy))]
    uv, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), np.eye(3), dist)
    np.testing.assert_allclose(distort_normalized(xy, dist), uv.reshape(-1, 2), rtol=0, atol=1e-12)
    np.testing.assert_allclose(undistort_normalized(uv.reshape(-1, 2), dist), xy, rtol=0, atol=1e-12)


def test_single_points_and_points_on_an_axis_are_inverted_too():
    """One point is a batch of one (not returned as it came); with radial distortion only, a
    point on the x axis has no y step at all and still converges in x."""
    dist = np.array([-0.3, 0.1, 0.0, 0.0, 0.0])
    xy = np.array([[0.5, 0.0]])
    xy_d = distort_normalized(xy, dist)
    assert xy_d[0, 1] == 0.0 and xy_d[0, 0] != 0.5
    np.testing.assert_allclose(undistort_normalized(xy_d, dist), xy, rtol=0, atol=1e-12)
    axis = np.array([[0.1, 0.0], [0.3, 0.0], [0.6, 0.0], [0.0, -0.5]])
    np.testing.assert_allclose(undistort_normalized(distort_normalized(axis, dist), dist), axis, rtol=0, atol=1e-12)
    k = np.array([-0.011603, 0.053991, -0.075427, 0.036664])
    one = np.array([[0.7, -0.4]])
    ref = cv2.fisheye.distortPoints(one[:, None], np.eye(3), k).reshape(-1, 2)
    np.testing.assert_allclose(distort_fisheye(one, k), ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(undistort_fisheye(ref, k), one, rtol=0, atol=1e-12)


def test_fisheye_boundaries():
    """90° off-axis exactly is already beyond a pinhole image plane (NaN, "at or beyond"); a
    lens folding before the first grid step has fold angle 0; k must hold four numbers."""
    got = undistort_fisheye(np.array([[np.pi / 2, 0.0], [0.5, 0.0]]), np.zeros(4))
    assert np.isnan(got[0]).all() and got[1] == pytest.approx([np.tan(0.5), 0.0], abs=1e-15)
    assert fisheye_fold_angle(np.array([-1e7, 0.0, 0.0, 0.0])) == 0.0
    # a slope of exactly 0 at a grid angle already counts as folded ("stops being positive"):
    # k1 = −1/(3θ²) at θ = π/2 (grid point 2048) makes 1 + 3 k1 θ² exactly 0.0 in floating point
    grid = np.linspace(0.0, np.pi, 4097)
    k1 = -1.0 / (3.0 * grid[2048] ** 2)
    assert _fisheye_slope(grid[2048:2049], np.array([k1, 0.0, 0.0, 0.0]))[0] == 0.0
    assert fisheye_fold_angle(np.array([k1, 0.0, 0.0, 0.0])) == grid[2047]
    for fn in (lambda k: fisheye_fold_angle(k), lambda k: fisheye_theta(np.array([0.1]), k),
               lambda k: distort_fisheye(np.array([[0.1, 0.2]]), k)):
        with pytest.raises(ValueError):
            fn(np.zeros(5))
