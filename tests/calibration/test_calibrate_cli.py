"""``studio calibrate``: end to end on a rendered capture session, real photos, and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibration import RigCalibration
from calibration.boards import load_board
from calibration.synthetic import camera_ring, floor_board_pose, random_board_poses, render_board_view
from studio.cli import main

BOARD = "studio_charuco_a1"


@pytest.fixture(scope="module")
def rendered_session(tmp_path_factory):
    """4 distortion-free cameras, frame 0 = ChArUco board on the floor, frames 1-32 hand-held."""
    from rigs.session import SessionWriter

    rng = np.random.default_rng(7)
    board = load_board(BOARD)
    cams = camera_ring(4, radius=2.2, height=1.5, target=(0.2, -0.2, 0.7), size=(800, 500), focal=650.0,
                       dist=(0.0, 0.0, 0.0, 0.0, 0.0))
    poses = [floor_board_pose(board, (0.0, 0.0))]
    poses += list(random_board_poses(32, board, rng, centre=(0.2, -0.2, 0.9), spread=(0.4, 0.4, 0.25),
                                     max_tilt_deg=40).values())
    path = tmp_path_factory.mktemp("calib") / "session"
    with SessionWriter.create(path, list(cams), rig="synthetic") as writer:
        for index, pose in enumerate(poses):
            writer.write_frame(index, {n: render_board_view(c, board, pose, rng=rng) for n, c in cams.items()})
    return path, cams


def test_calibrate_all_from_session(rendered_session, tmp_path, capsys):
    path, truth = rendered_session
    out = tmp_path / "calibration.json"
    code = main(["calibrate", "all", str(path), "--board", BOARD, "-o", str(out), "--floor-frames", "0"])
    assert code == 0
    rig = RigCalibration.load(out)
    assert rig.camera_names == list(truth)
    for name, cam in rig.cameras.items():
        # few views per camera at ~30 px per square: centimetre-level, z up from the floor board
        assert np.linalg.norm(cam.center - truth[name].center) < 0.03, name
        assert abs(cam.K[0, 0] / truth[name].K[0, 0] - 1) < 0.02, name
    meta = rig.metadata
    assert meta["world_frame"].startswith("floor board") and meta["extrinsics"]["rms_px"] < 0.5
    assert set(meta["floor_check"]) == set(truth)
    report = (tmp_path / "calibration_report.html").read_text()
    for section in ("Intrinsics", "bundle adjustment", "Floor and world frame", "rig from above", "data:image/png;base64"):
        assert section in report
    assert "wrote" in capsys.readouterr().out


def test_calibrate_steps_from_folders(rendered_session, tmp_path):
    """intrinsics -> extrinsics -> floor, with the session's images laid out as folders per camera."""
    from rigs.session import Session

    path, truth = rendered_session
    s = Session.open(path)
    import shutil

    for cam in s.cameras:
        (tmp_path / "views" / cam).mkdir(parents=True)
        for i in s.frame_indices[1:]:
            shutil.copy(s.frame_path(cam, i), tmp_path / "views" / cam / f"{cam}_{i:03d}.png")
    views = [f"{c}={tmp_path / 'views' / c}" for c in s.cameras]
    intr = tmp_path / "intr.json"
    assert main(["calibrate", "intrinsics", "--board", BOARD, "-o", str(intr), *views]) == 0
    ext = tmp_path / "ext.json"
    assert main(["calibrate", "extrinsics", "--board", BOARD, "--intrinsics", str(intr), "-o", str(ext), *views]) == 0
    floor = [f"{c}={s.frame_path(c, 0)}" for c in s.cameras]
    world = tmp_path / "world.json"
    assert main(["calibrate", "floor", "--board", BOARD, "--calibration", str(ext), "-o", str(world), *floor]) == 0
    rig = RigCalibration.load(world)
    for name, cam in rig.cameras.items():
        assert np.linalg.norm(cam.center - truth[name].center) < 0.03, name
    assert (tmp_path / "calibration_report.html").exists()


