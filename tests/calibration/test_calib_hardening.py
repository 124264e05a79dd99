"""Bad calibration files are refused naming the file and the field; nothing is silently dropped
(defects 2/7, 3, 12, 15, 16 of the hardening issue)."""

from __future__ import annotations

import ast
import logging
from pathlib import Path

import numpy as np
import pytest

from calibration import CalibrationError, RigCalibration
from studio.cli import main

from test_calib_formats import POSE2SIM, make_rig  # noqa: E402  (same folder)

FORMATS_DIR = Path(__file__).parents[2] / "calibration" / "formats"


def test_format_modules_do_not_import_the_rig_class():
    """The registry is the one way between formats and RigCalibration: no import circle."""
    for module in FORMATS_DIR.glob("*.py"):
        tree = ast.parse(module.read_text())
        imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
        imported |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        assert "calibration.rig" not in imported, module.name
        assert "calibration" not in imported or module.name == "__init__.py", module.name


def test_qualisys_duplicate_serial_and_nan(shared_data, tmp_path):
    src = (shared_data / POSE2SIM / "Calib.qca.txt").read_text()
    bad = tmp_path / "dup.qca.txt"
    bad.write_text(src.replace('serial="cam02"', 'serial="cam01"'))
    with pytest.raises(CalibrationError, match=r"dup\.qca\.txt: field 'serial': <camera> entries 0 and 1 share serial 'cam01'"):
        RigCalibration.from_qualisys(bad)
    bad.write_text(src.replace('x="2582.0136248568124"', 'x="nan"'))
    with pytest.raises(CalibrationError, match=r"camera 'cam02': field 'transform\.x': expected a finite number, got 'nan'"):
        RigCalibration.from_qualisys(bad)


def test_opencv_text_in_a_matrix_and_duplicate_names(tmp_path):
    intri, extri = make_rig(5).to_opencv(tmp_path / "ocv")
    text = intri.read_text()
    start = text.index("data: [", text.index("K_02:")) + len("data: [")
    intri.write_text(text[:start] + "abc, " + text[text.index(",", start) + 1:])
    with pytest.raises(CalibrationError, match=r"intri\.yml: camera '02': field 'K_02': element 0 is 'abc': expected a number"):
        RigCalibration.from_opencv(tmp_path / "ocv")
    intri.write_text(text.replace('- "02"', '- cam_a', 1) if '- "02"' in text else text.replace("- '02'", "- cam_a", 1))
    with pytest.raises(CalibrationError, match=r"field 'names': camera 'cam_a' is listed twice \(entries 0 and 1\)"):
        RigCalibration.from_opencv(tmp_path / "ocv")


def test_deeply_nested_or_non_utf8_files_are_refused(tmp_path):
    """A 100 000-deep YAML used to crash the process inside OpenCV's parser."""
    intri, extri = make_rig(5).to_opencv(tmp_path / "ocv")
    intri.write_text("%YAML:1.0\n---\nx: " + "[" * 100_000 + "]" * 100_000 + "\n")
    with pytest.raises(CalibrationError, match=r"intri\.yml: nested more than 64 levels deep"):
        RigCalibration.from_opencv(tmp_path / "ocv")
    intri.write_bytes(b"%YAML:1.0\n---\nnames: [ \xff\xfe ]\n")
    with pytest.raises(CalibrationError, match=r"intri\.yml: not UTF-8 text \(byte 23\)"):
        RigCalibration.from_opencv(tmp_path / "ocv")
    (tmp_path / "c.json").write_bytes(b'{"format": "\xff"}')
    with pytest.raises(CalibrationError, match=r"c\.json: not UTF-8 text \(byte 12\)"):
        RigCalibration.load(tmp_path / "c.json")
    (tmp_path / "d.json").write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(CalibrationError, match=r"d\.json: not valid JSON \(nested too deeply\)"):
        RigCalibration.load(tmp_path / "d.json")
    (tmp_path / "e.toml").write_bytes(b'[cam]\nname = "\xff"\n')
    with pytest.raises(CalibrationError, match=r"e\.toml: not UTF-8 text"):
        RigCalibration.from_toml(tmp_path / "e.toml")


def test_colmap_zero_quaternion_and_missing_sidecar(tmp_path, caplog):
    rig = make_rig(5)
    rig.to_colmap(tmp_path / "col")
    frames = tmp_path / "col" / "frames.txt"
    lines = frames.read_text().splitlines()
    k = next(i for i, line in enumerate(lines) if line and not line.startswith("#"))
    parts = lines[k].split()
    parts[2:6] = ["0", "0", "0", "0"]
    lines[k] = " ".join(parts)
    frames.write_text("\n".join(lines) + "\n")
    with pytest.raises(CalibrationError, match=rf"frames\.txt: field 'QW QX QY QZ': line {k + 1}: quaternion \[0\.0, 0\.0, 0\.0, 0\.0\] is not a rotation"):
        RigCalibration.from_colmap(tmp_path / "col")
    rig.to_colmap(tmp_path / "plain")
    (tmp_path / "plain" / "studio_rig.json").unlink()
    with caplog.at_level(logging.WARNING, logger="calibration.formats.colmap"):
        back = RigCalibration.from_colmap(tmp_path / "plain")
    assert "no studio_rig.json beside the COLMAP model" in caplog.text
    assert "assumed z = 0" in back.metadata["ground_source"]
    np.testing.assert_allclose(back["02"].K, rig["02"].K, atol=1e-9)


def test_convert_to_colmap_with_force_keeps_the_users_points(tmp_path, capsys):
    src = make_rig(5).save(tmp_path / "calibration.json")
    out = tmp_path / "sparse"
    assert main(["convert", str(src), str(out), "--to", "colmap", "--binary"]) == 0
    user_points = b"the user's reconstruction"
    (out / "points3D.bin").write_bytes(user_points)
    (out / "points3D.txt").write_text("# the user's text points\n")
    (out / "notes.md").write_text("mine")
    assert main(["convert", str(src), str(out), "--to", "colmap", "--binary", "--force"]) == 0
    assert (out / "points3D.bin").read_bytes() == user_points
    assert (out / "points3D.txt").read_text() == "# the user's text points\n"
    assert (out / "notes.md").read_text() == "mine"
    assert sorted(p.name for p in out.iterdir() if p.suffix == ".bin") == [
        "cameras.bin", "frames.bin", "images.bin", "points3D.bin", "rigs.bin"]
