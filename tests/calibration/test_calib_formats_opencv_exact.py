"""EasyMocap's intri.yml / extri.yml (``calibration.formats.opencv``) written by hand here in
OpenCV's YAML, read back with ``cv2.FileStorage`` directly when the toolkit writes them: each
refusal whole (detail, camera, field, file), the documented limits at the limit (64 MiB,
64 levels of nesting, the 1e-4 rounding tolerance), the notes and metadata exactly.
"""

from __future__ import annotations

import json
import os

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from calibration import Camera, GroundPlane, RigCalibration
from calibration.formats import reader
from calibration.formats.opencv import MAX_BYTES, MAX_NESTING, _check_text
from formatkit import assert_error, raised

K = [[500.0, 0.0, 320.0], [0.0, 510.0, 240.0], [0.0, 0.0, 1.0]]
RV = [0.1, -0.2, 0.3]
R = Rotation.from_rotvec(RV).as_matrix()
GAP = np.max(np.abs(Rotation.from_rotvec([0.1, -0.2, 0.31]).as_matrix() - R))


def mat(key, values, shape=None) -> str:
    a = np.asarray(values, dtype=float)
    rows, cols = shape or (a.shape if a.ndim == 2 else (a.size, 1))
    return (f"{key}: !!opencv-matrix\n   rows: {rows}\n   cols: {cols}\n   dt: d\n"
            f"   data: [ {', '.join(repr(float(v)) for v in a.ravel())} ]\n")


def doc(*items, names=("c1",)) -> str:
    head = "%YAML:1.0\n---\n"
    if names is not None:
        head += "names:\n" + "".join(f'   - "{n}"\n' for n in names)
    return head + "".join(items)


def intri(name="c1", k=K, dist=(-0.2, 0.05, 0.001, -0.002, 0.0), size=(640, 480), model=None, key="dist") -> str:
    out = mat(f"K_{name}", k)
    if dist is not None:
        out += mat(f"{key}_{name}", [dist], (1, len(dist)))
    if size is not None:
        out += f"H_{name}: {size[1]}\nW_{name}: {size[0]}\n"
    if model is not None:
        out += f"model_{name}: {model}\n"
    return out


def extri(name="c1", rvec=RV, rot=R, t=(0.1, 0.2, 3.0)) -> str:
    out = ""
    if rvec is not None:
        out += mat(f"R_{name}", rvec)
    if rot is not None:
        out += mat(f"Rot_{name}", rot)
    return out + mat(f"T_{name}", t)


def files(tmp_path, i_text, e_text):
    tmp_path.mkdir(parents=True, exist_ok=True)
    (tmp_path / "intri.yml").write_text(i_text)
    (tmp_path / "extri.yml").write_text(e_text)
    return tmp_path / "intri.yml", tmp_path / "extri.yml"


def read(tmp_path, i_text, e_text):
    return reader("opencv")(*files(tmp_path, i_text, e_text))


def test_hand_written_pair_and_notes(tmp_path):
    parts = read(tmp_path, doc(intri(), intri("c2", dist=(0.01, 0.0, 0.0, 0.0), model="fisheye", key="D", size=None),
                               names=("c1", "c2")),
                 doc(extri(), extri("c2", rot=None), names=None))
    c1, c2 = parts.cameras["c1"], parts.cameras["c2"]
    np.testing.assert_array_equal(c1.K, K)
    np.testing.assert_array_equal(c1.dist, [-0.2, 0.05, 0.001, -0.002, 0.0])
    np.testing.assert_array_equal(c1.R, R)  # Rot_ exact: kept to the bit
    np.testing.assert_array_equal(c1.t, [0.1, 0.2, 3.0])
    assert c1.size == (640, 480) and c1.model == "pinhole"
    assert c2.model == "fisheye" and c2.size == (641, 481)  # 2 c + 1
    np.testing.assert_array_equal(c2.dist, [0.01, 0.0, 0.0, 0.0])  # D_ read when dist_ is absent
    np.testing.assert_allclose(c2.R, R, rtol=0, atol=1e-15)
    assert parts.notes == ("units: EasyMocap's documentation asks for metres",
                           "warning: no H_/W_ image size for c2: guessed from the principal point (2 c + 1)")
    assert parts.metadata == {"size_guessed": ["c2"]}
    assert (parts.units, parts.units_fixed, parts.own_frame) == ("m", False, False)
    np.testing.assert_array_equal(parts.ground.normal, [0.0, 0.0, 1.0])


