"""Camera: projection, distortion against OpenCV, back-projection, validation."""

import cv2
import numpy as np

from calibration.rotation import matrix_to_rotvec, rotvec_to_matrix
import pytest

from calibration import CalibrationError, Camera
from calibration.camera import (
    distort_normalized,
    undistort_normalized,
)

K = np.array([[812.5, 0.0, 322.25], [0.0, 806.0, 241.75], [0.0, 0.0, 1.0]])
DISTS = {
    0: np.zeros(0),
    4: np.array([-0.21, 0.08, 0.0012, -0.0008]),
    5: np.array([-0.21, 0.08, 0.0012, -0.0008, -0.02]),
    8: np.array([0.12, -0.05, 0.001, 0.0015, 0.01, 0.3, -0.04, 0.02]),
    12: np.array([-0.2, 0.07, 0.001, -0.001, -0.01, 0.02, 0.01, -0.005, 0.002, -0.001, 0.001, 0.0005]),
    14: np.array(
        [-0.2, 0.07, 0.001, -0.001, -0.01, 0.02, 0.01, -0.005, 0.002, -0.001, 0.001, 0.0005, 0.01, -0.015]
    ),
}


def make_camera(n=5, name="cam0"):
    R = rotvec_to_matrix([0.3, -0.5, 0.2])
    return Camera(name, K, DISTS[n], R, np.array([0.1, -0.2, 3.5]), (640, 480))


def scene_points(rng, n=200):
    """Points in front of the camera spread over (roughly) the image."""
    cam = make_camera(0)
    uv = rng.uniform([0, 0], [639, 479], (n, 2))
    o, d = cam.pixel_rays(uv, distorted=False)
    return o + d * rng.uniform(1.0, 6.0, (n, 1))


@pytest.mark.parametrize("n", sorted(DISTS))
def test_project_matches_cv2_projectPoints(n):
    rng = np.random.default_rng(n)
    cam = make_camera(n)
    X = scene_points(rng)
    uv = cam.project(X)
    ref = cv2.projectPoints(X, cv2.Rodrigues(cam.R)[0], cam.t, K, DISTS[n])[0][:, 0]
    assert np.max(np.abs(uv - ref)) < 1e-9
    ideal = cv2.projectPoints(X, cv2.Rodrigues(cam.R)[0], cam.t, K, None)[0][:, 0]
    assert np.max(np.abs(cam.project(X, distort=False) - ideal)) < 1e-9
    h = np.c_[X, np.ones(len(X))] @ cam.P.T
    assert np.max(np.abs(h[:, :2] / h[:, 2:] - ideal)) < 1e-9


@pytest.mark.parametrize("n", [4, 5, 8, 12, 14])
def test_undistort_matches_cv2_undistortPoints(n):
    rng = np.random.default_rng(10 + n)
    cam = make_camera(n)
    uv = cam.project(scene_points(rng))
    ours = cam.undistort_pixels(uv)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-16)
    ref = cv2.undistortPoints(uv[:, None], K, DISTS[n], P=K, criteria=crit)[:, 0]
    assert np.max(np.abs(ours - ref)) < 1e-6
    # and ours is an exact inverse of the forward model
    assert np.max(np.abs(cam.distort_pixels(ours) - uv)) < 1e-9


def test_distort_normalized_identity_without_coefficients():
    xy = np.array([[0.1, -0.2], [0.3, 0.4]])
    assert np.array_equal(distort_normalized(xy, np.zeros(5)), xy)
    assert np.array_equal(undistort_normalized(xy, np.zeros(0)), xy)


@pytest.mark.parametrize("n", [0, 5, 14])
def test_backproject_round_trip(n):
    rng = np.random.default_rng(20 + n)
    cam = make_camera(n)
    X = scene_points(rng)
    uv = cam.project(X)
    o, d = cam.pixel_rays(uv)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(o, np.broadcast_to(cam.center, o.shape), atol=1e-12)
    # X lies on its ray: distance from X to the line o + s d
    v = X - o
    dist_to_ray = np.linalg.norm(v - (v * d).sum(1, keepdims=True) * d, axis=1)
    assert dist_to_ray.max() < 1e-9
    # and any other point on the ray projects back to the same pixel
    assert np.max(np.abs(cam.project(o + 2.5 * d) - uv)) < 1e-8


