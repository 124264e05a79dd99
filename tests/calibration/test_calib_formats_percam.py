"""Per-camera OpenCV FileStorage files: the UU course's <cam>/config.xml, NAME=FILE pairs, OpenCV's sample output."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from calibration import CalibrationError, RigCalibration
from studio.cli import main

UU = "multiview/uu_infomcv_4cam_person"
F = np.diag([1.0, -1.0, -1.0])

CONFIG = """<?xml version="1.0"?>
<opencv_storage>
<CameraMatrix type_id="opencv-matrix"><rows>3</rows><cols>3</cols><dt>d</dt>
  <data>500. 0. 320. 0. 510. 240. 0. 0. 1.</data></CameraMatrix>
<DistortionCoeffs type_id="opencv-matrix"><rows>5</rows><cols>1</cols><dt>d</dt>
  <data>-0.2 0.05 0.001 -0.002 0.0</data></DistortionCoeffs>
<{rkey} type_id="opencv-matrix"><rows>3</rows><cols>1</cols><dt>d</dt>
  <data>{r}</data></{rkey}>
<{tkey} type_id="opencv-matrix"><rows>3</rows><cols>1</cols><dt>d</dt>
  <data>{t}</data></{tkey}>
</opencv_storage>
"""


def _xml_numbers(path, key) -> np.ndarray:
    """The numbers of ``<key><data>`` read with ElementTree (independent of OpenCV)."""
    return np.array([float(v) for v in ET.parse(path).getroot().find(f"{key}/data").text.split()])


def test_uu_config_folder_matches_the_raw_xml(shared_data):
    folder = shared_data / UU
    rig = RigCalibration.load_any(folder)
    assert rig.camera_names == ["cam1", "cam2", "cam3", "cam4"]
    for name in rig.camera_names:
        cfg = folder / name / "config.xml"
        K = _xml_numbers(cfg, "CameraMatrix").reshape(3, 3)
        r, T = _xml_numbers(cfg, "Rotation"), _xml_numbers(cfg, "Translation")
        cam = rig[name]
        np.testing.assert_allclose(cam.K, K, rtol=1e-6)  # stored as float32 ('dt f')
        np.testing.assert_allclose(cam.dist, _xml_numbers(cfg, "DistortionCoeffs"), rtol=1e-6, atol=1e-9)
        # mm → m, and the course's Z-down board world turned half a turn about X
        R_file = Rotation.from_rotvec(r).as_matrix()
        np.testing.assert_allclose(cam.R, R_file @ F, atol=1e-12)
        np.testing.assert_allclose(cam.t, T / 1000.0, atol=1e-12)
        np.testing.assert_allclose(cam.center, F @ (-R_file.T @ T) / 1000.0, atol=1e-9)
        assert cam.size == (644, 486)  # from the videos beside the files
        assert 1.5 < cam.center[2] < 2.2  # cameras above the floor now
    assert "units: mm (detected: camera centres spread over 8195 file units; expected mm)" in rig.notes
    assert "checkerboard.xml: board squares of 115 in the translations' unit, so mm is expected" in rig.notes
    assert any("the file's world had Z pointing down (cameras 1.65 to 2.11 m below the floor" in n for n in rig.notes)
    with pytest.raises(CalibrationError, match=r"uu_infomcv_4cam_person: field 'up axis': the world's Z axis points down "
                                               r"\(all cameras 1\.65 to 2\.11 m below the floor"):
        RigCalibration.load_any(folder, z_down="refuse")


def test_uu_intrinsics_file_is_intrinsics_only(shared_data):
    """intrinsics.xml has no ``<?xml?>`` line (OpenCV alone reads it as YAML and fails) and no pose."""
    rig = RigCalibration.load_any(shared_data / UU / "cam1" / "intrinsics.xml")
    cam = rig["cam1"]
    assert cam.K[0, 0] == pytest.approx(392.288344338314) and cam.K[1, 1] == pytest.approx(522.9569244927329)
    np.testing.assert_array_equal(cam.R, np.eye(3))
    assert any("intrinsics only (no Rotation/Translation): R = I, t = 0" in n for n in rig.notes)


def test_opencv_sample_output_loads_as_intrinsics(shared_data):
    path = shared_data / "calibration/opencv_chessboard_9x6/left_intrinsics.REFERENCE.yml"
    rig = RigCalibration.load_any(path)
    cam = rig["left_intrinsics.REFERENCE"]
    assert cam.K[0, 0] == pytest.approx(535.91573396163199) and cam.size == (640, 480)
    assert cam.dist[0] == pytest.approx(-0.26637260909660682)
    np.testing.assert_array_equal(cam.t, np.zeros(3))
    assert any("intrinsics only (OpenCV calibration sample output): R = I, t = 0" in n for n in rig.notes)
    assert "up axis: not applicable (no camera pose)" in rig.notes


def _write_rig(root, poses, rkey="Rotation", tkey="Translation"):
    for name, (r, t) in poses.items():
        (root / name).mkdir(parents=True)
        (root / name / "config.xml").write_text(CONFIG.format(rkey=rkey, tkey=tkey, r=" ".join(map(str, r)),
                                                              t=" ".join(map(str, t))))
    return root


def _course_poses():
    """Three cameras 2 m above a floor board, in the board's Z-down frame, translations in mm."""
    poses = {}
    for k, name in enumerate(("left", "mid", "right")):
        centre_up = np.array([-2.0 + 2.0 * k, -3.0, 2.0])  # metres, Z up
        from calibration.rotation import look_at

        R_up, _ = look_at(centre_up, [0.0, 0.0, 0.0])
        R = R_up @ F  # the same camera in the board's Z-down world
        t = -R @ (F @ centre_up)
        poses[name] = (Rotation.from_matrix(R).as_rotvec(), t * 1000.0)
    return poses


