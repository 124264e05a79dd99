"""Capture sessions on disk: a crash-safe writer and a validating reader.

Folder layout (DESIGN.md, "Capture session")::

    session.json                 see below
    calibration.json             the calibration in force, copied verbatim (opaque JSON here)
    background/<cam>/NNNNNN.png  empty-scene frames (or .exr for float images)
    frames/<cam>/NNNNNN.png      frame NNNNNN of every camera = one trigger instant
    frames.csv                   one row per complete frame (columns below)
    truth/                       synthetic sessions only (free-form, written by the simulator)

``NNNNNN`` is the frame index, zero-padded to 6 digits (more digits past 999999).
Integer images (uint8/uint16/bool) are PNG, float images OpenEXR (:mod:`rigs.imageio`).

``session.json`` (``format`` ``"studio.capture-session"``, ``version`` 1): ``rig``,
``cameras`` (ordered names), ``fps`` (or null), ``pixel_formats`` {cam: str}, ``start_time`` /
``end_time`` (ISO 8601 UTC), ``status`` (``"recording"`` while the writer is open,
``"complete"`` or ``"aborted"`` once closed), ``frame_count`` (set on close), ``images``
{cam: {width, height, channels, dtype, suffix}} (set at each camera's first image),
``durability``, ``png_compression``, ``calibration`` (file name or null), ``metadata`` (free).
Readers accept any ``1.x`` version and reject other major versions.

``frames.csv`` columns: ``index`` then, per camera in ``cameras`` order,
``<cam>.timestamp_ns`` (device or host timestamp in ns; empty = unknown), ``<cam>.frame_id``
(the camera's own frame counter; empty = unknown), ``<cam>.flag`` (a short token from the
sync layer: ``ok`` by default; e.g. ``late``, ``resent``; never contains ``,`` or quotes).

Crash safety, and what the reader does with a damaged session:

* every file is written under a hidden temporary name and renamed (:func:`os.replace`);
* a frame's row is appended to ``frames.csv`` (one ``write`` of the whole line, ``O_APPEND``)
  only after every camera's image of it is on disk under its final name, so a writer killed
  at any instant leaves a session whose listed frames are all complete;
* a last line without its newline (a torn append) or any line with the wrong number of
  fields or unparseable values is **ignored** and reported in :attr:`Session.issues`;
* a row whose image is missing, empty or truncated is **not** listed in
  :attr:`Session.frame_indices`; it appears in :attr:`Session.gaps` with the reason, and so do
  indices absent from ``frames.csv`` between two listed frames (dropped frames);
* a session whose writer never closed has status ``"recording"``: it reads normally.

Durability (``SessionWriter.create(..., durability=...)``):

* ``"rename"`` (default): temporary file + rename, no fsync. Guarantees the above after the
  writing **process** dies (crash, SIGKILL, exception). After an operating-system crash or
  power loss the most recent files may come back empty or truncated; the reader then reports
  those frames as gaps, never returns torn pixels.
* ``"fsync"``: also fsyncs every image, its folder and ``frames.csv`` after each row, so every
  listed frame survives power loss; costs a few milliseconds per file on most disks.

Speed (4 cameras of 656×490 RGB, busy 2-core test machine): ``compression=0`` ≈ 18 ms per
multi-frame with ``workers=1`` and ≈ 11 ms with ``workers=4`` (≈ 90 multi-frames/s, ~1 MB
per image); ``compression=1`` ≈ 64–96 ms (~0.45 MB per image). For live 4×60 fps use
``compression=0, workers=4``; recompress offline if disk space matters.
"""

from __future__ import annotations

import errno
import json
import logging
import math
import os
import re
import shutil
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from rigs import imageio
from rigs import atomic
from rigs.atomic import is_temporary
from rigs.imageio import ImageIOError

__all__ = [
    "SessionError",
    "SessionWriter",
    "Session",
    "ValidationReport",
    "SESSION_FORMAT",
    "SESSION_VERSION",
    "index_name",
]

log = logging.getLogger(__name__)

