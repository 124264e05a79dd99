"""Format readers and writers against values derived here, independently of the code under test.

Poses composed with 4x4 homogeneous matrices (``numpy.linalg.inv``) or SciPy rotations rather
than the readers' own ``R, t`` algebra; written files parsed back with PyYAML / json / tomllib
and compared key by key with documents built here from the formats' published layouts;
nearest rotations from an SVD written out here; error messages compared whole (the detail,
camera and field a user reads), not by a fragment.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from calibration import Camera, RigCalibration
from calibration.formats import reader
from formatkit import assert_error, raised

K = [[900.0, 0.0, 640.0], [0.0, 905.0, 360.0], [0.0, 0.0, 1.0]]


def homogeneous(R, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, t
    return T


def svd_rotation(M) -> np.ndarray:
    """The rotation nearest ``M`` (Frobenius), written out here: U Vᵀ of its SVD (det +1 here)."""
    U, _, Vt = np.linalg.svd(np.asarray(M, float))
    R = U @ Vt
    assert np.linalg.det(R) > 0
    return R


def _numpy_reason(values) -> str:
    with pytest.raises(ValueError) as info:
        np.asarray(values, dtype=np.float64)
    return str(info.value)


# ------------------------------------------------------------------------------------------ multical
#: a ragged distortion table: NumPy's own message, as the camera quotes it
RAGGED = f"not numeric ({_numpy_reason([[0.1, 0.2], [0.3]])})"
def _multical_doc(poses: dict, names=("cam1", "cam2", "cam3")) -> dict:
    return {"cameras": {n: {"model": "standard", "image_size": [1280, 720], "K": K,
                            "dist": [[-0.1, 0.02, 0.001, -0.002, 0.003]]} for n in names},
            "camera_poses": poses}


def _entry(R, T) -> dict:
    return {"R": np.asarray(R).tolist(), "T": np.asarray(T).tolist()}


def test_multical_links_resolve_backwards_and_over_several_passes(tmp_path):
    """``a_to_b`` maps camera b's frame into a's (X_a = R X_b + T). Here only cam1 is absolute,
    ``cam1_to_cam2`` must be inverted to pose cam2 (a known, b not), and the link to cam3 is
    listed first, so it resolves only on a second pass. Expected poses: 4x4 inverses."""
    T1 = homogeneous(Rotation.from_rotvec([0.1, -0.2, 0.05]).as_matrix(), [0.1, -0.3, 2.0])
    T12 = homogeneous(Rotation.from_rotvec([0.0, 0.3, 0.02]).as_matrix(), [-0.5, 0.04, 0.05])  # cam2 → cam1
    T32 = homogeneous(Rotation.from_rotvec([0.02, 0.25, -0.01]).as_matrix(), [-0.45, 0.01, 0.2])  # cam2 → cam3
    poses = {"cam3_to_cam2": _entry(T32[:3, :3], T32[:3, 3]),
             "cam1_to_cam2": _entry(T12[:3, :3], T12[:3, 3]),
             "cam1": _entry(T1[:3, :3], T1[:3, 3])}
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(_multical_doc(poses)))
    parts = reader("multical")(path)
    T2 = np.linalg.inv(T12) @ T1  # world → cam1 → cam2
    T3 = T32 @ T2
    for name, T in (("cam1", T1), ("cam2", T2), ("cam3", T3)):
        np.testing.assert_allclose(parts.cameras[name].R, T[:3, :3], rtol=0, atol=1e-12)
        np.testing.assert_allclose(parts.cameras[name].t, T[:3, 3], rtol=0, atol=1e-12)
    assert parts.notes == ("multical: poses map world (or the named camera) to camera",)
    assert (parts.units, parts.units_fixed, parts.metadata) == ("m", False, {"source": "multical"})


def test_multical_link_resolved_forward_opens_a_backward_one(tmp_path):
    """``cam2_to_cam3`` comes first but needs cam2, which ``cam2_to_cam1`` poses only later
    in the same pass (forward): a second pass then inverts the first link for cam3."""
    T1 = homogeneous(Rotation.from_rotvec([0.1, -0.2, 0.05]).as_matrix(), [0.1, -0.3, 2.0])
    T21 = homogeneous(Rotation.from_rotvec([0.0, 0.3, 0.02]).as_matrix(), [-0.5, 0.04, 0.05])  # cam1 → cam2
    T23 = homogeneous(Rotation.from_rotvec([0.02, 0.25, -0.01]).as_matrix(), [-0.45, 0.01, 0.2])  # cam3 → cam2
    poses = {"cam2_to_cam3": _entry(T23[:3, :3], T23[:3, 3]), "cam2_to_cam1": _entry(T21[:3, :3], T21[:3, 3]),
             "cam1": _entry(T1[:3, :3], T1[:3, 3])}
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(_multical_doc(poses)))
    parts = reader("multical")(path)
    T3 = np.linalg.inv(T23) @ T21 @ T1
    np.testing.assert_allclose(parts.cameras["cam3"].R, T3[:3, :3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(parts.cameras["cam3"].t, T3[:3, 3], rtol=0, atol=1e-12)


def test_multical_rounded_rotation_is_reorthonormalised_and_noted(tmp_path):
    """A rotation written with 5 decimals (off by ~1e-5, within the 1e-4 allowed to rounding)
    is replaced by its nearest rotation (SVD here); T written as a 3x1 column is accepted."""
    R = Rotation.from_rotvec([0.3, -1.2, 0.5]).as_matrix()
    rounded = np.round(R, 5)
    assert 1e-6 < np.max(np.abs(rounded @ rounded.T - np.eye(3))) < 1e-4
    poses = {"cam1": {"R": rounded.tolist(), "T": [[0.1], [-0.3], [2.0]]},
             "cam2": {"R": rounded.tolist(), "T": [0.1, -0.3, 2.0]}}
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(_multical_doc(poses, names=("cam1", "cam2"))))
    parts = reader("multical")(path)
    np.testing.assert_allclose(parts.cameras["cam1"].R, svd_rotation(rounded), rtol=0, atol=1e-14)
    np.testing.assert_array_equal(parts.cameras["cam1"].t, [0.1, -0.3, 2.0])
    np.testing.assert_array_equal(parts.cameras["cam1"].dist, [-0.1, 0.02, 0.001, -0.002, 0.003])
    assert parts.notes == ("multical: poses map world (or the named camera) to camera",
                           "pose rotations of cam1, cam2 re-orthonormalised (written with few decimals)")


def test_multical_without_poses_is_intrinsics_only(tmp_path):
    doc = _multical_doc({}, names=("cam1",))
    del doc["camera_poses"]
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(doc))
    parts = reader("multical")(path)
    np.testing.assert_array_equal(parts.cameras["cam1"].R, np.eye(3))
    np.testing.assert_array_equal(parts.cameras["cam1"].t, np.zeros(3))
    assert parts.notes == ("multical: poses map world (or the named camera) to camera",
                           "no camera_poses: intrinsics only, every camera at R = I, t = 0")


@pytest.mark.parametrize("poses, detail, field", [
    ({"cam1": None}, "expected {R: 3x3, T: [3]}", "camera_poses.cam1"),
    ({"cam1": {"R": np.eye(3).tolist()}}, "expected {R: 3x3, T: [3]}", "camera_poses.cam1"),
    ({"cam1": {"T": [0, 0, 1]}}, "expected {R: 3x3, T: [3]}", "camera_poses.cam1"),
    ({"cam1": {"R": np.eye(3).tolist(), "T": ["a", 0, 1]}},
     "not numeric (could not convert string to float: 'a')", "camera_poses.cam1"),
    ({"cam1": {"R": [["a", 0, 0], [0, 1, 0], [0, 0, 1]], "T": [0, 0, 1]}},
     "not numeric (could not convert string to float: 'a')", "camera_poses.cam1"),
    ({"cam1": {"R": np.eye(3).tolist(), "T": [0, float("nan"), 1]}},
     "expected finite R 3x3 and T [3], got shapes (3, 3) and (3,)", "camera_poses.cam1"),
    ({"cam1": {"R": [[1, 0, 0], [0, 1, 0], [0, 0, float("inf")]], "T": [0, 0, 1]}},
     "expected finite R 3x3 and T [3], got shapes (3, 3) and (3,)", "camera_poses.cam1"),
    ({"cam1": {"R": np.eye(3).tolist(), "T": [0, 1]}},
     "expected finite R 3x3 and T [3], got shapes (3, 3) and (2,)", "camera_poses.cam1"),
    ({"cam1": {"R": np.diag([1.0, 1.0, -1.0]).tolist(), "T": [0, 0, 1]}},
     "R is not a rotation (max |R Rᵀ - I| = 0 > 0.0001)", "camera_poses.cam1.R"),
    ({"cam1_to_camX": _entry(np.eye(3), [0, 0, 1])}, "names camera 'camX', which 'cameras' does not hold",
     "camera_poses.cam1_to_camX"),
    ({"camY_to_cam1": _entry(np.eye(3), [0, 0, 1])}, "names camera 'camY', which 'cameras' does not hold",
     "camera_poses.camY_to_cam1"),
    ({"camZ": _entry(np.eye(3), [0, 0, 1])}, "camera 'camZ' is not in 'cameras'", "camera_poses.camZ"),
    ({"cam1_to_cam2_to_x": _entry(np.eye(3), [0, 0, 1])}, "names camera 'cam2_to_x', which 'cameras' does not hold",
     "camera_poses.cam1_to_cam2_to_x"),
    ([1, 2], "expected an object", "camera_poses"),
])
def test_multical_bad_poses_name_the_entry(tmp_path, poses, detail, field):
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(_multical_doc(poses, names=("cam1", "cam2"))))
    assert_error(raised(reader("multical"), path), detail, field=field, file=path)


def test_multical_bad_documents(tmp_path):
    path = tmp_path / "calibration.json"
    path.write_text("[1, 2]")
    assert_error(raised(reader("multical"), path), "expected an object with a non-empty 'cameras' table",
                 field="cameras", file=path)
    path.write_text('{"cameras": {"a": 1},}')
    exc = raised(reader("multical"), path)
    assert exc.detail.startswith("not valid JSON (") and exc.field is None and exc.file == str(path)


@pytest.mark.parametrize("change, detail, camera, field", [
    (lambda d: d.update(cameras=[]), "expected an object with a non-empty 'cameras' table", None, "cameras"),
    (lambda d: d.update(cameras={}), "expected an object with a non-empty 'cameras' table", None, "cameras"),
    (lambda d: d["cameras"].update(cam1=[1]), "expected an object, got list", "cam1", None),
    (lambda d: d["cameras"]["cam1"].pop("K"), "missing", "cam1", "K"),
    (lambda d: d["cameras"]["cam1"].pop("dist"), "missing", "cam1", "dist"),
    (lambda d: d["cameras"]["cam1"].pop("image_size"), "missing", "cam1", "image_size"),
    (lambda d: d["cameras"]["cam1"].update(image_size=[1280]), "expected [width, height], got [1280]", "cam1",
     "image_size"),
    (lambda d: d["cameras"]["cam1"].update(image_size=[1280, 0]),
     "expected two positive integers (width, height), got (1280, 0)", "cam1", "image_size"),
    (lambda d: d["camera_poses"].pop("cam2"),
     "no pose reaches camera(s) cam2: expected an absolute entry or a chain of <a>_to_<b> entries", None,
     "camera_poses"),
    (lambda d: d.update(cameras={**d["cameras"], "cam3": d["cameras"]["cam1"], "cam4": d["cameras"]["cam1"]}),
     "no pose reaches camera(s) cam3, cam4: expected an absolute entry or a chain of <a>_to_<b> entries", None,
     "camera_poses"),
    (lambda d: d["cameras"]["cam1"].update(K=[[1, 0], [0, 1]]), "expected shape (3, 3), got (2, 2)", "cam1", "K"),
    (lambda d: d["cameras"]["cam1"].update(dist=[[0.1, 0.2], [0.3]]), RAGGED, "cam1", "dist"),
])
def test_multical_bad_cameras_name_camera_and_field(tmp_path, change, detail, camera, field):
    doc = _multical_doc({"cam1": _entry(np.eye(3), [0, 0, 1]), "cam2": _entry(np.eye(3), [1, 0, 1])},
                        names=("cam1", "cam2"))
    change(doc)
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(doc))
    assert_error(raised(reader("multical"), path), detail, camera=camera, field=field, file=path)


def test_multical_writer_document(tmp_path):
    """The written document key by key: the model named after the coefficient count, one
    absolute world → camera entry per camera; refusals name the camera."""
    R = Rotation.from_rotvec([0.2, 0.1, -0.3]).as_matrix()
    cams = [Camera("a", K, [-0.1, 0.02, 0.001, -0.002, 0.003, 0.01, 0.002, -0.001], R, [0.1, 0.2, 2.0], (1280, 720)),
            Camera("b", K, [], np.eye(3), [0.0, 0.0, 1.0], (640, 480))]
    path = tmp_path / "sub" / "calibration.json"
    RigCalibration(cams).write(path, "multical")
    doc = json.loads(path.read_text())
    assert doc == {"cameras": {
        "a": {"model": "rational", "image_size": [1280, 720], "K": K,
              "dist": [[-0.1, 0.02, 0.001, -0.002, 0.003, 0.01, 0.002, -0.001]]},
        "b": {"model": "standard", "image_size": [640, 480], "K": K, "dist": [[0.0] * 5]}},
        "camera_poses": {"a": {"R": R.tolist(), "T": [0.1, 0.2, 2.0]},
                         "b": {"R": np.eye(3).tolist(), "T": [0.0, 0.0, 1.0]}}}
    assert path.read_text().startswith('{\n  "cameras": {\n    "a": {\n')  # indented, one key a line
    models = {}
    for n in (4, 5, 8, 12, 14):
        cam = Camera("c", K, [0.01] * n, np.eye(3), [0, 0, 1], (1280, 720))
        RigCalibration([cam]).write(tmp_path / "n.json", "multical")
        models[n] = json.loads((tmp_path / "n.json").read_text())["cameras"]["c"]["model"]
    assert models == {4: "standard", 5: "standard", 8: "rational", 12: "thin_prism", 14: "tilted"}
    fish = Camera("f", K, [0.01, 0.0, 0.0, 0.0], np.eye(3), [0, 0, 1], (1280, 720), "fisheye")
    assert_error(raised(RigCalibration([fish]).write, tmp_path / "f.json", "multical"),
                 "multical has no fisheye model", camera="f", field="model", file=tmp_path / "f.json")
    bad = Camera("x_to_y", K, [], np.eye(3), [0, 0, 1], (1280, 720))
    assert_error(raised(RigCalibration([bad]).write, tmp_path / "x.json", "multical"),
                 "'_to_' in a camera name reads as a relative pose in multical", camera="x_to_y", field="name",
                 file=tmp_path / "x.json")


# ------------------------------------------------------------------------------------------ Kalibr
def test_kalibr_writer_document_and_fisheye(tmp_path):
    """The camchain key by key (Kalibr's names, rostopic, radtan of 4 coefficients even for a
    5-coefficient camera with k3 = 0, equidistant for fisheye) and T_cn_cnm1 = T_n · T_(n-1)⁻¹
    from 4x4 inverses; read back, the fisheye camera stays fisheye."""
    R0, t0 = Rotation.from_rotvec([0.1, 0.2, -0.1]).as_matrix(), np.array([0.1, -0.2, 2.0])
    R1, t1 = Rotation.from_rotvec([-0.2, 0.5, 0.1]).as_matrix(), np.array([-0.4, 0.1, 2.2])
    cams = [Camera("left", K, [-0.1, 0.02, 0.001, -0.002, 0.0], R0, t0, (1280, 720)),
            Camera("right", K, [0.01, -0.02, 0.003, -0.001], R1, t1, (1280, 720), "fisheye")]
    path = tmp_path / "sub" / "camchain.yaml"
    RigCalibration(cams).write(path, "kalibr")
    doc = yaml.safe_load(path.read_text())
    T10 = homogeneous(R1, t1) @ np.linalg.inv(homogeneous(R0, t0))
    common = {"camera_model": "pinhole", "intrinsics": [900.0, 905.0, 640.0, 360.0]}
    assert list(doc) == ["cam0", "cam1"]
    assert list(doc["cam0"]) == ["camera_model", "intrinsics", "distortion_model", "distortion_coeffs",
                                 "resolution", "rostopic", "T_cam_world"]
    assert {k: v for k, v in doc["cam0"].items() if k != "T_cam_world"} == {
        **common, "distortion_model": "radtan", "distortion_coeffs": [-0.1, 0.02, 0.001, -0.002],
        "resolution": [1280, 720], "rostopic": "/left/image_raw"}
    np.testing.assert_allclose(doc["cam0"]["T_cam_world"], homogeneous(R0, t0), rtol=0, atol=1e-15)
    assert {k: v for k, v in doc["cam1"].items() if k != "T_cn_cnm1"} == {
        **common, "distortion_model": "equidistant", "distortion_coeffs": [0.01, -0.02, 0.003, -0.001],
        "resolution": [1280, 720], "rostopic": "/right/image_raw"}
    np.testing.assert_allclose(doc["cam1"]["T_cn_cnm1"], T10, rtol=0, atol=1e-14)
    parts = reader("kalibr")(path)
    assert parts.own_frame and parts.notes == ()
    assert parts.cameras["cam1"].model == "fisheye"
    np.testing.assert_array_equal(parts.cameras["cam1"].dist, [0.01, -0.02, 0.003, -0.001])
    np.testing.assert_allclose(parts.cameras["cam1"].R, R1, rtol=0, atol=1e-14)
    np.testing.assert_allclose(parts.cameras["cam1"].t, t1, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(parts.cameras["cam0"].R, R0)  # an exact rotation is kept to the bit


def _kalibr_cam(**extra) -> dict:
    return {"camera_model": "pinhole", "intrinsics": [458.6, 457.3, 367.2, 248.4], "distortion_model": "radtan",
            "distortion_coeffs": [-0.28, 0.07, 0.0002, 0.00002], "resolution": [752, 480], **extra}


def test_kalibr_rounded_transform_is_reorthonormalised(tmp_path):
    R = Rotation.from_rotvec([0.3, -1.2, 0.5]).as_matrix()
    T = homogeneous(np.round(R, 5), [0.1, 0.0, 0.02])
    path = tmp_path / "camchain.yaml"
    path.write_text(yaml.safe_dump({"cam0": _kalibr_cam(), "cam1": _kalibr_cam(T_cn_cnm1=T.tolist())}))
    parts = reader("kalibr")(path)
    np.testing.assert_allclose(parts.cameras["cam1"].R, svd_rotation(np.round(R, 5)), rtol=0, atol=1e-14)
    np.testing.assert_array_equal(parts.cameras["cam1"].t, [0.1, 0.0, 0.02])
    assert parts.notes == ("Kalibr: the world is cam0's frame (the chain's base); cameras composed along T_cn_cnm1",)
    assert (parts.units, parts.units_fixed, parts.own_frame, parts.metadata) == ("m", True, False, {"source": "kalibr"})


_EYE4 = np.eye(4).tolist()


@pytest.mark.parametrize("doc, detail, camera, field", [
    ([1, 2], "expected a mapping of cam0, cam1, ...", None, None),
    ({"imu0": {}}, "no cam0, cam1, ... entries", None, "cam0"),
    ({"cam0": _kalibr_cam(), "cam2": _kalibr_cam(T_cn_cnm1=_EYE4)}, "expected cam0..cam1 in a chain, got cam0, cam2",
     None, None),
    ({"cam0": _kalibr_cam(), "cam1": [1]}, "missing: every camera after cam0 needs its T_cn_cnm1", "cam1", "T_cn_cnm1"),
    ({"cam0": _kalibr_cam(), "cam1": _kalibr_cam(T_cn_cnm1=[["a"] * 4] * 4)},
     "not numeric (could not convert string to float: 'a')", "cam1", "T_cn_cnm1"),
    ({"cam0": _kalibr_cam(), "cam1": _kalibr_cam(T_cn_cnm1=np.eye(3).tolist())},
     "expected a finite 4x4 transform with last row [0, 0, 0, 1], got shape (3, 3)", "cam1", "T_cn_cnm1"),
    ({"cam0": _kalibr_cam(), "cam1": _kalibr_cam(T_cn_cnm1=np.diag([1.0, 1, 1, 2]).tolist())},
     "expected a finite 4x4 transform with last row [0, 0, 0, 1], got shape (4, 4)", "cam1", "T_cn_cnm1"),
    ({"cam0": _kalibr_cam(), "cam1": _kalibr_cam(T_cn_cnm1=np.diag([1.0, 1, np.inf, 1]).tolist())},
     "expected a finite 4x4 transform with last row [0, 0, 0, 1], got shape (4, 4)", "cam1", "T_cn_cnm1"),
    ({"cam0": _kalibr_cam(), "cam1": _kalibr_cam(T_cn_cnm1=np.diag([1.0, 1, -1, 1]).tolist())},
     "rotation part is not a rotation (max |R Rᵀ - I| = 0)", "cam1", "T_cn_cnm1"),
    ({"cam0": _kalibr_cam(), "cam1": _kalibr_cam(T_cn_cnm1=np.diag([1.0, 1, 1.1, 1]).tolist())},
     "rotation part is not a rotation (max |R Rᵀ - I| = 0.21)", "cam1", "T_cn_cnm1"),
    ({"cam0": _kalibr_cam(T_cam_world=np.diag([1.0, 1, 1.1, 1]).tolist())},
     "rotation part is not a rotation (max |R Rᵀ - I| = 0.21)", "cam0", "T_cam_world"),
    ({"cam0": "pinhole"}, "expected a mapping, got str", "cam0", None),
    ({"cam0": {"resolution": [752, 480]}}, "missing", "cam0", "intrinsics"),
    ({"cam0": {"intrinsics": [1, 1, 1, 1]}}, "missing", "cam0", "resolution"),
    ({"cam0": _kalibr_cam(camera_model="ds")}, "camera model 'ds' has no OpenCV equivalent: expected 'pinhole'",
     "cam0", "camera_model"),
    ({"cam0": _kalibr_cam(distortion_model="fov")}, "expected one of radtan, equidistant, none, got 'fov'", "cam0",
     "distortion_model"),
    ({"cam0": _kalibr_cam(intrinsics=[1, 1, 1])}, "expected [fu, fv, pu, pv], got [1, 1, 1]", "cam0", "intrinsics"),
    ({"cam0": _kalibr_cam(intrinsics="1 1 1 1")}, "expected [fu, fv, pu, pv], got '1 1 1 1'", "cam0", "intrinsics"),
    ({"cam0": _kalibr_cam(resolution=[752])}, "expected [width, height], got [752]", "cam0", "resolution"),
    ({"cam0": _kalibr_cam(resolution="752 480")}, "expected [width, height], got '752 480'", "cam0", "resolution"),
    ({"cam0": _kalibr_cam(resolution=[752, 0])}, "expected two positive integers (width, height), got (752, 0)",
     "cam0", "resolution"),
    ({"cam0": _kalibr_cam(intrinsics=[458.6, 457.3, 367.2, float("nan")])},
     "contains NaN or infinite values", "cam0", "intrinsics"),
    ({"cam0": _kalibr_cam(distortion_coeffs=[0.1, "x"])},
     "not numeric (could not convert string to float: 'x')", "cam0", "distortion_coeffs"),
])
def test_kalibr_bad_input_names_camera_and_field(tmp_path, doc, detail, camera, field):
    path = tmp_path / "camchain.yaml"
    path.write_text(yaml.safe_dump(doc))
    assert_error(raised(reader("kalibr"), path), detail, camera=camera, field=field, file=path)


def test_kalibr_distortion_none_ignores_coefficients_and_k3_is_refused(tmp_path):
    path = tmp_path / "camchain.yaml"
    path.write_text(yaml.safe_dump({"cam0": _kalibr_cam(distortion_model="none")}))
    cam = reader("kalibr")(path).cameras["cam0"]
    assert cam.dist.size == 0 and cam.model == "pinhole"
    np.testing.assert_array_equal(cam.K, [[458.6, 0, 367.2], [0, 457.3, 248.4], [0, 0, 1]])
    assert cam.size == (752, 480)
    k3 = Camera("c", K, [-0.1, 0.02, 0.001, -0.002, 0.004], np.eye(3), [0, 0, 1], (1280, 720))
    assert_error(raised(RigCalibration([k3]).write, tmp_path / "k.yaml", "kalibr"),
                 "Kalibr's radtan model holds k1 k2 p1 p2 only: k3 and beyond are not zero", camera="c", field="dist",
                 file=tmp_path / "k.yaml")


# ------------------------------------------------------------------------------------------ OptiTrack
def _mcal_camera(serial="M1", enabled="1", drop=(), orient=None, centre=(2.5, 2.6, 3.4)) -> str:
    """One ``<Camera>`` of a .mcal, every attribute written out; ``drop`` leaves some out."""
    M = np.eye(3) if orient is None else np.asarray(orient)
    attrs = {"Attributes": {"ImagerPixelWidth": "1664", "ImagerPixelHeight": "1088"},
             "IntrinsicStandardCameraModel": {"LensCenterX": "812.5", "LensCenterY": "563.25",
                                              "HorizontalFocalLength": "1193.5", "VerticalFocalLength": "1193.75",
                                              "k1": "0.14", "k2": "-0.16", "k3": "0.0001", "TangentialX": "-0.00035",
                                              "TangentialY": "-0.00017"},
             "Extrinsic": {"X": repr(centre[0]), "Y": repr(centre[1]), "Z": repr(centre[2]),
                           **{f"OrientMatrix{i}": repr(float(v)) for i, v in enumerate(M.reshape(-1))}}}
    out = [f'<Camera Serial="{serial}">' if serial is not None else "<Camera>"]
    if enabled is not None:
        out.append(f'<Properties Enabled="{enabled}"/>')
    else:
        out.append("<Properties/>")
    for tag, values in attrs.items():
        if tag in drop:
            continue
        out.append(f"<{tag} " + " ".join(f'{k}="{v}"' for k, v in values.items() if k not in drop) + "/>")
    return "".join(out) + "</Camera>"


def _mcal(*cameras) -> str:
    return ('<calibrationProfile version="1"><Calibration><Cameras>' + "".join(cameras)
            + "</Cameras></Calibration></calibrationProfile>")


def test_optitrack_camera_axes_world_turn_and_notes(tmp_path):
    """OrientMatrix = camera-to-world of a camera looking along its -Z in a Y-up world: with a
    camera at (x, y, z) = (2.5, 2.6, 3.4) whose axes are the world's (looking along world -Z),
    the OpenCV camera looks along world -Z of Motive = +y of the toolkit's Z-up world; its
    centre becomes (x, -z, y). A disabled camera listed first is skipped, not the end."""
    path = tmp_path / "lab.mcal"
    path.write_text(_mcal(_mcal_camera("M0", enabled="0"), _mcal_camera(serial=None, enabled="0"),
                          _mcal_camera("M1", enabled=None)))
    parts = reader("optitrack")(path)
    cam = parts.cameras["M1"]
    np.testing.assert_array_equal(cam.K, [[1193.5, 0.0, 812.5], [0.0, 1193.75, 563.25], [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(cam.dist, [0.14, -0.16, -0.00035, -0.00017, 0.0001])
    assert cam.size == (1664, 1088)
    # OpenCV axes in the Z-up world: x = +x, y (down) = -z_world, z (forward) = +y_world
    np.testing.assert_array_equal(cam.R, [[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    np.testing.assert_allclose(cam.center, [2.5, -3.4, 2.6], rtol=0, atol=1e-15)
    assert list(parts.cameras) == ["M1"]
    assert parts.notes == (
        "OptiTrack: Extrinsic X Y Z = camera position (m), OrientMatrix = camera-to-world rotation of a camera looking "
        "along -Z; R_cam_from_world = diag(1, -1, -1) OrientMatrixᵀ",
        "Motive's world is Y up: turned to Z up, (x, y, z) → (x, -z, y)",
        "distortion: IntrinsicStandardCameraModel k1 k2 k3, TangentialX/Y as OpenCV k1 k2 k3, p1 p2",
        "skipped disabled camera(s) M0, ?")
    assert (parts.units, parts.units_fixed, parts.own_frame, parts.metadata) == ("m", True, False,
                                                                                 {"source": "optitrack"})


@pytest.mark.parametrize("encoding, declared", [("utf-16-le", "UTF-16BE"), ("utf-16-be", "UTF-16LE"),
                                                ("utf-8-sig", "UTF-16"), ("utf-8", "UTF-16")])
def test_optitrack_declaration_naming_another_encoding(tmp_path, encoding, declared):
    """Expat refuses bytes whose declaration names another encoding; the text decoded by its
    byte-order mark (else UTF-8) is read. A processing instruction inside is kept as such."""
    text = (f'<?xml version="1.0" encoding="{declared}"?>\n<?motive export?>'
            + _mcal(_mcal_camera("M1")).replace("<Calibration>", "<Calibration><?motive cameras?>"))
    bom = {"utf-16-le": b"\xff\xfe", "utf-16-be": b"\xfe\xff"}.get(encoding, b"")
    path = tmp_path / "lab.mcal"
    path.write_bytes(bom + text.encode(encoding))
    assert list(reader("optitrack")(path).cameras) == ["M1"]


def test_optitrack_unreadable_and_invalid_files(tmp_path):
    assert_error(raised(reader("optitrack"), tmp_path), "cannot read (Is a directory)", file=tmp_path)
    bad = tmp_path / "bad.mcal"
    bad.write_text("<calibrationProfile><Calibration></calibrationProfile>")
    assert_error(raised(reader("optitrack"), bad), "not valid XML (mismatched tag: line 1, column 35)", file=bad)
    bad.write_bytes(b"<calibrationProfile>\xff</calibrationProfile>")
    assert_error(raised(reader("optitrack"), bad),
                 "not valid XML ('utf-8' codec can't decode byte 0xff in position 20: invalid start byte)", file=bad)


@pytest.mark.parametrize("cameras, detail, camera, field", [
    ([_mcal_camera(serial="")], "<Camera> without Serial", None, "Serial"),
    ([_mcal_camera(drop=("Attributes",))], "missing", "M1", "Attributes"),
    ([_mcal_camera(drop=("ImagerPixelWidth",))], "missing", "M1", "Attributes.ImagerPixelWidth"),
    ([_mcal_camera(drop=("ImagerPixelHeight",))], "missing", "M1", "Attributes.ImagerPixelHeight"),
    ([_mcal_camera(drop=("IntrinsicStandardCameraModel",))], "missing", "M1", "IntrinsicStandardCameraModel"),
    ([_mcal_camera(drop=("k2",))], "missing", "M1", "IntrinsicStandardCameraModel.k2"),
    ([_mcal_camera(drop=("Extrinsic",))], "missing", "M1", "Extrinsic"),
    ([_mcal_camera(drop=("Y",))], "missing", "M1", "Extrinsic.Y"),
    ([_mcal_camera(drop=("OrientMatrix4",))], "missing", "M1", "Extrinsic.OrientMatrix4"),
    ([_mcal_camera(orient=np.diag([1.0, 1.0, -1.0]))], "OrientMatrix0..8 is not a rotation (max |M Mᵀ - I| = 0)",
     "M1", "Extrinsic"),
    ([_mcal_camera(orient=np.diag([1.0, 1.0, 1.01]))],
     "OrientMatrix0..8 is not a rotation (max |M Mᵀ - I| = 0.0201)", "M1", "Extrinsic"),
    ([_mcal_camera("M1"), _mcal_camera("M1")], "two <Camera> entries share this Serial", "M1", "Serial"),
    ([_mcal_camera("M1", enabled="0")], "no enabled <Camera> elements", None, "Camera"),
])
def test_optitrack_bad_cameras_name_camera_and_field(tmp_path, cameras, detail, camera, field):
    path = tmp_path / "lab.mcal"
    path.write_text(_mcal(*cameras))
    assert_error(raised(reader("optitrack"), path), detail, camera=camera, field=field, file=path)


def test_optitrack_rounded_orientation_is_taken_as_its_nearest_rotation(tmp_path):
    M = Rotation.from_rotvec([0.3, -1.2, 0.5]).as_matrix()
    path = tmp_path / "lab.mcal"
    path.write_text(_mcal(_mcal_camera(orient=np.round(M, 5))))
    cam = reader("optitrack")(path).cameras["M1"]
    turn = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # Y up → Z up
    expected = np.diag([1.0, -1.0, -1.0]) @ svd_rotation(np.round(M, 5)).T @ turn.T
    np.testing.assert_allclose(cam.R, expected, rtol=0, atol=1e-14)


# ------------------------------------------------------------------------------------------ Vicon
def _xcp_camera(dev="101", user="1", aspect="0.98", sensor="2048 1088", focal="1800.5", pp="1020.25 540.5",
                q=(0.0, 0.0, 0.0, 1.0), pos="100 -200 2500", radial2="Vicon3Parameter 1020.25 540.5 0 0 0",
                radial=None, world_error="0.3", keyframe=True) -> str:
    attrs = {"DEVICEID": dev, "USERID": user, "PIXEL_ASPECT_RATIO": aspect, "SENSOR_SIZE": sensor}
    kf = {"FOCAL_LENGTH": focal, "PRINCIPAL_POINT": pp, "ORIENTATION": " ".join(repr(float(v)) for v in q), "POSITION": pos,
          "VICON_RADIAL2": radial2, "VICON_RADIAL": radial, "WORLD_ERROR": world_error}
    head = "<Camera " + " ".join(f'{k}="{v}"' for k, v in attrs.items() if v is not None) + ">"
    body = ("<KeyFrames><KeyFrame " + " ".join(f'{k}="{v}"' for k, v in kf.items() if v is not None)
            + "/></KeyFrames>") if keyframe else ""
    return head + body + "</Camera>"


def _xcp(*cameras) -> str:
    return '<?xml version="1.0"?><Cameras VERSION="2.0">' + "".join(cameras) + "</Cameras>"


def test_vicon_fields_pose_and_notes(tmp_path):
    """fx = FOCAL_LENGTH, fy = FOCAL_LENGTH / PIXEL_ASPECT_RATIO; the quaternion x y z w is
    R_cam_from_world (SciPy here), t = -R · POSITION (mm as in the file); a camera without
    DEVICEID is named by USERID; WORLD_ERROR goes to the metadata."""
    q = Rotation.from_rotvec([2.0, 0.3, -0.2]).as_quat()
    path = tmp_path / "lab.xcp"
    path.write_text(_xcp(_xcp_camera(q=tuple(q)), _xcp_camera(dev=None, user="7", aspect=None, world_error=None,
                                                               radial2=None)))
    parts = reader("vicon")(path)
    assert list(parts.cameras) == ["101", "7"]
    cam = parts.cameras["101"]
    np.testing.assert_array_equal(cam.K, [[1800.5, 0.0, 1020.25], [0.0, 1800.5 / 0.98, 540.5], [0.0, 0.0, 1.0]])
    R = Rotation.from_quat(q).as_matrix()
    np.testing.assert_allclose(cam.R, R, rtol=0, atol=1e-15)
    np.testing.assert_allclose(cam.t, -R @ [100.0, -200.0, 2500.0], rtol=0, atol=1e-12)
    assert cam.size == (2048, 1088)
    np.testing.assert_array_equal(cam.dist, np.zeros(5))
    assert parts.cameras["7"].K[1, 1] == 1800.5
    assert parts.notes == (
        "Vicon: POSITION = camera centre in mm, ORIENTATION = quaternion (x y z w) of R_cam_from_world",
        "Vicon radial distortion (pixel units, taken as the correction of observed pixels) refitted as OpenCV k1 k2 "
        "k3: largest error 0 px within the circle inscribed in the sensor",
        "image size = SENSOR_SIZE (the full sensor): a cropped video needs its principal point shifted")
    assert (parts.units, parts.units_fixed, parts.own_frame) == ("mm", True, False)
    assert parts.metadata == {"source": "vicon", "world_error": {"101": 0.3}}


def test_vicon_radial_refit_against_opencv_projection(tmp_path):
    """Vicon's correction u_ideal = c + (u - c)(1 + k1 r² + k2 r⁴ + k3 r⁶) (r in px) refitted
    as OpenCV k1 k2 k3 by least squares over 400 radii from 1 px to the inscribed circle
    (min(cx, w - cx, cy, h - cy) = 540.5 px here). The noted largest error is recomputed with
    cv2.projectPoints of each ideal radius against the observed one; the coefficients are the
    normal equations' solution of the distortion factor over that grid."""
    import cv2

    k_px = (4e-8, -3e-14, 2e-20)
    path = tmp_path / "lab.xcp"
    path.write_text(_xcp(_xcp_camera(radial2="Vicon3Parameter 1020.25 540.5 " + " ".join(map(repr, k_px)))))
    parts = reader("vicon")(path)
    cam = parts.cameras["101"]
    f, r_max = 1800.5, 540.5
    r_d = np.linspace(1.0, r_max, 400)
    r_u = r_d * (1 + k_px[0] * r_d**2 + k_px[1] * r_d**4 + k_px[2] * r_d**6)
    rho = r_u / f
    A = np.column_stack([rho**2, rho**4, rho**6])
    expected = np.linalg.solve(A.T @ A, A.T @ (r_d / r_u - 1.0))
    np.testing.assert_allclose(cam.dist[[0, 1, 4]], expected, rtol=1e-9, atol=0)
    assert cam.dist[2] == 0.0 and cam.dist[3] == 0.0
    pts = np.column_stack([rho, np.zeros_like(rho), np.ones_like(rho)])
    uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), np.diag([f, f, 1.0]), cam.dist)
    worst = np.max(np.abs(uv.reshape(-1, 2)[:, 0] - r_d))
    assert 1e-4 < worst < 0.5
    assert parts.notes[1] == (f"Vicon radial distortion (pixel units, taken as the correction of observed pixels) "
                              f"refitted as OpenCV k1 k2 k3: largest error {worst:.3g} px within the circle inscribed "
                              "in the sensor")


