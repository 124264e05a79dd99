"""The workspace: a session folder opened once, its calibration validated once against it.

Every command that reads or writes a session (``segment``, ``fit``, ``report``,
``session info --check``, ``capture``) goes through :class:`Workspace`: it opens the capture
(:class:`rigs.session.Session`), loads ``calibration.json`` and checks it against the session
(:func:`validate_calibration`), and knows where every derived output lives
(:class:`studio.workspace.Layout`). Outputs go into the session folder, or into ``out`` when
given (a read-only session, a shared archive); writability is checked before any long work.
"""

from __future__ import annotations

import logging
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from studio.workspace.layout import Layout

__all__ = ["FLOOR_TILT_WARN_DEG", "Workspace", "WorkspaceError", "validate_calibration"]

log = logging.getLogger(__name__)

#: A ground plane tilted more than this from the world's Z axis is accepted with a warning.
FLOOR_TILT_WARN_DEG = 10.0
#: Plausible focal lengths in pixels (a 1e-300 px or 1e9 px focal length is a unit or parse error).
FOCAL_RANGE_PX = (1e-1, 1e7)


class WorkspaceError(ValueError):
    """A session folder cannot be used as asked; the message names the file, the camera or
    field, and what was expected."""


def validate_calibration(calibration, sizes: Mapping[str, tuple[int, int]] | None = None, *,
                         source: str | os.PathLike = "calibration") -> list[str]:
    """Check a :class:`calibration.RigCalibration` against the cameras that will use it.

    ``sizes`` maps every camera name of the session (or rig) to its image ``(width, height)``;
    each must be calibrated for exactly that size. Every camera must have finite values, a
    rotation ``R`` (orthonormal, det +1), plausible positive focal lengths; the floor's normal
    must point up (world Z up, DESIGN.md). Raises :class:`WorkspaceError` naming ``source``,
    the camera and the field; returns warnings (a floor tilted over ``FLOOR_TILT_WARN_DEG``).
    """
    from calibration.rotation import is_rotation

    src = str(source)
    if sizes is not None:
        missing = [c for c in sizes if c not in calibration]
        if missing:
            raise WorkspaceError(f"{src}: no calibration for camera(s) {missing} of the session "
                                 f"(calibrated: {list(calibration.camera_names)})")
    for cam in calibration:
        where = f"{src}: camera {cam.name!r}"
        for field in ("K", "dist", "R", "t"):
            if not np.all(np.isfinite(getattr(cam, field))):
                raise WorkspaceError(f"{where}: field {field!r}: expected finite values, got "
                                     f"{np.asarray(getattr(cam, field)).tolist()}")
        if not is_rotation(cam.R):
            raise WorkspaceError(f"{where}: field 'R': expected a rotation (orthonormal, determinant +1)")
        fx, fy = float(cam.K[0, 0]), float(cam.K[1, 1])
        lo, hi = FOCAL_RANGE_PX
        if not (lo <= fx <= hi and lo <= fy <= hi):
            raise WorkspaceError(f"{where}: field 'K': expected focal lengths between {lo:g} and {hi:g} px, "
                                 f"got fx={fx:g}, fy={fy:g}")
        if sizes is not None and cam.name in sizes:
            w, h = (int(v) for v in sizes[cam.name])
            if tuple(cam.size) != (w, h):
                raise WorkspaceError(f"{where}: field 'size': calibrated for {cam.size[0]}x{cam.size[1]} "
                                     f"images, the session's are {w}x{h}")
    warnings = []
    ground = getattr(calibration, "ground", None)
    if ground is not None:
        n = np.asarray(ground.normal, dtype=float)
        if not np.all(np.isfinite(n)) or n[2] <= 0:
            raise WorkspaceError(f"{src}: field 'ground.normal': expected a floor normal pointing up "
                                 f"(world Z up), got {n.tolist()} — the world frame is upside down "
                                 "or the floor was fitted from below")
        tilt = float(np.degrees(np.arccos(np.clip(n[2] / np.linalg.norm(n), -1, 1))))
        if tilt > FLOOR_TILT_WARN_DEG:
            warnings.append(f"{src}: field 'ground.normal': the floor is tilted {tilt:.1f}° from the world's "
                            f"Z axis (more than {FLOOR_TILT_WARN_DEG:g}°): check the floor calibration")
    for w in warnings:
        log.warning(w)
    return warnings


def _load_warnings(calibration, source) -> list[str]:
    """Warnings of the calibration's load (units, up axis, :mod:`calibration.formats.checks`) and
    of the conversion that made it (``metadata["import_notes"]``, written by ``studio convert``)."""
    earlier = calibration.metadata.get("import_notes", [])
    found = list(calibration.warnings) + [f"when imported: {n}" for n in earlier
                                          if isinstance(n, str) and n.startswith("warning:")]
    out = [f"{source}: {w}" for w in found]
    for w in out:
        log.warning(w)
    return out


