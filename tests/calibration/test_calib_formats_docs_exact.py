"""Native JSON, Pose2Sim/anipose TOML and Caliscope TOML, and the document helpers of
``calibration.formats.text``: whole errors (detail, camera, field, file) for every refusal,
written documents compared key by key with ones built here from the formats' layouts, and
the readers' notes and units exactly.
"""

from __future__ import annotations

import json
import tomllib

import numpy as np
import pytest
import tomli_w
from scipy.spatial.transform import Rotation

from calibration import Camera, GroundPlane, RigCalibration
from calibration.formats import reader
from calibration.formats.text import attr_float, child, parse_xml, read_document
from formatkit import assert_error, raised

K = [[900.0, 0.0, 640.0], [0.0, 905.0, 360.0], [0.0, 0.0, 1.0]]
R1 = Rotation.from_rotvec([0.2, -0.1, 0.3]).as_matrix()


def reason(parse, text) -> str:
    """The parser's own message for ``text`` (one line), as the reader quotes it."""
    with pytest.raises(Exception) as info:
        parse(text)
    return str(info.value).replace("\n", " ")


# ------------------------------------------------------------------------------------------ text
def test_read_document_errors_name_the_file_and_kind(tmp_path):
    assert_error(raised(read_document, tmp_path / "no.json", json.loads, "JSON", (json.JSONDecodeError,)),
                 "cannot read (No such file or directory)", file=tmp_path / "no.json")
    bad = tmp_path / "a.json"
    bad.write_bytes(b'{"a": "\xff"}')
    assert_error(raised(read_document, bad, json.loads, "JSON", (json.JSONDecodeError,)),
                 "not UTF-8 text (byte 7): expected a UTF-8 JSON file", file=bad)
    bad.write_text('{"a": 1,\n}')
    assert_error(raised(read_document, bad, json.loads, "JSON", (json.JSONDecodeError,)),
                 f"not valid JSON ({reason(json.loads, bad.read_text())})", file=bad)
    bad.write_text("[" * 100000 + "]" * 100000)
    assert_error(raised(read_document, bad, json.loads, "JSON", (json.JSONDecodeError,)),
                 "not valid JSON (nested too deeply)", file=bad)
    bad.write_text("x = [1,\n2,,]")
    assert_error(raised(read_document, bad, tomllib.loads, "TOML", (tomllib.TOMLDecodeError,)),
                 f"not valid TOML ({reason(tomllib.loads, bad.read_text())})", file=bad)
    bad.write_text('{"a": [1, 2]}')
    assert read_document(bad, json.loads, "JSON", ()) == {"a": [1, 2]}


def test_parse_xml_and_attribute_helpers(tmp_path):
    path = tmp_path / "a.xml"
    path.write_text("<a><b x='1.5' y='inf' z='one'/></a>")
    root = parse_xml(path)
    b = child(root, "b", "cam")
    assert attr_float(b, "x", "cam", "b") == 1.5
    assert_error(raised(attr_float, b, "w", "cam", "b"), "missing", camera="cam", field="b.w")
    assert_error(raised(attr_float, b, "y", "cam", "b"), "expected a finite number, got 'inf'", camera="cam",
                 field="b.y")
    assert_error(raised(attr_float, b, "z", "cam", "b"), "not a number: 'one'", camera="cam", field="b.z")
    assert_error(raised(child, root, "c", "cam"), "missing", camera="cam", field="c")
    path.write_text("<a>")
    assert_error(raised(parse_xml, path, "Vicon XML"), "not valid Vicon XML (no element found: line 1, column 3)",
                 file=path)
    assert_error(raised(parse_xml, path), "not valid XML (no element found: line 1, column 3)", file=path)
    assert_error(raised(parse_xml, tmp_path / "none.xml"), "cannot read (No such file or directory)",
                 file=tmp_path / "none.xml")


# ------------------------------------------------------------------------------------------ native
def _native(**changes) -> dict:
    cam = Camera("c1", K, [-0.1, 0.01, 0.0, 0.0, 0.0], R1, [0.1, 0.2, 3.0], (1280, 720))
    doc = {"format": "studio.rig-calibration", "version": 1, "units": "m", "cameras": {"c1": cam.to_dict()},
           "ground": {"normal": [0.0, 0.0, 1.0], "offset": 0.0}, "metadata": {"k": 1}}
    doc.update(changes)
    return doc


