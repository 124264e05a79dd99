"""The ground plane, plane-induced homographies between views, and top-down floor views.

Shadows are cast on the floor, so every camera's image of a shadow is related to every
other camera's by the homography the ground plane induces (thesis §5.5.2, multi-view
shadow segmentation: "each shadow pixel corresponds to a 3D ray which can be intersected
with the ground plane"). :func:`plane_homography` gives that warp between two views;
:func:`floor_view` warps any view onto a common metric raster of the floor, where the
registered shadows vote.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from calibration.camera import Camera, _check_points
from calibration.errors import CalibrationError

__all__ = [
    "GroundPlane",
    "plane_homography",
    "camera_plane_homography",
    "FloorGrid",
    "floor_view",
]

UNIT_TOL = 1e-6
_REMAP_DTYPES = tuple(np.dtype(t) for t in (np.uint8, np.uint16, np.int16, np.float32, np.float64))


@dataclass(frozen=True, eq=False)
class GroundPlane:
    """The plane ``n · X = d`` (world coordinates, metres); ``n`` a unit normal pointing up.

    ``GroundPlane.floor()`` is the default floor ``z = 0`` with ``n = (0, 0, 1)``.
    """

    normal: np.ndarray
    offset: float = 0.0

    def __post_init__(self) -> None:
        try:
            n = np.array(self.normal, dtype=np.float64).reshape(-1)
            d = float(self.offset)
        except (TypeError, ValueError) as exc:
            raise CalibrationError(f"not numeric ({exc})", field="ground") from None
        if n.shape != (3,) or not np.all(np.isfinite(n)):
            raise CalibrationError(
                f"expected a finite (3,) normal, got {np.shape(self.normal)} {n.tolist()}",
                field="ground.normal",
            )
        if not math.isfinite(d):
            raise CalibrationError(f"expected a finite offset, got {d}", field="ground.offset")
        norm = float(np.linalg.norm(n))
        if abs(norm - 1.0) > UNIT_TOL:
            raise CalibrationError(
                f"normal must have unit length, |n| = {norm:.9g}", field="ground.normal"
            )
        n = n / norm
        n.setflags(write=False)
        object.__setattr__(self, "normal", n)
        object.__setattr__(self, "offset", d)

    @classmethod
    def floor(cls) -> GroundPlane:
        """The plane z = 0."""
        return cls(np.array([0.0, 0.0, 1.0]), 0.0)

    @classmethod
    def from_point_normal(cls, point: np.ndarray, normal: np.ndarray) -> GroundPlane:
        """The plane through ``point`` with (not necessarily unit) ``normal``."""
        n = np.asarray(normal, dtype=np.float64)
        n = n / np.linalg.norm(n)
        return cls(n, float(n @ np.asarray(point, dtype=np.float64)))

    def allclose(self, other: GroundPlane, atol: float = 1e-9) -> bool:
        return bool(
            np.allclose(self.normal, other.normal, rtol=0, atol=atol)
            and abs(self.offset - other.offset) <= atol
        )

    def to_dict(self) -> dict:
        return {"normal": self.normal.tolist(), "offset": self.offset}

    def signed_distance(self, X: np.ndarray) -> np.ndarray:
        """(N,) signed distance ``n·X - d`` of points (N, 3) (positive on the normal's side)."""
        X, _ = _check_points(X, 3, "X")
        return X @ self.normal - self.offset

    def project_onto(self, X: np.ndarray) -> np.ndarray:
        """Orthogonal projection (N, 3) of points onto the plane."""
        X, _ = _check_points(X, 3, "X")
        return X - self.signed_distance(X)[:, None] * self.normal

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """In-plane right-handed frame ``(origin, e1, e2)`` with ``e1 × e2 = n``.

        ``origin = d n`` (the plane point closest to the world origin); ``e1`` is the world
        x axis projected on the plane (the y axis if x is nearly normal to it). For the
        floor z = 0 this is origin 0, e1 = x, e2 = y, so plane coordinates are world (x, y).
        """
        n = self.normal
        axis = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = axis - (axis @ n) * n
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(n, e1)
        return self.offset * n, e1, e2

    def to_plane_coords(self, X: np.ndarray) -> np.ndarray:
        """World points (N, 3) → plane coordinates (N, 2) in :meth:`basis` (drops the offset)."""
        X, _ = _check_points(X, 3, "X")
        o, e1, e2 = self.basis()
        return np.stack([(X - o) @ e1, (X - o) @ e2], axis=1)

    def from_plane_coords(self, ab: np.ndarray) -> np.ndarray:
        """Plane coordinates (N, 2) → world points (N, 3) on the plane."""
        ab, _ = _check_points(ab, 2, "ab")
        o, e1, e2 = self.basis()
        return o + ab[:, :1] * e1 + ab[:, 1:] * e2

    def intersect_rays(
        self, origins: np.ndarray, dirs: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Intersect rays ``o + s d`` with the plane.

        Returns points (N, 3) (NaN where no hit) and valid (N,) bool: the ray is not
        parallel to the plane and the hit is in front (``s > 0``).
        """
        o, _ = _check_points(origins, 3, "origins")
        d, _ = _check_points(dirs, 3, "dirs")
        denom = d @ self.normal
        num = self.offset - o @ self.normal
        with np.errstate(divide="ignore", invalid="ignore"):
            s = num / denom
        valid = (np.abs(denom) > 1e-12) & (s > 0) & np.isfinite(s)
        pts = o + np.where(valid, s, np.nan)[:, None] * d
        return pts, valid

    def pixel_to_ground(self, camera: Camera, uv: np.ndarray, distorted: bool = True) -> np.ndarray:
        """Pixels (N, 2) of ``camera`` → world points (N, 3) on the plane (NaN where no hit)."""
        o, d = camera.pixel_rays(uv, distorted=distorted)
        return self.intersect_rays(o, d)[0]

    def __repr__(self) -> str:
        n = self.normal
        return f"GroundPlane(normal=({n[0]:.6g}, {n[1]:.6g}, {n[2]:.6g}), offset={self.offset:.6g})"


def _normalize_h(H: np.ndarray) -> np.ndarray:
    return H / H[2, 2] if abs(H[2, 2]) > 1e-12 else H


def camera_plane_homography(camera: Camera, plane: GroundPlane) -> np.ndarray:
    """(3, 3) homography from plane coordinates (in ``plane.basis()``) to ideal pixels.

    ``x ~ K [R e1 | R e2 | R o + t] (a, b, 1)ᵀ`` for the plane point ``o + a e1 + b e2``.
    """
    o, e1, e2 = plane.basis()
    M = np.stack([camera.R @ e1, camera.R @ e2, camera.R @ o + camera.t], axis=1)
    return _normalize_h(camera.K @ M)


def plane_homography(cam_from: Camera, cam_to: Camera, plane: GroundPlane) -> np.ndarray:
    """(3, 3) homography induced by ``plane`` from ``cam_from``'s to ``cam_to``'s image.

    Maps UNDISTORTED (ideal pinhole) pixels of ``cam_from`` to undistorted pixels of
    ``cam_to`` for points on the plane (thesis §5.5.2: shadows registered across views).
    Use :meth:`Camera.undistort_pixels` / :meth:`Camera.distort_pixels` around it for raw
    pixels.
    """
    H_from = camera_plane_homography(cam_from, plane)
    H_to = camera_plane_homography(cam_to, plane)
    return _normalize_h(H_to @ np.linalg.inv(H_from))


def apply_homography(H: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Apply a (3, 3) homography to points (N, 2) → (N, 2) (NaN where w = 0)."""
    uv, _ = _check_points(uv, 2, "uv")
    h = np.hstack([uv, np.ones((len(uv), 1))]) @ np.asarray(H, dtype=np.float64).T
    with np.errstate(divide="ignore", invalid="ignore"):
        return h[:, :2] / h[:, 2:]


@dataclass(frozen=True)
class FloorGrid:
    """A metric raster of the ground plane (a top-down map).

    Coordinates are plane coordinates in ``GroundPlane.basis()`` (world x, y for the floor
    z = 0). ``x_range``/``y_range`` are (min, max) in metres, ``resolution`` metres per
    cell. Cell ``(row, col)`` covers ``x ∈ x0 + [col, col+1)·res`` and
    ``y ∈ y1 - [row+1, row)·res``: **row 0 is the largest y**, so the raster reads like a
    map with +x to the right and +y up.
    """

    x_range: tuple[float, float]
    y_range: tuple[float, float]
    resolution: float

    def __post_init__(self) -> None:
        try:
            xr = tuple(float(v) for v in self.x_range)
            yr = tuple(float(v) for v in self.y_range)
            res = float(self.resolution)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"FloorGrid: expected numbers ({exc})") from None
        if len(xr) != 2 or len(yr) != 2 or not (xr[1] > xr[0] and yr[1] > yr[0]):
            raise ValueError(
                f"FloorGrid: x_range and y_range must be (min, max) with max > min, "
                f"got {self.x_range}, {self.y_range}"
            )
        if not (res > 0 and math.isfinite(res)):
            raise ValueError(f"FloorGrid: resolution must be positive, got {self.resolution}")
        object.__setattr__(self, "x_range", xr)
        object.__setattr__(self, "y_range", yr)
        object.__setattr__(self, "resolution", res)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols) = (ceil(Δy/res), ceil(Δx/res)) (to 1e-9 to absorb rounding)."""
        cols = math.ceil((self.x_range[1] - self.x_range[0]) / self.resolution - 1e-9)
        rows = math.ceil((self.y_range[1] - self.y_range[0]) / self.resolution - 1e-9)
        return rows, cols

    @property
    def cells_from_plane(self) -> np.ndarray:
        """(3, 3) affine map plane (x, y, 1) → cell (col, row, 1) with cell centres integral."""
        r = self.resolution
        return np.array(
            [
                [1.0 / r, 0.0, -self.x_range[0] / r - 0.5],
                [0.0, -1.0 / r, self.y_range[1] / r - 0.5],
                [0.0, 0.0, 1.0],
            ]
        )

    @property
    def plane_from_cells(self) -> np.ndarray:
        """(3, 3) inverse of :attr:`cells_from_plane`: cell (col, row, 1) → plane (x, y, 1)."""
        r = self.resolution
        return np.array(
            [
                [r, 0.0, self.x_range[0] + 0.5 * r],
                [0.0, -r, self.y_range[1] - 0.5 * r],
                [0.0, 0.0, 1.0],
            ]
        )

    def cell_centers(self) -> tuple[np.ndarray, np.ndarray]:
        """Plane coordinates of every cell centre: ``(X, Y)``, each (rows, cols) float64."""
        rows, cols = self.shape
        r = self.resolution
        x = self.x_range[0] + (np.arange(cols) + 0.5) * r
        y = self.y_range[1] - (np.arange(rows) + 0.5) * r
        return np.meshgrid(x, y)

    def to_cells(self, xy: np.ndarray) -> np.ndarray:
        """Plane points (N, 2) → integer cells (N, 2) as ``(row, col)``.

        Points outside the grid give indices outside ``[0, rows) × [0, cols)``; check with
        :meth:`contains`.
        """
        xy, _ = _check_points(xy, 2, "xy")
        r = self.resolution
        col = np.floor((xy[:, 0] - self.x_range[0]) / r)
        row = np.floor((self.y_range[1] - xy[:, 1]) / r)
        return np.stack([row, col], axis=1).astype(np.int64)

    def contains(self, xy: np.ndarray) -> np.ndarray:
        """(N,) bool: the plane point falls in a cell of the grid."""
        rc = self.to_cells(xy)
        rows, cols = self.shape
        return (rc[:, 0] >= 0) & (rc[:, 0] < rows) & (rc[:, 1] >= 0) & (rc[:, 1] < cols)


def floor_view(
    image: np.ndarray,
    camera: Camera,
    plane: GroundPlane,
    grid: FloorGrid,
    distorted: bool = True,
    interpolation: int | None = None,
    fill: float = 0,
) -> np.ndarray:
    """Warp a camera image onto the floor grid: a top-down metric view.

    ``image`` (H, W[, C]) of ``camera`` (lens-distorted as captured when ``distorted``,
    else already undistorted). Returns (rows, cols[, C]) of the same dtype with
    ``grid.shape``; row 0 is the largest y (map orientation, see :class:`FloorGrid`).
    Cells whose floor point is behind the camera or outside the image get ``fill``.
    Fisheye cameras are warped through their own model over the whole field of view.
    Bool masks come back bool; labels and masks should use ``cv2.INTER_NEAREST`` (the
    default for bool images, ``cv2.INTER_LINEAR`` otherwise). Integer label images of
    types OpenCV cannot remap (int32, int64, ...) go through float64 and come back in
    their own dtype.
    """
    import cv2

    image = np.asarray(image)
    if image.ndim not in (2, 3) or image.shape[:2] != (camera.height, camera.width):
        raise ValueError(
            f"floor_view: camera {camera.name!r} expects a {camera.width}x{camera.height} "
            f"image, got shape {image.shape}"
        )
    is_bool = image.dtype == bool
    if interpolation is None:
        interpolation = cv2.INTER_NEAREST if is_bool else cv2.INTER_LINEAR
    if is_bool:
        src = image.astype(np.uint8)
    elif image.dtype in _REMAP_DTYPES:
        src = image
    else:  # e.g. int32/int64 label images: exact through float64 with nearest sampling
        src = image.astype(np.float64)
    rows, cols = grid.shape
    X, Y = grid.cell_centers()
    world = plane.from_plane_coords(np.stack([X.ravel(), Y.ravel()], axis=1))
    uv = camera.project_near(world) if distorted else camera.project(world, distort=False)
    uv = np.where(np.isfinite(uv), uv, -1e6)
    mx = uv[:, 0].reshape(rows, cols).astype(np.float32)
    my = uv[:, 1].reshape(rows, cols).astype(np.float32)
    out = cv2.remap(
        src, mx, my, interpolation, borderMode=cv2.BORDER_CONSTANT, borderValue=fill
    )
    if out.ndim == 2 and image.ndim == 3:
        out = out[:, :, None]
    return out.astype(image.dtype) if out.dtype != image.dtype else out
