"""Lens distortion, pure and vectorised: OpenCV's radial-tangential model (pinhole cameras)
and its equidistant Kannala–Brandt fisheye model.

- pinhole: coefficients in OpenCV order ``k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tau_x tau_y]]]]``
  (``cv2.projectPoints``);
- fisheye: exactly four coefficients ``k1 k2 k3 k4``; a ray at angle θ from the optical axis
  lands at normalized radius ``θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)`` (``cv2.fisheye``).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "DIST_LENGTHS",
    "FISHEYE_DIST_LENGTH",
    "distort_fisheye",
    "distort_normalized",
    "fisheye_fold_angle",
    "fisheye_theta",
    "lens_distort",
    "normalized_to_pixels",
    "undistort_fisheye",
    "undistort_normalized",
]

#: Lengths of a distortion vector OpenCV accepts (pinhole model).
DIST_LENGTHS = (0, 4, 5, 8, 12, 14)
#: Number of coefficients of the fisheye model (k1 k2 k3 k4).
FISHEYE_DIST_LENGTH = 4


# --------------------------------------------------------------------------- distortion
def _tilt_matrix(tau_x: float, tau_y: float) -> np.ndarray:
    """OpenCV's ``computeTiltProjectionMatrix`` (3, 3) for a tilted sensor."""
    cx, sx, cy, sy = np.cos(tau_x), np.sin(tau_x), np.cos(tau_y), np.sin(tau_y)
    rot_x = np.array([[1.0, 0.0, 0.0], [0.0, cx, sx], [0.0, -sx, cx]])
    rot_y = np.array([[cy, 0.0, -sy], [0.0, 1.0, 0.0], [sy, 0.0, cy]])
    rot_xy = rot_y @ rot_x
    proj_z = np.array(
        [[rot_xy[2, 2], 0.0, -rot_xy[0, 2]], [0.0, rot_xy[2, 2], -rot_xy[1, 2]], [0.0, 0.0, 1.0]]
    )
    return proj_z @ rot_xy


def _padded(dist: np.ndarray) -> np.ndarray:
    d = np.zeros(14)
    d[: len(dist)] = dist
    return d


def _radial_tangential(
    x: np.ndarray, y: np.ndarray, d: np.ndarray, jacobian: bool = False
) -> tuple[np.ndarray, ...]:
    """Distortion before the sensor tilt; with ``jacobian`` also ∂(xd, yd)/∂(x, y)."""
    k1, k2, p1, p2, k3, k4, k5, k6, s1, s2, s3, s4 = d[:12]
    r2 = x * x + y * y
    num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    radial = num / den
    xy2 = 2.0 * x * y
    xd = x * radial + p1 * xy2 + p2 * (r2 + 2.0 * x * x) + r2 * (s1 + s2 * r2)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + p2 * xy2 + r2 * (s3 + s4 * r2)
    if not jacobian:
        return xd, yd
    dnum = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    dden = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
    g = (dnum * den - num * dden) / (den * den)  # d radial / d r2
    h1 = s1 + 2.0 * s2 * r2
    h2 = s3 + 2.0 * s4 * r2
    j11 = radial + 2.0 * x * x * g + 2.0 * p1 * y + 6.0 * p2 * x + 2.0 * x * h1
    j12 = 2.0 * x * y * g + 2.0 * p1 * x + 2.0 * p2 * y + 2.0 * y * h1
    j21 = 2.0 * x * y * g + 2.0 * p1 * x + 2.0 * p2 * y + 2.0 * x * h2
    j22 = radial + 2.0 * y * y * g + 6.0 * p1 * y + 2.0 * p2 * x + 2.0 * y * h2
    return xd, yd, j11, j12, j21, j22


