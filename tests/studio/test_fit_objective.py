"""The frame objective (eq. 4.6 + 6.8 + 6.9): every term the breakdown reports is in the
optimised cost, with the closed-form prior values.

A joint pushed ``δ`` past its limit costs ``w·(δ/σ)²`` more than the same pose clipped back
onto the limit (the mesh is the same, so the silhouette term is); a shape coefficient at
``4σ`` costs ``w·(4 − 3)²`` (eq. 6.8's flat zone ends at 3σ).
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration import Camera
from studio.body import BodyModel
from studio.body.skeleton import POSE_SIZE
from studio.cost import SilhouetteTarget
from studio.fit.objective import BATCH, FrameObjective, parameter_box, pose_bounds
from studio.render import silhouette

JOINT = 6  # first angle after the root: limits (-0.5, 1.2)
SIGMA_LIMIT = 0.05  # the objective's joint-limit σ


@pytest.fixture(scope="module")
def scene():
    model = BodyModel.load("female")
    cams = [Camera.look_at(f"cam{k}", [3.0 * np.cos(a), 3.0 * np.sin(a), 1.5], [0, 0, 0.9], 90.0, (96, 72),
                           np.zeros(5)) for k, a in enumerate((0.4, 2.2))]
    shape = model.mean_shape()
    pose = model.default_pose()
    V = model.vertices(shape, pose)
    masks = [silhouette(c, V, model.faces) for c in cams]
    targets = {lvl: SilhouetteTarget.build(masks, level=lvl) for lvl in (0, 1)}
    return model, cams, targets, shape, pose


def test_cost_holds_every_reported_term(scene):
    model, cams, targets, shape, pose = scene
    w = 2.5
    obj = FrameObjective(model, cams, targets, shape, n_shape_free=1, prior_weight=w)
    sigma0 = float(np.sqrt(model.eigenvalues[0]))
    inside = pose.copy()
    inside[JOINT] = model.pose_limits[JOINT, 1]  # on the limit: no penalty
    outside = inside.copy()
    outside[JOINT] += 0.1  # 0.1 rad past it: (0.1 / 0.05)² = 4
    beta = shape.copy()
    beta[0] = 4.0 * sigma0  # 4σ: (4 − 3)² = 1
    for level in (0, 1):
        x_in, x_out = obj.pack(beta, inside), obj.pack(beta, outside)
        t_in, t_out = obj.terms(x_in, level), obj.terms(x_out, level)
        assert t_in["pose_limits"] == 0.0
        assert t_out["pose_limits"] == pytest.approx((0.1 / SIGMA_LIMIT) ** 2, rel=1e-9)
        assert t_out["shape_prior"] == pytest.approx(1.0, rel=1e-9)
        assert t_out["silhouette"] == t_in["silhouette"] > 0  # same (clipped) mesh
        assert t_out["silhouette"] == pytest.approx(sum(t_out["silhouette_per_view"].values()), rel=1e-12)
        assert sorted(t_out["silhouette_per_view"]) == ["view0", "view1"]  # the targets' names
        assert t_out["total"] == pytest.approx(t_out["silhouette"] + w * (1.0 + 4.0), rel=1e-12)
        assert t_out["level"] == level
        if level == 0:
            assert obj.terms(x_out) == t_out  # level 0 (full resolution) by default
        costs = obj(np.stack([x_in, x_out]), level)  # the optimised cost
        np.testing.assert_allclose(costs, [t_in["total"], t_out["total"]], rtol=1e-12)
        assert costs[1] - costs[0] == pytest.approx(w * (0.1 / SIGMA_LIMIT) ** 2, rel=1e-9)
        assert obj.scalar(level)(x_out) == pytest.approx(costs[1], rel=1e-12)
    assert obj.n_evaluations == 2 * 2 + 2  # two batches of two, two scalar calls


def test_pack_split_and_batches(scene):
    model, cams, targets, shape, pose = scene
    obj = FrameObjective(model, cams, targets, shape + 0.5, n_shape_free=2)
    assert obj.size == POSE_SIZE + 2
    beta = shape + np.arange(len(shape))
    x = obj.pack(beta, pose)
    np.testing.assert_array_equal(x, np.r_[pose, beta[:2]])
    shapes, poses = obj.split(x)
    np.testing.assert_array_equal(shapes[0], np.r_[beta[:2], shape[2:] + 0.5])  # the rest stay at base_shape
    np.testing.assert_array_equal(poses[0], pose)
    # more particles than one batch: each mesh is its own parameters' mesh
    X = np.repeat(x[None], 2 * BATCH + 2, axis=0)
    X[:, 0] = np.linspace(-0.5, 0.5, len(X))  # root x
    V = obj.meshes(X)
    ref = model.vertices_batch(shapes[:1], pose[None], free_shape=2)[0]  # the objective's 2 free coefficients
    np.testing.assert_allclose(ref, model.vertices(shapes[0], pose), atol=1e-8)  # float32 sums grouped apart
    for i in (0, BATCH - 1, BATCH, 2 * BATCH, 2 * BATCH + 1):
        np.testing.assert_allclose(V[i], ref + [X[i, 0], 0, 0], atol=1e-9)


def test_pose_bounds():
    model = BodyModel.load("female")
    lo, hi = pose_bounds(model)
    np.testing.assert_array_equal(lo[3:], model.pose_limits[3:, 0])
    np.testing.assert_array_equal(hi[3:], model.pose_limits[3:, 1])
    np.testing.assert_array_equal(lo[:3], [model.pose_limits[0, 0], model.pose_limits[1, 0], -0.6])
    np.testing.assert_array_equal(hi[:3], [model.pose_limits[0, 1], model.pose_limits[1, 1], 0.3])
    lo, hi = pose_bounds(model, root_xy=[0.2, -0.4])  # within 1 m by default
    np.testing.assert_allclose(lo[:2], [-0.8, -1.4])
    np.testing.assert_allclose(hi[:2], [1.2, 0.6])
    lo, hi = pose_bounds(model, root_xy=[0.2, -0.4], xy_margin=0.25)
    np.testing.assert_allclose(lo[:3], [-0.05, -0.65, -0.6])
    np.testing.assert_allclose(hi[:3], [0.45, -0.15, 0.3])
    assert model.pose_limits[2, 0] == -10.0  # the model's own limits are left alone


def test_parameter_box_bounds_pose_and_shape_with_their_steps():
    """Pose + n shape coefficients: the pose bounds given, the shape within ±3 σ; steps 3 cm at
    the root's position, 0.08 rad for every angle, σ / 2 for a coefficient."""
    model = BodyModel.load("female")
    lo, hi = pose_bounds(model, np.array([0.2, -0.1]))
    (blo, bhi), step = parameter_box(model, lo, hi, 4)
    sig = np.sqrt(model.eigenvalues[:4])
    np.testing.assert_array_equal(blo, np.concatenate([lo, -3 * sig]))
    np.testing.assert_array_equal(bhi, np.concatenate([hi, 3 * sig]))
    np.testing.assert_array_equal(step[:3], 0.03)
    np.testing.assert_array_equal(step[3:POSE_SIZE], 0.08)
    np.testing.assert_allclose(step[POSE_SIZE:], 0.5 * sig, rtol=1e-15)
    (plo, phi), pstep = parameter_box(model, lo, hi, 0)
    assert plo.shape == phi.shape == pstep.shape == (POSE_SIZE,)


