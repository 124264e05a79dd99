"""Per-camera intrinsics from many views of a board (Zhang's method through OpenCV).

Pinhole + Brown–Conrady distortion (k1 k2 p1 p2 k3) by ``cv2.calibrateCamera``, or the
equidistant fisheye model (k1..k4) by ``cv2.fisheye.calibrate`` when ``model="fisheye"``.

Outlier views: after each fit, the worst view is dropped while its RMS exceeds both
``outlier_factor`` × the median view RMS and ``outlier_min_px`` pixels, and at least
``min_views`` views remain; the result lists every rejected view with the reason.

Degenerate input is refused: fewer than ``min_views`` usable views; views whose board planes
are all parallel (Zhang's method needs the board tilted: parallel planes give the same two
constraints on the image of the absolute conic), judged before fitting from PnP with a rough
pinhole guess (spread of the board normals below ``min_plane_spread_deg``); and, after
fitting, a focal length whose OpenCV standard deviation exceeds ``max_focal_std`` of itself.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from calibration.detect import Detection
from calibration.errors import CalibrationError

__all__ = [
    "IntrinsicsResult",
    "calibrate_intrinsics",
    "coverage_map",
    "coverage_advice",
    "view_plane_spread_deg",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class IntrinsicsResult:
    """Intrinsics of one camera and how well the views fit.

    Attributes
    ----------
    camera : str
    K : (3, 3) float64
    dist : (n,) float64
        (k1 k2 p1 p2 k3) pinhole, (k1 k2 k3 k4) fisheye.
    image_size : (width, height)
    model : ``"pinhole"`` or ``"fisheye"``
    rms : float
        Root-mean-square reprojection error over all corners of the kept views, pixels.
    view_errors : dict[str, float]
        RMS per kept view, pixels.
    rejected : dict[str, str]
        View → reason, for detection rejects and outlier views.
    board_poses : dict[str, tuple[(3,) rvec, (3,) tvec]]
        Board pose in the camera frame per kept view.
    coverage : (gy, gx) int64
        Corner counts per image cell of the kept views (see :func:`coverage_map`).
    """

    camera: str
    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]
    model: str
    rms: float
    view_errors: dict
    rejected: dict
    board_poses: dict = field(repr=False)
    coverage: np.ndarray = field(repr=False)
    n_corners: int = 0
    focal_std: float = float("nan")

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    def to_camera(self, R=None, t=None):
        """A :class:`calibration.Camera` with these intrinsics (identity pose unless given);
        a fisheye fit gives a ``model="fisheye"`` camera."""
        from calibration.camera import Camera

        return Camera(
            self.camera,
            self.K.copy(),
            self.dist.copy(),
            np.eye(3) if R is None else np.asarray(R, float),
            np.zeros(3) if t is None else np.asarray(t, float),
            tuple(self.image_size),
            self.model,
        )

    def summary(self) -> dict:
        return {
            "camera": self.camera,
            "model": self.model,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "dist": self.dist.tolist(),
            "rms_px": self.rms,
            "views_used": len(self.view_errors),
            "view_errors_px": dict(self.view_errors),
            "rejected": dict(self.rejected),
            "coverage_fraction": float((self.coverage > 0).mean()),
            "fx_std": self.focal_std,
        }


def coverage_map(detections, image_size: tuple[int, int], grid: tuple[int, int] = (8, 6)) -> np.ndarray:
    """Corner counts per image cell: ``(gy, gx) int64`` for ``grid = (gx, gy)`` cells.

    Tells the user where in the image the board has been and where to wave it next.
    """
    w, h = image_size
    gx, gy = grid
    counts = np.zeros((gy, gx), np.int64)
    for det in detections:
        if not det.usable or det.n == 0:
            continue
        ix = np.clip((det.image_points[:, 0] + 0.5) / w * gx, 0, gx - 1).astype(int)
        iy = np.clip((det.image_points[:, 1] + 0.5) / h * gy, 0, gy - 1).astype(int)
        np.add.at(counts, (iy, ix), 1)
    return counts


def coverage_advice(counts: np.ndarray) -> str:
    """One sentence naming the image regions with no corners yet ('' when covered)."""
    gy, gx = counts.shape
    empty = counts == 0
    if not empty.any():
        return ""
    names = []
    for name, rows, cols in [
        ("top-left", slice(0, gy // 3 or 1), slice(0, gx // 3 or 1)),
        ("top", slice(0, gy // 3 or 1), slice(gx // 3, gx - gx // 3)),
        ("top-right", slice(0, gy // 3 or 1), slice(gx - (gx // 3 or 1), gx)),
        ("left", slice(gy // 3, gy - gy // 3), slice(0, gx // 3 or 1)),
        ("centre", slice(gy // 3, gy - gy // 3), slice(gx // 3, gx - gx // 3)),
        ("right", slice(gy // 3, gy - gy // 3), slice(gx - (gx // 3 or 1), gx)),
        ("bottom-left", slice(gy - (gy // 3 or 1), gy), slice(0, gx // 3 or 1)),
        ("bottom", slice(gy - (gy // 3 or 1), gy), slice(gx // 3, gx - gx // 3)),
        ("bottom-right", slice(gy - (gy // 3 or 1), gy), slice(gx - (gx // 3 or 1), gx)),
    ]:
        block = empty[rows, cols]
        if block.size and block.mean() > 0.5:
            names.append(name)
    pct = 100.0 * empty.mean()
    where = ", ".join(names) if names else "scattered cells"
    return f"{pct:.0f}% of the image has no corners: show the board next in the {where} of the image"


def _plane_normals(dets: list[Detection], image_size: tuple[int, int], K: np.ndarray | None = None) -> np.ndarray:
    """Board normals (V, 3) in the camera frame from a rough pinhole guess (no distortion)."""
    import cv2

    w, h = image_size
    if K is None:
        f = 1.2 * max(w, h)
        K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1.0]])
    normals = []
    for det in dets:
        ok, rvec, _ = cv2.solvePnP(det.object_points, det.image_points, K, None, flags=cv2.SOLVEPNP_IPPE)
        R, _ = cv2.Rodrigues(rvec)
        normals.append(R[:, 2])
    return np.array(normals)


def view_plane_spread_deg(dets: list[Detection], image_size: tuple[int, int]) -> float:
    """Largest angle (degrees) between the board planes of any two views (rough pinhole guess)."""
    n = _plane_normals(dets, image_size)
    cos = np.clip(np.abs(n @ n.T), -1, 1)
    return float(np.degrees(np.arccos(cos.min())))


def _view_rms(obj, img, rvec, tvec, K, dist, fisheye) -> tuple[float, np.ndarray]:
    import cv2

    if fisheye:
        proj, _ = cv2.fisheye.projectPoints(obj.reshape(1, -1, 3).astype(np.float64), rvec, tvec, K, dist)
    else:
        proj, _ = cv2.projectPoints(obj, rvec, tvec, K, dist)
    err = np.linalg.norm(proj.reshape(-1, 2) - img, axis=1)
    return float(np.sqrt(np.mean(err**2))), err


def calibrate_intrinsics(
    detections: list[Detection],
    *,
    camera: str = "cam",
    image_size: tuple[int, int] | None = None,
    model: str = "pinhole",
    fix_aspect_ratio: bool = False,
    zero_tangent: bool = False,
    n_radial: int = 3,
    min_views: int = 3,
    min_plane_spread_deg: float = 2.0,
    outlier_factor: float = 3.0,
    outlier_min_px: float = 1.0,
    coverage_grid: tuple[int, int] = (8, 6),
    max_focal_std: float = 0.05,
    fix_principal_point: bool = False,
    focal_only: bool = False,
) -> IntrinsicsResult:
    """Calibrate one camera from board detections.

    Parameters
    ----------
    detections : list of Detection
        All views, rejected ones included (they are listed in the result).
    camera : str
        Name used in messages and in the result.
    model : ``"pinhole"`` (k1 k2 p1 p2 k3) or ``"fisheye"`` (equidistant k1..k4).
    fix_aspect_ratio : bool
        Keep fx = fy (``CALIB_FIX_ASPECT_RATIO`` with a unit ratio).
    n_radial : int
        Radial terms for the pinhole model (1-3).
    min_views : int
        Refuse to calibrate from fewer usable views.
    min_plane_spread_deg : float
        Refuse when all board planes are within this angle of each other.
    outlier_factor, outlier_min_px : float
        Outlier-view rule (see module docstring).
    max_focal_std : float
        Refuse when OpenCV's standard deviation of fx exceeds this fraction of fx (pinhole).
    fix_principal_point : bool
        Keep the principal point at the image centre (views that cannot constrain it).
    focal_only : bool
        One focal length (fx = fy), principal point at the centre, no distortion: what a single
        tilted view of a plane still constrains (e.g. one board lying on the floor); needs one view.

    Raises
    ------
    CalibrationError
        No usable view, too few views, or all views parallel — the message names the camera,
        the views and what to capture next.
    """
    import cv2

    if model not in ("pinhole", "fisheye"):
        raise CalibrationError(f"camera {camera!r}: model must be 'pinhole' or 'fisheye', got {model!r}")
    if focal_only:
        fix_aspect_ratio = fix_principal_point = zero_tangent = True
        n_radial, min_views = 0, 1
    rejected = {d.view: d.reason for d in detections if not d.usable}
    usable = [d for d in detections if d.usable]
    if image_size is None:
        sizes = {d.image_size for d in detections}
        if len(sizes) != 1:
            raise CalibrationError(
                f"camera {camera!r}: views have different image sizes {sorted(sizes)}; one camera, one size"
            )
        image_size = sizes.pop()
    if not usable:
        raise CalibrationError(
            f"camera {camera!r}: the board was never detected in {len(detections)} views "
            f"({'; '.join(f'{k}: {v}' for k, v in list(rejected.items())[:3])}); check the board "
            "file matches the printed board, and capture views with the whole board in focus"
        )
    if len(usable) < min_views:
        raise CalibrationError(
            f"camera {camera!r}: only {len(usable)} usable views ({[d.view for d in usable]}), "
            f"need at least {min_views}; capture {min_views - len(usable)} more views of the board, tilted "
            "and in different parts of the image"
        )
    spread = view_plane_spread_deg(usable, image_size)
    if spread < min_plane_spread_deg and not (fix_principal_point and fix_aspect_ratio):
        raise CalibrationError(
            f"camera {camera!r}: all {len(usable)} views show the board in parallel planes (max angle "
            f"{spread:.1f} deg < {min_plane_spread_deg} deg) - degenerate for focal length; capture views "
            "with the board tilted 20-45 deg about different axes"
        )

    fisheye = model == "fisheye"
    kept = list(usable)
    while True:
        K, dist, rvecs, tvecs, k_std = _fit(kept, image_size, fisheye, fix_aspect_ratio, zero_tangent, n_radial, fix_principal_point)
        errs = {}
        all_err = []
        for d, rv, tv in zip(kept, rvecs, tvecs):
            rms_v, e = _view_rms(d.object_points, d.image_points, rv, tv, K, dist, fisheye)
            errs[d.view] = rms_v
            all_err.append(e)
        med = float(np.median(list(errs.values())))
        worst = max(errs, key=errs.get)
        limit = max(outlier_factor * med, outlier_min_px)
        if errs[worst] > limit and len(kept) > min_views:
            rejected[worst] = (
                f"outlier view: RMS {errs[worst]:.2f} px > {limit:.2f} px "
                f"({outlier_factor:g} x median {med:.2f} px)"
            )
            log.info("camera %s: dropping view %s (%s)", camera, worst, rejected[worst])
            kept = [d for d in kept if d.view != worst]
            continue
        break
    all_err = np.concatenate(all_err)
    rms = float(np.sqrt(np.mean(all_err**2)))
    if np.isfinite(k_std[0]) and k_std[0] > max_focal_std * K[0, 0]:
        raise CalibrationError(
            f"camera {camera!r}: focal length is poorly constrained by these {len(kept)} views "
            f"(fx {K[0, 0]:.1f} +/- {k_std[0]:.1f} px, > {100 * max_focal_std:g} %); capture more views "
            "with the board tilted 20-45 deg toward and away from the camera"
        )
    poses = {d.view: (np.asarray(rv, float).reshape(3), np.asarray(tv, float).reshape(3)) for d, rv, tv in zip(kept, rvecs, tvecs)}
    cov = coverage_map(kept, image_size, coverage_grid)
    log.info("camera %s: fx %.2f fy %.2f cx %.2f cy %.2f RMS %.3f px (%d views)", camera, K[0, 0], K[1, 1], K[0, 2], K[1, 2], rms, len(kept))
    return IntrinsicsResult(
        camera=camera,
        K=np.asarray(K, float),
        dist=np.asarray(dist, float).reshape(-1),
        image_size=tuple(int(v) for v in image_size),
        model=model,
        rms=rms,
        view_errors=errs,
        rejected=rejected,
        board_poses=poses,
        coverage=cov,
        n_corners=int(all_err.size),
        focal_std=float(k_std[0]),
    )


def _fit(dets, image_size, fisheye, fix_aspect_ratio, zero_tangent, n_radial, fix_principal_point=False):
    import cv2

    obj = [d.object_points.astype(np.float32).reshape(-1, 1, 3) for d in dets]
    img = [d.image_points.astype(np.float32).reshape(-1, 1, 2) for d in dets]
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-10)
    if fisheye:
        # OpenCV 5 moved the fisheye flags from cv2.fisheye.* to cv2.*
        ns = cv2.fisheye if hasattr(cv2.fisheye, "CALIB_RECOMPUTE_EXTRINSIC") else cv2
        flags = ns.CALIB_RECOMPUTE_EXTRINSIC | getattr(ns, "CALIB_FIX_SKEW", 0)
        # cv2.fisheye wants (1, N, 3) / (1, N, 2) float64 arrays
        fobj = [d.object_points.reshape(1, -1, 3).astype(np.float64) for d in dets]
        fimg = [d.image_points.reshape(1, -1, 2).astype(np.float64) for d in dets]
        K0, D0 = np.zeros((3, 3)), np.zeros((4, 1))
        _, K, D, rvecs, tvecs = cv2.fisheye.calibrate(
            fobj, fimg, tuple(image_size), K0, D0, flags=flags, criteria=crit
        )
        return K, D.reshape(-1), rvecs, tvecs, np.full(4, np.nan)
    flags = 0
    K0 = None
    if fix_aspect_ratio:
        flags |= cv2.CALIB_FIX_ASPECT_RATIO
        K0 = np.eye(3)
    if zero_tangent:
        flags |= cv2.CALIB_ZERO_TANGENT_DIST
    if n_radial < 3:
        flags |= cv2.CALIB_FIX_K3
    if n_radial < 2:
        flags |= cv2.CALIB_FIX_K2
    if n_radial < 1:
        flags |= cv2.CALIB_FIX_K1
    if fix_principal_point:
        w, h = image_size
        f0 = 1.2 * max(w, h)
        K0 = np.array([[f0, 0, (w - 1) / 2], [0, f0, (h - 1) / 2], [0, 0, 1.0]])
        flags |= cv2.CALIB_FIX_PRINCIPAL_POINT | cv2.CALIB_USE_INTRINSIC_GUESS
    out = cv2.calibrateCameraExtended(obj, img, tuple(image_size), K0, None, flags=flags, criteria=crit)
    _, K, D, rvecs, tvecs, std_intr = out[:6]
    return K, D.reshape(-1)[:5], rvecs, tvecs, np.asarray(std_intr, float).reshape(-1)[:4]
