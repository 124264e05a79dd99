"""ISO 7250-1 measurements (studio.body.iso7250): analytic shapes with known answers, and the
model against the same definitions computed independently (trimesh sections)."""

import numpy as np
import pytest

from studio.body import BodyModel
from studio.body.iso7250 import DEFINITIONS, ISO20685_MAE, ISO_NAMES, measure_iso, plane_section, template_landmarks
from studio.body.measure import t_pose
from studio.body.skeleton import PART_NAMES

P = {n: i for i, n in enumerate(PART_NAMES)}


@pytest.fixture(scope="module")
def body():
    m = BodyModel.load("female")
    s = m.mean_shape()
    v = m.vertices(s)
    return m, v, m.vertices(s, t_pose(m, s)), m.joint_regressor @ v


def _measure(m, v, vt, J):
    return measure_iso(v, vt, J, m.faces, np.asarray(m.parts), np.asarray(m.face_parts))


def _tube(n=96, rings=12, r=0.1, z0=0.0, z1=1.0):
    """A closed cylinder (vertices, faces) of radius r around the z axis."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    zs = np.linspace(z0, z1, rings)
    v = np.array([[r * np.cos(a), r * np.sin(a), z] for z in zs for a in t])
    f = []
    for k in range(rings - 1):
        for i in range(n):
            a, b = k * n + i, k * n + (i + 1) % n
            f += [[a, b, b + n], [a, b + n, a + n]]
    return v, np.array(f)


def test_definitions_name_a_clause_kind_and_iso20685_limit():
    assert len(DEFINITIONS) >= 15 and len(set(ISO_NAMES)) == len(ISO_NAMES)
    for d in DEFINITIONS:
        assert d.clause and d.text and d.kind in set(ISO20685_MAE) | {"mass", "index"}
    by = {d.name: d for d in DEFINITIONS}
    assert by["stature"].max_error == 0.004 and by["shoulder_elbow_length"].max_error == 0.005
    assert by["chest_circumference"].max_error == 0.009 and by["neck_circumference"].max_error == 0.004
    assert by["mass"].max_error is None and by["stature"].clause == "ISO 7250-1 4.1.2"


def test_plane_section_of_a_cylinder_is_its_girth_at_any_tilt():
    v, f = _tube(r=0.1)
    n = 96
    polygon = 2 * n * 0.1 * np.sin(np.pi / n)  # the tube is a 96-gon prism
    per, ring = plane_section(v, f, [0, 0, 0.5], [0, 0, 1])
    assert per == pytest.approx(polygon, rel=1e-9)
    np.testing.assert_allclose(ring[:, 2], 0.5)
    # tilt the tube 40° about x: a section perpendicular to its axis is still the girth
    c, s = np.cos(0.7), np.sin(0.7)
    R = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    per2, _ = plane_section(v @ R.T, f, R @ [0, 0, 0.5], R @ [0, 0, 1])
    assert per2 == pytest.approx(polygon, rel=1e-9)
    assert plane_section(v, f, [0, 0, 2.0], [0, 0, 1])[0] == 0.0


def test_each_measurement_on_bodies_made_analytic(body):
    """Heights set on the landmarks, trunk and limbs replaced by cylinders and a box: every
    definition returns the value built in (girths = the 2πr of a fine polygon, within 0.5 %)."""
    m, v0, vt, J = body
    v = v0.copy()
    parts = np.asarray(m.parts)
    L = template_landmarks()
    base = _measure(m, v0, vt, J).values
    # heights: move the landmarks themselves
    v[L["acromion_l"], 2] = v[L["acromion_r"], 2] = 1.40
    v[L["exocanthion_l"], 2], v[L["exocanthion_r"], 2] = 1.51, 1.53
    v[L["tibiale_l"], 2] = v[L["tibiale_r"], 2] = 0.47
    v[L["crotch"], 2] = v[L["crotch"], 2] - 0.01
    v[L["acromion_l"], 0], v[L["acromion_r"], 0] = 0.18, -0.19
    v[L["acromion_l"], 1] = v[L["acromion_r"], 1] = 0.0
    got = _measure(m, v, vt, J).values
    assert got["shoulder_height"] == pytest.approx(1.40, abs=1e-9)
    assert got["eye_height"] == pytest.approx(1.52, abs=1e-9)
    assert got["knee_height"] == pytest.approx(0.47, abs=1e-9)
    assert got["crotch_height"] == pytest.approx(base["crotch_height"] - 0.01, abs=1e-9)
    assert got["biacromial_breadth"] == pytest.approx(0.37, abs=1e-9)
    assert got["stature"] == pytest.approx(base["stature"], abs=1e-9)
    assert got["elbow_height"] == pytest.approx(1.40 - got["shoulder_elbow_length"], abs=1e-9)

    # trunk → a cylinder of radius 0.14 around a vertical axis
    torso = parts == P["torso"]
    ang = np.arctan2(v[torso, 1] - 0.02, v[torso, 0])
    v[torso, 0], v[torso, 1] = 0.14 * np.cos(ang), 0.02 + 0.14 * np.sin(ang)
    # hips → a box 0.36 wide (x clipped to ±0.18 for pelvis and upper thighs)
    hips = np.isin(parts, [P["pelvis"], P["upperleg_l"], P["upperleg_r"]])
    v[hips, 0] = np.clip(v[hips, 0], -0.18, 0.18)
    # upper arms → cylinders of radius 0.045 around their shoulder-elbow axis
    for side in ("l", "r"):
        S, E = J[P[f"upperarm_{side}"]], J[P[f"lowerarm_{side}"]]
        a = (E - S) / np.linalg.norm(E - S)
        arm = parts == P[f"upperarm_{side}"]
        d = v[arm] - S
        radial = d - np.outer(d @ a, a)
        v[arm] = S + np.outer(d @ a, a) + 0.045 * radial / np.linalg.norm(radial, axis=1, keepdims=True)
    res = _measure(m, v, vt, J).values
    assert res["chest_circumference"] == pytest.approx(2 * np.pi * 0.14, rel=0.005)
    assert res["chest_depth"] == pytest.approx(0.28, rel=0.005)
    assert res["hip_breadth"] == pytest.approx(0.36, abs=1e-9)
    assert res["upper_arm_circumference"] == pytest.approx(2 * np.pi * 0.045, rel=0.02)


def test_model_measurements_against_independent_trimesh_sections(body):
    """Girths: trimesh's own plane section of the same part faces at the same level, its convex
    hull perimeter (scipy) — within 0.1 mm; heights and lengths from the landmark vertices."""
    trimesh = pytest.importorskip("trimesh")
    from scipy.spatial import ConvexHull

    m, v, vt, J = body
    res = _measure(m, v, vt, J)
    L = template_landmarks()
    fp = np.asarray(m.face_parts)

    def girth(face_sel, origin, normal):
        mesh = trimesh.Trimesh(v, m.faces[face_sel], process=False)
        sec = mesh.section(plane_origin=origin, plane_normal=normal)
        pts = np.asarray(sec.vertices)
        flat = trimesh.transform_points(pts, trimesh.geometry.plane_transform(origin, normal))[:, :2]
        return ConvexHull(flat).area  # the 2-D hull's "area" is its perimeter

    zc = 0.5 * (v[L["thelion_l"], 2] + v[L["thelion_r"], 2])
    assert res.values["chest_circumference"] == pytest.approx(girth(fp == P["torso"], [0, 0, zc], [0, 0, 1]), abs=1e-4)
    zw = float(np.mean(res.lines["waist_circumference"][:, 2]))
    trunk = np.isin(fp, [P["torso"], P["pelvis"]])
    assert res.values["waist_circumference"] == pytest.approx(girth(trunk, [0, 0, zw], [0, 0, 1]), abs=1e-4)
    a, o = v[L["acromion_l"]], v[L["olecranon_l"]]
    ax = (J[P["lowerarm_l"]] - J[P["upperarm_l"]]) / np.linalg.norm(J[P["lowerarm_l"]] - J[P["upperarm_l"]])
    arm_l = girth(fp == P["upperarm_l"], 0.5 * (a + o), ax)
    a, o = v[L["acromion_r"]], v[L["olecranon_r"]]
    ax = (J[P["lowerarm_r"]] - J[P["upperarm_r"]]) / np.linalg.norm(J[P["lowerarm_r"]] - J[P["upperarm_r"]])
    arm_r = girth(fp == P["upperarm_r"], 0.5 * (a + o), ax)
    assert res.values["upper_arm_circumference"] == pytest.approx(0.5 * (arm_l + arm_r), abs=1e-4)
    assert res.values["stature"] == pytest.approx(np.ptp(v[:, 2]), abs=1e-9)
    assert res.values["arm_span"] == pytest.approx(np.ptp(vt[:, 0]), abs=1e-9)
    vol = trimesh.Trimesh(v, m.faces, process=False).volume
    assert res.values["mass"] == pytest.approx(980 * abs(vol), rel=1e-9)
    assert res.values["bmi"] == pytest.approx(res.values["mass"] / res.values["stature"] ** 2)
    # plausible adult proportions (mean female of the model)
    r = res.values
    assert r["knee_height"] < r["crotch_height"] < r["elbow_height"] < r["shoulder_height"] < r["eye_height"] < r["stature"]
    assert r["neck_circumference"] < r["waist_circumference"] < r["chest_circumference"] < r["hip_circumference"]
    assert 0.29 < r["biacromial_breadth"] < 0.42 and 0.18 < r["chest_depth"] < 0.32


def test_a_scan_whose_bounds_cross_measures_the_plane_halfway_instead_of_failing():
    # a fitted frame's extreme shape put the neck scan's lower bound (shoulder height + 3 cm) above its
    # upper one (head top - 15 cm): the scan had no plane and raised IndexError inside the fit
    from studio.body.iso7250 import _horizontal_scan

    v, f = _tube(r=0.1)
    girth, ring, z = _horizontal_scan(v, f, 0.62, 0.58, np.argmin)
    assert z == pytest.approx(0.60)
    assert girth == pytest.approx(plane_section(v, f, [0, 0, 0.60], [0, 0, 1])[0]) and len(ring) > 3
    assert girth == pytest.approx(2 * np.pi * 0.1, rel=0.01)
    same, _, z_same = _horizontal_scan(v, f, 0.60, 0.60, np.argmin)  # one plane: the scan as before
    assert (same, z_same) == (girth, z)