@pytest.mark.parametrize("doc, detail, camera, field", [
    ([1], "expected a JSON object at the top level", None, None),
    (_native(format="other"), "expected 'studio.rig-calibration', got 'other'", None, "format"),
    ({k: v for k, v in _native().items() if k != "format"}, "expected 'studio.rig-calibration', got None", None,
     "format"),
    ({k: v for k, v in _native().items() if k != "version"}, "missing", None, "version"),
    (_native(version=2), "unknown major version 2 (this reader knows 1)", None, "version"),
    (_native(version="2.1"), "unknown major version '2.1' (this reader knows 1)", None, "version"),
    (_native(version="0"), "unknown major version '0' (this reader knows 1)", None, "version"),
    (_native(version=True), "expected an integer version, got True", None, "version"),
    (_native(version=None), "expected an integer version, got None", None, "version"),
    (_native(version="v1"), "expected an integer version, got 'v1'", None, "version"),
    (_native(version=float("nan")), "expected an integer version, got nan", None, "version"),
    (_native(units="mm"), "expected 'm', got 'mm'", None, "units"),
    (_native(cameras=[]), "missing or empty camera table", None, "cameras"),
    (_native(cameras={}), "missing or empty camera table", None, "cameras"),
    (_native(ground={"normal": [0, 0, 1]}), "expected {normal, offset}", None, "ground"),
    (_native(ground={"offset": 0}), "expected {normal, offset}", None, "ground"),
    (_native(ground=[0, 0, 1]), "expected {normal, offset}", None, "ground"),
])
def test_native_refusals(tmp_path, doc, detail, camera, field):
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(doc))
    assert_error(raised(reader("native"), path), detail, camera=camera, field=field, file=path)


def test_native_defaults_and_parts(tmp_path):
    path = tmp_path / "calibration.json"
    doc = _native(version=1.0, metadata=None, ground={"normal": [0, 0, -1], "offset": -0.5})
    del doc["units"]
    path.write_text(json.dumps(doc))
    parts = reader("native")(path)
    assert (parts.units, parts.units_fixed, parts.own_frame, parts.metadata, parts.notes) == ("m", True, True, {}, ())
    np.testing.assert_array_equal(parts.ground.normal, [0, 0, -1])
    assert parts.ground.offset == -0.5
    doc = _native(version="1")
    del doc["ground"]
    path.write_text(json.dumps(doc))
    parts = reader("native")(path)
    assert parts.metadata == {"k": 1} and parts.ground.offset == 0.0
    np.testing.assert_array_equal(parts.ground.normal, [0, 0, 1])
    np.testing.assert_array_equal(parts.cameras["c1"].R, R1)


def test_native_writer_document(tmp_path):
    cam = Camera("c1", K, [-0.1, 0.01, 0.0, 0.0, 0.0], R1, [0.1, 0.2, 3.0], (1280, 720))
    rig = RigCalibration([cam], ground=GroundPlane([0.0, 0.0, 1.0], 0.25), metadata={"who": "me"})
    path = tmp_path / "sub" / "calibration.json"
    assert rig.write(path, "native") == path
    text = path.read_text()
    assert json.loads(text) == {"format": "studio.rig-calibration", "version": 1, "units": "m",
                                "cameras": {"c1": cam.to_dict()}, "ground": {"normal": [0.0, 0.0, 1.0],
                                                                           "offset": 0.25},
                                "metadata": {"who": "me"}}
    assert text.startswith('{\n  "format": "studio.rig-calibration",\n') and text.endswith("}\n")
    nan = rig.replace(metadata={"x": float("nan")})
    assert_error(raised(nan.write, tmp_path / "n.json", "native"),
                 "metadata cannot be written as JSON (Out of range float values are not JSON compliant: nan)",
                 field="metadata", file=tmp_path / "n.json")


# ------------------------------------------------------------------------------------------ TOML
def _toml_cam(**changes) -> dict:
    table = {"name": "A", "size": [640, 480], "matrix": K, "distortions": [0.01, -0.02, 0.001, 0.002],
             "rotation": [0.1, -0.2, 0.3], "translation": [0.0, 0.0, 3.0], "fisheye": False}
    table.update(changes)
    return {k: v for k, v in table.items() if v is not None}


