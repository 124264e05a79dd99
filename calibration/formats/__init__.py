"""Calibration file formats: one module per format, plus detection and dispatch.

=========  ==========================================================
name       what
=========  ==========================================================
native     ``calibration.json`` (:mod:`calibration.formats.native`)
opencv     EasyMocap ``intri.yml`` + ``extri.yml`` folder (OpenCV FileStorage)
toml       Pose2Sim / anipose ``Calib.toml``
colmap     COLMAP sparse model folder (``cameras`` + ``images``, via pycolmap)
qualisys   Qualisys QTM ``*.qca.txt`` (read only)
=========  ==========================================================
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

from calibration.errors import CalibrationError

__all__ = ["FORMATS", "WRITABLE", "detect_format", "read", "write"]

FORMATS = ("native", "opencv", "toml", "colmap", "qualisys")
WRITABLE = ("native", "opencv", "toml", "colmap")


def _looks_qualisys(path: Path) -> bool:
    try:
        with open(path, "rb") as f:
            head = f.read(2048)
    except OSError:
        return False
    return b"<calibration" in head


def detect_format(path: str | PathLike, for_writing: bool = False) -> str:
    """The format of ``path`` from its name (and, for reading, its content).

    Folders: ``intri.yml``/``extri.yml`` inside → opencv; ``cameras.txt``/``cameras.bin``
    inside → colmap. When writing a folder that does not exist yet, a name ending in
    ``colmap`` or ``sparse``… is ambiguous: pass the format explicitly instead.
    """
    path = Path(path)
    name = path.name.lower()
    if path.is_dir():
        if (path / "intri.yml").exists() or (path / "extri.yml").exists():
            return "opencv"
        if (path / "cameras.txt").exists() or (path / "cameras.bin").exists():
            return "colmap"
        if for_writing:
            raise CalibrationError(
                "is a folder: say which format to write (opencv or colmap)", file=path
            )
        raise CalibrationError(
            "folder holds neither intri.yml/extri.yml (OpenCV) nor cameras.txt/.bin (COLMAP)",
            file=path,
        )
    if name.endswith(".json"):
        return "native"
    if name.endswith(".toml"):
        return "toml"
    if name.endswith((".yml", ".yaml")):
        return "opencv"
    if name.endswith(".qca.txt") or name.endswith(".qca"):
        return "qualisys"
    if name in ("cameras.txt", "cameras.bin", "images.txt", "images.bin"):
        return "colmap"
    if not for_writing and path.is_file() and _looks_qualisys(path):
        return "qualisys"
    raise CalibrationError(
        "cannot tell the calibration format from the name "
        "(expected .json, .toml, .yml, .qca.txt or an OpenCV/COLMAP folder)",
        file=path,
    )


def read(path: str | PathLike, fmt: str | None = None):
    """Read ``path`` as ``fmt`` (detected when None) → :class:`RigCalibration`."""
    from calibration.rig import RigCalibration

    path = Path(path)
    fmt = fmt or detect_format(path)
    if not path.exists():
        raise CalibrationError("no such file or folder", file=path)
    if fmt == "native":
        return RigCalibration.load(path)
    if fmt == "toml":
        return RigCalibration.from_toml(path)
    if fmt == "qualisys":
        return RigCalibration.from_qualisys(path)
    if fmt == "opencv":
        if path.is_dir():
            return RigCalibration.from_opencv(path)
        if path.name.lower().startswith("extri"):
            return RigCalibration.from_opencv(path.with_name(path.name.replace("extri", "intri")), path)
        return RigCalibration.from_opencv(path, path.with_name(path.name.replace("intri", "extri")))
    if fmt == "colmap":
        return RigCalibration.from_colmap(path if path.is_dir() else path.parent)
    raise CalibrationError(f"unknown format {fmt!r} (known: {', '.join(FORMATS)})", file=path)


def write(rig, path: str | PathLike, fmt: str | None = None) -> Path:
    """Write ``rig`` to ``path`` as ``fmt`` (from the name when None); returns the path."""
    path = Path(path)
    fmt = fmt or detect_format(path, for_writing=True)
    if fmt == "native":
        return rig.save(path)
    if fmt == "toml":
        return rig.to_toml(path)
    if fmt == "opencv":
        if path.suffix.lower() in (".yml", ".yaml"):
            rig.to_opencv(path, path.with_name(path.name.replace("intri", "extri")))
            return path
        rig.to_opencv(path)
        return path
    if fmt == "colmap":
        return rig.to_colmap(path)
    raise CalibrationError(
        f"cannot write format {fmt!r} (writable: {', '.join(WRITABLE)})", file=path
    )
