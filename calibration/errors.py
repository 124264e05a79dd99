"""The one error type of the calibration package."""

from __future__ import annotations

from os import PathLike

__all__ = ["CalibrationError"]


class CalibrationError(ValueError):
    """A malformed or inconsistent calibration.

    The message names, where known, the file, the camera and the field, then what was
    expected, e.g. ``calib.json: camera 'cam02': field 'R': not orthonormal ...``.
    The parts are also kept as attributes (``file``, ``camera``, ``field``, ``detail``).
    """

    def __init__(
        self,
        detail: str,
        *,
        file: str | PathLike | None = None,
        camera: str | None = None,
        field: str | None = None,
    ):
        self.detail = detail
        self.file = None if file is None else str(file)
        self.camera = camera
        self.field = field
        super().__init__(self._compose())

    def _compose(self) -> str:
        parts = []
        if self.file is not None:
            parts.append(f"{self.file}:")
        if self.camera is not None:
            parts.append(f"camera {self.camera!r}:")
        if self.field is not None:
            parts.append(f"field {self.field!r}:")
        parts.append(self.detail)
        return " ".join(parts)

    def in_file(self, file: str | PathLike) -> CalibrationError:
        """The same error with ``file`` filled in (kept if already set)."""
        if self.file is not None:
            return self
        return CalibrationError(self.detail, file=file, camera=self.camera, field=self.field)
