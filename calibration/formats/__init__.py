"""Calibration file formats: one module per format, plus detection and dispatch.

=============  ==========================================================
name           what
=============  ==========================================================
native         ``calibration.json`` (:mod:`calibration.formats.native`)
opencv         EasyMocap ``intri.yml`` + ``extri.yml`` folder (OpenCV FileStorage)
opencv_camera  one OpenCV FileStorage file per camera: ``<cam>/config.xml`` folders
               (``CameraMatrix``, ``DistortionCoeffs``, ``Rotation``, ``Translation``),
               OpenCV's calibration sample output (``camera_matrix``, intrinsics only)
toml           Pose2Sim / anipose / FreeMoCap ``Calib.toml``
caliscope      Caliscope ``camera_array.toml`` (and its older ``config.toml``)
multical       multical ``calibration.json``
kalibr         Kalibr ``camchain.yaml`` (``T_cn_cnm1`` chain)
colmap         COLMAP sparse model folder (``cameras`` + ``images``, via pycolmap)
qualisys       Qualisys QTM ``*.qca.txt`` (read only)
vicon          Vicon Nexus / Shogun ``.xcp`` (read only)
optitrack      OptiTrack Motive ``.mcal`` calibration export (read only)
=============  ==========================================================

Every read goes through :func:`calibration.formats.checks.settle`: translations end in
metres (units detected from magnitudes or given), the world's Z axis up (checked from the
cameras' heights), and the result carries ``notes`` saying what was read and assumed.
"""

from __future__ import annotations

import importlib
from os import PathLike
from pathlib import Path
from typing import Any, Callable, NamedTuple

from calibration.errors import CalibrationError

__all__ = ["FORMATS", "RigParts", "WRITABLE", "detect_format", "read", "read_pairs", "reader", "write", "writer"]


class RigParts(NamedTuple):
    """What a format reader returns; :class:`calibration.RigCalibration` is built from it
    (format modules never import the rig class: the registry below is the one way in).

    ``units`` are those of the translations as returned (``"m"``, ``"mm"``, ``"cm"``, or
    ``"arbitrary"`` for scale-free models); ``units_fixed`` says the format defines them
    (otherwise magnitudes decide, :mod:`calibration.formats.checks`); ``own_frame`` marks a
    world frame this toolkit wrote (its ground plane is in the file), which loads unchanged;
    ``notes`` are the reader's statements of conventions it applied or assumed.
    """

    cameras: dict
    ground: Any
    metadata: dict
    units: str = "m"
    units_fixed: bool = True
    own_frame: bool = False
    notes: tuple = ()


