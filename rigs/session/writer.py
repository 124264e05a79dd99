"""The crash-safe session writer (see :mod:`rigs.session` for the guarantees)."""

from __future__ import annotations

import logging

import json
import math
import os
import shutil
from collections.abc import Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from rigs import atomic, imageio
from rigs.session.checks import _check_cameras, _check_index, _describe, _image_spec
from rigs.session.index import csv_header
from rigs.session.layout import (
    BACKGROUND_DIR,
    CALIBRATION_JSON,
    DURABILITIES,
    FRAMES_CSV,
    FRAMES_DIR,
    SESSION_FORMAT,
    SESSION_JSON,
    SESSION_VERSION,
    SessionError,
    TRUTH_DIR,
    _FLAG_RE,
    _STORABLE,
    _now,
    _os_reason,
    _unlink_quietly,
    index_name,
)

log = logging.getLogger(__name__)


class SessionWriter:
    """Writes a capture session; create it with :meth:`create`, use it as a context manager.

    ``__exit__`` closes with status ``"complete"``, or ``"aborted"`` when the block raised.
    Not thread-safe: call it from one thread (the recorder's writer thread).
    """

    def __init__(self, path: Path, cameras: list[str], info: dict, *, durability: str,
                 compression: int, workers: int = 1):  # fmt: skip
        self._path = path
        self._pool = ThreadPoolExecutor(workers, thread_name_prefix="session-writer") if workers > 1 else None
        self._cameras = cameras
        self._info = info
        self._compression = compression
        self._fsync = durability == "fsync"
        self._specs: dict[str, dict] = {}
        self._written: set[int] = set()
        self._backgrounds: dict[str, set[int]] = {cam: set() for cam in cameras}
        self._broken: str | None = None
        self._closed = False
        csv_path = path / FRAMES_CSV
        self._csv_fd = os.open(csv_path, os.O_WRONLY | os.O_APPEND)
        self._csv_size = os.fstat(self._csv_fd).st_size

    # ------------------------------------------------------------------ creation
    @classmethod
    def create(
        cls,
        path: str | Path,
        cameras: list[str],
        *,
        rig: str = "unknown",
        fps: float | None = None,
        pixel_formats: dict[str, str] | None = None,
        calibration: str | Path | dict | None = None,
        metadata: dict | None = None,
        overwrite: bool = False,
        durability: str = "rename",
        compression: int = 1,
        workers: int = 1,
    ) -> SessionWriter:
        """Create the session folder and return a writer for it.

        Args:
            path: the session folder; created (with parents). An existing empty folder is
                used; an existing session is replaced only with ``overwrite=True``.
            cameras: camera names, in the order of the ``frames.csv`` columns.
            rig: rig name recorded in ``session.json``.
            fps: nominal frame rate, or ``None`` when unknown.
            pixel_formats: {camera: sensor pixel format, e.g. ``"BayerRG8"``}.
            calibration: a calibration file (copied byte for byte), a dict (written as JSON)
                or ``None``. Must be valid JSON; its content is not interpreted here.
            metadata: free JSON-serialisable dict stored under ``metadata``.
            overwrite: replace an existing session at ``path``.
            durability: ``"rename"`` or ``"fsync"`` (see the module docstring).
            compression: PNG zlib level 0..9 for every image (0 fastest, largest; see
                :mod:`rigs.imageio` for timings).
            workers: threads encoding and writing the cameras' images of one frame in
                parallel (OpenCV and file writes release the GIL); 1 writes them in turn.
                The frame's row is still appended only once every image is on disk.

        Raises:
            SessionError: invalid arguments, ``path`` exists (and is not an empty folder or
                ``overwrite`` is false), the calibration is missing or not JSON, or the disk
                refused the write.
        """
        path = Path(path)
        cameras = _check_cameras(cameras)
        if durability not in DURABILITIES:
            raise SessionError(f"durability: {durability!r} is not one of {DURABILITIES}")
        if isinstance(compression, bool) or not isinstance(compression, int) or not 0 <= compression <= 9:
            raise SessionError(f"compression: {compression!r} is not a PNG level in 0..9")
        if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
            raise SessionError(f"workers: {workers!r} is not a positive integer")
        if fps is not None:
            if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not math.isfinite(fps) or fps <= 0:
                raise SessionError(f"fps: {fps!r} is not a positive number or None")
            fps = float(fps)
        pixel_formats = dict(pixel_formats or {})
        for cam, fmt in pixel_formats.items():
            if cam not in cameras:
                raise SessionError(f"pixel_formats: camera {cam!r} is not one of {cameras}")
            if not isinstance(fmt, str):
                raise SessionError(f"pixel_formats[{cam!r}]: expected a string, got {fmt!r}")
        if metadata is not None and not isinstance(metadata, dict):
            raise SessionError(f"metadata: expected a dict, got {type(metadata).__name__}")
        try:
            json.dumps(metadata or {}, allow_nan=False)
        except (TypeError, ValueError) as exc:
            raise SessionError(f"metadata: not JSON-serialisable ({exc})") from exc
        calibration_bytes = _calibration_bytes(calibration)

        _prepare_folder(path, overwrite)
        info = {
            "format": SESSION_FORMAT,
            "version": SESSION_VERSION,
            "rig": str(rig),
            "cameras": cameras,
            "fps": fps,
            "pixel_formats": pixel_formats,
            "start_time": _now(),
            "end_time": None,
            "status": "recording",
            "frame_count": None,
            "images": {},
            "durability": durability,
            "png_compression": compression,
            "calibration": CALIBRATION_JSON if calibration_bytes is not None else None,
            "metadata": metadata or {},
        }
        try:
            for cam in cameras:
                (path / FRAMES_DIR / cam).mkdir(parents=True, exist_ok=True)
                (path / BACKGROUND_DIR / cam).mkdir(parents=True, exist_ok=True)
            if calibration_bytes is not None:
                imageio.atomic_write_bytes(path / CALIBRATION_JSON, calibration_bytes)
            imageio.atomic_write_text(path / FRAMES_CSV, ",".join(csv_header(cameras)) + "\n")
            imageio.atomic_write_json(path / SESSION_JSON, info)  # last: marks a session
        except OSError as exc:
            raise SessionError(f"cannot create session {path}: {_os_reason(exc)}") from exc
        log.info("created capture session %s (cameras %s)", path, ", ".join(cameras))
        return cls(path, cameras, info, durability=durability, compression=compression, workers=workers)

    # ------------------------------------------------------------------ properties
    @property
    def path(self) -> Path:
        return self._path

    @property
    def cameras(self) -> list[str]:
        return list(self._cameras)

    @property
    def frame_count(self) -> int:
        """Number of frames written (rows in ``frames.csv``)."""
        return len(self._written)

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def info(self) -> dict:
        """A copy of what ``session.json`` holds (or will hold on close)."""
        return json.loads(json.dumps(self._info))

    @property
    def truth_dir(self) -> Path:
        """The ``truth/`` folder, created on first use."""
        folder = self._path / TRUTH_DIR
        folder.mkdir(exist_ok=True)
        return folder

    def frame_path(self, camera: str, index: int, suffix: str = ".png") -> Path:
        """Where frame ``index`` of ``camera`` is stored (``suffix`` ``.png`` or ``.exr``)."""
        return self._path / FRAMES_DIR / camera / f"{index_name(index)}{suffix}"

    def background_path(self, camera: str, index: int, suffix: str = ".png") -> Path:
        """Where background frame ``index`` of ``camera`` is stored."""
        return self._path / BACKGROUND_DIR / camera / f"{index_name(index)}{suffix}"

    # ------------------------------------------------------------------ writing
    def _check_writable(self, what: str) -> None:
        if self._closed:
            raise SessionError(f"{what}: session {self._path} is closed")
        if self._broken:
            raise SessionError(f"{what}: session {self._path} cannot take more frames: {self._broken}")

    def _check_image(self, camera: str, image: Any, what: str) -> dict | None:
        """Validate one image against the camera's first one; returns a new spec or None."""
        if not isinstance(image, np.ndarray):
            raise SessionError(f"{what}, camera '{camera}': expected a numpy array, got {type(image).__name__}")
        if image.dtype not in _STORABLE:
            raise SessionError(
                f"{what}, camera '{camera}': dtype {image.dtype} is not storable "
                "(expected uint8, uint16, bool, float32 or float16)"
            )
        shape_ok = image.ndim == 2 or (image.ndim == 3 and image.shape[2] in (1, 2, 3, 4))
        if not shape_ok or 0 in image.shape[:2]:
            raise SessionError(
                f"{what}, camera '{camera}': shape {image.shape} is not (H, W) or (H, W, C) with C in 1..4"
            )
        if image.ndim == 3 and image.shape[2] == 2 and imageio.image_suffix(image) == ".png":
            raise SessionError(f"{what}, camera '{camera}': 2-channel integer images are not storable as PNG")
        spec = _image_spec(image)  # (H, W, 1) is described as (H, W): one channel
        known = self._specs.get(camera)
        if known is None:
            return spec
        if spec != known:
            raise SessionError(
                f"{what}, camera '{camera}': image is {_describe(spec)} ({image.dtype}), "
                f"expected {_describe(known)} like the camera's first image "
                f"(field 'images.{camera}' of {SESSION_JSON})"
            )
        return None

    def _record_specs(self, new_specs: dict[str, dict]) -> None:
        if not new_specs:
            return
        specs = {**self._specs, **new_specs}
        info = {**self._info, "images": {cam: specs[cam] for cam in self._cameras if cam in specs}}
        imageio.atomic_write_json(self._path / SESSION_JSON, info, fsync=self._fsync)
        self._specs, self._info = specs, info  # only once session.json holds them

    def write_background(self, camera: str, index: int, image: np.ndarray) -> Path:
        """Write background (empty-scene) frame ``index`` of ``camera``; returns its path.

        Same size and dtype as the camera's frames. Raises :class:`SessionError` for an
        unknown camera, a duplicate index, a mismatched image or a failed write.
        """
        what = f"background {index!r}"
        self._check_writable(what)
        if camera not in self._cameras:
            raise SessionError(f"{what}: unknown camera {camera!r} (expected one of {self._cameras})")
        index = _check_index(index, what)
        if index in self._backgrounds[camera]:
            raise SessionError(f"{what}, camera '{camera}': duplicate background index")
        new = self._check_image(camera, image, what)
        path = self.background_path(camera, index, imageio.image_suffix(image))
        try:
            imageio.write_image(path, image, self._compression, fsync=self._fsync)
            self._record_specs({camera: new} if new else {})
        except OSError as exc:
            _unlink_quietly(path)
            raise SessionError(f"{what}, camera '{camera}': {_os_reason(exc)}") from exc
        self._backgrounds[camera].add(index)
        return path

    def write_frame(
        self,
        index: int,
        images: Mapping[str, np.ndarray],
        timestamps_ns: Mapping[str, int] | None = None,
        frame_ids: Mapping[str, int] | None = None,
        flags: Mapping[str, str] | None = None,
    ) -> None:
        """Write frame ``index``: every camera's image (atomically), then its ``frames.csv`` row.

        Args:
            index: frame index (unique within the session; need not be contiguous — a skipped
                index is reported by the reader as a gap).
            images: {camera: image} for **every** camera; each camera's images keep the size,
                channels and dtype of its first image.
            timestamps_ns, frame_ids: {camera: int}; cameras left out are written empty.
            flags: {camera: token}; default ``"ok"``.

        Raises:
            SessionError: missing/unknown camera, mismatched image, duplicate index, bad
                metadata, or a failed write (disk full names ENOSPC). After a failed write
                nothing of this frame is listed and the images already written for it are
                removed; the session stays readable and later frames can still be written.
        """
        what = f"frame {index!r}"
        self._check_writable(what)
        index = _check_index(index, what)
        if index in self._written:
            raise SessionError(f"{what}: duplicate index (already in {self._path / FRAMES_CSV})")
        if not isinstance(images, Mapping):
            raise SessionError(f"{what}: images must be a dict {{camera: array}}, got {type(images).__name__}")
        missing = [cam for cam in self._cameras if cam not in images]
        if missing:
            raise SessionError(
                f"{what}: missing image for camera(s) {missing} (every frame needs all of {self._cameras})"
            )
        extra = [cam for cam in images if cam not in self._cameras]
        if extra:
            raise SessionError(f"{what}: unknown camera(s) {extra} (expected {self._cameras})")
        new_specs = {}
        for cam in self._cameras:
            spec = self._check_image(cam, images[cam], what)
            if spec is not None:
                new_specs[cam] = spec
        row = [str(index)]
        ts = self._check_ints(timestamps_ns, "timestamps_ns", what)
        ids = self._check_ints(frame_ids, "frame_ids", what)
        fl = self._check_flags(flags, what)
        for cam in self._cameras:
            row += [ts.get(cam, ""), ids.get(cam, ""), fl.get(cam, "ok")]
        line = (",".join(row) + "\n").encode("utf-8")

        paths = [self.frame_path(cam, index, imageio.image_suffix(images[cam])) for cam in self._cameras]
        try:
            # with durability "fsync", write_image also fsyncs each file and its folder
            self._write_images(paths, [images[cam] for cam in self._cameras])
            self._record_specs(new_specs)
            self._append_row(line)
        except OSError as exc:
            for path in paths:
                _unlink_quietly(path)
            raise SessionError(f"{what}: {_os_reason(exc)}; frame not recorded") from exc
        self._written.add(index)

    def _write_images(self, paths: list[Path], arrays: list[np.ndarray]) -> None:
        """Write every image (in parallel with a pool); raise the first error after all ended."""
        if self._pool is None:
            for path, array in zip(paths, arrays):
                imageio.write_image(path, array, self._compression, fsync=self._fsync)
            return
        futures = [
            self._pool.submit(imageio.write_image, path, array, self._compression, fsync=self._fsync)
            for path, array in zip(paths, arrays)
        ]
        errors = [f.exception() for f in futures]  # waits for all: none still writing after
        for exc in errors:
            if exc is not None:
                raise exc

    def _check_ints(self, values: Mapping | None, field: str, what: str) -> dict[str, str]:
        if values is None:
            return {}
        out = {}
        for cam, value in values.items():
            if cam not in self._cameras:
                raise SessionError(f"{what}: {field} names unknown camera {cam!r} (expected {self._cameras})")
            if value is None:
                continue
            if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
                raise SessionError(f"{what}: {field}[{cam!r}] = {value!r} is not an integer")
            out[cam] = str(int(value))
        return out

    def _check_flags(self, flags: Mapping | None, what: str) -> dict[str, str]:
        if flags is None:
            return {}
        for cam, flag in flags.items():
            if cam not in self._cameras:
                raise SessionError(f"{what}: flags names unknown camera {cam!r} (expected {self._cameras})")
            if not isinstance(flag, str) or not _FLAG_RE.match(flag):
                raise SessionError(
                    f"{what}: flags[{cam!r}] = {flag!r} is not a string without commas, quotes or newlines"
                )
        return dict(flags)

    def _append_row(self, line: bytes) -> None:
        """Append one complete line; on failure truncate back so no torn line stays."""
        try:
            atomic._write_all(self._csv_fd, line)
            if self._fsync:
                os.fsync(self._csv_fd)
        except OSError:
            try:
                os.ftruncate(self._csv_fd, self._csv_size)
            except OSError as exc2:
                self._broken = f"{FRAMES_CSV} could not be restored after a failed append ({exc2})"
            raise
        self._csv_size += len(line)

    # ------------------------------------------------------------------ closing
    def record_drops(self, drops: Mapping[str, Any]) -> None:
        """Record what the capture lost, written into ``session.json`` (``"drops"``) at close:
        e.g. ``{"incomplete_instants": 3, "recorder_dropped": 0, "cameras": {cam: {"dropped": 2,
        "late": 0, "duplicates": 0, "mismatched": 0, "queue_dropped": 1}}}``. Instants that not
        every camera delivered have no row in ``frames.csv``; this is where they are counted."""
        self._check_writable("record_drops")
        try:
            self._info["drops"] = json.loads(json.dumps(dict(drops), allow_nan=False))
        except (TypeError, ValueError) as exc:
            raise SessionError(f"record_drops: expected JSON-serialisable counts ({exc})") from None

    def close(self, status: str = "complete") -> None:
        """Close ``frames.csv`` and record ``status``, ``frame_count`` and ``end_time`` in
        ``session.json`` (atomically, fsynced). Closing twice does nothing."""
        if self._closed:
            return
        if status not in ("complete", "aborted"):
            raise SessionError(f"close: status {status!r} is not 'complete' or 'aborted'")
        self._closed = True
        if self._pool is not None:
            self._pool.shutdown(wait=True)
        try:
            os.close(self._csv_fd)
        except OSError:  # pragma: no cover - close of a plain file descriptor
            pass
        self._info.update(status=status, frame_count=len(self._written), end_time=_now())
        try:
            imageio.atomic_write_json(self._path / SESSION_JSON, self._info)
        except OSError as exc:
            raise SessionError(
                f"close: cannot update {self._path / SESSION_JSON}: {_os_reason(exc)} "
                "(frames already written stay readable; status remains 'recording')"
            ) from exc
        log.info("closed capture session %s: %d frames, %s", self._path, len(self._written), status)

    def __enter__(self) -> SessionWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close("complete")
            return
        try:
            self.close("aborted")
        except SessionError as close_exc:
            log.error("%s", close_exc)

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return f"SessionWriter({str(self._path)!r}, cameras={self._cameras}, frames={len(self._written)}, {state})"


