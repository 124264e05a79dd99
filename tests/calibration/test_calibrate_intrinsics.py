"""Boards, detection and intrinsics: real OpenCV / Pose2Sim data against published references."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration.boards import Board, load_board, shipped_boards
from calibration.detect import Detection, detect_board, detect_files, read_image, to_gray
from calibration.errors import CalibrationError
from calibration.intrinsics import calibrate_intrinsics, coverage_advice, coverage_map
from calibration.synthetic import camera_ring, default_board, observe

# Published references (see each data folder's SOURCE.md)
OPENCV_LEFT_FX = 535.91573396163199  # left_intrinsics.yml, fx = fy
CHARUCO_REF = dict(fx=452.51072219637672, fy=456.76707935146891)
QUALISYS_FX = {"cam01": 1681.2, "cam02": 1673.7, "cam03": 1681.6, "cam04": 1675.2}
QUALISYS_C = {"cam01": (533.0, 948.1), "cam02": (534.5, 963.2), "cam03": (513.2, 955.0), "cam04": (540.1, 964.0)}


# ------------------------------------------------------------------ boards
def test_shipped_boards_load_with_geometry():
    assert {"opencv_chessboard_9x6", "opencv_charuco_5x7", "pose2sim_checker_4x7"} <= set(shipped_boards())
    b = load_board("opencv_chessboard_9x6")
    assert b.corner_grid == (9, 6) and b.n_corners == 54
    pts = b.object_points
    assert pts.shape == (54, 3)
    assert np.allclose(pts[1] - pts[0], [0.025, 0, 0]) and np.allclose(pts[9] - pts[0], [0, 0.025, 0])
    c = load_board("opencv_charuco_5x7")
    assert c.corner_grid == (4, 6) and c.n_corners == 24
    # our corner ids / positions agree with OpenCV's ChArUco board
    assert np.allclose(c.cv_board.getChessboardCorners(), c.object_points)


def test_board_round_trip_and_errors(tmp_path):
    b = load_board("studio_charuco_a1")
    assert Board.from_dict(b.to_dict()) == b
    with pytest.raises(CalibrationError, match="not found"):
        load_board("no_such_board")
    with pytest.raises(CalibrationError, match="kind must be one of"):
        Board("x", "circles", 4, 4, 0.1)
    with pytest.raises(CalibrationError, match="at least 2x2"):
        Board("x", "checkerboard", 1, 4, 0.1)
    with pytest.raises(CalibrationError, match="square_size must be > 0"):
        Board("x", "checkerboard", 4, 4, 0.0)
    with pytest.raises(CalibrationError, match="marker_size must be in"):
        Board("x", "charuco", 5, 7, 0.04, 0.05, "DICT_6X6_250")
    with pytest.raises(CalibrationError, match="unknown ArUco dictionary"):
        Board("x", "charuco", 5, 7, 0.04, 0.02, "DICT_NOPE")
    with pytest.raises(CalibrationError, match="board field 'square_size' is missing"):
        Board.from_dict({"kind": "checkerboard", "inner_corners": [4, 5]})
    with pytest.raises(CalibrationError, match="must be two integers"):
        Board.from_dict({"kind": "checkerboard", "inner_corners": "ab", "square_size": 0.1})
    with pytest.raises(CalibrationError, match="must hold a mapping"):
        Board.from_dict([1, 2])
    with pytest.raises(CalibrationError, match="has no ArUco board"):
        load_board("opencv_chessboard_9x6").cv_board


# ------------------------------------------------------------------ detection
def test_detection_rules_and_errors(shared_data):
    img = read_image(shared_data / "calibration/opencv_charuco_5x7/img_00.jpg")
    board = load_board("opencv_charuco_5x7")
    det = detect_board(img, board, view="img_00")
    assert det.status == "ok" and det.n == 24
    # partial: cover the left 45 % of the board area -> fewer corners but kept
    part = img.copy()
    xs = det.image_points[:, 0]
    part[:, : int(np.percentile(xs, 45))] = 128
    pdet = detect_board(part, board, view="part")
    assert pdet.status == "partial" and 6 <= pdet.n < 24 and "corners" in pdet.reason
    # wrong board: never detected, the reason says so
    other = detect_board(img, load_board("studio_charuco_a1"), view="x")
    assert other.status == "rejected" and "no ChArUco corners" in other.reason
    blank = detect_board(np.full((200, 300), 127, np.uint8), load_board("opencv_chessboard_9x6"), view="blank")
    assert blank.status == "rejected" and "not found" in blank.reason
    with pytest.raises(CalibrationError, match="uint8 or uint16"):
        to_gray(np.zeros((4, 4), np.float32))
    with pytest.raises(CalibrationError, match=r"\(H, W\) or \(H, W, 3\)"):
        to_gray(np.zeros((4, 4, 2), np.uint8))
    with pytest.raises(CalibrationError, match="cannot read this image"):
        read_image(shared_data / "calibration/opencv_charuco_5x7/SOURCE.md")
    assert to_gray(np.full((2, 2), 65535, np.uint16)).max() == 255


def test_collinear_corners_rejected():
    board = load_board("opencv_charuco_5x7")
    # a tiny ChArUco detection reduced to one row of corners is degenerate
    from calibration.detect import _spread_rank

    assert not _spread_rank(np.c_[np.arange(6.0), 2 * np.arange(6.0)], tol=1.0)
    assert _spread_rank(board.object_points[:, :2] * 1000, tol=1.0)


# ------------------------------------------------------------------ intrinsics on real data
def test_opencv_left_chessboard_matches_reference(shared_data):
    """fx within 0.5 % of OpenCV's published left_intrinsics.yml (535.9); RMS below its 0.39 px."""
    folder = shared_data / "calibration/opencv_chessboard_9x6"
    dets = detect_files(sorted(folder.glob("left*.jpg")), load_board("opencv_chessboard_9x6"))
    res = calibrate_intrinsics(dets, camera="left", fix_aspect_ratio=True)
    assert len(res.view_errors) == 13 and not res.rejected
    assert abs(res.fx / OPENCV_LEFT_FX - 1) < 0.005
    assert res.fx == pytest.approx(res.fy)
    assert abs(res.cx - 342.28) < 3 and abs(res.cy - 235.57) < 3
    assert res.rms < 0.39
    assert res.coverage.sum() == 13 * 54
    cam = res.to_camera()
    assert cam.size == (640, 480) and cam.K[0, 0] == res.fx


