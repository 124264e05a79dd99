"""Geometry: cameras, lenses, the floor, boards, bundle adjustment and calibration file formats.

Conventions (DESIGN.md): metres, world Z up, floor z = 0 unless the ground plane says
otherwise; OpenCV cameras with ``X_c = R X_w + t``, pixel (0, 0) the centre of the
top-left pixel.
"""

from calibration.camera import Camera, distort_normalized, undistort_normalized
from calibration.errors import CalibrationError
from calibration.ground import (
    FloorGrid,
    GroundPlane,
    apply_homography,
    camera_plane_homography,
    floor_view,
    plane_homography,
)
from calibration.rig import RigCalibration

__all__ = [
    "Camera",
    "CalibrationError",
    "GroundPlane",
    "RigCalibration",
    "plane_homography",
    "camera_plane_homography",
    "apply_homography",
    "floor_view",
    "FloorGrid",
    "distort_normalized",
    "undistort_normalized",
]
