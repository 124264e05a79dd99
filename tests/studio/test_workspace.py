"""The Workspace: a session opened once, its calibration validated against it, every output path in one place."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibration import Camera, GroundPlane, RigCalibration
from rigs.session import SessionWriter
from studio.cli import main
from studio.workspace import Layout, Workspace, WorkspaceError, validate_calibration
from studio.workspace.frames import FrameSelectionError, select_frames

SIZE = (32, 24)


def _calibration(names=("a", "b"), size=SIZE, ground=None) -> RigCalibration:
    cams = {n: Camera.look_at(n, [3.0 * np.cos(k), 3.0 * np.sin(k), 2.0], [0, 0, 1], 30.0, size)
            for k, n in enumerate(names)}
    return RigCalibration(cameras=cams) if ground is None else RigCalibration(cameras=cams, ground=ground)


def _session(path, calibration=None, names=("a", "b"), frames=3):
    calib_file = None
    if calibration is not None:
        calib_file = path.parent / f"{path.name}-calibration.json"
        calibration.save(calib_file)
    with SessionWriter.create(path, list(names), rig="test", calibration=calib_file) as w:
        for i in range(frames):
            w.write_frame(i, {n: np.full((SIZE[1], SIZE[0], 3), 10 * i, np.uint8) for n in names})
    return path


def test_layout_places_every_output_and_truth_beside_the_source(tmp_path):
    lay = Layout(tmp_path / "out", source=tmp_path / "s")
    assert lay.labels("a", 12) == tmp_path / "out" / "segmentation" / "a" / "000012.png"
    assert lay.fit_overlay("a", 3) == tmp_path / "out" / "fit" / "overlay" / "a" / "000003.png"
    assert lay.truth_body(5) == tmp_path / "s" / "truth" / "bodies" / "000005.npz"
    assert lay.light_json == tmp_path / "out" / "light" / "light.json"
    assert Layout(tmp_path).truth_dir == tmp_path / "truth"


def test_open_validates_the_calibration_against_the_session(tmp_path):
    ws = Workspace.open(_session(tmp_path / "ok", _calibration()))
    assert ws.camera_names == ["a", "b"] and ws.frame_indices == [0, 1, 2] and ws.warnings == []
    assert [c.name for c in ws.cameras] == ["a", "b"]
    with pytest.raises(WorkspaceError, match=r"calibration\.json: no calibration for camera\(s\) \['b'\] of the session"):
        Workspace.open(_session(tmp_path / "missing", _calibration(names=("a",))))
    with pytest.raises(WorkspaceError, match=r"camera 'a': field 'size': calibrated for 64x48 images, the session's are 32x24"):
        Workspace.open(_session(tmp_path / "size", _calibration(size=(64, 48))))
    with pytest.raises(WorkspaceError, match="no such session folder"):
        Workspace.open(tmp_path / "absent")


def test_a_z_down_world_and_a_tilted_floor(tmp_path):
    down = _calibration(ground=GroundPlane(np.array([0.0, 0.0, -1.0]), 0.0))
    with pytest.raises(WorkspaceError, match=r"field 'ground.normal': expected a floor normal pointing up"):
        Workspace.open(_session(tmp_path / "down", down))
    tilt = np.radians(33.0)
    tilted = _calibration(ground=GroundPlane(np.array([np.sin(tilt), 0.0, np.cos(tilt)]), 0.0))
    ws = Workspace.open(_session(tmp_path / "tilt", tilted))
    assert len(ws.warnings) == 1 and "tilted 33.0°" in ws.warnings[0]


def test_implausible_focal_length_is_refused():
    from calibration import CalibrationError

    K = lambda f: np.array([[f, 0, 16], [0, f, 12], [0, 0, 1]])  # noqa: E731
    with pytest.raises(CalibrationError, match=r"camera 'a': field 'K': focal lengths must be at least 0.001"):
        Camera("a", K(1e-300), np.zeros(5), np.eye(3), np.array([0, 0, 3.0]), SIZE)
    cam = Camera("a", K(1e9), np.zeros(5), np.eye(3), np.array([0, 0, 3.0]), SIZE)
    with pytest.raises(WorkspaceError, match=r"calib.json: camera 'a': field 'K': expected focal lengths between 0.1 and 1e\+07 px, got fx=1e\+09"):
        validate_calibration(RigCalibration(cameras={"a": cam}), {"a": SIZE}, source="calib.json")


def test_unwritable_outputs_fail_before_any_work(tmp_path):
    ws = Workspace.open(_session(tmp_path / "s", _calibration()))
    (tmp_path / "s" / "fit").write_text("a file where the fit folder should be")
    with pytest.raises(WorkspaceError, match=r"s/fit: cannot write results there .*give an output folder with --out DIR"):
        ws.check_writable(ws.layout.fit_dir)
    other = Workspace.open(tmp_path / "s", out=tmp_path / "elsewhere")
    assert other.check_writable(other.layout.fit_dir) == tmp_path / "elsewhere" / "fit"
    assert other.layout.truth_dir == tmp_path / "s" / "truth"


def test_a_command_clears_what_a_killed_run_left_in_its_outputs(tmp_path):
    """Every command checks its output folder before work (fit, light, report, export, segment): the
    temporary files of a killed run's writers go, finished files and other folders stay."""
    ws = Workspace.open(_session(tmp_path / "s", _calibration()))
    fit, report = ws.layout.fit_dir, ws.layout.report_dir
    (fit / "overlay" / "a").mkdir(parents=True)
    report.mkdir()
    kept = [fit / "000000.json", fit / "overlay" / "a" / "000000.png", report / ".index.html.tmp-r1.html"]
    for p in kept:
        p.write_bytes(b"x")
    torn = [fit / ".000001.json.tmp-q9.json", fit / "overlay" / "a" / ".000001.png.tmp-z3.png"]
    for p in torn:
        p.write_bytes(b"half")
    ws.check_writable(fit)
    assert sorted(p for p in fit.rglob("*") if p.is_file()) == sorted(kept[:2])
    assert kept[2].is_file()  # the report folder is the report command's