@pytest.mark.parametrize("doc, detail, camera, field", [
    ({"cam_0": 3}, "expected a table, got int", "cam_0", None),
    ({"cam_0": _toml_cam(size=None)}, "missing", "A", "size"),
    ({"cam_0": _toml_cam(matrix=None)}, "missing", "A", "matrix"),
    ({"cam_0": _toml_cam(distortions=None)}, "missing", "A", "distortions"),
    ({"cam_0": _toml_cam(rotation=None)}, "missing", "A", "rotation"),
    ({"cam_0": _toml_cam(translation=None)}, "missing", "A", "translation"),
    ({"cam_0": _toml_cam(fisheye="no")}, "expected true or false, got 'no'", "A", "fisheye"),
    ({"cam_0": _toml_cam(rotation=["a", 0, 0])}, "not numeric (could not convert string to float: 'a')", "A",
     "rotation"),
    ({"cam_0": _toml_cam(rotation=[0.1, 0.2])}, "expected a Rodrigues vector of 3 values, got 2", "A", "rotation"),
    ({"cam_0": _toml_cam(size=[640])}, "expected [width, height], got [640]", "A", "size"),
    ({"cam_0": _toml_cam(size="640x480")}, "expected [width, height], got '640x480'", "A", "size"),
    ({"cam_0": _toml_cam(), "cam_1": _toml_cam()}, "camera name used twice", "A", "name"),
    ({"metadata": {}}, "no camera tables", None, "cameras"),
    ({"cam_0": _toml_cam(), "metadata": {"studio_ground": 3}}, "expected {normal, offset}", None,
     "metadata.studio_ground"),
    ({"cam_0": _toml_cam(), "metadata": {"studio_ground": {"normal": [0, 0, 1]}}}, "expected {normal, offset}", None,
     "metadata.studio_ground"),
    ({"cam_0": _toml_cam(), "metadata": {"studio_ground": {"offset": 0}}}, "expected {normal, offset}", None,
     "metadata.studio_ground"),
])
def test_toml_refusals(tmp_path, doc, detail, camera, field):
    path = tmp_path / "Calib.toml"
    path.write_text(tomli_w.dumps(doc))
    assert_error(raised(reader("toml"), path), detail, camera=camera, field=field, file=path)


def test_toml_units_notes_and_layouts(tmp_path):
    """Pose2Sim (metres) vs FreeMoCap (charuco_square_size → mm); a 3x3 rotation or a 1x3
    Rodrigues vector; the table name when there is no ``name``; ``fisheye = true``."""
    R = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    doc = {"cam_0": _toml_cam(name=None, rotation=R.tolist()),
           "cam_1": _toml_cam(name="B", rotation=[[0.1, -0.2, 0.3]], fisheye=True),
           "metadata": {"adjusted": False}}
    path = tmp_path / "Calib.toml"
    path.write_text(tomli_w.dumps(doc))
    parts = reader("toml")(path)
    assert list(parts.cameras) == ["cam_0", "B"]
    np.testing.assert_array_equal(parts.cameras["cam_0"].R, R)
    np.testing.assert_allclose(parts.cameras["B"].R, R, rtol=0, atol=1e-15)
    assert parts.cameras["B"].model == "fisheye" and parts.cameras["cam_0"].model == "pinhole"
    assert parts.cameras["cam_0"].size == (640, 480)
    assert (parts.units, parts.units_fixed, parts.own_frame, parts.metadata) == ("m", False, False,
                                                                                 {"adjusted": False})
    assert parts.notes == ("Pose2Sim writes metres; anipose writes the board's unit (not stated in the file)",)
    doc["metadata"] = {"charuco_square_size": 39.0, "studio_ground": {"normal": [0, 0, 1], "offset": 12.0}}
    path.write_text(tomli_w.dumps(doc))
    parts = reader("toml")(path)
    assert (parts.units, parts.own_frame, parts.metadata) == ("mm", True, {"charuco_square_size": 39.0})
    assert parts.notes == ("FreeMoCap file (charuco_square_size = 39.0, entered in mm)",)
    assert parts.ground.offset == 12.0


def test_toml_writer_layout(tmp_path):
    """Pose2Sim's layout, line by line: one [name] table per camera, one value per line,
    lists as ``[ a, b]``, then [metadata] with the ground plane."""
    cams = [Camera("A", K, [0.01, -0.02, 0.001, 0.002], np.eye(3), [0.0, 0.0, 3.0], (640, 480)),
            Camera("cam 2", K, [0.01, 0.0, 0.0, 0.0], np.eye(3), [1.0, 0.0, 3.0], (640, 480), "fisheye")]
    rig = RigCalibration(cams, ground=GroundPlane([0.0, 0.0, 1.0], 0.5), metadata={"error": 0.25, "by": "me"})
    path = tmp_path / "sub" / "Calib.toml"
    rig.write(path, "toml")
    lines = path.read_text().split("\n")
    assert lines[:9] == ["[A]", 'name = "A"', "size = [ 640, 480]",
                         "matrix = [ [ 900.0, 0.0, 640.0], [ 0.0, 905.0, 360.0], [ 0.0, 0.0, 1.0]]",
                         "distortions = [ 0.01, -0.02, 0.001, 0.002]", "rotation = [ 0.0, 0.0, 0.0]",
                         "translation = [ 0.0, 0.0, 3.0]", "fisheye = false", ""]
    assert lines[9] == '["cam 2"]' and lines[16] == "fisheye = true"
    doc = tomllib.loads(path.read_text())
    assert doc["metadata"] == {"adjusted": False, "error": 0.25, "by": "me",
                               "studio_ground": {"normal": [0.0, 0.0, 1.0], "offset": 0.5}}
    assert_error(raised(RigCalibration([cams[0].replace(name="metadata")]).write, tmp_path / "m.toml", "toml"),
                 "a camera named 'metadata' clashes with the [metadata] table", camera="metadata",
                 file=tmp_path / "m.toml")
    assert_error(raised(rig.replace(metadata={"x": None}).write, tmp_path / "n.toml", "toml"),
                 f"metadata cannot be written as TOML ({reason(tomli_w.dumps, {'x': None})})",
                 field="metadata", file=tmp_path / "n.toml")