SESSION_FORMAT = "studio.capture-session"
SESSION_VERSION = 1
SESSION_JSON = "session.json"
CALIBRATION_JSON = "calibration.json"
FRAMES_CSV = "frames.csv"
FRAMES_DIR = "frames"
BACKGROUND_DIR = "background"
TRUTH_DIR = "truth"
INDEX_DIGITS = 6
STATUSES = ("recording", "complete", "aborted")
DURABILITIES = ("rename", "fsync")
MAX_GAP_ENTRIES = 1000  # a longer run of absent indices is reported as one gap entry

_CAMERA_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]*$")
_FLAG_RE = re.compile(r"^[^,\"'\r\n]*$")
_IMAGE_NAME_RE = re.compile(r"^(\d{%d,})\.(png|exr)$" % INDEX_DIGITS)
_STORABLE = (np.uint8, np.uint16, np.bool_, np.float32, np.float16)


class SessionError(RuntimeError):
    """A capture session cannot be written or read as asked; the message names the file,
    the field or camera, and what was expected."""


def _now() -> str:
    return datetime.now(timezone.utc).isoformat(timespec="milliseconds")


def index_name(index: int) -> str:
    """File stem of frame ``index`` (``000042``): the one place a frame number is formatted."""
    return f"{index:0{INDEX_DIGITS}d}"


def csv_header(cameras: list[str]) -> list[str]:
    """Column names of ``frames.csv`` for ``cameras`` (see the module docstring)."""
    cols = ["index"]
    for cam in cameras:
        cols += [f"{cam}.timestamp_ns", f"{cam}.frame_id", f"{cam}.flag"]
    return cols


def _check_index(index: Any, what: str) -> int:
    if isinstance(index, (bool, np.bool_)) or not isinstance(index, (int, np.integer)) or index < 0:
        raise SessionError(f"{what}: index {index!r} is not a non-negative integer")
    return int(index)


def _check_cameras(cameras: Any) -> list[str]:
    if isinstance(cameras, str) or not isinstance(cameras, (list, tuple)) or not cameras:
        raise SessionError(f"cameras: expected a non-empty list of names, got {cameras!r}")
    for cam in cameras:
        if not isinstance(cam, str) or not _CAMERA_RE.match(cam):
            raise SessionError(
                f"cameras: name {cam!r} is not valid (expected letters, digits, '_' or '-', "
                "starting with a letter or digit: it names a folder and CSV columns)"
            )
    if len(set(cameras)) != len(cameras):
        raise SessionError(f"cameras: duplicate names in {list(cameras)}")
    return list(cameras)


def _image_spec(image: np.ndarray) -> dict:
    """The session.json ``images`` entry describing ``image`` as it will be read back."""
    h, w = image.shape[:2]
    channels = 1 if image.ndim == 2 else image.shape[2]
    dtype = {np.dtype(np.bool_): "uint8", np.dtype(np.float16): "float32"}.get(
        image.dtype, str(image.dtype)
    )
    return {
        "width": int(w),
        "height": int(h),
        "channels": int(channels),
        "dtype": dtype,
        "suffix": imageio.image_suffix(image),
    }


def _describe(spec: Mapping) -> str:
    return f"{spec['width']}x{spec['height']}x{spec['channels']} {spec['dtype']}"


# =========================================================================== writer


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
        self._durability = durability
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
        if image.ndim == 3 and image.shape[2] == 1:
            image = image[:, :, 0]
        spec = _image_spec(image)
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


def _unlink_quietly(path: Path) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def _os_reason(exc: OSError) -> str:
    if exc.errno == errno.ENOSPC:
        return f"disk full (ENOSPC): {exc}"
    return str(exc)


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


# =========================================================================== reader


@dataclass(frozen=True)
class ValidationReport:
    """What :meth:`Session.validate` found.

    ``problems``: damage a user must know about (torn or malformed CSV lines, rows whose
    images are missing/truncated/undecodable/mis-sized, duplicate rows, cameras with different
    background counts). ``gaps``: every ``(index, reason)`` not listed as a complete frame,
    including indices absent from ``frames.csv`` (dropped frames, not a problem by themselves).
    ``notes``: harmless findings (files not listed in ``frames.csv``, leftover temporary files).
    """

    path: Path
    frames_checked: int
    images_checked: int
    deep: bool
    problems: tuple[str, ...]
    gaps: tuple[tuple[int, str], ...]
    notes: tuple[str, ...]

    @property
    def ok(self) -> bool:
        return not self.problems


