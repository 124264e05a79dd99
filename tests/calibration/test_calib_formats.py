"""Calibration files: native JSON, OpenCV YAML, Pose2Sim TOML, COLMAP, Qualisys.

Round trips use a rig with a non-default value in every field (skew-free K with fx != fy
and an off-centre principal point, all distortion terms set, rotations far from identity,
a tilted and offset ground plane, nested metadata) and must agree to 1e-9.
"""

import json
import shutil

import cv2
import numpy as np
import pytest

from calibration import CalibrationError, Camera, GroundPlane, RigCalibration
from calibration.rotation import rotvec_to_matrix
from calibration.formats import detect_format, write

POSE2SIM = "calibration/pose2sim_demo_4cam"
POSE2SIM_TOML = "Calib_scene.pose2sim_output_at_1bcde0685195.toml"


def make_rig(n_dist=8) -> RigCalibration:
    rng = np.random.default_rng(7)
    cams = {}
    for i, name in enumerate(["cam_a", "02", "side-left"]):
        K = np.array([[900.0 + 13.7 * i, 0.0, 317.3 + i], [0.0, 905.25 - i, 243.9 - 2 * i], [0.0, 0.0, 1.0]])
        dist = rng.normal(0.0, 0.02, n_dist)
        R = rotvec_to_matrix(rng.normal(0.0, 1.2, 3))
        t = rng.normal(0.0, 2.0, 3)
        cams[name] = Camera(name, K, dist, R, t, (640 + 16 * i, 480 - 8 * i))
    ground = GroundPlane.from_point_normal([0.0, 0.0, 0.037], [0.02, -0.05, 1.0])
    meta = {"operator": "ab", "session": 3, "nested": {"rms_px": [0.21, 0.35], "ok": True}}
    return RigCalibration(cams, ground, meta)


def assert_same(a: RigCalibration, b: RigCalibration, atol=1e-9):
    assert a.camera_names == b.camera_names
    for name in a.camera_names:
        ca, cb = a[name], b[name]
        assert ca.size == cb.size, name
        assert ca.model == cb.model, name
        np.testing.assert_allclose(cb.K, ca.K, rtol=0, atol=atol)
        n = max(ca.dist.size, cb.dist.size)
        np.testing.assert_allclose(np.pad(cb.dist, (0, n - cb.dist.size)), np.pad(ca.dist, (0, n - ca.dist.size)), rtol=0, atol=atol)
        np.testing.assert_allclose(cb.R, ca.R, rtol=0, atol=atol)
        np.testing.assert_allclose(cb.t, ca.t, rtol=0, atol=atol)
    np.testing.assert_allclose(b.ground.normal, a.ground.normal, rtol=0, atol=atol)
    assert abs(b.ground.offset - a.ground.offset) <= atol
    for key, value in a.metadata.items():
        assert b.metadata[key] == value


# ---------------------------------------------------------------- round trips
def test_native_round_trip_is_exact(tmp_path):
    rig = make_rig()
    path = rig.save(tmp_path / "calibration.json")
    doc = json.loads(path.read_text())
    assert doc["format"] == "studio.rig-calibration" and doc["version"] == 1 and doc["units"] == "m"
    back = RigCalibration.load(path)
    assert_same(rig, back, atol=0.0)
    assert back.metadata == rig.metadata
    assert not list(tmp_path.glob(".*tmp"))  # no temporary left behind


def test_opencv_round_trip(tmp_path):
    rig = make_rig()
    intri, extri = rig.to_opencv(tmp_path / "ocv")
    assert intri.read_text().startswith("%YAML:1.0")
    fs = cv2.FileStorage(str(extri), cv2.FILE_STORAGE_READ)  # EasyMocap's layout
    np.testing.assert_allclose(cv2.Rodrigues(fs.getNode("R_02").mat())[0], fs.getNode("Rot_02").mat(), atol=1e-12)
    assert fs.getNode("T_02").mat().shape == (3, 1)
    fs.release()
    back = RigCalibration.from_opencv(intri, extri)
    assert_same(rig, back)
    assert back.metadata == rig.metadata
    assert_same(rig, RigCalibration.load_any(tmp_path / "ocv"))
    assert_same(rig, RigCalibration.load_any(extri))


def test_toml_round_trip(tmp_path):
    rig = make_rig()
    path = rig.to_toml(tmp_path / "Calib.toml")
    back = RigCalibration.from_toml(path)
    assert_same(rig, back)
    assert back.metadata["adjusted"] is False  # Pose2Sim's metadata keys are kept
    assert 'name = "side-left"' in path.read_text()