def test_toml_value_writer():
    from calibration.formats.toml_calib import _value

    assert _value(True) == "true" and _value(False) == "false"
    assert _value(np.int64(3)) == "3" and _value(np.float32(0.5)) == "0.5" and _value(2.0) == "2.0"
    assert _value('a "q"') == '"a \\"q\\""'
    assert _value((1, [2.5, "x"])) == '[ 1, [ 2.5, "x"]]'
    with pytest.raises(TypeError, match=r"^cannot write dict as a TOML value$"):
        _value({})


# ------------------------------------------------------------------------------------------ Caliscope
def _cs_table(**changes) -> dict:
    table = {"port": 0, "size": [1280, 720], "matrix": K, "distortions": [-0.1, 0.02, 0.001, -0.001, 0.003],
             "rotation": [0.2, -0.1, 0.3], "translation": [0.1, 0.2, 3.0], "fisheye": False, "error": 0.4}
    table.update(changes)
    return {k: v for k, v in table.items() if v is not None}


@pytest.mark.parametrize("doc, detail, camera, field", [
    ({"charuco": {"columns": 4}}, "no [cameras.N] or [cam_N] tables", None, "cameras"),
    ({"cameras": {"0": 3}}, "expected a table, got int", "0", None),
    ({"cameras": {"0": _cs_table(fisheye=1)}}, "expected true or false, got 1", "0", "fisheye"),
    ({"cameras": {"0": _cs_table(size=[1280])}}, "expected [width, height], got [1280]", "0", "size"),
    ({"cameras": {"0": _cs_table(size="1280x720")}}, "expected [width, height], got '1280x720'", "0", "size"),
    ({"cameras": {"0": _cs_table(name="x"), "1": _cs_table(name="x")}}, "camera name used twice", "x", "name"),
    ({"cameras": {"0": _cs_table(rotation=["a", 0, 0])}}, "not numeric (could not convert string to float: 'a')",
     "0", "rotation"),
    ({"cameras": {"0": _cs_table(rotation=[0.1, 0.2])}},
     "expected a Rodrigues vector [3] or a 3x3 matrix, got shape (2,)", "0", "rotation"),
    ({"cameras": {"0": _cs_table(rotation=np.diag([1.0, 1.0, 1.01]).tolist())}},
     "not orthonormal (max |R Rᵀ - I| = 0.0201 > 1e-06)", "0", "R"),
    ({"cameras": {"0": _cs_table(ignore=True), "1": _cs_table(matrix=None)}},
     "no calibrated camera (every table is ignored or lacks matrix/rotation/translation)", None, "cameras"),
])
def test_caliscope_refusals(tmp_path, doc, detail, camera, field):
    path = tmp_path / "camera_array.toml"
    path.write_text(tomli_w.dumps(doc))
    assert_error(raised(reader("caliscope"), path), detail, camera=camera, field=field, file=path)


def test_caliscope_rotations_notes_and_skipped(tmp_path):
    """A Rodrigues vector as [3] or [[3]], a 3x3 rounded to 5 decimals (its nearest rotation:
    SVD here) and an exact one (kept to the bit); skipped and turned cameras noted."""
    R = Rotation.from_rotvec([0.3, -1.2, 0.5]).as_matrix()
    U, _, Vt = np.linalg.svd(np.round(R, 5))
    doc = {"cameras": {"0": _cs_table(rotation=[0.3, -1.2, 0.5]), "1": _cs_table(rotation=[[0.3], [-1.2], [0.5]]),
                       "2": _cs_table(rotation=np.round(R, 5).tolist(), rotation_count=-1),
                       "3": _cs_table(rotation=R1.tolist(), fisheye=True, distortions=[0.01, 0.0, 0.0, 0.0],
                                      rotation_count=2),
                       "4": _cs_table(ignore=True), "5": _cs_table(translation=None)}}
    path = tmp_path / "camera_array.toml"
    path.write_text(tomli_w.dumps(doc))
    parts = reader("caliscope")(path)
    assert list(parts.cameras) == ["0", "1", "2", "3"]
    for name in ("0", "1"):
        np.testing.assert_allclose(parts.cameras[name].R, R, rtol=0, atol=1e-15)
    np.testing.assert_allclose(parts.cameras["2"].R, U @ Vt, rtol=0, atol=1e-14)
    np.testing.assert_array_equal(parts.cameras["3"].R, R1)
    assert parts.cameras["3"].model == "fisheye" and parts.cameras["2"].model == "pinhole"
    assert parts.notes == (
        "Caliscope: rotation and translation map world to camera; metres (boards sized in metres)",
        "skipped camera(s) 4, 5: ignore = true or not calibrated",
        "warning: rotation_count set for camera(s) 2 (-1), 3 (+2): Caliscope turns those cameras' frames by quarter "
        "turns before use; give the calibration frames turned the same way")
    assert parts.metadata == {"source": "caliscope", "skipped": ["4", "5"]}
    assert (parts.units, parts.units_fixed, parts.own_frame) == ("m", False, False)
    path.write_text(tomli_w.dumps({"cam_7": _cs_table(), "cam_x": 3, "CreationDate": "today"}))
    parts = reader("caliscope")(path)
    assert list(parts.cameras) == ["7"] and parts.metadata == {"source": "caliscope"}
    assert parts.notes == ("Caliscope: rotation and translation map world to camera; metres (boards sized in metres)",)


