"""Vicon camera calibration ``.xcp`` (Nexus / Tracker / Shogun XML), read only.

::

    <Cameras VERSION="2.0" SOURCE="Nexus ...">
      <Camera DEVICEID="2109510" USERID="1" SENSOR_SIZE="4096 4096" PIXEL_ASPECT_RATIO="1" ...>
        <KeyFrames>
          <KeyFrame FOCAL_LENGTH="3962.3" PRINCIPAL_POINT="2076.2 2043.3"
                    ORIENTATION="qx qy qz qw" POSITION="x y z"
                    VICON_RADIAL2="Vicon3Parameter cx cy k1 k2 k3" WORLD_ERROR=... IMAGE_ERROR=.../>

- Cameras are named by ``DEVICEID``; image size ``SENSOR_SIZE`` (the full sensor);
  ``fx = FOCAL_LENGTH``, ``fy = FOCAL_LENGTH / PIXEL_ASPECT_RATIO`` (as Pose2Sim reads them).
- ``POSITION`` is the camera centre in **millimetres** (lab floor frame, Z up);
  ``ORIENTATION`` a quaternion ``x y z w`` whose matrix is ``R_cam_from_world`` (what
  Pose2Sim's ``calib_vicon_fun`` composes to); ``t = -R · centre``.
- ``VICON_RADIAL2`` is Vicon's radial model in *pixel* units about its own centre (``cx cy``):
  taken as the correction of observed pixels, ``u_ideal = c + (u - c)(1 + k1 r² + k2 r⁴ +
  k3 r⁶)`` with ``r = |u - c|`` in pixels. OpenCV's model runs the other way in normalised
  coordinates, so OpenCV ``k1 k2 k3`` are fitted (least squares over the radii of the circle
  inscribed in the sensor: beyond it, in the corners, several real files' polynomials fold
  back) and the fit's largest error in pixels is noted (≤ 1.7 px on a real 25-camera file). (Older files: ``VICON_RADIAL="k1 k2"`` about the
  principal point.) The distortion centre must lie within ``CENTRE_TOL_PX`` of the principal
  point (OpenCV has one centre for both), else the file is refused.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.formats import RigParts
from calibration.formats.text import attr_float as _float, parse_xml
from calibration.ground import GroundPlane
from calibration.rotation import quaternion_to_matrix

#: Largest distance (px) between Vicon's distortion centre and the principal point accepted.
CENTRE_TOL_PX = 2.0


def _numbers(elem, attr: str, cam: str, count: int) -> list[float]:
    raw = elem.get(attr)
    if raw is None:
        raise CalibrationError("missing", camera=cam, field=attr)
    return _parse(raw, attr, cam, count)


def _parse(raw: str, attr: str, cam: str, count: int) -> list[float]:
    try:
        values = [float(v) for v in raw.split()]
    except ValueError:
        raise CalibrationError(f"expected {count} numbers, got {raw!r}", camera=cam, field=attr) from None
    if len(values) != count or not np.all(np.isfinite(values)):
        raise CalibrationError(f"expected {count} finite numbers, got {raw!r}", camera=cam, field=attr)
    return values


def opencv_from_vicon_radial(k_px, f: float, r_max: float) -> tuple[np.ndarray, float]:
    """OpenCV ``k1 k2 k3`` (normalised) fitted to Vicon's pixel-unit correction
    ``r_ideal = r (1 + k1 r² + k2 r⁴ + k3 r⁶)`` over ``r`` in ``[0, r_max]`` px, and the
    fit's largest error in pixels.

    >>> k, err = opencv_from_vicon_radial([0.0, 0.0, 0.0], 1000.0, 800.0)
    >>> np.allclose(k, 0.0), err < 1e-9
    (True, True)
    """
    k1, k2, k3 = (float(v) for v in k_px)
    r_d = np.linspace(1.0, r_max, 400)
    r_u = r_d * (1 + k1 * r_d**2 + k2 * r_d**4 + k3 * r_d**6)
    rho = r_u / f
    A = np.stack([rho**2, rho**4, rho**6], axis=1)
    K, *_ = np.linalg.lstsq(A, r_d / r_u - 1.0, rcond=None)
    fitted = r_u * (1 + A @ K)
    return K, float(np.max(np.abs(fitted - r_d)))


def _camera(elem) -> tuple[Camera, float]:
    name = elem.get("DEVICEID") or elem.get("USERID")
    if not name:
        raise CalibrationError("<Camera> without DEVICEID", field="DEVICEID")
    kf = elem.find("KeyFrames/KeyFrame")
    if kf is None:
        raise CalibrationError("missing", camera=name, field="KeyFrames/KeyFrame")
    w, h = _numbers(elem, "SENSOR_SIZE", name, 2)
    aspect = _float(elem, "PIXEL_ASPECT_RATIO", name, "Camera") if elem.get("PIXEL_ASPECT_RATIO") else 1.0
    f = _float(kf, "FOCAL_LENGTH", name, "KeyFrame")
    cx, cy = _numbers(kf, "PRINCIPAL_POINT", name, 2)
    K = np.array([[f, 0.0, cx], [0.0, f / aspect, cy], [0.0, 0.0, 1.0]])
    if kf.get("VICON_RADIAL2") is not None:
        parts = kf.get("VICON_RADIAL2").split()
        if not parts or parts[0] != "Vicon3Parameter" or len(parts) != 6:
            raise CalibrationError(f"expected 'Vicon3Parameter cx cy k1 k2 k3', got {kf.get('VICON_RADIAL2')!r}",
                                   camera=name, field="VICON_RADIAL2")
        dcx, dcy, *k_px = _parse(" ".join(parts[1:]), "VICON_RADIAL2", name, 5)
    elif kf.get("VICON_RADIAL") is not None:
        (dcx, dcy), k_px = (cx, cy), _numbers(kf, "VICON_RADIAL", name, 2) + [0.0]
    else:
        (dcx, dcy), k_px = (cx, cy), [0.0, 0.0, 0.0]
    if np.hypot(dcx - cx, dcy - cy) > CENTRE_TOL_PX:
        raise CalibrationError(f"distortion centre ({dcx:.1f}, {dcy:.1f}) is {np.hypot(dcx - cx, dcy - cy):.1f} px "
                               f"from the principal point: OpenCV needs them within {CENTRE_TOL_PX:g} px",
                               camera=name, field="VICON_RADIAL2")
    r_max = float(min(cx, w - cx, cy, h - cy))  # the inscribed circle: Vicon's polynomials run wild in the corners
    if r_max <= 1.0:
        raise CalibrationError(f"principal point ({cx:g}, {cy:g}) outside the {w:g}x{h:g} sensor", camera=name,
                               field="PRINCIPAL_POINT")
    (K1, K2, K3), err = opencv_from_vicon_radial(k_px, f, r_max)
    qx, qy, qz, qw = _numbers(kf, "ORIENTATION", name, 4)
    try:
        R = quaternion_to_matrix([qx, qy, qz, qw], scalar_first=False)
    except ValueError as exc:
        raise CalibrationError(str(exc), camera=name, field="ORIENTATION") from None
    centre = np.array(_numbers(kf, "POSITION", name, 3))
    cam = Camera(name, K, [K1, K2, 0.0, 0.0, K3], R, -R @ centre, (int(w), int(h)))
    return cam, err


def read_vicon(path) -> RigParts:
    path = Path(path)
    root = parse_xml(path)
    cameras, worst, errors = {}, 0.0, {}
    try:
        for elem in root.iter("Camera"):
            cam, err = _camera(elem)
            if cam.name in cameras:
                raise CalibrationError("two <Camera> entries share this DEVICEID", camera=cam.name, field="DEVICEID")
            cameras[cam.name] = cam
            worst = max(worst, err)
            kf = elem.find("KeyFrames/KeyFrame")
            if kf.get("WORLD_ERROR") is not None:
                errors[cam.name] = float(kf.get("WORLD_ERROR"))
        if not cameras:
            raise CalibrationError("no <Camera> elements", field="Camera")
    except CalibrationError as exc:
        raise exc.in_file(path) from None
    notes = ("Vicon: POSITION = camera centre in mm, ORIENTATION = quaternion (x y z w) of R_cam_from_world",
             f"Vicon radial distortion (pixel units, taken as the correction of observed pixels) refitted as OpenCV "
             f"k1 k2 k3: largest error {worst:.3g} px within the circle inscribed in the sensor",
             "image size = SENSOR_SIZE (the full sensor): a cropped video needs its principal point shifted")
    return RigParts(cameras, GroundPlane.floor(), {"source": "vicon", "world_error": errors}, units="mm",
                    units_fixed=True, notes=notes)