@pytest.mark.parametrize("n_dist", [0, 4, 5, 8])
def test_colmap_round_trip(tmp_path, n_dist):
    rig = make_rig(n_dist)
    rig.to_colmap(tmp_path / "sparse")
    assert_same(rig, RigCalibration.from_colmap(tmp_path / "sparse"))
    rig.to_colmap(tmp_path / "sparse", binary=True)
    assert not (tmp_path / "sparse" / "cameras.txt").exists()
    assert_same(rig, RigCalibration.load_any(tmp_path / "sparse"))


def test_colmap_pixel_convention_matches_pycolmap(tmp_path):
    """Our pixel = COLMAP's pixel - 0.5: check with pycolmap's own projection."""
    import pycolmap

    rig = make_rig(8)
    rig.to_colmap(tmp_path)
    rec = pycolmap.Reconstruction(str(tmp_path))
    cam = rig["02"]
    image = next(im for im in rec.images.values() if im.name == "02")
    X = cam.center + 3.0 * cam.R[2] + np.array([[0.1, -0.2, 0.05], [-0.3, 0.1, 0.2]])
    ours = cam.project(X)
    Xc = (image.cam_from_world().rotation.matrix() @ X.T).T + image.cam_from_world().translation
    theirs = np.asarray(image.camera.img_from_cam(Xc))
    np.testing.assert_allclose(theirs - ours, 0.5, atol=1e-7)
    assert json.loads((tmp_path / "studio_rig.json").read_text())["ground"]["offset"] == pytest.approx(rig.ground.offset)


def test_chain_native_opencv_toml_colmap_native(tmp_path):
    rig = make_rig()
    rig.save(tmp_path / "a.json")
    r = RigCalibration.load(tmp_path / "a.json")
    r.to_opencv(tmp_path / "ocv")
    r = RigCalibration.from_opencv(tmp_path / "ocv")
    r.to_toml(tmp_path / "b.toml")
    r = RigCalibration.from_toml(tmp_path / "b.toml")
    r.to_colmap(tmp_path / "col")
    r = RigCalibration.from_colmap(tmp_path / "col")
    r.save(tmp_path / "c.json")
    final = RigCalibration.load(tmp_path / "c.json")
    assert_same(rig, final)
    assert rig.allclose(final) and not rig.allclose(final.replace(ground=GroundPlane.floor()))


def test_generic_read_write_dispatch(tmp_path):
    rig = make_rig()
    for target, fmt in [("x.json", "native"), ("x.toml", "toml"), ("intri.yml", "opencv")]:
        write(rig, tmp_path / target)
        assert detect_format(tmp_path / target) == fmt
        assert_same(rig, RigCalibration.load_any(tmp_path / target))
    write(rig, tmp_path / "col", "colmap")
    assert detect_format(tmp_path / "col") == "colmap"
    assert detect_format(tmp_path / "col" / "cameras.txt") == "colmap"
    assert_same(rig, RigCalibration.load_any(tmp_path / "col" / "cameras.txt"))
    with pytest.raises(CalibrationError, match="cannot tell the calibration format"):
        detect_format(tmp_path / "x.xyz")
    (tmp_path / "empty").mkdir()
    with pytest.raises(CalibrationError, match="neither intri.yml"):
        detect_format(tmp_path / "empty")
    with pytest.raises(CalibrationError, match="say which format"):
        detect_format(tmp_path / "empty", for_writing=True)
    with pytest.raises(CalibrationError, match="no such file"):
        RigCalibration.load_any(tmp_path / "missing.json")
    with pytest.raises(CalibrationError, match="unknown format 'bogus'"):
        RigCalibration.load_any(tmp_path / "x.json", "bogus")
    with pytest.raises(CalibrationError, match="cannot write format 'qualisys'"):
        write(rig, tmp_path / "y.qca.txt", "qualisys")


