"""Board detection with sub-pixel refinement, and the rules that keep or reject a view.

Checkerboards: ``cv2.findChessboardCorners`` on a copy downscaled to at most ``max_side``
pixels (big portrait photos take seconds at full size), then ``cv2.cornerSubPix`` at full
resolution with a window scaled to the square size in pixels.

ChArUco: OpenCV's current aruco API (``cv2.aruco.CharucoDetector``, OpenCV >= 4.7; the
pre-4.7 ``detectMarkers``/``interpolateCornersCharuco`` functions no longer exist in 5.0).
ChArUco views may be partial; a view is

- ``"ok"``        every corner found,
- ``"partial"``   at least ``min_corners`` found, spread over two dimensions (kept),
- ``"rejected"``  no board, too few corners, or all corners on one line (the reason says which).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from calibration.boards import Board
from calibration.errors import CalibrationError

__all__ = ["Detection", "detect_board", "detect_files", "read_image", "to_gray", "MIN_CORNERS"]

log = logging.getLogger(__name__)

MIN_CORNERS = 6  # fewer corners than this give no usable homography / pose
#: Sub-pixel refinement half-window as a fraction of the smallest square side in pixels
#: (larger windows reach across into the next corner on small, tilted boards).
SUBPIX_WINDOW_FRACTION = 0.4


@dataclass(frozen=True)
class Detection:
    """Board corners found in one image.

    Attributes
    ----------
    view : str
        Label of the view (file name or frame index).
    ids : (N,) int64
        Corner ids into :attr:`Board.object_points`.
    image_points : (N, 2) float64
        Pixel positions (OpenCV convention, (0, 0) = centre of the top-left pixel).
    object_points : (N, 3) float64
        The same corners in the board frame, metres.
    image_size : (width, height)
    status : ``"ok"``, ``"partial"`` or ``"rejected"``
    reason : str
        Why a view is partial or rejected ('' when ok).
    """

    view: str
    ids: np.ndarray
    image_points: np.ndarray
    object_points: np.ndarray
    image_size: tuple[int, int]
    status: str = "ok"
    reason: str = ""
    extra: dict = field(default_factory=dict, compare=False)

    @property
    def usable(self) -> bool:
        return self.status != "rejected"

    @property
    def n(self) -> int:
        return int(len(self.ids))

    @classmethod
    def rejected(cls, view: str, image_size: tuple[int, int], reason: str) -> "Detection":
        return cls(
            view=view,
            ids=np.zeros(0, np.int64),
            image_points=np.zeros((0, 2)),
            object_points=np.zeros((0, 3)),
            image_size=image_size,
            status="rejected",
            reason=reason,
        )


def to_gray(image: np.ndarray) -> np.ndarray:
    """``(H, W)`` uint8 grey from an RGB ``(H, W, 3)`` or grey image (uint8 or uint16)."""
    import cv2

    img = np.asarray(image)
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)
    elif img.dtype != np.uint8:
        raise CalibrationError(f"image must be uint8 or uint16, got {img.dtype}")
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    if img.ndim == 2:
        return img
    raise CalibrationError(f"image must be (H, W) or (H, W, 3), got shape {img.shape}")


def _spread_rank(points: np.ndarray, tol: float) -> bool:
    """True when ``points`` (N, 2) span two dimensions (second singular value > ``tol`` pixels)."""
    if len(points) < 3:
        return False
    s = np.linalg.svd(points - points.mean(0), compute_uv=False)
    return bool(s[1] / np.sqrt(len(points)) > tol)


def detect_board(
    image: np.ndarray,
    board: Board,
    *,
    view: str = "",
    max_side: int = 1000,
    min_corners: int = MIN_CORNERS,
    robust: bool = False,
    outer_corners: np.ndarray | None = None,
) -> Detection:
    """Find ``board`` in ``image`` (RGB or grey) and refine the corners to sub-pixel accuracy.

    Parameters
    ----------
    image : (H, W, 3) or (H, W) uint8/uint16
    board : Board
    view : str
        Label carried into the :class:`Detection` and error messages.
    max_side : int
        Checkerboard search runs on a copy whose longer side is at most this many pixels.
    min_corners : int
        ChArUco views with fewer corners are rejected.
    robust : bool
        Checkerboards OpenCV misses: also try an upscaled copy, then the board's quadrilateral
        (:mod:`calibration.board_quad`); slower on views without a board (~1 s).
    outer_corners : (4, 2), optional
        The user's four outer inner corners (corner 0, end of its row, opposite corner, start
        of the last row): the grid is refined from them when every detector fails.

    The method that found the board is ``det.extra["method"]`` (``"opencv"``, ``"sb"``,
    ``"upscaled"``, ``"quad"`` or ``"user"``).
    """
    gray = to_gray(image)
    h, w = gray.shape
    if board.kind == "checkerboard":
        det = _detect_checkerboard(gray, board, view, max_side, robust or outer_corners is not None, outer_corners)
    else:
        det = _detect_charuco(gray, board, view, min_corners)
    if det.usable and not _spread_rank(det.image_points, tol=1.0):
        return Detection.rejected(view, (w, h), f"{det.n} corners all on one line (degenerate view)")
    return det


def find_chessboard_sb(gray: np.ndarray, pattern: tuple[int, int], flags: int):
    """``cv2.findChessboardCornersSB`` made repeatable: it draws from OpenCV's global random
    generator, so the same image could give differently numbered corners depending on what ran
    before in the process (seen on the Pose2Sim photos); the generator is seeded first."""
    import cv2

    cv2.setRNGSeed(0)
    return cv2.findChessboardCornersSB(gray, pattern, flags=flags)


def _find_checkerboard(gray: np.ndarray, board: Board, max_side: int, robust: bool) -> tuple[np.ndarray | None, str]:
    """Corners (N, 2) at full resolution before refinement, and the method that found them."""
    import cv2

    h, w = gray.shape
    pattern = board.corner_grid
    scale = min(1.0, max_side / max(h, w))
    if robust and scale == 1.0 and max(h, w) <= 1200:
        scales = (1.0, 2.0)  # small images: an upscaled copy helps both detectors on tiny squares
    else:
        scales = (scale,)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    for s in scales:
        if s > 1 and robust:  # the board's quadrilateral before the (slow) upscaled search
            from calibration.board_quad import detect_by_quads

            pts = detect_by_quads(gray, board)
            if pts is not None:
                return pts, "quad"
        interp = cv2.INTER_AREA if s < 1 else cv2.INTER_CUBIC
        img = cv2.resize(gray, (round(w * s), round(h * s)), interpolation=interp) if s != 1 else gray
        for method, find in (("opencv", lambda x: cv2.findChessboardCorners(x, pattern, flags=flags)),
                             ("sb", lambda x: find_chessboard_sb(x, pattern, cv2.CALIB_CB_EXHAUSTIVE))):
            found, corners = find(img)
            if found:
                # (0,0) is a pixel centre in both images: x_full = (x_scaled + 0.5) / s - 0.5
                return (corners.reshape(-1, 2).astype(np.float64) + 0.5) / s - 0.5, method if s <= 1 else "upscaled"
    if robust and len(scales) == 1:
        from calibration.board_quad import detect_by_quads

        pts = detect_by_quads(gray, board)
        if pts is not None:
            return pts, "quad"
    return None, ""


def _detect_checkerboard(gray: np.ndarray, board: Board, view: str, max_side: int, robust: bool = False,
                         outer_corners: np.ndarray | None = None) -> Detection:  # fmt: skip
    import cv2

    h, w = gray.shape
    pattern = board.corner_grid
    pts, method = (None, "") if outer_corners is not None else _find_checkerboard(gray, board, max_side, robust)
    if pts is None and outer_corners is not None:
        from calibration.board_quad import corners_from_outer

        pts, method = corners_from_outer(gray, outer_corners, board), "user"
        ids = np.arange(board.n_corners, dtype=np.int64)
        return Detection(view, ids, pts, board.object_points[ids], (w, h), "ok", "", {"method": method})
    if pts is None:
        return Detection.rejected(
            view, (w, h), f"checkerboard {pattern[0]}x{pattern[1]} not found (whole board must be visible)"
        )
    if method == "quad":  # refined in the rectified view already
        ids = np.arange(board.n_corners, dtype=np.int64)
        return Detection(view, ids, pts, board.object_points[ids], (w, h), "ok", "", {"method": method})
    # sub-pixel window: ~40 % of the smallest square side in pixels, 3..15
    grid = pts.reshape(pattern[1], pattern[0], 2)
    side = min(
        np.linalg.norm(np.diff(grid, axis=1), axis=2).min() if pattern[0] > 1 else np.inf,
        np.linalg.norm(np.diff(grid, axis=0), axis=2).min() if pattern[1] > 1 else np.inf,
    )
    win = int(np.clip(side * SUBPIX_WINDOW_FRACTION, 3, 15))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    refined = cv2.cornerSubPix(gray, pts.astype(np.float32).reshape(-1, 1, 2), (win, win), (-1, -1), criteria)
    pts = refined.reshape(-1, 2).astype(np.float64)
    ids = np.arange(board.n_corners, dtype=np.int64)
    return Detection(view, ids, pts, board.object_points[ids], (w, h), "ok", "", {"subpix_window": win, "method": method})


def _detect_charuco(gray: np.ndarray, board: Board, view: str, min_corners: int) -> Detection:
    import cv2

    h, w = gray.shape
    params = cv2.aruco.CharucoParameters()
    params.tryRefineMarkers = True
    det_params = cv2.aruco.DetectorParameters()
    det_params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
    detector = cv2.aruco.CharucoDetector(board.cv_board, params, det_params)
    corners, ids, _marker_corners, marker_ids = detector.detectBoard(gray)
    n_markers = 0 if marker_ids is None else len(marker_ids)
    if ids is None or len(ids) == 0:
        return Detection.rejected(
            view, (w, h), f"no ChArUco corners ({n_markers} {board.dictionary} markers seen)"
        )
    ids = ids.reshape(-1).astype(np.int64)
    pts = corners.reshape(-1, 2).astype(np.float64)
    if len(ids) < min_corners:
        return Detection.rejected(view, (w, h), f"only {len(ids)} ChArUco corners (< {min_corners})")
    order = np.argsort(ids)
    ids, pts = ids[order], pts[order]
    status, reason = "ok", ""
    if len(ids) < board.n_corners:
        status, reason = "partial", f"{len(ids)}/{board.n_corners} corners"
    return Detection(view, ids, pts, board.object_points[ids], (w, h), status, reason, {"markers": n_markers})


def read_image(path) -> np.ndarray:
    """RGB ``(H, W, 3)`` uint8 of an image file (JPEG, PNG, ... via OpenCV)."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise CalibrationError(f"{path}: cannot read this image (missing or not an image file)")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def detect_files(paths, board: Board, *, max_side: int = 1000, progress=None) -> list[Detection]:
    """:func:`detect_board` on each image file; the view label is the file name.

    ``progress`` is an optional callable ``progress(done, total)``.
    """
    from pathlib import Path

    paths = [Path(p) for p in paths]
    out = []
    for k, p in enumerate(paths):
        out.append(detect_board(read_image(p), board, view=p.name, max_side=max_side))
        if progress is not None:
            progress(k + 1, len(paths))
    return out
