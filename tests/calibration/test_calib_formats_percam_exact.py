"""Per-camera OpenCV files (``calibration.formats.opencv_camera``) against values built here:
the image size from an image or video beside the file (written here with OpenCV at a known
size), the board hint's unit at its documented bound (a square over 5 units is mm), the
keys a camera error names in each layout, the written ``config.xml`` read back with
ElementTree, and every refusal whole.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from calibration import Camera, RigCalibration
from calibration.formats import RigParts, reader
from calibration.formats.opencv_camera import _board_hint, _media_size, read_camera_file, read_camera_pairs
from calibration.ground import GroundPlane
from formatkit import assert_error, raised


def _matrix(key, rows, cols, values) -> str:
    return (f'<{key} type_id="opencv-matrix"><rows>{rows}</rows><cols>{cols}</cols><dt>d</dt>'
            f"<data>{' '.join(repr(float(v)) for v in np.ravel(values))}</data></{key}>")


def _storage(*items, declaration=True) -> str:
    return ('<?xml version="1.0"?>\n' if declaration else "") + "<opencv_storage>" + "".join(items) + "</opencv_storage>\n"


KM = [[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]]
DIST = [-0.2, 0.05, 0.001, -0.002, 0.0]


def _course(rvec=(0.1, -0.2, 0.3), t=(100.0, 200.0, 3000.0), rkey="Rotation", tkey="Translation", extra=(),
            k=KM, dist=DIST, rshape=(3, 1)) -> str:
    return _storage(_matrix("CameraMatrix", *np.shape(k), k), _matrix("DistortionCoeffs", 1, len(dist), dist),
                    _matrix(rkey, *rshape, rvec), _matrix(tkey, 3, 1, t), *extra)


def _video(path, size, fourcc):
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), 10.0, size)
    assert out.isOpened(), path
    for _ in range(2):
        out.write(np.zeros((size[1], size[0], 3), np.uint8))
    out.release()


@pytest.mark.parametrize("name, fourcc", [("v.avi", "MJPG"), ("v.mp4", "mp4v"), ("v.mov", "MJPG"),
                                          ("v.mkv", "MJPG")])
def test_media_size_from_a_video(tmp_path, name, fourcc):
    _video(tmp_path / name, (64, 48), fourcc)
    (tmp_path / "z.png").write_bytes(b"not a png")
    assert _media_size(tmp_path) == ((64, 48), name)


def test_media_size_from_images_first_readable_wins(tmp_path):
    """Images in MEDIA order (png before jpg), sorted by name; unreadable ones skipped; a
    colour image's (h, w, 3) shape gives (w, h); sizes of a single pixel row or column count."""
    assert _media_size(tmp_path) is None
    (tmp_path / "a.png").write_bytes(b"not a png")
    (tmp_path / "bad.avi").write_bytes(b"not a video")
    assert _media_size(tmp_path) is None
    cv2.imwrite(str(tmp_path / "c.jpg"), np.zeros((30, 40, 3), np.uint8))
    assert _media_size(tmp_path) == ((40, 30), "c.jpg")
    cv2.imwrite(str(tmp_path / "b.png"), np.zeros((5, 1, 3), np.uint8))
    assert _media_size(tmp_path) == ((1, 5), "b.png")
    cv2.imwrite(str(tmp_path / "a.png"), np.zeros((1, 7), np.uint16))
    assert _media_size(tmp_path) == ((7, 1), "a.png")