def test_opencv_charuco_tutorial_matches_reference(shared_data):
    """Only 4 views: K within 2 % of tutorial_camera_charuco.yml, RMS < 0.3 px."""
    folder = shared_data / "calibration/opencv_charuco_5x7"
    dets = detect_files(sorted(folder.glob("img_*.jpg")), load_board("opencv_charuco_5x7"))
    assert [d.n for d in dets] == [24] * 4
    res = calibrate_intrinsics(dets, camera="tutorial")
    assert abs(res.fx / CHARUCO_REF["fx"] - 1) < 0.02
    assert abs(res.fy / CHARUCO_REF["fy"] - 1) < 0.02
    assert res.rms < 0.3


def test_pose2sim_four_cameras_match_qualisys(shared_data):
    """Focal lengths within 1 % of the independent Qualisys calibration; failed photos reported."""
    board = load_board("pose2sim_checker_4x7")
    root = shared_data / "calibration/pose2sim_demo_4cam/intrinsics"
    rejected_any = False
    for cam, fx_ref in QUALISYS_FX.items():
        dets = detect_files(sorted((root / f"int_{cam}_img").glob("*.jpg")), board, max_side=800)
        res = calibrate_intrinsics(dets, camera=cam)
        assert abs(res.fx / fx_ref - 1) < 0.01, (cam, res.fx)
        assert abs(res.fy / fx_ref - 1) < 0.01, (cam, res.fy)
        assert np.hypot(res.cx - QUALISYS_C[cam][0], res.cy - QUALISYS_C[cam][1]) < 50
        assert res.rms < 0.5 and len(res.view_errors) >= 5
        rejected_any |= bool(res.rejected)
        for view, reason in res.rejected.items():
            assert view.startswith(cam) and reason
    assert rejected_any  # some photo fails detection or is an outlier, and says why


# ------------------------------------------------------------------ intrinsics on synthetic data / bad input
def _synthetic_views(n, rng, tilt=True, dist=(-0.12, 0.05, 0.0005, -0.0003, 0.0)):
    board = default_board()
    cam = camera_ring(1, radius=1.2, height=1.0, size=(1280, 800), focal=900.0, dist=dist)["cam00"]
    from calibration.synthetic import random_board_poses

    poses = {}
    for view, (R, t) in random_board_poses(4 * n, board, rng, centre=(0.0, 0.0, 1.0), spread=(0.15, 0.15, 0.1),
                                           max_tilt_deg=35.0 if tilt else 0.0).items():
        poses[view] = (R, t)
    if not tilt:  # every board parallel to the image plane
        R_face = cam.R.T @ np.diag([1.0, 1.0, 1.0])
        poses = {v: (R_face, t + 0 * R[:, 0]) for v, (R, t) in poses.items()}
    obs = observe({"cam00": cam}, board, poses, rng, noise_px=0.2)["cam00"]
    return cam, list(obs.values())[:n]


