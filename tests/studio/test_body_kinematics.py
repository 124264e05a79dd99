"""The compiled kinematic chain (studio.body.kinematics) against the SciPy path of skeleton."""

import numpy as np
import pytest

from studio.body import BodyModel, skeleton
from studio.body.kinematics import chain_rotations


@pytest.fixture(scope="module")
def model():
    return BodyModel.load("female")


def _reference(poses, axes):
    G, _ = skeleton.part_rotations(poses, axes)
    return G, skeleton.joint_rotvecs(G)


def test_random_poses_equal_the_scipy_path(model):
    rng = np.random.default_rng(0)
    poses = model.clip_pose(rng.normal(size=(64, skeleton.POSE_SIZE)) * 0.8)
    G, rv = chain_rotations(poses, model.hinge_axes)
    G_ref, rv_ref = _reference(poses, model.hinge_axes)
    assert np.abs(rv_ref).max() > 1.0  # large joint angles are in the sample
    np.testing.assert_allclose(G, G_ref, rtol=0, atol=1e-13)
    np.testing.assert_allclose(rv, rv_ref, rtol=0, atol=1e-12)
    assert np.all(rv[:, 0] == 0.0)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 5e-4, 1e-3, 2e-3, 1.0, np.pi - 1e-6, np.pi, 3.5])
def test_small_large_and_wrapping_angles(model, angle):
    """Both small-angle series, π and a ball joint beyond π (its relative rotation wraps to
    2π − θ about the opposite axis, as SciPy's does)."""
    axis = np.array([0.48, -0.6, 0.64])
    poses = np.zeros((2, skeleton.POSE_SIZE))
    sl = skeleton.pose_slices()
    poses[0, sl[3]] = angle * axis  # left shoulder, a ball joint
    poses[1, sl[4]] = angle  # left elbow, a hinge
    poses[1, 3:6] = 0.3 * axis  # and a turned root
    G, rv = chain_rotations(poses, model.hinge_axes)
    G_ref, rv_ref = _reference(poses, model.hinge_axes)
    np.testing.assert_allclose(G, G_ref, rtol=0, atol=1e-13)
    np.testing.assert_allclose(rv, rv_ref, rtol=0, atol=1e-12 if angle < 3 else 1e-7)
    if 0 < angle < np.pi:
        np.testing.assert_allclose(rv[0, 3], angle * axis, atol=1e-12)
        np.testing.assert_allclose(rv[1, 4], angle * model.hinge_axes[4], atol=1e-12)
    if angle > np.pi:
        np.testing.assert_allclose(rv[0, 3], (angle - 2 * np.pi) * axis, atol=1e-9)


def test_mesh_through_the_chain_equals_the_scipy_chain(model):
    """The model's meshes (which use the compiled chain) equal meshes whose posed edges come
    from the SciPy rotations, to 1e-9 m."""
    from studio.body import posed

    rng = np.random.default_rng(1)
    shapes = rng.normal(size=(3, model.n_shape)) * np.sqrt(model.eigenvalues)
    poses = model.clip_pose(rng.normal(size=(3, skeleton.POSE_SIZE)) * 0.5)
    G, rv = _reference(poses, model.hinge_axes)
    x = posed.slot_regressors(model._joint_features(G, rv), model._slots, model._Q_reduce)
    e = posed.posed_edges_planar(x, model._Qp, model._slot, model._shape_gradients(shapes), G.astype(np.float32),
                                 model._part_start)
    np.testing.assert_allclose(model._posed_edges(shapes, poses), e, rtol=0, atol=1e-6)
