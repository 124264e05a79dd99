"""Checkerboards OpenCV's detectors miss: small, oblique boards found through their quadrilateral.

A board lying on the floor far from a camera is a thin sliver of squares a few pixels high;
``cv2.findChessboardCorners`` and ``findChessboardCornersSB`` both give up on it (two of the
four cameras of the Utrecht INFOMCV rig). The paper it is printed on is still an obvious
bright quadrilateral, so:

1. :func:`find_quads` — bright, convex, four-sided blobs (Otsu and adaptive thresholds);
2. :func:`rectify` — each quadrilateral warped onto a padded rectangle (a homography, exact for
   a plane up to lens distortion, which is negligible over a small board), where the squares
   are large and square; the dark squares, shrunk by blur and bloom, are grown back by an
   erosion of the white before OpenCV's detector runs on the rectified image;
3. the corners are refined (``cv2.cornerSubPix``) in the rectified image, where the refinement
   window fits inside a square, and mapped back through the inverse homography.

The last resort is the user's own four outer corners (:func:`corners_from_outer`): the grid
predicted by the homography of those four points is refined the same way. Because the user
names corner 0, this path also fixes the board's labelling (a symmetric board's half-turn).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

from calibration.boards import Board
from calibration.errors import CalibrationError

__all__ = ["find_quads", "rectify", "detect_in_quad", "detect_by_quads", "corners_from_outer", "load_outer_corners", "parse_outer_corners"]

log = logging.getLogger(__name__)

#: Rectified board: squares of about this many pixels, plus this many squares of padding.
RECT_SQUARE_PX = 48
RECT_PAD_SQUARES = 2.5
#: Erosions of the white tried before detection, as fractions of a rectified square.
ERODE_FRACTIONS = (0.0, 0.15, 0.27)
MAX_QUADS = 3
#: Quadrilaterals whose dark-square count is further than this from the board's (:func:`checker_score`) are not tried.
MAX_CHECKER_SCORE = 0.9


def find_quads(gray: np.ndarray, board: Board, *, min_area: float = 150.0, max_fraction: float = 0.3) -> list[np.ndarray]:
    """Bright convex four-sided regions of ``gray`` (H, W) uint8 that may hold ``board`` → list of (4, 2) float32, clockwise.

    Best :func:`checker_score` first (at most :data:`MAX_QUADS`, none worse than
    :data:`MAX_CHECKER_SCORE`); near-duplicates (vertices within 3 px) dropped.
    """
    import cv2

    h, w = gray.shape
    found: list[tuple[float, np.ndarray]] = []
    binaries = [cv2.threshold(gray, 0, 255, cv2.THRESH_BINARY + cv2.THRESH_OTSU)[1]]
    binaries += [cv2.adaptiveThreshold(gray, 255, cv2.ADAPTIVE_THRESH_MEAN_C, cv2.THRESH_BINARY, b, -5) for b in (31, 61)]
    for bw in binaries:
        bw = cv2.morphologyEx(bw, cv2.MORPH_CLOSE, np.ones((5, 5), np.uint8))
        contours, _ = cv2.findContours(bw, cv2.RETR_LIST, cv2.CHAIN_APPROX_SIMPLE)
        for c in contours:
            area = cv2.contourArea(c)
            if area < min_area or area > max_fraction * h * w:
                continue
            hull = cv2.convexHull(c)
            poly = cv2.approxPolyDP(hull, 0.03 * cv2.arcLength(hull, True), True).reshape(-1, 2)
            if len(poly) != 4 or cv2.contourArea(hull) > 1.3 * area:
                continue
            q = poly.astype(np.float32)
            if _signed_area(q) < 0:
                q = q[::-1].copy()
            if any(_same_quad(q, other) for _, other in found):
                continue
            found.append((float(area), q))
    scored = [(checker_score(gray, q, board), -area, q) for area, q in found]
    scored = [s for s in scored if s[0] <= MAX_CHECKER_SCORE]
    scored.sort(key=lambda s: (s[0], s[1]))
    return [q for _, _, q in scored[:MAX_QUADS]]


def checker_score(gray: np.ndarray, quad: np.ndarray, board: Board) -> float:
    """How far the inside of ``quad`` is from ``board``'s dark squares: |n - expected| / expected,
    with n the dark blobs of a square's size in a rectified copy (0 for a perfect match)."""
    import cv2

    cols, rows = board.corner_grid
    n_sq = (cols + 1) * (rows + 1)
    expected = (n_sq + 1) // 2
    W, H = 16 * (max(cols, rows) + 2), 16 * (min(cols, rows) + 2)
    M = cv2.getPerspectiveTransform(np.asarray(quad, np.float32), np.float32([[0, 0], [W - 1, 0], [W - 1, H - 1], [0, H - 1]]))
    small = cv2.warpPerspective(gray, M, (W, H), flags=cv2.INTER_AREA)
    if int(small.max()) - int(small.min()) < 40:
        return float("inf")
    _, dark = cv2.threshold(small, 0, 255, cv2.THRESH_BINARY_INV + cv2.THRESH_OTSU)
    dark = cv2.erode(dark, np.ones((3, 3), np.uint8))  # blurred squares touch at their corners
    n, _, stats, _ = cv2.connectedComponentsWithStats(dark, connectivity=4)
    square_area = W * H / n_sq
    areas = stats[1:, cv2.CC_STAT_AREA]
    count = int(np.sum((areas > 0.15 * square_area) & (areas < 2.5 * square_area)))
    return abs(count - expected) / expected


