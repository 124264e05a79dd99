"""``calibration.formats.checks.settle`` on hand-built rigs whose heights, spreads and facing
are known exactly: each branch's whole note, the scale applied to translations and ground
offset, the documented boundaries (≤ 25 units → m, ≥ 250 → mm, within 1 mm of the floor →
on it, at least half the cameras facing the others → no warning) at the boundary itself.

Cameras look straight down (``R = diag(1, -1, -1)``) or up, so a centre ``C`` gives
``t = -R C`` and the height ``C_z`` exactly, with no rounding.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from calibration import Camera, CalibrationError, GroundPlane
from calibration.formats import RigParts
from calibration.formats.checks import camera_spread, facing_count, flip_world, settle, up_status

K = [[800.0, 0.0, 319.5], [0.0, 800.0, 239.5], [0.0, 0.0, 1.0]]
DOWN = np.diag([1.0, -1.0, -1.0])  # camera z axis along world -Z
F = np.diag([1.0, -1.0, -1.0])  # the half turn about world X


def cam(name, C, R=DOWN) -> Camera:
    R = np.asarray(R, float)
    return Camera(name, K, [], R, -R @ np.asarray(C, float), (640, 480))


def parts_of(*cams, ground=None, **kw) -> RigParts:
    return RigParts({c.name: c for c in cams}, ground or GroundPlane.floor(), {}, **kw)


def centres(parts) -> dict:
    return {n: c.center for n, c in parts.cameras.items()}


# ------------------------------------------------------------------------------------------ units
def test_spread_is_the_largest_pairwise_distance_or_one_centre_from_the_origin():
    a, b, c = cam("a", [0, 0, 2]), cam("b", [3, 4, 2]), cam("c", [1, 1, 2])
    assert camera_spread({"a": a, "b": b, "c": c}) == 5.0
    assert camera_spread({"b": b}) == pytest.approx(np.sqrt(29.0), abs=1e-15)


def test_units_detected_from_the_spread_at_both_documented_bounds():
    """≥ 250 file units → mm, ≤ 25 → m, each exactly at the bound; the mm rig converted."""
    mm = settle(parts_of(cam("a", [0, 0, 2000]), cam("b", [250, 0, 2000]), units_fixed=False))
    assert mm.notes == ("units: mm (detected: camera centres spread over 250 file units; expected m)",
                        "translations converted from mm to metres",
                        "up axis: Z up (cameras 2.00 m above the floor)")
    np.testing.assert_allclose(centres(mm)["b"], [0.25, 0.0, 2.0], rtol=0, atol=1e-15)
    m = settle(parts_of(cam("a", [0, 0, 2]), cam("b", [25, 0, 3]), units="arbitrary", units_fixed=False,
                        notes=("reader's note",)), units=None)
    assert m.notes[0] == "reader's note"
    assert m.notes[1].startswith("units: arbitrary (the format has no scale)")
    m = settle(parts_of(cam("a", [0, 0, 2]), cam("b", [15, 20, 2]), units="cm", units_fixed=False))
    assert m.notes == ("units: m (detected: camera centres spread over 25 file units; expected cm)",
                       "up axis: Z up (cameras 2.00 m above the floor)")
    assert (m.units, m.units_fixed) == ("m", True)
    np.testing.assert_array_equal(centres(m)["b"], [15.0, 20.0, 2.0])


def test_ambiguous_spread_falls_back_to_the_readers_unit_with_the_rule_spelt_out():
    p = parts_of(cam("a", [0, 0, 200]), cam("b", [60, 0, 200]), ground=GroundPlane([0, 0, 1], 100.0),
                 units="cm", units_fixed=False)
    out = settle(p)
    assert out.notes[:2] == (
        "warning: units: cm assumed — camera centres spread over 60 file units, too few to tell mm from m "
        "(≤ 25 means m, ≥ 250 mm); pass units= (--units) to be sure",
        "translations converted from cm to metres")
    np.testing.assert_allclose(centres(out)["b"], [0.6, 0.0, 2.0], rtol=0, atol=1e-15)
    assert out.ground.offset == pytest.approx(1.0, abs=1e-15)  # the ground offset scaled too
    other = settle(p._replace(units="feet"))
    assert other.notes[0].startswith("warning: units: m assumed — camera centres spread over 60 file units")
    np.testing.assert_array_equal(centres(other)["b"], [60.0, 0.0, 200.0])


def test_given_and_format_units_and_their_disagreements():
    p = parts_of(cam("a", [0, 0, 2000]), cam("b", [3000, 4000, 2000]), units="m", units_fixed=True)
    fixed = settle(p)
    assert fixed.notes[:2] == (
        "units: m (as the format defines; camera centres spread over 5000 file units)",
        "warning: camera centres spread over 5000 file units, which suggests mm, but the format defines m: kept m; "
        "pass units='mm' (--units mm) if the file is not as documented")
    np.testing.assert_array_equal(centres(fixed)["b"], [3000.0, 4000.0, 2000.0])
    given = settle(p, units="mm")
    assert given.notes[:2] == ("units: mm (given; camera centres spread over 5000 file units)",
                               "translations converted from mm to metres")
    np.testing.assert_allclose(centres(given)["b"], [3.0, 4.0, 2.0], rtol=0, atol=1e-15)
    cm = settle(p, units="cm")
    assert cm.notes[:3] == (
        "units: cm (given; camera centres spread over 5000 file units)",
        "warning: the given units cm disagree with the magnitudes (camera centres spread over 5000 file units "
        "suggests mm)",
        "translations converted from cm to metres")
    np.testing.assert_allclose(centres(cm)["b"], [30.0, 40.0, 20.0], rtol=0, atol=1e-13)
    mm_format = settle(p._replace(units="mm"))
    assert mm_format.notes[:2] == ("units: mm (as the format defines; camera centres spread over 5000 file units)",
                                   "translations converted from mm to metres")
    exc = pytest.raises(CalibrationError, settle, p, units="inch").value
    assert (exc.detail, exc.field) == ("expected one of m, cm, mm, got 'inch'", "units")


def test_intrinsics_only_rigs_keep_or_scale_by_the_stated_unit():
    """No pose (every centre at the origin): no units to detect, no up axis, no facing check."""
    p = parts_of(cam("a", [0, 0, 0], np.eye(3)), cam("b", [0, 0, 0], np.eye(3)),
                 ground=GroundPlane([0, 0, 1], 5.0), units="mm", units_fixed=False)
    out = settle(p)
    assert out.notes == ("units: not applicable (no camera pose in the file)",
                         "up axis: not applicable (no camera pose)")
    assert out.ground.offset == 0.005
    assert settle(p, units="cm").ground.offset == 0.05
    assert settle(p._replace(units="arbitrary"), units="m").ground.offset == 5.0
    assert settle(p._replace(units="pixels")).ground.offset == 5.0
    assert up_status(p.cameras, p.ground)[0] == "none"
    assert facing_count(p.cameras) == (0, 0)


# ------------------------------------------------------------------------------------------ up axis
def test_up_status_within_a_millimetre_of_the_floor_is_on_it():
    """ON_FLOOR_M: a camera exactly 1 mm from the floor counts as on it (unknown), 1.5 mm not."""
    ground = GroundPlane.floor()
    up = {"a": cam("a", [0, 0, 2]), "b": cam("b", [1, 0, 0.0015])}
    status, h = up_status(up, ground)
    assert status == "up"
    np.testing.assert_array_equal(h, [2.0, 0.0015])
    on = {"a": cam("a", [0, 0, 2]), "b": cam("b", [1, 0, 0.001])}
    assert up_status(on, ground)[0] == "unknown"
    below_on = {"a": cam("a", [0, 0, -2]), "b": cam("b", [1, 0, -0.001])}
    assert up_status(below_on, ground)[0] == "unknown"
    below = {"a": cam("a", [0, 0, -2]), "b": cam("b", [1, 0, -0.0015])}
    assert up_status(below, ground)[0] == "below"
    shifted = GroundPlane([0, 0, 1], 0.5)  # heights n·C - d
    np.testing.assert_array_equal(up_status(up, shifted)[1], [1.5, -0.4985])


def test_unverified_up_axis_names_the_cameras_on_the_floor():
    out = settle(parts_of(cam("a", [0, 0, 2]), cam("b", [2, 0, 0.001]), cam("c", [0, 2, 0])))
    assert out.notes[1] == ("warning: up axis not verified — camera(s) b, c on the floor plane: the world is "
                             "anchored on a camera (heights 0.00 to 2.00 m); calibrate the floor "
                             "(`studio calibrate floor`) before segmenting or fitting")
    both = settle(parts_of(cam("a", [0, 0, 2]), cam("b", [2, 0, -1])))
    assert both.notes[-1] == ("warning: up axis not verified — cameras on both sides of the floor plane (heights "
                              "-1.00 to 2.00 m); calibrate the floor (`studio calibrate floor`) before segmenting "
                              "or fitting")


def test_z_down_world_flipped_refused_or_kept():
    """Cameras 2 m below a floor with normal +Z: a Z-down world. Flipping turns R to R·F and
    the cameras' centres to (x, -y, -z); the ground normal, reversed towards the cameras and
    turned, is +Z again."""
    cams = (cam("a", [1, 2, -2], np.eye(3)), cam("b", [-1, 0.5, -2.5], np.eye(3)))
    p = parts_of(*cams)
    out = settle(p)
    assert out.notes[-1] == ("up axis: the file's world had Z pointing down (cameras 2.00 to 2.50 m below the floor "
                             "along +Z): turned half a turn about X (x, y, z) → (x, -y, -z); cameras project exactly "
                             "as before")
    np.testing.assert_array_equal(out.cameras["a"].R, F)
    np.testing.assert_array_equal(out.cameras["a"].t, p.cameras["a"].t)
    np.testing.assert_allclose(out.cameras["b"].center, [-1, -0.5, 2.5], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(out.ground.normal, [0.0, 0.0, 1.0])
    assert out.ground.offset == 0.0 and math.copysign(1.0, out.ground.offset) == 1.0  # not -0.0 in files written
    exc = pytest.raises(CalibrationError, settle, p, z_down="refuse", source="down.toml").value
    assert (exc.detail, exc.file, exc.field) == (
        "the world's Z axis points down (all cameras 2.00 to 2.50 m below the floor z = 0 along +Z): expected world "
        "Z up; pass z_down='flip' (--z-down flip) to turn the world half a turn about X", "down.toml", "up axis")
    kept = settle(p, z_down="keep")
    assert kept.notes[-1] == ("warning: the world's Z axis points down (the cameras stand 2.00 to 2.50 m from the "
                              "floor on the side of [-0.0, -0.0, -1.0]); kept as it is — z_down='flip' (--z-down "
                              "flip) turns it")
    np.testing.assert_array_equal(kept.cameras["a"].R, np.eye(3))
    assert settle(p._replace(own_frame=True)).notes[-1] == kept.notes[-1]  # own files: kept by default
    exc = pytest.raises(CalibrationError, settle, p, z_down="up").value
    assert (exc.detail, exc.field) == ("expected one of flip, refuse, keep, got 'up'", "z_down")


def test_flip_world_with_a_downward_normal_and_an_offset():
    """Cameras above a plane whose normal points down (n = -Z, d = -0.5: the plane z = 0.5)."""
    cams = {"a": cam("a", [0, 0, -2], np.eye(3))}
    ground = GroundPlane([0, 0, -1], -0.5)
    turned, g = flip_world(cams, ground, toward_cameras=False)
    np.testing.assert_array_equal(g.normal, [0.0, 0.0, 1.0])
    assert g.offset == -0.5
    turned, g = flip_world(cams, ground, toward_cameras=True)
    np.testing.assert_array_equal(g.normal, [0.0, 0.0, -1.0])
    assert g.offset == 0.5
    np.testing.assert_array_equal(turned["a"].R, F)


def test_ground_normal_pointing_away_from_cameras_above():
    """Cameras at z = 2 above a floor given with normal -Z: foreign files get the normal reversed
    (offset too), own files keep it with a warning; cameras below a +Z normal but above a -Z
    one are 'below' the plane's normal side: a Z-down world in the file's terms."""
    cams = (cam("a", [0, 0, 2]), cam("b", [1, 0, 3]))
    p = parts_of(*cams, ground=GroundPlane([0, 0, -1], -0.25))
    out = settle(p)
    assert out.notes[-1] == ("up axis: Z up (cameras 1.75 to 2.75 m above the floor); the ground normal was "
                             "reversed to point at them")
    np.testing.assert_array_equal(out.ground.normal, [0.0, 0.0, 1.0])
    assert out.ground.offset == 0.25
    np.testing.assert_array_equal(out.cameras["a"].R, DOWN)
    own = settle(p._replace(own_frame=True))
    assert own.notes[-1] == ("warning: the ground normal [0.0, 0.0, -1.0] points away from the cameras (1.75 to "
                             "2.75 m from the floor on its other side); kept as it is")
    assert own.ground.offset == -0.25
    assert settle(p, z_down="refuse").notes[-1] == out.notes[-1]  # not a Z-down world: nothing to refuse


def test_cameras_above_a_sideways_normal_are_a_z_down_world():
    """A ground normal along +X with every camera on its positive side: 'up' by the plane, but
    the plane's up is not +Z, so the world is flipped (foreign) like a Z-down one."""
    p = parts_of(cam("a", [2, 0, 1], np.eye(3)), cam("b", [3, 1, 1], np.eye(3)), ground=GroundPlane([1, 0, 0], 0.0))
    out = settle(p, z_down="keep")
    assert out.notes[-1].startswith("warning: the world's Z axis points down (the cameras stand 2.00 to 3.00 m from "
                                    "the floor on the side of [1.0, 0.0, 0.0])")
    flipped = settle(p)
    np.testing.assert_array_equal(flipped.cameras["a"].R, F)
    np.testing.assert_array_equal(flipped.ground.normal, [1.0, 0.0, 0.0])


