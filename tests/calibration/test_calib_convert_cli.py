"""``studio convert``: every format pair through the command line."""

import re

import numpy as np
import pytest

from calibration import Camera, GroundPlane, RigCalibration
from studio.cli import main


def make_rig() -> RigCalibration:
    K = np.array([[800.0, 0.0, 319.0], [0.0, 801.0, 241.0], [0.0, 0.0, 1.0]])
    cams = [
        Camera(f"c{i}", K, [0.01 * i, -0.02, 0.001, 0.0, 0.003], np.eye(3), [0.1 * i, 0.0, 3.0], (640, 480))
        for i in range(2)
    ]
    return RigCalibration(cams, GroundPlane([0.0, 0.0, 1.0], 0.02), {"site": "lab"})

POSE2SIM_TOML = "calibration/pose2sim_demo_4cam/Calib_scene.pose2sim_output_at_1bcde0685195.toml"


def test_convert_chain_through_all_formats(shared_data, tmp_path, capsys):
    src = shared_data / POSE2SIM_TOML
    assert main(["convert", str(src), str(tmp_path / "a.json")]) == 0
    assert "wrote 4 cameras" in capsys.readouterr().out
    assert main(["convert", str(tmp_path / "a.json"), str(tmp_path / "ocv"), "--to", "opencv"]) == 0
    assert main(["convert", str(tmp_path / "ocv"), str(tmp_path / "col"), "--to", "colmap", "--binary"]) == 0
    assert (tmp_path / "col" / "cameras.bin").exists()
    assert main(["convert", str(tmp_path / "col"), str(tmp_path / "b.toml")]) == 0
    assert main(["convert", str(tmp_path / "b.toml"), str(tmp_path / "intri.yml")]) == 0
    assert main(["convert", str(tmp_path / "intri.yml"), str(tmp_path / "c.json"), "--from", "opencv"]) == 0
    first = RigCalibration.load_any(src)
    last = RigCalibration.load(tmp_path / "c.json")
    assert first.allclose(last, atol=1e-9)
    assert np.allclose(first["int_cam02_img"].K, last["int_cam02_img"].K, rtol=0, atol=1e-9)


def test_convert_reads_qualisys(shared_data, tmp_path):
    qca = shared_data / "calibration/pose2sim_demo_4cam/Calib.qca.txt"
    assert main(["convert", str(qca), str(tmp_path / "q.json")]) == 0
    assert RigCalibration.load(tmp_path / "q.json").camera_names == ["cam01", "cam02", "cam03", "cam04"]


@pytest.mark.parametrize(
    "args, message",
    [
        (["missing.json", "out.json"], "no such file or folder"),
        (["in.json", "newfolder"], "cannot tell the output format of a new folder"),
        (["in.json", "out.xyz"], "cannot tell the calibration format.*pass --to"),
        (["in.json", "in.json"], "exists; pass --force"),
        (["bad.json", "out.json"], r"bad\.json: field 'version': unknown major version 9"),
    ],
)
def test_convert_errors_are_one_line(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    make_rig().save(tmp_path / "in.json")
    (tmp_path / "bad.json").write_text((tmp_path / "in.json").read_text().replace('"version": 1', '"version": 9'))
    assert main(["convert", *args]) == 1
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert re.search(message, err), err


def test_convert_force_overwrites(tmp_path):
    make_rig().save(tmp_path / "in.json")
    main(["convert", str(tmp_path / "in.json"), str(tmp_path / "out.toml")])
    assert main(["convert", str(tmp_path / "in.json"), str(tmp_path / "out.toml"), "--force"]) == 0
    assert main(["convert", str(tmp_path / "in.json"), str(tmp_path / "ocv"), "--to", "opencv"]) == 0
    assert main(["convert", str(tmp_path / "in.json"), str(tmp_path / "ocv"), "--to", "opencv"]) == 1