def _signed_area(q: np.ndarray) -> float:
    x, y = q[:, 0], q[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _same_quad(a: np.ndarray, b: np.ndarray, tol: float = 3.0) -> bool:
    return any(np.max(np.linalg.norm(np.roll(a, k, axis=0) - b, axis=1)) < tol for k in range(4))


def rectify(gray: np.ndarray, quad: np.ndarray, size: tuple[int, int], pad: int) -> tuple[np.ndarray, np.ndarray]:
    """Warp the quadrilateral ``quad`` (4, 2) onto ``size`` = (W, H) with ``pad`` pixels around it.

    Returns ``(rectified (H, W) uint8, H_rect_from_image (3, 3))``.
    """
    import cv2

    w, h = size
    dst = np.float32([[pad, pad], [w - pad, pad], [w - pad, h - pad], [pad, h - pad]])
    H = cv2.getPerspectiveTransform(np.asarray(quad, np.float32), dst)
    rect = cv2.warpPerspective(gray, H, (w, h), flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
    return rect, H


def _map(H: np.ndarray, pts: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.perspectiveTransform(np.asarray(pts, np.float64).reshape(-1, 1, 2), H).reshape(-1, 2)


def _refine(rect: np.ndarray, pts: np.ndarray, square_px: float) -> np.ndarray:
    import cv2

    win = int(np.clip(0.35 * square_px, 3, 21))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 60, 1e-3)
    out = cv2.cornerSubPix(rect, np.asarray(pts, np.float32).reshape(-1, 1, 2), (win, win), (-1, -1), criteria)
    return out.reshape(-1, 2).astype(np.float64)


def _rect_geometry(quad: np.ndarray, board: Board) -> tuple[tuple[int, int], int, float]:
    """Rectified image size, padding and square size in pixels for a quadrilateral of ``board``."""
    cols, rows = board.corner_grid
    long_side = max(np.linalg.norm(quad[1] - quad[0]), np.linalg.norm(quad[3] - quad[2]))
    short_side = max(np.linalg.norm(quad[2] - quad[1]), np.linalg.norm(quad[0] - quad[3]))
    squares = (cols + 1, rows + 1) if long_side >= short_side else (rows + 1, cols + 1)
    sq = RECT_SQUARE_PX
    pad = int(RECT_PAD_SQUARES * sq)
    size = (int(squares[0] * sq + 2 * pad), int(squares[1] * sq + 2 * pad))
    return size, pad, float(sq)


def detect_in_quad(gray: np.ndarray, quad: np.ndarray, board: Board) -> np.ndarray | None:
    """Inner corners (N, 2) of ``board`` inside the image quadrilateral ``quad``, or None.

    Corners come in OpenCV's order for the rectified view (row by row); which end is corner 0
    is as ambiguous as with OpenCV's own detector for symmetric boards.
    """
    import cv2

    from calibration.detect import find_chessboard_sb

    size, pad, sq = _rect_geometry(np.asarray(quad, np.float64), board)
    rect, H = rectify(gray, quad, size, pad)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    eroded = [cv2.erode(rect, np.ones((k, k), np.uint8)) if k else rect
              for k in (int(round(f * sq)) | 1 if f > 0 else 0 for f in ERODE_FRACTIONS)]  # fmt: skip
    finders = (lambda x: cv2.findChessboardCorners(x, board.corner_grid, flags=flags),
               lambda x: find_chessboard_sb(x, board.corner_grid, cv2.CALIB_CB_NORMALIZE_IMAGE))  # fmt: skip
    for find in finders:  # the fast detector on every erosion first
        for img in eroded:
            found, corners = find(img)
            if found:
                refined = _refine(rect, corners.reshape(-1, 2), sq)
                return _map(np.linalg.inv(H), refined)
    return None


def detect_by_quads(gray: np.ndarray, board: Board) -> np.ndarray | None:
    """:func:`detect_in_quad` on each of :func:`find_quads`; the first board found (N, 2), or None."""
    for quad in find_quads(gray, board):
        pts = detect_in_quad(gray, quad, board)
        if pts is not None:
            return pts
    return None


def corners_from_outer(gray: np.ndarray, outer: np.ndarray, board: Board) -> np.ndarray:
    """All inner corners (N, 2), in board order, from the four outer inner corners given by a user.

    ``outer`` (4, 2): pixels of corner 0, of the last corner of the first row, of the last
    corner, and of the first corner of the last row (OpenCV's numbering, see
    :attr:`Board.object_points`). The grid follows from their homography and is refined in
    the rectified image.
    """
    import cv2

    outer = np.asarray(outer, np.float64)
    if outer.shape != (4, 2) or not np.all(np.isfinite(outer)):
        raise CalibrationError(f"four outer corners must be 4 (x, y) pixel pairs, got shape {outer.shape}")
    if abs(_signed_area(outer)) < 10.0:
        raise CalibrationError(f"the four outer corners {outer.tolist()} enclose no area (collinear or repeated)")
    cols, rows = board.corner_grid
    sq = RECT_SQUARE_PX
    pad = int(RECT_PAD_SQUARES * sq)
    grid = np.array([[0, 0], [cols - 1, 0], [cols - 1, rows - 1], [0, rows - 1]], np.float64) * sq + pad
    H = cv2.getPerspectiveTransform(outer.astype(np.float32), grid.astype(np.float32))  # rect <- image
    size = (int((cols - 1) * sq + 2 * pad), int((rows - 1) * sq + 2 * pad))
    rect = cv2.warpPerspective(gray, H, size, flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REPLICATE)
    ids = np.arange(board.n_corners)
    predicted = np.stack([ids % cols, ids // cols], axis=1) * sq + pad
    refined = _refine(rect, predicted, sq)
    moved = np.linalg.norm(refined - predicted, axis=1)
    if np.median(moved) > 0.3 * sq:
        raise CalibrationError(
            f"the four outer corners do not fit a {cols}x{rows} grid here (corners moved {np.median(moved) / sq:.2f} "
            "squares on refinement); give the outermost INNER corners, in order: corner 0, end of its row, "
            "the opposite corner, start of the last row"
        )
    return _map(np.linalg.inv(H), refined)


def load_outer_corners(path: str | Path) -> dict[str, np.ndarray]:
    """``{camera: (4, 2) pixels}`` from a small JSON file ``{"cam1": [[x, y], [x, y], [x, y], [x, y]], ...}``."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise CalibrationError(f"cannot read the outer-corners file ({exc.strerror})", file=path) from None
    except ValueError as exc:
        raise CalibrationError(f"not valid JSON ({exc})", file=path) from None
    return parse_outer_corners(data, path)


def parse_outer_corners(data, path: str | Path = "<corners>") -> dict[str, np.ndarray]:
    """Validate ``{camera: [[x, y] x 4]}`` (already parsed JSON) → ``{camera: (4, 2)}``."""
    if not isinstance(data, dict) or not data:
        raise CalibrationError('expected an object {"camera": [[x, y] x 4], ...}', file=path)
    out = {}
    for cam, pts in data.items():
        arr = np.asarray(pts, dtype=float) if isinstance(pts, list) else np.zeros(0)
        if arr.shape != (4, 2) or not np.all(np.isfinite(arr)):
            raise CalibrationError(
                "expected four [x, y] pixel pairs: corner 0, end of its row, opposite corner, start of the last row",
                file=path, camera=str(cam),
            )
        out[str(cam)] = arr
    return out