# ------------------------------------------------------------------------------------------ facing
def _facing_rig(n_facing: int, n: int) -> dict:
    """``n`` cameras on a circle of radius 2 at z = 2, the first ``n_facing`` looking at the
    circle's centre (z axis inward), the rest looking outward."""
    cams = {}
    for k in range(n):
        a = 2 * np.pi * k / n
        C = np.array([2 * np.cos(a), 2 * np.sin(a), 2.0])
        z = -C * [1, 1, 0] / 2 if k < n_facing else C * [1, 1, 0] / 2
        x = np.cross([0, 0, -1.0], z)
        R = np.array([x, np.cross(z, x), z])
        cams[f"c{k}"] = cam(f"c{k}", C, R)
    return cams


@pytest.mark.parametrize("n_facing, n, warned", [(2, 4, False), (1, 4, True), (2, 3, False), (1, 3, True),
                                                 (0, 2, False)])
def test_facing_warning_when_fewer_than_half_look_at_the_others(n_facing, n, warned):
    """The module's rule: at least half must look towards the others; exactly half is enough."""
    cams = _facing_rig(n_facing, n)
    assert facing_count(cams) == ((n_facing, n) if n >= 3 else (0, 0))
    notes = settle(RigParts(cams, GroundPlane.floor(), {})).notes
    warning = (f"warning: only {n_facing} of {n} cameras look towards the others: the file's rotation convention may "
               "differ from OpenCV's (world → camera, camera looking along +z), e.g. an extra half turn about the "
               "camera x axis as older Pose2Sim versions wrote")
    assert (notes[-1] == warning) is warned
    assert len(notes) == 2 + warned


