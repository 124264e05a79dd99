"""Bad input to the other tools' readers: one clear error naming the file, the camera and the field."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibration import Camera, CalibrationError, RigCalibration
from calibration.formats import detect_format
from studio.cli import main

CAM = {"size": [640, 480], "matrix": [[500.0, 0, 320], [0, 500, 240], [0, 0, 1]], "distortions": [0.0] * 5,
       "rotation": [0.1, 0.2, 0.3], "translation": [0.0, 0.0, 3.0]}


def _toml(tables: dict) -> str:
    import tomli_w

    return tomli_w.dumps(tables)


KALIBR_CAM = ("cam0:\n  camera_model: pinhole\n  intrinsics: {intr}\n  distortion_model: {dm}\n"
              "  distortion_coeffs: [0, 0, 0, 0]\n  resolution: {res}\n")
T_BAD = "cam1:\n  intrinsics: [1, 1, 1, 1]\n  resolution: [640, 480]\n  T_cn_cnm1: [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0]]\n"

XCP = ('<Cameras VERSION="2.0"><Camera DEVICEID="7" SENSOR_SIZE="{size}" PIXEL_ASPECT_RATIO="1">{kf}'
       "</Camera></Cameras>")
KF = ('<KeyFrames><KeyFrame FOCAL_LENGTH="1000" PRINCIPAL_POINT="{pp}" ORIENTATION="{q}" POSITION="0 0 3000" '
      '{radial}/></KeyFrames>')


def _kf(pp="500 400", q="0 0 0 1", radial='VICON_RADIAL2="Vicon3Parameter 500 400 0 0 0"'):
    return KF.format(pp=pp, q=q, radial=radial)


MCAL = ('<calibrationProfile><Calibration><Cameras>{cams}</Cameras></Calibration></calibrationProfile>')
MCAL_CAM = ('<Camera Serial="{serial}"><Attributes ImagerPixelWidth="640" ImagerPixelHeight="480"/>'
            '<IntrinsicStandardCameraModel LensCenterX="320" LensCenterY="240" HorizontalFocalLength="500" '
            'VerticalFocalLength="500" k1="0" k2="0" k3="0" TangentialX="0" TangentialY="0"/>'
            '<Extrinsic X="1" Y="2" Z="3" {orient}/></Camera>')


def _orient(M) -> str:
    return " ".join(f'OrientMatrix{i}="{float(v)!r}"' for i, v in enumerate(np.asarray(M).reshape(-1)))


CASES = [
    # Caliscope
    ("camera_array.toml", _toml({"cameras": {"0": {**CAM, "name": "a"}, "1": {**CAM, "name": "a"}}}),
     r"camera 'a': field 'name': camera name used twice"),
    ("camera_array.toml", _toml({"cameras": {"0": {**CAM, "rotation": [1.0, 2.0]}}}),
     r"camera '0': field 'rotation': expected a Rodrigues vector \[3\] or a 3x3 matrix, got shape \(2,\)"),
    ("camera_array.toml", _toml({"cameras": {"0": {**CAM, "size": [640]}}}),
     r"camera '0': field 'size': expected \[width, height\]"),
    ("camera_array.toml", _toml({"cameras": {"0": {**CAM, "rotation": ["a", 0, 0]}}}),
     r"camera '0': field 'rotation': not numeric"),
    ("config.toml", "cam_id = 1\n[other]\nx = 1\n", r"field 'cameras': no \[cameras\.N\] or \[cam_N\] tables"),
    ("camera_array.toml", "[cameras.0\n", r"not valid TOML"),
    # multical
    ("calibration.json", json.dumps({"cameras": {}, "camera_poses": {}}),
     r"field 'cameras': expected an object with a non-empty"),
    ("calibration.json", json.dumps({"cameras": {"a": {"K": CAM["matrix"], "dist": [0.0] * 5}}, "camera_poses": {}}),
     r"camera 'a': field 'image_size': missing"),
    ("calibration.json", json.dumps({"cameras": {"a": {"K": CAM["matrix"], "dist": [0.0] * 5, "image_size": [640]}}}),
     r"camera 'a': field 'image_size': expected \[width, height\]"),
    ("calibration.json", json.dumps({"cameras": {"a": {"K": CAM["matrix"], "dist": [0.0] * 5, "image_size": [640, 480]}},
                                     "camera_poses": {"a_to_z": {"R": np.eye(3).tolist(), "T": [0, 0, 0]}}}),
     r"field 'camera_poses\.a_to_z': names camera 'z', which 'cameras' does not hold"),
    ("calibration.json", json.dumps({"cameras": {"a": {"K": CAM["matrix"], "dist": [0.0] * 5, "image_size": [640, 480]}},
                                     "camera_poses": {"b": {"R": np.eye(3).tolist(), "T": [0, 0, 0]}}}),
     r"field 'camera_poses\.b': camera 'b' is not in 'cameras'"),
    ("calibration.json", json.dumps({"cameras": {"a": {"K": CAM["matrix"], "dist": [0.0] * 5, "image_size": [640, 480]}},
                                     "camera_poses": {"a": {"R": [[1, 0], [0, 1]], "T": [0, 0, 0]}}}),
     r"field 'camera_poses\.a': expected finite R 3x3 and T \[3\]"),
    ("calibration.json", json.dumps({"cameras": {"a": {"K": CAM["matrix"], "dist": [0.0] * 5, "image_size": [640, 480]}},
                                     "camera_poses": {"a": {"R": "eye"}}}),
     r"field 'camera_poses\.a': expected \{R: 3x3, T: \[3\]\}"),
    # Kalibr
    ("camchain.yaml", KALIBR_CAM.format(intr="[1, 2, 3]", dm="radtan", res="[640, 480]"),
     r"camera 'cam0': field 'intrinsics': expected \[fu, fv, pu, pv\]"),
    ("camchain.yaml", KALIBR_CAM.format(intr="[500, 500, 320, 240]", dm="fov", res="[640, 480]"),
     r"camera 'cam0': field 'distortion_model': expected one of radtan, equidistant, none, got 'fov'"),
    ("camchain.yaml", KALIBR_CAM.format(intr="[500, 500, 320, 240]", dm="radtan", res="640"),
     r"camera 'cam0': field 'resolution': expected \[width, height\]"),
    ("camchain.yaml", KALIBR_CAM.format(intr="[500, 500, 320, 240]", dm="radtan", res="[640, 480]") + T_BAD,
     r"camera 'cam1': field 'T_cn_cnm1': expected a finite 4x4 transform"),
    ("camchain.yaml", KALIBR_CAM.format(intr="[500, 500, 320, 240]", dm="radtan", res="[640, 480]").replace("cam0", "cam1"),
     r"expected cam0\.\.cam0 in a chain, got cam1"),
    ("camchain.yaml", "cam0:\n  intrinsics: [1, 2\n  resolution: [640, 480]\n", r"not valid YAML"),
    # Vicon
    ("lab.xcp", XCP.format(size="1000 800", kf=""), r"camera '7': field 'KeyFrames/KeyFrame': missing"),
    ("lab.xcp", XCP.format(size="1000 800", kf=_kf(q="0 0 0 0")), r"camera '7': field 'ORIENTATION': .*zero"),
    ("lab.xcp", XCP.format(size="1000 800", kf=_kf(radial='VICON_RADIAL2="Other 1 2"')),
     r"camera '7': field 'VICON_RADIAL2': expected 'Vicon3Parameter cx cy k1 k2 k3'"),
    ("lab.xcp", XCP.format(size="1000 800", kf=_kf(pp="1500 400", radial="")),
     r"camera '7': field 'PRINCIPAL_POINT': principal point \(1500, 400\) outside the 1000x800 sensor"),
    ("lab.xcp", XCP.format(size="1000", kf=_kf()), r"camera '7': field 'SENSOR_SIZE': expected 2 finite numbers"),
    ("lab.xcp", XCP.format(size="1000 800", kf=_kf(q="0 0 x 1")), r"camera '7': field 'ORIENTATION': expected 4 numbers"),
    ("lab.xcp", "<Cameras>", r"not valid XML"),
    ("lab.xcp", "<Cameras VERSION='2'></Cameras>", r"field 'Camera': no <Camera> elements"),
    # OptiTrack
    ("lab.mcal", MCAL.format(cams=MCAL_CAM.format(serial="A", orient=_orient(np.eye(3) * 1.1))),
     r"camera 'A': field 'Extrinsic': OrientMatrix0\.\.8 is not a rotation"),
    ("lab.mcal", MCAL.format(cams=2 * MCAL_CAM.format(serial="A", orient=_orient(np.eye(3)))),
     r"camera 'A': field 'Serial': two <Camera> entries share this Serial"),
    ("lab.mcal", MCAL.format(cams=MCAL_CAM.format(serial="A", orient=_orient(np.eye(3))).replace('X="1"', 'X="a"')),
     r"camera 'A': field 'Extrinsic\.X': not a number"),
    ("lab.mcal", MCAL.format(cams=MCAL_CAM.format(serial="A", orient="").replace("<Attributes", "<Attr")),
     r"camera 'A': field 'Attributes': missing"),
    ("lab.mcal", MCAL.format(cams=""), r"field 'Camera': no enabled <Camera> elements"),
    ("lab.mcal", "<calibrationProfile>", r"not valid XML"),
]


@pytest.mark.parametrize("name, text, message", CASES, ids=[f"{c[0]}-{i}" for i, c in enumerate(CASES)])
def test_bad_input_names_file_camera_field(tmp_path, name, text, message):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(CalibrationError, match=path.name.replace(".", r"\.") + ": .*" + message):
        RigCalibration.load_any(path)


def test_detection_and_writing_errors(tmp_path):
    (tmp_path / "x.bin").write_bytes(b"\x00\x01")
    with pytest.raises(CalibrationError, match=r"x\.bin: cannot tell the calibration format from the name or content"):
        RigCalibration.load_any(tmp_path / "x.bin")
    (tmp_path / "plain.xml").write_text("<root/>")
    with pytest.raises(CalibrationError, match=r"plain\.xml: cannot tell the calibration format"):
        RigCalibration.load_any(tmp_path / "plain.xml")
    (tmp_path / "empty").mkdir()
    with pytest.raises(CalibrationError, match=r"nor <camera>/config\.xml sub-folders"):
        RigCalibration.load_any(tmp_path / "empty")
    with pytest.raises(CalibrationError, match=r"empty: no <camera>/config\.xml sub-folders"):
        RigCalibration.load_any(tmp_path / "empty", "opencv_camera")
    (tmp_path / "q.xml").write_text('<calibration><cameras/></calibration>')
    assert detect_format(tmp_path / "q.xml") == "qualisys"
    (tmp_path / "latin.json").write_bytes('{"cameras": "é"}'.encode("latin-1"))
    with pytest.raises(CalibrationError, match=r"latin\.json: not UTF-8 text \(byte 13\): expected a UTF-8 JSON file"):
        RigCalibration.load_any(tmp_path / "latin.json", "multical")
    fish = Camera("f", np.diag([300.0, 300.0, 1.0]) + [[0, 0, 320], [0, 0, 240], [0, 0, 0]], [0.1, 0, 0, 0],
                  np.eye(3), [0, 0, 1], (640, 480), "fisheye")
    rig = RigCalibration([fish])
    with pytest.raises(CalibrationError, match=r"x\.xml: per-camera OpenCV files are written as a folder"):
        rig.write(tmp_path / "x.xml")
    for fmt, message in (("opencv_camera", "the per-camera OpenCV layout has no fisheye model"),
                         ("multical", "multical has no fisheye model")):
        with pytest.raises(CalibrationError, match=f"camera 'f': field 'model': {message}"):
            rig.write(tmp_path / "out.json" if fmt == "multical" else tmp_path / "out", fmt)
    bad = RigCalibration([fish.replace(name="a_to_b", model="pinhole", dist=np.zeros(5))])
    with pytest.raises(CalibrationError, match=r"camera 'a_to_b': field 'name': '_to_' in a camera name"):
        bad.write(tmp_path / "m.json", "multical")
    with pytest.raises(CalibrationError, match=r"cannot write format 'vicon'"):
        bad.write(tmp_path / "m.xcp", "vicon")
    with pytest.raises(CalibrationError, match=r"field 'cameras': expected at least one NAME=FILE pair"):
        RigCalibration.from_camera_files({})


def test_per_camera_rotation_errors(tmp_path):
    base = ('<?xml version="1.0"?>\n<opencv_storage><CameraMatrix type_id="opencv-matrix"><rows>3</rows><cols>3</cols>'
            "<dt>d</dt><data>500. 0. 320. 0. 500. 240. 0. 0. 1.</data></CameraMatrix>"
            '<Rotation type_id="opencv-matrix"><rows>{n}</rows><cols>1</cols><dt>d</dt><data>{r}</data></Rotation>'
            '<Translation type_id="opencv-matrix"><rows>3</rows><cols>1</cols><dt>d</dt><data>0 0 3000</data>'
            "</Translation></opencv_storage>\n")
    (tmp_path / "a.xml").write_text(base.format(n=2, r="0.1 0.2"))
    with pytest.raises(CalibrationError, match=r"a\.xml: camera 'a': field 'Rotation': expected a 3x1 Rodrigues"):
        RigCalibration.load_any(tmp_path / "a.xml")
    (tmp_path / "b.xml").write_text(base.format(n=9, r="1.01 0 0 0 1 0 0 0 1"))
    with pytest.raises(CalibrationError, match=r"b\.xml: camera 'b': field 'Rotation': not a rotation"):
        RigCalibration.load_any(tmp_path / "b.xml")
    (tmp_path / "c.xml").write_text(base.format(n=9, r="1.00001 0 0 0 1 0 0 0 1"))  # rounding: re-orthonormalised
    rig = RigCalibration.load_any(tmp_path / "c.xml", z_down="keep")
    np.testing.assert_allclose(rig["c"].R, np.eye(3), atol=1e-12)
    assert "camera 'c': Rotation re-orthonormalised (written with few decimals)" in rig.notes
    with pytest.raises(CalibrationError, match=r"field 'name': empty camera name in a NAME=FILE pair"):
        RigCalibration.from_camera_files({"": tmp_path / "c.xml"})


def test_convert_units_and_z_down_options(tmp_path, capsys):
    from tests.calibration.test_calib_checks import foreign_toml, ring, z_down

    foreign_toml(z_down(ring(scale=1000.0)), tmp_path / "in.toml")
    assert main(["convert", str(tmp_path / "in.toml"), str(tmp_path / "keep.json"), "--z-down", "keep",
                 "--units", "mm"]) == 0
    out = capsys.readouterr().out
    assert "  - units: mm (given; camera centres spread over" in out and "kept as it is" in out
    kept = RigCalibration.load(tmp_path / "keep.json")
    np.testing.assert_allclose(kept["c0"].center, z_down(ring())["c0"].center, atol=1e-12)
    assert main(["convert", str(tmp_path / "in.toml"), str(tmp_path / "no.json"), "--z-down", "refuse"]) == 1
    assert "field 'up axis': the world's Z axis points down" in capsys.readouterr().err
    assert main(["convert", str(tmp_path / "in.toml"), str(tmp_path / "ok.json")]) == 0
    assert RigCalibration.load(tmp_path / "ok.json").allclose(ring(), atol=1e-9)
