"""Recorded footage → capture session: one video (or folder of numbered images) per camera.

:func:`probe` opens each source once, decoding it through (a container's announced frame count
is often wrong: the Utrecht INFOMCV AVIs announce 134 frames and decode 132), and keeps the
container's time of every frame (``CAP_PROP_POS_MSEC``). :func:`check_sources` compares the
cameras — frame counts, frame rates, image sizes — and names the camera and file that differ;
unequal lengths are an error unless the caller trims to the shortest. :func:`import_session`
then decodes all cameras in lockstep and writes the chosen frames through
:class:`rigs.session.SessionWriter` (atomic files; a frame listed only once every camera's image
of it is on disk), renumbered 0, 1, 2, ... with each camera's source frame number in the
``frame_id`` column of ``frames.csv`` and its container time in ``timestamp_ns``.

Container times: a frame whose time does not increase over the previous one (FFmpeg returns 0
for the last frame of some AVIs) gets the previous time plus one frame period and the flag
``ts_nominal``; a source with no container times at all gets ``k / fps`` for every frame, flagged
the same way. Image folders have no times unless a rate is given.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rigs.session import SessionError, SessionWriter

__all__ = ["Source", "FootageError", "probe", "check_sources", "import_session", "time_spread_ms", "IMAGE_SUFFIXES", "NOMINAL_FLAG"]

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
NOMINAL_FLAG = "ts_nominal"
#: Frame rates of two cameras further apart than this (relative) cannot be one trigger.
RATE_TOLERANCE = 1e-3
_NUMBER = re.compile(r"(\d+)(?!.*\d)")


class FootageError(SessionError):
    """Footage that cannot become one capture session; the message names the camera and file."""


@dataclass(frozen=True)
class Source:
    """One camera's footage as probed.

    ``times_ns`` (frames,) int64 container times (nominal where ``nominal`` is True); ``files``
    the numbered images of a folder in frame order (empty for a video).
    """

    camera: str
    path: Path
    kind: str  # "video" or "images"
    frame_count: int
    fps: float | None
    size: tuple[int, int]
    times_ns: np.ndarray = field(repr=False)
    nominal: np.ndarray = field(repr=False)
    files: tuple = field(default=(), repr=False)

    @property
    def container_times(self) -> bool:
        """True when at least half the frames carry the container's own time."""
        return bool(len(self.nominal) and np.mean(~self.nominal) >= 0.5)