# ---------------------------------------------------------------- real data
def test_pose2sim_real_calibration_agrees_with_qualisys(shared_data, tmp_path):
    """Pose2Sim's own checkerboard/scene calibration vs the Qualisys hardware calibration of
    the same 4 cameras (SOURCE.md): focal lengths within 2 %, principal points within 50 px
    (few checkerboard views), camera centres within 0.2 m and orientations within 5 deg."""
    folder = shared_data / POSE2SIM
    p2s = RigCalibration.load_any(folder / POSE2SIM_TOML)
    qtm = RigCalibration.load_any(folder / "Calib.qca.txt")
    assert p2s.camera_names == ["int_cam01_img", "int_cam02_img", "int_cam03_img", "int_cam04_img"]
    assert qtm.camera_names == ["cam01", "cam02", "cam03", "cam04"]
    cam01 = p2s["int_cam01_img"]
    assert cam01.size == (1088, 1920)
    np.testing.assert_allclose([cam01.K[0, 0], cam01.K[0, 2], cam01.K[1, 2]], [1671.50, 564.64, 933.01], atol=0.01)
    q01 = qtm["cam01"]  # SOURCE.md: fx 1681.2 fy 1681.1 cx 533.0 cy 948.1
    np.testing.assert_allclose([q01.K[0, 0], q01.K[1, 1], q01.K[0, 2], q01.K[1, 2]], [1681.2, 1681.1, 533.0, 948.1], atol=0.06)
    for a, b in zip(p2s, qtm):
        assert a.size == b.size
        np.testing.assert_allclose(np.diag(a.K)[:2], np.diag(b.K)[:2], rtol=0.02)
        np.testing.assert_allclose(a.K[:2, 2], b.K[:2, 2], atol=50)
        assert np.linalg.norm(a.center - b.center) < 0.2
        angle = np.degrees(np.arccos(np.clip((np.trace(a.R @ b.R.T) - 1) / 2, -1, 1)))
        assert angle < 5.0
    # the real calibration goes through every format unchanged
    p2s.to_opencv(tmp_path / "ocv")
    p2s.to_colmap(tmp_path / "col")
    p2s.to_toml(tmp_path / "c.toml")
    for path in (tmp_path / "ocv", tmp_path / "col", tmp_path / "c.toml"):
        assert_same(p2s, RigCalibration.load_any(path))


def test_pose2sim_toml_projects_scene_points_consistently(shared_data):
    """The 4 cameras see the same floor point: back-project from cam01, reproject elsewhere."""
    rig = RigCalibration.load_any(shared_data / POSE2SIM / POSE2SIM_TOML)
    X = np.array([[0.0, 0.0, 0.0], [0.5, 0.3, 0.0]])
    uv = rig["int_cam01_img"].project(X)
    back = rig.ground.pixel_to_ground(rig["int_cam01_img"], uv)
    np.testing.assert_allclose(back, X, atol=1e-9)
    for cam in rig:
        assert cam.in_image(cam.project(X)).all(), cam.name


# ---------------------------------------------------------------- bad input
def _native_doc():
    return json.loads(json.dumps({"format": "studio.rig-calibration", "version": 1, "units": "m",
                                  "cameras": {n: c.to_dict() for n, c in make_rig().cameras.items()},
                                  "ground": {"normal": [0, 0, 1], "offset": 0.0}, "metadata": {}}))


def _edit(doc, change):
    change(doc)
    return doc


NATIVE_BAD = [
    (lambda d: d.update(version=2), r"field 'version': unknown major version 2"),
    (lambda d: d.update(version="x"), r"field 'version': expected an integer"),
    (lambda d: d.pop("version"), r"field 'version': missing"),
    (lambda d: d.update(format="other"), r"field 'format'"),
    (lambda d: d.update(units="mm"), r"field 'units'"),
    (lambda d: d.update(cameras={}), r"field 'cameras': missing or empty"),
    (lambda d: d["cameras"]["02"].pop("K"), r"camera '02': field 'K': missing"),
    (lambda d: d["cameras"]["02"].update(K=[[1, 0], [0, 1]]), r"camera '02': field 'K': expected shape \(3, 3\)"),
    (lambda d: d["cameras"]["cam_a"]["t"].__setitem__(1, float("nan")), r"camera 'cam_a': field 't': contains NaN"),
    (lambda d: d["cameras"]["cam_a"]["R"][0].__setitem__(0, 2.0), r"camera 'cam_a': field 'R': not orthonormal"),
    (lambda d: d["cameras"].update(x=[1, 2]), r"camera 'x': expected a mapping"),
    (lambda d: d.update(ground={"normal": [0, 0, 1]}), r"field 'ground': expected \{normal, offset\}"),
    (lambda d: d.update(ground={"normal": [0, 0, 3], "offset": 0}), r"field 'ground.normal'"),
    (lambda d: d.update(metadata=[1]), r"field 'metadata': expected a mapping"),
]


@pytest.mark.parametrize("change, message", NATIVE_BAD)
def test_native_bad_input_names_file_camera_field(tmp_path, change, message):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(_edit(_native_doc(), change)))
    with pytest.raises(CalibrationError, match=r"bad\.json: " + message) as info:
        RigCalibration.load(path)
    assert info.value.file == str(path)


def test_native_unwritable_metadata(tmp_path):
    rig = make_rig().replace(metadata={"when": object()})
    with pytest.raises(CalibrationError, match=r"x\.json: field 'metadata': metadata cannot be written as JSON"):
        rig.save(tmp_path / "x.json")
    with pytest.raises(CalibrationError, match=r"field 'metadata': metadata cannot be written as JSON"):
        make_rig().replace(metadata={"nan": float("nan")}).save(tmp_path / "x.json")
    assert not (tmp_path / "x.json").exists()