def test_vicon_older_two_term_radial_about_the_principal_point(tmp_path):
    """``VICON_RADIAL="k1 k2"``: centred on the principal point, k3 = 0: the same fit as
    VICON_RADIAL2 with that centre and a zero third term."""
    older, newer = tmp_path / "a.xcp", tmp_path / "b.xcp"
    older.write_text(_xcp(_xcp_camera(radial2=None, radial="4e-08 -3e-14")))
    newer.write_text(_xcp(_xcp_camera(radial2="Vicon3Parameter 1020.25 540.5 4e-08 -3e-14 0")))
    a, b = reader("vicon")(older).cameras["101"], reader("vicon")(newer).cameras["101"]
    np.testing.assert_array_equal(a.dist, b.dist)
    assert a.dist[0] < 0


def test_vicon_distortion_centre_within_two_pixels_is_accepted():
    """CENTRE_TOL_PX: exactly 2 px from the principal point is within; 2.01 px is not."""
    from calibration.formats.vicon import _camera
    import xml.etree.ElementTree as ET

    ok = ET.fromstring(_xcp_camera(radial2="Vicon3Parameter 1022.25 540.5 0 0 0"))
    assert _camera(ok)[0].name == "101"
    far = ET.fromstring(_xcp_camera(radial2="Vicon3Parameter 1020.25 542.51 0 0 0"))
    assert_error(raised(_camera, far), "distortion centre (1020.2, 542.5) is 2.0 px from the principal point: "
                 "OpenCV needs them within 2 px", camera="101", field="VICON_RADIAL2")