def test_course_file_size_from_the_image_beside_it_and_notes(tmp_path):
    (tmp_path / "cam1").mkdir()
    path = tmp_path / "cam1" / "config.xml"
    path.write_text(_course())
    cv2.imwrite(str(tmp_path / "cam1" / "frame.png"), np.zeros((480, 644, 3), np.uint8))
    cam, notes, posed = read_camera_file(path, "cam1")
    assert posed and cam.size == (644, 480)
    assert notes == ["camera 'cam1': image size 644x480 from frame.png beside the file"]
    np.testing.assert_allclose(cam.R, Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix(), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(cam.t, [100.0, 200.0, 3000.0])
    np.testing.assert_array_equal(cam.K, KM)
    np.testing.assert_array_equal(cam.dist, DIST)


def test_size_written_in_the_file_wins_and_both_keys_are_needed(tmp_path):
    path = tmp_path / "config.xml"
    cv2.imwrite(str(tmp_path / "frame.png"), np.zeros((480, 644, 3), np.uint8))
    w, h = "<image_width>800</image_width>", "<image_height>600</image_height>"
    path.write_text(_course(extra=(w, h)))
    cam, notes, _ = read_camera_file(path, "c")
    assert cam.size == (800, 600) and notes == []
    for only in (w, h):
        path.write_text(_course(extra=(only,)))
        assert read_camera_file(path, "c")[0].size == (644, 480)


def test_guessed_size_rounded_rotation_and_value_keys(tmp_path):
    """No size anywhere: 2 c + 1 from the principal point (641 x 481), noted as a warning; a 3x3
    Rotation with 5 decimals re-orthonormalised (SVD here) under RotationValues."""
    R = Rotation.from_rotvec([0.3, -1.2, 0.5]).as_matrix()
    path = tmp_path / "cam.xml"
    path.write_text(_course(rvec=np.round(R, 5), rshape=(3, 3), rkey="RotationValues", tkey="TranslationValues"))
    cam, notes, posed = read_camera_file(path, "c")
    U, _, Vt = np.linalg.svd(np.round(R, 5))
    np.testing.assert_allclose(cam.R, U @ Vt, rtol=0, atol=1e-14)
    assert cam.size == (641, 481)
    assert notes == ["camera 'c': Rotation re-orthonormalised (written with few decimals)",
                     "warning: camera 'c': no image size in the file and no video or image beside it: guessed 641x481 "
                     "from the principal point (2 c + 1)"]
    path.write_text(_course(rvec=R, rshape=(3, 3)))  # exact: kept to the bit, no note
    cam, notes, _ = read_camera_file(path, "c")
    np.testing.assert_array_equal(cam.R, R)
    assert notes[0].startswith("warning: camera 'c': no image size")


def test_sample_layout_is_intrinsics_only(tmp_path):
    path = tmp_path / "out_camera_data.yml"
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 1280)
    fs.write("image_height", 720)
    fs.write("camera_matrix", np.array(KM))
    fs.write("distortion_coefficients", np.array(DIST).reshape(5, 1))
    fs.write("Rotation", np.zeros((3, 1)))  # not the sample's: ignored in this layout
    fs.release()
    cam, notes, posed = read_camera_file(path, "s")
    assert not posed and cam.size == (1280, 720)
    np.testing.assert_array_equal(cam.R, np.eye(3))
    np.testing.assert_array_equal(cam.t, np.zeros(3))
    np.testing.assert_array_equal(cam.dist, DIST)
    assert notes == ["camera 's': intrinsics only (OpenCV calibration sample output): R = I, t = 0 — the camera's "
                     "pose is not in the file; calibrate the extrinsics"]
    path.write_text(_storage(_matrix("CameraMatrix", 3, 3, KM)))
    assert read_camera_file(path, "u")[1][0] == (
        "camera 'u': intrinsics only (no Rotation/Translation): R = I, t = 0 — the camera's pose is not in the file; "
        "calibrate the extrinsics")


