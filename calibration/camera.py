"""The OpenCV camera (pinhole or fisheye lens model), and its pure projection math.

Conventions (DESIGN.md): ``X_c = R X_w + t`` with ``R = R_cam_from_world``; pixel
``(0, 0)`` is the centre of the top-left pixel. Two lens models:

- ``"pinhole"``: OpenCV's radial-tangential model, distortion coefficients in OpenCV order
  ``k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [tau_x tau_y]]]]`` (``cv2.projectPoints``).
- ``"fisheye"``: OpenCV's equidistant Kannala–Brandt model (``cv2.fisheye``), exactly four
  coefficients ``k1 k2 k3 k4``: a ray at angle θ from the optical axis lands at normalized
  radius ``θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)``.

The functions here are vectorised NumPy and stateless; :class:`Camera` only holds the
parameters and calls them.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace as dc_replace
from typing import Any

import numpy as np

from calibration.distortion import (
    DIST_LENGTHS,
    FISHEYE_DIST_LENGTH,
    distort_fisheye,
    distort_normalized,
    fisheye_fold_angle,
    fisheye_theta,
    lens_distort,
    normalized_to_pixels,
    undistort_fisheye,
    undistort_normalized,
)
from calibration.errors import CalibrationError
from calibration.rotation import look_at, matrix_to_rotvec, rotvec_to_matrix

__all__ = [
    "Camera",
    "DIST_LENGTHS",
    "distort_normalized",
    "undistort_normalized",
    "distort_fisheye",
    "undistort_fisheye",
    "fisheye_theta",
    "fisheye_fold_angle",
    "lens_distort",
    "normalized_to_pixels",
    "MODELS",
]

log = logging.getLogger(__name__)

#: Lens models a :class:`Camera` knows: OpenCV radial-tangential and ``cv2.fisheye``.
MODELS = ("pinhole", "fisheye")
#: Smallest focal length accepted (a 1e-300 px focal length is a unit or parse error).
MIN_FOCAL = 1e-3
#: Largest deviation of ``R Rᵀ`` from the identity accepted as a rotation.
ORTHONORMAL_TOL = 1e-6


# --------------------------------------------------------------------------- validation
def _as_array(value: Any, camera: str, name: str, shape: tuple[int, ...]) -> np.ndarray:
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError) as exc:  # ragged nesting, e.g. [[1, 2], [3]]
        raise CalibrationError(f"not an array of numbers ({exc})", camera=camera, field=name) from None
    if raw.dtype.kind not in "iuf":
        raise CalibrationError(f"expected numbers, got {raw.dtype} values {value!r}", camera=camera, field=name)
    arr = np.array(raw, dtype=np.float64)  # a copy: the caller's array is never made read-only
    if arr.shape != shape:
        if arr.size == int(np.prod(shape)) and name in ("t", "rvec"):
            arr = arr.reshape(shape)  # (3,1) column vectors are common (cv2's tvec, rvec)
        else:
            raise CalibrationError(
                f"expected shape {shape}, got {arr.shape}", camera=camera, field=name
            )
    if not np.all(np.isfinite(arr)):
        raise CalibrationError("contains NaN or infinite values", camera=camera, field=name)
    arr.setflags(write=False)
    return arr


def _check_points(X: Any, dim: int, what: str) -> tuple[np.ndarray, bool]:
    arr = np.asarray(X, dtype=np.float64)
    single = arr.ndim == 1
    if single:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != dim:
        raise ValueError(f"{what}: expected shape (N, {dim}) or ({dim},), got {np.shape(X)}")
    return arr, single


# --------------------------------------------------------------------------- Camera
@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated camera: OpenCV intrinsics + lens model, world → camera pose.

    Attributes
    ----------
    name : camera name (non-empty).
    K : (3, 3) float64 intrinsic matrix ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``.
        (OpenCV's own ``projectPoints`` ignores the skew ``s``; keep it 0 for exchange.)
    dist : (n,) float64; pinhole: n in ``DIST_LENGTHS``, OpenCV order; fisheye: n = 4,
        ``k1 k2 k3 k4`` of ``cv2.fisheye``.
    R : (3, 3) ``R_cam_from_world``, orthonormal with det +1.
    t : (3,) so that ``X_c = R X_w + t`` (metres).
    size : (width, height) in pixels.
    model : ``"pinhole"`` (default, OpenCV radial-tangential) or ``"fisheye"``
        (``cv2.fisheye`` equidistant). "Ideal" / "undistorted" pixels are always those of
        the pinhole camera with the same ``K`` and no distortion.

    Arrays are stored read-only; use :meth:`replace` to derive a changed camera.
    Equality is identity; compare with :meth:`allclose`.
    """

    name: str
    K: np.ndarray
    dist: np.ndarray
    R: np.ndarray
    t: np.ndarray
    size: tuple[int, int]
    model: str = "pinhole"
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        name = self.name
        if not isinstance(name, str) or not name:
            raise CalibrationError(f"expected a non-empty string, got {name!r}", field="name")
        K = _as_array(self.K, name, "K", (3, 3))
        if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
            raise CalibrationError(
                f"expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got {K.tolist()}",
                camera=name,
                field="K",
            )
        if not (K[0, 0] >= MIN_FOCAL and K[1, 1] >= MIN_FOCAL):
            raise CalibrationError(
                f"focal lengths must be at least {MIN_FOCAL:g} (pixels, or 1 for normalised cameras), "
                f"got fx={K[0, 0]:g}, fy={K[1, 1]:g}",
                camera=name,
                field="K",
            )
        try:
            d = np.array(self.dist, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError) as exc:
            raise CalibrationError(f"not numeric ({exc})", camera=name, field="dist") from None
        model = self.model
        if model not in MODELS:
            raise CalibrationError(
                f"expected one of {MODELS}, got {model!r}", camera=name, field="model"
            )
        if model == "fisheye" and d.size != FISHEYE_DIST_LENGTH:
            raise CalibrationError(
                f"the fisheye model needs exactly {FISHEYE_DIST_LENGTH} coefficients "
                f"(k1 k2 k3 k4), got {d.size}",
                camera=name,
                field="dist",
            )
        if d.size not in DIST_LENGTHS:
            raise CalibrationError(
                f"expected {DIST_LENGTHS} coefficients, got {d.size}", camera=name, field="dist"
            )
        dist = _as_array(d, name, "dist", (d.size,))
        R = _as_array(self.R, name, "R", (3, 3))
        err = float(np.max(np.abs(R @ R.T - np.eye(3))))
        if err > ORTHONORMAL_TOL:
            raise CalibrationError(
                f"not orthonormal (max |R Rᵀ - I| = {err:.3g} > {ORTHONORMAL_TOL})",
                camera=name,
                field="R",
            )
        if np.linalg.det(R) < 0:
            raise CalibrationError(
                "determinant is -1 (a reflection, not a rotation)", camera=name, field="R"
            )
        t = _as_array(self.t, name, "t", (3,))
        if any(isinstance(v, (bool, np.bool_, str)) for v in np.atleast_1d(np.asarray(self.size, dtype=object))):
            raise CalibrationError(
                f"expected two positive integers (width, height), got {self.size!r}", camera=name, field="size"
            )
        try:
            w, h = (int(v) for v in self.size)
            exact = all(float(v) == int(v) for v in self.size)
        except (TypeError, ValueError):
            raise CalibrationError(
                f"expected (width, height), got {self.size!r}", camera=name, field="size"
            ) from None
        if not exact or w <= 0 or h <= 0:
            raise CalibrationError(
                f"expected two positive integers (width, height), got {self.size!r}",
                camera=name,
                field="size",
            )
        for key, value in (("K", K), ("dist", dist), ("R", R), ("t", t), ("size", (w, h))):
            object.__setattr__(self, key, value)

    # ------------------------------------------------------------------ properties
    @property
    def width(self) -> int:
        return self.size[0]

    @property
    def height(self) -> int:
        return self.size[1]

    @property
    def center(self) -> np.ndarray:
        """(3,) camera centre in world coordinates, ``-Rᵀ t``."""
        return -self.R.T @ self.t

    @property
    def P(self) -> np.ndarray:
        """(3, 4) projection matrix ``K [R | t]`` (ideal, undistorted pixels)."""
        return self.K @ np.hstack([self.R, self.t[:, None]])

    @property
    def is_fisheye(self) -> bool:
        """``model == "fisheye"``."""
        return self.model == "fisheye"

    @property
    def has_distortion(self) -> bool:
        """Observed pixels differ from ideal pinhole ones (always, for a fisheye lens)."""
        return self.model == "fisheye" or bool(np.any(self.dist != 0))

    def _distort(self, xy: np.ndarray) -> np.ndarray:
        return lens_distort(xy, self.dist, self.model)

    def _undistort(self, xy_d: np.ndarray) -> np.ndarray:
        if self.model == "fisheye":
            return undistort_fisheye(xy_d, self.dist)
        return undistort_normalized(xy_d, self.dist)

    # ------------------------------------------------------------------ projection
    def to_camera(self, X: np.ndarray) -> np.ndarray:
        """World points (N, 3) or (3,) → camera coordinates (N, 3)."""
        X, _ = _check_points(X, 3, "X")
        return X @ self.R.T + self.t

    def _normalized_to_pixels(self, xy: np.ndarray) -> np.ndarray:
        return normalized_to_pixels(xy, self.K)

    def _pixels_to_normalized(self, uv: np.ndarray) -> np.ndarray:
        K = self.K
        y = (uv[:, 1] - K[1, 2]) / K[1, 1]
        x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        return np.stack([x, y], axis=1)

    def project_points(
        self, X: np.ndarray, distort: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Project world points; flag those behind the camera.

        Returns ``uv`` (N, 2) pixels (NaN where the point is not in front), ``depth``
        (N,) camera-frame z, and ``in_front`` (N,) bool (``depth > 0``). ``distort=False``
        gives ideal pinhole pixels whatever the lens model. A fisheye camera, too, sees
        only points in front of it (less than 90° off-axis) here.
        """
        Xc = self.to_camera(X)
        z = Xc[:, 2]
        in_front = z > 0
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = Xc[:, :2] / z[:, None]
        xy[~in_front] = np.nan
        if distort and self.has_distortion:
            xy = self._distort(xy)
        return self._normalized_to_pixels(xy), z, in_front

    def project(self, X: np.ndarray, distort: bool = True) -> np.ndarray:
        """World points (N, 3) or (3,) → pixels (N, 2); NaN for points behind the camera."""
        return self.project_points(X, distort)[0]

    def project_near(self, X: np.ndarray, margin: float = 0.5) -> np.ndarray:
        """Distorted pixels (N, 2) of world points where the lens model is trustworthy.

        A radial-tangential polynomial is only meaningful near the image: far outside it
        may fold back into the frame. Points whose ideal (pinhole) pixel lies more than
        ``margin`` × the larger image side outside the frame ``[0, width] × [0, height]``
        (exactly that far is kept), points behind the camera, and fisheye points past the
        model's fold-back angle (:func:`fisheye_fold_angle`; at it is kept) come back as NaN.
        A camera without distortion gives its pinhole pixels everywhere in front. Use this
        (not :meth:`project`) when building dense maps over large areas (floor views,
        view-to-view warps).
        """
        uv_ideal, _, in_front = self.project_points(X, distort=False)
        if self.is_fisheye:
            uv = self.project_points(X, distort=True)[0]
            Xc = self.to_camera(X)
            theta = np.arctan2(np.hypot(Xc[:, 0], Xc[:, 1]), Xc[:, 2])
            uv[~in_front | (theta > fisheye_fold_angle(self.dist))] = np.nan
            return uv
        if not self.has_distortion:
            return uv_ideal
        m = margin * max(self.width, self.height)
        near = (  # NaN (behind the camera) compares False
            in_front
            & (uv_ideal[:, 0] >= -m)
            & (uv_ideal[:, 0] <= self.width + m)
            & (uv_ideal[:, 1] >= -m)
            & (uv_ideal[:, 1] <= self.height + m)
        )
        uv = np.full_like(uv_ideal, np.nan)
        if near.any():
            uv[near] = self.distort_pixels(uv_ideal[near])
        return uv

    def undistort_pixels(self, uv: np.ndarray) -> np.ndarray:
        """Remove lens distortion: observed pixels (N, 2) → ideal pinhole pixels, same K.

        Fisheye: NaN for pixels of rays 90° or more off-axis (no pinhole pixel exists).
        """
        uv, _ = _check_points(uv, 2, "uv")
        if not self.has_distortion:
            return uv.copy()
        xy = self._undistort(self._pixels_to_normalized(uv))
        return self._normalized_to_pixels(xy)

    def distort_pixels(self, uv_ideal: np.ndarray) -> np.ndarray:
        """Add lens distortion: ideal pinhole pixels (N, 2) → observed pixels (N, 2)."""
        uv, _ = _check_points(uv_ideal, 2, "uv_ideal")
        if not self.has_distortion:
            return uv.copy()
        xy = self._distort(self._pixels_to_normalized(uv))
        return self._normalized_to_pixels(xy)

    def pixel_rays(
        self, uv: np.ndarray, distorted: bool = True
    ) -> tuple[np.ndarray, np.ndarray]:
        """Back-project pixels (N, 2) to world rays.

        ``distorted`` says whether ``uv`` are observed (lens-distorted) pixels or ideal ones.
        Returns origins (N, 3) (the camera centre) and unit directions (N, 3) in world
        coordinates; ``project(o + s d)`` gives back ``uv`` for every ``s > 0``.
        Fisheye rays come straight from the off-axis angle, so they stay exact up to and
        beyond 90° (NaN only beyond the model's fold, :func:`fisheye_fold_angle`).
        """
        uv, _ = _check_points(uv, 2, "uv")
        xy = self._pixels_to_normalized(uv)
        if distorted and self.model == "fisheye":
            theta_d = np.hypot(xy[:, 0], xy[:, 1])
            theta = fisheye_theta(theta_d, self.dist)
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = np.where(theta_d > 1e-12, np.sin(theta) / theta_d, 1.0)
            d_cam = np.stack([xy[:, 0] * ratio, xy[:, 1] * ratio, np.cos(theta)], axis=1)
        else:
            if distorted and self.has_distortion:
                xy = undistort_normalized(xy, self.dist)
            d_cam = np.hstack([xy, np.ones((len(xy), 1))])
        d = d_cam @ self.R  # Rᵀ d_cam for each row
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return np.broadcast_to(self.center, d.shape).copy(), d

    def in_image(self, uv: np.ndarray) -> np.ndarray:
        """(N,) bool: pixel inside ``[-0.5, w-0.5) × [-0.5, h-0.5)`` (NaN → False)."""
        uv, _ = _check_points(uv, 2, "uv")
        return (  # NaN compares False
            (uv[:, 0] >= -0.5)
            & (uv[:, 0] < self.width - 0.5)
            & (uv[:, 1] >= -0.5)
            & (uv[:, 1] < self.height - 0.5)
        )

    # ------------------------------------------------------------------ images
    def undistort_maps(self) -> tuple[np.ndarray, np.ndarray]:
        """(H, W) float32 maps for ``cv2.remap`` giving the undistorted image (same K).

        Fisheye cameras use ``cv2.fisheye.initUndistortRectifyMap`` (the same K, so only the
        central part of a wide field of view stays in the frame).
        """
        maps = self._cache.get("undistort_maps")
        if maps is None:
            import cv2

            if self.model == "fisheye":
                maps = cv2.fisheye.initUndistortRectifyMap(
                    self.K, self.dist, np.eye(3), self.K, self.size, cv2.CV_32FC1
                )
            else:
                maps = cv2.initUndistortRectifyMap(
                    self.K, self.dist, None, self.K, self.size, cv2.CV_32FC1
                )
            self._cache["undistort_maps"] = maps
        return maps

    def undistort_image(self, image: np.ndarray, interpolation: int | None = None) -> np.ndarray:
        """The image as an ideal pinhole camera with the same K would see it.

        ``image`` (H, W[, C]) with (W, H) = ``size``; bool masks come back bool (nearest).
        """
        import cv2

        image = np.asarray(image)
        if image.shape[:2] != (self.height, self.width):
            raise ValueError(
                f"camera {self.name!r}: image is {image.shape[1]}x{image.shape[0]}, "
                f"calibration says {self.width}x{self.height}"
            )
        if not self.has_distortion:
            return image.copy()
        is_bool = image.dtype == bool
        src = image.astype(np.uint8) if is_bool else image
        if interpolation is None:
            interpolation = cv2.INTER_NEAREST if is_bool else cv2.INTER_LINEAR
        mx, my = self.undistort_maps()
        out = cv2.remap(src, mx, my, interpolation, borderMode=cv2.BORDER_CONSTANT)
        return out.astype(bool) if is_bool else out

    # ------------------------------------------------------------------ misc
    def replace(self, **changes: Any) -> Camera:
        """A new camera with some fields changed (validated again)."""
        return dc_replace(self, **changes)

    def allclose(self, other: Camera, atol: float = 1e-9) -> bool:
        """True when the models match and every parameter agrees to ``atol`` (distortion
        padded with zeros)."""
        if self.model != other.model:
            return False
        n = max(self.dist.size, other.dist.size)
        da, db = np.zeros(n), np.zeros(n)
        da[: self.dist.size] = self.dist
        db[: other.dist.size] = other.dist
        return (
            self.name == other.name
            and tuple(self.size) == tuple(other.size)
            and np.allclose(self.K, other.K, rtol=0, atol=atol)
            and np.allclose(da, db, rtol=0, atol=atol)
            and np.allclose(self.R, other.R, rtol=0, atol=atol)
            and np.allclose(self.t, other.t, rtol=0, atol=atol)
        )

    def to_dict(self) -> dict:
        """Plain JSON-able dict ``{model, K, dist, R, t, size}`` (native per-camera entry)."""
        return {
            "model": self.model,
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "R": self.R.tolist(),
            "t": self.t.tolist(),
            "size": list(self.size),
        }

    @classmethod
    def from_dict(cls, name: str, data: dict) -> Camera:
        """Inverse of :meth:`to_dict`; missing fields raise :class:`CalibrationError`.

        ``model`` is optional (files written before it existed are pinhole).
        """
        if not isinstance(data, dict):
            raise CalibrationError(f"expected a mapping, got {type(data).__name__}", camera=name)
        for key in ("K", "dist", "R", "t", "size"):
            if key not in data:
                raise CalibrationError("missing", camera=name, field=key)
        model = data.get("model", "pinhole")
        return cls(name, data["K"], data["dist"], data["R"], data["t"], tuple(data["size"]), model)

    @classmethod
    def from_rvec(cls, name: str, K, dist, rvec, t, size, model: str = "pinhole") -> Camera:
        """Build from an axis-angle rotation vector (OpenCV ``rvec``)."""
        rv = _as_array(rvec, name, "rvec", (3,))
        return cls(name, K, dist, rotvec_to_matrix(rv), t, size, model)

    @classmethod
    def look_at(
        cls, name: str, center, target, K, size, dist=(), model: str = "pinhole", up=(0.0, 0.0, 1.0)
    ) -> Camera:
        """A camera at ``center`` (3,) looking at ``target`` (3,), ``up`` (world +Z) up in the image.

        ``K`` is a (3, 3) matrix or a focal length in pixels (principal point at the image
        centre). The image x axis is perpendicular to ``up`` (:func:`calibration.rotation.look_at`).
        """
        try:
            R, t = look_at(center, target, up)
        except ValueError:
            raise CalibrationError(
                "looks straight along the up axis: give a target off the vertical", camera=name, field="target"
            ) from None
        w, h = int(size[0]), int(size[1])
        if np.ndim(K) == 0:
            f = float(K)
            K = np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]])
        return cls(name, K, dist, R, t, (w, h), model)

    @property
    def rvec(self) -> np.ndarray:
        """(3,) axis-angle of ``R`` (OpenCV ``rvec``)."""
        return matrix_to_rotvec(self.R)

    def __repr__(self) -> str:
        fx, fy, cx, cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        c = self.center
        return (
            f"Camera({self.name!r}, {self.width}x{self.height}, f=({fx:.1f}, {fy:.1f}), "
            f"c=({cx:.1f}, {cy:.1f}), {self.model}, dist={self.dist.size}, "
            f"centre=({c[0]:.3f}, {c[1]:.3f}, {c[2]:.3f}))"
        )
