"""The session folder's fixed names: file and folder names, the frame-number format, the error type, and listing of image files."""

from __future__ import annotations

import errno
import os
import re
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from rigs import imageio


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


def _unlink_quietly(path: Path) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


def _os_reason(exc: OSError) -> str:
    if exc.errno == errno.ENOSPC:
        return f"disk full (ENOSPC): {exc}"
    return str(exc)


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
