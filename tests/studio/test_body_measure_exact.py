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