@pytest.mark.parametrize("text, detail, field", [
    (_storage(_matrix("Other", 1, 1, [1])),
     "missing: expected CameraMatrix (per-camera rig file) or camera_matrix (OpenCV calibration sample output)",
     "CameraMatrix"),
    (_course(k=np.eye(2)), "expected shape (3, 3), got (2, 2)", "CameraMatrix"),
    (_course(k=[[500.0, 0, 320], [0, 510, 240], [0, 0, 2]]),
     "expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]], got [[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 2.0]]",
     "CameraMatrix"),
    (_course(dist=[0.1, 0.2, 0.3]), "expected (0, 4, 5, 8, 12, 14) coefficients, got 3", "DistortionCoeffs"),
    (_course(rvec=np.diag([1.0, 1.0, -1.0]), rshape=(3, 3)), "determinant is -1 (a reflection, not a rotation)",
     "Rotation"),
    (_course(rvec=np.diag([1.0, 1.0, 1.01]), rshape=(3, 3)), "not a rotation: max |R Rᵀ - I| = 0.0201 > 0.0001",
     "Rotation"),
    (_course(rvec=[0.1, 0.2, 0.3, 0.4], rshape=(4, 1)),
     "expected a 3x1 Rodrigues vector or a 3x3 matrix, got shape (4, 1)", "Rotation"),
    (_course(rvec=[[np.nan, 0, 0], [0, 1, 0], [0, 0, 1]], rshape=(3, 3)), "element 0 is 'nan': expected a number",
     "Rotation"),
    (_course(rkey="RotationValues", tkey="TranslationValues", t=[0, np.inf, 1]), "element 1 is 'inf': expected a number",
     "TranslationValues"),
    (_course(extra=("<image_width>0</image_width>", "<image_height>480</image_height>")),
     "expected two positive integers (width, height), got (0.0, 480.0)", "image_width/image_height"),
])
def test_course_file_refusals_name_the_key(tmp_path, text, detail, field):
    path = tmp_path / "config.xml"
    path.write_text(text)
    assert_error(raised(read_camera_file, path, "c1"), detail, camera="c1", field=field, file=path)


def test_sample_layout_refusals_name_its_keys(tmp_path):
    path = tmp_path / "s.xml"
    path.write_text(_storage(_matrix("camera_matrix", 2, 2, np.eye(2))))
    assert_error(raised(read_camera_file, path, "s"), "expected shape (3, 3), got (2, 2)", camera="s",
                 field="camera_matrix", file=path)
    path.write_text(_storage(_matrix("camera_matrix", 3, 3, KM), _matrix("distortion_coefficients", 1, 2, [1, 2])))
    assert_error(raised(read_camera_file, path, "s"), "expected (0, 4, 5, 8, 12, 14) coefficients, got 2",
                 camera="s", field="distortion_coefficients", file=path)


def test_xml_without_declaration_and_unreadable_storage(tmp_path):
    path = tmp_path / "config.xml"
    path.write_text("  \n" + _course(extra=("<image_width>640</image_width>", "<image_height>480</image_height>"))
                    .split("\n", 1)[1])
    assert read_camera_file(path, "c")[0].size == (640, 480)
    path.write_text("<opencv_storage><CameraMatrix></opencv_storage>")  # OpenCV raises: one error naming the file
    exc = raised(read_camera_file, path, "c")
    assert exc.detail.startswith("not an OpenCV FileStorage file (OpenCV(") and exc.detail.endswith(")")
    assert "Mismatched closing tag" in exc.detail and exc.file == str(path)


def _parts(units="m", notes=("n",)) -> RigParts:
    cam = Camera("c", KM, [], np.eye(3), [0, 0, 1], (640, 480))
    return RigParts({"c": cam}, GroundPlane.floor(), {}, units=units, units_fixed=False, notes=notes)


@pytest.mark.parametrize("square, unit", [(25.0, "mm"), (5.5, "mm"), (5.0, "m"), (0.5, "m"), (1.0, "m")])
def test_board_hint_unit_at_the_documented_bound(tmp_path, square, unit):
    """'a size over 5 cannot be metres, so the usual unit is mm': 5 itself is metres."""
    board = tmp_path / "checkerboard.xml"
    board.write_text(_storage(f"<CheckerBoardSquareSize>{square!r}</CheckerBoardSquareSize>"))
    hinted = _board_hint(_parts(), board)
    assert hinted.units == unit
    assert hinted.notes == ("n", f"checkerboard.xml: board squares of {square:g} in the translations' unit, so {unit} "
                                 "is expected")


@pytest.mark.parametrize("content", ["<CheckerBoardSquareSize>0</CheckerBoardSquareSize>",
                                     "<CheckerBoardSquareSize>-3</CheckerBoardSquareSize>",
                                     "<CheckerBoardSquareSize>big</CheckerBoardSquareSize>",
                                     "<CheckerBoardWidth>9</CheckerBoardWidth>"])
