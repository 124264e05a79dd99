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

from rigs.session.checks import ValidationReport
from rigs.session.index import csv_header
from rigs.session.layout import (
    BACKGROUND_DIR,
    CALIBRATION_JSON,
    FRAMES_CSV,
    FRAMES_DIR,
    INDEX_DIGITS,
    SESSION_FORMAT,
    SESSION_JSON,
    SESSION_VERSION,
    TRUTH_DIR,
    SessionError,
    index_name,
)
from rigs.session.reader import Session
from rigs.session.writer import SessionWriter

__all__ = [
    "SessionError",
    "SessionWriter",
    "Session",
    "ValidationReport",
    "SESSION_FORMAT",
    "SESSION_VERSION",
    "index_name",
    "csv_header",
    "BACKGROUND_DIR",
    "CALIBRATION_JSON",
    "FRAMES_CSV",
    "FRAMES_DIR",
    "INDEX_DIGITS",
    "SESSION_JSON",
    "TRUTH_DIR",
]