def test_caliscope_writer_document(tmp_path):
    cams = [Camera("cam_a", K, [-0.1, 0.02, 0.001, -0.001, 0.003], R1, [0.1, 0.2, 3.0], (1280, 720)),
            Camera("cam_b", K, [0.01, 0.0, 0.0, 0.0], np.eye(3), [1.0, 0.0, 3.0], (1280, 720), "fisheye")]
    path = tmp_path / "sub" / "camera_array.toml"
    RigCalibration(cams).write(path, "caliscope")
    doc = tomllib.loads(path.read_text())
    rvec = Rotation.from_matrix(R1).as_rotvec()
    assert list(doc["cameras"]) == ["0", "1"]
    a = doc["cameras"]["0"]
    np.testing.assert_allclose(a.pop("rotation"), rvec, rtol=0, atol=1e-15)
    assert a == {"port": 0, "name": "cam_a", "size": [1280, 720], "matrix": K,
                 "distortions": [-0.1, 0.02, 0.001, -0.001, 0.003], "translation": [0.1, 0.2, 3.0],
                 "fisheye": False, "rotation_count": 0, "ignore": False}
    assert doc["cameras"]["1"]["fisheye"] is True and doc["cameras"]["1"]["port"] == 1
    numbered = [c.replace(name=n) for c, n in zip(cams, ("3", "12"))]
    RigCalibration(numbered).write(path, "caliscope")
    doc = tomllib.loads(path.read_text())
    assert list(doc["cameras"]) == ["3", "12"] and doc["cameras"]["12"]["port"] == 12


# ------------------------------------------------------------------------------------------ detection
from calibration.formats import FORMATS, WRITABLE, detect_format, read, read_pairs, write, writer  # noqa: E402

DETECT = [
    # (file name, content (None: do not create), expected format when reading)
    ("calibration.json", '{"format": "studio.rig-calibration", "camera_poses": {}}', "native"),
    ("calibration.json", '{"cameras": {}, "camera_poses": {}}', "multical"),
    ("calibration.json", '{"cameras": {"a": {"image_size": [1, 2]}}}', "multical"),
    ("calibration.json", '{"cameras": {"a": {"size": [1, 2]}}}', "native"),
    ("calibration.json", '{"format": "x", "cameras": {"a": {"image_size": [1, 2]}}}', "native"),
    ("CALIB.JSON", '{"camera_poses": {}}', "multical"),
    ("camera_array.toml", "[cameras.0]\nport = 0\n", "caliscope"),
    ("config.toml", "[cam_1]\ncam_id = 1\n", "caliscope"),
    ("Calib.toml", "[cam_1]\ncam_id = 1\nname = \"a\"\n", "toml"),
    ("Calib.toml", "[cam_1]\nname = \"a\"\n", "toml"),
    ("x.TOML", "[cameras.0]\n", "caliscope"),
    ("camchain.yaml", "cam0:\n  T_cn_cnm1: []\n", "kalibr"),
    ("camchain.yml", "cam0:\n  intrinsics: [1]\n  resolution: [1]\n", "kalibr"),
    ("cam.yml", "cam0:\n  intrinsics: [1]\n", "opencv"),
    ("c.yaml", "%YAML:1.0\ncamera_matrix: 1\n", "opencv_camera"),
    ("c.yml", "%YAML:1.0\nCameraMatrix: 1\n", "opencv_camera"),
    ("intri.YML", "%YAML:1.0\nnames: []\n", "opencv"),
    ("lab.qca.txt", "x", "qualisys"),
    ("lab.qca", "x", "qualisys"),
    ("lab.XCP", "x", "vicon"),
    ("lab.mcal", "x", "optitrack"),
    ("cameras.txt", "x", "colmap"),
    ("cameras.bin", "x", "colmap"),
    ("images.txt", "x", "colmap"),
    ("images.bin", "x", "colmap"),
    ("config.xml", '<?xml version="1.0"?>\n<opencv_storage>\n</opencv_storage>', "opencv_camera"),
    ("a.xml", "<calibrationProfile/>", "optitrack"),
    ("a.xml", '<Cameras VERSION="2"><Camera DEVICEID="1"/></Cameras>', "vicon"),
    ("a.xml", "<Cameras><KeyFrames/></Cameras>", "vicon"),
    ("a.xml", "<calibration><cameras/></calibration>", "qualisys"),
    ("lab.export", "<calibrationProfile/>", "optitrack"),
    ("lab.export", "<Cameras><Camera DEVICEID='1'/></Cameras>", "vicon"),
    ("lab.export", "<opencv_storage/>", "opencv_camera"),
    ("lab.export", "<calibration/>", "qualisys"),
]