def test_board_hint_ignores_sizes_that_say_nothing(tmp_path, content):
    board = tmp_path / "checkerboard.xml"
    board.write_text(_storage(content))
    parts = _parts(units="cm")
    assert _board_hint(parts, board) is parts
    assert _board_hint(parts, tmp_path / "none.xml") is parts
    (tmp_path / "d.xml").mkdir()
    assert _board_hint(parts, tmp_path / "d.xml") is parts


def test_folder_reader_config_names_and_refusals(tmp_path):
    for sub, name in (("a", "config.yml"), ("b", "config.yaml"), ("c", "config.xml"), ("d", "other.xml")):
        (tmp_path / sub).mkdir()
        if name.endswith(".xml"):
            (tmp_path / sub / name).write_text(_course())
        else:
            fs = cv2.FileStorage(str(tmp_path / sub / name), cv2.FILE_STORAGE_WRITE)
            fs.write("CameraMatrix", np.array(KM))
            fs.write("Rotation", np.array([[0.1], [-0.2], [0.3]]))
            fs.write("Translation", np.array([[100.0], [200.0], [3000.0]]))
            fs.release()
    (tmp_path / "e.xml").write_text(_course())
    parts = reader("opencv_camera")(tmp_path)
    assert list(parts.cameras) == ["a", "b", "c"]
    assert (parts.units, parts.units_fixed, parts.metadata) == ("m", False, {"source": "opencv per-camera files"})
    single = reader("opencv_camera")(tmp_path / "c" / "config.xml")
    assert list(single.cameras) == ["c"]
    assert list(reader("opencv_camera")(tmp_path / "d" / "other.xml").cameras) == ["other"]
    (tmp_path / "e").mkdir()
    (tmp_path / "e" / "Intrinsics.xml").write_text(_course())
    assert list(reader("opencv_camera")(tmp_path / "e" / "Intrinsics.xml").cameras) == ["e"]
    empty = tmp_path / "empty"
    (empty / "x").mkdir(parents=True)
    assert_error(raised(reader("opencv_camera"), empty), "no <camera>/config.xml sub-folders", file=empty)
    assert_error(raised(read_camera_pairs, {"": tmp_path / "c" / "config.xml"}),
                 "empty camera name in a NAME=FILE pair", field="name", file=tmp_path / "c" / "config.xml")
    (tmp_path / "u.xml").write_text(_storage(_matrix("CameraMatrix", 3, 3, KM)))
    assert_error(raised(read_camera_pairs, {"p": tmp_path / "c" / "config.xml", "q": tmp_path / "u.xml",
                                            "r": tmp_path / "u.xml"}),
                 "camera(s) q, r have no Rotation/Translation while the others do: expected every camera posed in "
                 "the same world", file=tmp_path / "u.xml")


def test_writer_layout_read_back_with_elementtree(tmp_path):
    """The course layout: Rodrigues Rotation, Translation in mm, a 1x5 zero distortion when the
    camera has none, and the image size; refusals name the camera."""
    R = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    cams = [Camera("left", KM, [], R, [0.1, 0.2, 3.0], (640, 480)),
            Camera("right", KM, DIST, np.eye(3), [1.0, 0.0, 3.0], (800, 600))]
    out = tmp_path / "rig"
    assert RigCalibration(cams).write(out, "opencv_camera") == out
    root = ET.parse(out / "left" / "config.xml").getroot()

    def numbers(key):
        node = root.find(key)
        return [float(v) for v in node.find("data").text.split()], (int(node.find("rows").text),
                                                                     int(node.find("cols").text))

    assert numbers("DistortionCoeffs") == ([0.0] * 5, (1, 5))
    values, shape = numbers("Rotation")
    np.testing.assert_allclose(values, Rotation.from_matrix(R).as_rotvec(), rtol=0, atol=1e-15)
    assert shape == (3, 1)
    np.testing.assert_allclose(numbers("Translation")[0], [100.0, 200.0, 3000.0], rtol=1e-15)
    assert numbers("CameraMatrix") == ([500.0, 0.0, 320.0, 0.0, 510.0, 240.0, 0.0, 0.0, 1.0], (3, 3))
    assert (root.find("image_width").text.strip(), root.find("image_height").text.strip()) == ("640", "480")
    right = ET.parse(out / "right" / "config.xml").getroot()
    assert [float(v) for v in right.find("DistortionCoeffs/data").text.split()] == DIST
    for bad in ("a/b", "a\\b", ".", ".."):
        assert_error(raised(RigCalibration([cams[0].replace(name=bad)]).write, out, "opencv_camera"),
                     "camera names must be plain folder names", camera=bad, field="name", file=out)
    fish = cams[0].replace(model="fisheye", dist=np.array([0.01, 0.0, 0.0, 0.0]))
    assert_error(raised(RigCalibration([fish]).write, out, "opencv_camera"),
                 "the per-camera OpenCV layout has no fisheye model", camera="left", field="model", file=out)