def test_integer_inputs_are_taken_as_real_numbers(scene):
    """A base shape or parameters given as integers are not truncated when the free shape
    coefficients (fractions of a standard deviation) are written in."""
    model, cams, targets, shape, pose = scene
    n = len(shape)
    obj = FrameObjective(model, cams, targets, [0] * n, n_shape_free=2)
    x = obj.pack([0] * n, [0] * POSE_SIZE)
    assert x.dtype == np.float64 and x.shape == (POSE_SIZE + 2,)
    x[POSE_SIZE:] = [0.25, -1.5]
    shapes, _ = obj.split(x)
    np.testing.assert_array_equal(shapes[0, :3], [0.25, -1.5, 0.0])


def test_cylinder_meshes_follow_a_turned_root_with_their_own_sides(scene):
    """The cone model's chain (rest joints precomputed) equals ``CylinderModel.mesh`` for a body
    turned and tilted at the root, with the objective's number of sides."""
    from studio.fit.objective import CylinderObjective

    model, cams, targets, shape, pose = scene
    obj = CylinderObjective(model, cams, targets, shape, sides=8)
    p = pose.copy()
    p[:6] = [0.2, -0.1, 0.05, 0.3, -0.2, 1.0]
    p[6] = 0.4
    V = obj.meshes(p[None])[0]
    Vr, Fr = obj.cylinder.mesh(p, sides=8)
    np.testing.assert_allclose(V, Vr, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(obj.faces, Fr)