def _apply_h(T: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u = T[0, 0] * x + T[0, 1] * y + T[0, 2]
    v = T[1, 0] * x + T[1, 1] * y + T[1, 2]
    w = T[2, 0] * x + T[2, 1] * y + T[2, 2]
    w = np.where(w != 0.0, w, 1.0)
    return u / w, v / w


def distort_normalized(xy: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """Apply OpenCV lens distortion to normalised image coordinates.

    ``xy`` (N, 2) ideal coordinates ``(X_c/Z_c, Y_c/Z_c)``; ``dist`` (n,) coefficients.
    Returns (N, 2) distorted normalised coordinates (the model of ``cv2.projectPoints``:
    radial rational ``(1+k1r²+k2r⁴+k3r⁶)/(1+k4r²+k5r⁴+k6r⁶)``, tangential p1 p2, thin prism
    s1..s4, sensor tilt τx τy).
    """
    xy = np.asarray(xy, dtype=np.float64)
    dist = np.asarray(dist, dtype=np.float64)
    if dist.size == 0 or not np.any(dist):
        return xy.copy()
    d = _padded(dist)
    xd, yd = _radial_tangential(xy[:, 0], xy[:, 1], d)
    if d[12] != 0.0 or d[13] != 0.0:
        xd, yd = _apply_h(_tilt_matrix(d[12], d[13]), xd, yd)
    return np.stack([xd, yd], axis=1)


def undistort_normalized(
    xy_d: np.ndarray, dist: np.ndarray, iterations: int = 20, tol: float = 1e-12
) -> np.ndarray:
    """Invert :func:`distort_normalized` (N, 2) → (N, 2).

    The sensor tilt (a homography) is inverted exactly; the rest by Newton's method with
    the analytic 2×2 Jacobian, started at the distorted point and iterated only on the
    points not yet converged (``|step| < tol``). Points where the model cannot be
    inverted (far outside the calibrated field) return the last iterate.
    """
    xy_d = np.asarray(xy_d, dtype=np.float64)
    dist = np.asarray(dist, dtype=np.float64)
    if dist.size == 0 or not np.any(dist) or len(xy_d) == 0:
        return xy_d.copy()
    d = _padded(dist)
    tx, ty = xy_d[:, 0], xy_d[:, 1]
    if d[12] != 0.0 or d[13] != 0.0:
        tx, ty = _apply_h(np.linalg.inv(_tilt_matrix(d[12], d[13])), tx, ty)
    x, y = tx.copy(), ty.copy()
    active = np.flatnonzero(np.isfinite(x) & np.isfinite(y))
    for _ in range(iterations):
        if active.size == 0:
            break
        xa, ya = x[active], y[active]
        fx, fy, j11, j12, j21, j22 = _radial_tangential(xa, ya, d, jacobian=True)
        rx, ry = fx - tx[active], fy - ty[active]
        det = j11 * j22 - j12 * j21
        ok = np.abs(det) > 1e-12
        det = np.where(ok, det, 1.0)
        dx = np.where(ok, (j22 * rx - j12 * ry) / det, rx)
        dy = np.where(ok, (-j21 * rx + j11 * ry) / det, ry)
        x[active] = xa - dx
        y[active] = ya - dy
        moving = (np.abs(dx) > tol) | (np.abs(dy) > tol)
        active = active[moving & np.isfinite(dx) & np.isfinite(dy)]
    return np.stack([x, y], axis=1)


# --------------------------------------------------------------------------- fisheye
def _fisheye_poly(theta: np.ndarray, k: np.ndarray) -> np.ndarray:
    t2 = theta * theta
    return theta * (1.0 + t2 * (k[0] + t2 * (k[1] + t2 * (k[2] + t2 * k[3]))))


def _fisheye_slope(theta: np.ndarray, k: np.ndarray) -> np.ndarray:
    t2 = theta * theta
    return 1.0 + t2 * (3.0 * k[0] + t2 * (5.0 * k[1] + t2 * (7.0 * k[2] + t2 * 9.0 * k[3])))


def fisheye_fold_angle(k: np.ndarray, samples: int = 4097) -> float:
    """Largest off-axis angle θ (radians, ≤ π) up to which the fisheye model is monotone.

    Beyond it ``θ_d(θ)`` turns back, so image radii fold over and cannot be inverted; the
    angle is the last of ``samples`` grid points on [0, π] before ``dθ_d/dθ`` stops being
    positive (π when it never does: the usual case for a well-calibrated lens).
    """
    k = np.asarray(k, dtype=np.float64).reshape(FISHEYE_DIST_LENGTH)
    theta = np.linspace(0.0, np.pi, samples)
    bad = np.flatnonzero(_fisheye_slope(theta, k) <= 0.0)
    return float(np.pi) if bad.size == 0 else float(theta[max(bad[0] - 1, 0)])


def distort_fisheye(xy: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Apply the ``cv2.fisheye`` model to normalized pinhole coordinates (N, 2) → (N, 2).

    ``r = |xy|``, ``θ = atan r``, ``θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)``,
    result ``xy θ_d / r`` (``xy`` itself for ``r < 1e-8``, as OpenCV). ``k`` (4,).
    Pixels are then ``K`` applied to the result (with skew ``α = K[0,1] / fx``).
    """
    xy = np.asarray(xy, dtype=np.float64)
    k = np.asarray(k, dtype=np.float64).reshape(FISHEYE_DIST_LENGTH)
    if len(xy) == 0:
        return xy.copy()
    r = np.hypot(xy[:, 0], xy[:, 1])
    theta_d = _fisheye_poly(np.arctan(r), k)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(r > 1e-8, theta_d / r, 1.0)
    return xy * scale[:, None]


def fisheye_theta(
    theta_d: np.ndarray, k: np.ndarray, iterations: int = 30, tol: float = 1e-15
) -> np.ndarray:
    """Off-axis angle θ (N,) of distorted normalized radii ``θ_d`` (N,) ≥ 0.

    Newton's method on ``θ (1 + k1 θ² + …) = θ_d`` started at ``θ_d`` and kept inside
    ``[0, fisheye_fold_angle(k)]``, where the model is monotone, so it cannot jump to another
    branch. Radii beyond the fold (no angle maps there) give NaN.
    """
    theta_d = np.asarray(theta_d, dtype=np.float64)
    k = np.asarray(k, dtype=np.float64).reshape(FISHEYE_DIST_LENGTH)
    if not np.any(k):  # equidistant: θ = θ_d, up to a half turn
        with np.errstate(invalid="ignore"):
            return np.where(theta_d <= np.pi, theta_d, np.nan)
    t_max = fisheye_fold_angle(k)
    with np.errstate(invalid="ignore"):
        ok = np.isfinite(theta_d) & (theta_d <= _fisheye_poly(np.array(t_max), k) * (1 + 1e-12))
    theta = np.where(ok, np.clip(theta_d, 0.0, t_max), np.nan)
    active = np.flatnonzero(ok)
    for _ in range(iterations):
        if active.size == 0:
            break
        ta = theta[active]
        step = (_fisheye_poly(ta, k) - theta_d[active]) / _fisheye_slope(ta, k)
        theta[active] = np.clip(ta - step, 0.0, t_max)
        active = active[np.abs(step) > tol * np.maximum(1.0, ta)]
    return theta


def undistort_fisheye(xy_d: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Invert :func:`distort_fisheye`: distorted (N, 2) → normalized pinhole (N, 2).

    Same as ``cv2.fisheye.undistortPoints`` (to its Newton tolerance). Points at or beyond
    90° off-axis, which a pinhole image plane cannot hold, and radii beyond the model's fold
    (:func:`fisheye_fold_angle`) give NaN; use :meth:`Camera.pixel_rays` for rays there.
    """
    xy_d = np.asarray(xy_d, dtype=np.float64)
    if len(xy_d) == 0:
        return xy_d.copy()
    theta_d = np.hypot(xy_d[:, 0], xy_d[:, 1])
    theta = fisheye_theta(theta_d, k)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(theta_d > 1e-8, np.tan(theta) / theta_d, 1.0)
        scale = np.where(theta < np.pi / 2, scale, np.nan)
    return xy_d * scale[:, None]


def lens_distort(xy: np.ndarray, dist: np.ndarray, model: str = "pinhole") -> np.ndarray:
    """Ideal normalized coordinates (N, 2) → distorted ones through the lens ``model``
    (:func:`distort_fisheye` for ``"fisheye"``, else :func:`distort_normalized`)."""
    if model == "fisheye":
        return distort_fisheye(xy, dist)
    return distort_normalized(xy, dist)


def normalized_to_pixels(xy: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Normalized coordinates (N, 2) → pixels (N, 2): ``u = fx x + s y + cx``, ``v = fy y + cy``
    for ``K = [[fx, s, cx], [0, fy, cy], [0, 0, 1]]``."""
    u = K[0, 0] * xy[:, 0] + K[0, 1] * xy[:, 1] + K[0, 2]
    v = K[1, 1] * xy[:, 1] + K[1, 2]
    return np.stack([u, v], axis=1)