@pytest.mark.parametrize("name, content, expected", DETECT)
def test_detect_format_from_name_and_content(tmp_path, name, content, expected):
    path = tmp_path / name
    path.write_text(content)
    assert detect_format(path) == expected


@pytest.mark.parametrize("name, expected", [
    ("out.json", "native"), ("out.toml", "toml"), ("intri.yml", "opencv"), ("camchain.yaml", "opencv"),
    ("a.qca.txt", "qualisys"), ("a.xcp", "vicon"), ("a.mcal", "optitrack"), ("cameras.txt", "colmap"),
])
def test_detect_format_for_writing_goes_by_the_name(tmp_path, name, expected):
    """For writing (or a file not there yet) the content is not read."""
    path = tmp_path / name
    path.write_text('[cameras.0]\n{"camera_poses": 1}\nT_cn_cnm1')
    assert detect_format(path, for_writing=True) == expected
    assert detect_format(tmp_path / "new" / name) == expected


def test_detect_format_of_utf16_and_folders(tmp_path):
    (tmp_path / "a.mcal2").write_bytes(b"\xfe\xff" + "<calibrationProfile/>".encode("utf-16-be"))
    assert detect_format(tmp_path / "a.mcal2") == "optitrack"
    (tmp_path / "b.x").write_bytes(b"\xff\xfe" + "<Cameras><Camera ".encode("utf-16-le"))
    assert detect_format(tmp_path / "b.x") == "vicon"
    for marker, fmt in (("intri.yml", "opencv"), ("extri.yml", "opencv"), ("cameras.txt", "colmap"),
                        ("cameras.bin", "colmap")):
        folder = tmp_path / marker.replace(".", "_")
        folder.mkdir()
        (folder / marker).write_text("x")
        assert detect_format(folder) == fmt
        assert detect_format(folder, for_writing=True) == fmt
    folder = tmp_path / "course"
    (folder / "cam1").mkdir(parents=True)
    (folder / "notes.txt").write_text("x")
    (folder / "cam1" / "config.xml").write_text("x")
    assert detect_format(folder) == "opencv_camera"
    (folder / "cam1" / "config.xml").unlink()
    (folder / "cam1" / "config.xml").mkdir()  # a folder named config.xml is not a camera file
    assert_error(raised(detect_format, folder),
                 "folder holds neither intri.yml/extri.yml (OpenCV), cameras.txt/.bin (COLMAP) nor <camera>/config.xml "
                 "sub-folders (per-camera OpenCV files)", file=folder)
    assert_error(raised(detect_format, folder, for_writing=True),
                 "is a folder: say which format to write (opencv, opencv_camera or colmap)", file=folder)
    unknown = ("cannot tell the calibration format from the name or content (expected .json, .toml, .yml, .xml, "
               ".xcp, .mcal, .qca.txt, or an OpenCV/COLMAP folder)")
    assert_error(raised(detect_format, tmp_path / "none.xml"), unknown, file=tmp_path / "none.xml")
    (tmp_path / "p.xml").write_text("<root/>")
    assert_error(raised(detect_format, tmp_path / "p.xml"), unknown, file=tmp_path / "p.xml")
    assert_error(raised(detect_format, tmp_path / "p.xml", for_writing=True),
                 "per-camera OpenCV files are written as a folder of <camera>/config.xml: give a folder name and the "
                 "format opencv_camera", file=tmp_path / "p.xml")
    (tmp_path / "k.dat").write_text('<Camera DEVICEID="1"><KeyFrames/></Camera>')  # no <Cameras: not Vicon
    assert_error(raised(detect_format, tmp_path / "k.dat"), unknown, file=tmp_path / "k.dat")
    (tmp_path / "p.dat").write_text("<root/>")
    assert_error(raised(detect_format, tmp_path / "p.dat"), unknown, file=tmp_path / "p.dat")
    assert_error(raised(detect_format, tmp_path / "q.dat", for_writing=True), unknown, file=tmp_path / "q.dat")