def test_center_and_to_camera():
    cam = make_camera()
    np.testing.assert_allclose(cam.to_camera(cam.center), [[0, 0, 0]], atol=1e-12)
    assert cam.to_camera(np.array([1.0, 2.0, 3.0])).shape == (1, 3)
    assert cam.width == 640 and cam.height == 480


def test_points_behind_camera_are_flagged():
    cam = make_camera()
    ahead = cam.center + 2.0 * cam.R[2]  # optical axis in world = third row of R
    behind = cam.center - 2.0 * cam.R[2]
    uv, depth, front = cam.project_points(np.stack([ahead, behind]))
    assert front.tolist() == [True, False]
    np.testing.assert_allclose(depth, [2.0, -2.0], atol=1e-12)
    assert np.all(np.isfinite(uv[0])) and np.all(np.isnan(uv[1]))
    # the principal ray hits the principal point
    np.testing.assert_allclose(uv[0], K[:2, 2], atol=1e-9)


def test_in_image_bounds():
    cam = make_camera()
    uv = np.array([[-0.5, -0.5], [639.49, 479.49], [639.5, 0], [0, -0.51], [np.nan, 3]])
    assert cam.in_image(uv).tolist() == [True, True, False, False, False]


def test_undistort_image_moves_features_to_ideal_positions():
    cam = make_camera(5).replace(size=(640, 480))
    img = np.zeros((480, 640), np.uint8)
    uv_ideal = np.array([[60.0, 50.0], [590.0, 440.0]])
    uv = cam.distort_pixels(uv_ideal)
    for u, v in np.round(uv).astype(int):
        img[v - 2 : v + 3, u - 2 : u + 3] = 255
    und = cam.undistort_image(img)
    for u, v in uv_ideal:
        ys, xs = np.nonzero(und[int(v) - 10 : int(v) + 11, int(u) - 10 : int(u) + 11] > 127)
        assert len(xs) > 0
        # blob centre within 1.5 px of the ideal position (the blob was drawn rounded)
        assert abs(xs.mean() + int(u) - 10 - u) < 1.5
        assert abs(ys.mean() + int(v) - 10 - v) < 1.5
    # distorted positions are far (> 4 px) from ideal ones here, so the test can fail
    assert np.min(np.linalg.norm(uv - uv_ideal, axis=1)) > 4
    mask = img > 0
    assert cam.undistort_image(mask).dtype == bool
    with pytest.raises(ValueError, match="image is 10x10"):
        cam.undistort_image(np.zeros((10, 10), np.uint8))


def test_rodrigues_round_trip_matches_cv2():
    rng = np.random.default_rng(3)
    for r in [np.zeros(3), [np.pi, 0, 0], [0, np.pi - 1e-9, 0], *rng.normal(0, 1.5, (20, 3))]:
        r = np.asarray(r, float)
        R = rotvec_to_matrix(r)
        np.testing.assert_allclose(R, cv2.Rodrigues(r)[0], atol=1e-12)
        np.testing.assert_allclose(rotvec_to_matrix(matrix_to_rotvec(R)), R, atol=1e-12)


def test_replace_and_allclose():
    cam = make_camera()
    moved = cam.replace(t=np.array([0.0, 0.0, 1.0]))
    assert not cam.allclose(moved)
    assert cam.allclose(cam.replace())
    assert cam.replace(dist=np.r_[cam.dist, 0, 0, 0]).allclose(cam)
    assert not cam.K.flags.writeable


