"""The fisheye lens model (``Camera(model="fisheye")``, OpenCV's ``cv2.fisheye``) end to end.

Projection and undistortion are checked against ``cv2.fisheye`` itself over the whole
hemisphere in front of the camera (up to 89.5 deg off-axis): both are closed-form or Newton
to machine precision, so the tolerances are 1e-9 px (1e-9 relative for undistorted pixels,
which grow like tan θ). Files round-trip a mixed pinhole/fisheye rig to 1e-9.
"""

from __future__ import annotations

import json

import cv2
import numpy as np

from calibration.rotation import rotvec_to_matrix
import pytest

from calibration import CalibrationError, Camera, FloorGrid, GroundPlane, RigCalibration, floor_view
from calibration.bundle import bundle_adjust
from calibration.camera import (
    distort_fisheye,
    fisheye_fold_angle,
    fisheye_theta,
    undistort_fisheye,
)
from calibration.detect import Detection
from calibration.extrinsics import calibrate_extrinsics, initial_rig, solve_board_pose
from calibration.intrinsics import calibrate_intrinsics
from calibration.rotation import look_at
from calibration.synthetic import camera_ring, default_board, observe, random_board_poses

#: Two realistic lenses (a GoPro-like and a stronger negative one) and the pure equidistant.
LENSES = {
    "positive": (0.052, -0.011, 0.0043, -0.0009),
    "negative": (-0.031, 0.0083, -0.0021, 0.00031),
    "equidistant": (0.0, 0.0, 0.0, 0.0),
}
TIGHT = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-15)


def fisheye_camera(dist=LENSES["positive"], skew=0.0, name="fe") -> Camera:
    K = np.array([[420.0, skew, 645.3], [0.0, 418.5, 481.2], [0.0, 0.0, 1.0]])
    R = rotvec_to_matrix([0.1, -0.2, 0.05])
    return Camera(name, K, np.array(dist), R, np.array([0.1, 0.2, 0.3]), (1280, 960), "fisheye")


def hemisphere_points(cam: Camera, n=2000, max_deg=89.5, seed=0) -> tuple[np.ndarray, np.ndarray]:
    """World points (n, 3) at random off-axis angles θ ≤ ``max_deg`` and depths; and θ (n,)."""
    rng = np.random.default_rng(seed)
    th = rng.uniform(0.0, np.radians(max_deg), n)
    ph = rng.uniform(0.0, 2 * np.pi, n)
    rho = rng.uniform(0.5, 5.0, n)
    Xc = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], 1) * rho[:, None]
    return (Xc - cam.t) @ cam.R, th


# ---------------------------------------------------------------- projection vs cv2.fisheye
@pytest.mark.parametrize("lens", list(LENSES))
@pytest.mark.parametrize("skew", [0.0, 1.7])
def test_project_matches_cv2_fisheye_projectPoints(lens, skew):
    cam = fisheye_camera(LENSES[lens], skew)
    X, _ = hemisphere_points(cam)
    ref, _ = cv2.fisheye.projectPoints(X.reshape(1, -1, 3), cam.rvec, cam.t, cam.K, cam.dist, alpha=skew / cam.K[0, 0])
    uv = cam.project(X)
    assert np.max(np.abs(uv - ref.reshape(-1, 2))) < 1e-9
    # undistorted projection is the ideal pinhole one, whatever the lens
    ideal = cam.project(X, distort=False)
    pin = Camera("p", cam.K, np.zeros(0), cam.R, cam.t, cam.size)
    np.testing.assert_array_equal(ideal, pin.project(X))