def test_native_unreadable_files(tmp_path):
    (tmp_path / "a.json").write_text("{not json")
    with pytest.raises(CalibrationError, match=r"a\.json: not valid JSON"):
        RigCalibration.load(tmp_path / "a.json")
    (tmp_path / "b.json").write_text("[1, 2]")
    with pytest.raises(CalibrationError, match=r"b\.json: expected a JSON object"):
        RigCalibration.load(tmp_path / "b.json")
    with pytest.raises(CalibrationError, match=r"nope\.json: cannot read"):
        RigCalibration.load(tmp_path / "nope.json")


def test_rig_construction_errors():
    cam = make_rig()["02"]
    with pytest.raises(CalibrationError, match="at least one camera"):
        RigCalibration({})
    with pytest.raises(CalibrationError, match=r"camera 'x': field 'name': listed under 'x' but named '02'"):
        RigCalibration({"x": cam})
    with pytest.raises(CalibrationError, match=r"camera 'x': expected a Camera"):
        RigCalibration({"x": 3})
    with pytest.raises(CalibrationError, match=r"field 'ground': expected a GroundPlane"):
        RigCalibration([cam], ground=3)
    rig = RigCalibration([cam])
    assert rig.camera_names == ["02"] and "02" in rig and len(rig) == 1
    assert rig.ground.allclose(GroundPlane.floor())
    with pytest.raises(KeyError, match="no camera 'zz'"):
        rig["zz"]
    assert make_rig().subset(["side-left", "02"]).camera_names == ["side-left", "02"]
    uv = make_rig().project(np.array([0.0, 0.0, 0.0]))
    assert set(uv) == {"cam_a", "02", "side-left"} and uv["02"].shape == (1, 2)


TOML_OK = """[cam_0]
name = "{name}"
size = [ 640.0, 480.0]
matrix = [ [ 800.0, 0.0, 320.0], [ 0.0, 800.0, 240.0], [ 0.0, 0.0, 1.0]]
distortions = [ 0.01, 0.0, 0.0, 0.0]
rotation = {rotation}
translation = [ 0.0, 0.0, 3.0]
fisheye = {fisheye}
"""


@pytest.mark.parametrize(
    "text, message",
    [
        (TOML_OK.format(name="A", rotation="[0.0, 0.0]", fisheye="false"), r"camera 'A': field 'rotation': expected a Rodrigues"),
        (TOML_OK.format(name="A", rotation="[0.0, 0.0, 0.1]", fisheye="1"), r"camera 'A': field 'fisheye': expected true or false"),
        (TOML_OK.format(name="A", rotation='["a", 0.0, 0.1]', fisheye="false"), r"camera 'A': field 'rotation': not numeric"),
        (TOML_OK.format(name="A", rotation="[0.0, 0.0, 0.1]", fisheye="false").replace("matrix", "matrixx"), r"camera 'A': field 'matrix': missing"),
        (TOML_OK.format(name="A", rotation="[0.0, 0.0, 0.1]", fisheye="false").replace("[ 640.0, 480.0]", "640"), r"camera 'A': field 'size': expected \[width, height\]"),
        (TOML_OK.format(name="A", rotation="[0.0, 0.0, 0.1]", fisheye="false").replace("3.0]", "3.0, 1.0]"), r"camera 'A': field 't': expected shape"),
        (TOML_OK.format(name="A", rotation="[0.0, 0.0, 0.1]", fisheye="false") * 1 + TOML_OK.format(name="A", rotation="[0.0, 0.0, 0.1]", fisheye="false").replace("cam_0", "cam_1"), r"camera 'A': field 'name': camera name used twice"),
        ("[metadata]\nerror = 0.0\n", r"field 'cameras': no camera tables"),
        ("[cam_0]\nx = \n", r"not valid TOML"),
        ("cam_0 = 3\n", r"camera 'cam_0': expected a table"),
        (TOML_OK.format(name="A", rotation="[0.0, 0.0, 0.1]", fisheye="false") + "[metadata]\nstudio_ground = 3\n", r"field 'metadata.studio_ground'"),
    ],
)
def test_toml_bad_input(tmp_path, text, message):
    path = tmp_path / "Calib.toml"
    path.write_text(text)
    with pytest.raises(CalibrationError, match=r"Calib\.toml: .*" + message):
        RigCalibration.from_toml(path)


