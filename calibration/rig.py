"""A calibrated rig: cameras, the ground plane and metadata, with file import/export."""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace as dc_replace
from os import PathLike
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.ground import GroundPlane

__all__ = ["RigCalibration"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class RigCalibration:
    """Cameras (by name, in rig order) + ground plane + free-form JSON-able metadata.

    Readers and writers (all raise :class:`CalibrationError` naming file, camera, field):

    ========================  =================================  ==========================
    format                    read                               write
    ========================  =================================  ==========================
    native JSON (v1)          :meth:`load`                       :meth:`save`
    OpenCV YAML (EasyMocap)   :meth:`from_opencv`                :meth:`to_opencv`
    Pose2Sim/anipose TOML     :meth:`from_toml`                  :meth:`to_toml`
    COLMAP model (pycolmap)   :meth:`from_colmap`                :meth:`to_colmap`
    Qualisys ``.qca.txt``     :meth:`from_qualisys`              —
    ========================  =================================  ==========================

    Every format keeps each camera's lens model (``Camera.model``, pinhole or fisheye).
    :meth:`load_any` picks the reader from the path and reads every format of
    :mod:`calibration.formats` (Caliscope, multical, Kalibr, Vicon, OptiTrack, per-camera
    OpenCV files, ...); :meth:`from_camera_files` reads ``{name: file}`` pairs. Every load
    converts to metres and world Z up and says what it read and assumed in ``notes``
    (:mod:`calibration.formats.checks`). ``rig[name]`` gives a camera; iterating a rig
    yields its :class:`Camera` objects in rig order.
    """

    cameras: dict[str, Camera]
    ground: GroundPlane = field(default_factory=GroundPlane.floor)
    metadata: dict = field(default_factory=dict)
    #: What the load that made this rig read and assumed (units, up axis, conventions);
    #: sentences, warnings start with ``"warning:"``. Empty for rigs built in code.
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        cams = self.cameras
        if isinstance(cams, (list, tuple)):
            cams = {c.name: c for c in cams}
        if not isinstance(cams, dict) or not cams:
            raise CalibrationError("a rig calibration needs at least one camera", field="cameras")
        for key, cam in cams.items():
            if not isinstance(cam, Camera):
                raise CalibrationError(
                    f"expected a Camera, got {type(cam).__name__}", camera=str(key)
                )
            if key != cam.name:
                raise CalibrationError(
                    f"listed under {key!r} but named {cam.name!r}", camera=str(key), field="name"
                )
        if not isinstance(self.ground, GroundPlane):
            raise CalibrationError(
                f"expected a GroundPlane, got {type(self.ground).__name__}", field="ground"
            )
        if not isinstance(self.metadata, dict):
            raise CalibrationError(
                f"expected a mapping, got {type(self.metadata).__name__}", field="metadata"
            )
        object.__setattr__(self, "cameras", dict(cams))
        object.__setattr__(self, "metadata", dict(self.metadata))
        object.__setattr__(self, "notes", tuple(str(n) for n in self.notes))

    # ------------------------------------------------------------------ access
    @property
    def camera_names(self) -> list[str]:
        return list(self.cameras)

    def __getitem__(self, name: str) -> Camera:
        try:
            return self.cameras[name]
        except KeyError:
            raise KeyError(
                f"no camera {name!r} in the calibration (cameras: {', '.join(self.cameras)})"
            ) from None

    def __contains__(self, name: object) -> bool:
        return name in self.cameras

    def __iter__(self):
        return iter(self.cameras.values())

    def __len__(self) -> int:
        return len(self.cameras)

    def replace(self, **changes: Any) -> RigCalibration:
        return dc_replace(self, **changes)

    def subset(self, names: Iterable[str]) -> RigCalibration:
        """The same rig restricted to ``names`` (in that order)."""
        return self.replace(cameras={n: self[n] for n in names})

    def allclose(self, other: RigCalibration, atol: float = 1e-9) -> bool:
        """Same camera names (same order), every camera and the ground plane to ``atol``."""
        return (
            self.camera_names == other.camera_names
            and all(self[n].allclose(other[n], atol) for n in self.camera_names)
            and self.ground.allclose(other.ground, atol)
        )

    def project(self, X: np.ndarray, distort: bool = True) -> dict[str, np.ndarray]:
        """World points (N, 3) → ``{camera: (N, 2) pixels}``."""
        return {n: c.project(X, distort) for n, c in self.cameras.items()}

    def __repr__(self) -> str:
        return (
            f"RigCalibration({len(self)} cameras: {', '.join(self.cameras)}; ground={self.ground!r})"
        )

    # ------------------------------------------------------------------ files (calibration.formats)
    @property
    def warnings(self) -> list[str]:
        """The notes that are warnings (``"warning: ..."``)."""
        return [n for n in self.notes if n.startswith("warning:")]

    @classmethod
    def _from_parts(cls, parts, source) -> RigCalibration:
        try:
            return cls(parts.cameras, parts.ground, parts.metadata, parts.notes)
        except CalibrationError as exc:
            raise exc.in_file(source) from None

    @classmethod
    def _read(cls, fmt: str, *args) -> RigCalibration:
        from calibration import formats
        from calibration.formats.checks import settle

        parts = formats.reader(fmt)(*args)
        try:
            parts = settle(parts, source=str(args[0]))
        except CalibrationError as exc:
            raise exc.in_file(args[0]) from None
        return cls._from_parts(parts, args[0])

    @classmethod
    def load(cls, path: str | PathLike) -> RigCalibration:
        """Read the native ``calibration.json`` (``format studio.rig-calibration``, version 1)."""
        return cls._read("native", path)

    def save(self, path: str | PathLike) -> Path:
        """Write the native JSON atomically; returns the path."""
        from calibration import formats

        return formats.writer("native")(self, path)

    @classmethod
    def from_opencv(
        cls, intri_path: str | PathLike, extri_path: str | PathLike | None = None
    ) -> RigCalibration:
        """Read EasyMocap-style ``intri.yml`` + ``extri.yml`` (OpenCV FileStorage).

        ``intri_path`` may also be the folder holding both files.
        """
        return cls._read("opencv", intri_path, extri_path)

    def to_opencv(
        self, intri_path: str | PathLike, extri_path: str | PathLike | None = None
    ) -> tuple[Path, Path]:
        """Write EasyMocap-style ``intri.yml`` + ``extri.yml`` (or both into a folder)."""
        from calibration import formats

        return formats.writer("opencv")(self, intri_path, extri_path)

    @classmethod
    def from_toml(cls, path: str | PathLike) -> RigCalibration:
        """Read a Pose2Sim / anipose ``Calib.toml``."""
        return cls._read("toml", path)

    def to_toml(self, path: str | PathLike) -> Path:
        """Write a Pose2Sim / anipose ``Calib.toml``."""
        from calibration import formats

        return formats.writer("toml")(self, path)

    @classmethod
    def from_colmap(cls, path: str | PathLike) -> RigCalibration:
        """Read a COLMAP model folder (cameras + images, text or binary) via pycolmap."""
        return cls._read("colmap", path)

    def to_colmap(self, path: str | PathLike, binary: bool = False) -> Path:
        """Write a COLMAP model folder (OPENCV / FULL_OPENCV / OPENCV_FISHEYE cameras, one
        image per camera); a ``points3D`` already there is kept."""
        from calibration import formats

        return formats.writer("colmap")(self, path, binary=binary)

    @classmethod
    def from_qualisys(cls, path: str | PathLike) -> RigCalibration:
        """Read a Qualisys QTM calibration export (``*.qca.txt``, XML)."""
        return cls._read("qualisys", path)

    @classmethod
    def load_any(cls, path: str | PathLike, fmt: str | None = None, *, units: str | None = None,
                 z_down: str | None = None) -> RigCalibration:
        """Read a calibration in any supported format (``fmt``, or chosen from the path and content).

        ``units`` (``"m"``, ``"cm"``, ``"mm"``) overrides the units detected from the
        magnitudes; ``z_down`` says what to do with a world whose Z points down (``"flip"``,
        the default for other tools' files; ``"refuse"``; ``"keep"``, the default for the
        toolkit's own). ``notes`` of the result say what was read and assumed.
        """
        from calibration import formats

        return cls._from_parts(formats.read(path, fmt, units=units, z_down=z_down), path)

    @classmethod
    def from_camera_files(cls, pairs: dict, *, units: str | None = None,
                          z_down: str | None = None) -> RigCalibration:
        """Per-camera OpenCV FileStorage files ``{camera name: file}`` (e.g. ``config.xml`` with
        ``CameraMatrix``, ``DistortionCoeffs``, ``Rotation``, ``Translation``), as :meth:`load_any`."""
        from calibration import formats

        if not pairs:
            raise CalibrationError("expected at least one NAME=FILE pair", field="cameras")
        return cls._from_parts(formats.read_pairs(pairs, units=units, z_down=z_down), next(iter(pairs.values())))

    def write(self, path: str | PathLike, fmt: str | None = None) -> Path:
        """Write in any writable format (``fmt``, or chosen from the path)."""
        from calibration import formats

        return formats.write(self, path, fmt)