@pytest.mark.parametrize(
    "change, field, message",
    [
        ({"K": np.eye(2)}, "K", r"expected shape \(3, 3\)"),
        ({"K": np.array([[800, 0, 320], [0, 800, 240], [0, 0, 2.0]])}, "K", r"\[0, 0, 1\]"),
        ({"K": np.array([[-800, 0, 320], [0, 800, 240], [0, 0, 1.0]])}, "K", "focal lengths must be at least 0.001"),
        ({"K": np.array([[1e-300, 0, 320], [0, 1e-300, 240], [0, 0, 1.0]])}, "K", r"got fx=1e-300, fy=1e-300"),
        ({"size": (True, True)}, "size", "expected two positive integers"),
        ({"t": ["1", "2", "3"]}, "t", "expected numbers, got <U1"),
        ({"K": np.array([[np.nan, 0, 320], [0, 800, 240], [0, 0, 1.0]])}, "K", "NaN"),
        ({"K": [["a", 0, 0]] * 3}, "K", "expected numbers"),
        ({"dist": np.zeros(6)}, "dist", "coefficients, got 6"),
        ({"dist": ["x"]}, "dist", "not numeric"),
        ({"R": np.eye(3) * 1.01}, "R", "not orthonormal"),
        ({"R": np.diag([1.0, 1.0, -1.0])}, "R", "determinant"),
        ({"R": np.eye(4)}, "R", "shape"),
        ({"t": np.array([0.0, np.inf, 0.0])}, "t", "NaN or infinite"),
        ({"t": np.zeros(4)}, "t", "shape"),
        ({"size": (640,)}, "size", "width, height"),
        ({"size": (640, 0)}, "size", "positive integers"),
        ({"size": (640.5, 480)}, "size", "positive integers"),
    ],
)
def test_invalid_camera_names_camera_and_field(change, field, message):
    with pytest.raises(CalibrationError, match=rf"camera 'cam0': field '{field}': .*{message}"):
        make_camera().replace(**change)


def test_invalid_name():
    with pytest.raises(CalibrationError, match="field 'name'"):
        make_camera().replace(name="")


def test_column_vector_translation_accepted():
    cam = make_camera().replace(t=np.array([[0.1], [-0.2], [3.5]]))
    assert cam.t.shape == (3,)


def test_bad_point_shapes():
    cam = make_camera()
    with pytest.raises(ValueError, match=r"X: expected shape \(N, 3\)"):
        cam.project(np.zeros((4, 2)))
    with pytest.raises(ValueError, match=r"uv: expected shape \(N, 2\)"):
        cam.pixel_rays(np.zeros((4, 3)))


def test_look_at_points_the_optical_axis_at_the_target():
    cam = Camera.look_at("c", [3.0, -2.0, 2.0], [0.0, 0.5, 1.0], 500.0, (640, 480))
    uv = cam.project(np.array([[0.0, 0.5, 1.0]]))
    np.testing.assert_allclose(uv[0], [319.5, 239.5], atol=1e-9)
    np.testing.assert_allclose(cam.center, [3.0, -2.0, 2.0], atol=1e-12)
    # world up projects upwards in the image (smaller v)
    above = cam.project(np.array([[0.0, 0.5, 1.5]]))[0]
    assert above[1] < 239.5 - 50 and abs(above[0] - 319.5) < 1e-6


def test_look_at_straight_down_is_refused():
    with pytest.raises(CalibrationError, match="camera 'top'.*target.*vertical"):
        Camera.look_at("top", [0.0, 0.0, 3.0], [0.0, 0.0, 0.0], 500.0, (640, 480))


def test_project_near_equals_project_in_view_and_drops_far_points():
    cam = Camera.look_at("c", [3.0, 0.0, 1.5], [0.0, 0.0, 1.0], 400.0, (320, 240),
                         dist=[-0.3, 0.1, 0.0, 0.0, 0.0])
    near = np.array([[0.0, 0.0, 1.0], [0.1, 0.2, 1.2]])
    np.testing.assert_allclose(cam.project_near(near), cam.project(near), atol=1e-12)
    far_off = np.array([[0.0, 40.0, 1.0], [6.0, 0.0, 1.0]])  # far outside the frame; behind
    assert np.isnan(cam.project_near(far_off)).all()