def test_toml_anipose_layout_and_matrix_rotation(tmp_path):
    """anipose sections are cam_0.. with a name field; some writers store R as 3x3."""
    path = tmp_path / "calibration.toml"
    path.write_text(TOML_OK.format(name="A", rotation="[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]", fisheye="false"))
    rig = RigCalibration.load_any(path, z_down="keep")
    assert rig.camera_names == ["A"] and rig["A"].size == (640, 480)
    np.testing.assert_array_equal(rig["A"].R, np.eye(3))
    assert rig.ground.allclose(GroundPlane.floor())
    # R = I and t = (.., 3): the camera stands 3 m below the floor z = 0 — a Z-down world,
    # which a plain load turns half a turn about X (the camera projects as before)
    flipped = RigCalibration.from_toml(path)
    np.testing.assert_array_equal(flipped["A"].R, np.diag([1.0, -1.0, -1.0]))
    assert flipped["A"].center[2] > 2.9 and any("turned half a turn about X" in n for n in flipped.notes)


def test_toml_write_errors(tmp_path):
    cam = make_rig()["02"]
    with pytest.raises(CalibrationError, match="camera 'metadata'"):
        RigCalibration([cam.replace(name="metadata")]).to_toml(tmp_path / "a.toml")
    with pytest.raises(CalibrationError, match=r"field 'metadata': metadata cannot be written"):
        RigCalibration([cam], metadata={"x": None}).to_toml(tmp_path / "a.toml")


def _ocv_files(tmp_path, rig=None):
    rig = rig or make_rig(5)
    intri, extri = rig.to_opencv(tmp_path)
    return intri, extri


def _rewrite(path, old, new):
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))


def test_opencv_rotation_disagreement(tmp_path):
    """Rot_<cam> and R_<cam> both present but describing different rotations."""
    intri, extri = _ocv_files(tmp_path)
    rig = make_rig(5)
    bad_R = rig["02"].replace(R=rotvec_to_matrix([0.1, 0.2, 0.3]))
    rig.replace(cameras={**rig.cameras, "02": bad_R}).to_opencv(tmp_path / "other")
    # splice the other file's R_02 (rvec) into ours: Rot_02 and R_02 now disagree
    other = (tmp_path / "other" / "extri.yml").read_text()
    ours = extri.read_text()
    seg = lambda s: s[s.index("R_02:"): s.index("Rot_02:")]  # noqa: E731
    extri.write_text(ours.replace(seg(ours), seg(other)))
    with pytest.raises(CalibrationError, match=r"extri\.yml: camera '02': field 'Rot_02': disagrees with R_02"):
        RigCalibration.from_opencv(intri, extri)


@pytest.mark.parametrize(
    "which, old, new, message",
    [
        ("intri", "K_02:", "Kx_02:", r"intri\.yml: camera '02': field 'K_02': missing"),
        ("extri", "T_02:", "Tx_02:", r"extri\.yml: camera '02': field 'T_02': missing"),
        ("intri", "names:", "nams:", r"intri\.yml: field 'names': missing"),
        ("extri", '- "02"', '- "03"', r"extri\.yml: camera '02': field 'names': listed in intri"),
        ("intri", "K_02: !!opencv-matrix\n   rows: 3\n   cols: 3", "K_02: !!opencv-matrix\n   rows: 1\n   cols: 9", r"intri\.yml: camera '02': field 'K_02': expected shape"),
        ("extri", "T_02: !!opencv-matrix\n   rows: 3\n   cols: 1\n   dt: d\n   data: [ ", "T_02: !!opencv-matrix\n   rows: 3\n   cols: 1\n   dt: d\n   data: [ 7, ", r"extri\.yml: camera '02': field 'T_02': not an OpenCV matrix"),
        ("extri", "ground_offset:", "ground_offset: 1\nground_offsetx:", None),
    ],
)
def test_opencv_missing_and_malformed_fields(tmp_path, which, old, new, message):
    intri, extri = _ocv_files(tmp_path)
    _rewrite(intri if which == "intri" else extri, old, new)
    if message is None:  # a valid edit: the offset is read
        assert RigCalibration.from_opencv(tmp_path).ground.offset == 1.0
        return
    with pytest.raises(CalibrationError, match=message):
        RigCalibration.from_opencv(tmp_path)


def test_opencv_nan_names_file_camera_field(tmp_path):
    intri, extri = _ocv_files(tmp_path)
    text = extri.read_text()
    start = text.index("data: [ ", text.index("T_02:")) + len("data: [ ")
    extri.write_text(text[:start] + ".nan" + text[text.index(",", start):])
    with pytest.raises(CalibrationError, match=r"extri\.yml: camera '02': field 'T_02': contains NaN"):
        RigCalibration.from_opencv(tmp_path)


