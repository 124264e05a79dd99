"""The validating session reader (see :mod:`rigs.session` for what it does with a damaged session)."""

from __future__ import annotations

import logging

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from rigs import imageio
from rigs.atomic import is_temporary
from rigs.imageio import ImageIOError
from rigs.session.checks import ValidationReport, _describe, _image_spec
from rigs.session.index import _Row, _read_frames_csv, _read_info
from rigs.session.layout import (
    BACKGROUND_DIR,
    CALIBRATION_JSON,
    FRAMES_CSV,
    FRAMES_DIR,
    MAX_GAP_ENTRIES,
    SESSION_JSON,
    STATUSES,
    SessionError,
    TRUTH_DIR,
    _find_image,
    _list_images,
    _list_names,
)

log = logging.getLogger(__name__)


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
    def drops(self) -> dict:
        """What the capture lost (``session.json`` ``"drops"``, see :meth:`SessionWriter.record_drops`);
        empty when nothing was recorded."""
        return dict(self.info.get("drops") or {})

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
        spec = self._spec(camera)
        # the camera's declared size bounds what is decoded (a forged 40000x40000 header is refused first)
        limit = (int(spec["width"]), int(spec["height"])) if spec is not None else None
        try:
            image = imageio.read_image(path, max_size=limit)
        except (OSError, ImageIOError) as exc:
            raise SessionError(f"camera '{camera}' {what}: {exc}") from exc
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
            notes.append("status is 'recording': the writer never closed the session (crashed or still running)")
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
