"""Small oblique checkerboards: the board's quadrilateral path and the user's four corners.

A rendered 8x6 board (115 mm squares) lying on the floor 4 m in front of a 644x486 camera 1.4 m
high, as in the Utrecht recording: OpenCV's detectors miss it, the robust path finds it to
~0.16 px (mean, against the rendered truth; tolerance 0.3 px), and four outer corners clicked
1.5 px off give the grid to ~0.22 px (tolerance 0.35 px).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibration import Camera
from calibration.board_quad import corners_from_outer, find_quads, load_outer_corners
from calibration.boards import Board
from calibration.detect import detect_board, to_gray
from calibration.errors import CalibrationError
from calibration.synthetic import floor_board_pose, render_board_view

BOARD = Board("floor8x6", "checkerboard", 8, 6, 0.115)


@pytest.fixture(scope="module")
def far_board():
    K = np.array([[490.0, 0, 321.5], [0, 490.0, 242.5], [0, 0, 1.0]])
    cam = Camera.look_at("c", np.array([4.0, -1.0, 1.4]), np.array([0.4, 0.3, 0.0]), K, (644, 486), np.zeros(5))
    pose = floor_board_pose(BOARD, (0.0, 0.0), 0.3)
    image = render_board_view(cam, BOARD, pose, blur_sigma=1.0, rng=np.random.default_rng(0), background=70)
    truth = cam.project(BOARD.object_points @ pose[0].T + pose[1])
    return image, truth


def mean_error(points, truth):
    """Mean corner error (px), either numbering (the board is symmetric under a half turn)."""
    return min(np.linalg.norm(p - truth, axis=1).mean() for p in (points, points[::-1]))


def test_opencv_misses_the_far_board_the_quadrilateral_finds_it(far_board):
    image, truth = far_board
    assert not detect_board(image, BOARD).usable
    quads = find_quads(to_gray(image), BOARD)
    assert len(quads) == 1 and np.all(np.abs(quads[0].mean(0) - truth.mean(0)) < 15)
    det = detect_board(image, BOARD, robust=True)
    assert det.usable and det.extra["method"] == "quad"
    assert mean_error(det.image_points, truth) < 0.3
    assert not detect_board(np.full((486, 644), 70, np.uint8), BOARD, robust=True).usable


def test_four_user_corners_give_the_grid_and_corner_zero(far_board):
    image, truth = far_board
    outer = truth[[0, 7, 47, 40]] + np.random.default_rng(1).normal(0, 1.5, (4, 2))
    det = detect_board(image, BOARD, outer_corners=outer)
    assert det.extra["method"] == "user"
    assert np.linalg.norm(det.image_points - truth, axis=1).mean() < 0.35  # numbered as the user said: no flip
    turned = detect_board(image, BOARD, outer_corners=outer[[2, 3, 0, 1]])
    assert np.linalg.norm(turned.image_points[::-1] - truth, axis=1).mean() < 0.35
    with pytest.raises(CalibrationError, match="enclose no area"):
        corners_from_outer(to_gray(image), np.array([[0, 0], [10, 0], [20, 0], [30, 0]]), BOARD)
    with pytest.raises(CalibrationError, match=r"4 \(x, y\) pixel pairs"):
        corners_from_outer(to_gray(image), np.zeros((3, 2)), BOARD)


def test_corners_file_errors(tmp_path):
    good = tmp_path / "c.json"
    good.write_text(json.dumps({"cam1": [[1, 2], [3, 4], [5, 6], [7, 9]]}))
    assert load_outer_corners(good)["cam1"].shape == (4, 2)
    bad = tmp_path / "bad.json"
    cases = [("{", "not valid JSON"), ("[]", "expected an object"), ('{"cam1": [[1, 2]]}', "camera 'cam1': expected four")]
    for text, message in cases:
        bad.write_text(text)
        with pytest.raises(CalibrationError, match=message):
            load_outer_corners(bad)
    with pytest.raises(CalibrationError, match="cannot read the outer-corners file"):
        load_outer_corners(tmp_path / "none.json")