def test_opencv_rotation_variants_and_guessed_size(tmp_path, caplog):
    intri, extri = _ocv_files(tmp_path)
    rig = RigCalibration.from_opencv(tmp_path)
    # only the Rodrigues vector (older EasyMocap files)
    text = extri.read_text()
    for name in rig.camera_names:
        start = text.index(f"Rot_{name}:")
        end = text.index(f"T_{name}:")
        text = text[:start] + text[end:]
    extri.write_text(text)
    assert_same(rig, RigCalibration.from_opencv(tmp_path))
    # without image sizes: guessed from the principal point, with a warning
    text = intri.read_text()
    for name in rig.camera_names:
        text = text.replace(f"H_{name}:", f"Hx_{name}:")
    intri.write_text(text)
    guessed = RigCalibration.from_opencv(tmp_path)
    assert guessed.metadata["size_guessed"] == rig.camera_names
    assert guessed["cam_a"].size == (round(2 * 317.3 + 1), round(2 * 243.9 + 1))
    assert "guessed from the principal point" in caplog.text
    # no rotation at all
    extri.write_text(extri.read_text().replace("R_02:", "Q_02:"))
    with pytest.raises(CalibrationError, match=r"camera '02': field 'R_02': missing \(neither Rot_02 nor R_02\)"):
        RigCalibration.from_opencv(tmp_path)


def test_opencv_file_errors(tmp_path):
    with pytest.raises(CalibrationError, match=r"intri\.yml: no such file"):
        RigCalibration.from_opencv(tmp_path)
    rig = make_rig()
    with pytest.raises(CalibrationError, match=r"camera 'a b': field 'name': camera names must be plain"):
        RigCalibration([rig["02"].replace(name="a b")]).to_opencv(tmp_path)


def test_colmap_errors(tmp_path):
    rig = make_rig()
    skewed = rig["02"].replace(K=np.array([[800.0, 1.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]]))
    with pytest.raises(CalibrationError, match=r"camera '02': field 'K': COLMAP cannot store a skewed K"):
        RigCalibration([skewed]).to_colmap(tmp_path / "a")
    prism = rig["02"].replace(dist=np.r_[np.zeros(8), 0.01, 0, 0, 0])
    with pytest.raises(CalibrationError, match=r"camera '02': field 'dist': thin-prism"):
        RigCalibration([prism]).to_colmap(tmp_path / "a")
    # zero extra terms are fine
    flat = rig["02"].replace(dist=np.r_[rig["02"].dist[:5], np.zeros(9)])
    RigCalibration([flat]).to_colmap(tmp_path / "b")
    assert_same(RigCalibration([flat]), RigCalibration.from_colmap(tmp_path / "b"))
    with pytest.raises(CalibrationError, match="not a COLMAP model folder"):
        RigCalibration.from_colmap(tmp_path)
    # a model that is neither OpenCV pinhole nor cv2.fisheye (FOV: fx fy cx cy omega)
    cams = tmp_path / "b" / "cameras.txt"
    cams.write_text(cams.read_text().replace("FULL_OPENCV", "FOV").replace(
        cams.read_text().splitlines()[-1].split(" ", 4)[-1], " ".join(["800", "800", "320", "240", "0.1"])))
    with pytest.raises(CalibrationError, match=r"camera '02': field 'model': COLMAP camera model FOV"):
        RigCalibration.from_colmap(tmp_path / "b")
    (tmp_path / "b" / "cameras.txt").write_text("garbage line\n")
    with pytest.raises(CalibrationError, match="pycolmap cannot read"):
        RigCalibration.from_colmap(tmp_path / "b")


def test_colmap_reads_simple_models(tmp_path):
    rig = RigCalibration([make_rig()["02"]])
    rig.to_colmap(tmp_path)
    cams = tmp_path / "cameras.txt"
    head, line = cams.read_text().rsplit("\n", 2)[0], cams.read_text().rsplit("\n", 2)[1]
    parts = line.split()
    for model, params, dist in [
        ("SIMPLE_PINHOLE", "900 320.5 240.5", []),
        ("PINHOLE", "900 901 320.5 240.5", []),
        ("SIMPLE_RADIAL", "900 320.5 240.5 0.01", [0.01, 0, 0, 0]),
        ("RADIAL", "900 320.5 240.5 0.01 -0.02", [0.01, -0.02, 0, 0]),
    ]:
        cams.write_text(head + "\n" + " ".join(parts[:1] + [model] + parts[2:4]) + " " + params + "\n")
        cam = RigCalibration.from_colmap(tmp_path)["02"]
        np.testing.assert_allclose(cam.K[:2, 2], [320.0, 240.0])
        np.testing.assert_allclose(cam.dist, dist)


