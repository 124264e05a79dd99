"""World frame and ground plane from a board lying on the floor (thesis §4.4).

The board's pose in the rig frame is refined over every camera that sees it (reprojection
least squares, 6 unknowns); the world frame is then the board frame with z turned to point
up toward the cameras: origin at the board's corner 0 (shifted down by the board's
thickness), x along the board's first row, z up, so the floor is z = 0.

:func:`floor_check` then asks each camera on its own (PnP of the floor board with its
calibrated intrinsics) where the floor corners are, and reports how far from z = 0 each
camera puts them and the reprojection error of the calibrated floor in that camera.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

from calibration.camera import Camera
from calibration.rotation import matrix_to_rotvec, rotvec_to_matrix
from calibration.detect import Detection
from calibration.errors import CalibrationError
from calibration.extrinsics import solve_board_pose
from calibration.ground import GroundPlane

__all__ = ["FloorResult", "fit_floor_board", "world_from_floor", "floor_check", "calibrate_floor", "transform_cameras"]

log = logging.getLogger(__name__)


def fit_floor_board(
    cameras: dict[str, Camera], detections: dict[str, Detection], *, loss: str = "soft_l1"
) -> tuple[np.ndarray, np.ndarray, dict]:
    """Pose ``(R_rig_from_board, t)`` of one board seen by several calibrated cameras.

    Returns the pose and ``{camera: rms px}``.
    """
    seen = {c: d for c, d in detections.items() if c in cameras and d.usable}
    if not seen:
        raise CalibrationError(
            f"the floor board was not detected by any camera ({sorted(detections)}); lay the board flat "
            "on the floor where every camera sees it whole and capture one frame"
        )
    best = max(seen, key=lambda c: seen[c].n)
    Rcb, tcb, _ = solve_board_pose(cameras[best], seen[best])
    cb = cameras[best]
    R0 = cb.R.T @ Rcb
    t0 = cb.R.T @ (tcb - cb.t)

    def residual(p):
        R = rotvec_to_matrix(p[:3])
        out = []
        for c, d in seen.items():
            X = d.object_points @ R.T + p[3:]
            out.append((cameras[c].project(X) - d.image_points).ravel())
        return np.concatenate(out)

    sol = least_squares(residual, np.concatenate([matrix_to_rotvec(R0), t0]), loss=loss, f_scale=1.0)
    R, t = rotvec_to_matrix(sol.x[:3]), sol.x[3:]
    rms = {}
    for c, d in seen.items():
        e = cameras[c].project(d.object_points @ R.T + t) - d.image_points
        rms[c] = float(np.sqrt(np.mean(np.sum(e**2, axis=1))))
    return R, t, rms


def world_from_floor(
    cameras: dict[str, Camera],
    placements: list[tuple[np.ndarray, np.ndarray]],
    board_points: np.ndarray,
    thickness: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """``(R_rig_from_world, t)`` of the world frame defined by floor-board placements.

    ``placements`` are board poses ``(R_rig_from_board, t)``; ``board_points`` (N, 3) the
    board corners. The floor normal is the least-squares plane through the corners of all
    placements (one placement: its own normal), oriented toward the cameras (z up); x is the
    first placement's x axis projected onto the plane; the origin is the first placement's
    corner 0 lowered by ``thickness`` onto the floor.
    """
    pts = np.concatenate([board_points @ R.T + t for R, t in placements])
    R0, t0 = placements[0]
    if len(placements) == 1:
        n = R0[:, 2].copy()
        p0 = t0
    else:
        centroid = pts.mean(0)
        _, _, Vt = np.linalg.svd(pts - centroid)
        n = Vt[2]
        p0 = t0 - n * (n @ (t0 - centroid))  # corner 0 projected onto the fitted plane
    centres = np.array([c.center for c in cameras.values()])
    if np.median((centres - p0) @ n) < 0:
        n = -n
    x = R0[:, 0] - n * (n @ R0[:, 0])
    x /= np.linalg.norm(x)
    y = np.cross(n, x)
    R_rw = np.stack([x, y, n], axis=1)
    t_rw = p0 - thickness * n
    return R_rw, t_rw


def transform_cameras(cameras: dict[str, Camera], R_rw: np.ndarray, t_rw: np.ndarray) -> dict[str, Camera]:
    """Cameras re-expressed in a new world frame given ``X_rig = R_rw X_w + t_rw``."""
    out = {}
    for n, c in cameras.items():
        R = c.R @ R_rw
        R = _orthonormal(R)
        out[n] = c.replace(R=R, t=c.R @ t_rw + c.t)
    return out


def _orthonormal(R: np.ndarray) -> np.ndarray:
    U, _, Vt = np.linalg.svd(R)
    return U @ np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))]) @ Vt


def floor_check(
    cameras: dict[str, Camera], detections: dict[str, Detection], ground: GroundPlane | None = None
) -> dict[str, dict]:
    """Does each camera see the floor board where the calibration says the floor is?

    For every camera that sees the floor board: PnP with its own intrinsics and calibrated pose
    gives the corners in world coordinates; ``plane_mm`` is the largest distance of those
    corners from the ground plane (millimetres); ``tilt_deg`` the angle between the board plane
    this camera sees on its own and the ground plane; ``reproj_px`` is the RMS pixel error of the
    floor corners placed by the *calibration* (from all cameras) in this camera.
    """
    ground = GroundPlane.floor() if ground is None else ground
    seen = {c: d for c, d in detections.items() if c in cameras and d.usable}
    if not seen:
        raise CalibrationError("floor check: the floor board is not detected by any calibrated camera")
    # calibrated board pose, world frame
    Rwb, twb, _ = fit_floor_board(cameras, seen)
    out = {}
    for c, d in seen.items():
        cam = cameras[c]
        Rcb, tcb, _ = solve_board_pose(cam, d)
        Xw = (d.object_points @ Rcb.T + tcb - cam.t) @ cam.R  # R^T (X_c - t)
        dist = ground.signed_distance(Xw)
        e = cam.project(d.object_points @ Rwb.T + twb) - d.image_points
        normal_w = cam.R.T @ Rcb[:, 2]
        out[c] = {
            "tilt_deg": float(np.degrees(np.arccos(min(1.0, abs(float(normal_w @ ground.normal)))))),
            "plane_mm": float(np.max(np.abs(dist)) * 1000),
            "mean_height_mm": float(np.mean(dist) * 1000),
            "reproj_px": float(np.sqrt(np.mean(np.sum(e**2, axis=1)))),
            "corners": int(d.n),
        }
    return out


@dataclass(frozen=True)
class FloorResult:
    """Cameras in the world frame (floor z = 0), the ground plane and the per-camera check."""

    cameras: dict
    ground: GroundPlane
    R_rig_from_world: np.ndarray
    t_rig_from_world: np.ndarray
    board_rms: dict
    check: dict = field(default_factory=dict)
    placements: list = field(default_factory=list)  # the floor detections used, numbered alike across cameras


def calibrate_floor(
    cameras: dict[str, Camera],
    detections: dict[str, Detection] | list[dict[str, Detection]],
    *,
    thickness: float = 0.0,
    max_plane_mm: float | None = None,
    max_tilt_deg: float | None = None,
    board=None,
) -> FloorResult:
    """Move a calibrated rig into the world frame of a floor board (floor z = 0, z up).

    Parameters
    ----------
    cameras : dict[str, Camera]
        Rig cameras in any common frame (e.g. the reference camera's).
    detections : dict[str, Detection] or a list of them
        The floor board as seen by (some of) the cameras, one dict per placement of the board
        on the floor; the first placement sets the origin and x axis, all of them the plane.
    thickness : float
        Board thickness in metres: the printed face is this far above the floor.
    max_plane_mm : float, optional
        Raise if any camera puts the floor corners further than this from z = 0.
    max_tilt_deg : float, optional
        Raise if the board plane any camera sees on its own is tilted more than this from the floor.
    board : Board, optional
        The floor board: a half-turn-symmetric checkerboard's numbering is first made to agree
        across the calibrated cameras (:func:`calibration.halfturn.align_to_rig`).

    Every camera must end up above the floor (world z up): a camera below it means the rig
    and the floor board disagree (e.g. a mirrored rig) and is refused by name.
    """
    if thickness < 0:
        raise CalibrationError(f"floor board thickness must be >= 0 metres, got {thickness}")
    placements = [detections] if isinstance(detections, dict) else list(detections)
    if not placements:
        raise CalibrationError("no floor-board views given; lay the board flat on the floor and capture it")
    if board is not None:
        from calibration.halfturn import align_to_rig

        aligned = []
        for k, dets in enumerate(placements):
            dets, renumbered = align_to_rig(cameras, dets, board)
            if renumbered:
                log.warning("floor board placement %d: corner numbering turned by 180 deg in cameras %s to agree with the rig", k, renumbered)
            aligned.append(dets)
        placements = aligned
    poses, rms = [], {}
    for k, dets in enumerate(placements):
        R, t, r = fit_floor_board(cameras, dets)
        poses.append((R, t))
        for c, v in r.items():
            rms[f"{c}/{k}"] = v
    board_points = np.unique(
        np.concatenate([d.object_points for dets in placements for d in dets.values() if d.usable]), axis=0
    )
    R_rw, t_rw = world_from_floor(cameras, poses, board_points, thickness)
    world = transform_cameras(cameras, R_rw, t_rw)
    below = {n: round(float(c.center[2]), 3) for n, c in world.items() if c.center[2] <= 0}
    if below:
        raise CalibrationError(
            f"cameras {below} (height, m) come out below the floor with z up: the rig and the floor board disagree "
            "(a mirrored rig or a board seen from below); recalibrate these cameras' extrinsics"
        )
    ground = GroundPlane.floor()
    surface = GroundPlane(np.array([0.0, 0.0, 1.0]), thickness)
    check = {}
    for k, dets in enumerate(placements):
        for c, v in floor_check(world, dets, surface).items():
            check[c if len(placements) == 1 else f"{c}/{k}"] = v
    gates = (("plane_mm", max_plane_mm, "mm", "see the floor board off the calibrated plane by more than {} mm; "
              "recalibrate these cameras' extrinsics or recapture the floor view"),
             ("tilt_deg", max_tilt_deg, "degrees", "see the floor board tilted from the fitted floor by more than {} deg; "
              "their extrinsics or the board's corner numbering disagree with the rig"))  # fmt: skip
    for key, limit, unit, why in gates:
        bad = {c: round(v[key], 1) for c, v in check.items() if limit is not None and v[key] > limit}
        if bad:
            raise CalibrationError(f"floor check failed: cameras {bad} ({unit}) {why.format(limit)}")
    return FloorResult(world, ground, R_rw, t_rw, rms, check, placements)

