"""Kalibr ``camchain.yaml`` (``kalibr_calibrate_cameras`` / ``kalibr_calibrate_imu_camera`` output).

Per camera ``cam0``, ``cam1``, ... (plain YAML)::

    camera_model: pinhole            # omni, ds, eucm: refused (no OpenCV equivalent)
    intrinsics: [fu, fv, pu, pv]
    distortion_model: radtan         # radtan → OpenCV k1 k2 p1 p2; equidistant → cv2.fisheye
    distortion_coeffs: [k1, k2, p1, p2]
    resolution: [width, height]
    T_cn_cnm1: 4x4                   # cam n-1 → cam n: X_cn = T X_cn-1 (absent for cam0)
    T_cam_imu: 4x4                   # IMU → camera (imu-camera calibrations; not used)

The world is ``cam0``'s frame, the chain's base (Kalibr's ``ConfigReader``: ``T_camN =
T_cN_cN-1 ... T_c1_c0``). Metres (Kalibr sizes its targets in metres). A ``%YAML:1.0`` first
line (added by OpenVINS for ``cv::FileStorage``) is skipped. This writer adds ``T_cam_world``
to ``cam0`` (ignored by Kalibr) so that the toolkit's world frame survives a round trip.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.formats import RigParts
from calibration.formats.text import read_document
from calibration.ground import GroundPlane
from calibration.rotation import nearest_rotation
from rigs.atomic import atomic_write_text

DISTORTIONS = {"radtan": "pinhole", "equidistant": "fisheye", "none": "pinhole"}
WORLD_KEY = "T_cam_world"
#: Largest ``max |R Rᵀ - I|`` of a transform's rotation put down to rounding.
ROUNDING_TOL = 1e-4


def _yaml(text: str):
    return yaml.safe_load("\n".join(ln for ln in text.splitlines() if not ln.startswith("%YAML")))


def _load(path: Path) -> dict:
    doc = read_document(path, _yaml, "YAML", (yaml.YAMLError,))
    if not isinstance(doc, dict):
        raise CalibrationError("expected a mapping of cam0, cam1, ...", file=path)
    return doc


def _transform(value, name: str, key: str) -> tuple[np.ndarray, np.ndarray]:
    try:
        T = np.array(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"not numeric ({exc})", camera=name, field=key) from None
    if T.shape != (4, 4) or not np.all(np.isfinite(T)) or not np.allclose(T[3], [0, 0, 0, 1]):
        raise CalibrationError(f"expected a finite 4x4 transform with last row [0, 0, 0, 1], got shape {T.shape}",
                               camera=name, field=key)
    R, err = nearest_rotation(T[:3, :3])
    if err > ROUNDING_TOL or np.linalg.det(T[:3, :3]) < 0:
        raise CalibrationError(f"rotation part is not a rotation (max |R Rᵀ - I| = {err:.3g})", camera=name, field=key)
    return (R if err > 1e-6 else T[:3, :3]), T[:3, 3]


def _camera(name: str, item: dict, R, t) -> Camera:
    if not isinstance(item, dict):
        raise CalibrationError(f"expected a mapping, got {type(item).__name__}", camera=name)
    for key in ("intrinsics", "resolution"):
        if key not in item:
            raise CalibrationError("missing", camera=name, field=key)
    model = item.get("camera_model", "pinhole")
    if model != "pinhole":
        raise CalibrationError(f"camera model {model!r} has no OpenCV equivalent: expected 'pinhole'",
                               camera=name, field="camera_model")
    dmodel = item.get("distortion_model", "none")
    if dmodel not in DISTORTIONS:
        raise CalibrationError(f"expected one of {', '.join(DISTORTIONS)}, got {dmodel!r}", camera=name,
                               field="distortion_model")
    intr = item["intrinsics"]
    if not isinstance(intr, list) or len(intr) != 4:
        raise CalibrationError(f"expected [fu, fv, pu, pv], got {intr!r}", camera=name, field="intrinsics")
    fu, fv, pu, pv = intr
    K = [[fu, 0.0, pu], [0.0, fv, pv], [0.0, 0.0, 1.0]]
    dist = item.get("distortion_coeffs", []) if dmodel != "none" else []
    res = item["resolution"]
    if not isinstance(res, list) or len(res) != 2:
        raise CalibrationError(f"expected [width, height], got {res!r}", camera=name, field="resolution")
    try:
        return Camera(name, K, dist, R, t, tuple(res), DISTORTIONS[dmodel])
    except CalibrationError as exc:
        field = {"K": "intrinsics", "dist": "distortion_coeffs", "size": "resolution"}.get(exc.field, exc.field)
        raise CalibrationError(exc.detail, camera=name, field=field) from None


def read_kalibr(path) -> RigParts:
    path = Path(path)
    doc = _load(path)
    names = sorted((k for k in doc if isinstance(k, str) and k.startswith("cam") and k[3:].isdigit()),
                   key=lambda k: int(k[3:]))
    if not names:
        raise CalibrationError("no cam0, cam1, ... entries", file=path, field="cam0")
    if names != [f"cam{i}" for i in range(len(names))]:
        raise CalibrationError(f"expected cam0..cam{len(names) - 1} in a chain, got {', '.join(names)}", file=path)
    cameras, own = {}, False
    try:
        R, t = np.eye(3), np.zeros(3)
        first = doc["cam0"] if isinstance(doc["cam0"], dict) else {}
        if WORLD_KEY in first:
            R, t = _transform(first[WORLD_KEY], "cam0", WORLD_KEY)
            own = True
        for i, name in enumerate(names):
            item = doc[name]
            if i > 0:
                if not isinstance(item, dict) or "T_cn_cnm1" not in item:
                    raise CalibrationError("missing: every camera after cam0 needs its T_cn_cnm1", camera=name,
                                           field="T_cn_cnm1")
                Rn, tn = _transform(item["T_cn_cnm1"], name, "T_cn_cnm1")
                R, t = Rn @ R, Rn @ t + tn
            cameras[name] = _camera(name, item, R, t)
    except CalibrationError as exc:
        raise exc.in_file(path) from None
    notes = ("Kalibr: the world is cam0's frame (the chain's base); cameras composed along T_cn_cnm1",) if not own else ()
    return RigParts(cameras, GroundPlane.floor(), {"source": "kalibr"}, units="m", units_fixed=True,
                    own_frame=own, notes=notes)


def _matrix(R, t) -> list:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T.tolist()


def write_kalibr(rig, path) -> Path:
    """Write a camchain: cameras named ``cam0..`` in rig order (Kalibr needs those names; the
    rig's names go into ``rostopic``), each chained to the previous one."""
    path = Path(path)
    doc, prev = {}, None
    for i, (name, cam) in enumerate(rig.cameras.items()):
        item = {
            "camera_model": "pinhole",
            "intrinsics": [float(cam.K[0, 0]), float(cam.K[1, 1]), float(cam.K[0, 2]), float(cam.K[1, 2])],
            "distortion_model": "equidistant" if cam.model == "fisheye" else "radtan",
            "distortion_coeffs": cam.dist.tolist() if cam.model == "fisheye" else _radtan(cam, path),
            "resolution": [int(cam.width), int(cam.height)],
            "rostopic": f"/{name}/image_raw",
        }
        if prev is None:
            item[WORLD_KEY] = _matrix(cam.R, cam.t)
        else:
            R = cam.R @ prev.R.T
            item["T_cn_cnm1"] = _matrix(R, cam.t - R @ prev.t)
        doc[f"cam{i}"] = item
        prev = cam
    return atomic_write_text(path, yaml.safe_dump(doc, sort_keys=False), mkdir=True)


def _radtan(cam, path) -> list:
    d = np.zeros(4)
    d[: min(4, cam.dist.size)] = cam.dist[:4]
    if cam.dist.size > 4 and np.any(cam.dist[4:]):
        raise CalibrationError("Kalibr's radtan model holds k1 k2 p1 p2 only: k3 and beyond are not zero",
                               file=path, camera=cam.name, field="dist")
    return d.tolist()