def test_qualisys_bad_input(shared_data, tmp_path):
    src = (shared_data / POSE2SIM / "Calib.qca.txt").read_text()
    bad = tmp_path / "bad.qca.txt"
    bad.write_text(src.replace('focalLengthU="107118.695313"', ""))
    with pytest.raises(CalibrationError, match=r"bad\.qca\.txt: camera 'cam02': field 'intrinsic\.focalLengthU': missing"):
        RigCalibration.from_qualisys(bad)
    bad.write_text(src.replace('x="2582.0136248568124"', 'x="abc"'))
    with pytest.raises(CalibrationError, match=r"camera 'cam02': field 'transform\.x': not a number"):
        RigCalibration.from_qualisys(bad)
    bad.write_text(src.replace("<fov_video ", "<fov_other ", 1))
    with pytest.raises(CalibrationError, match=r"camera 'cam01': field 'fov_video': missing"):
        RigCalibration.from_qualisys(bad)
    bad.write_text(src.replace('serial="cam01"', 'serial=""'))
    with pytest.raises(CalibrationError, match=r"field 'serial'"):
        RigCalibration.from_qualisys(bad)
    bad.write_text(src.replace('active="1"', 'active="0"'))
    with pytest.raises(CalibrationError, match=r"field 'cameras': no active"):
        RigCalibration.from_qualisys(bad)
    bad.write_text("<calibration><cameras>")
    with pytest.raises(CalibrationError, match="not valid Qualisys XML"):
        RigCalibration.from_qualisys(bad)
    with pytest.raises(CalibrationError, match="cannot read"):
        RigCalibration.from_qualisys(tmp_path / "missing.qca.txt")
    # content sniffing: a Qualisys export with another name
    other = tmp_path / "export.txt"
    shutil.copy(shared_data / POSE2SIM / "Calib.qca.txt", other)
    assert detect_format(other) == "qualisys"


# ---------------------------------------------------------------- less common branches
def test_native_version_types(tmp_path):
    for version, ok in [(1, True), ("1.2", True), (True, False), (float("inf"), False)]:
        doc = _native_doc()
        doc["version"] = version
        doc.pop("ground")  # absent ground -> default floor
        path = tmp_path / "v.json"
        path.write_text(json.dumps(doc))
        if ok:
            assert RigCalibration.load(path).ground.allclose(GroundPlane.floor())
        else:
            with pytest.raises(CalibrationError, match=r"v\.json: field 'version': expected an integer"):
                RigCalibration.load(path)


def test_opencv_less_common_layouts(tmp_path):
    rig = make_rig(5)
    intri, extri = rig.to_opencv(tmp_path / "easymocap_intri.yml")
    assert extri.name == "easymocap_extri.yml"  # sibling chosen by name
    # rotation matrix stored under R_ (3x3) is accepted; integer camera names too
    text = extri.read_text()
    for name in rig.camera_names:
        start, end = text.index(f"R_{name}:"), text.index(f"Rot_{name}:")
        text = text[:start] + text[end:].replace(f"Rot_{name}:", f"R_{name}:", 1)
    extri.write_text(text)
    assert_same(rig, RigCalibration.from_opencv(intri))
    single = RigCalibration([rig["02"]])
    i2, e2 = single.to_opencv(tmp_path / "num")
    for f in (i2, e2):
        f.write_text(f.read_text().replace('- "02"', "- 2").replace("_02:", "_2:"))
    assert RigCalibration.from_opencv(tmp_path / "num").camera_names == ["2"]
    for f in (i2, e2):
        f.write_text(f.read_text().replace("- 2", "- 2.5").replace("_2:", "_2.5:"))
    assert RigCalibration.from_opencv(tmp_path / "num").camera_names == ["2.5"]


@pytest.mark.parametrize(
    "which, old, new, message",
    [
        ("intri", 'names:\n   - "02"\n', "names: []\n", r"intri\.yml: field 'names': empty camera list"),
        ("extri", "R_02: !!opencv-matrix\n   rows: 3", "R_02: !!opencv-matrix\n   rows: 1",
         r"extri\.yml: camera '02': field 'R_02': not an OpenCV matrix"),
        ("extri", 'studio_metadata: "', 'studio_metadata: "{', r"extri\.yml: field 'studio_metadata': not JSON"),
        ("intri", "K_02: !!opencv-matrix\n   rows: 3\n   cols: 3\n", "K_02: !!opencv-matrix\n   rows: 1\n   cols: 9\n",
         r"intri\.yml: camera '02': field 'K_02': expected shape \(3, 3\)"),
    ],
    ids=["names", "rvec-shape", "metadata", "K-shape"],
)
@pytest.mark.parametrize("with_size", [True, False], ids=["size", "no-size"])
def test_opencv_more_bad_input(tmp_path, which, old, new, message, with_size):
    rig = RigCalibration([make_rig(5)["02"]])
    intri, extri = rig.to_opencv(tmp_path)
    _rewrite(intri if which == "intri" else extri, old, new)
    if not with_size:  # the size guess from K must not hide a malformed K
        _rewrite(intri, "H_02:", "Hx_02:")
    with pytest.raises(CalibrationError, match=message):
        RigCalibration.from_opencv(tmp_path)