@pytest.mark.parametrize("keys", [("Rotation", "Translation"), ("RotationValues", "TranslationValues")])
def test_hand_written_course_folder(tmp_path, keys):
    root = _write_rig(tmp_path / "data", _course_poses(), *keys)
    rig = RigCalibration.load_any(root)
    assert rig.camera_names == ["left", "mid", "right"]
    np.testing.assert_allclose(rig["mid"].center, [0.0, -3.0, 2.0], atol=1e-9)
    np.testing.assert_allclose(rig["left"].K, [[500, 0, 320], [0, 510, 240], [0, 0, 1]])
    np.testing.assert_allclose(rig["left"].dist, [-0.2, 0.05, 0.001, -0.002, 0.0])
    assert rig["left"].size == (641, 481)  # nothing beside the files: from the principal point, with a warning
    assert any("guessed 641x481 from the principal point" in w for w in rig.warnings)
    # NAME=FILE pairs name the cameras; the CLI writes them with the notes kept in the metadata
    pairs = {"a": root / "left" / "config.xml", "b": root / "right" / "config.xml"}
    two = RigCalibration.from_camera_files(pairs)
    np.testing.assert_allclose(two["b"].center, [2.0, -3.0, 2.0], atol=1e-9)
    out = tmp_path / "two.json"
    assert main(["convert", f"a={pairs['a']}", f"b={pairs['b']}", str(out)]) == 0
    saved = RigCalibration.load(out)
    assert saved.camera_names == ["a", "b"]
    assert any("turned half a turn about X" in n for n in saved.metadata["import_notes"])


def test_course_writer_round_trip(tmp_path):
    rig = RigCalibration.load_any(_write_rig(tmp_path / "in", _course_poses()))
    rig.write(tmp_path / "out", "opencv_camera")
    assert "<Translation" in (tmp_path / "out" / "mid" / "config.xml").read_text()
    back = RigCalibration.load_any(tmp_path / "out")
    assert back.allclose(rig, atol=1e-9)
    assert any(n.startswith("units: mm") for n in back.notes)  # the course layout is written in mm
    assert any(n.startswith("up axis: Z up") for n in back.notes)


def test_per_camera_errors(tmp_path, capsys):
    root = _write_rig(tmp_path / "d", _course_poses())
    (root / "mid" / "config.xml").write_text(CONFIG.replace("<CameraMatrix", "<Other").replace("</CameraMatrix", "</Other")
                                             .format(rkey="Rotation", tkey="Translation", r="0 0 0", t="0 0 1"))
    with pytest.raises(CalibrationError, match=r"mid/config\.xml: camera 'mid': field 'CameraMatrix': missing"):
        RigCalibration.load_any(root)
    unposed = tmp_path / "u"
    _write_rig(unposed, {"a": (np.zeros(3), [0, 0, 1000])})
    (unposed / "b").mkdir()
    (unposed / "b" / "config.xml").write_text(
        '<?xml version="1.0"?>\n<opencv_storage><CameraMatrix type_id="opencv-matrix"><rows>3</rows><cols>3</cols>'
        "<dt>d</dt><data>500. 0. 320. 0. 500. 240. 0. 0. 1.</data></CameraMatrix></opencv_storage>\n")
    with pytest.raises(CalibrationError, match=r"camera\(s\) b have no Rotation/Translation while the others do"):
        RigCalibration.load_any(unposed)
    assert main(["convert", "a=x.xml", str(tmp_path / "o.json")]) == 1
    assert "x.xml: no such file (camera 'a')" in capsys.readouterr().err
    assert main(["convert", "junk", "a=b=c", str(tmp_path / "o.json")]) == 1
    assert "junk: expected NAME=FILE when several inputs are given" in capsys.readouterr().err


def test_easymocap_reader_points_a_single_camera_file_elsewhere(shared_data):
    path = shared_data / "calibration/opencv_chessboard_9x6/left_intrinsics.REFERENCE.yml"
    with pytest.raises(CalibrationError, match=r"REFERENCE\.yml: field 'names': missing: this is a single-camera "
                                               r"OpenCV file \(camera_matrix\), not EasyMocap's intri\.yml"):
        RigCalibration.from_opencv(path, path)