@dataclass(frozen=True)
class _Row:
    line: int
    timestamps_ns: dict
    frame_ids: dict
    flags: dict


class Session:
    """A capture session on disk, read-only. Open it with :meth:`open`.

    Attributes:
        path: the session folder.
        info: ``session.json`` as a dict.
        cameras: camera names in ``frames.csv`` column order.
        fps: nominal frame rate or ``None``.
        status: ``"recording"`` (writer never closed: crashed or still running), ``"complete"``
            or ``"aborted"``.
        frame_indices: sorted indices of the complete frames (row present, every image on disk
            and not truncated).
        gaps: ``(index, reason)`` for rows with missing/empty/truncated images and for indices
            absent from ``frames.csv`` between listed frames, sorted by index (a run of more
            than ``MAX_GAP_ENTRIES`` absent indices is one entry, at its first index).
        issues: file-level findings: ignored CSV lines (torn, wrong field count, bad values),
            duplicate rows, background count mismatches, ``frame_count`` disagreement.
    """

    def __init__(self, path: Path, info: dict, rows: dict[int, _Row], gaps: list, issues: list,
                 bad_rows: set[int]):  # fmt: skip
        self.path = path
        self.info = info
        self.cameras: list[str] = list(info["cameras"])
        self.fps: float | None = info.get("fps")
        self.status: str = info.get("status", "recording")
        self._rows = rows
        self._bad_rows = bad_rows
        self.frame_indices: list[int] = sorted(i for i in rows if i not in bad_rows)
        self._complete = set(self.frame_indices)
        self.gaps: list[tuple[int, str]] = sorted(gaps, key=lambda g: g[0])
        self.issues: list[str] = issues
        self._sizes: dict[str, tuple[int, int]] = {}

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, path: str | Path, *, verify: bool = True) -> Session:
        """Open and check a session folder (reads ``session.json`` and ``frames.csv`` and
        checks that every listed image exists and is not truncated — no pixel decoding).

        ``verify=True`` opens every listed image file to check its PNG end chunk / EXR magic
        (about 0.1 ms per image); ``verify=False`` only checks that the files exist (one folder
        listing per camera), for very long sessions. Decoding happens in :meth:`image` and
        :meth:`validate` (``deep=True``).

        Raises:
            SessionError: no such folder, ``session.json`` missing/invalid (wrong ``format``,
                unknown major ``version``, bad ``cameras``), ``frames.csv`` missing or with a
                header that does not match the cameras.
        """
        path = Path(path)
        if not path.is_dir():
            raise SessionError(f"{path}: no such capture-session folder")
        info = _read_info(path)
        cameras = info["cameras"]
        rows, issues = _read_frames_csv(path / FRAMES_CSV, cameras)
        suffixes = {cam: info.get("images", {}).get(cam, {}).get("suffix") for cam in cameras}
        gaps: list[tuple[int, str]] = []
        bad: set[int] = set()
        listings = {} if verify else {cam: _list_names(path / FRAMES_DIR / cam) for cam in cameras}
        for index in sorted(rows):
            for cam in cameras:
                frame_file = _find_image(path / FRAMES_DIR / cam, index, suffixes[cam])
                if verify:
                    reason = imageio.check_image_file(frame_file)
                else:
                    reason = None if frame_file.name in listings[cam] else f"{frame_file} is missing"
                if reason is not None:
                    rel = frame_file.relative_to(path)
                    gaps.append((index, f"row on line {rows[index].line} of {FRAMES_CSV}, but "
                                        + reason.replace(str(frame_file), str(rel))))  # fmt: skip
                    bad.add(index)
        listed = sorted(rows)
        for a, b in zip(listed, listed[1:]):
            if b - a - 1 > MAX_GAP_ENTRIES:  # one entry for a huge hole (e.g. a bogus index)
                gaps.append((a + 1, f"indices {a + 1}..{b - 1} ({b - a - 1} frames) absent from {FRAMES_CSV}"))
                continue
            for missing in range(a + 1, b):
                gaps.append((missing, f"index absent from {FRAMES_CSV} (no row between frames {a} and {b})"))
        session = cls(path, info, rows, gaps, issues, bad)
        issues.extend(session._background_issues())
        if info.get("status", "recording") not in STATUSES:
            issues.append(f"{SESSION_JSON}: field 'status' is {info.get('status')!r}, expected one of {STATUSES}")
        if info.get("status") in ("complete", "aborted") and info.get("frame_count") != len(rows):
            issues.append(
                f"{SESSION_JSON}: field 'frame_count' is {info.get('frame_count')!r} but "
                f"{FRAMES_CSV} has {len(rows)} valid rows"
            )
        for msg in issues:
            log.warning("session %s: %s", path, msg)
        return session

    # ------------------------------------------------------------------ simple accessors
    @property
    def rig(self) -> str:
        return str(self.info.get("rig", "unknown"))

    @property
    def frame_count(self) -> int:
        """Number of complete frames (``len(frame_indices)``)."""
        return len(self.frame_indices)

    def __len__(self) -> int:
        return len(self.frame_indices)

    @property
    def calibration_path(self) -> Path | None:
        p = self.path / CALIBRATION_JSON
        return p if p.is_file() else None

    def calibration_json(self) -> dict | None:
        """The stored calibration as a dict (uninterpreted), or ``None`` when absent."""
        p = self.calibration_path
        if p is None:
            return None
        try:
            return json.loads(p.read_text(encoding="utf-8"))
        except (UnicodeDecodeError, ValueError) as exc:
            raise SessionError(f"{p}: not valid JSON ({exc})") from exc

    @property
    def truth_dir(self) -> Path | None:
        p = self.path / TRUTH_DIR
        return p if p.is_dir() else None

    def _check_camera(self, camera: str) -> None:
        if camera not in self.cameras:
            raise SessionError(f"session {self.path}: unknown camera {camera!r} (cameras: {self.cameras})")

    def _spec(self, camera: str) -> dict | None:
        spec = self.info.get("images", {}).get(camera)
        return spec if isinstance(spec, dict) else None

    def frame_path(self, camera: str, index: int) -> Path:
        """Path of frame ``index`` of ``camera`` (``.png`` or ``.exr``; may not exist)."""
        self._check_camera(camera)
        spec = self._spec(camera) or {}
        return _find_image(self.path / FRAMES_DIR / camera, int(index), spec.get("suffix"))

    def background_path(self, camera: str, index: int) -> Path:
        self._check_camera(camera)
        spec = self._spec(camera) or {}
        return _find_image(self.path / BACKGROUND_DIR / camera, int(index), spec.get("suffix"))

    def image_size(self, camera: str) -> tuple[int, int]:
        """``(width, height)`` of ``camera``'s images (from ``session.json`` or the first image)."""
        self._check_camera(camera)
        if camera not in self._sizes:
            spec = self._spec(camera)
            if spec is not None:
                self._sizes[camera] = (int(spec["width"]), int(spec["height"]))
            else:
                candidates = [self.frame_path(camera, i) for i in self.frame_indices[:1]]
                candidates += [self.background_path(camera, i) for i in self.background_indices(camera)[:1]]
                if not candidates:
                    raise SessionError(f"session {self.path}: camera '{camera}' has no images to size")
                try:
                    meta = imageio.image_info(candidates[0])
                except (OSError, ImageIOError) as exc:
                    raise SessionError(f"camera '{camera}': {exc}") from exc
                self._sizes[camera] = (meta.width, meta.height)
        return self._sizes[camera]

    # ------------------------------------------------------------------ frames
    def _check_frame(self, index: int) -> int:
        if isinstance(index, (bool, np.bool_)) or not isinstance(index, (int, np.integer)):
            raise SessionError(f"session {self.path}: frame index {index!r} is not an integer")
        index = int(index)
        if index not in self._complete:
            reasons = [r for i, r in self.gaps if i == index]
            if reasons:
                raise SessionError(f"session {self.path}: frame {index} is not complete: {'; '.join(reasons)}")
            span = f"{self.frame_indices[0]}..{self.frame_indices[-1]}" if self.frame_indices else "none"
            raise SessionError(
                f"session {self.path}: frame {index} is not in {FRAMES_CSV} "
                f"({len(self.frame_indices)} complete frames, indices {span})"
            )
        return index

    def _load(self, path: Path, camera: str, what: str) -> np.ndarray:
        try:
            image = imageio.read_image(path)
        except (OSError, ImageIOError) as exc:
            raise SessionError(f"camera '{camera}' {what}: {exc}") from exc
        spec = self._spec(camera)
        if spec is not None:
            got = _image_spec(image)
            got["suffix"] = spec.get("suffix", got["suffix"])
            if any(got[k] != spec.get(k) for k in ("width", "height", "channels", "dtype")):
                raise SessionError(
                    f"{path}: image is {_describe(got)}, expected {_describe(spec)} "
                    f"(field 'images.{camera}' of {SESSION_JSON})"
                )
        else:
            w, h = self.image_size(camera)
            if image.shape[:2] != (h, w):
                raise SessionError(
                    f"{path}: image size is {image.shape[1]}x{image.shape[0]}, expected {w}x{h} "
                    f"like camera '{camera}''s first image"
                )
        return image

    def image(self, camera: str, index: int) -> np.ndarray:
        """Frame ``index`` of ``camera`` (RGB uint8/uint16, gray ``(H, W)``, or float32).

        Raises :class:`SessionError` for an unknown camera, an index that is not a complete
        frame (with the gap reason), or an image that fails to decode or has the wrong size.
        """
        self._check_camera(camera)
        index = self._check_frame(index)
        return self._load(self.frame_path(camera, index), camera, f"frame {index}")

    def frame(self, index: int) -> dict[str, np.ndarray]:
        """Every camera's image of frame ``index``: {camera: array} (see :meth:`image`)."""
        index = self._check_frame(index)
        return {cam: self.image(cam, index) for cam in self.cameras}

    def frames(self):
        """Iterate ``(index, {camera: image})`` over the complete frames in index order."""
        for index in self.frame_indices:
            yield index, self.frame(index)

    def frame_meta(self, index: int) -> dict:
        """``{"index", "timestamps_ns": {cam: int|None}, "frame_ids": {cam: int|None},
        "flags": {cam: str}}`` for a complete frame."""
        index = self._check_frame(index)
        row = self._rows[index]
        return {
            "index": index,
            "timestamps_ns": dict(row.timestamps_ns),
            "frame_ids": dict(row.frame_ids),
            "flags": dict(row.flags),
        }

    # ------------------------------------------------------------------ backgrounds
    def background_indices(self, camera: str) -> list[int]:
        """Sorted indices of ``camera``'s background frames on disk."""
        self._check_camera(camera)
        return sorted(_list_images(self.path / BACKGROUND_DIR / camera))

    def background(self, camera: str, index: int) -> np.ndarray:
        if index not in self.background_indices(camera):
            raise SessionError(f"session {self.path}: camera '{camera}' has no background frame {index}")
        return self._load(self.background_path(camera, index), camera, f"background {index}")

    def backgrounds(self, camera: str) -> list[np.ndarray]:
        """Every background frame of ``camera``, in index order."""
        return [self.background(camera, i) for i in self.background_indices(camera)]

    def _background_issues(self) -> list[str]:
        counts = {cam: set(self.background_indices(cam)) for cam in self.cameras}
        union = set().union(*counts.values())
        out = []
        for cam, got in counts.items():
            if got != union:
                missing = sorted(union - got)
                out.append(
                    f"{BACKGROUND_DIR}/{cam}: {len(got)} background frames, other cameras have "
                    f"{len(union)} (missing indices {missing[:10]}{' ...' if len(missing) > 10 else ''})"
                )
        return out

    # ------------------------------------------------------------------ validation
    def validate(self, deep: bool = False, progress: Callable[[int, int], None] | None = None) -> ValidationReport:
        """Check the session: every listed image exists and has the camera's size (from its
        header); with ``deep`` every frame and background image is also decoded. ``progress``
        is called with ``(done, total)`` frames."""
        problems = list(self.issues)
        problems += [f"frame {i}: {r}" for i, r in self.gaps if i in self._bad_rows]
        notes = []
        images = 0
        total = len(self.frame_indices)
        for done, index in enumerate(self.frame_indices, 1):
            for cam in self.cameras:
                problem = self._check_one(self.frame_path(cam, index), cam, f"frame {index}", deep)
                images += 1
                if problem:
                    problems.append(problem)
            if progress is not None:
                progress(done, total)
        for cam in self.cameras:
            for index in self.background_indices(cam):
                problem = self._check_one(self.background_path(cam, index), cam, f"background {index}", deep)
                images += 1
                if problem:
                    problems.append(problem)
            folder = self.path / FRAMES_DIR / cam
            orphans = sorted(set(_list_images(folder)) - set(self._rows))
            if orphans:
                notes.append(
                    f"{FRAMES_DIR}/{cam}: {len(orphans)} image file(s) not listed in {FRAMES_CSV} "
                    f"(e.g. an interrupted last frame): indices {orphans[:10]}"
                )
            for sub in (FRAMES_DIR, BACKGROUND_DIR):
                d = self.path / sub / cam
                tmp = [p.name for p in d.iterdir() if is_temporary(p.name)] if d.is_dir() else []
                if tmp:
                    notes.append(f"{sub}/{cam}: {len(tmp)} leftover temporary file(s) from an interrupted write")
        if self.status == "recording":
            notes.append(f"status is 'recording': the writer never closed the session (crashed or still running)")
        return ValidationReport(self.path, total, images, deep, tuple(problems), tuple(self.gaps), tuple(notes))

    def _check_one(self, path: Path, camera: str, what: str, deep: bool) -> str | None:
        if deep:
            try:
                self._load(path, camera, what)
            except SessionError as exc:
                return str(exc)
            return None
        try:
            meta = imageio.image_info(path)
        except (OSError, ImageIOError) as exc:
            return f"camera '{camera}' {what}: {exc}"
        w, h = self.image_size(camera)
        if (meta.width, meta.height) != (w, h):
            return f"{path}: image size is {meta.width}x{meta.height}, expected {w}x{h} (camera '{camera}')"
        return None

    def __repr__(self) -> str:
        return (
            f"Session({str(self.path)!r}, cameras={self.cameras}, frames={len(self.frame_indices)}, "
            f"gaps={len(self.gaps)}, status={self.status!r})"
        )


