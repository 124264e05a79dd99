"""Camera against independent derivations: pixels of exactly representable points worked out
by hand, the documented boundaries at the boundary (focal length "at least" MIN_FOCAL, the
largest accepted deviation from orthonormality, ``depth > 0``, the ``project_near`` margin and
fisheye fold), OpenCV's own map and remap functions for the images, and every validation
message naming the camera and the field.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from calibration import CalibrationError, Camera
from calibration.camera import MIN_FOCAL, ORTHONORMAL_TOL, fisheye_fold_angle
from calibration.rotation import rotvec_to_matrix

K = np.array([[812.5, 0.0, 322.3], [0.0, 806.0, 241.7], [0.0, 0.0, 1.0]])
R = rotvec_to_matrix([0.3, -0.5, 0.2])
T = np.array([0.1, -0.2, 3.5])
DIST = np.array([-0.21, 0.08, 0.0012, -0.0008, -0.02])


def cam(**changes) -> Camera:
    args = {"name": "cam0", "K": K, "dist": DIST, "R": R, "t": T, "size": (640, 480)}
    args.update(changes)
    return Camera(**args)


def raises(field: str | None, detail: str):
    """pytest.raises for the whole message ``camera 'cam0': [field 'F': ]detail``."""
    where = "camera 'cam0': " + (f"field '{field}': " if field else "")
    return pytest.raises(CalibrationError, match="^" + where + detail + "$")


# --------------------------------------------------------------------------- stored values
def test_numbers_are_stored_as_read_only_float64_copies():
    K_in = np.array([[800, 0, 320], [0, 800, 240], [0, 0, 1]])
    c = Camera("c", K_in, [0, 0, 0, 0, 0], np.eye(3, dtype=int), [0, 0, 3], [640.0, 480.0])
    for a in (c.K, c.dist, c.R, c.t):
        assert a.dtype == np.float64 and not a.flags.writeable
    assert K_in.flags.writeable  # the caller's array is not frozen
    assert type(c.size) is tuple and c.size == (640, 480) and all(type(v) is int for v in c.size)
    # integer pixels come back as float pixels (no distortion: a copy)
    out = c.undistort_pixels([[1, 2]])
    assert out.dtype == np.float64 and out.tolist() == [[1.0, 2.0]]


def test_row_and_column_vectors_from_opencv_are_accepted():
    rvec = np.array([[0.3], [-0.5], [0.2]])  # cv2.Rodrigues / calibrateCamera give (3, 1)
    c = Camera.from_rvec("cam0", K, DIST[None, :], rvec, T[:, None], (640, 480))  # dist (1, 5) as cv2 gives it
    assert c.model == "pinhole" and c.dist.shape == (5,) and c.t.shape == (3,)
    np.testing.assert_allclose(c.R, cv2.Rodrigues(rvec)[0], rtol=0, atol=1e-15)
    assert cam(dist=DIST[:, None]).dist.tolist() == DIST.tolist()


@pytest.mark.parametrize(
    "rvec, detail",
    [
        (["0.3", "-0.5", "0.2"], r"expected numbers, got <U4 values \['0.3', '-0.5', '0.2'\]"),
        ([0.3, np.nan, 0.2], "contains NaN or infinite values"),
        ([0.3, -0.5, 0.2, 0.0], r"expected shape \(3,\), got \(4,\)"),
    ],
)
def test_from_rvec_checks_the_rotation_vector(rvec, detail):
    with raises("rvec", detail):
        Camera.from_rvec("cam0", K, DIST, rvec, T, (640, 480))


# --------------------------------------------------------------------------- validation
@pytest.mark.parametrize("entry", [(1, 0), (2, 0), (2, 1)])
def test_K_below_the_diagonal_must_be_zero(entry):
    bad = K.copy()
    bad[entry] = 0.5
    with raises("K", r"expected \[\[fx, s, cx\], \[0, fy, cy\], \[0, 0, 1\]\], got .*"):
        cam(K=bad)
    skewed = K.copy()
    skewed[0, 1] = 0.5  # skew is allowed
    assert cam(K=skewed).K[0, 1] == 0.5


def test_focal_length_at_least_min_focal():
    """"at least": exactly MIN_FOCAL is accepted, for fx and fy alike; either one below is not."""
    at = K.copy()
    at[0, 0] = at[1, 1] = MIN_FOCAL
    assert cam(K=at).K[0, 0] == MIN_FOCAL
    for entry, fx, fy in (((0, 0), "-812.5", "806"), ((1, 1), "812.5", "-806")):
        bad = K.copy()
        bad[entry] *= -1
        with raises("K", rf"focal lengths must be at least 0.001 \(pixels, or 1 for normalised cameras\), "
                         rf"got fx={fx}, fy={fy}"):
            cam(K=bad)


def test_orthonormality_tolerance_is_inclusive():
    """R R^T of [[1, e, 0], [0, 1, 0], [0, 0, 1]] differs from I by exactly e (and e^2 on the diagonal)."""
    at = np.eye(3)
    at[0, 1] = ORTHONORMAL_TOL
    assert np.max(np.abs(at @ at.T - np.eye(3))) == ORTHONORMAL_TOL
    assert cam(R=at).R[0, 1] == ORTHONORMAL_TOL
    past = np.eye(3)
    past[0, 1] = 2 * ORTHONORMAL_TOL
    with raises("R", r"not orthonormal \(max \|R Rᵀ - I\| = 2e-06 > 1e-06\)"):
        cam(R=past)
    with raises("R", r"determinant is -1 \(a reflection, not a rotation\)"):
        cam(R=-R)


def test_array_messages_name_the_field():
    with raises("K", r"not an array of numbers \(.*inhomogeneous.*\)"):
        cam(K=[[1.0, 0.0, 2.0], [0.0, 1.0], [0.0, 0.0, 1.0]])
    with raises("t", "contains NaN or infinite values"):
        cam(t=[0.0, np.nan, 1.0])
    with raises("dist", "contains NaN or infinite values"):
        cam(dist=[0.1, np.inf, 0.0, 0.0])


@pytest.mark.parametrize("size", [(640, True), (np.True_, 480), (640, "480")])
def test_size_refuses_flags_and_text(size):
    with raises("size", r"expected two positive integers \(width, height\), got .*"):
        cam(size=size)


def test_size_boundaries():
    """Positive: 1 x 1 is a camera, a zero side is not."""
    assert cam(size=(1, 1)).size == (1, 1)
    for size in ((0, 480), (640, 0)):
        with raises("size", rf"expected two positive integers \(width, height\), got \({size[0]}, {size[1]}\)"):
            cam(size=size)


def test_from_dict_messages():
    with raises(None, "expected a mapping, got list"):
        Camera.from_dict("cam0", [1, 2])
    data = cam().to_dict()
    del data["R"]
    with raises("R", "missing"):
        Camera.from_dict("cam0", data)


@pytest.mark.parametrize(
    "method, arg, shape",
    [("project", "X", (4, 2)), ("to_camera", "X", (4, 2)), ("undistort_pixels", "uv", (4, 3)),
     ("distort_pixels", "uv_ideal", (4, 3)), ("in_image", "uv", (4, 3)), ("pixel_rays", "uv", (4, 3))],
)
def test_point_shape_messages_name_the_argument(method, arg, shape):
    dim = 3 if arg == "X" else 2
    with pytest.raises(ValueError, match=rf"^{arg}: expected shape \(N, {dim}\) or \({dim},\), got \(4, {shape[1]}\)$"):
        getattr(cam(), method)(np.zeros(shape))


def test_repr_shows_the_intrinsics_and_centre():
    c = Camera("cam0", K, DIST, np.eye(3), [-0.5, -1.25, -2.125], (640, 480))
    assert repr(c) == ("Camera('cam0', 640x480, f=(812.5, 806.0), c=(322.3, 241.7), pinhole, dist=5, "
                       "centre=(0.500, 1.250, 2.125))")


# --------------------------------------------------------------------------- allclose
def _scaled(c: Camera, field: str, factor: float) -> Camera:
    if field == "K":
        k = c.K.copy()
        k[0, 0] *= factor
        return c.replace(K=k)
    return c.replace(**{field: getattr(c, field) * factor})


@pytest.mark.parametrize("field", ["K", "dist", "R", "t"])
def test_allclose_is_absolute_per_field(field):
    """A relative change of 4e-7 (R stays orthonormal to 1e-6) is beyond the default atol = 1e-9
    (every change is above 1e-8 here) and within atol = 1e-3: the comparison is absolute (rtol = 0),
    with the given atol."""
    c = cam()
    moved = _scaled(c, field, 1 + 4e-7)
    assert not c.allclose(moved) and not moved.allclose(c)
    assert c.allclose(moved, atol=1e-3) and moved.allclose(c, atol=1e-3)


# --------------------------------------------------------------------------- look_at
def test_look_at_with_another_up_axis():
    """A ceiling camera 2.5 m up looking down with world +Y up in the image: R = diag(1, -1, -1)
    (image y = -Y, optical axis = -Z, x = y × z = +X); (0.1, 0.2, 0) sits at camera (0.1, -0.2, 2.5)."""
    c = Camera.look_at("top", [0.0, 0.0, 2.5], [0.0, 0.0, 0.0], 300.0, (800, 800), up=(0.0, 1.0, 0.0))
    np.testing.assert_allclose(c.R, np.diag([1.0, -1.0, -1.0]), rtol=0, atol=1e-15)
    np.testing.assert_allclose(c.project([0.1, 0.2, 0.0]), [[399.5 + 300 * 0.04, 399.5 - 300 * 0.08]], atol=1e-12)
    assert c.dist.shape == (0,) and c.dist.dtype == np.float64 and c.model == "pinhole"
    fe = Camera.look_at("fe", [0.0, 0.0, 2.5], [0.0, 0.0, 0.0], 300.0, (800, 800), dist=[0.0] * 4,
                        model="fisheye", up=(0.0, 1.0, 0.0))
    assert fe.model == "fisheye" and fe.dist.tolist() == [0.0] * 4
    with pytest.raises(CalibrationError, match=r"^camera 'top': field 'target': looks straight along the up axis: "
                                               r"give a target off the vertical$"):
        Camera.look_at("top", [0.0, 0.0, 3.0], [0.0, 0.0, 0.0], 500.0, (640, 480))


# --------------------------------------------------------------------------- projection
def test_in_image_is_half_open_pixel_edges():
    """[-0.5, w - 0.5) x [-0.5, h - 0.5): each side at, just inside and just outside its edge."""
    c = cam()
    uv = np.array([[-0.5, -0.5], [-0.51, 0.0], [-1.0, 0.0], [639.49, 479.49], [639.5, 0.0], [0.0, 479.5],
                   [0.0, 479.9], [0.0, -0.51], [np.nan, 3.0], [3.0, np.nan]])
    assert c.in_image(uv).tolist() == [True, False, False, True, False, False, False, False, False, False]


def test_depth_zero_is_not_in_front():
    """``in_front`` is ``depth > 0``: points in the camera plane (x/0, 0/0) are NaN, without warnings."""
    c = Camera("c", K, np.zeros(0), np.eye(3), np.zeros(3), (640, 480))
    uv, depth, front = c.project_points(np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    assert front.tolist() == [False, False, True] and depth.tolist() == [0.0, 0.0, 1.0]
    assert np.isnan(uv[:2]).all() and uv[2].tolist() == [322.3, 241.7]


def test_fisheye_ray_at_and_next_to_the_principal_point():
    """The principal pixel's ray is the optical axis (θ_d = 0, no 0/0 warning); a pixel 2⁻³³ px off
    (θ_d ≈ 3e-13, below the 1e-12 switch) has direction (x, 0, 1), x = 2⁻³³ / f."""
    c = Camera("fe", [[400.0, 0, 300.0], [0, 400.0, 200.0], [0, 0, 1]], np.array([0.05, -0.01, 0.004, -0.001]),
               np.eye(3), np.zeros(3), (600, 400), "fisheye")
    _, d = c.pixel_rays([[300.0, 200.0], [300.0 + 2.0**-33, 200.0]])
    assert d[0].tolist() == [0.0, 0.0, 1.0]
    assert d[1, 0] == pytest.approx(2.0**-33 / 400.0, rel=1e-9, abs=0.0) and d[1, 1] == 0.0


def _margin_camera(dist=(-0.01, 0.0, 0.0, 0.0, 0.0)):
    # f = 128, principal point (64, 32), 256 x 128: margin 0.5 -> m = 128 px; ideal u = 128 x + 64, v = 128 y + 32
    return Camera("m", [[128.0, 0, 64.0], [0, 128.0, 32.0], [0, 0, 1]], np.array(dist), np.eye(3), np.zeros(3),
                  (256, 128))


def test_project_near_margin_is_inclusive_on_every_side():
    """Ideal pixels exactly m = 128 px outside [0, 256] x [0, 128] are kept, 1 px further are NaN."""
    c = _margin_camera()
    at = np.array([[-1.5, 0.0, 1.0], [2.5, 0.0, 1.0], [0.0, -1.25, 1.0], [0.0, 1.75, 1.0]])  # u=-128, 384; v=-128, 256
    np.testing.assert_array_equal(c.project(at, distort=False), [[-128.0, 32.0], [384.0, 32.0], [64.0, -128.0],
                                                                  [64.0, 256.0]])
    near = c.project_near(at)
    assert np.isfinite(near).all()
    np.testing.assert_array_equal(near, c.project(at))
    step = np.array([[-1.0, 0, 0], [1.0, 0, 0], [0, -1.0, 0], [0, 1.0, 0]]) / 128.0
    assert np.isnan(c.project_near(at + step)).all()
    # a wider margin keeps them; without distortion every point in front keeps its pinhole pixel
    assert np.isfinite(c.project_near(at + step, margin=1.0)).all()
    assert np.isnan(c.project_near(at + 2 * 128 * step, margin=1.0)).all()
    plain = _margin_camera(dist=np.zeros(5))
    far = np.array([[-20.0, 3.0, 1.0]])
    np.testing.assert_array_equal(plain.project_near(far), [[128.0 * -20 + 64, 128.0 * 3 + 32]])


def test_fisheye_project_near_keeps_the_fold_angle_itself():
    """θ_d = θ - 0.3 θ³ folds at θ = 1/sqrt(0.9): a point exactly at that angle (off-axis along y) is
    kept, one ulp further is NaN; along x, too."""
    c = Camera("f", [[100.0, 0, 100.0], [0, 100.0, 100.0], [0, 0, 1]], np.array([-0.3, 0.0, 0.0, 0.0]), np.eye(3),
               np.zeros(3), (200, 200), "fisheye")
    fold = fisheye_fold_angle(c.dist)
    z, y = np.cos(fold), np.sin(fold)
    for _ in range(200):  # the off-axis angle the camera computes, arctan2(|y|, z), equal to the fold
        th = np.arctan2(np.hypot(0.0, y), z)
        if th == fold:
            break
        y = np.nextafter(y, np.inf if th < fold else -np.inf)
    assert np.arctan2(y, z) == fold
    beyond = y
    while np.arctan2(beyond, z) == fold:  # the next representable angle past the fold
        beyond = np.nextafter(beyond, np.inf)
    X = np.array([[0.0, y, z], [0.0, beyond, z], [y, 0.0, z], [beyond, 0.0, z]])
    near = c.project_near(X)
    np.testing.assert_array_equal(near[[0, 2]], c.project(X[[0, 2]]))
    assert np.isnan(near[[1, 3]]).all()


# --------------------------------------------------------------------------- images
def _small_camera() -> Camera:
    return Camera("cam0", [[150.0, 0, 79.5], [0, 148.0, 60.2], [0, 0, 1]], DIST, np.eye(3), np.zeros(3), (160, 120))


def test_undistort_maps_are_opencvs_float_maps_and_cached():
    c = _small_camera()
    mx, my = c.undistort_maps()
    ref = cv2.initUndistortRectifyMap(c.K, c.dist, None, c.K, (160, 120), cv2.CV_32FC1)
    assert mx.dtype == np.float32 and mx.shape == (120, 160)
    np.testing.assert_array_equal(mx, ref[0])
    np.testing.assert_array_equal(my, ref[1])
    # and they are our forward model: the map at an ideal pixel is its distorted pixel
    rows, cols = np.mgrid[0:120:7, 0:160:9]
    src = c.distort_pixels(np.stack([cols.ravel(), rows.ravel()], 1).astype(float))
    np.testing.assert_allclose(np.stack([mx[rows, cols].ravel(), my[rows, cols].ravel()], 1), src, atol=2e-3)
    assert c.undistort_maps() is c.undistort_maps()  # computed once per camera


def test_undistort_image_is_opencv_remap():
    c = _small_camera()
    mx, my = cv2.initUndistortRectifyMap(c.K, c.dist, None, c.K, (160, 120), cv2.CV_32FC1)
    rng = np.random.default_rng(5)
    colour = rng.integers(0, 256, (120, 160, 3), dtype=np.uint8)
    np.testing.assert_array_equal(c.undistort_image(colour), cv2.remap(colour, mx, my, cv2.INTER_LINEAR))
    mask = rng.random((120, 160)) > 0.5
    out = c.undistort_image(mask)
    assert out.dtype == bool
    np.testing.assert_array_equal(out, cv2.remap(mask.astype(np.uint8), mx, my, cv2.INTER_NEAREST) > 0)
    lin = c.undistort_image(mask, interpolation=cv2.INTER_LINEAR)  # 0/1 bytes interpolated, then > 0
    np.testing.assert_array_equal(lin, cv2.remap(mask.astype(np.uint8), mx, my, cv2.INTER_LINEAR) > 0)
    assert not np.array_equal(lin, out)
    with pytest.raises(ValueError, match=r"^camera 'cam0': image is 12x10, calibration says 160x120$"):
        c.undistort_image(np.zeros((10, 12), np.uint8))
