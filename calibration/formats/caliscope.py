"""Caliscope ``camera_array.toml`` (and the camera tables of its older ``config.toml``).

Current layout (Caliscope's ``persistence.save_camera_array``)::

    [cameras.0]                      # the camera's port (an integer)
    port = 0
    size = [1280, 720]               # width, height
    matrix = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]
    distortions = [k1, k2, p1, p2, k3]   # OpenCV order; k1..k4 with fisheye = true
    rotation = [rx, ry, rz]          # Rodrigues, world -> camera (3x3 matrices in legacy files)
    translation = [tx, ty, tz]       # metres (Caliscope sizes its boards in metres)
    fisheye = false
    error = 0.37, grid_count, exposure, rotation_count, ignore, verified_resolutions

The older single ``config.toml`` holds the same fields in ``[cam_N]`` tables (with ``cam_id``)
next to unrelated tables (``[charuco]``, ``CreationDate``): only ``cam_*`` tables are read.
Rotation and translation map world to camera (Caliscope's ``capture_volume`` takes the camera
centre as ``-Rᵀ t``). Cameras are named by port (or by a ``name`` key, which this module
writes). Cameras marked ``ignore = true`` or lacking ``matrix``/``rotation``/
``translation`` (not calibrated yet) are skipped, with a note.
"""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import tomli_w

from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.formats import RigParts
from calibration.formats.text import read_document
from calibration.formats.toml_calib import camera_table
from calibration.ground import GroundPlane
from calibration.rotation import nearest_rotation
from rigs.atomic import atomic_write_text

NEEDED = ("matrix", "distortions", "rotation", "translation", "size")
#: Largest ``max |R Rᵀ - I|`` of a legacy 3x3 rotation put down to rounding.
ROUNDING_TOL = 1e-4


def _tables(doc: dict, path: Path) -> dict[str, dict]:
    """``{port: table}`` of the current ``[cameras.N]`` or the legacy ``[cam_N]`` layout."""
    if isinstance(doc.get("cameras"), dict):
        return {str(k): v for k, v in doc["cameras"].items()}
    legacy = {k[4:]: v for k, v in doc.items() if k.startswith("cam_") and isinstance(v, dict)}
    if not legacy:
        raise CalibrationError("no [cameras.N] or [cam_N] tables", file=path, field="cameras")
    return legacy


def _rotation(value, name: str) -> np.ndarray:
    try:
        r = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"not numeric ({exc})", camera=name, field="rotation") from None
    if r.shape in ((3,), (3, 1)):
        from calibration.rotation import rotvec_to_matrix

        return rotvec_to_matrix(r.reshape(3))
    if r.shape != (3, 3):
        raise CalibrationError(f"expected a Rodrigues vector [3] or a 3x3 matrix, got shape {r.shape}",
                               camera=name, field="rotation")
    R, err = nearest_rotation(r)
    if err > ROUNDING_TOL or not np.all(np.isfinite(r)):
        return r  # Camera refuses it, naming the field
    return R if err > 1e-6 else r


def read_caliscope(path) -> RigParts:
    path = Path(path)
    doc = read_document(path, tomllib.loads, "TOML", (tomllib.TOMLDecodeError,))
    cameras, skipped, turned = {}, [], []
    try:
        for port, table in _tables(doc, path).items():
            if not isinstance(table, dict):
                raise CalibrationError(f"expected a table, got {type(table).__name__}", camera=port)
            if table.get("ignore", False) or any(table.get(k) is None for k in NEEDED):
                skipped.append(port)
                continue
            fisheye = table.get("fisheye", False)
            if not isinstance(fisheye, bool):
                raise CalibrationError(f"expected true or false, got {fisheye!r}", camera=port, field="fisheye")
            size = table["size"]
            if not isinstance(size, list) or len(size) != 2:
                raise CalibrationError(f"expected [width, height], got {size!r}", camera=port, field="size")
            name = str(table.get("name", port))
            if name in cameras:
                raise CalibrationError("camera name used twice", camera=name, field="name")
            R = _rotation(table["rotation"], name)
            cameras[name] = Camera(name, table["matrix"], table["distortions"], R, table["translation"],
                                   tuple(size), "fisheye" if fisheye else "pinhole")
            if table.get("rotation_count", 0):
                turned.append(f"{port} ({table['rotation_count']:+d})")
        if not cameras:
            raise CalibrationError("no calibrated camera (every table is ignored or lacks matrix/rotation/"
                                   "translation)", field="cameras")
    except CalibrationError as exc:
        raise exc.in_file(path) from None
    notes = ["Caliscope: rotation and translation map world to camera; metres (boards sized in metres)"]
    if skipped:
        notes.append(f"skipped camera(s) {', '.join(skipped)}: ignore = true or not calibrated")
    if turned:
        notes.append(f"warning: rotation_count set for camera(s) {', '.join(turned)}: Caliscope turns those "
                     "cameras' frames by quarter turns before use; give the calibration frames turned the same way")
    meta = {"source": "caliscope", "skipped": skipped} if skipped else {"source": "caliscope"}
    return RigParts(cameras, GroundPlane.floor(), meta, units="m", units_fixed=False, notes=tuple(notes))


def write_caliscope(rig, path) -> Path:
    """Write the current ``camera_array.toml`` layout. Caliscope names cameras by integer
    port: camera names that are integers are kept, other rigs are numbered in rig order
    (the names are kept in a ``name`` key that Caliscope ignores and this reader prefers)."""
    path = Path(path)
    numeric = all(n.isdigit() for n in rig.camera_names)
    tables = {}
    for i, (name, cam) in enumerate(rig.cameras.items()):
        port = int(name) if numeric else i
        tables[str(port)] = {"port": port, **camera_table(name, cam), "rotation_count": 0, "ignore": False}
    return atomic_write_text(path, tomli_w.dumps({"cameras": tables}), mkdir=True)