@pytest.mark.parametrize("kw, detail, camera, field", [
    (dict(dev=None, user=None), "<Camera> without DEVICEID", None, "DEVICEID"),
    (dict(keyframe=False), "missing", "101", "KeyFrames/KeyFrame"),
    (dict(sensor=None), "missing", "101", "SENSOR_SIZE"),
    (dict(sensor="2048 a"), "expected 2 numbers, got '2048 a'", "101", "SENSOR_SIZE"),
    (dict(sensor="2048 1088 3"), "expected 2 finite numbers, got '2048 1088 3'", "101", "SENSOR_SIZE"),
    (dict(sensor="2048 nan"), "expected 2 finite numbers, got '2048 nan'", "101", "SENSOR_SIZE"),
    (dict(aspect="x"), "not a number: 'x'", "101", "Camera.PIXEL_ASPECT_RATIO"),
    (dict(focal=None), "missing", "101", "KeyFrame.FOCAL_LENGTH"),
    (dict(pp="1020.25"), "expected 2 finite numbers, got '1020.25'", "101", "PRINCIPAL_POINT"),
    (dict(radial2="Vicon3Parameter 1020.25 540.5 0 0"),
     "expected 'Vicon3Parameter cx cy k1 k2 k3', got 'Vicon3Parameter 1020.25 540.5 0 0'", "101", "VICON_RADIAL2"),
    (dict(radial2="Vicon2Parameter 1020.25 540.5 0 0 0"),
     "expected 'Vicon3Parameter cx cy k1 k2 k3', got 'Vicon2Parameter 1020.25 540.5 0 0 0'", "101", "VICON_RADIAL2"),
    (dict(radial2=""), "expected 'Vicon3Parameter cx cy k1 k2 k3', got ''", "101", "VICON_RADIAL2"),
    (dict(radial2="Vicon3Parameter 1020.25 540.5 0 0 inf"),
     "expected 5 finite numbers, got '1020.25 540.5 0 0 inf'", "101", "VICON_RADIAL2"),
    (dict(radial2=None, radial="1e-8"), "expected 2 finite numbers, got '1e-8'", "101", "VICON_RADIAL"),
    (dict(pp="1 540.5", radial2=None), "principal point (1, 540.5) outside the 2048x1088 sensor", "101",
     "PRINCIPAL_POINT"),
    (dict(pp="1020.25 1087", radial2=None), "principal point (1020.25, 1087) outside the 2048x1088 sensor", "101",
     "PRINCIPAL_POINT"),
    (dict(pp="2047.5 540", radial2=None), "principal point (2047.5, 540) outside the 2048x1088 sensor", "101",
     "PRINCIPAL_POINT"),
    (dict(pp="1020 0.5", radial2=None), "principal point (1020, 0.5) outside the 2048x1088 sensor", "101",
     "PRINCIPAL_POINT"),
    (dict(q=(0.0, 0.0, 0.0, 0.0)),
     "quaternion_to_matrix: a quaternion of zero or non-finite norm is not a rotation: [0.0, 0.0, 0.0, 0.0]",
     "101", "ORIENTATION"),
    (dict(q=(0.0, 0.0, 1.0)), "expected 4 finite numbers, got '0.0 0.0 1.0'", "101", "ORIENTATION"),
    (dict(pos="1 2"), "expected 3 finite numbers, got '1 2'", "101", "POSITION"),
])
def test_vicon_bad_input_names_camera_and_field(tmp_path, kw, detail, camera, field):
    path = tmp_path / "lab.xcp"
    path.write_text(_xcp(_xcp_camera(**kw)))
    assert_error(raised(reader("vicon"), path), detail, camera=camera, field=field, file=path)


