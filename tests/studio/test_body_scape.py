"""SCAPE algebra on small analytic meshes (no model file needed)."""

import numpy as np

from calibration.rotation import matrix_to_rotvec, rotvec_to_matrix
import pytest

from studio.body import scape, skeleton


def cube():
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
    f = np.array([
        [0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
        [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5],
    ])
    return v, f


def test_rotvec_round_trip_and_known_rotation():
    rng = np.random.default_rng(0)
    rv = rng.normal(size=(50, 3))
    rv *= (rng.uniform(0, 3.0, 50) / np.linalg.norm(rv, axis=1))[:, None]
    R = rotvec_to_matrix(rv)
    assert np.allclose(R @ np.swapaxes(R, 1, 2), np.eye(3), atol=1e-12)
    assert np.allclose(matrix_to_rotvec(R), rv, atol=1e-9)
    Rz = rotvec_to_matrix(np.array([0, 0, np.pi / 2]))
    assert np.allclose(Rz @ [1, 0, 0], [0, 1, 0])
    near_pi = np.array([0.0, np.pi - 1e-9, 0.0])
    assert np.allclose(rotvec_to_matrix(matrix_to_rotvec(rotvec_to_matrix(near_pi))),
                       rotvec_to_matrix(near_pi), atol=1e-6)


def test_procrustes_recovers_rotation():
    rng = np.random.default_rng(1)
    src = rng.normal(size=(30, 3))
    R = rotvec_to_matrix(np.array([0.3, -1.2, 0.5]))
    tgt = src @ R.T + [1.0, 2.0, 3.0]
    assert np.allclose(scape.procrustes_rotation(src, tgt), R, atol=1e-10)


def test_deformation_gradient_of_linear_map_is_the_map():
    v, f = cube()
    A = np.array([[1.2, 0.1, 0.0], [0.0, 0.9, 0.2], [0.05, 0.0, 1.1]])
    D = scape.deformation_gradients(v, v @ A.T, f)
    # edges are reproduced exactly (third column is the normal convention)
    e = scape.triangle_edges(v, f)
    assert np.allclose(D @ e, scape.triangle_edges(v @ A.T, f), atol=1e-12)
    # identity for the undeformed mesh
    assert np.allclose(scape.deformation_gradients(v, v, f), np.eye(3), atol=1e-12)


def test_poisson_solver_reconstructs_rotated_scaled_mesh():
    v, f = cube()
    solver = scape.PoissonSolver(f, len(v))
    R = rotvec_to_matrix(np.array([0.2, 0.4, -0.1]))
    target = 1.5 * v @ R.T
    edges = scape.triangle_edges(target, f)
    y = solver.solve(edges)
    assert np.allclose(y[0], 0.0)
    assert np.allclose(y - y[0], target - target[0], atol=1e-10)
    # batch of right-hand sides equals separate solves
    batch = solver.solve(np.stack([edges, scape.triangle_edges(v, f)]))
    assert np.allclose(batch[0], y) and np.allclose(batch[1], v - v[0], atol=1e-10)


def test_poisson_solver_least_squares_for_inconsistent_edges():
    v, f = cube()
    solver = scape.PoissonSolver(f, len(v))
    rng = np.random.default_rng(2)
    edges = scape.triangle_edges(v, f) + rng.normal(scale=0.01, size=(len(f), 3, 2))
    y = solver.solve(edges)
    G = scape.edge_operator(f, len(v)).toarray()
    E = np.transpose(edges, (2, 0, 1)).reshape(-1, 3)  # rows (edge k, face)
    ref = np.linalg.lstsq(G[:, 1:], E, rcond=None)[0]
    assert np.allclose(y[1:], ref, atol=1e-10)


def test_pose_deformation_regression_recovers_linear_model():
    rng = np.random.default_rng(3)
    F, J, N = 5, 15, 40
    pairs = rng.integers(0, J, size=(F, 2))
    coef = rng.normal(scale=0.1, size=(F, 7, 9))
    rv = rng.normal(scale=0.5, size=(N, J, 3))
    Q = scape.pose_deformation(coef, rv, pairs)
    fit = scape.fit_pose_deformation(Q, rv, pairs, ridge=0.0, rest_identity=False)
    assert np.allclose(fit, coef, atol=1e-8)
    # with the intercept fixed to I the rest pose gives Q = I exactly
    coef[:, 6] = np.eye(3).ravel()
    Q = scape.pose_deformation(coef, rv, pairs)
    fit = scape.fit_pose_deformation(Q, rv, pairs, ridge=0.0)
    assert np.allclose(fit, coef, atol=1e-8)
    assert np.allclose(scape.pose_deformation(fit, np.zeros((1, J, 3)), pairs), np.eye(3))


def test_skeleton_rotations_compose_down_the_tree():
    axes = np.zeros((15, 3))
    axes[:, 0] = 1.0
    pose = np.zeros(skeleton.POSE_SIZE)
    sl = skeleton.pose_slices()
    pose[sl[1]] = [0.3, 0.0, 0.0]  # torso
    pose[sl[2]] = [0.2]  # head hinge about x
    G, L = skeleton.part_rotations(pose, axes)
    assert np.allclose(G[2], rotvec_to_matrix(np.array([0.5, 0, 0])))
    assert np.allclose(G[0], np.eye(3)) and np.allclose(G[9], np.eye(3))
    rv = skeleton.joint_rotvecs(G)
    assert np.allclose(rv[1], [0.3, 0, 0]) and np.allclose(rv[2], [0.2, 0, 0])
    assert skeleton.POSE_SIZE == 30


def test_large_batches_give_the_superlu_result():
    """64 bodies (192 right-hand sides) through the compiled back-substitution equal SuperLU's."""
    v, f = cube()
    solver = scape.PoissonSolver(f, len(v))
    rng = np.random.default_rng(5)
    targets = v[None] * rng.uniform(0.5, 2.0, (64, 1, 3))
    edges = np.stack([scape.triangle_edges(t, f) for t in targets])
    rhs = rng.normal(size=(len(v) - 1, 192))
    np.testing.assert_allclose(solver._back_substitute(rhs), solver._lu.solve(rhs), atol=1e-12)
    y = solver.solve(edges)
    np.testing.assert_allclose(y, targets - targets[:, :1], atol=1e-10)


@pytest.mark.parametrize("angle", [np.pi - 1e-6, np.pi])
def test_joint_angles_near_pi_come_back_with_their_axis(angle):
    """The old SCAPE inverse lost the axis near π; the skeleton's relative rotations now go
    through calibration.rotation (SciPy), exact there."""
    from studio.body.skeleton import joint_rotvecs

    axis = np.array([0.2, -0.6, 0.77]) / np.linalg.norm([0.2, -0.6, 0.77])
    G = np.repeat(np.eye(3)[None], 15, axis=0)
    G[3] = rotvec_to_matrix(axis * angle)  # upper left arm turned by ~π relative to the torso
    rv = joint_rotvecs(G)
    got = rv[..., 3, :]
    assert abs(np.linalg.norm(got) - angle) < 1e-9
    assert abs(abs(got @ axis) / np.linalg.norm(got) - 1.0) < 1e-9


def test_joint_features_are_the_relative_rotations_minus_identity():
    """eq. 3.16's regressors of the shipped model: zero at rest, R_rel − I otherwise (a hinge of
    θ about x: sin θ and 1 − cos θ in their places), even in the angle where rotation vectors
    are odd (a flexion's bulge is the same either side of rest only through these)."""
    axes = np.zeros((15, 3))
    axes[:, 0] = 1.0
    sl = skeleton.pose_slices()
    pose = np.zeros(skeleton.POSE_SIZE)
    assert np.abs(skeleton.joint_features(skeleton.part_rotations(pose, axes)[0])).max() == 0.0
    pose[sl[1]] = [0.3, 0.0, 0.0]  # torso
    pose[sl[2]] = [0.2]  # head hinge about x
    G = skeleton.part_rotations(pose, axes)[0]
    f = skeleton.joint_features(G)
    assert f.shape == (15, 9) and np.all(f[0] == 0.0)
    np.testing.assert_allclose(f[1].reshape(3, 3), rotvec_to_matrix(np.array([0.3, 0, 0])) - np.eye(3), atol=1e-12)
    np.testing.assert_allclose(f[2].reshape(3, 3)[1:, 1:], [[np.cos(0.2) - 1, -np.sin(0.2)],
                                                           [np.sin(0.2), np.cos(0.2) - 1]], atol=1e-12)
    pose[sl[2]] = [-0.2]
    g = skeleton.joint_features(skeleton.part_rotations(pose, axes)[0])
    assert g[2, 4] == pytest.approx(f[2, 4]) and g[2, 7] == pytest.approx(-f[2, 7])
    # a batch gives each body's own features
    np.testing.assert_array_equal(skeleton.joint_features(np.stack([G, G]))[1], f)


def test_pose_deformation_regression_recovers_any_feature_count():
    """eq. 3.17 on K = 9 features per joint: coefficients (F, 19, 9) recovered exactly from
    noiseless examples, Q = I at rest."""
    rng = np.random.default_rng(3)
    F, J, N = 5, 4, 80
    pairs = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [1, 3]])
    coef = rng.normal(size=(F, 19, 9)) * 0.1
    coef[:, 18] = np.eye(3).ravel()
    feats = rng.normal(size=(N, J, 9))
    Q = scape.pose_deformation(coef, feats, pairs)
    fit = scape.fit_pose_deformation(Q, feats, pairs, ridge=0.0)
    assert fit.shape == (F, 19, 9)
    np.testing.assert_allclose(fit, coef, atol=1e-9)
    np.testing.assert_allclose(scape.pose_deformation(fit, np.zeros((1, J, 9)), pairs)[0], np.broadcast_to(np.eye(3), (F, 3, 3)))
