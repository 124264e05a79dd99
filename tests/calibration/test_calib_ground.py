"""Ground plane: ray intersection, plane homographies between views, floor views."""

import cv2
import numpy as np
import pytest

from calibration import (
    CalibrationError,
    Camera,
    FloorGrid,
    GroundPlane,
    apply_homography,
    camera_plane_homography,
    floor_view,
    plane_homography,
)


def look_at(name, eye, target, size=(320, 240), f=300.0, dist=(-0.15, 0.05, 0.001, -0.002, 0.0)):
    """A camera at ``eye`` looking at ``target`` with world z up."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    K = np.array([[f, 0, size[0] / 2 - 0.5], [0, f * 1.01, size[1] / 2 - 0.5], [0, 0, 1]])
    return Camera(name, K, np.asarray(dist, float), R, -R @ eye, size)


CAM_A = look_at("a", [3.0, -2.0, 2.5], [0.2, 0.1, 0.0])
CAM_B = look_at("b", [-2.5, -2.5, 2.0], [0.0, 0.3, 0.0])
TILTED = GroundPlane.from_point_normal([0.0, 0.0, 0.05], [0.05, -0.03, 1.0])


def floor_points(rng, n=100, plane=GroundPlane.floor()):
    ab = rng.uniform(-1.0, 1.0, (n, 2))
    return plane.from_plane_coords(ab)


def test_floor_defaults_and_basis():
    g = GroundPlane.floor()
    o, e1, e2 = g.basis()
    np.testing.assert_array_equal(o, 0)
    np.testing.assert_array_equal(e1, [1, 0, 0])
    np.testing.assert_array_equal(e2, [0, 1, 0])
    o, e1, e2 = TILTED.basis()
    np.testing.assert_allclose(np.cross(e1, e2), TILTED.normal, atol=1e-12)
    np.testing.assert_allclose([e1 @ e2, e1 @ e1, e2 @ e2], [0, 1, 1], atol=1e-12)
    assert abs(TILTED.signed_distance(o)[0]) < 1e-12


def test_signed_distance_and_projection():
    g = GroundPlane([0.0, 0.0, 1.0], 0.5)
    np.testing.assert_allclose(g.signed_distance(np.array([[0, 0, 2.0], [1, 1, 0.0]])), [1.5, -0.5])
    np.testing.assert_allclose(g.project_onto(np.array([3.0, 4.0, 9.0])), [[3, 4, 0.5]])


@pytest.mark.parametrize("plane", [GroundPlane.floor(), TILTED], ids=["floor", "tilted"])
def test_pixel_to_ground_recovers_floor_points(plane):
    rng = np.random.default_rng(1)
    X = floor_points(rng, plane=plane)
    uv = CAM_A.project(X)
    back = plane.pixel_to_ground(CAM_A, uv)
    assert np.max(np.abs(back - X)) < 1e-9
    back_ideal = plane.pixel_to_ground(CAM_A, CAM_A.project(X, distort=False), distorted=False)
    assert np.max(np.abs(back_ideal - X)) < 1e-9


def test_rays_missing_the_plane_are_invalid():
    g = GroundPlane.floor()
    o = np.array([[0, 0, 1.0], [0, 0, 1.0], [0, 0, 1.0]])
    d = np.array([[0, 0, -1.0], [0, 0, 1.0], [1.0, 0, 0]])  # hit, points away, parallel
    pts, valid = g.intersect_rays(o, d)
    assert valid.tolist() == [True, False, False]
    np.testing.assert_allclose(pts[0], [0, 0, 0])
    assert np.all(np.isnan(pts[1:]))
    # a pixel above the horizon of a level camera never meets the floor
    level = look_at("level", [0, 0, 1.0], [5.0, 0, 1.0], dist=())
    hits = g.pixel_to_ground(level, np.array([[160.0, 10.0], [160.0, 230.0]]))
    assert np.all(np.isnan(hits[0])) and np.all(np.isfinite(hits[1]))


@pytest.mark.parametrize("plane", [GroundPlane.floor(), TILTED], ids=["floor", "tilted"])
def test_plane_homography_maps_known_floor_points(plane):
    rng = np.random.default_rng(2)
    X = floor_points(rng, plane=plane)
    H = plane_homography(CAM_A, CAM_B, plane)
    uv_a = CAM_A.project(X, distort=False)
    uv_b = CAM_B.project(X, distort=False)
    assert np.max(np.abs(apply_homography(H, uv_a) - uv_b)) < 1e-8
    # raw pixels: undistort, warp, distort
    raw_b = CAM_B.distort_pixels(apply_homography(H, CAM_A.undistort_pixels(CAM_A.project(X))))
    assert np.max(np.abs(raw_b - CAM_B.project(X))) < 1e-8
    # points off the plane do NOT map consistently (the test can fail)
    up = X + 0.3 * plane.normal
    err = np.abs(apply_homography(H, CAM_A.project(up, distort=False)) - CAM_B.project(up, distort=False))
    assert err.max() > 5.0
    # plane coordinates -> pixels
    Hc = camera_plane_homography(CAM_A, plane)
    ab = plane.to_plane_coords(X)
    assert np.max(np.abs(apply_homography(Hc, ab) - uv_a)) < 1e-8


def test_plane_homography_matches_cv2_findHomography():
    rng = np.random.default_rng(5)
    X = floor_points(rng, 50)
    ua, ub = CAM_A.project(X, distort=False), CAM_B.project(X, distort=False)
    Href, _ = cv2.findHomography(ua, ub, 0)
    H = plane_homography(CAM_A, CAM_B, GroundPlane.floor())
    np.testing.assert_allclose(H / H[2, 2], Href / Href[2, 2], rtol=1e-5, atol=1e-9)


def test_ground_plane_validation():
    with pytest.raises(CalibrationError, match="field 'ground.normal': normal must have unit"):
        GroundPlane([0.0, 0.0, 2.0], 0.0)
    with pytest.raises(CalibrationError, match="field 'ground.normal': expected a finite"):
        GroundPlane([0.0, np.nan, 1.0], 0.0)
    with pytest.raises(CalibrationError, match="field 'ground.normal': expected a finite"):
        GroundPlane([0.0, 1.0], 0.0)
    with pytest.raises(CalibrationError, match="field 'ground.offset'"):
        GroundPlane([0.0, 0.0, 1.0], float("nan"))
    with pytest.raises(CalibrationError, match="field 'ground': not numeric"):
        GroundPlane(["x", 0, 1], 0.0)


def test_floor_grid_geometry():
    grid = FloorGrid((-1.0, 2.0), (0.0, 1.0), 0.1)
    assert grid.shape == (10, 30)
    X, Y = grid.cell_centers()
    assert X.shape == (10, 30)
    np.testing.assert_allclose([X[0, 0], Y[0, 0]], [-0.95, 0.95])  # row 0 = max y
    np.testing.assert_allclose([X[-1, -1], Y[-1, -1]], [1.95, 0.05])
    rc = grid.to_cells(np.array([[-0.95, 0.95], [1.95, 0.05], [5.0, 0.52]]))
    assert rc.tolist() == [[0, 0], [9, 29], [4, 60]]
    assert grid.contains(np.array([[-0.95, 0.95], [5.0, 0.5]])).tolist() == [True, False]
    h = np.array([1.95, 0.05, 1.0])
    np.testing.assert_allclose(grid.cells_from_plane @ h, [29, 9, 1], atol=1e-12)
    np.testing.assert_allclose(grid.plane_from_cells @ grid.cells_from_plane, np.eye(3), atol=1e-12)
    with pytest.raises(ValueError, match="max > min"):
        FloorGrid((1.0, 0.0), (0.0, 1.0), 0.1)
    with pytest.raises(ValueError, match="resolution must be positive"):
        FloorGrid((0.0, 1.0), (0.0, 1.0), 0.0)
    with pytest.raises(ValueError, match="expected numbers"):
        FloorGrid(("a", 1.0), (0.0, 1.0), 0.1)


def _paint_floor_disc(camera, centre, radius):
    """A camera image (bool) of a floor disc, painted pixel by pixel through back-projection."""
    vv, uu = np.mgrid[0 : camera.height, 0 : camera.width]
    uv = np.stack([uu.ravel(), vv.ravel()], 1).astype(float)
    P = GroundPlane.floor().pixel_to_ground(camera, uv)
    inside = np.linalg.norm(P[:, :2] - centre, axis=1) < radius
    return inside.reshape(camera.height, camera.width)


@pytest.mark.parametrize("distorted", [True, False])
def test_floor_view_of_two_cameras_agree_with_truth(distorted):
    """A disc painted on the floor lands at the same metric place in both floor views."""
    centre, radius = np.array([0.3, 0.2]), 0.25
    grid = FloorGrid((-0.5, 1.0), (-0.5, 1.0), 0.01)
    X, Y = grid.cell_centers()
    truth = np.hypot(X - centre[0], Y - centre[1]) < radius
    for cam in (CAM_A, CAM_B):
        img = _paint_floor_disc(cam, centre, radius)
        if not distorted:
            img = cam.undistort_image(img)
        top = floor_view(img, cam, GroundPlane.floor(), grid, distorted=distorted)
        assert top.shape == grid.shape and top.dtype == bool
        iou = (top & truth).sum() / (top | truth).sum()
        assert iou > 0.95, (cam.name, iou)
    # colour images keep their channels and dtype
    rgb = np.zeros((CAM_A.height, CAM_A.width, 3), np.uint8)
    rgb[..., 1] = 200
    top = floor_view(rgb, CAM_A, GroundPlane.floor(), grid, distorted=distorted)
    assert top.shape == (*grid.shape, 3) and top.dtype == np.uint8
    assert top[..., 1].max() == 200
    one = floor_view(rgb[..., 1:2], CAM_A, GroundPlane.floor(), grid, distorted=distorted)
    assert one.shape == (*grid.shape, 1)
    np.testing.assert_array_equal(one[..., 0], top[..., 1])


def test_floor_view_of_integer_labels_is_exact():
    labels = (np.arange(CAM_A.height * CAM_A.width, dtype=np.int64) * 7919 + 2**40).reshape(CAM_A.height, CAM_A.width)
    grid = FloorGrid((-0.5, 0.5), (-0.5, 0.5), 0.05)
    top = floor_view(labels, CAM_A, GroundPlane.floor(), grid, interpolation=cv2.INTER_NEAREST, fill=-1)
    assert top.dtype == np.int64 and top.shape == grid.shape
    # every cell holds the label of the pixel nearest to where its centre projects
    X, Y = grid.cell_centers()
    uv = CAM_A.project(np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1))
    rc = np.round(uv).astype(int)
    np.testing.assert_array_equal(top.ravel(), labels[rc[:, 1], rc[:, 0]])


def test_floor_view_behind_camera_is_filled():
    level = look_at("level", [0, 0, 1.0], [5.0, 0, 1.0])
    img = np.full((level.height, level.width), 255, np.uint8)
    grid = FloorGrid((-5.0, 5.0), (-1.0, 1.0), 0.1)
    top = floor_view(img, level, GroundPlane.floor(), grid)
    X, _ = grid.cell_centers()
    assert np.all(top[X < 0] == 0)  # floor behind the camera stays empty
    assert np.any(top[X > 2] == 255)
    with pytest.raises(ValueError, match="expects a 320x240 image"):
        floor_view(np.zeros((10, 10)), level, GroundPlane.floor(), grid)