def test_vicon_file_level_errors(tmp_path):
    path = tmp_path / "lab.xcp"
    path.write_text(_xcp(_xcp_camera(), _xcp_camera(user="2")))
    assert_error(raised(reader("vicon"), path), "two <Camera> entries share this DEVICEID", camera="101",
                 field="DEVICEID", file=path)
    path.write_text(_xcp())
    assert_error(raised(reader("vicon"), path), "no <Camera> elements", field="Camera", file=path)
    path.write_text("<Cameras>")
    assert_error(raised(reader("vicon"), path), "not valid XML (no element found: line 1, column 9)", file=path)
    assert_error(raised(reader("vicon"), tmp_path), "cannot read (Is a directory)", file=tmp_path)


# ------------------------------------------------------------------------------------------ Qualisys
def _qca_camera(serial="1", cam_id=None, active="1", residual="0.4", drop=(), skew="0.25", k3="0.001",
                fov=(64, 1087, 32, 575)) -> str:
    """A QTM camera whose video field of view (64..1087 × 32..575, inclusive: 1024 × 544 px)
    is half the 2048 × 1088 sensor (sensorMin/Max in 1/64 px, V starting at 8 px)."""
    r = Rotation.from_rotvec([0.4, -0.3, 2.0]).as_matrix()
    left, right, top, bottom = fov
    elems = {
        "fov_video": {"left": left, "right": right, "top": top, "bottom": bottom},
        "intrinsic": {"sensorMinU": 64 * 4, "sensorMaxU": 64 * 2051, "sensorMinV": 64 * 8, "sensorMaxV": 64 * 1095,
                      "focalLengthU": 64 * 1800, "focalLengthV": 64 * 1802, "centerPointU": 64 * 1000,
                      "centerPointV": 64 * 560, "skew": skew, "radialDistortion1": "-0.05",
                      "radialDistortion2": "0.14", "radialDistortion3": k3, "tangentalDistortion1": "0.0006",
                      "tangentalDistortion2": "-0.0007"},
        "transform": {"x": "1460.5", "y": "-1909.25", "z": "1896.75",
                      **{f"r{i + 1}{j + 1}": repr(float(r[i, j])) for i in range(3) for j in range(3)}},
    }
    attrs = {"serial": serial, "id": cam_id, "active": active, "avg-residual": residual}
    head = "<camera " + " ".join(f'{k}="{v}"' for k, v in attrs.items() if v is not None) + ">"
    body = "".join(f"<{tag} " + " ".join(f'{k}="{v}"' for k, v in values.items() if k not in drop and v is not None)
                   + "/>" for tag, values in elems.items() if tag not in drop)
    return head + body + "</camera>"


