"""COLMAP models (``calibration.formats.colmap``) written by hand in COLMAP's text format
(``CAMERA_ID MODEL WIDTH HEIGHT PARAMS``; ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME``),
quaternions from SciPy, the pixel convention ``c_colmap = c_opencv + 0.5`` applied here; the
toolkit's own files parsed back line by line; every refusal whole.
"""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from calibration import Camera, GroundPlane, RigCalibration
from calibration.formats import reader
from formatkit import assert_error, raised

K = [[900.0, 0.0, 640.0], [0.0, 905.0, 360.0], [0.0, 0.0, 1.0]]
R1 = Rotation.from_rotvec([0.2, -0.1, 0.3]).as_matrix()


def _wxyz(R) -> str:
    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return " ".join(repr(float(v)) for v in (w, x, y, z))


def model(folder, cameras: list[str], images: list[str]):
    """cameras.txt lines ``MODEL PARAMS`` (ids 1..), images.txt lines ``NAME R t`` (camera i+1)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "cameras.txt").write_text(
        "# Camera list\n" + "".join(f"{i} {c}\n" for i, c in enumerate(cameras, start=1)))
    (folder / "images.txt").write_text("# Image list\n" + "".join(f"{i} {line}\n\n" for i, line in enumerate(images, 1)))
    (folder / "points3D.txt").write_text("# 3D point list\n")
    return folder


def image(R, t, camera_id, name) -> str:
    return f"{_wxyz(R)} {' '.join(repr(float(v)) for v in t)} {camera_id} {name}"


@pytest.mark.parametrize("line, K_expected, dist, lens", [
    ("SIMPLE_PINHOLE 640 480 800 320.5 240.5", [[800, 0, 320], [0, 800, 240], [0, 0, 1]], [], "pinhole"),
    ("PINHOLE 640 480 800 801 320.5 240.5", [[800, 0, 320], [0, 801, 240], [0, 0, 1]], [], "pinhole"),
    ("SIMPLE_RADIAL 640 480 800 320.5 240.5 0.01", [[800, 0, 320], [0, 800, 240], [0, 0, 1]], [0.01, 0, 0, 0],
     "pinhole"),
    ("RADIAL 640 480 800 320.5 240.5 0.01 -0.02", [[800, 0, 320], [0, 800, 240], [0, 0, 1]], [0.01, -0.02, 0, 0],
     "pinhole"),
    ("OPENCV 640 480 800 801 320.5 240.5 0.01 -0.02 0.001 0.002", [[800, 0, 320], [0, 801, 240], [0, 0, 1]],
     [0.01, -0.02, 0.001, 0.002], "pinhole"),
    ("FULL_OPENCV 640 480 800 801 320.5 240.5 0.01 -0.02 0.001 0.002 0.003 0 0 0",
     [[800, 0, 320], [0, 801, 240], [0, 0, 1]], [0.01, -0.02, 0.001, 0.002, 0.003], "pinhole"),
    ("FULL_OPENCV 640 480 800 801 320.5 240.5 0.01 -0.02 0.001 0.002 0.003 0.004 0 0",
     [[800, 0, 320], [0, 801, 240], [0, 0, 1]], [0.01, -0.02, 0.001, 0.002, 0.003, 0.004, 0, 0], "pinhole"),
    ("FULL_OPENCV 640 480 800 801 320.5 240.5 0.01 -0.02 0.001 0.002 0.003 0 0 0.005",
     [[800, 0, 320], [0, 801, 240], [0, 0, 1]], [0.01, -0.02, 0.001, 0.002, 0.003, 0, 0, 0.005], "pinhole"),
    ("OPENCV_FISHEYE 640 480 800 801 320.5 240.5 0.01 -0.02 0.003 -0.004",
     [[800, 0, 320], [0, 801, 240], [0, 0, 1]], [0.01, -0.02, 0.003, -0.004], "fisheye"),
    ("FISHEYE 640 480 800 801 320.5 240.5", [[800, 0, 320], [0, 801, 240], [0, 0, 1]], [0, 0, 0, 0], "fisheye"),
    ("SIMPLE_FISHEYE 640 480 800 320.5 240.5", [[800, 0, 320], [0, 800, 240], [0, 0, 1]], [0, 0, 0, 0], "fisheye"),
    ("SIMPLE_RADIAL_FISHEYE 640 480 800 320.5 240.5 0.01", [[800, 0, 320], [0, 800, 240], [0, 0, 1]],
     [0.01, 0, 0, 0], "fisheye"),
    ("RADIAL_FISHEYE 640 480 800 320.5 240.5 0.01 -0.02", [[800, 0, 320], [0, 800, 240], [0, 0, 1]],
     [0.01, -0.02, 0, 0], "fisheye"),
])
def test_colmap_camera_models(tmp_path, line, K_expected, dist, lens):
    """Each model's parameters in COLMAP's documented order; principal point − 0.5."""
    folder = model(tmp_path / "m", [line], [image(R1, [0.1, 0.2, 3.0], 1, "cam0.png")])
    cam = reader("colmap")(folder).cameras["cam0"]
    np.testing.assert_array_equal(cam.K, K_expected)
    np.testing.assert_array_equal(cam.dist, dist)
    assert cam.model == lens and cam.size == (640, 480)
    np.testing.assert_allclose(cam.R, R1, rtol=0, atol=1e-15)
    np.testing.assert_allclose(cam.t, [0.1, 0.2, 3.0], rtol=0, atol=1e-15)


def test_colmap_names_order_notes_and_skipped_images(tmp_path, caplog):
    """Cameras in image-id order, named after the image without an image suffix (any case);
    without the sidecar the units are arbitrary and the floor z = 0 is assumed, said so."""
    lines = ["PINHOLE 640 480 800 801 320.5 240.5"] * 3
    folder = model(tmp_path / "m", lines, [image(np.eye(3), [0, 0, 3], 1, "left.JPG"),
                                           image(R1, [1, 0, 3], 2, "right.avi"),
                                           image(np.eye(3), [2, 0, 3], 3, "mid")])
    with caplog.at_level(logging.WARNING, logger="calibration.formats.colmap"):
        parts = reader("colmap")(folder / "cameras.txt")
    assert list(parts.cameras) == ["left", "right.avi", "mid"]
    assert parts.notes == ("no studio_rig.json beside the model: the floor is assumed to be z = 0",)
    assert (parts.units, parts.own_frame) == ("arbitrary", False)
    assert parts.metadata == {"ground_source": f"assumed z = 0: no studio_rig.json in {folder}"}
    assert [r.getMessage() for r in caplog.records if r.name == "calibration.formats.colmap"] == [
        f"{folder}: no studio_rig.json beside the COLMAP model (COLMAP has no floor): the ground plane is assumed to "
        "be z = 0 — calibrate the floor (`studio calibrate floor`) if it is not"]


def test_colmap_sidecar_ground_metadata_and_version(tmp_path):
    folder = model(tmp_path / "m", ["PINHOLE 640 480 800 801 320.5 240.5"], [image(R1, [0, 0, 3], 1, "c.png")])
    side = folder / "studio_rig.json"
    side.write_text(json.dumps({"version": "1.3", "ground": {"normal": [0, 0, 1], "offset": 0.25},
                                "metadata": {"who": "me"}}))
    parts = reader("colmap")(folder)
    assert (parts.units, parts.units_fixed, parts.own_frame, parts.notes) == ("m", True, True, ())
    assert parts.metadata == {"who": "me"} and parts.ground.offset == 0.25
    side.write_text(json.dumps({}))
    parts = reader("colmap")(folder)
    assert parts.metadata == {} and parts.ground.offset == 0.0 and parts.own_frame
    side.write_text(json.dumps({"version": 2}))
    assert_error(raised(reader("colmap"), folder), "unknown major version 2 (this reader knows 1)", field="version",
                 file=side)
    side.write_text(json.dumps({"ground": {"normal": [0, 0, 1]}}))
    assert_error(raised(reader("colmap"), folder), "bad sidecar (KeyError('offset'))", field="ground", file=side)
    side.write_text(json.dumps([1]))
    assert_error(raised(reader("colmap"), folder), "bad sidecar (expected a JSON object, got list)", field="ground",
                 file=side)
    side.write_text("{")
    assert_error(raised(reader("colmap"), folder),
                 "bad sidecar (JSONDecodeError('Expecting property name enclosed in double quotes: line 1 column 2 "
                 "(char 1)'))", field="ground", file=side)


def test_colmap_refusals(tmp_path):
    assert_error(raised(reader("colmap"), tmp_path), "not a COLMAP model folder (no cameras.txt or cameras.bin)",
                 file=tmp_path)
    folder = model(tmp_path / "a", ["PINHOLE 640 480 800 801 320.5 240.5"] * 2,
                   [image(np.eye(3), [0, 0, 3], 1, "c.png"), image(np.eye(3), [1, 0, 3], 2, "c.jpg")])
    assert_error(raised(reader("colmap"), folder), "two images map to this camera name", camera="c", field="name",
                 file=folder)
    folder = model(tmp_path / "b", ["FOV 640 480 800 801 320.5 240.5 0.1"], [image(np.eye(3), [0, 0, 3], 1, "c")])
    assert_error(raised(reader("colmap"), folder),
                 "COLMAP camera model FOV is not an OpenCV pinhole or fisheye model (expected OPENCV, FULL_OPENCV, "
                 "PINHOLE, SIMPLE_PINHOLE, SIMPLE_RADIAL, RADIAL, or OPENCV_FISHEYE, FISHEYE, SIMPLE_FISHEYE, "
                 "RADIAL_FISHEYE, SIMPLE_RADIAL_FISHEYE)", camera="c", field="model", file=folder)
    folder = model(tmp_path / "c", ["PINHOLE 640 480 800 801 320.5 240.5"], [])
    assert_error(raised(reader("colmap"), folder), "no registered images", field="images", file=folder)
    (folder / "cameras.txt").write_text("1 PINHOLE 640\n")
    exc = raised(reader("colmap"), folder)
    assert exc.detail.startswith("pycolmap cannot read the model (") and exc.file == str(folder)


def test_colmap_zero_quaternion_in_images_txt(tmp_path):
    """images.txt: two lines an image (the pose, then its POINTS2D): the pose line's quaternion
    is checked, the points line skipped even when it looks like numbers."""
    folder = model(tmp_path / "m", ["PINHOLE 640 480 800 801 320.5 240.5"] * 2,
                   [image(np.eye(3), [0, 0, 3], 1, "a"), image(np.eye(3), [1, 0, 3], 2, "b")])
    text = (folder / "images.txt").read_text().split("\n")
    text[2] = "1 2 3 4 5 6 7 8 9 10 11 12"  # a POINTS2D line of numbers: not a pose
    text[3] = "2 0 0 0 0 1 0 3 2 b"
    (folder / "images.txt").write_text("\n".join(text))
    assert_error(raised(reader("colmap"), folder), "line 4: quaternion [0.0, 0.0, 0.0, 0.0] is not a rotation (zero "
                 "or non-finite norm)", field="QW QX QY QZ", file=folder / "images.txt")
    text[3] = "2 nan 0 0 1 1 0 3 2 b"
    (folder / "images.txt").write_text("\n".join(text))
    assert_error(raised(reader("colmap"), folder), "line 4: quaternion [nan, 0.0, 0.0, 1.0] is not a rotation (zero "
                 "or non-finite norm)", field="QW QX QY QZ", file=folder / "images.txt")


def _text_lines(path) -> list[list[str]]:
    return [line.split() for line in path.read_text().splitlines() if line and not line.startswith("#")]


def test_colmap_writer_lines(tmp_path):
    """cameras.txt: OPENCV for ≤ 4 coefficients or zero k3..k6, FULL_OPENCV otherwise,
    OPENCV_FISHEYE; principal point + 0.5. images.txt: the quaternion (SciPy) and t."""
    cams = [Camera("a", K, [-0.1, 0.01, 0.001, 0.002, 0.0], R1, [0.1, 0.2, 3.0], (1280, 720)),
            Camera("b", K, [-0.1, 0.01, 0.001, 0.002, 0.003], np.eye(3), [1.0, 0.0, 3.0], (1280, 720)),
            Camera("c", K, [0.01, 0.02, 0.003, 0.004], np.eye(3), [2.0, 0.0, 3.0], (1280, 720), "fisheye"),
            Camera("d", K, [], np.eye(3), [3.0, 0.0, 3.0], (640, 480)),
            Camera("e", K, [-0.1, 0.01, 0.001, 0.002, 0.0, 0.0, 0.0, 0.004, 0, 0, 0, 0], np.eye(3), [4.0, 0.0, 3.0],
                   (640, 480))]
    rig = RigCalibration(cams, ground=GroundPlane([0.0, 0.0, 1.0], 0.5), metadata={"who": "me"})
    out = rig.write(tmp_path / "m", "colmap")
    rows = _text_lines(out / "cameras.txt")
    assert [r[:4] for r in rows] == [["1", "OPENCV", "1280", "720"], ["2", "FULL_OPENCV", "1280", "720"],
                                     ["3", "OPENCV_FISHEYE", "1280", "720"], ["4", "OPENCV", "640", "480"],
                                     ["5", "FULL_OPENCV", "640", "480"]]
    params = [[float(v) for v in r[4:]] for r in rows]
    assert params[0] == [900.0, 905.0, 640.5, 360.5, -0.1, 0.01, 0.001, 0.002]
    assert params[1] == [900.0, 905.0, 640.5, 360.5, -0.1, 0.01, 0.001, 0.002, 0.003, 0.0, 0.0, 0.0]
    assert params[2] == [900.0, 905.0, 640.5, 360.5, 0.01, 0.02, 0.003, 0.004]
    assert params[3] == [900.0, 905.0, 640.5, 360.5, 0.0, 0.0, 0.0, 0.0]
    assert params[4] == [900.0, 905.0, 640.5, 360.5, -0.1, 0.01, 0.001, 0.002, 0.0, 0.0, 0.0, 0.004]
    first = _text_lines(out / "images.txt")[0]
    x, y, z, w = Rotation.from_matrix(R1).as_quat()
    q = np.array([float(v) for v in first[1:5]])
    np.testing.assert_allclose(q * np.sign(q[0]), np.array([w, x, y, z]) * np.sign(w), rtol=0, atol=1e-15)
    assert [float(v) for v in first[5:8]] == [0.1, 0.2, 3.0] and first[8:] == ["1", "a"]
    assert json.loads((out / "studio_rig.json").read_text()) == {
        "format": "studio.rig-calibration.colmap-sidecar", "version": 1,
        "ground": {"normal": [0.0, 0.0, 1.0], "offset": 0.5}, "metadata": {"who": "me"}}
    assert (out / "studio_rig.json").read_text().startswith('{\n  "format"')
    assert sorted(p.name for p in out.iterdir()) == ["cameras.txt", "frames.txt", "images.txt", "points3D.txt",
                                                     "rigs.txt", "studio_rig.json"]


def test_colmap_writer_flavours_keep_points_and_remove_stale(tmp_path):
    rig = RigCalibration([Camera("a", K, [], np.eye(3), [0.0, 0.0, 3.0], (640, 480))])
    out = tmp_path / "m"
    out.mkdir()
    (out / "points3D.txt").write_text("# the user's points\n")
    rig.write(out, "colmap")
    assert (out / "points3D.txt").read_text() == "# the user's points\n"
    from calibration.formats.colmap import write_colmap

    write_colmap(rig, out, binary=True)
    names = sorted(p.name for p in out.iterdir())
    assert names == ["cameras.bin", "frames.bin", "images.bin", "points3D.bin", "points3D.txt", "rigs.bin",
                     "studio_rig.json"]
    assert (out / "points3D.txt").read_text() == "# the user's points\n"
    assert list(reader("colmap")(out).cameras) == ["a"]


def test_colmap_writer_refusals(tmp_path):
    skew = Camera("s", [[900.0, 0.5, 640.0], [0.0, 905.0, 360.0], [0.0, 0.0, 1.0]], [], np.eye(3), [0, 0, 3],
                  (1280, 720))
    assert_error(raised(RigCalibration([skew]).write, tmp_path / "m", "colmap"),
                 "COLMAP cannot store a skewed K (K[0,1] != 0)", camera="s", field="K", file=tmp_path / "m")
    prism = Camera("p", K, [0.0] * 12 + [0.001, 0.0], np.eye(3), [0, 0, 3], (1280, 720))
    assert_error(raised(RigCalibration([prism]).write, tmp_path / "m", "colmap"),
                 "thin-prism/tilt terms (coefficients 9-14) have no COLMAP model", camera="p", field="dist",
                 file=tmp_path / "m")


def test_colmap_points_lines_are_not_poses_and_bytes_are_tolerated(tmp_path):
    """Only every other data line of images.txt is a pose: a POINTS2D line whose numbers would
    read as a NaN quaternion is not checked; a byte that is not UTF-8 in an image name does
    not stop the check (pycolmap then reads or names the file itself)."""
    folder = model(tmp_path / "m", ["PINHOLE 640 480 800 801 320.5 240.5"], [image(np.eye(3), [0, 0, 3], 1, "a")])
    lines = (folder / "images.txt").read_text().split("\n")
    lines[2] = "1.5 nan -1 2.5 3.5 -1 4.5 5.5 -1"  # x y POINT3D_ID triples, y = nan: not a pose
    (folder / "images.txt").write_text("\n".join(lines))
    assert list(reader("colmap")(folder).cameras) == ["a"]
    raw = (folder / "images.txt").read_bytes().replace(b" a\n", b" a\xff\n")
    (folder / "images.txt").write_bytes(raw)
    assert_error(raised(reader("colmap"), folder), "image 1: its name is not UTF-8 text ('utf-8' codec can't decode "
                 "byte 0xff in position 1: invalid start byte)", field="NAME", file=folder)


def test_colmap_writer_creates_parents_and_removes_a_stale_binary_model(tmp_path):
    rig = RigCalibration([Camera("a", K, [], np.eye(3), [0.0, 0.0, 3.0], (640, 480))])
    from calibration.formats.colmap import write_colmap

    out = tmp_path / "x" / "y" / "m"
    write_colmap(rig, out, binary=True)
    rig.write(out, "colmap")  # text now: the binary calibration files go, points3D.bin stays
    assert sorted(p.name for p in out.iterdir()) == ["cameras.txt", "frames.txt", "images.txt", "points3D.bin",
                                                     "points3D.txt", "rigs.txt", "studio_rig.json"]