@pytest.mark.parametrize("lens", list(LENSES))
def test_undistort_matches_cv2_fisheye_undistortPoints(lens):
    """Agreement with cv2 where cv2 is right; exact (vs the true ideal pixel) everywhere.

    ``cv2.fisheye.undistortPoints`` clamps the distorted radius θ_d to π/2 before its Newton
    iterations, so it is wrong for rays whose θ_d exceeds π/2 (the "positive" lens beyond
    ~80 deg off-axis); there we check against the truth only.
    """
    cam = fisheye_camera(LENSES[lens])
    X, th = hemisphere_points(cam, max_deg=85.0)
    uv = cam.project(X)
    ours = cam.undistort_pixels(uv)
    truth = cam.project(X, distort=False)
    # ideal pixels reach ~5000 px from the centre at 85 deg: compare relative to their size
    assert np.max(np.abs(ours - truth) / np.maximum(1.0, np.abs(truth))) < 1e-10
    xy_d = cam._pixels_to_normalized(uv)
    ok = np.hypot(xy_d[:, 0], xy_d[:, 1]) < np.pi / 2  # where cv2 does not clamp
    assert ok.mean() > 0.9
    ref = cv2.fisheye.undistortPoints(uv[ok].reshape(1, -1, 2), cam.K, cam.dist, P=cam.K, criteria=TIGHT).reshape(-1, 2)
    assert np.max(np.abs(ours[ok] - ref) / np.maximum(1.0, np.abs(ref))) < 1e-9
    # normalized (P = identity) as well
    ref_n = cv2.fisheye.undistortPoints(uv[ok].reshape(1, -1, 2), cam.K, cam.dist, criteria=TIGHT).reshape(-1, 2)
    ours_n = undistort_fisheye(xy_d[ok], cam.dist)
    assert np.max(np.abs(ours_n - ref_n) / np.maximum(1.0, np.abs(ref_n))) < 1e-9


@pytest.mark.parametrize("lens", list(LENSES))
def test_round_trips_and_rays_up_to_90_degrees(lens):
    cam = fisheye_camera(LENSES[lens], skew=0.9)
    X, th = hemisphere_points(cam, max_deg=89.9)
    uv = cam.project(X)
    # rays: exact straight from the off-axis angle, no tan(θ) blow-up near 90 deg
    o, d = cam.pixel_rays(uv)
    true_dir = (X - o) / np.linalg.norm(X - o, axis=1, keepdims=True)
    assert np.max(np.linalg.norm(np.cross(d, true_dir), axis=1)) < 1e-12
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-14)
    np.testing.assert_allclose(cam.project(o + 2.5 * d), uv, rtol=0, atol=1e-9)
    # distort(undistort(uv)) == uv and undistort(distort(ideal)) == ideal
    sel = th < np.radians(80)
    ideal = cam.undistort_pixels(uv[sel])
    np.testing.assert_allclose(cam.distort_pixels(ideal), uv[sel], rtol=0, atol=1e-9)
    ideal_true = cam.project(X[sel], distort=False)
    assert np.max(np.abs(ideal - ideal_true) / np.maximum(1.0, np.abs(ideal_true))) < 1e-10
    # ideal pixels give rays too
    o2, d2 = cam.pixel_rays(ideal, distorted=False)
    assert np.max(np.linalg.norm(np.cross(d2, true_dir[sel]), axis=1)) < 1e-9


def test_equidistant_radius_is_f_theta_and_always_distorted():
    cam = Camera("eq", np.array([[400.0, 0, 300], [0, 400.0, 200], [0, 0, 1]]), np.zeros(4), np.eye(3), np.zeros(3),
                 (600, 400), "fisheye")
    assert cam.has_distortion and cam.is_fisheye  # equidistant != pinhole even with k = 0
    th = np.radians([0.0, 1e-9, 10.0, 45.0, 89.0])
    X = np.stack([np.sin(th), np.zeros_like(th), np.cos(th)], 1)
    uv = cam.project(X)
    np.testing.assert_allclose(uv[:, 0] - 300.0, 400.0 * th, rtol=1e-13, atol=1e-12)
    np.testing.assert_allclose(cam.undistort_pixels(uv)[:, 0] - 300.0, 400.0 * np.tan(th), rtol=1e-12, atol=1e-9)
    assert not Camera("p", cam.K, np.zeros(4), np.eye(3), np.zeros(3), (600, 400)).has_distortion


