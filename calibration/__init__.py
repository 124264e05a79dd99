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

# Calibrating from images (after the core: these modules build on it).
from calibration.boards import Board, load_board, shipped_boards
from calibration.bundle import BundleParameterization, BundleResult, bundle_adjust
from calibration.detect import Detection, detect_board, detect_files
from calibration.extrinsics import ExtrinsicsResult, calibrate_extrinsics, initial_rig, view_graph
from calibration.floor import FloorResult, calibrate_floor, floor_check, transform_cameras
from calibration.intrinsics import (
    IntrinsicsResult,
    calibrate_intrinsics,
    coverage_advice,
    coverage_map,
)
from calibration.report import render_report, write_report
from calibration.sampling import SampledViews, iter_video_frames, sample_views, sharpness
from calibration.board_quad import corners_from_outer, find_quads
from calibration.halfturn import align_to_rig, is_half_turn_symmetric, resolve_half_turns
from calibration.rigchecks import camera_heights, scale_check

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
    "Board",
    "load_board",
    "shipped_boards",
    "Detection",
    "detect_board",
    "detect_files",
    "IntrinsicsResult",
    "calibrate_intrinsics",
    "coverage_map",
    "coverage_advice",
    "ExtrinsicsResult",
    "calibrate_extrinsics",
    "initial_rig",
    "view_graph",
    "BundleResult",
    "BundleParameterization",
    "bundle_adjust",
    "FloorResult",
    "calibrate_floor",
    "floor_check",
    "transform_cameras",
    "SampledViews",
    "sample_views",
    "iter_video_frames",
    "sharpness",
    "render_report",
    "write_report",
    "find_quads",
    "corners_from_outer",
    "is_half_turn_symmetric",
    "resolve_half_turns",
    "align_to_rig",
    "scale_check",
    "camera_heights",
]
