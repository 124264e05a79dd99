"""multical ``calibration.json`` (oliver-batchelor/multical, ``FORMAT.md`` and ``io/export_calib.py``).

::

    {"cameras": {"cam1": {"model": "standard", "image_size": [w, h],
                          "K": 3x3, "dist": [[k1, k2, p1, p2, k3, ...]]}, ...},
     "camera_poses": {"cam1": {"R": 3x3, "T": [3]},            # absolute: world -> cam1
                      "cam2_to_cam1": {"R": 3x3, "T": [3]}}}    # relative: cam1 -> cam2

An absolute entry ``cam`` maps world points into the camera (``X_c = R X_w + T``); a relative
entry ``a_to_b`` maps points of camera ``b``'s frame into camera ``a``'s (``X_a = R X_b + T``;
multical writes them relative to its master camera, whose own entry is the identity), so
``a`` is posed by composing onto ``b``. ``model`` (standard, rational, thin_prism, tilted)
only names how many OpenCV coefficients ``dist`` holds. Units are the board's, which
multical's board files give in metres. ``image_sets`` and other keys are ignored.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.formats import RigParts
from calibration.formats.text import read_document
from calibration.ground import GroundPlane
from calibration.rotation import nearest_rotation
from rigs.atomic import atomic_write_text

#: Largest ``max |R Rᵀ - I|`` of a pose's rotation put down to rounding (re-orthonormalised).
ROUNDING_TOL = 1e-4


def _load(path: Path) -> dict:
    doc = read_document(path, json.loads, "JSON", (json.JSONDecodeError,))
    if not isinstance(doc, dict) or not isinstance(doc.get("cameras"), dict) or not doc["cameras"]:
        raise CalibrationError("expected an object with a non-empty 'cameras' table", file=path, field="cameras")
    return doc


def _pose(entry, key: str, rounded: list) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(entry, dict) or "R" not in entry or "T" not in entry:
        raise CalibrationError("expected {R: 3x3, T: [3]}", field=f"camera_poses.{key}")
    try:
        R = np.array(entry["R"], dtype=np.float64)
        T = np.array(entry["T"], dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"not numeric ({exc})", field=f"camera_poses.{key}") from None
    if R.shape != (3, 3) or T.shape != (3,) or not (np.all(np.isfinite(R)) and np.all(np.isfinite(T))):
        raise CalibrationError(f"expected finite R 3x3 and T [3], got shapes {R.shape} and {T.shape}",
                               field=f"camera_poses.{key}")
    nearest, err = nearest_rotation(R)
    if err > ROUNDING_TOL or np.linalg.det(R) < 0:
        raise CalibrationError(f"R is not a rotation (max |R Rᵀ - I| = {err:.3g} > {ROUNDING_TOL:g})",
                               field=f"camera_poses.{key}.R")
    if err > 1e-6:
        rounded.append(key)
        R = nearest
    return R, T


def _poses(doc: dict, names: list[str], rounded: list) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    table = doc.get("camera_poses")
    if table is None:
        return {}
    if not isinstance(table, dict):
        raise CalibrationError("expected an object", field="camera_poses")
    known, links = {}, []
    for key, entry in table.items():
        R, T = _pose(entry, key, rounded)
        if "_to_" in key:
            a, b = key.split("_to_", 1)
            for n in (a, b):
                if n not in names:
                    raise CalibrationError(f"names camera {n!r}, which 'cameras' does not hold", field=f"camera_poses.{key}")
            links.append((a, b, R, T))
        else:
            if key not in names:
                raise CalibrationError(f"camera {key!r} is not in 'cameras'", field=f"camera_poses.{key}")
            known[key] = (R, T)
    changed = True
    while changed:  # X_a = R X_b + T: pose a from pose b (or b from a)
        changed = False
        for a, b, R, T in links:
            if b in known and a not in known:
                Rb, tb = known[b]
                known[a] = (R @ Rb, R @ tb + T)
                changed = True
            elif a in known and b not in known:
                Ra, ta = known[a]
                known[b] = (R.T @ Ra, R.T @ (ta - T))
                changed = True
    return known


def read_multical(path) -> RigParts:
    path = Path(path)
    doc = _load(path)
    names = [str(n) for n in doc["cameras"]]
    rounded: list = []
    try:
        poses = _poses(doc, names, rounded)
        missing = [n for n in names if n not in poses]
        if poses and missing:
            raise CalibrationError(f"no pose reaches camera(s) {', '.join(missing)}: expected an absolute entry "
                                   "or a chain of <a>_to_<b> entries", field="camera_poses")
        cameras = {}
        for name in names:
            item = doc["cameras"][name]
            if not isinstance(item, dict):
                raise CalibrationError(f"expected an object, got {type(item).__name__}", camera=name)
            for key in ("K", "dist", "image_size"):
                if key not in item:
                    raise CalibrationError("missing", camera=name, field=key)
            R, t = poses.get(name, (np.eye(3), np.zeros(3)))
            size = item["image_size"]
            if not isinstance(size, list) or len(size) != 2:
                raise CalibrationError(f"expected [width, height], got {size!r}", camera=name, field="image_size")
            try:
                cameras[name] = Camera(name, item["K"], np.ravel(np.asarray(item["dist"], dtype=object)).tolist(),
                                       R, t, tuple(size))
            except CalibrationError as exc:
                raise CalibrationError(exc.detail, camera=name,
                                       field={"size": "image_size"}.get(exc.field, exc.field)) from None
    except CalibrationError as exc:
        raise exc.in_file(path) from None
    notes = ["multical: poses map world (or the named camera) to camera"]
    if not poses:
        notes.append("no camera_poses: intrinsics only, every camera at R = I, t = 0")
    if rounded:
        notes.append(f"pose rotations of {', '.join(rounded)} re-orthonormalised (written with few decimals)")
    return RigParts(cameras, GroundPlane.floor(), {"source": "multical"}, units="m", units_fixed=False,
                    notes=tuple(notes))


def write_multical(rig, path) -> Path:
    """Write ``cameras`` and absolute ``camera_poses`` (one world -> camera entry per camera)."""
    path = Path(path)
    models = {8: "rational", 12: "thin_prism", 14: "tilted"}  # 4 or 5 coefficients: "standard"
    doc = {"cameras": {}, "camera_poses": {}}
    for name, cam in rig.cameras.items():
        if cam.model != "pinhole":
            raise CalibrationError("multical has no fisheye model", file=path, camera=name, field="model")
        if "_to_" in name:
            raise CalibrationError("'_to_' in a camera name reads as a relative pose in multical",
                                   file=path, camera=name, field="name")
        dist = cam.dist if cam.dist.size else np.zeros(5)
        doc["cameras"][name] = {"model": models.get(dist.size, "standard"), "image_size": [cam.width, cam.height],
                                "K": cam.K.tolist(), "dist": [dist.tolist()]}
        doc["camera_poses"][name] = {"R": cam.R.tolist(), "T": cam.t.tolist()}
    return atomic_write_text(path, json.dumps(doc, indent=2) + "\n", mkdir=True)