def test_rounded_rotations_ground_and_metadata(tmp_path):
    """Rot_ with 5 decimals (off by ~1e-5): taken from R_ when present, else the nearest
    rotation (SVD here); ground plane and studio metadata read."""
    Rr = np.round(R, 5)
    U, _, Vt = np.linalg.svd(Rr)
    e = doc(extri(rot=Rr), extri("c2", rvec=None, rot=Rr), mat("ground_normal", [0.0, 0.0, 1.0]),
            "ground_offset: 0.25\n", 'studio_metadata: "{\\"who\\": \\"me\\"}"\n', names=("c1", "c2"))
    parts = read(tmp_path, doc(intri(), intri("c2"), names=("c1", "c2")), e)
    np.testing.assert_array_equal(parts.cameras["c1"].R, Rotation.from_rotvec(RV).as_matrix())
    np.testing.assert_allclose(parts.cameras["c2"].R, U @ Vt, rtol=0, atol=1e-14)
    assert parts.notes == ("units: EasyMocap's documentation asks for metres",
                           "rotations of c1, c2 written with few decimals (not orthonormal to 1e-06, within 0.0001): "
                           "taken from R_ (Rodrigues) or the nearest rotation (SVD)")
    assert parts.metadata == {"who": "me"} and parts.own_frame
    assert parts.ground.offset == 0.25


@pytest.mark.parametrize("i_items, e_items, detail, camera, field, which", [
    ((intri(k=[[500.0, 0, 320], [0, 510, 240]]),), (extri(),), "expected shape (3, 3), got (2, 3)", "c1", "K_c1",
     "intri"),
    ((intri(k=[[500.0, 0, 320], [0, 510, 240]], size=None),), (extri(),), "expected shape (3, 3), got (2, 3)",
     "c1", "K_c1", "intri"),
    ((intri(dist=(0.1, 0.2, 0.3)),), (extri(),), "expected (0, 4, 5, 8, 12, 14) coefficients, got 3", "c1",
     "dist_c1", "intri"),
    ((intri(size=(0, 480)),), (extri(),), "expected two positive integers (width, height), got (0.0, 480.0)", "c1",
     "W_c1/H_c1", "intri"),
    ((intri(model="pinhole2"),), (extri(),), "expected one of ('pinhole', 'fisheye'), got 'pinhole2'", "c1", "model_c1",
     "intri"),
    ((intri(model=3),), (extri(),), "expected a string, 'pinhole' or 'fisheye'", "c1", "model_c1", "intri"),
    ((intri(),), (extri(rvec=None, rot=None),), "missing (neither Rot_c1 nor R_c1)", "c1", "R_c1", "extri"),
    ((intri(),), (extri(rvec=[0.1, 0.2]),), "expected a 3x1 Rodrigues vector, got shape (2, 1)", "c1", "R_c1",
     "extri"),
    ((intri(),), (extri(rvec=None, rot=np.diag([1.0, 1.0, -1.0])),), "determinant is -1 (a reflection, not a rotation)",
     "c1", "Rot_c1", "extri"),
    ((intri(),), (extri(rvec=None, rot=np.diag([1.0, 1.0, 1.001])),),
     "not a rotation: max |R Rᵀ - I| = 0.002, more than rounding to few decimals explains (0.0001)", "c1", "Rot_c1",
     "extri"),
    ((intri(),), (extri(rvec=[0.1, -0.2, 0.31]),), f"disagrees with R_c1 (max difference {GAP:.3g} > 0.0001)", "c1",
     "Rot_c1", "extri"),
    ((intri(),), (extri(t=(0.1, 0.2)),), "expected shape (3,), got (2, 1)", "c1", "T_c1", "extri"),
    ((intri(),), (extri(), mat("ground_normal", [0.0, 0.0, 1.0])), "missing", None, "ground_offset", "extri"),
    ((intri(),), (extri(), mat("ground_normal", [0.0, 0.0, 2.0]), "ground_offset: 0\n"),
     "normal must have unit length, |n| = 2", None, "ground.normal", "extri"),
    ((intri(),), (extri(), 'studio_metadata: "{x"\n'),
     "not JSON (Expecting property name enclosed in double quotes: line 1 column 2 (char 1))", None,
     "studio_metadata", "extri"),
])
def test_refusals_name_file_camera_and_key(tmp_path, i_items, e_items, detail, camera, field, which):
    paths = files(tmp_path, doc(*i_items), doc(*e_items))
    exc = raised(reader("opencv"), *paths)
    assert_error(exc, detail, camera=camera, field=field, file=paths[0] if which == "intri" else paths[1])


