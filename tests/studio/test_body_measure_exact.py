"""The model's own measurement definitions (``studio.body.measure``) against hand-computed values.

``arm_length`` is shoulder joint → elbow → wrist joint, mean of both arms: with the arm joints
moved to known points the value is exact. ``shoulder_breadth`` is the x-extent of torso and
upper-arm vertices above ``shoulder height − 3 cm``; ``volume`` the divergence theorem.
"""

from __future__ import annotations

import numpy as np
import pytest

from studio.body import BodyModel
from studio.body.measure import MEASUREMENT_NAMES, measure, measure_mesh, place_canonical, t_pose
from studio.body.skeleton import PART_NAMES, pose_slices

P = {n: i for i, n in enumerate(PART_NAMES)}


@pytest.fixture(scope="module")
def body():
    model = BodyModel.load("female")
    shape = model.mean_shape()
    v = model.vertices(shape)
    vt = model.vertices(shape, t_pose(model, shape))
    return model, shape, v, vt, model.joints(shape)


def _measure(model, v, vt, J, **kw):
    return measure_mesh(v, vt, J, model.faces, model.parts, model.face_parts, **kw)


def test_arm_length_is_shoulder_elbow_wrist_mean_of_both_arms(body):
    model, _, v, vt, J = body
    J = J.copy()
    # left: 0.3 to the elbow, 0.25 to the wrist (a bent arm: the path, not the straight line)
    J[P["upperarm_l"]], J[P["lowerarm_l"]], J[P["hand_l"]] = [0.2, 0, 1.3], [0.5, 0, 1.3], [0.5, 0.15, 1.1]
    # right: a 3-4-5 upper arm (0.5) and a 0.2 forearm
    J[P["upperarm_r"]], J[P["lowerarm_r"]], J[P["hand_r"]] = [-0.2, 0, 1.3], [-0.5, 0, 0.9], [-0.5, 0, 0.7]
    m = _measure(model, v, vt, J)
    assert m["arm_length"] == pytest.approx(((0.3 + 0.25) + (0.5 + 0.2)) / 2, rel=1e-12)


def test_shoulder_breadth_volume_and_mass_by_definition(body):
    model, _, v, vt, J = body
    m = _measure(model, v, vt, J, density=1000.0)
    sh_z = 0.5 * (J[P["upperarm_l"], 2] + J[P["upperarm_r"], 2])
    sel = np.isin(model.parts, [P["torso"], P["upperarm_l"], P["upperarm_r"]]) & (v[:, 2] > sh_z - 0.03)
    assert m["shoulder_breadth"] == pytest.approx(v[sel, 0].max() - v[sel, 0].min(), rel=1e-12)
    # not the whole body's width (the hands hang lower, outside the selection)
    assert m["shoulder_breadth"] < v[:, 0].max() - v[:, 0].min()
    # volume: signed tetrahedra against the origin, written out
    a, b, c = (v[model.faces[:, k]] for k in range(3))
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    assert m["volume"] == pytest.approx(volume, rel=1e-12)
    assert m["mass"] == pytest.approx(1000.0 * volume, rel=1e-9)
    assert set(MEASUREMENT_NAMES) <= set(m)
    assert m["inseam"] == m["crotch_height"]


def test_t_pose_raises_the_arms_level_and_straight(body):
    """Upper arms along ±x; each elbow (a one-angle hinge) at the angle that straightens the arm
    most: turning it 0.02 rad either way bends the arm more (the forearm leaves the hinge's
    plane by ~1°, so "straight" is the hinge's best, cos 0.9998 on this body)."""
    model, shape, _, _, _ = body
    pose = t_pose(model, shape)
    sl = pose_slices()

    def straightness(p, side):
        J = model.joints(shape, p)
        s, e, w = J[P[f"upperarm_{side}"]], J[P[f"lowerarm_{side}"]], J[P[f"hand_{side}"]]
        return (e - s) / np.linalg.norm(e - s), float((e - s) @ (w - e) / np.linalg.norm(e - s) / np.linalg.norm(w - e))

    for side, sign in (("l", 1.0), ("r", -1.0)):
        d, best = straightness(pose, side)
        np.testing.assert_allclose(d, [sign, 0, 0], atol=1e-6)  # upper arm along ±x
        assert best > 0.999
        elbow = sl[P[f"lowerarm_{side}"]]
        assert np.all(pose[elbow] < 0)
        for step in (-0.02, 0.02):
            other = pose.copy()
            other[elbow] += step
            assert straightness(other, side)[1] < best


def test_place_canonical_puts_the_pelvis_over_the_origin_on_the_floor(body):
    model, _, v, _, _ = body
    moved = v + [0.3, -0.2, 0.5]
    placed = place_canonical(moved, model.parts)
    pelvis = placed[model.parts == P["pelvis"]].mean(axis=0)
    np.testing.assert_allclose(pelvis[:2], [0, 0], atol=1e-12)
    assert placed[:, 2].min() == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(placed - moved, np.broadcast_to(placed[0] - moved[0], v.shape), atol=1e-12)


