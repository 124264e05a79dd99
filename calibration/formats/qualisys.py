"""Qualisys QTM calibration export (``*.qca.txt``, XML), read only.

Per ``<camera serial=...>``:

- ``<intrinsic>`` focal lengths and principal point in **1/64 pixel** units of the
  sensor (``focalLengthU/64`` = fx in sensor pixels); scaled to the video field of view
  ``<fov_video>`` (left/right/top/bottom, inclusive) when it differs from the sensor
  (``sensorMinU..sensorMaxU``, also 1/64 px). Distortion ``radialDistortion1..3``,
  ``tangentalDistortion1..2`` → OpenCV ``k1 k2 p1 p2 k3``.
- ``<transform>``: ``x y z`` is the camera centre in **millimetres**; the matrix
  ``r11..r33`` has the camera axes as rows with the camera looking along its −z and y up
  (OpenGL-like). OpenCV's ``R_cam_from_world = diag(1, -1, -1) · r`` (a half turn about the
  camera x axis, as Pose2Sim's ``calib_qca_fun``), ``t = -R · centre / 1000``.
  Checked on Pose2Sim's Demo_SinglePerson: camera centres agree with Pose2Sim's own scene
  calibration to ≤ 15 cm and orientations to ≤ 3° (focal lengths to ≤ 1 %).
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import numpy as np

from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.formats import RigParts
from calibration.formats.text import attr_float as _float, child as _child, parse_xml
from calibration.ground import GroundPlane

FLIP = np.diag([1.0, -1.0, -1.0])


def _camera(elem) -> Camera:
    name = elem.get("serial") or elem.get("id")
    if not name:
        raise CalibrationError("camera without a serial", field="serial")
    fov = _child(elem, "fov_video", name)
    left, right = _float(fov, "left", name, "fov_video"), _float(fov, "right", name, "fov_video")
    top, bottom = _float(fov, "top", name, "fov_video"), _float(fov, "bottom", name, "fov_video")
    width, height = int(right - left + 1), int(bottom - top + 1)
    intr = _child(elem, "intrinsic", name)
    g = lambda a: _float(intr, a, name, "intrinsic")  # noqa: E731
    sensor_w = (g("sensorMaxU") - g("sensorMinU")) / 64.0 + 1.0
    sensor_h = (g("sensorMaxV") - g("sensorMinV")) / 64.0 + 1.0
    su, sv = width / sensor_w, height / sensor_h
    fx, fy = g("focalLengthU") / 64.0 * su, g("focalLengthV") / 64.0 * sv
    cx = (g("centerPointU") / 64.0 - left) * su
    cy = (g("centerPointV") / 64.0 - top) * sv
    skew = float(intr.get("skew", 0.0))
    K = np.array([[fx, skew, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    dist = np.array(
        [
            g("radialDistortion1"),
            g("radialDistortion2"),
            g("tangentalDistortion1"),
            g("tangentalDistortion2"),
            float(intr.get("radialDistortion3", 0.0)),
        ]
    )
    tr = _child(elem, "transform", name)
    r = np.array([[_float(tr, f"r{i}{j}", name, "transform") for j in (1, 2, 3)] for i in (1, 2, 3)])
    centre = np.array([_float(tr, a, name, "transform") for a in "xyz"]) / 1000.0
    R = FLIP @ r
    return Camera(name, K, dist, R, -R @ centre, (width, height))


def read_qualisys(path: str | PathLike):
    path = Path(path)
    root = parse_xml(path, "Qualisys XML")
    try:
        cameras = {}
        residuals = {}
        entry = {}
        for k, elem in enumerate(root.iter("camera")):
            if elem.get("active", "1") == "0":
                continue
            cam = _camera(elem)
            if cam.name in cameras:
                raise CalibrationError(f"<camera> entries {entry[cam.name]} and {k} share serial {cam.name!r}: "
                                       "expected one entry per camera", field="serial")
            cameras[cam.name] = cam
            entry[cam.name] = k
            if elem.get("avg-residual") is not None:
                residuals[cam.name] = float(elem.get("avg-residual"))
        if not cameras:
            raise CalibrationError("no active <camera> elements", field="cameras")
    except CalibrationError as exc:
        raise exc.in_file(path) from None
    meta = {"source": "qualisys", "avg_residual": residuals}
    return RigParts(cameras, GroundPlane.floor(), meta, units="m", units_fixed=True,
                    notes=("Qualisys camera centres are in mm by the format: converted to metres on reading",))