def test_cameras_all_at_one_point_carry_no_pose_information():
    """Two cameras at the same centre (not the origin): spread 0, so no units, no up axis."""
    p = parts_of(cam("a", [1, 2, 3]), cam("b", [1, 2, 3]), units="mm", units_fixed=False)
    assert camera_spread(p.cameras) == 0.0
    assert up_status(p.cameras, p.ground)[0] == "none"
    assert settle(p).notes == ("units: not applicable (no camera pose in the file)",
                               "up axis: not applicable (no camera pose)")
    np.testing.assert_allclose(settle(p).cameras["a"].center, [0.001, 0.002, 0.003], rtol=0, atol=1e-18)


def test_detect_units_below_one_unit_is_metres():
    """A spread of half a file unit (a 12 cm stereo pair in metres) is metres too: the bound
    is 0 < spread ≤ 25."""
    from calibration.formats.checks import detect_units

    assert detect_units(0.5) == "m" and detect_units(1.0) == "m" and detect_units(1e-9) == "m"


def test_notes_whole_for_arbitrary_and_unknown_reader_units():
    p = parts_of(cam("a", [0, 0, 2]), cam("b", [1, 0, 2]), units="arbitrary", units_fixed=False)
    assert settle(p).notes[0] == ("units: arbitrary (the format has no scale); taken as metres — set the scale with a "
                                  "floor or board calibration before measuring")
    big = parts_of(cam("a", [0, 0, 2000]), cam("b", [1000, 0, 2000]), units="feet", units_fixed=False)
    assert settle(big).notes[0] == "units: mm (detected: camera centres spread over 1000 file units)"