def _calibration_bytes(calibration: str | Path | dict | None) -> bytes | None:
    if calibration is None:
        return None
    if isinstance(calibration, dict):
        try:
            return (json.dumps(calibration, indent=2, allow_nan=False) + "\n").encode("utf-8")
        except (TypeError, ValueError) as exc:
            raise SessionError(f"calibration: dict is not JSON-serialisable ({exc})") from exc
    if isinstance(calibration, (str, Path)):
        src = Path(calibration)
        try:
            data = src.read_bytes()
        except OSError as exc:
            raise SessionError(f"calibration: cannot read {src}: {exc.strerror or exc}") from exc
        try:
            json.loads(data)
        except (UnicodeDecodeError, ValueError) as exc:
            raise SessionError(f"calibration: {src} is not a JSON file ({exc})") from exc
        return data
    raise SessionError(
        f"calibration: expected a JSON file path, a dict or None, got {type(calibration).__name__}"
    )


def _prepare_folder(path: Path, overwrite: bool) -> None:
    if path.exists():
        if not path.is_dir():
            raise SessionError(f"cannot create session {path}: a file of that name exists")
        if any(path.iterdir()):
            if not overwrite:
                raise SessionError(
                    f"cannot create session {path}: folder exists and is not empty "
                    "(pass overwrite=True to replace an existing session)"
                )
            if not (path / SESSION_JSON).is_file():
                raise SessionError(
                    f"cannot overwrite {path}: it is not a capture session (no {SESSION_JSON}); "
                    "refusing to delete it"
                )
            shutil.rmtree(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SessionError(f"cannot create session folder {path}: {_os_reason(exc)}") from exc