def _qca(*cameras) -> str:
    return "<?xml version='1.0' encoding='ASCII'?><calibration><cameras>" + "".join(cameras) + "</cameras></calibration>"


QCA_R = Rotation.from_rotvec([0.4, -0.3, 2.0]).as_matrix()


def test_qualisys_field_of_view_scaling_pose_and_metadata(tmp_path):
    """Sensor 2048 × 1088 px ((max - min) / 64 + 1), video 1024 × 544: scale ½ both ways, so
    fx = 1800 · ½ = 900, fy = 901, cx = (1000 - 64) · ½ = 468, cy = (560 - 32) · ½ = 264;
    R = diag(1, -1, -1) · r, centre in mm / 1000, t = -R · centre. An inactive camera is skipped;
    one without a serial is named by its id."""
    path = tmp_path / "Calib.qca.txt"
    path.write_text(_qca(_qca_camera("off", active="0"), _qca_camera(), _qca_camera(serial=None, cam_id="5",
                                                                                    residual=None, skew=None, k3=None)))
    parts = reader("qualisys")(path)
    assert list(parts.cameras) == ["1", "5"]
    cam = parts.cameras["1"]
    np.testing.assert_array_equal(cam.K, [[900.0, 0.25, 468.0], [0.0, 901.0, 264.0], [0.0, 0.0, 1.0]])
    assert cam.size == (1024, 544)
    np.testing.assert_array_equal(cam.dist, [-0.05, 0.14, 0.0006, -0.0007, 0.001])
    R = np.diag([1.0, -1.0, -1.0]) @ QCA_R
    np.testing.assert_allclose(cam.R, R, rtol=0, atol=1e-15)
    np.testing.assert_allclose(cam.center, [1.4605, -1.90925, 1.89675], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(parts.cameras["5"].K[0, 1], 0.0)
    np.testing.assert_array_equal(parts.cameras["5"].dist, [-0.05, 0.14, 0.0006, -0.0007, 0.0])
    assert parts.metadata == {"source": "qualisys", "avg_residual": {"1": 0.4}}
    assert parts.notes == ("Qualisys camera centres are in mm by the format: converted to metres on reading",)
    assert (parts.units, parts.units_fixed, parts.own_frame) == ("m", True, False)


@pytest.mark.parametrize("cameras, detail, camera, field", [
    ([_qca_camera(serial=None)], "camera without a serial", None, "serial"),
    ([_qca_camera(drop=("fov_video",))], "missing", "1", "fov_video"),
    ([_qca_camera(drop=("left",))], "missing", "1", "fov_video.left"),
    ([_qca_camera(drop=("right",))], "missing", "1", "fov_video.right"),
    ([_qca_camera(drop=("top",))], "missing", "1", "fov_video.top"),
    ([_qca_camera(drop=("bottom",))], "missing", "1", "fov_video.bottom"),
    ([_qca_camera(drop=("intrinsic",))], "missing", "1", "intrinsic"),
    ([_qca_camera(drop=("centerPointV",))], "missing", "1", "intrinsic.centerPointV"),
    ([_qca_camera(drop=("transform",))], "missing", "1", "transform"),
    ([_qca_camera(drop=("r23",))], "missing", "1", "transform.r23"),
    ([_qca_camera(drop=("z",))], "missing", "1", "transform.z"),
    ([_qca_camera(), _qca_camera("2"), _qca_camera()],
     "<camera> entries 0 and 2 share serial '1': expected one entry per camera", None, "serial"),
    ([_qca_camera(active="0")], "no active <camera> elements", None, "cameras"),
])
def test_qualisys_bad_cameras_name_camera_and_field(tmp_path, cameras, detail, camera, field):
    path = tmp_path / "Calib.qca.txt"
    path.write_text(_qca(*cameras))
    assert_error(raised(reader("qualisys"), path), detail, camera=camera, field=field, file=path)


def test_qualisys_invalid_xml_names_the_format(tmp_path):
    path = tmp_path / "Calib.qca.txt"
    path.write_text("<calibration><cameras></calibration>")
    assert_error(raised(reader("qualisys"), path), "not valid Qualisys XML (mismatched tag: line 1, column 24)",
                 file=path)


# ------------------------------------------------------------------------------------------ rounding bounds
def sheared(e: float) -> np.ndarray:
    """A rotation part off by exactly ``e`` = max |M Mᵀ - I| (the off-diagonal product e·1)."""
    M = np.eye(3)
    M[0, 1] = e
    assert np.max(np.abs(M @ M.T - np.eye(3))) == e
    return M


@pytest.mark.parametrize("fmt", ["multical", "kalibr", "optitrack"])
def test_rounding_tolerances_at_their_bounds(tmp_path, fmt):
    """ROUNDING_TOL (1e-4) is the largest error put down to rounding: at exactly 1e-4 the
    nearest rotation (SVD here) is taken; up to 1e-6 the matrix is a rotation as written."""

    def load(M):
        if fmt == "multical":
            path = tmp_path / "calibration.json"
            path.write_text(json.dumps(_multical_doc({"cam1": _entry(M, [0, 0, 1])}, names=("cam1",))))
            return reader(fmt)(path).cameras["cam1"].R
        if fmt == "kalibr":
            path = tmp_path / "camchain.yaml"
            path.write_text(yaml.safe_dump({"cam0": _kalibr_cam(), "cam1": _kalibr_cam(T_cn_cnm1=homogeneous(
                M, [0.1, 0, 0]).tolist())}))
            return reader(fmt)(path).cameras["cam1"].R
        path = tmp_path / "lab.mcal"
        path.write_text(_mcal(_mcal_camera(orient=M)))
        turn = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
        return np.diag([1.0, -1.0, -1.0]).T @ reader(fmt)(path).cameras["M1"].R @ turn  # back to OrientMatrixᵀ

    at_bound = load(sheared(1e-4))
    expected = svd_rotation(sheared(1e-4))
    np.testing.assert_allclose(at_bound, expected.T if fmt == "optitrack" else expected, rtol=0, atol=1e-15)
    exact = load(sheared(1e-6))
    if fmt == "optitrack":  # the reader always takes the nearest rotation of OrientMatrix
        np.testing.assert_allclose(exact, svd_rotation(sheared(1e-6)).T, rtol=0, atol=1e-15)
    else:
        np.testing.assert_array_equal(exact, sheared(1e-6))
