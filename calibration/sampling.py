"""Choosing board views from videos or image folders: sharp and diverse.

A video of someone waving a board has hundreds of near-identical, partly blurred frames.
:func:`sample_views` keeps the detected frames whose board corners are sharp (edge steepness
over contrast, :func:`sharpness`, at least ``min_rel_sharpness`` × the median of the detected
frames) and then picks
``n_views`` of them by greedy farthest-point sampling on a pose descriptor (where the board
is in the image, how big, how foreshortened and in which direction), so the kept views cover
the image and the tilts instead of repeating one pose.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calibration.boards import Board
from calibration.detect import Detection, detect_board, read_image, to_gray
from calibration.errors import CalibrationError

__all__ = ["sharpness", "view_descriptor", "select_diverse", "iter_video_frames", "sample_views", "SampledViews"]

log = logging.getLogger(__name__)

VIDEO_SUFFIXES = {".mp4", ".avi", ".mov", ".mkv", ".webm", ".m4v"}


def sharpness(gray: np.ndarray, points: np.ndarray | None = None, half: int = 5) -> float:
    """Edge sharpness ``(1/px)``: steepest gradient over local contrast, median over ``points``.

    For each corner (N, 2) a ``(2 half + 1)²`` window gives ``max |∇I| / (p95 − p5 of I)``:
    about 0.5 for a crisp edge and ``≈ 1 / (σ √(2π))`` for one blurred by a Gaussian of σ
    pixels, whatever the square size or the lighting. Without points, the whole image's
    variance of the Laplacian is returned instead.
    """
    import cv2

    g = np.asarray(gray, np.float32)
    if points is None or len(points) == 0:
        return float(cv2.Laplacian(g, cv2.CV_32F).var())
    gx = cv2.Sobel(g, cv2.CV_32F, 1, 0, ksize=3) / 8
    gy = cv2.Sobel(g, cv2.CV_32F, 0, 1, ksize=3) / 8
    mag = np.hypot(gx, gy)
    h, w = g.shape
    vals = []
    for x, y in np.round(points).astype(int):
        x0, x1, y0, y1 = max(x - half, 0), min(x + half + 1, w), max(y - half, 0), min(y + half + 1, h)
        if x1 - x0 < 3 or y1 - y0 < 3:
            continue
        patch = g[y0:y1, x0:x1]
        lo, hi = np.percentile(patch, [5, 95])
        if hi - lo < 10:
            continue
        vals.append(float(mag[y0:y1, x0:x1].max() / (hi - lo)))
    return float(np.median(vals)) if vals else 0.0


def view_descriptor(det: Detection) -> np.ndarray:
    """(6,) pose descriptor: centre (2, in image fractions), size, elongation, orientation (cos 2θ, sin 2θ)."""
    w, h = det.image_size
    p = det.image_points
    c = p.mean(0) / [w, h]
    cov = np.cov((p - p.mean(0)).T) if len(p) > 2 else np.eye(2)
    evals, evecs = np.linalg.eigh(cov)
    evals = np.maximum(evals, 1e-9)
    size = np.sqrt(np.sqrt(evals[0] * evals[1])) / max(w, h) * 4
    # foreshortening of the board changes the ratio of the corner spread relative to the board's own
    obj = det.object_points[:, :2]
    ocov = np.cov((obj - obj.mean(0)).T) if len(obj) > 2 else np.eye(2)
    oe = np.maximum(np.linalg.eigvalsh(ocov), 1e-12)
    elong = 0.5 * np.log((evals[1] / evals[0]) / (oe[1] / oe[0]))
    theta = np.arctan2(evecs[1, 1], evecs[0, 1])
    return np.array([c[0], c[1], size, elong, 0.3 * np.cos(2 * theta), 0.3 * np.sin(2 * theta)])


def select_diverse(descriptors: np.ndarray, n: int, first: int = 0) -> list[int]:
    """Greedy farthest-point sampling: indices of ``n`` rows of ``descriptors`` (M, D) far apart."""
    m = len(descriptors)
    if n >= m:
        return list(range(m))
    chosen = [first]
    d = np.linalg.norm(descriptors - descriptors[first], axis=1)
    while len(chosen) < n:
        k = int(np.argmax(d))
        chosen.append(k)
        d = np.minimum(d, np.linalg.norm(descriptors - descriptors[k], axis=1))
    return sorted(chosen)


def iter_video_frames(path: str | Path, step: int = 1):
    """Yield ``(frame_index, RGB (H, W, 3) uint8)`` for every ``step``-th frame of a video file."""
    import cv2

    if step < 1:
        raise CalibrationError(f"{path}: frame step must be >= 1, got {step}")
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise CalibrationError(f"{path}: cannot open this video")
    try:
        k = 0
        while True:
            ok = cap.grab()
            if not ok:
                break
            if k % step == 0:
                ok, bgr = cap.retrieve()
                if ok:
                    yield k, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
            k += 1
    finally:
        cap.release()


@dataclass(frozen=True)
class SampledViews:
    """Views kept from a video / folder, and why the others were dropped.

    kept : list[Detection]; dropped : dict[view, reason]; sharpness : dict[view, float]
    """

    kept: list
    dropped: dict
    sharpness: dict = field(default_factory=dict)


def sample_views(
    source,
    board: Board,
    *,
    n_views: int = 30,
    step: int = 1,
    min_rel_sharpness: float = 0.6,
    max_side: int = 1000,
    progress=None,
) -> SampledViews:
    """Detect the board in a video file, an image folder or an iterable of ``(label, RGB)``, keep sharp diverse views.

    Parameters
    ----------
    source : path to a video / folder of images, or iterable of (label, image)
    n_views : int
        At most this many views are kept.
    step : int
        Video: look at every ``step``-th frame.
    min_rel_sharpness : float
        Drop views whose board region is less sharp than this fraction of the median.
    progress : callable(done, total or None), optional
    """
    frames = _frames(source, step)
    dets, sharp, dropped = [], {}, {}
    for k, (label, image) in enumerate(frames):
        det = detect_board(image, board, view=str(label), max_side=max_side)
        if progress is not None:
            progress(k + 1, None)
        if not det.usable:
            dropped[det.view] = det.reason
            continue
        sharp[det.view] = sharpness(to_gray(image), det.image_points)
        dets.append(det)
    if not dets:
        raise CalibrationError(
            f"{source}: the board {board.name!r} was not detected in any of {len(dropped)} frames; "
            "check the board file and that the whole board is visible and in focus"
        )
    med = float(np.median(list(sharp.values())))
    sharp_dets = []
    for d in dets:
        if sharp[d.view] < min_rel_sharpness * med:
            dropped[d.view] = f"blurred: sharpness {sharp[d.view]:.3f} < {min_rel_sharpness:g} x median {med:.3f} /px"
        else:
            sharp_dets.append(d)
    desc = np.array([view_descriptor(d) for d in sharp_dets])
    first = int(np.argmax([sharp[d.view] for d in sharp_dets]))
    keep = set(select_diverse(desc, n_views, first))
    kept = []
    for i, d in enumerate(sharp_dets):
        if i in keep:
            kept.append(d)
        else:
            dropped[d.view] = "similar to a kept view (diversity sampling)"
    log.info("%s: kept %d of %d detected views", source, len(kept), len(dets))
    return SampledViews(kept, dropped, sharp)


def _frames(source, step):
    if isinstance(source, (str, Path)):
        path = Path(source)
        if path.is_dir():
            files = sorted(p for p in path.iterdir() if p.suffix.lower() in {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"})
            if not files:
                raise CalibrationError(f"{path}: no images (.png/.jpg/...) in this folder")
            return ((p.name, read_image(p)) for p in files[::step])
        if path.suffix.lower() in VIDEO_SUFFIXES:
            return ((f"{path.stem}#{k:06d}", img) for k, img in iter_video_frames(path, step))
        if not path.exists():
            raise CalibrationError(f"{path}: no such video or image folder")
        raise CalibrationError(f"{path}: not a folder or a video ({sorted(VIDEO_SUFFIXES)})")
    return iter(source)
