"""OptiTrack Motive calibration export ``.mcal`` (XML, usually UTF-16), read only.

::

    <calibrationProfile version="1"><Calibration><Cameras Count="13">
      <Camera Serial="M09472">
        <Properties Enabled="1" .../>
        <Attributes ImagerPixelWidth="1664" ImagerPixelHeight="1088" .../>
        <IntrinsicStandardCameraModel LensCenterX LensCenterY HorizontalFocalLength
            VerticalFocalLength k1 k2 k3 TangentialX TangentialY/>     # OpenCV-style model
        <Extrinsic X Y Z OrientMatrix0 .. OrientMatrix8/>

- ``X Y Z``: the camera's position in the world, **metres**; ``OrientMatrix0..8``: the
  camera-to-world rotation, row-major, for a camera looking along its **-Z** with Y up
  (OpenGL-like). OpenCV's ``R_cam_from_world = diag(1, -1, -1) · OrientMatrixᵀ``.
- Motive's world is **Y up**. It is turned to the toolkit's Z up on reading:
  ``(x, y, z) → (x, -z, y)`` (a quarter turn about X), noted.
- The standard model's ``k1 k2 k3`` and ``TangentialX TangentialY`` are taken as OpenCV's
  ``k1 k2 k3`` and ``p1 p2``; the ``<Intrinsic>`` element (Motive's internal model) is not used.
- Disabled cameras (``Properties Enabled="0"``) are skipped, with a note.

The older binary Motive ``.cal`` files have no published layout and are not read.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.formats import RigParts
from calibration.formats.text import attr_float as _float, child as _child
from calibration.ground import GroundPlane
from calibration.rotation import nearest_rotation

#: OpenCV camera axes from OptiTrack's (x right, y up, looking along -z).
FLIP = np.diag([1.0, -1.0, -1.0])
#: Motive's Y-up world → the toolkit's Z-up world: (x, y, z) → (x, -z, y).
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
#: Largest ``max |M Mᵀ - I|`` of ``OrientMatrix`` put down to rounding.
ROUNDING_TOL = 1e-4


def _camera(elem) -> Camera:
    name = elem.get("Serial")
    if not name:
        raise CalibrationError("<Camera> without Serial", field="Serial")
    attrs = _child(elem, "Attributes", name)
    w = _float(attrs, "ImagerPixelWidth", name, "Attributes")
    h = _float(attrs, "ImagerPixelHeight", name, "Attributes")
    intr = _child(elem, "IntrinsicStandardCameraModel", name)
    g = lambda a: _float(intr, a, name, "IntrinsicStandardCameraModel")  # noqa: E731
    K = np.array([[g("HorizontalFocalLength"), 0.0, g("LensCenterX")],
                  [0.0, g("VerticalFocalLength"), g("LensCenterY")], [0.0, 0.0, 1.0]])
    dist = [g("k1"), g("k2"), g("TangentialX"), g("TangentialY"), g("k3")]
    ext = _child(elem, "Extrinsic", name)
    centre = np.array([_float(ext, a, name, "Extrinsic") for a in "XYZ"])
    M = np.array([_float(ext, f"OrientMatrix{i}", name, "Extrinsic") for i in range(9)]).reshape(3, 3)
    M_rot, err = nearest_rotation(M)
    if err > ROUNDING_TOL or np.linalg.det(M) < 0:
        raise CalibrationError(f"OrientMatrix0..8 is not a rotation (max |M Mᵀ - I| = {err:.3g})",
                               camera=name, field="Extrinsic")
    R = FLIP @ M_rot.T @ Y_UP_TO_Z_UP.T  # world (Z up) → world (Y up) → OptiTrack camera → OpenCV camera
    return Camera(name, K, dist, R, -R @ (Y_UP_TO_Z_UP @ centre), (int(w), int(h)))


def _parse(path: Path):
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise CalibrationError(f"cannot read ({exc.strerror})", file=path) from None
    try:
        return ET.fromstring(data)
    except ET.ParseError:
        pass
    try:  # a declaration naming another encoding than the bytes' (UTF-16BE on a UTF-16LE file): parsed
        # as decoded text, whose declared encoding ElementTree then ignores
        text = data.decode("utf-16") if data[:2] in (b"\xff\xfe", b"\xfe\xff") else data.decode("utf-8")
        return ET.fromstring(text)
    except (UnicodeDecodeError, ET.ParseError) as exc:
        raise CalibrationError(f"not valid XML ({exc})", file=path) from None


def read_optitrack(path) -> RigParts:
    path = Path(path)
    root = _parse(path)
    cameras, disabled = {}, []
    try:
        for elem in root.iter("Camera"):
            props = elem.find("Properties")
            if props is not None and props.get("Enabled", "1") == "0":
                disabled.append(elem.get("Serial", "?"))
                continue
            cam = _camera(elem)
            if cam.name in cameras:
                raise CalibrationError("two <Camera> entries share this Serial", camera=cam.name, field="Serial")
            cameras[cam.name] = cam
        if not cameras:
            raise CalibrationError("no enabled <Camera> elements", field="Camera")
    except CalibrationError as exc:
        raise exc.in_file(path) from None
    notes = ["OptiTrack: Extrinsic X Y Z = camera position (m), OrientMatrix = camera-to-world rotation of a "
             "camera looking along -Z; R_cam_from_world = diag(1, -1, -1) OrientMatrixᵀ",
             "Motive's world is Y up: turned to Z up, (x, y, z) → (x, -z, y)",
             "distortion: IntrinsicStandardCameraModel k1 k2 k3, TangentialX/Y as OpenCV k1 k2 k3, p1 p2"]
    if disabled:
        notes.append(f"skipped disabled camera(s) {', '.join(disabled)}")
    return RigParts(cameras, GroundPlane.floor(), {"source": "optitrack"}, units="m", units_fixed=True,
                    notes=tuple(notes))