def test_beyond_90_degrees_rays_work_and_pinhole_pixels_are_nan():
    """A 190-degree lens: pixels past 90 deg off-axis have rays (z < 0) but no pinhole pixel."""
    cam = Camera("wide", np.array([[200.0, 0, 400], [0, 200.0, 400], [0, 0, 1]]), np.array(LENSES["positive"]),
                 np.eye(3), np.zeros(3), (800, 800), "fisheye")
    th = np.radians([60.0, 95.0])
    theta_d = th * (1 + sum(k * th ** (2 * i + 2) for i, k in enumerate(LENSES["positive"])))
    uv = np.stack([400 + 200 * theta_d, np.full(2, 400.0)], 1)
    _, d = cam.pixel_rays(uv)
    np.testing.assert_allclose(np.arccos(d[:, 2]), th, rtol=0, atol=1e-12)
    assert d[1, 2] < 0 and d[0, 1] == 0.0
    und = cam.undistort_pixels(uv)
    assert np.all(np.isfinite(und[0])) and np.all(np.isnan(und[1]))
    # points behind the camera are not projected (same convention as the pinhole model)
    uv_b, depth, front = cam.project_points(np.array([[0.2, 0.0, -1.0]]))
    assert not front[0] and np.all(np.isnan(uv_b))


def test_fold_angle_and_inversion_limits():
    k = np.array([-0.3, 0.0, 0.0, 0.0])  # θ_d = θ - 0.3 θ³ turns back at θ = 1/sqrt(0.9)
    fold = fisheye_fold_angle(k)
    assert fold == pytest.approx(1 / np.sqrt(0.9), abs=1e-3) and fold <= 1 / np.sqrt(0.9)
    assert fisheye_fold_angle(np.zeros(4)) == pytest.approx(np.pi)
    np.testing.assert_array_equal(fisheye_theta(np.array([0.5, 3.0, 3.5]), np.zeros(4)), [0.5, 3.0, np.nan])
    th = np.linspace(0.0, fold, 50)
    theta_d = th - 0.3 * th**3
    np.testing.assert_allclose(fisheye_theta(theta_d, k), th, rtol=0, atol=1e-10)
    assert np.isnan(fisheye_theta(np.array([0.9]), k)[0])  # beyond the fold's radius 0.702
    # the distort / undistort pair on normalized coordinates
    xy = np.array([[0.3, -0.2], [0.0, 0.0], [1e-10, 0.0], [2.0, 1.0]])
    back = undistort_fisheye(distort_fisheye(xy, LENSES["negative"]), LENSES["negative"])
    np.testing.assert_allclose(back, xy, rtol=1e-12, atol=1e-15)
    assert distort_fisheye(np.zeros((0, 2)), k).shape == (0, 2) and undistort_fisheye(np.zeros((0, 2)), k).shape == (0, 2)


# ---------------------------------------------------------------- images and the floor
def test_undistort_maps_and_image_follow_the_model():
    cam = fisheye_camera(LENSES["negative"])
    mx, my = cam.undistort_maps()
    assert mx.shape == (960, 1280) and mx.dtype == np.float32
    rows, cols = np.mgrid[0:960:37, 0:1280:41]
    ideal = np.stack([cols.ravel(), rows.ravel()], 1).astype(float)
    src = cam.distort_pixels(ideal)
    np.testing.assert_allclose(np.stack([mx[rows, cols].ravel(), my[rows, cols].ravel()], 1), src, rtol=0, atol=2e-3)
    # a linear ramp (value = source column) undistorts to the map itself: linear interpolation is exact
    ramp = np.tile(np.arange(1280, dtype=np.float32), (960, 1))
    out = cam.undistort_image(ramp)
    inside = (src[:, 0] > 1) & (src[:, 0] < 1278) & (src[:, 1] > 1) & (src[:, 1] < 958)
    np.testing.assert_allclose(out[rows, cols].ravel()[inside], src[inside, 0], atol=5e-3)
    mask = cam.undistort_image(np.ones((960, 1280), bool))
    assert mask.dtype == bool and mask[480, 640]