# --------------------------------------------------------------------------- reader helpers


def _find_image(folder: Path, index: int, suffix: str | None) -> Path:
    name = index_name(index)
    if suffix in imageio.IMAGE_SUFFIXES:
        return folder / f"{name}{suffix}"
    for candidate in imageio.IMAGE_SUFFIXES:
        p = folder / f"{name}{candidate}"
        if p.exists():
            return p
    return folder / f"{name}.png"


def _list_names(folder: Path) -> set[str]:
    return {entry.name for entry in os.scandir(folder)} if folder.is_dir() else set()


def _list_images(folder: Path) -> list[int]:
    if not folder.is_dir():
        return []
    out = []
    for entry in os.scandir(folder):
        m = _IMAGE_NAME_RE.match(entry.name)
        if m:
            out.append(int(m.group(1)))
    return out


def _parse_major(version: Any, path: Path) -> int:
    if isinstance(version, int) and not isinstance(version, bool):
        return version
    if isinstance(version, str) and re.match(r"^\d+(\.\d+)*$", version):
        return int(version.split(".")[0])
    raise SessionError(f"{path}: field 'version' is {version!r}, expected an integer such as {SESSION_VERSION}")


def _read_info(path: Path) -> dict:
    file = path / SESSION_JSON
    try:
        text = file.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SessionError(
            f"{path}: not a capture session ({SESSION_JSON} missing; expected a folder written "
            "by rigs.SessionWriter)"
        ) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SessionError(f"{file}: cannot read ({exc})") from exc
    try:
        info = json.loads(text)
    except ValueError as exc:
        raise SessionError(f"{file}: not valid JSON ({exc})") from exc
    if not isinstance(info, dict):
        raise SessionError(f"{file}: expected a JSON object, got {type(info).__name__}")
    if info.get("format") != SESSION_FORMAT:
        raise SessionError(f"{file}: field 'format' is {info.get('format')!r}, expected {SESSION_FORMAT!r}")
    major = _parse_major(info.get("version"), file)
    if major != SESSION_VERSION:
        raise SessionError(
            f"{file}: field 'version' is {info.get('version')!r}; this reader understands major "
            f"version {SESSION_VERSION} only (a newer toolkit wrote it?)"
        )
    try:
        _check_cameras(info.get("cameras"))
    except SessionError as exc:
        raise SessionError(f"{file}: field {exc}") from None
    fps = info.get("fps")
    if fps is not None and (isinstance(fps, bool) or not isinstance(fps, (int, float)) or fps <= 0):
        raise SessionError(f"{file}: field 'fps' is {fps!r}, expected a positive number or null")
    images = info.get("images", {})
    if not isinstance(images, dict):
        raise SessionError(f"{file}: field 'images' is {images!r}, expected an object")
    for cam, spec in images.items():
        keys = {"width", "height", "channels", "dtype"}
        if not isinstance(spec, dict) or not keys <= set(spec):
            raise SessionError(f"{file}: field 'images.{cam}' is {spec!r}, expected keys {sorted(keys)}")
    return info