def test_names_refusals_and_kinds(tmp_path):
    i, e = files(tmp_path, doc(intri(), names=None), doc(extri()))
    assert_error(raised(reader("opencv"), i, e), "missing", field="names", file=i)
    for key in ("camera_matrix", "CameraMatrix"):
        i.write_text(doc(mat(key, K), names=None))
        assert_error(raised(reader("opencv"), i, e),
                     f"missing: this is a single-camera OpenCV file ({key}), not EasyMocap's intri.yml: read it as "
                     "format opencv_camera (load_any detects it)", field="names", file=i)
    i.write_text("%YAML:1.0\n---\nnames: []\n")
    assert_error(raised(reader("opencv"), i, e), "empty camera list", field="names", file=i)
    i.write_text(doc(intri(), names=("c1", "c2", "c1")))
    assert_error(raised(reader("opencv"), i, e), "camera 'c1' is listed twice (entries 0 and 2): expected unique names",
                 field="names", file=i)
    i.write_text(doc(intri(), intri("c2"), names=("c1", "c2")))
    e.write_text(doc(extri(), names=("c1", "c3")))
    assert_error(raised(reader("opencv"), i, e), "listed in intri but not in extri", camera="c2", field="names", file=e)
    i.write_text("%YAML:1.0\n---\nnames: [ 7, 2.5 ]\n" + intri("7") + intri("2.5"))
    e.write_text("%YAML:1.0\n---\n" + extri("7") + extri("2.5"))
    assert list(reader("opencv")(i, e).cameras) == ["7", "2.5"]


def test_text_and_matrix_values_refused(tmp_path):
    i, e = files(tmp_path, doc(intri()), doc(extri()))
    e.write_text(doc(extri(t=(0.1, 0.2, 3.0)).replace("data: [ 0.1, 0.2, 3.0 ]", 'data: [ 0.1, "x", 3.0 ]')))
    assert_error(raised(reader("opencv"), i, e), "element 1 is 'x': expected a number", camera="c1", field="T_c1",
                 file=e)
    e.write_text(doc(extri(t=(0.1, 0.2, 3.0)).replace("data: [ 0.1, 0.2, 3.0 ]", "data: [ 0.1, { a: 1 }, 3.0 ]")))
    assert_error(raised(reader("opencv"), i, e), "element 1 is 'a mapping': expected a number", camera="c1",
                 field="T_c1", file=e)
    e.write_text(doc(extri(t=(0.1, 0.2, 3.0)).replace("data: [ 0.1, 0.2, 3.0 ]", "data: [ 0.1, [ 1 ], 3.0 ]")))
    assert_error(raised(reader("opencv"), i, e), "element 1 is 'not a number': expected a number", camera="c1",
                 field="T_c1", file=e)
    e.write_text(doc(extri(), "ground_normal: [ 0, 0, 1 ]\nground_offset: 0.5\n"))
    assert_error(raised(reader("opencv"), i, e), "not an OpenCV matrix", field="ground_normal", file=e)
    i.write_text(doc(intri(size=None), "H_c1: x\nW_c1: 640\n"))
    assert_error(raised(reader("opencv"), i, e), "element 0 is 'x': expected a number", camera="c1", field="H_c1",
                 file=i)


def test_size_and_nesting_limits_at_the_limit(tmp_path):
    """MAX_BYTES is the largest size read ('at most'); MAX_NESTING the deepest nesting accepted."""
    path = tmp_path / "big.yml"
    with open(path, "wb") as f:
        f.truncate(MAX_BYTES)
    _check_text(path)  # exactly the limit: read
    with open(path, "wb") as f:
        f.truncate(MAX_BYTES + 1)
    assert_error(raised(_check_text, path), "67108865 bytes: larger than any calibration (67108864 bytes at most)",
                 file=path)
    path.write_text("a: " + "[" * MAX_NESTING + "]" * MAX_NESTING + "\nb: { c: [ 1 ] }\n")
    _check_text(path)
    path.write_text("a: " + "[{" * 32 + "[" + "]" + "}]" * 32)
    assert_error(raised(_check_text, path), "nested more than 64 levels deep: not a calibration", file=path)
    path.write_text("a: " + "[]" * 100)
    _check_text(path)
    path.write_bytes(b"a: \xe9t\xe9")
    assert_error(raised(_check_text, path), "not UTF-8 text (byte 3): expected a UTF-8 YAML/XML file", file=path)
    assert MAX_NESTING == 64 and MAX_BYTES == 64 * 1024 * 1024
    assert os.path.getsize(path) == 6