def test_registry_reader_writer_and_dispatch(tmp_path):
    assert FORMATS == ("native", "opencv", "opencv_camera", "toml", "caliscope", "multical", "kalibr", "colmap",
                       "qualisys", "vicon", "optitrack")
    assert WRITABLE == ("native", "opencv", "opencv_camera", "toml", "caliscope", "multical", "kalibr", "colmap")
    assert writer("toml").__name__ == "write_toml" and reader("vicon").__name__ == "read_vicon"
    assert_error(raised(reader, "csv"), "unknown format 'csv' (known: " + ", ".join(FORMATS) + ")")
    assert_error(raised(writer, "vicon"), "cannot write format 'vicon' (writable: " + ", ".join(WRITABLE) + ")")
    cam = Camera("c1", K, [-0.1, 0.01, 0.0, 0.0, 0.0], R1, -R1 @ [0.5, 0.2, 2.0], (1280, 720))
    cam2 = Camera("c2", K, [], np.eye(3), -np.diag([1.0, -1.0, -1.0]) @ [2.0, 0.0, 2.5], (1280, 720))
    cam2 = cam2.replace(R=np.diag([1.0, -1.0, -1.0]))
    rig = RigCalibration([cam, cam2])
    assert_error(raised(write, rig, tmp_path / "x.qca.txt"),
                 "cannot write format 'qualisys' (writable: " + ", ".join(WRITABLE) + ")", file=tmp_path / "x.qca.txt")
    # EasyMocap pairs: either file of the pair names both; a folder gets intri.yml + extri.yml
    assert write(rig, tmp_path / "pair" / "intri_a.yml") == tmp_path / "pair" / "intri_a.yml"
    assert (tmp_path / "pair" / "extri_a.yml").is_file()
    for name in ("intri_a.yml", "extri_a.yml"):
        parts = read(tmp_path / "pair" / name)
        assert list(parts.cameras) == ["c1", "c2"] and parts.notes[0] == "format: opencv"
    assert write(rig, tmp_path / "folder", "opencv") == tmp_path / "folder"
    assert sorted(p.name for p in (tmp_path / "folder").iterdir()) == ["extri.yml", "intri.yml"]
    assert write(rig, tmp_path / "col", "colmap") == tmp_path / "col"
    parts = read(tmp_path / "col" / "images.txt")
    assert parts.notes[0] == "format: colmap" and list(parts.cameras) == ["c1", "c2"]
    assert_error(raised(read, tmp_path / "nothing.json"), "no such file or folder", file=tmp_path / "nothing.json")
    write(rig, tmp_path / "r.json")
    parts = read(tmp_path / "r.json", units="mm", z_down="keep")
    np.testing.assert_allclose(parts.cameras["c1"].center, [0.0005, 0.0002, 0.002], rtol=0, atol=1e-15)
    assert parts.notes[:3] == ("format: native", "units: mm (given; camera centres spread over 1.594 file units)",
                               "warning: the given units mm disagree with the magnitudes (camera centres spread "
                               "over 1.594 file units suggests m)")
    assert_error(raised(read, tmp_path / "r.json", z_down="never"), "expected one of flip, refuse, keep, got 'never'",
                 field="z_down", file=tmp_path / "r.json")


def test_read_pairs_settles_and_names_the_first_file(tmp_path):
    cam = Camera("c1", K, [-0.1, 0.01, 0.0, 0.0, 0.0], np.eye(3), [0.0, 0.0, 2000.0], (1280, 720))
    RigCalibration([cam]).write(tmp_path / "course", "opencv_camera")
    first = tmp_path / "course" / "c1" / "config.xml"
    parts = read_pairs({"left": first}, units="m", z_down="keep")
    assert list(parts.cameras) == ["left"]
    assert parts.notes[0] == "format: opencv_camera"
    assert parts.notes[1] == "units: m (given; camera centres spread over 2e+06 file units)"
    np.testing.assert_array_equal(parts.cameras["left"].t, [0.0, 0.0, 2e6])
    assert_error(raised(read_pairs, {"left": first}, z_down="up"), "expected one of flip, refuse, keep, got 'up'",
                 field="z_down", file=first)
    assert_error(raised(read_pairs, {"left": first}, z_down="refuse"),
                 "the world's Z axis points down (all cameras 2000.00 m below the floor z = 0 along +Z): expected "
                 "world Z up; pass z_down='flip' (--z-down flip) to turn the world half a turn about X",
                 field="up axis", file=first)


def test_detection_reads_the_first_4096_bytes(tmp_path):
    """Content sniffing looks at the head of the file only (4 KiB): a marker ending at byte
    4096 counts, one ending at byte 4097 does not."""
    marker = '"camera_poses"'
    for end, expected in ((4096, "multical"), (4097, "native")):
        pad = "x" * (end - len('{"a": "') - len('", ') - len(marker))
        text = '{"a": "' + pad + '", ' + marker + ": {}}"
        assert text.index(marker) + len(marker) == end
        (tmp_path / "c.json").write_text(text)
        assert detect_format(tmp_path / "c.json") == expected