def test_floor_view_uses_the_whole_fisheye_field():
    """A ceiling fisheye 2.5 m above the floor: the top-down map is right out to ~80 deg off-axis."""
    R, t = look_at([0.0, 0.0, 2.5], [0.0, 0.0, 0.0], up=(0.0, 1.0, 0.0))
    K = np.array([[300.0, 0, 399.5], [0, 300.0, 399.5], [0, 0, 1]])
    cam = Camera("ceiling", K, np.array(LENSES["positive"]), R, t, (800, 800), "fisheye")
    # the image: every pixel holds the world x of the floor point it sees
    v, u = np.mgrid[0:800, 0:800].astype(float)
    ground = GroundPlane.floor().pixel_to_ground(cam, np.stack([u.ravel(), v.ravel()], 1))
    img = np.nan_to_num(ground[:, 0].reshape(800, 800), nan=-99.0).astype(np.float32)
    grid = FloorGrid((-12.0, 12.0), (-12.0, 12.0), 0.3)
    top = floor_view(img, cam, GroundPlane.floor(), grid, fill=np.nan)
    X, Y = grid.cell_centers()
    off_axis = np.degrees(np.arctan2(np.hypot(X, Y), 2.5))
    seen = np.isfinite(top)
    assert seen[off_axis < 60].all() and seen[off_axis > 80].any()
    # linear interpolation of a smooth image: 1e-4 of the distance (measured ~5e-5 at 80 deg)
    assert np.max(np.abs(top[seen] - X[seen]) / np.maximum(1.0, np.hypot(X[seen], Y[seen]))) < 1e-4
    # the pinhole-style margin (half an image) would have dropped these cells
    ideal = cam.project(GroundPlane.floor().from_plane_coords(np.stack([X[seen], Y[seen]], 1)), distort=False)
    assert np.max(np.abs(ideal - 399.5)) > 800 + 400


def test_fisheye_fold_limits_the_floor_view():
    R, t = look_at([0.0, 0.0, 2.5], [0.0, 0.0, 0.0], up=(0.0, 1.0, 0.0))
    K = np.array([[300.0, 0, 399.5], [0, 300.0, 399.5], [0, 0, 1]])
    cam = Camera("folded", K, np.array([-0.3, 0.0, 0.0, 0.0]), R, t, (800, 800), "fisheye")
    grid = FloorGrid((-9.0, 9.0), (-0.5, 0.5), 0.25)
    top = floor_view(np.ones((800, 800), np.float32), cam, GroundPlane.floor(), grid, fill=0)
    X, _ = grid.cell_centers()
    off_axis = np.arctan2(np.abs(X), 2.5)
    assert np.all(top[off_axis > fisheye_fold_angle(cam.dist)] == 0)  # no folded-back samples
    assert np.all(top[off_axis < 0.8] == 1)


# ---------------------------------------------------------------- the Camera object
@pytest.mark.parametrize(
    "kwargs, field, message",
    [
        ({"model": "fish-eye"}, "model", r"expected one of \('pinhole', 'fisheye'\), got 'fish-eye'"),
        ({"model": None}, "model", "expected one of .*, got None"),
        ({"dist": np.zeros(5)}, "dist", r"the fisheye model needs exactly 4 coefficients \(k1 k2 k3 k4\), got 5"),
        ({"dist": np.zeros(0)}, "dist", "the fisheye model needs exactly 4 coefficients .* got 0"),
    ],
)
def test_invalid_fisheye_camera_names_camera_and_field(kwargs, field, message):
    with pytest.raises(CalibrationError, match=rf"camera 'fe': field '{field}': {message}"):
        fisheye_camera().replace(**kwargs)


def test_dict_allclose_and_repr():
    cam = fisheye_camera()
    d = cam.to_dict()
    assert d["model"] == "fisheye"
    assert Camera.from_dict("fe", d).allclose(cam, atol=0.0)
    pin = cam.replace(model="pinhole")
    assert not pin.allclose(cam) and not cam.allclose(pin) and pin.allclose(pin)
    del d["model"]  # calibration files written before the field existed
    assert Camera.from_dict("fe", d).model == "pinhole"
    assert "fisheye" in repr(cam) and "pinhole" in repr(pin)
    assert Camera.from_rvec("fe", cam.K, cam.dist, cam.rvec, cam.t, cam.size, "fisheye").allclose(cam)


# ---------------------------------------------------------------- file formats
def mixed_rig() -> RigCalibration:
    rng = np.random.default_rng(3)
    cams = {}
    for i, (name, model, n) in enumerate([("pin8", "pinhole", 8), ("fish", "fisheye", 4), ("pin5", "pinhole", 5),
                                         ("fish2", "fisheye", 4)]):
        K = np.array([[600.0 + 11.3 * i, 0.0, 641.7 - i], [0.0, 598.25 + i, 481.3 + 2 * i], [0.0, 0.0, 1.0]])
        cams[name] = Camera(name, K, rng.normal(0.0, 0.02, n), rotvec_to_matrix(rng.normal(0, 1.2, 3)),
                            rng.normal(0, 2.0, 3), (1280 + 16 * i, 960 - 8 * i), model)
    ground = GroundPlane.from_point_normal([0.0, 0.0, 0.021], [0.03, 0.01, 1.0])
    return RigCalibration(cams, ground, {"lab": "b", "n": 2})