def test_paths_of_a_pair(tmp_path):
    """A .yml/.yaml name gives its extri sibling by name; a folder gives intri.yml/extri.yml."""
    rig = RigCalibration([Camera("c1", K, [], R, [0.1, 0.2, 3.0], (640, 480))])
    rig.write(tmp_path / "a_intri.yaml", "opencv")
    assert (tmp_path / "a_extri.yaml").is_file()
    assert list(reader("opencv")(tmp_path / "a_intri.yaml").cameras) == ["c1"]
    assert list(reader("opencv")(tmp_path / "a_intri.yaml", tmp_path / "a_extri.yaml").cameras) == ["c1"]
    assert_error(raised(reader("opencv"), tmp_path), "no such file", file=tmp_path / "intri.yml")


def test_writer_document_read_with_filestorage(tmp_path):
    cams = [Camera("c1", K, [], R, [0.1, 0.2, 3.0], (640, 480)),
            Camera("c2", K, [0.01, 0.0, 0.0, 0.0], np.eye(3), [1.0, 0.0, 3.0], (800, 600), "fisheye")]
    rig = RigCalibration(cams, ground=GroundPlane([0.0, 0.0, 1.0], 0.25), metadata={"who": "me"})
    i, e = tmp_path / "sub" / "intri.yml", tmp_path / "sub" / "extri.yml"
    rig.write(tmp_path / "sub", "opencv")
    assert i.read_text().startswith("%YAML:1.0\n") and e.read_text().startswith("%YAML:1.0\n")
    fi = cv2.FileStorage(str(i), cv2.FILE_STORAGE_READ)
    fe = cv2.FileStorage(str(e), cv2.FILE_STORAGE_READ)
    node = fi.getNode("names")
    assert [node.at(k).string() for k in range(node.size())] == ["c1", "c2"]
    np.testing.assert_array_equal(fi.getNode("K_c1").mat(), K)
    np.testing.assert_array_equal(fi.getNode("dist_c1").mat(), np.zeros((1, 5)))
    np.testing.assert_array_equal(fi.getNode("dist_c2").mat(), [[0.01, 0.0, 0.0, 0.0]])
    assert (fi.getNode("H_c2").real(), fi.getNode("W_c2").real()) == (600.0, 800.0)
    assert (fi.getNode("model_c1").string(), fi.getNode("model_c2").string()) == ("pinhole", "fisheye")
    np.testing.assert_allclose(fe.getNode("R_c1").mat(), np.reshape(RV, (3, 1)), rtol=0, atol=1e-15)
    np.testing.assert_array_equal(fe.getNode("Rot_c1").mat(), R)
    np.testing.assert_array_equal(fe.getNode("T_c1").mat(), [[0.1], [0.2], [3.0]])
    np.testing.assert_array_equal(fe.getNode("ground_normal").mat(), [[0.0], [0.0], [1.0]])
    assert fe.getNode("ground_offset").real() == 0.25
    assert json.loads(fe.getNode("studio_metadata").string()) == {"who": "me"}
    fi.release()
    fe.release()
    for bad in ("a b", "a:b", "a{", "a]", "a,b", "a#", "a'b", 'a"b', "a%", "a@", "a`", "a|b", "a>b", "a!"):
        one = RigCalibration([cams[0].replace(name=bad)])
        assert_error(raised(one.write, tmp_path / "x", "opencv"),
                     "camera names must be plain words to form FileStorage keys like K_<name>", camera=bad,
                     field="name", file=tmp_path / "x" / "intri.yml")


def test_rotation_tolerances_at_their_bounds(tmp_path):
    """Rot_ alone off by exactly ROUNDING_TOL (1e-4): the nearest rotation (SVD here), with the
    rounding note; off by exactly EXACT_TOL (1e-6): kept as written, no note."""
    for e, note in ((1e-4, True), (1e-6, False)):
        M = np.eye(3)
        M[0, 1] = e
        assert np.max(np.abs(M @ M.T - np.eye(3))) == e
        parts = read(tmp_path, doc(intri()), doc(extri(rvec=None, rot=M)))
        U, _, Vt = np.linalg.svd(M)
        if note:
            np.testing.assert_allclose(parts.cameras["c1"].R, U @ Vt, rtol=0, atol=1e-15)
            assert parts.notes[1].startswith("rotations of c1 written with few decimals")
        else:
            np.testing.assert_array_equal(parts.cameras["c1"].R, M)
            assert parts.notes == ("units: EasyMocap's documentation asks for metres",)