def test_measure_checks_density_and_mesh_shapes(body):
    model, shape, v, vt, J = body
    assert measure(model, shape)["mass"] == pytest.approx(980.0 * measure(model, shape)["volume"], rel=1e-12)
    with pytest.raises(ValueError, match=r"density must be a positive number of kg/m³, got 0"):
        _measure(model, v, vt, J, density=0.0)
    with pytest.raises(ValueError, match=r"joints must have shape \(15, 3\), got \(14, 3\)"):
        _measure(model, v, vt, J[:14])
    with pytest.raises(ValueError, match=r"tpose_vertices must have shape"):
        _measure(model, v, vt[:-1], J)
    bad = v.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match=r"vertices contains NaN or infinite values"):
        _measure(model, bad, vt, J)
    faces = model.faces.copy()
    faces[0, 0] = len(v)
    with pytest.raises(ValueError, match=rf"faces index vertices 0..{len(v)}, the mesh has {len(v)}"):
        measure_mesh(v, vt, J, faces, model.parts, model.face_parts)


def test_measure_mesh_passes_every_iso_value_through(body):
    """Each ISO 7250-1 value is the one :func:`measure_iso` computes on the same meshes (the
    body's parts included: the hip selection uses them); default density 980 kg/m³."""
    from studio.body.iso7250 import measure_iso

    model, _, v, vt, J = body
    iso = measure_iso(v, vt, J, model.faces, model.parts, model.face_parts, density=980.0).values
    m = _measure(model, v, vt, J)
    for key, value in iso.items():
        assert m[key] == value, key
    assert (m["stature"], m["arm_span"], m["mass"]) == (iso["stature"], iso["arm_span"], iso["mass"])
    assert m["mass"] == pytest.approx(980.0 * m["volume"], rel=1e-12)


def test_shoulder_breadth_is_zero_when_nothing_is_above_the_shoulders(body):
    model, _, v, vt, J = body
    J = J.copy()
    J[P["upperarm_l"], 2] = J[P["upperarm_r"], 2] = 10.0  # shoulders 10 m up: no vertex above
    assert _measure(model, v, vt, J)["shoulder_breadth"] == 0.0


def test_density_boundaries_and_mesh_error_messages(body):
    model, shape, v, vt, J = body
    light = _measure(model, v, vt, J, density=0.5)  # any positive density, below 1 too
    assert light["mass"] == pytest.approx(0.5 * light["volume"], rel=1e-12)
    with pytest.raises(ValueError, match=r"density must be a positive number of kg/m³, got 0"):
        measure(model, shape, density=0.0)
    with pytest.raises(ValueError, match=r"density must be a positive number of kg/m³, got inf"):
        measure(model, shape, density=np.inf)
    assert measure(model, shape, density=0.5)["mass"] == pytest.approx(light["mass"], rel=1e-12)
    with pytest.raises(ValueError, match=r"^vertices must have shape \(N, 3\), got \(3,\)$"):
        _measure(model, v[0], vt, J)
    with pytest.raises(ValueError, match=r"^faces must have shape \(N, 3\), got \(4,\)$"):
        measure_mesh(v, vt, J, model.faces[0].tolist() + [0], model.parts, model.face_parts)
    with pytest.raises(ValueError, match=rf"^parts must have shape \({len(v)}\), got \(3,\)$"):
        measure_mesh(v, vt, J, model.faces, model.parts[:3], model.face_parts)
    with pytest.raises(ValueError, match=rf"^face_parts must have shape \({len(model.faces)}\), got"):
        measure_mesh(v, vt, J, model.faces, model.parts, model.face_parts[:-1])
    with pytest.raises(ValueError, match=r"faces index vertices -1\.\."):
        measure_mesh(v, vt, J, np.r_[[[-1, 0, 1]], model.faces[1:]], model.parts, model.face_parts)


def test_t_pose_of_a_non_mean_shape(body):
    """The T-pose is built from the joints of the body being measured, not the mean body's."""
    model, shape, _, _, _ = body
    tall = shape.copy()
    tall[:3] = 2.0 * np.sqrt(model.eigenvalues[:3])
    pose = t_pose(model, tall)
    J = model.joints(tall, pose)
    for side, sign in (("l", 1.0), ("r", -1.0)):
        s, e = J[P[f"upperarm_{side}"]], J[P[f"lowerarm_{side}"]]
        np.testing.assert_allclose((e - s) / np.linalg.norm(e - s), [sign, 0, 0], atol=1e-6)


def test_slices_of_a_box_hand_computed():
    """Box [0,2]×[0,1]×[0,3] with triangulated sides: the plane z = 1 cuts the 4 vertical edges
    and the 4 side diagonals, at points on the 2 × 1 rectangle; a plane through vertices (z = 0,
    z = 3) cuts no edge; a triangle's perimeter is its three sides; volumes of a batch."""
    from studio.body.measure import convex_perimeter, mesh_volume, slice_points

    v = np.array([[x, y, z] for x in (0, 2) for y in (0, 1) for z in (0, 3)], float)
    f = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                  [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]])
    p = slice_points(v, f, 1.0)
    pts = {tuple(float(c) for c in np.round(q, 12)) for q in p}
    expected = {(0, 0), (0, 1), (2, 0), (2, 1),  # (x, y) of the vertical edges
                (0, 1 / 3), (2, 1 / 3), (2 / 3, 0), (2 / 3, 1)}  # diagonals (from a z = 0 corner), a third up
    assert pts == {tuple(round(c, 12) for c in e) for e in expected} and len(p) == 8
    assert len(slice_points(v, f, 0.0)) == 0 and len(slice_points(v, f, 3.0)) == 0
    assert convex_perimeter(np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 4.0]])) == pytest.approx(12.0)
    vols = mesh_volume(np.stack([v, 2 * v]), f)
    np.testing.assert_allclose(vols, [6.0, 48.0])
