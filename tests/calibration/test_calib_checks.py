"""Every load reports units and the up axis: mm/m detection, Z-down worlds, EasyMocap at 6 decimals."""

from __future__ import annotations

import re

import tomllib

import numpy as np
import pytest
import tomli_w
from scipy.spatial.transform import Rotation

from calibration import Camera, CalibrationError, GroundPlane, RigCalibration
from calibration.formats.checks import camera_spread, detect_units, facing_count

SIZE = (640, 480)
K = np.array([[800.0, 0.0, 319.5], [0.0, 800.0, 239.5], [0.0, 0.0, 1.0]])


def ring(n=4, radius=3.0, height=2.0, scale=1.0) -> RigCalibration:
    """Cameras on a ring ``height`` above the floor looking near (0, 0, 1) (uneven angles, so
    no rotation has round entries); translations × ``scale``."""
    cams = {}
    for k in range(n):
        a = 2 * np.pi * k / n + 0.37 * k + 0.2
        c = Camera.look_at(f"c{k}", [radius * np.cos(a), radius * np.sin(a), height],
                           [0.1 * radius * np.sin(k), -0.05 * radius, 0.5 * height], K, SIZE,
                           dist=[-0.1, 0.01, 0.0, 0.0, 0.0])
        cams[c.name] = c.replace(t=c.t * scale)
    return RigCalibration(cams)


def z_down(rig: RigCalibration) -> RigCalibration:
    """The same rig in a world turned half a turn about X (Z pointing down)."""
    F = np.diag([1.0, -1.0, -1.0])
    return rig.replace(cameras={n: c.replace(R=c.R @ F) for n, c in rig.cameras.items()})


def test_detect_units_thresholds():
    assert detect_units(5836.0) == "mm" and detect_units(250.0) == "mm"
    assert detect_units(3.2) == "m" and detect_units(25.0) == "m"
    assert detect_units(60.0) is None and detect_units(0.0) is None
    rig = ring(scale=1000.0)
    C = np.array([c.center for c in rig])
    assert camera_spread(rig.cameras) == pytest.approx(max(np.linalg.norm(a - b) for a in C for b in C))
    assert camera_spread(rig.cameras) > 5000.0


def foreign_toml(rig: RigCalibration, path):
    """``rig`` as a Calib.toml another tool would write (no studio ground plane)."""
    rig.to_toml(path)
    doc = tomllib.loads(path.read_text())
    del doc["metadata"]["studio_ground"]
    path.write_text(tomli_w.dumps(doc))
    return path


def test_toml_in_mm_is_detected_and_converted(tmp_path):
    """An anipose file in mm (a 6 m ring written as 6000) loads in metres, saying so."""
    truth = ring()
    foreign_toml(ring(scale=1000.0), tmp_path / "mm.toml")
    rig = RigCalibration.load_any(tmp_path / "mm.toml")
    for name in truth.camera_names:
        np.testing.assert_allclose(rig[name].center, truth[name].center, atol=1e-9)
    assert any(re.match(r"units: mm \(detected: camera centres spread over 5594 file units", n) for n in rig.notes)
    assert "translations converted from mm to metres" in rig.notes
    # the same file told to be in metres: kept, with a warning naming the disagreement
    forced = RigCalibration.load_any(tmp_path / "mm.toml", units="m")
    np.testing.assert_allclose(forced["c0"].center, truth["c0"].center * 1000.0, rtol=1e-12)
    assert any("the given units m disagree with the magnitudes" in w for w in forced.warnings)


def test_ambiguous_magnitudes_fall_back_to_the_format_and_warn(tmp_path):
    """A 60-unit spread (60 mm? 60 m?) cannot be told: the format's unit, with a warning; --units decides."""
    truth = ring(radius=30.0, height=20.0)
    foreign_toml(truth, tmp_path / "a.toml")
    rig = RigCalibration.load_any(tmp_path / "a.toml")
    assert 25.0 < camera_spread(truth.cameras) < 250.0
    np.testing.assert_allclose(rig["c0"].center, truth["c0"].center, rtol=1e-12)
    assert any("units: m assumed" in w and "too few to tell mm from m" in w for w in rig.warnings)
    mm = RigCalibration.load_any(tmp_path / "a.toml", units="mm")
    np.testing.assert_allclose(mm["c0"].center, truth["c0"].center / 1000.0, rtol=1e-12)
    with pytest.raises(CalibrationError, match=r"a\.toml: field 'units': expected one of m, cm, mm, got 'inch'"):
        RigCalibration.load_any(tmp_path / "a.toml", units="inch")


def test_native_in_metres_with_huge_magnitudes_warns_but_keeps_metres(tmp_path):
    ring(scale=1000.0).save(tmp_path / "c.json")
    rig = RigCalibration.load(tmp_path / "c.json")
    np.testing.assert_allclose(rig["c0"].center, ring()["c0"].center * 1000.0, rtol=1e-12)
    assert any("suggests mm, but the format defines m" in w for w in rig.warnings)