def test_intrinsics_cli_on_opencv_samples(shared_data, tmp_path):
    folder = shared_data / "calibration/opencv_chessboard_9x6"
    out = tmp_path / "c.json"
    code = main(["calibrate", "intrinsics", "--board", "opencv_chessboard_9x6", "--fix-aspect", "-o", str(out),
                 f"left={folder}/left*.jpg"])
    assert code == 0
    data = json.loads(out.read_text())
    fx = data["cameras"]["left"]["K"][0][0]
    assert abs(fx / 535.916 - 1) < 0.005
    assert data["metadata"]["intrinsics"]["left"]["rms_px"] < 0.39


def test_cli_bad_input_one_line_errors(tmp_path, capsys, shared_data):
    folder = shared_data / "calibration/opencv_charuco_5x7"
    cases = [
        (["calibrate", "intrinsics", "--board", "nope", f"a={folder}"], "board 'nope' not found"),
        (["calibrate", "intrinsics", "--board", "opencv_chessboard_9x6", f"a={folder}"],
         "was not detected in any of 4 frames"),
        (["calibrate", "intrinsics", "--board", "opencv_charuco_5x7", f"{folder}/img_*.jpg"], "name the camera of a glob"),
        (["calibrate", "intrinsics", "--board", "opencv_charuco_5x7", f"x={tmp_path}/none*.jpg"], "no file matches"),
        (["calibrate", "intrinsics", "--board", "opencv_charuco_5x7", "=abc"], "expected NAME=PATH"),
        (["calibrate", "extrinsics", "--board", "opencv_charuco_5x7", "--intrinsics", str(tmp_path / "no.json"),
          f"a={folder}"], "no.json"),
        (["calibrate", "all", str(tmp_path / "nosession"), "--board", "opencv_charuco_5x7"], "nosession"),
    ]
    for argv, message in cases:
        assert main(argv) == 1, argv
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, (argv, err)
    assert main(["calibrate"]) == 2


def test_cli_session_and_camera_errors(rendered_session, tmp_path, capsys):
    path, truth = rendered_session
    assert main(["calibrate", "all", str(path), "--board", BOARD, "--floor-frames", "99", "-o", str(tmp_path / "c.json")]) == 1
    assert "floor frames [99] are not complete frames" in capsys.readouterr().err
    assert main(["calibrate", "all", str(path), "--board", BOARD, "--floor-frames", "a,b", "-o", str(tmp_path / "c.json")]) == 1
    assert "--floor-frames must be comma-separated" in capsys.readouterr().err
    RigCalibration({n: c for n, c in truth.items() if n != "cam03"}).save(tmp_path / "three.json")
    assert main(["calibrate", "extrinsics", "--board", BOARD, "--intrinsics", str(tmp_path / "three.json"),
                 f"cam03={tmp_path}"]) == 1
    assert "no intrinsics for cameras ['cam03']" in capsys.readouterr().err
    assert main(["calibrate", "floor", "--board", BOARD, "--calibration", str(tmp_path / "three.json"),
                 f"cam03={tmp_path}/x.png"]) == 1
    assert "camera 'cam03' is not calibrated" in capsys.readouterr().err
    assert main(["calibrate", "extrinsics", "--board", BOARD, "--intrinsics", str(tmp_path / "three.json"),
                 f"cam00={tmp_path}/nothing"]) == 1
    assert "not a folder of images" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    assert main(["calibrate", "extrinsics", "--board", BOARD, "--intrinsics", str(tmp_path / "three.json"),
                 f"cam00={tmp_path}/empty"]) == 1
    assert "no images (.png/.jpg) in this folder" in capsys.readouterr().err


def test_cli_too_few_views_names_source(shared_data, capsys):
    folder = shared_data / "calibration/opencv_charuco_5x7"
    assert main(["calibrate", "intrinsics", "--board", "opencv_charuco_5x7", "--views", "2", f"tut={folder}"]) == 1
    err = capsys.readouterr().err
    assert f"{folder}: camera 'tut': only 2 usable views" in err and "capture 1 more" in err