def assert_same(a: RigCalibration, b: RigCalibration, atol=1e-9):
    assert a.camera_names == b.camera_names
    assert [c.model for c in a] == [c.model for c in b]
    assert a.allclose(b, atol=atol)


@pytest.mark.parametrize("fmt, target", [("native", "calibration.json"), ("opencv", "ocv"), ("toml", "Calib.toml"),
                                         ("colmap", "sparse")])
def test_mixed_rig_round_trips(tmp_path, fmt, target):
    rig = mixed_rig()
    from calibration.formats import write

    write(rig, tmp_path / target, fmt)
    back = RigCalibration.load_any(tmp_path / target, fmt)
    assert_same(rig, back, atol=0.0 if fmt == "native" else 1e-9)
    assert [c.model for c in back] == ["pinhole", "fisheye", "pinhole", "fisheye"]


def test_native_file_model_field(tmp_path):
    rig = mixed_rig()
    path = rig.save(tmp_path / "calibration.json")
    doc = json.loads(path.read_text())
    assert doc["version"] == 1 and doc["cameras"]["fish"]["model"] == "fisheye"
    assert doc["cameras"]["pin8"]["model"] == "pinhole"
    del doc["cameras"]["pin8"]["model"]  # an old file
    path.write_text(json.dumps(doc))
    assert RigCalibration.load(path)["pin8"].model == "pinhole"
    doc["cameras"]["fish"]["model"] = "omnidir"
    path.write_text(json.dumps(doc))
    with pytest.raises(CalibrationError, match=r"calibration\.json: camera 'fish': field 'model': expected one of"):
        RigCalibration.load(path)


def test_toml_fisheye_flag(tmp_path):
    rig = mixed_rig()
    path = rig.to_toml(tmp_path / "Calib.toml")
    text = path.read_text()
    assert text.count("fisheye = true") == 2 and text.count("fisheye = false") == 2
    # an anipose file without the key is pinhole; fisheye = true with 5 coefficients is refused
    RigCalibration([rig["pin5"]]).to_toml(tmp_path / "p.toml")
    p = tmp_path / "p.toml"
    p.write_text(p.read_text().replace("fisheye = false\n", ""))
    assert RigCalibration.from_toml(p)["pin5"].model == "pinhole"
    p.write_text(p.read_text().replace('name = "pin5"', 'name = "pin5"\nfisheye = true'))
    with pytest.raises(CalibrationError, match=r"p\.toml: camera 'pin5': field 'dist': the fisheye model needs exactly 4"):
        RigCalibration.from_toml(p)


def test_opencv_model_entries(tmp_path):
    rig = mixed_rig()
    intri, _ = rig.to_opencv(tmp_path)
    fs = cv2.FileStorage(str(intri), cv2.FILE_STORAGE_READ)
    assert fs.getNode("model_fish").string() == "fisheye" and fs.getNode("model_pin8").string() == "pinhole"
    assert fs.getNode("dist_fish").mat().shape == (1, 4)
    fs.release()
    text = intri.read_text()
    # EasyMocap files have no model_ entries: pinhole; D_<cam> is accepted for dist_<cam>
    assert "model_pin5: pinhole\n" in text and "model_fish: fisheye\n" in text
    intri.write_text(text.replace("model_pin5: pinhole\n", "").replace("dist_pin5", "D_pin5"))
    back = RigCalibration.from_opencv(tmp_path)
    assert back["pin5"].model == "pinhole" and back["pin5"].allclose(rig["pin5"])
    bad_entries = [("omnidir", r"field 'model_fish': expected one of"), ("3", r"field 'model_fish': expected a string")]
    for bad, message in bad_entries:
        intri.write_text(text.replace("model_fish: fisheye", f"model_fish: {bad}"))
        with pytest.raises(CalibrationError, match=r"intri\.yml: camera 'fish': " + message):
            RigCalibration.from_opencv(tmp_path)