def test_frame_selection_deduplicates_and_rejects_step_zero():
    frames = list(range(10))
    assert select_frames(None, frames) is None
    assert select_frames("1,1,1", frames) == [1]
    assert select_frames("3,1,3,2", frames) == [3, 1, 2]
    assert select_frames("0:10:4", frames) == [0, 4, 8]
    assert select_frames(":3", frames) == [0, 1, 2]
    with pytest.raises(FrameSelectionError, match="STEP must be a positive integer, got 0"):
        select_frames("0:10:0", frames)
    with pytest.raises(FrameSelectionError, match="STEP must be a positive integer, got -1"):
        select_frames("0:10:-1", frames)
    with pytest.raises(FrameSelectionError, match=r"STOP \(2\) must be greater than START \(5\)"):
        select_frames("5:2", frames)
    with pytest.raises(FrameSelectionError, match=r"frame\(s\) \[12\] are not complete frames"):
        select_frames("1,12", frames)
    with pytest.raises(FrameSelectionError, match="selects no frame"):
        select_frames("20:30", frames)
    with pytest.raises(FrameSelectionError, match="'x' is not an integer"):
        select_frames("x:3", frames)


def test_session_info_check_validates_the_calibration(tmp_path, capsys):
    _session(tmp_path / "s", _calibration(size=(64, 48)))
    assert main(["session", "info", str(tmp_path / "s"), "--check"]) == 1
    out = capsys.readouterr().out
    assert "calibration invalid" in out and "field 'size': calibrated for 64x48 images" in out
    assert main(["session", "info", str(tmp_path / "s"), "--check", "--json"]) == 1
    check = json.loads(capsys.readouterr().out)["check"]
    assert not check["ok"] and "field 'size'" in check["calibration_problems"][0]
    _session(tmp_path / "good", _calibration())
    assert main(["session", "info", str(tmp_path / "good"), "--check"]) == 0
    assert "calibration valid" in capsys.readouterr().out


def test_the_calibration_load_notes_and_import_warnings_reach_the_workspace(tmp_path):
    """What the load read and assumed is on ``ws.calibration.notes``; warnings of the load and of
    the ``studio convert`` that made the file join ``ws.warnings``."""
    calib = _calibration()
    calib = calib.replace(metadata={"import_notes": ["format: toml", "warning: units: m assumed — too few to tell"]})
    ws = Workspace.open(_session(tmp_path / "s", calib))
    assert "up axis: Z up (cameras 2.00 m above the floor)" in ws.calibration.notes
    assert len(ws.warnings) == 1 and ws.warnings[0].endswith("when imported: warning: units: m assumed — too few to tell")
    below = calib.replace(cameras={n: c.replace(R=c.R @ np.diag([1.0, -1.0, -1.0])) for n, c in calib.cameras.items()},
                          metadata={})
    ws = Workspace.open(_session(tmp_path / "b", below))
    assert len(ws.warnings) == 1 and "the world's Z axis points down" in ws.warnings[0]