def test_normals_in_warnings_rounded_to_three_decimals():
    a = 0.5
    n = [np.sin(a), 0.0, -np.cos(a)]  # [0.479, 0.0, -0.878]: pointing down and sideways
    own = parts_of(cam("a", [0, 0, -2], np.eye(3)), cam("b", [1, 0, -3], np.eye(3)), ground=GroundPlane(n, 0.0),
                   own_frame=True)
    notes = settle(own).notes
    assert "[0.479, 0.0, -0.878]" in notes[-1]


def test_facing_count_centroid_and_bounds():
    """c1 at (10, 1, 2) and c2 at (10, -1, 2) look along -x. Camera 0 at (8, 0, 2) looking
    along +x has the others' centroid (10, 0, 2) 2 m ahead: all three face (c1's centroid of
    the others (9, -0.5, 2) is 1 m ahead of it). At (10, 0, 2) looking along +y every camera
    has its centroid exactly sideways (dot 0): none counts. At (9.5, 0, 2) looking along +x
    the dots are 0.5, 0.25, 0.25 (less than 1): all count. Three cameras at one point: not
    checked."""
    def look(name, C, z):
        z = np.asarray(z, float)
        x = np.cross([0, 0, 1.0], z)
        return cam(name, C, np.array([x, np.cross(z, x), z]))

    c1, c2 = look("c1", [10, 1, 2], [-1, 0, 0]), look("c2", [10, -1, 2], [-1, 0, 0])
    rigs = {"ahead": look("c0", [8, 0, 2], [1, 0, 0]), "sideways": look("c0", [10, 0, 2], [0, 1, 0]),
            "near": look("c0", [9.5, 0, 2], [1, 0, 0])}
    counts = {k: facing_count({"c0": c0, "c1": c1, "c2": c2}) for k, c0 in rigs.items()}
    assert counts == {"ahead": (3, 3), "sideways": (0, 3), "near": (3, 3)}
    one = {k: cam(k, [1, 2, 3]) for k in ("a", "b", "c")}
    assert facing_count(one) == (0, 0)


def test_refusal_names_the_default_source():
    p = parts_of(cam("a", [0, 0, -2], np.eye(3)), cam("b", [1, 0, -2], np.eye(3)))
    exc = pytest.raises(CalibrationError, settle, p, z_down="refuse").value
    assert exc.file == "calibration"


def test_normal_pointing_away_rounded_to_three_decimals():
    a = 0.5
    own = parts_of(cam("a", [0, 0, 2]), cam("b", [1, 0, 3]), ground=GroundPlane([np.sin(a), 0.0, -np.cos(a)], 0.0),
                   own_frame=True)
    assert "the ground normal [0.479, 0.0, -0.878] points away from the cameras" in settle(own).notes[-1]