def repair_times(ms: np.ndarray, fps: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Container times (ms, per frame) → ``(times_ns int64, nominal bool)``.

    >>> t, n = repair_times(np.array([60.0, 80.0, 100.0, 0.0]), 50.0)
    >>> (t // 1_000_000).tolist(), n.tolist()
    ([60, 80, 100, 120], [False, False, False, True])
    """
    ms = np.asarray(ms, float)
    period = 1000.0 / fps if fps else 0.0
    nominal = np.zeros(len(ms), bool)
    if len(ms) == 0:
        return np.zeros(0, np.int64), nominal
    if not np.any(ms[1:] > ms[:-1]) and period:  # no container times: the nominal rate
        return np.round(np.arange(len(ms)) * period * 1e6).astype(np.int64), np.ones(len(ms), bool)
    out = ms.copy()
    for k in range(1, len(out)):
        if not (np.isfinite(out[k]) and out[k] > out[k - 1]):
            out[k] = out[k - 1] + (period or 1.0)
            nominal[k] = True
    return np.round(out * 1e6).astype(np.int64), nominal


def _numbered_images(folder: Path, camera: str) -> list[Path]:
    files = [p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and _NUMBER.search(p.stem)]
    if not files:
        raise FootageError(f"camera {camera}: {folder}: no numbered images ({', '.join(IMAGE_SUFFIXES)}) in this folder")
    files.sort(key=lambda p: int(_NUMBER.search(p.stem).group(1)))
    numbers = [int(_NUMBER.search(p.stem).group(1)) for p in files]
    if len(set(numbers)) != len(numbers):
        dup = sorted({n for n in numbers if numbers.count(n) > 1})[:3]
        raise FootageError(f"camera {camera}: {folder}: several images carry the same number {dup}")
    return files


def _read_rgb(path: Path, camera: str) -> np.ndarray:
    import cv2

    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise FootageError(f"camera {camera}: {path}: cannot read this image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def probe(camera: str, path: str | Path, *, fps: float | None = None) -> Source:
    """Open one camera's video or image folder, count its frames and read its times.

    ``fps`` gives an image folder a rate (and times ``k / fps``); a video's own rate is used otherwise.
    """
    import cv2

    path = Path(path)
    if path.is_dir():
        files = _numbered_images(path, camera)
        h, w = _read_rgb(files[0], camera).shape[:2]
        n = len(files)
        times, nominal = (repair_times(np.zeros(n), fps) if fps else (np.zeros(n, np.int64), np.ones(n, bool)))
        return Source(camera, path, "images", n, fps, (w, h), times, nominal, tuple(files))
    if not path.is_file():
        raise FootageError(f"camera {camera}: {path}: no such video or image folder")
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise FootageError(f"camera {camera}: {path}: OpenCV cannot open this video (format or codec not supported)")
    try:
        rate = float(cap.get(cv2.CAP_PROP_FPS)) or None
        size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        ms = []
        while cap.grab():
            ms.append(cap.get(cv2.CAP_PROP_POS_MSEC))
    finally:
        cap.release()
    if not ms:
        raise FootageError(f"camera {camera}: {path}: no frame could be decoded")
    rate = fps or rate
    times, nominal = repair_times(np.array(ms), rate)
    return Source(camera, path, "video", len(ms), rate, size, times, nominal)


def check_sources(sources: list[Source], *, trim: bool = False, what: str = "video") -> int:
    """Frames usable from every camera: equal counts (or the shortest with ``trim``), equal rates.

    Raises :class:`FootageError` naming the cameras and files whose frame count or rate differ
    from the others (counts: unless ``trim``).
    """
    counts = {s.camera: s.frame_count for s in sources}
    rates = {s.camera: s.fps for s in sources if s.fps}
    if rates:
        ref = float(np.median(list(rates.values())))
        off = {c: r for c, r in rates.items() if abs(r - ref) > RATE_TOLERANCE * ref}
        if off:
            files = {s.camera: str(s.path) for s in sources if s.camera in off}
            raise FootageError(
                f"{what}s run at different frame rates: {off} fps vs {ref:g} for the others ({files}); "
                "frames of one instant cannot be matched - resample the footage to one rate"
            )
    if len(set(counts.values())) > 1:
        shortest = min(counts.values())
        if not trim:
            longer = {s.camera: f"{s.path} ({s.frame_count} frames)" for s in sources if s.frame_count > shortest}
            raise FootageError(
                f"{what}s differ in length: {longer} vs {shortest} frames for "
                f"{[c for c, n in counts.items() if n == shortest]}; pass --trim to keep the first {shortest} frames of each"
            )
        log.warning("%ss trimmed to the shortest: %d frames (%s)", what, shortest, counts)
        return shortest
    return next(iter(counts.values()))


def time_spread_ms(sources: list[Source], frames: list[int]) -> float:
    """Largest difference (ms) between the cameras' container times of one frame (0 without times).

    Synchronised footage differs by well under a frame period; more means the footage (or the
    container's clock) does not start at the same instant in every camera.
    """
    timed = [s for s in sources if s.fps and s.container_times]
    if len(timed) < 2 or not frames:
        return 0.0
    t = np.stack([s.times_ns[frames] for s in timed])
    return float((t.max(0) - t.min(0)).max() / 1e6)


def _frames(source: Source, indices):
    """Yield ``(index, RGB)`` for the sorted ``indices`` of one source, decoding forward."""
    import cv2

    wanted = list(indices)
    if source.kind == "images":
        for k in wanted:
            yield k, _read_rgb(source.files[k], source.camera)
        return
    cap = cv2.VideoCapture(str(source.path))
    try:
        k, i = 0, 0
        while i < len(wanted) and cap.grab():
            if k == wanted[i]:
                ok, bgr = cap.retrieve()
                if not ok:
                    raise FootageError(f"camera {source.camera}: {source.path}: frame {k} cannot be decoded")
                yield k, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
                i += 1
            k += 1
    finally:
        cap.release()
    if i < len(wanted):
        raise FootageError(f"camera {source.camera}: {source.path}: ended before frame {wanted[i]}")


def _check_size(source: Source, image: np.ndarray, index: int, size: tuple[int, int]) -> None:
    h, w = image.shape[:2]
    if (w, h) != tuple(size):
        where = source.files[index] if source.kind == "images" else f"{source.path} frame {index}"
        raise FootageError(f"camera {source.camera}: {where}: image is {w}x{h}, expected {size[0]}x{size[1]} like the camera's first frame")


def import_session(
    out: str | Path,
    videos: list[Source],
    frames: list[int],
    *,
    backgrounds: list[Source] = (),
    background_frames: int = 30,
    calibration: dict | None = None,
    metadata: dict | None = None,
    overwrite: bool = False,
    compression: int = 1,
    progress=None,
) -> SessionWriter:
    """Write ``frames`` (source indices, increasing) of every camera into a new session at ``out``.

    ``backgrounds``: each camera's empty-scene footage; at most ``background_frames`` frames
    spread over it become ``background/<cam>/``; they must have the camera's image size.
    ``progress(stage, done, total)`` is called after each frame. Returns the closed writer.
    """
    names = [s.camera for s in videos]
    frames = sorted(frames)
    bad = [k for k in frames if not 0 <= k < min(s.frame_count for s in videos)]
    if bad:
        raise FootageError(f"frames {bad[:5]} are outside the footage (0..{min(s.frame_count for s in videos) - 1})")
    fps = {s.fps for s in videos if s.fps}
    meta = {"imported_from": {s.camera: {"path": str(s.path), "kind": s.kind, "frames": s.frame_count, "fps": s.fps,
                                         "size": list(s.size), "container_times": s.container_times} for s in videos},
            "source_frames": [frames[0], frames[-1]] if frames else [], **(metadata or {})}  # fmt: skip
    writer = SessionWriter.create(out, names, rig="imported", fps=next(iter(fps)) if fps else None, calibration=calibration,
                                  metadata=meta, overwrite=overwrite, compression=compression)  # fmt: skip
    with writer:
        by_cam = {s.camera: s for s in backgrounds}
        for cam in names:
            if cam not in by_cam:
                continue
            bg = by_cam[cam]
            pick = sorted({int(round(v)) for v in np.linspace(0, bg.frame_count - 1, min(background_frames, bg.frame_count))})
            size = next(s.size for s in videos if s.camera == cam)
            for i, (k, img) in enumerate(_frames(bg, pick)):
                _check_size(bg, img, k, size)
                writer.write_background(cam, i, img)
                if progress:
                    progress(f"background {cam}", i + 1, len(pick))
        streams = {s.camera: _frames(s, frames) for s in videos}
        sources = {s.camera: s for s in videos}
        for j, k in enumerate(frames):
            images = {}
            for cam in names:
                _, img = next(streams[cam])
                _check_size(sources[cam], img, k, sources[cam].size)
                images[cam] = img
            ts = {c: int(sources[c].times_ns[k]) for c in names if sources[c].fps}
            flags = {c: NOMINAL_FLAG for c in names if sources[c].fps and sources[c].nominal[k]}
            writer.write_frame(j, images, timestamps_ns=ts, frame_ids={c: k for c in names}, flags=flags)
            if progress:
                progress("frames", j + 1, len(frames))
    return writer