def test_opencv_bad_ground_names_file_and_field(tmp_path):
    _, extri = RigCalibration([make_rig(5)["02"]]).to_opencv(tmp_path)
    text = extri.read_text()
    start = text.index("data: [ ", text.index("ground_normal:")) + len("data: [ ")
    extri.write_text(text[:start] + "5., " + text[text.index(",", start) + 1 :])
    with pytest.raises(CalibrationError, match=r"extri\.yml: field 'ground\.normal': normal must have unit"):
        RigCalibration.from_opencv(tmp_path)


def test_opencv_rvec_wrong_length(tmp_path):
    rig = RigCalibration([make_rig(5)["02"]])
    intri, extri = rig.to_opencv(tmp_path)
    text = extri.read_text()
    start, end = text.index("Rot_02:"), text.index("T_02:")
    text = text[:start] + text[end:]
    text = text.replace("R_02: !!opencv-matrix\n   rows: 3\n   cols: 1", "R_02: !!opencv-matrix\n   rows: 2\n   cols: 1")
    s = text.index("data: [ ", text.index("R_02:")) + len("data: [ ")
    text = text[:s] + text[text.index(",", s) + 1 :]
    extri.write_text(text)
    with pytest.raises(CalibrationError, match=r"camera '02': field 'R_02': expected a 3x1 Rodrigues vector"):
        RigCalibration.from_opencv(tmp_path)


def test_opencv_garbage_file(tmp_path):
    (tmp_path / "intri.yml").write_text("%YAML:1.0\n---\nnames: [ a\n  : ]]\n")
    (tmp_path / "extri.yml").write_text("x")
    with pytest.raises(CalibrationError, match=r"intri\.yml: not an OpenCV FileStorage file"):
        RigCalibration.from_opencv(tmp_path)


def test_colmap_sidecar_and_registration_errors(tmp_path):
    import pycolmap

    rig = make_rig()
    rig.to_colmap(tmp_path / "m")
    side = tmp_path / "m" / "studio_rig.json"
    side.write_text("{")
    with pytest.raises(CalibrationError, match=r"studio_rig\.json: field 'ground': bad sidecar"):
        RigCalibration.from_colmap(tmp_path / "m")
    side.write_text(json.dumps({"ground": {"normal": [0, 0, 3], "offset": 0}}))
    with pytest.raises(CalibrationError, match=r"studio_rig\.json: field 'ground\.normal'"):
        RigCalibration.from_colmap(tmp_path / "m")
    side.write_text(json.dumps({"version": 2}))
    with pytest.raises(CalibrationError, match=r"studio_rig\.json: field 'version': unknown major version 2"):
        RigCalibration.from_colmap(tmp_path / "m")
    side.unlink()
    assert RigCalibration.from_colmap(tmp_path / "m" / "cameras.txt").ground.allclose(GroundPlane.floor())
    # a model with a camera but no registered image
    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(pycolmap.Camera(model="PINHOLE", width=64, height=48, params=[50, 50, 32, 24], camera_id=1))
    (tmp_path / "e").mkdir()
    rec.write_text(str(tmp_path / "e"))
    with pytest.raises(CalibrationError, match=r"field 'images': no registered images"):
        RigCalibration.from_colmap(tmp_path / "e")
    # two images whose names give the same camera name
    rec.add_image_with_trivial_frame(pycolmap.Image(name="a.png", camera_id=1, image_id=1), pycolmap.Rigid3d())
    rec.add_camera_with_trivial_rig(pycolmap.Camera(model="PINHOLE", width=64, height=48, params=[50, 50, 32, 24], camera_id=2))
    rec.add_image_with_trivial_frame(pycolmap.Image(name="a.jpg", camera_id=2, image_id=2), pycolmap.Rigid3d())
    rec.write_text(str(tmp_path / "e"))
    with pytest.raises(CalibrationError, match=r"camera 'a': field 'name': two images"):
        RigCalibration.from_colmap(tmp_path / "e")


def test_toml_unreadable_and_value_types(tmp_path):
    from calibration.formats.toml_calib import _value

    with pytest.raises(CalibrationError, match=r"nope\.toml: cannot read"):
        RigCalibration.from_toml(tmp_path / "nope.toml")
    assert _value([1, 2.5, "x", True]) == '[ 1, 2.5, "x", true]'
    with pytest.raises(TypeError, match="cannot write NoneType"):
        _value(None)