def test_synthetic_intrinsics_recover_truth_and_reject_outlier():
    rng = np.random.default_rng(3)
    cam, dets = _synthetic_views(15, rng)
    assert len(dets) == 15
    bad = dets[0]
    dets[0] = Detection(bad.view, bad.ids, bad.image_points + rng.normal(0, 4.0, bad.image_points.shape),
                        bad.object_points, bad.image_size)
    res = calibrate_intrinsics(dets, camera="cam00")
    assert bad.view in res.rejected and "outlier view" in res.rejected[bad.view]
    assert abs(res.fx - cam.K[0, 0]) < 0.01 * cam.K[0, 0]
    assert res.rms < 0.4


def test_fisheye_model_runs_on_pinhole_data(shared_data):
    folder = shared_data / "calibration/opencv_chessboard_9x6"
    dets = detect_files(sorted(folder.glob("left*.jpg")), load_board("opencv_chessboard_9x6"))
    res = calibrate_intrinsics(dets, camera="left", model="fisheye")
    assert res.model == "fisheye" and res.dist.shape == (4,)
    assert abs(res.fx / OPENCV_LEFT_FX - 1) < 0.03 and res.rms < 0.6
    # the fitted model becomes a fisheye Camera that reproduces cv2.fisheye's view errors
    cam = res.to_camera()
    assert cam.model == "fisheye" and np.array_equal(cam.dist, res.dist)
    det = next(d for d in dets if d.view in res.board_poses)
    rvec, tvec = res.board_poses[det.view]
    uv = cam.replace(R=cv2.Rodrigues(rvec)[0], t=tvec).project(det.object_points)
    rms = np.sqrt(np.mean(np.sum((uv - det.image_points) ** 2, axis=1)))
    assert rms == pytest.approx(res.view_errors[det.view], abs=1e-9)


def test_intrinsics_bad_input_names_camera_and_next_capture():
    rng = np.random.default_rng(5)
    cam, dets = _synthetic_views(6, rng)
    with pytest.raises(CalibrationError, match="camera 'c1': only 2 usable views.*capture 1 more"):
        calibrate_intrinsics(dets[:2], camera="c1")
    never = [Detection.rejected(f"f{i}", (640, 480), "checkerboard 9x6 not found") for i in range(3)]
    with pytest.raises(CalibrationError, match="camera 'c2': the board was never detected in 3 views"):
        calibrate_intrinsics(never, camera="c2")
    _, flat = _synthetic_views(6, rng, tilt=False, dist=(0.0, 0.0, 0.0, 0.0, 0.0))
    with pytest.raises(CalibrationError, match=r"camera 'c3': all \d+ views show the board in parallel planes \(max angle 0\.\d deg"):
        calibrate_intrinsics(flat, camera="c3")
    with pytest.raises(CalibrationError, match="model must be"):
        calibrate_intrinsics(dets, camera="c4", model="orthographic")
    with pytest.raises(CalibrationError, match="camera 'c6': focal length is poorly constrained"):
        calibrate_intrinsics(dets[:4], camera="c6", max_focal_std=1e-5)
    mixed = [dets[0], Detection.rejected("x", (10, 10), "no")]
    with pytest.raises(CalibrationError, match="different image sizes"):
        calibrate_intrinsics(mixed, camera="c5")


def test_coverage_map_and_advice():
    d = Detection("v", np.arange(3), np.array([[10.0, 10.0], [630.0, 10.0], [10.0, 470.0]]),
                  np.zeros((3, 3)), (640, 480))
    cov = coverage_map([d], (640, 480), grid=(4, 3))
    assert cov.shape == (3, 4) and cov.sum() == 3
    assert cov[0, 0] == 1 and cov[0, 3] == 1 and cov[2, 0] == 1
    advice = coverage_advice(cov)
    assert "no corners" in advice and "centre" in advice
    assert coverage_advice(np.ones((3, 4), int)) == ""


def test_focal_only_from_one_floor_view_and_fixed_centre():
    """One tilted view of a board on the floor constrains one focal length (principal point at the
    centre, no distortion): 490 px recovered within 1 % from 0.2 px corner noise."""
    from calibration.synthetic import camera_ring, floor_board_pose, observe

    board = Board("floor8x6", "checkerboard", 8, 6, 0.115)
    cams = camera_ring(2, radius=3.0, height=1.5, target=(0.4, 0.3, 0.0), size=(644, 486), focal=490.0,
                       dist=(0, 0, 0, 0, 0), principal_offset=(0, 0))
    obs = observe(cams, board, {"floor": floor_board_pose(board)}, np.random.default_rng(3), noise_px=0.2, max_view_angle_deg=85)
    det = obs["cam00"]["floor"]
    res = calibrate_intrinsics([det], camera="cam00", focal_only=True)
    assert res.fx == pytest.approx(490.0, rel=0.01) and res.fx == res.fy
    assert (res.cx, res.cy) == (321.5, 242.5) and np.all(res.dist == 0)
    with pytest.raises(CalibrationError, match="only 1 usable views"):
        calibrate_intrinsics([det], camera="cam00")