def test_rotation_tolerances_at_their_bounds(tmp_path):
    """A 3x3 Rotation off by exactly ROUNDING_TOL (1e-4): re-orthonormalised (SVD here) and
    noted; off by exactly 1e-6: kept as written."""
    path = tmp_path / "config.xml"
    for e, rounded in ((1e-4, True), (1e-6, False)):
        M = np.eye(3)
        M[0, 1] = e
        assert np.max(np.abs(M @ M.T - np.eye(3))) == e
        path.write_text(_course(rvec=M, rshape=(3, 3), extra=("<image_width>640</image_width>",
                                                              "<image_height>480</image_height>")))
        cam, notes, _ = read_camera_file(path, "c")
        if rounded:
            U, _, Vt = np.linalg.svd(M)
            np.testing.assert_allclose(cam.R, U @ Vt, rtol=0, atol=1e-15)
            assert notes == ["camera 'c': Rotation re-orthonormalised (written with few decimals)"]
        else:
            np.testing.assert_array_equal(cam.R, M)
            assert notes == []


def test_pairs_keep_every_cameras_notes_and_names_with_x(tmp_path):
    for name in ("camX", "b"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "config.xml").write_text(_course())
    parts = reader("opencv_camera")(tmp_path)
    assert [n.split(":")[0] for n in parts.notes] == ["warning", "warning"]
    assert "camera 'b'" in parts.notes[0] and "camera 'camX'" in parts.notes[1]  # folders in name order
    rig = RigCalibration([Camera("camX", KM, [], np.eye(3), [0, 0, 1], (640, 480))])
    rig.write(tmp_path / "out", "opencv_camera")
    assert (tmp_path / "out" / "camX" / "config.xml").is_file()


def test_rounded_reflections_singular_and_shrunk_rotations(tmp_path):
    """A reflection written with 5 decimals is not turned into a rotation (the camera check
    refuses it); a singular matrix is refused as not a rotation; a rotation shrunk by 2e-5
    (det < 1, within rounding) is taken as its nearest rotation."""
    path = tmp_path / "config.xml"
    F = np.round(Rotation.from_rotvec([0.3, -1.2, 0.5]).as_matrix() @ np.diag([1.0, 1.0, -1.0]), 5)
    path.write_text(_course(rvec=F, rshape=(3, 3)))
    err = np.max(np.abs(F @ F.T - np.eye(3)))
    assert_error(raised(read_camera_file, path, "c"), f"not orthonormal (max |R Rᵀ - I| = {err:.3g} > 1e-06)",
                 camera="c", field="Rotation", file=path)  # kept as written: not made a rotation
    path.write_text(_course(rvec=np.zeros((3, 3)), rshape=(3, 3)))
    assert_error(raised(read_camera_file, path, "c"), "not a rotation: max |R Rᵀ - I| = 1 > 0.0001", camera="c",
                 field="Rotation", file=path)
    R = Rotation.from_rotvec([0.3, -1.2, 0.5]).as_matrix() * (1 - 2e-5)
    assert np.linalg.det(R) < 1
    path.write_text(_course(rvec=R, rshape=(3, 3)))
    U, _, Vt = np.linalg.svd(R)
    np.testing.assert_allclose(read_camera_file(path, "c")[0].R, U @ Vt, rtol=0, atol=1e-15)
