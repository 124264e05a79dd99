"""Checks of what a writer is given (frame indices, camera lists, image specs) and the result of validating a session."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from rigs import imageio
from rigs.session.layout import SessionError, _CAMERA_RE


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