def test_colmap_fisheye_matches_pycolmap_projection(tmp_path):
    """OPENCV_FISHEYE params are fx fy cx cy k1 k2 k3 k4 with c shifted by 0.5 px (COLMAP's pixel corner)."""
    import pycolmap

    rig = mixed_rig()
    rig.to_colmap(tmp_path)
    assert "OPENCV_FISHEYE" in (tmp_path / "cameras.txt").read_text()
    rec = pycolmap.Reconstruction(str(tmp_path))
    cam = rig["fish"]
    image = next(im for im in rec.images.values() if im.name == "fish")
    X, _ = hemisphere_points(cam, n=200, max_deg=85.0)
    Xc = cam.to_camera(X)
    theirs = np.asarray(image.camera.img_from_cam(Xc))
    np.testing.assert_allclose(theirs - cam.project(X), 0.5, rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    "model, params, k",
    [
        ("SIMPLE_RADIAL_FISHEYE", [600.0, 640.5, 480.5, 0.03], [0.03, 0, 0, 0]),
        ("RADIAL_FISHEYE", [600.0, 640.5, 480.5, 0.03, -0.01], [0.03, -0.01, 0, 0]),
        ("SIMPLE_FISHEYE", [600.0, 640.5, 480.5], [0, 0, 0, 0]),
        ("FISHEYE", [600.0, 610.0, 640.5, 480.5], [0, 0, 0, 0]),
    ],
)
def test_colmap_reads_fisheye_special_cases(tmp_path, model, params, k):
    import pycolmap

    rig = RigCalibration([mixed_rig()["fish"]])
    rig.to_colmap(tmp_path)
    cams = tmp_path / "cameras.txt"
    head, line = cams.read_text().rstrip("\n").rsplit("\n", 1)
    cid, _, w, h = line.split()[:4]
    cams.write_text(f"{head}\n{cid} {model} {w} {h} {' '.join(map(str, params))}\n")
    cam = RigCalibration.from_colmap(tmp_path)["fish"]
    assert cam.model == "fisheye" and np.allclose(cam.dist, k, atol=0)
    i = 2 if model == "FISHEYE" else 1  # index of cx: after fx fy, or after the single f
    assert cam.K[0, 2] == params[i] - 0.5 and cam.K[1, 2] == params[i + 1] - 0.5
    pc = pycolmap.Reconstruction(str(tmp_path)).cameras[int(cid)]
    Xc = np.array([[0.3, -0.2, 1.0], [1.5, 0.7, 0.5], [0.0, 0.0, 2.0]])
    np.testing.assert_allclose(np.asarray(pc.img_from_cam(Xc)) - 0.5, cam.replace(R=np.eye(3), t=np.zeros(3)).project(Xc),
                               rtol=0, atol=1e-9)


# ---------------------------------------------------------------- calibrating fisheye cameras
def fisheye_ring(n=4, seed=2, models=("fisheye", "pinhole", "fisheye", "pinhole")):
    """``n`` cameras on a 1.1 m ring (boards close: they fill a good part of the fisheye field)."""
    rng = np.random.default_rng(seed)
    cams = camera_ring(n, radius=1.1, height=1.0, target=(0.0, 0.0, 0.9), size=(1280, 800), focal=600.0, rng=rng)
    out = {}
    for (name, cam), model in zip(cams.items(), models):
        if model == "fisheye":
            K = cam.K * [[0.7, 1, 1], [1, 0.7, 1], [1, 1, 1]]  # shorter focal: a wider field
            cam = cam.replace(model="fisheye", dist=np.array([0.04, -0.008, 0.002, -0.0004]), K=K)
        out[name] = cam
    return out, rng


def ring_views(cams, rng):
    board = default_board()
    poses = random_board_poses(30, board, rng, centre=(0.0, 0.0, 0.9), spread=(0.5, 0.5, 0.4))
    return observe(cams, board, poses, rng, noise_px=0.3, max_view_angle_deg=70.0, partial=True, min_corners=12)