def test_caliscope_rounding_tolerances_at_their_bounds(tmp_path):
    """A legacy 3x3 rotation off by exactly 1e-4 (the largest put down to rounding) is taken
    as its nearest rotation; off by exactly 1e-6 it is kept as written."""
    path = tmp_path / "camera_array.toml"
    for e, keep in ((1e-4, False), (1e-6, True)):
        M = np.eye(3)
        M[0, 1] = e
        assert np.max(np.abs(M @ M.T - np.eye(3))) == e
        path.write_text(tomli_w.dumps({"cameras": {"0": _cs_table(rotation=M.tolist())}}))
        R = reader("caliscope")(path).cameras["0"].R
        if keep:
            np.testing.assert_array_equal(R, M)
        else:
            U, _, Vt = np.linalg.svd(M)
            np.testing.assert_allclose(R, U @ Vt, rtol=0, atol=1e-15)


def test_detection_details(tmp_path):
    """A UTF-16 head cut in the middle of a character still sniffs; a Caliscope table after a
    comment line is found (line-anchored search); rig_from_dict names '<dict>' by default."""
    from calibration.formats.native import rig_from_dict

    (tmp_path / "a.x").write_bytes(b"\xff\xfe" + "<calibrationProfile/>".encode("utf-16-le") + b"\x00")
    assert detect_format(tmp_path / "a.x") == "optitrack"
    (tmp_path / "c.toml").write_text("# Caliscope camera array\n[cameras.0]\nport = 0\n")
    assert detect_format(tmp_path / "c.toml") == "caliscope"
    assert_error(raised(rig_from_dict, {"format": "x"}), "expected 'studio.rig-calibration', got 'x'",
                 field="format", file="<dict>")


def test_toml_reader_and_writer_details(tmp_path):
    """[metadata] first does not end the camera tables; a fisheye camera with a 3x3 rotation
    stays fisheye and a bad size under it names the camera; the default metadata written."""
    R = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    path = tmp_path / "Calib.toml"
    path.write_text(tomli_w.dumps({"metadata": {"adjusted": True},
                                   "cam_0": _toml_cam(rotation=R.tolist(), fisheye=True,
                                                      distortions=[0.01, 0.0, 0.0, 0.0])}))
    parts = reader("toml")(path)
    assert list(parts.cameras) == ["A"] and parts.cameras["A"].model == "fisheye"
    path.write_text(tomli_w.dumps({"cam_0": _toml_cam(rotation=R.tolist(), size=[640])}))
    assert_error(raised(reader("toml"), path), "expected [width, height], got [640]", camera="A", field="size",
                 file=path)
    cam = Camera("A", K, [], np.eye(3), [0.0, 0.0, 3.0], (640, 480))
    RigCalibration([cam]).write(path, "toml")
    assert tomllib.loads(path.read_text())["metadata"] == {
        "adjusted": False, "error": 0.0, "studio_ground": {"normal": [0.0, 0.0, 1.0], "offset": 0.0}}


def test_easymocap_pair_of_any_name_given_the_format(tmp_path):
    """With the format given, either file of a pair names the other by swapping intri/extri,
    whatever the suffix (here .txt, which no name-based rule knows)."""
    cam = Camera("c1", K, [], R1, [0.1, 0.2, 3.0], (1280, 720))
    i, e = RigCalibration([cam]).write(tmp_path / "intri.yml", "opencv"), tmp_path / "extri.yml"
    (tmp_path / "intri.txt").write_bytes(i.read_bytes())
    (tmp_path / "extri.txt").write_bytes(e.read_bytes())
    for name in ("intri.txt", "extri.txt"):
        parts = read(tmp_path / name, "opencv", z_down="keep")
        np.testing.assert_array_equal(parts.cameras["c1"].R, R1)


def test_multi_line_parser_messages_on_one_line_and_latin1_heads(tmp_path):
    import yaml

    bad = tmp_path / "camchain.yaml"
    bad.write_text("cam0: [1, 2\ncam1: 3\n")
    with pytest.raises(yaml.YAMLError) as info:
        yaml.safe_load(bad.read_text())
    assert "\n" in str(info.value)  # PyYAML's message spans lines; the error keeps it on one
    expected = f"not valid YAML ({str(info.value).replace(chr(10), ' ')})"
    assert_error(raised(read_document, bad, yaml.safe_load, "YAML", (yaml.YAMLError,)), expected, file=bad)
    (tmp_path / "l.x").write_bytes("<calibration>é".encode("latin-1"))
    assert detect_format(tmp_path / "l.x") == "qualisys"