#: The registry: format name → (module, reader, writer or None). Modules load on first use,
#: so e.g. pycolmap is imported only for COLMAP files.
_REGISTRY = {
    "native": ("native", "read_native", "write_native"),
    "opencv": ("opencv", "read_opencv", "write_opencv"),
    "opencv_camera": ("opencv_camera", "read_opencv_camera", "write_opencv_camera"),
    "toml": ("toml_calib", "read_toml", "write_toml"),
    "caliscope": ("caliscope", "read_caliscope", "write_caliscope"),
    "multical": ("multical", "read_multical", "write_multical"),
    "kalibr": ("kalibr", "read_kalibr", "write_kalibr"),
    "colmap": ("colmap", "read_colmap", "write_colmap"),
    "qualisys": ("qualisys", "read_qualisys", None),
    "vicon": ("vicon", "read_vicon", None),
    "optitrack": ("optitrack", "read_optitrack", None),
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


def _head(path: Path, size: int = 4096) -> str:
    """The start of a file as text (UTF-16 when it says so by its byte-order mark), '' if unreadable."""
    try:
        with open(path, "rb") as f:
            head = f.read(size)
    except OSError:
        return ""
    if head.startswith((b"\xff\xfe", b"\xfe\xff")):
        return head.decode("utf-16", errors="ignore")
    return head.decode("utf-8", errors="ignore")


def _sniff_xml(head: str) -> str | None:
    if "<opencv_storage" in head:
        return "opencv_camera"
    if "<calibrationProfile" in head:
        return "optitrack"
    if "<Cameras" in head and ("<Camera " in head or "KeyFrame" in head):
        return "vicon"
    if "<calibration" in head:
        return "qualisys"
    return None


def _sniff_yaml(head: str) -> str:
    if "T_cn_cnm1" in head or ("intrinsics:" in head and "resolution:" in head):
        return "kalibr"
    if "camera_matrix" in head or "CameraMatrix" in head:
        return "opencv_camera"
    return "opencv"


def _sniff_toml(head: str) -> str:
    import re

    if re.search(r"^\[cameras\.", head, re.M):
        return "caliscope"
    if re.search(r"^cam_id\s*=", head, re.M) and not re.search(r"^name\s*=", head, re.M):
        return "caliscope"  # Caliscope's older config.toml: [cam_N] tables with cam_id, no name
    return "toml"


def _camera_folders(path: Path) -> bool:
    return any((sub / "config.xml").is_file() for sub in path.iterdir() if sub.is_dir())


def detect_format(path: str | PathLike, for_writing: bool = False) -> str:
    """The format of ``path`` from its name (and, for reading, its content).

    Folders: ``intri.yml``/``extri.yml`` inside → opencv; ``cameras.txt``/``cameras.bin``
    inside → colmap; ``<camera>/config.xml`` sub-folders → opencv_camera. When writing a
    folder that does not exist yet, a name ending in ``colmap`` or ``sparse``… is ambiguous:
    pass the format explicitly instead.
    """
    path = Path(path)
    name = path.name.lower()
    if path.is_dir():
        if (path / "intri.yml").exists() or (path / "extri.yml").exists():
            return "opencv"
        if (path / "cameras.txt").exists() or (path / "cameras.bin").exists():
            return "colmap"
        if _camera_folders(path):
            return "opencv_camera"
        if for_writing:
            raise CalibrationError(
                "is a folder: say which format to write (opencv, opencv_camera or colmap)", file=path
            )
        raise CalibrationError(
            "folder holds neither intri.yml/extri.yml (OpenCV), cameras.txt/.bin (COLMAP) "
            "nor <camera>/config.xml sub-folders (per-camera OpenCV files)",
            file=path,
        )
    reading = not for_writing and path.is_file()
    head = _head(path) if reading else ""
    if name.endswith(".json"):
        if reading and '"format"' not in head and '"camera_poses"' in head or (
                reading and '"cameras"' in head and '"image_size"' in head and '"format"' not in head):
            return "multical"
        return "native"
    if name.endswith(".toml"):
        return _sniff_toml(head) if reading else "toml"
    if name.endswith((".yml", ".yaml")):
        return _sniff_yaml(head) if reading else "opencv"
    if name.endswith(".qca.txt") or name.endswith(".qca"):
        return "qualisys"
    if name.endswith(".xcp"):
        return "vicon"
    if name.endswith(".mcal"):
        return "optitrack"
    if name in ("cameras.txt", "cameras.bin", "images.txt", "images.bin"):
        return "colmap"
    if name.endswith(".xml"):
        if for_writing:
            raise CalibrationError("per-camera OpenCV files are written as a folder of <camera>/config.xml: "
                                   "give a folder name and the format opencv_camera", file=path)
        found = _sniff_xml(head)
        if found:
            return found
    elif reading:
        found = _sniff_xml(head)
        if found:
            return found
    raise CalibrationError(
        "cannot tell the calibration format from the name or content (expected .json, .toml, .yml, "
        ".xml, .xcp, .mcal, .qca.txt, or an OpenCV/COLMAP folder)",
        file=path,
    )


def _raw(path: Path, fmt: str) -> RigParts:
    if fmt == "opencv" and not path.is_dir():
        if path.name.lower().startswith("extri"):
            return reader(fmt)(path.with_name(path.name.replace("extri", "intri")), path)
        return reader(fmt)(path, path.with_name(path.name.replace("intri", "extri")))
    return reader(fmt)(path)  # a COLMAP file stands for its folder: read_colmap reads the folder


def read(path: str | PathLike, fmt: str | None = None, *, units: str | None = None,
         z_down: str | None = None) -> RigParts:
    """Read ``path`` as ``fmt`` (detected when None) → :class:`RigParts` in metres with world
    Z up and ``notes`` saying what was read and assumed (:func:`checks.settle`: ``units``
    overrides the detected units, ``z_down`` is ``"flip"``, ``"refuse"`` or ``"keep"``).
    :meth:`calibration.RigCalibration.load_any` makes the rig of them."""
    from calibration.formats.checks import settle

    path = Path(path)
    if not path.exists():
        raise CalibrationError("no such file or folder", file=path)
    fmt = fmt or detect_format(path)
    parts = _raw(path, fmt)
    try:
        settled = settle(parts, units=units, z_down=z_down, source=str(path))
    except CalibrationError as exc:
        raise exc.in_file(path) from None
    return settled._replace(notes=(f"format: {fmt}",) + settled.notes)


def read_pairs(pairs: dict, *, units: str | None = None, z_down: str | None = None) -> RigParts:
    """Per-camera OpenCV files given as ``{camera name: file}`` → settled :class:`RigParts`
    (as :func:`read`; camera names from the keys, in order)."""
    from calibration.formats.checks import settle
    from calibration.formats.opencv_camera import read_camera_pairs

    parts = read_camera_pairs({str(k): Path(v) for k, v in pairs.items()})
    first = str(next(iter(pairs.values())))
    try:
        settled = settle(parts, units=units, z_down=z_down, source=first)
    except CalibrationError as exc:
        raise exc.in_file(first) from None
    return settled._replace(notes=("format: opencv_camera",) + settled.notes)


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