def test_extri_anywhere_names_with_x_and_odd_rotations(tmp_path):
    """to_opencv with an extri path of its own, in a folder not there yet; camera names may hold
    an X; a Rot_ of another shape is named by the camera check; a singular Rot_ is refused as
    not a rotation (err 1 > 1e-4), not passed on."""
    rig = RigCalibration([Camera("camX1", K, [], R, [0.1, 0.2, 3.0], (640, 480))])
    i, e = rig.to_opencv(tmp_path / "a" / "in.yml", tmp_path / "b" / "c" / "out.yml")
    assert (i, e) == (tmp_path / "a" / "in.yml", tmp_path / "b" / "c" / "out.yml") and e.is_file()
    parts = reader("opencv")(i, e)
    np.testing.assert_array_equal(parts.cameras["camX1"].R, R)
    paths = files(tmp_path / "d", doc(intri()), doc(extri(rot=np.eye(3).ravel()[:9].reshape(1, 9))))
    assert_error(raised(reader("opencv"), *paths), "expected shape (3, 3), got (1, 9)", camera="c1", field="Rot_c1",
                 file=paths[1])
    paths = files(tmp_path / "e", doc(intri()), doc(extri(rvec=None, rot=np.zeros((3, 3)))))
    assert_error(raised(reader("opencv"), *paths),
                 "not a rotation: max |R Rᵀ - I| = 1, more than rounding to few decimals explains (0.0001)",
                 camera="c1", field="Rot_c1", file=paths[1])


def test_distortion_absent_or_malformed_and_extri_names(tmp_path):
    """Neither dist_ nor D_: a camera without distortion; a text element in dist_ or D_ named;
    a duplicate in extri's names named in extri."""
    parts = read(tmp_path / "a", doc(intri(dist=None)), doc(extri()))
    assert parts.cameras["c1"].dist.size == 0
    for key in ("dist", "D"):
        text = doc(intri(key=key)).replace("data: [ -0.2,", 'data: [ "x",')
        paths = files(tmp_path / key, text, doc(extri()))
        assert_error(raised(reader("opencv"), *paths), "element 0 is 'x': expected a number", camera="c1",
                     field=f"{key}_c1", file=paths[0])
    paths = files(tmp_path / "n", doc(intri()), doc(extri(), names=("c1", "c1")))
    assert_error(raised(reader("opencv"), *paths), "camera 'c1' is listed twice (entries 0 and 1): expected unique "
                 "names", field="names", file=paths[1])


def test_nesting_counted_after_closed_pairs_and_more_text_elements(tmp_path):
    """Depth is counted from the start: a closed pair before 65 open brackets is still 65 deep.
    Text in W_ or Rot_ is named; two cameras without a size are both listed in the warning."""
    path = tmp_path / "deep.yml"
    path.write_text("a: [] " + "[" * 65 + "]" * 65)
    assert_error(raised(_check_text, path), "nested more than 64 levels deep: not a calibration", file=path)
    i_text = doc(intri(size=None), "H_c1: 480\nW_c1: x\n")
    paths = files(tmp_path / "w", i_text, doc(extri()))
    assert_error(raised(reader("opencv"), *paths), "element 0 is 'x': expected a number", camera="c1", field="W_c1",
                 file=paths[0])
    e_text = doc(extri()).replace("data: [ " + ", ".join(repr(float(v)) for v in R.ravel()), "data: [ \"x\"")
    paths = files(tmp_path / "r", doc(intri()), e_text)
    assert_error(raised(reader("opencv"), *paths), "element 0 is 'x': expected a number", camera="c1", field="Rot_c1",
                 file=paths[1])
    parts = read(tmp_path / "two", doc(intri(size=None), intri("c2", size=None), names=("c1", "c2")),
                 doc(extri(), extri("c2"), names=None))
    assert parts.notes[1] == ("warning: no H_/W_ image size for c1, c2: guessed from the principal point (2 c + 1)")
