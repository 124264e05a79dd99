"""Pose2Sim / anipose ``Calib.toml``: one table per camera plus ``[metadata]``.

Per camera::

    [cam01]
    name = "cam01"
    size = [ 1088, 1920 ]                 # width, height
    matrix = [ [fx, 0, cx], [0, fy, cy], [0, 0, 1] ]
    distortions = [ k1, k2, p1, p2 ]      # OpenCV order, any OpenCV length
    rotation = [ rx, ry, rz ]             # Rodrigues, world -> camera
    translation = [ tx, ty, tz ]          # X_c = R X_w + t; Pose2Sim: metres, anipose: the
                                          # board's unit (often mm), FreeMoCap: mm
    fisheye = false

``fisheye = true`` (anipose / Pose2Sim) marks a ``cv2.fisheye`` camera: ``distortions`` is
then ``[k1, k2, k3, k4]`` and the camera is read with ``model="fisheye"``; a missing
``fisheye`` key means pinhole, as in both tools.

The ground plane, which the format lacks, is kept in ``[metadata]`` as
``studio_ground = { normal = [...], offset = ... }`` (default floor z = 0 when absent).
"""

from __future__ import annotations

import tomllib
from os import PathLike
from pathlib import Path

import numpy as np
import tomli_w

from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.formats import RigParts
from calibration.formats.text import read_document
from rigs.atomic import atomic_write_text
from calibration.ground import GroundPlane

GROUND_KEY = "studio_ground"
REQUIRED = ("size", "matrix", "distortions", "rotation", "translation")


def _camera_from_table(key: str, item: dict) -> Camera:
    if not isinstance(item, dict):
        raise CalibrationError(f"expected a table, got {type(item).__name__}", camera=key)
    name = str(item.get("name", key))
    for field in REQUIRED:
        if field not in item:
            raise CalibrationError("missing", camera=name, field=field)
    fisheye = item.get("fisheye", False)
    if not isinstance(fisheye, bool):
        raise CalibrationError(
            f"expected true or false, got {fisheye!r}", camera=name, field="fisheye"
        )
    model = "fisheye" if fisheye else "pinhole"
    try:
        rvec = np.array(item["rotation"], dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"not numeric ({exc})", camera=name, field="rotation") from None
    if rvec.shape == (9,):  # some writers store the matrix
        R = rvec.reshape(3, 3)
        return Camera(
            name, item["matrix"], item["distortions"], R, item["translation"], _size(item, name), model
        )
    if rvec.shape != (3,):
        raise CalibrationError(
            f"expected a Rodrigues vector of 3 values, got {rvec.size}", camera=name, field="rotation"
        )
    return Camera.from_rvec(
        name, item["matrix"], item["distortions"], rvec, item["translation"], _size(item, name), model
    )


def _size(item: dict, name: str) -> tuple:
    size = item["size"]
    if not isinstance(size, (list, tuple)) or len(size) != 2:
        raise CalibrationError(f"expected [width, height], got {size!r}", camera=name, field="size")
    return tuple(size)


def _units(meta: dict) -> tuple[str, tuple[str, ...]]:
    """The usual unit of the file's translations: FreeMoCap (``[metadata] charuco_square_size``,
    entered in millimetres in its GUI) → mm; Pose2Sim → m. anipose writes the board's unit,
    which the file does not say: magnitudes decide (:mod:`calibration.formats.checks`)."""
    if "charuco_square_size" in meta:
        return "mm", (f"FreeMoCap file (charuco_square_size = {meta['charuco_square_size']!r}, entered in mm)",)
    return "m", ("Pose2Sim writes metres; anipose writes the board's unit (not stated in the file)",)


def read_toml(path: str | PathLike):
    path = Path(path)
    doc = read_document(path, tomllib.loads, "TOML", (tomllib.TOMLDecodeError,))
    meta = dict(doc.get("metadata", {}))
    try:
        cameras = {}
        for key, item in doc.items():
            if key == "metadata":
                continue
            cam = _camera_from_table(key, item)
            if cam.name in cameras:
                raise CalibrationError("camera name used twice", camera=cam.name, field="name")
            cameras[cam.name] = cam
        if not cameras:
            raise CalibrationError("no camera tables", field="cameras")
        g = meta.pop(GROUND_KEY, None)
        units, notes = _units(meta)
        if g is None:
            ground = GroundPlane.floor()
        elif not isinstance(g, dict) or "normal" not in g or "offset" not in g:
            raise CalibrationError("expected {normal, offset}", field=f"metadata.{GROUND_KEY}")
        else:
            ground = GroundPlane(g["normal"], g["offset"])
        return RigParts(cameras, ground, meta, units=units, units_fixed=False, own_frame=g is not None,
                        notes=notes)
    except CalibrationError as exc:
        raise exc.in_file(path) from None


def camera_table(name: str, cam) -> dict:
    """A camera as the anipose-style table (also Caliscope's): name, size, matrix,
    distortions, rotation (Rodrigues), translation, fisheye."""
    return {
        "name": name,
        "size": [int(cam.width), int(cam.height)],
        "matrix": cam.K.tolist(),
        "distortions": cam.dist.tolist(),
        "rotation": cam.rvec.tolist(),
        "translation": cam.t.tolist(),
        "fisheye": cam.model == "fisheye",
    }


def rig_to_toml_doc(rig) -> dict:
    doc: dict = {name: camera_table(name, cam) for name, cam in rig.cameras.items()}
    meta = {"adjusted": False, "error": 0.0}
    meta.update(rig.metadata)
    meta[GROUND_KEY] = rig.ground.to_dict()
    doc["metadata"] = meta
    return doc


def _value(v) -> str:
    """One TOML value on one line (Pose2Sim's layout): numbers, strings, bools, lists."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, str):
        return tomli_w.dumps({"x": v})[4:].strip()
    if isinstance(v, (list, tuple)):
        return "[ " + ", ".join(_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} as a TOML value")


def write_toml(rig, path: str | PathLike) -> Path:
    if "metadata" in rig.cameras:
        raise CalibrationError(
            "a camera named 'metadata' clashes with the [metadata] table", file=path, camera="metadata"
        )
    doc = rig_to_toml_doc(rig)
    meta = doc.pop("metadata")
    lines = []
    for name, table in doc.items():
        lines.append(tomli_w.dumps({name: {}}).strip())  # [name], quoted when needed
        lines.extend(f"{key} = {_value(value)}" for key, value in table.items())
        lines.append("")
    try:
        lines.append(tomli_w.dumps({"metadata": meta}))
    except TypeError as exc:
        raise CalibrationError(
            f"metadata cannot be written as TOML ({exc})", file=path, field="metadata"
        ) from None
    return atomic_write_text(path, "\n".join(lines), mkdir=True)