def test_z_down_world_is_flipped_and_projects_the_same(tmp_path):
    truth = ring()
    down = z_down(truth)
    assert all(c.center[2] == pytest.approx(-2.0) for c in down)
    foreign_toml(down, tmp_path / "down.toml")
    rig = RigCalibration.load_any(tmp_path / "down.toml")
    for name in truth.camera_names:  # turned back exactly
        assert rig[name].allclose(truth[name], atol=1e-12)
    assert any("the file's world had Z pointing down (cameras 2.00 m below the floor" in n for n in rig.notes)
    # pixels of points in the file's world equal those of the turned points in the new world
    X = np.random.default_rng(1).uniform(-1, 1, (20, 3)) + [0, 0, -1]
    np.testing.assert_allclose(down["c1"].project(X), rig["c1"].project(X * [1, -1, -1]), atol=1e-9)
    with pytest.raises(CalibrationError, match=r"down\.toml: field 'up axis': the world's Z axis points down "
                                               r"\(all cameras 2\.00 m below the floor"):
        RigCalibration.load_any(tmp_path / "down.toml", z_down="refuse")
    kept = RigCalibration.load_any(tmp_path / "down.toml", z_down="keep")
    assert kept["c0"].center[2] == pytest.approx(-2.0)
    assert any("the world's Z axis points down" in w and "kept as it is" in w for w in kept.warnings)
    with pytest.raises(CalibrationError, match=r"field 'z_down': expected one of flip, refuse, keep"):
        RigCalibration.load_any(tmp_path / "down.toml", z_down="up")


def test_own_files_are_never_turned_and_a_wrong_ground_normal_is_reported(tmp_path):
    z_down(ring()).save(tmp_path / "down.json")
    rig = RigCalibration.load_any(tmp_path / "down.json")
    assert rig["c0"].center[2] == pytest.approx(-2.0)
    assert any("the world's Z axis points down" in w for w in rig.warnings)
    ring().replace(ground=GroundPlane([0.0, 0.0, -1.0], 0.0)).save(tmp_path / "n.json")
    assert any("the ground normal [0.0, 0.0, -1.0] points away from the cameras" in w
               for w in RigCalibration.load(tmp_path / "n.json").warnings)
    assert RigCalibration.load(tmp_path / "n.json").ground.normal[2] == -1.0


def test_camera_anchored_world_is_reported_unverified(tmp_path):
    truth = ring()
    c0 = truth["c0"]
    anchored = truth.replace(cameras={n: c.replace(R=c.R @ c0.R.T, t=c.t - c.R @ c0.R.T @ c0.t)
                                      for n, c in truth.cameras.items()})
    foreign_toml(anchored, tmp_path / "a.toml")
    rig = RigCalibration.load_any(tmp_path / "a.toml")
    assert [w for w in rig.warnings if "up axis not verified" in w and "camera(s) c0 on the floor plane" in w]
    np.testing.assert_allclose(rig["c0"].R, np.eye(3), atol=1e-12)  # nothing turned


def test_cameras_looking_away_are_flagged():
    rig = ring()
    assert facing_count(rig.cameras) == (4, 4)
    F = np.diag([1.0, -1.0, -1.0])  # an extra half turn about each camera's x axis (old Pose2Sim)
    away = {n: c.replace(R=F @ c.R, t=F @ c.t) for n, c in rig.cameras.items()}
    assert facing_count(away) == (0, 4)


# ---------------------------------------------------------------------------------- EasyMocap, 6 decimals
def _round_extri(path, decimals: int, drop_rvec: bool = False) -> None:
    """Rewrite every number of an OpenCV YAML file with ``decimals`` decimals (as EasyMocap's writer)."""
    text = path.read_text()
    text = re.sub(r"-?\d+\.\d+(?:e[-+]\d+)?", lambda m: f"{float(m.group()):.{decimals}f}", text)
    if drop_rvec:
        text = re.sub(r"R_c\d: !!opencv-matrix\n(?:   .*\n)+?(?=Rot_)", "", text)
    path.write_text(text)


def test_easymocap_six_decimals_loads_within_rounding(tmp_path):
    truth = ring()
    truth.to_opencv(tmp_path)
    text = (tmp_path / "extri.yml").read_text()
    (tmp_path / "extri.yml").write_text(text[: text.index("ground_normal")])
    _round_extri(tmp_path / "extri.yml", 6)
    worst = max(np.max(np.abs(np.round(c.R, 6) @ np.round(c.R, 6).T - np.eye(3))) for c in truth)
    assert worst > 1e-6  # what the toolkit refused before: "not orthonormal"
    rig = RigCalibration.from_opencv(tmp_path)
    for name in truth.camera_names:
        angle = Rotation.from_matrix(rig[name].R @ truth[name].R.T).magnitude()
        assert angle < 5e-6 and np.allclose(rig[name].t, truth[name].t, atol=1e-6)
    assert any("written with few decimals" in n and "R_ (Rodrigues)" in n for n in rig.notes)


def test_easymocap_rot_only_is_reorthonormalised_and_gross_errors_refused(tmp_path):
    truth = ring()
    truth.to_opencv(tmp_path)
    text = (tmp_path / "extri.yml").read_text()
    (tmp_path / "extri.yml").write_text(text[: text.index("ground_normal")])
    _round_extri(tmp_path / "extri.yml", 6, drop_rvec=True)
    assert "R_c1:" not in (tmp_path / "extri.yml").read_text()
    rig = RigCalibration.from_opencv(tmp_path)
    assert Rotation.from_matrix(rig["c1"].R @ truth["c1"].R.T).magnitude() < 5e-6
    _round_extri(tmp_path / "extri.yml", 2)  # 2 decimals: |R Rᵀ - I| ~ 1e-2, not rounding any more
    with pytest.raises(CalibrationError, match=r"extri\.yml: camera 'c\d': field 'Rot_c\d': not a rotation: "
                                               r"max \|R Rᵀ - I\| = .* more than rounding"):
        RigCalibration.from_opencv(tmp_path)