def test_fisheye_intrinsics_to_camera_end_to_end(tmp_path):
    """Synthetic fisheye views → cv2.fisheye.calibrate → Camera → calibration.json → same projections."""
    cams, rng = fisheye_ring(1, models=("fisheye",))
    truth = next(iter(cams.values()))
    board = default_board()
    poses = {}
    for k in range(40):  # boards held in front of this one camera, tilted, across the field
        c = truth.center + truth.R[2] * rng.uniform(0.5, 1.1) + truth.R.T @ np.r_[rng.uniform(-0.6, 0.6, 2), 0]
        R_wb = truth.R.T @ rotvec_to_matrix(rng.uniform(-0.6, 0.6, 3))
        poses[f"v{k:02d}"] = (R_wb, c - R_wb @ np.r_[board.extent[0] / 2, board.extent[1] / 2, 0.0])
    obs = observe(cams, board, poses, rng, noise_px=0.1, max_view_angle_deg=80)[truth.name]
    assert len(obs) >= 10
    res = calibrate_intrinsics(list(obs.values()), camera=truth.name, model="fisheye")
    cam = res.to_camera(truth.R, truth.t)
    assert cam.model == "fisheye" and res.rms < 0.2
    assert abs(cam.K[0, 0] / truth.K[0, 0] - 1) < 0.005
    X, _ = hemisphere_points(truth, n=300, max_deg=55.0)
    assert np.max(np.linalg.norm(cam.project(X) - truth.project(X), axis=1)) < 2.0
    back = RigCalibration([cam]).save(tmp_path / "calibration.json")
    assert RigCalibration.load(back)[truth.name].allclose(cam, atol=0.0)


def test_extrinsics_of_a_mixed_fisheye_pinhole_ring():
    cams, rng = fisheye_ring()
    obs = ring_views(cams, rng)
    # PnP through the fisheye model: the 0.3 px noise, not the pixels a pinhole reading gives
    cam0 = cams["cam00"]
    d0 = max(obs["cam00"].values(), key=lambda d: np.abs(d.image_points - cam0.K[:2, 2]).max())
    R, t, rms = solve_board_pose(cam0, d0)
    assert rms < 0.6
    assert solve_board_pose(cam0.replace(model="pinhole", dist=np.zeros(5)), d0)[2] > 3.0
    ex = calibrate_extrinsics(cams, obs, reference="cam00")
    assert ex.bundle.rms_after == pytest.approx(0.3 * np.sqrt(2), rel=0.15)
    ref = cams["cam00"]
    for name, truth in cams.items():
        R_rel = truth.R @ ref.R.T
        t_rel = truth.t - R_rel @ ref.t
        got = ex.cameras[name]
        assert got.model == truth.model
        assert np.degrees(np.linalg.norm(cv2.Rodrigues(got.R @ R_rel.T)[0])) < 0.1, name
        assert np.linalg.norm(got.t - t_rel) < 0.005, name


def test_fisheye_board_pose_needs_four_corners():
    cam = fisheye_ring(1, models=("fisheye",))[0]["cam00"]
    board = default_board()
    few = Detection("v7", np.arange(3), np.array([[600.0, 400.0], [650.0, 400.0], [600.0, 450.0]]),
                    board.object_points[:3], cam.size)
    with pytest.raises(CalibrationError, match=r"camera 'cam00': view 'v7': no board pose from 3 corners"):
        solve_board_pose(cam, few)


def test_free_intrinsics_bundle_refines_fisheye_cameras():
    """fx, fy started 1 % (4-6 px) off come back within 1.5 px; fisheye k1..k4 stay four."""
    cams, rng = fisheye_ring()
    obs = ring_views(cams, rng)
    init, bposes, info = initial_rig(cams, obs, reference="cam00")
    start = {n: c.replace(K=c.K * [[1.01, 1, 1], [1, 1.01, 1], [1, 1, 1]]) for n, c in init.items()}
    ba = bundle_adjust(start, bposes, obs, reference="cam00", free_intrinsics=True, max_nfev=20)
    for name, truth in cams.items():
        got = ba.cameras[name]
        assert got.model == truth.model and got.dist.size == truth.dist.size, name
        assert abs(got.K[0, 0] - truth.K[0, 0]) < 1.5 and abs(got.K[1, 1] - truth.K[1, 1]) < 1.5, name
    assert ba.rms_after < 0.45 and "free intrinsics" in ba.method
