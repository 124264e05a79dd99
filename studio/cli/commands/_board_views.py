"""Board views for ``studio calibrate extrinsics|floor``: image folders, single images or videos, and the user's corners file.

A video contributes the frames chosen by ``--video-frames`` (default: :data:`DEFAULT_VIDEO_FRAMES`
frames spread over it); the view key of a frame is its index, so frame k of every camera's video
is one instant seen by all cameras. Detection runs the robust path (upscaling, the board's
quadrilateral; :mod:`calibration.board_quad`), and a camera named in the corners file gets the
user's corners or corner-0 hint.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"}
DEFAULT_VIDEO_FRAMES = 5


def _error(msg: str):
    from studio.cli import CommandError

    return CommandError(msg)


def is_video(path: Path) -> bool:
    from calibration.sampling import VIDEO_SUFFIXES

    return path.suffix.lower() in VIDEO_SUFFIXES


def video_frame_count(path: Path) -> int:
    """Frames the container announces (decoding may yield a few fewer)."""
    import cv2

    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise _error(f"{path}: cannot open this video (missing, or a codec OpenCV cannot read)")
    try:
        return int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    finally:
        cap.release()


def chosen_video_frames(path: Path, spec: str | None) -> list[int]:
    """Frame indices of ``path`` named by ``spec`` (``START:STOP[:STEP]`` or a list; default a few spread out)."""
    from studio.workspace.frames import FrameSelectionError, select_frames

    n = video_frame_count(path)
    if n <= 0:
        raise _error(f"{path}: the container announces no frames")
    if spec is None:
        return sorted({int(round(v)) for v in np.linspace(0, max(n - 3, 0), DEFAULT_VIDEO_FRAMES)})
    try:
        return select_frames(spec, range(n))
    except FrameSelectionError as exc:
        raise _error(f"{path}: {exc}") from None


def read_video_frames(path: Path, indices: list[int]) -> dict[int, np.ndarray]:
    """``{index: RGB image}`` of the chosen frames (decoded in order; indices past the end are missing)."""
    from calibration.sampling import iter_video_frames

    wanted, out = set(indices), {}
    for k, img in iter_video_frames(path):
        if k in wanted:
            out[k] = img
        if k >= max(wanted):
            break
    return out


def load_corners(path: str | None) -> tuple[dict, dict]:
    """``(outer corners {cam: (4, 2)}, corner-0 hints {cam: (2,)})`` from the user's JSON file.

    Each camera maps to four ``[x, y]`` pixels (the outer inner corners: corner 0, end of its
    row, the opposite corner, start of the last row) or to one ``[x, y]``: the pixel of corner 0.
    """
    if path is None:
        return {}, {}
    from calibration.board_quad import parse_outer_corners

    file = Path(path)
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except OSError as exc:
        raise _error(f"{file}: cannot read the corners file ({exc.strerror})") from None
    except ValueError as exc:
        raise _error(f"{file}: not valid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise _error(f'{file}: expected an object {{"camera": [x, y] or [[x, y] x 4]}}')
    hints = {}
    four = {}
    for cam, value in data.items():
        arr = np.asarray(value, float) if isinstance(value, list) else np.zeros(0)
        if arr.shape == (2,) and np.all(np.isfinite(arr)):
            hints[str(cam)] = arr
        else:
            four[str(cam)] = value
    try:
        outer = parse_outer_corners(four, file) if four else {}
    except ValueError as exc:
        raise _error(str(exc)) from None
    hints.update({c: v[0] for c, v in outer.items()})
    return outer, hints


def detect_views(board, specs, *, max_side: int, frames: str | None, outer: dict, progress) -> dict:
    """``{camera: {view key: Detection}}`` for ``specs`` = [(camera, folder | image | video)]."""
    from calibration.detect import detect_board, read_image

    out = {}
    for name, path in specs:
        if is_video(path):
            idx = chosen_video_frames(path, frames)
            images = {f"{k:06d}": img for k, img in read_video_frames(path, idx).items()}
            if not images:
                raise _error(f"{path}: none of frames {idx[:5]}... could be decoded")
        elif path.is_dir():
            files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
            if not files:
                raise _error(f"{path}: no images (.png/.jpg) in this folder")
            images = {_view_key(f, name): f for f in files}
        elif path.is_file():
            images = {"floor": path}
        else:
            raise _error(f"{path}: not a folder of images, an image or a video (camera {name}: no such path)")
        task = progress.add_task(f"detect {name}", total=len(images))
        dets = {}
        for k, (key, img) in enumerate(images.items()):
            image = read_image(img) if isinstance(img, Path) else img
            dets[key] = detect_board(image, board, view=key, max_side=max_side, robust=True, outer_corners=outer.get(name))
            progress.update(task, completed=k + 1)
        out[name] = dets
        methods = sorted({d.extra.get("method", "?") for d in dets.values() if d.usable})
        log.info("camera %s: board in %d of %d views (%s)", name, sum(d.usable for d in dets.values()), len(dets), ", ".join(methods))
    return out


def _view_key(path: Path, camera: str) -> str:
    stem = path.stem.replace(camera, "").strip("_-. ")
    return stem or path.stem
