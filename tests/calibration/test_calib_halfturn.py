"""The half-turn ambiguity of symmetric checkerboards, Z up, the floor gates and the scale check.

The synthetic board (8x6 inner corners, 9x7 squares) is symmetric under a half turn, like the
Utrecht floor board; a camera that numbers its corners from the other end must be renumbered
(several placements decide it) or refused by name (one placement cannot), never silently
solved 180 deg off. Tolerances: 0.3 px corner noise gives rotations to ~0.05 deg.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration import GroundPlane
from calibration.boards import Board
from calibration.errors import CalibrationError
from calibration.extrinsics import calibrate_extrinsics
from calibration.floor import calibrate_floor
from calibration.halfturn import align_to_rig, is_half_turn_symmetric, resolve_half_turns, rotation_angle_deg, turned
from calibration.rigchecks import camera_heights, scale_check
from calibration.synthetic import camera_ring, floor_board_pose, make_scene, observe


def rel_rotation_error(cams, truth, a, b):
    est = cams[b].R @ cams[a].R.T
    tru = truth[b].R @ truth[a].R.T
    return rotation_angle_deg(est.T @ tru)


@pytest.fixture(scope="module")
def scene():
    return make_scene(n_cameras=4, n_views=24, noise_px=0.3, seed=5, radius=2.5)


def test_symmetry_rule():
    assert is_half_turn_symmetric(Board("a", "checkerboard", 8, 6, 0.1))
    assert not is_half_turn_symmetric(Board("b", "checkerboard", 9, 6, 0.1))  # 10x7 squares: corners differ in colour
    assert not is_half_turn_symmetric(Board("c", "charuco", 5, 7, 0.04, 0.02, "DICT_6X6_250"))


def test_turned_camera_is_renumbered_from_several_placements(scene):
    obs = {c: dict(v) for c, v in scene.observations.items()}
    victim = "cam02"
    turned_views = sorted(obs[victim])[::2]
    for v in turned_views:
        obs[victim][v] = turned(obs[victim][v])
    intr = {n: c.replace(R=np.eye(3), t=np.zeros(3)) for n, c in scene.cameras.items()}
    fixed, report = resolve_half_turns(intr, obs, scene.board, reference="cam00")
    shared = [v for v in turned_views if any(v in obs[c] for c in obs if c != victim)]
    assert len(shared) >= 3
    assert sum(r.startswith("renumbered") for r in report.values()) >= 1
    for v in shared:  # every camera seeing a placement numbers it alike (as truth, or all turned)
        as_truth = {c: np.array_equal(fixed[c][v].image_points, scene.observations[c][v].image_points)
                    for c in fixed if v in fixed[c]}
        assert len(set(as_truth.values())) == 1, (v, as_truth)
    ex = calibrate_extrinsics(intr, obs, board=scene.board)  # any reference: every placement numbered alike
    for other in ("cam00", "cam01", "cam03"):
        assert rel_rotation_error(ex.cameras, scene.cameras, other, victim) < 0.1
    assert ex.bundle.rms_after < 0.5


def test_single_placement_refused_by_name_or_decided_by_hints():
    """A board lying still on the floor: both numberings fit; refused unless corner 0 is named."""
    board = Board("floor8x6", "checkerboard", 8, 6, 0.115)
    cams = camera_ring(4, radius=4.0, height=1.5, target=(0.4, 0.3, 0.0), size=(644, 486), focal=490.0, principal_offset=(0, 0))
    pose = floor_board_pose(board, (0.0, 0.0))
    rng = np.random.default_rng(1)
    obs = observe(cams, board, {"f0": pose, "f1": pose}, rng, noise_px=0.2, max_view_angle_deg=85)
    obs["cam01"] = {v: turned(d) for v, d in obs["cam01"].items()}
    intr = {n: c.replace(R=np.eye(3), t=np.zeros(3)) for n, c in cams.items()}
    with pytest.raises(CalibrationError, match=r"cameras cam00-cam01.*cannot tell which end is corner 0.*--corners"):
        calibrate_extrinsics(intr, obs, board=board, reference="cam00")
    hints = {n: cams[n].project(pose[0] @ board.object_points[0] + pose[1])[0] + 3.0 for n in cams}  # a click 3 px off
    ex = calibrate_extrinsics(intr, obs, board=board, hints=hints, reference="cam00")
    assert ex.info["half_turn"]["cam01"] == "from the corner-0 hint"
    for n in ("cam01", "cam02", "cam03"):
        assert rel_rotation_error(ex.cameras, cams, "cam00", n) < 0.3
    partial = {k: v for k, v in hints.items() if k != "cam00"}  # the reference's corner 0 not named
    with pytest.raises(CalibrationError, match="cameras cam00-cam01, cam00-cam02, cam00-cam03 cannot tell"):
        calibrate_extrinsics(intr, obs, board=board, hints=partial, reference="cam00")


def test_floor_numbering_aligned_to_rig_and_world_z_up(scene):
    dets = dict(scene.floor_observations[0])
    victim = sorted(dets)[1]
    dets[victim] = turned(dets[victim])
    aligned, renumbered = align_to_rig(scene.cameras, dets, scene.board)
    assert renumbered == [victim]
    # a rig handed over in a Z-down frame (as the UU config.xml files are) comes out Z up, cameras above the floor
    flip = np.diag([1.0, -1.0, -1.0])
    z_down = {n: c.replace(R=c.R @ flip.T, t=c.t) for n, c in scene.cameras.items()}
    assert all(c.center[2] < 0 for c in z_down.values())
    with pytest.raises(CalibrationError, match=r"implausibly high above the floor"):
        camera_heights(z_down, GroundPlane.floor())
    fl = calibrate_floor(z_down, dets, board=scene.board, max_tilt_deg=0.5, max_plane_mm=5)
    heights = camera_heights(fl.cameras, fl.ground)
    for n, c in scene.cameras.items():
        assert heights[n] == pytest.approx(c.center[2], abs=0.005)
    assert max(v["tilt_deg"] for v in fl.check.values()) < 0.2
    sc = scale_check(fl.cameras, fl.placements[0], scene.board)
    assert sc["ratio"] == pytest.approx(1.0, abs=0.003)


def test_floor_gates_refuse_tilt_and_wrong_units(scene):
    dets = scene.floor_observations[0]
    victim = sorted(dets)[0]
    from calibration.rotation import rotvec_to_matrix

    bent = dict(scene.cameras)
    bent[victim] = bent[victim].replace(R=rotvec_to_matrix(np.radians([4.0, 0, 0])) @ bent[victim].R)
    with pytest.raises(CalibrationError, match=rf"floor check failed: cameras {{'{victim}': [0-9.]+}} \(degrees\)"):
        calibrate_floor(bent, dets, board=scene.board, max_tilt_deg=2.0)
    untouched = calibrate_floor(bent, dets, board=scene.board)  # no gate asked: reported, not refused
    assert untouched.check[victim]["tilt_deg"] > 2.0
    mm = {n: c.replace(t=c.t * 1000) for n, c in scene.cameras.items()}
    with pytest.raises(CalibrationError, match=r"scale check failed.*ratio (99|100)\d\."):
        scale_check(mm, dets, scene.board)
    one = {victim: dets[victim]}
    assert scale_check(scene.cameras, one, scene.board)["skipped"].startswith("the whole board is seen by 1 camera")


def test_cli_extrinsics_from_rendered_folders_with_estimated_focal(tmp_path, capsys):
    """Two cameras, four placements of a symmetric board on the floor and tilted: `calibrate extrinsics`
    without intrinsics (`--estimate focal`) recovers the relative rotation to 0.5 deg."""
    import cv2

    from calibration import RigCalibration
    from calibration.synthetic import render_board_view
    from studio.cli import main

    board = Board("floor8x6", "checkerboard", 8, 6, 0.115)
    cams = camera_ring(2, radius=2.5, height=1.5, target=(0.4, 0.3, 0.0), size=(644, 486), focal=490.0,
                       dist=(0, 0, 0, 0, 0), principal_offset=(0, 0), start=0.3)
    (tmp_path / "b.yaml").write_text("name: b\nkind: checkerboard\ninner_corners: [8, 6]\nsquare_size: 0.115\n")
    rng = np.random.default_rng(2)
    from calibration.rotation import rotvec_to_matrix

    poses = {}
    for k, (x, y, tilt) in enumerate([(0, 0, 0), (0.3, -0.2, 20), (-0.3, 0.2, -25), (0.1, 0.3, 15)]):
        R, t = floor_board_pose(board, (x, y), 0.2 * k)
        poses[f"p{k}"] = (rotvec_to_matrix(np.radians([tilt, 0, 0])) @ R, t + [0, 0, 0.3 * (k > 0)])
    for name, cam in cams.items():
        (tmp_path / name).mkdir()
        for view, pose in poses.items():
            img = render_board_view(cam, board, pose, blur_sigma=0.7, rng=rng)
            cv2.imwrite(str(tmp_path / name / f"{view}.png"), img[:, :, ::-1])
    out = tmp_path / "ex.json"
    argv = ["calibrate", "extrinsics", "--board", str(tmp_path / "b.yaml"), "-o", str(out), "--estimate", "focal"]
    assert main(argv + [f"{n}={tmp_path / n}" for n in cams]) == 0
    assert "intrinsics estimated (focal)" in capsys.readouterr().out
    rig = RigCalibration.load(out)
    assert rel_rotation_error(rig.cameras, cams, "cam00", "cam01") < 0.5
    assert rig["cam00"].K[0, 0] == pytest.approx(490.0, rel=0.02)
