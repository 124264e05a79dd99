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

import importlib
from os import PathLike
from pathlib import Path
from typing import Any, Callable, NamedTuple

from calibration.errors import CalibrationError

__all__ = ["FORMATS", "RigParts", "WRITABLE", "detect_format", "read", "reader", "write", "writer"]


class RigParts(NamedTuple):
    """What a format reader returns; :class:`calibration.RigCalibration` is built from it
    (format modules never import the rig class: the registry below is the one way in)."""

    cameras: dict
    ground: Any
    metadata: dict


#: The registry: format name → (module, reader, writer or None). Modules load on first use,
#: so e.g. pycolmap is imported only for COLMAP files.
_REGISTRY = {
    "native": ("native", "read_native", "write_native"),
    "opencv": ("opencv", "read_opencv", "write_opencv"),
    "toml": ("toml_calib", "read_toml", "write_toml"),
    "colmap": ("colmap", "read_colmap", "write_colmap"),
    "qualisys": ("qualisys", "read_qualisys", None),
}
FORMATS = tuple(_REGISTRY)
WRITABLE = tuple(name for name, (_, _, w) in _REGISTRY.items() if w is not None)


def _function(fmt: str, which: int) -> Callable:
    if fmt not in _REGISTRY:
        raise CalibrationError(f"unknown format {fmt!r} (known: {', '.join(FORMATS)})")
    module, *names = _REGISTRY[fmt]
    name = names[which]
    if name is None:
        raise CalibrationError(f"cannot write format {fmt!r} (writable: {', '.join(WRITABLE)})")
    return getattr(importlib.import_module(f"{__name__}.{module}"), name)


def reader(fmt: str) -> Callable[..., RigParts]:
    """The reader function of ``fmt`` (returns :class:`RigParts`)."""
    return _function(fmt, 0)


def writer(fmt: str) -> Callable:
    """The writer function of ``fmt`` (``write(rig, path, ...)``)."""
    return _function(fmt, 1)


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


def read(path: str | PathLike, fmt: str | None = None) -> RigParts:
    """Read ``path`` as ``fmt`` (detected when None) → :class:`RigParts`
    (:meth:`calibration.RigCalibration.load_any` makes the rig of them)."""
    path = Path(path)
    fmt = fmt or detect_format(path)
    if not path.exists():
        raise CalibrationError("no such file or folder", file=path)
    if fmt == "opencv" and not path.is_dir():
        if path.name.lower().startswith("extri"):
            return reader(fmt)(path.with_name(path.name.replace("extri", "intri")), path)
        return reader(fmt)(path, path.with_name(path.name.replace("intri", "extri")))
    if fmt == "colmap" and not path.is_dir():
        path = path.parent
    return reader(fmt)(path)


def write(rig, path: str | PathLike, fmt: str | None = None) -> Path:
    """Write ``rig`` to ``path`` as ``fmt`` (from the name when None); returns the path."""
    path = Path(path)
    fmt = fmt or detect_format(path, for_writing=True)
    try:
        write_fn = writer(fmt)
    except CalibrationError as exc:
        raise exc.in_file(path) from None
    if fmt == "opencv":
        if path.suffix.lower() in (".yml", ".yaml"):
            write_fn(rig, path, path.with_name(path.name.replace("intri", "extri")))
        else:
            write_fn(rig, path)
        return path
    return write_fn(rig, path)
