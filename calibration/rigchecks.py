"""Sanity checks of a solved rig against things known independently: the board's square size, camera heights.

:func:`scale_check` triangulates the board's corners from every camera that sees them (linear
multi-view triangulation on undistorted rays) and compares the spacing of neighbouring corners
with the board's square size: a rig in millimetres read as metres, or extrinsics from another
board, shows up as a ratio far from 1. :func:`camera_heights` reports how high each camera is
above the floor and refuses heights no lab rig has.
"""

from __future__ import annotations

import logging

import numpy as np

from calibration.boards import Board
from calibration.detect import Detection
from calibration.errors import CalibrationError

__all__ = ["triangulate", "scale_check", "camera_heights", "MAX_SCALE_ERROR", "HEIGHT_RANGE_M"]

log = logging.getLogger(__name__)

#: Largest accepted relative difference between the triangulated and the printed square size.
MAX_SCALE_ERROR = 0.05
#: Camera heights above the floor a rig can have (metres).
HEIGHT_RANGE_M = (0.1, 15.0)


def triangulate(cameras: dict, pixels: dict[str, np.ndarray]) -> np.ndarray:
    """Points (N, 3) from their pixels ``{camera: (N, 2)}`` in two or more cameras (linear, DLT on ideal rays)."""
    rows = []
    for name, uv in pixels.items():
        cam = cameras[name]
        x = cam.undistort_pixels(np.asarray(uv, float))  # ideal pinhole pixels
        xn = (x - cam.K[:2, 2]) / np.array([cam.K[0, 0], cam.K[1, 1]])
        P = np.hstack([cam.R, cam.t.reshape(3, 1)])
        rows.append(np.stack([xn[:, 0:1] * P[2] - P[0], xn[:, 1:2] * P[2] - P[1]], axis=1))  # (N, 2, 4)
    A = np.concatenate(rows, axis=1)  # (N, 2C, 4)
    _, _, Vt = np.linalg.svd(A)
    X = Vt[:, -1, :]
    return X[:, :3] / X[:, 3:4]


def scale_check(cameras: dict, detections: dict[str, Detection], board: Board, *, max_error: float = MAX_SCALE_ERROR) -> dict:
    """Square size measured on the triangulated board vs the printed one.

    Returns ``{"square_m": measured, "printed_m": board.square_size, "ratio": measured / printed,
    "cameras": [...]}``; raises :class:`CalibrationError` when the ratio is off by more than
    ``max_error`` (units, or extrinsics that do not belong to this board). Fewer than two cameras
    seeing the whole board: ``ratio`` is None and ``skipped`` says why.
    """
    seen = {c: d for c, d in detections.items() if c in cameras and d.usable and d.n == board.n_corners}
    if len(seen) < 2:
        return {"square_m": None, "printed_m": board.square_size, "ratio": None, "cameras": sorted(seen),
                "skipped": f"the whole board is seen by {len(seen)} camera(s); triangulation needs two"}
    X = triangulate(cameras, {c: d.image_points for c, d in seen.items()})
    cols, rows = board.corner_grid
    grid = X.reshape(rows, cols, 3)
    steps = np.concatenate([np.linalg.norm(np.diff(grid, axis=1), axis=2).ravel(), np.linalg.norm(np.diff(grid, axis=0), axis=2).ravel()])
    measured = float(np.median(steps))
    ratio = measured / board.square_size
    out = {"square_m": measured, "printed_m": board.square_size, "ratio": ratio, "cameras": sorted(seen)}
    if abs(ratio - 1) > max_error:
        raise CalibrationError(
            f"scale check failed: the board triangulated from cameras {sorted(seen)} has {1000 * measured:.1f} mm squares, "
            f"the board file says {1000 * board.square_size:.1f} mm (ratio {ratio:.3f}); the extrinsics are in other units "
            "or belong to another board"
        )
    return out


def camera_heights(cameras: dict, ground, *, limits: tuple[float, float] = HEIGHT_RANGE_M) -> dict[str, float]:
    """Height (m) of every camera centre above ``ground``; refuses heights outside ``limits``."""
    heights = {n: float(ground.signed_distance(c.center.reshape(1, 3))[0]) for n, c in cameras.items()}
    bad = {n: round(h, 3) for n, h in heights.items() if not limits[0] <= h <= limits[1]}
    if bad:
        raise CalibrationError(
            f"cameras {bad} are implausibly high above the floor (m; expected {limits[0]}-{limits[1]} m): "
            "check the units of the calibration and the board's square size"
        )
    return heights