def _parse_optional_int(text: str) -> int | None:
    return None if text == "" else int(text)


def _read_frames_csv(file: Path, cameras: list[str]) -> tuple[dict[int, _Row], list[str]]:
    try:
        data = file.read_bytes()
    except FileNotFoundError:
        raise SessionError(f"{file}: missing (every session has a {FRAMES_CSV} with a header line)") from None
    header = csv_header(cameras)
    lines = data.split(b"\n")
    got_header = lines[0].decode("utf-8", "replace").rstrip("\r").split(",")
    if len(lines) < 2 or got_header != header:
        raise SessionError(
            f"{file}: header is {got_header}, expected {header} (columns for cameras {cameras} of {SESSION_JSON})"
        )
    rows: dict[int, _Row] = {}
    issues: list[str] = []
    tail = lines[-1]
    body = lines[1:-1]
    if tail:
        shown = tail[:60].decode("utf-8", "replace")
        issues.append(
            f"{FRAMES_CSV} line {len(lines)}: last line has no newline (torn write, ignored): {shown!r}"
        )
    for number, raw in enumerate(body, start=2):
        try:
            text = raw.decode("utf-8").rstrip("\r")
        except UnicodeDecodeError:
            issues.append(f"{FRAMES_CSV} line {number}: not UTF-8 text (ignored)")
            continue
        fields = text.split(",")
        if len(fields) != len(header):
            issues.append(
                f"{FRAMES_CSV} line {number}: {len(fields)} fields, expected {len(header)} (ignored)"
            )
            continue
        try:
            index = int(fields[0])
            if index < 0:
                raise ValueError
        except ValueError:
            issues.append(
                f"{FRAMES_CSV} line {number}: field 'index' is {fields[0][:20]!r}, expected a "
                "non-negative integer (ignored)"
            )
            continue
        ts, ids, flags = {}, {}, {}
        bad = None
        for k, cam in enumerate(cameras):
            t, fid, flag = fields[1 + 3 * k : 4 + 3 * k]
            for col, value, target in ((f"{cam}.timestamp_ns", t, ts), (f"{cam}.frame_id", fid, ids)):
                try:
                    target[cam] = _parse_optional_int(value)
                except ValueError:
                    bad = f"field '{col}' is {value[:20]!r}, expected an integer or empty"
            flags[cam] = flag
        if bad:
            issues.append(f"{FRAMES_CSV} line {number}: {bad} (ignored)")
            continue
        if index in rows:
            issues.append(
                f"{FRAMES_CSV} line {number}: duplicate row for frame {index} "
                f"(line {rows[index].line} kept)"
            )
            continue
        rows[index] = _Row(number, ts, ids, flags)
    return rows, issues