class Workspace:
    """A capture session opened for analysis.

    Attributes: ``session`` (:class:`rigs.session.Session`), ``path`` (the session folder),
    ``layout`` (where outputs live), ``calibration`` (validated, or None when the session has
    none; its ``notes`` say what its load read and assumed), ``warnings`` (from the validation,
    the load's checks and the import that made the file).
    """

    def __init__(self, session, calibration, layout: Layout, warnings: list[str]):
        self.session = session
        self.calibration = calibration
        self.layout = layout
        self.warnings = warnings

    @classmethod
    def open(cls, path: str | os.PathLike, *, out: str | os.PathLike | None = None) -> Workspace:
        """Open the session at ``path``; derived outputs go to ``out`` (default: the session)."""
        from calibration import CalibrationError, RigCalibration
        from rigs.session import Session, SessionError

        path = Path(path)
        if not path.is_dir():
            raise WorkspaceError(f"{path}: no such session folder")
        try:
            session = Session.open(path)
        except SessionError as exc:
            raise WorkspaceError(str(exc)) from None
        calibration, warnings = None, []
        if session.calibration_path is not None:
            try:
                calibration = RigCalibration.load(session.calibration_path)
            except (CalibrationError, OSError) as exc:
                raise WorkspaceError(f"{session.calibration_path}: {exc}") from None
            sizes = {c: session.image_size(c) for c in session.cameras}
            warnings = validate_calibration(calibration, sizes, source=session.calibration_path)
            warnings += _load_warnings(calibration, session.calibration_path)
        layout = Layout(session.path if out is None else Path(out), source=session.path)
        return cls(session, calibration, layout, warnings)

    # ------------------------------------------------------------------ the capture
    @property
    def path(self) -> Path:
        return self.session.path

    @property
    def camera_names(self) -> list[str]:
        return list(self.session.cameras)

    @property
    def frame_indices(self) -> list[int]:
        return list(self.session.frame_indices)

    @property
    def cameras(self) -> list:
        """Calibrated cameras in session order (requires a calibration)."""
        calib = self.require_calibration("the cameras' geometry")
        return [calib[c] for c in self.session.cameras]

    def require_calibration(self, needed_for: str):
        if self.calibration is None:
            raise WorkspaceError(f"{self.path}: no calibration.json, needed for {needed_for} — calibrate the rig "
                                 "(`studio calibrate ...`) and copy its calibration.json into the session")
        return self.calibration

    def check_frames(self, frames) -> list[int]:
        """``frames`` as a list of complete frame indices of the session, or a clear error."""
        complete = set(self.session.frame_indices)
        out = [int(f) for f in frames]
        bad = [f for f in out if f not in complete]
        if bad:
            raise WorkspaceError(f"{self.path}: frame(s) {bad[:10]} are not complete frames of the session "
                                 f"(it has {len(complete)}: {min(complete, default='-')}..{max(complete, default='-')})")
        return out

    # ------------------------------------------------------------------ derived outputs
    def check_writable(self, folder: Path) -> Path:
        """Create ``folder`` (under the outputs) and prove it writable with a temporary file,
        before any long work; a read-only session fails here, naming ``--out`` as the way out.
        The temporary files a killed run's writers left in it (and below) are cleared: a command
        owns its output folder while it runs (one run per output folder at a time)."""
        from rigs.atomic import remove_temporaries

        folder = Path(folder)
        try:
            folder.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=folder, prefix=".write-check-"):
                pass
        except OSError as exc:
            raise WorkspaceError(f"{folder}: cannot write results there ({exc.strerror or exc}); "
                                 "give an output folder with --out DIR") from None
        for path in remove_temporaries(folder, recursive=True):
            log.info("%s: removed (a killed run's temporary file)", path)
        return folder

    def labels(self, camera: str, frame: int) -> np.ndarray:
        """Segmentation labels (H, W) uint8 of ``camera`` / ``frame`` (0 background, 1 person, 2 shadow)."""
        from rigs.imageio import read_image

        p = self.layout.labels(camera, frame)
        if not p.is_file():
            raise WorkspaceError(f"{p}: missing segmentation of frame {frame} — run `studio segment {self.path}` first")
        lab = read_image(p)
        return lab[..., 0] if lab.ndim == 3 else lab

    def person_masks(self, frame: int) -> list[np.ndarray]:
        """Person silhouettes (H, W) bool of ``frame`` in camera order (label 1)."""
        return [self.labels(c, frame) == 1 for c in self.session.cameras]

    def check_segmented(self, frames) -> None:
        """Every camera of every frame in ``frames`` has its labels, or a clear error."""
        seg = self.layout.segmentation_dir
        if not seg.is_dir():
            raise WorkspaceError(f"{self.path}: no segmentation/ folder — run `studio segment {self.path}` first")
        for f in frames:
            for c in self.session.cameras:
                p = self.layout.labels(c, f)
                if not p.is_file():
                    raise WorkspaceError(f"{p}: missing segmentation of frame {f} — run "
                                         f"`studio segment {self.path}` first")

    def images(self, frame: int) -> list[np.ndarray]:
        """Camera images of ``frame`` in camera order."""
        imgs = self.session.frame(frame)
        return [imgs[c] for c in self.session.cameras]

    def __repr__(self) -> str:
        out = "" if self.layout.root == self.path else f", out={str(self.layout.root)!r}"
        return f"Workspace({str(self.path)!r}{out}, cameras={self.camera_names}, frames={len(self.frame_indices)})"
