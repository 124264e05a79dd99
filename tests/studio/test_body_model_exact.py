"""BodyModel (eq. 3.11, 3.22, 3.23) on a box whose every result has a closed form.

The box has sides 1 × 2 × 3 m; vertex 0 is a top corner (so "the lowest vertices" are not the
first ones). Its shape space is linear maps: ``D = diag(1 + s0, 1 + s0, 1 + s0 + s1)`` on every
triangle, so the rest mesh of shape ``s`` is exactly ``D · (v − c)`` about the box centre
``c = (0.5, 1, 1.5)`` (one part: the pelvis is the whole box). A constant pose deformation
``Q = q·I`` scales every edge by ``q``. Joints are single vertices (one-hot regressor rows),
so forward kinematics is a rotation of known points.

The model file is written by the test (numpy.savez) and read back field by field, so the
loader is checked against what was stored — and, through a fresh path each time, not
against a model the cache already holds.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.rotation import rotvec_to_matrix
from studio.body import BodyModel, BodyModelError, anny_correspondence, scape
from studio.body.model import pose_entry_name
from studio.body.skeleton import POSE_SIZE, default_limits

# cube corners (x, y, z) ∈ {0,1}³ at index 4x + 2y + z, outward faces; vertices 0 and 1 swapped
_CUBE_FACES = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                        [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]])
_SWAP = np.array([1, 0, 2, 3, 4, 5, 6, 7])
TEMPLATE = np.array([[x, 2.0 * y, 3.0 * z] for x in (0, 1) for y in (0, 1) for z in (0, 1)])[_SWAP]
FACES = _SWAP[_CUBE_FACES]
CENTRE = np.array([0.5, 1.0, 1.5])
F = len(FACES)
V = len(TEMPLATE)


def box_arrays(q: float | None = None) -> dict:
    eye = np.tile(np.eye(3).ravel(), F)
    stretch = np.tile(np.diag([0.0, 0.0, 1.0]).ravel(), F)
    Q_coef = None
    if q is not None:
        Q_coef = np.zeros((F, 7, 9))
        Q_coef[:, 6] = q * np.eye(3).ravel()
    regressor = np.zeros((15, V))
    regressor[np.arange(15), np.arange(15) % V] = 1.0
    return dict(
        gender="box", template=TEMPLATE, faces=FACES, parts=np.zeros(V, int), face_parts=np.zeros(F, int),
        D_mean=eye, D_basis=np.stack([eye, stretch]), eigenvalues=np.array([4.0, 0.25]),
        hinge_axes=np.tile([1.0, 0.0, 0.0], (15, 1)), pose_limits=default_limits(),
        joint_regressor=regressor, joint_pairs=np.zeros((F, 2), int), Q_coef=Q_coef,
    )


def box_model(q: float | None = None, **over) -> BodyModel:
    return BodyModel(**{**box_arrays(q), **over})


def rest_box(s0: float, s1: float) -> np.ndarray:
    """Rest mesh of shape (s0, s1): D·(v − c)."""
    return (TEMPLATE - CENTRE) * [1 + s0, 1 + s0, 1 + s0 + s1]


def test_rest_and_posed_meshes_are_the_linear_maps_of_the_box():
    m = box_model()
    s = np.array([0.5, -0.25])
    np.testing.assert_allclose(m.rest_vertices_batch(s[None])[0], rest_box(0.5, -0.25), atol=1e-9)
    # standing on z = 0, centred over the root translation
    pose = m.default_pose()
    pose[:3] = [0.25, -1.0, 0.5]
    want = rest_box(0.5, -0.25) + [0.25, -1.0, 0.5 + 1.5 * 1.25]
    np.testing.assert_allclose(m.vertices(s, pose), want, atol=1e-6)
    assert m.vertices(s)[:, 2].min() == pytest.approx(0.0, abs=1e-6)
    # a batch of three equal shapes (computed once) and of different ones
    S = np.array([s, s, s])
    P = np.zeros((3, POSE_SIZE))
    np.testing.assert_allclose(m.vertices_batch(S, P), np.broadcast_to(m.vertices(s), (3, V, 3)), atol=1e-6)
    S[1] = [0.0, 0.0]
    np.testing.assert_allclose(m.vertices_batch(S, P)[1], rest_box(0, 0) + [0, 0, 1.5], atol=1e-6)
    # integer inputs are converted before use
    np.testing.assert_allclose(m.vertices(np.zeros(2, int), np.zeros(POSE_SIZE, int)), rest_box(0, 0) + [0, 0, 1.5],
                               atol=1e-6)
    assert m.check_shape([0, 0]).dtype == np.float64 and m.check_pose([0] * POSE_SIZE).dtype == np.float64


def centred(v: np.ndarray) -> np.ndarray:
    return v - v.mean(axis=-2, keepdims=True)


def test_pose_deformation_q_scales_the_edges_and_use_q_false_leaves_it_out():
    """(The floor height comes from the rest pose, with its Q: use_q=False is compared centred.)"""
    m = box_model(q=2.0)
    np.testing.assert_allclose(m.vertices(np.zeros(2)), 2 * rest_box(0, 0) + [0, 0, 3.0], atol=1e-6)
    np.testing.assert_allclose(centred(m.vertices(np.zeros(2), use_q=False)), rest_box(0, 0), atol=1e-6)
    np.testing.assert_allclose(centred(m.vertices_batch(np.zeros((2, 2)), np.zeros((2, POSE_SIZE)), use_q=False)),
                               np.broadcast_to(rest_box(0, 0), (2, V, 3)), atol=1e-6)


def test_joints_follow_the_kinematic_tree():
    """Only the torso turns (rotation vector r): joints of the pelvis and of its other children stay,
    the torso's children turn about the torso joint by R(r)."""
    m = box_model()
    s = np.array([0.5, 0.0])
    rest = rest_box(0.5, 0.0)
    J0 = rest[np.arange(15) % V]  # one-hot regressor rows
    r = np.array([0.3, -0.2, 0.5])
    pose = m.default_pose()
    pose[:3] = [1.0, 2.0, 0.0]
    pose[6:9] = r
    root = np.array([1.0, 2.0, 1.5 * 1.5])  # translation + the pelvis centre's height
    R = rotvec_to_matrix(r)
    J = m.joints(s, pose)
    for k in (0, 1, 9, 12):  # pelvis, torso, both upper legs: untouched by the torso's turn
        np.testing.assert_allclose(J[k], root + J0[k], atol=1e-9)
    for k in (2, 3, 6):  # head, both upper arms: children of the torso
        np.testing.assert_allclose(J[k], root + J0[1] + R @ (J0[k] - J0[1]), atol=1e-9)
    np.testing.assert_allclose(m.rest_joints(s), m.joints(s, m.default_pose()), atol=1e-12)
    np.testing.assert_allclose(m.rest_joints(s), J0 + [0, 0, 1.5 * 1.5], atol=1e-9)


def test_integer_poses_are_accepted_by_joints_batch():
    m = box_model()
    pose = np.zeros((1, POSE_SIZE), int)
    pose[0, :3] = [1, -2, 3]
    np.testing.assert_allclose(m.joints_batch(np.zeros((1, 2), int), pose)[0],
                               rest_box(0, 0)[np.arange(15) % V] + [1, -2, 3 + 1.5], atol=1e-9)


def test_shape_from_vertices_is_the_weighted_least_squares_shape():
    """Template vertices (D = I everywhere) against a mean D_f = (1 + c_f)·I and one basis row I:
    β = −Σ w_f c_f / Σ w_f, the weighted mean (weights D_weights, else 1)."""
    c = 0.01 * np.arange(F)
    w = 1.0 + np.arange(F) % 3
    D_mean = ((1 + c)[:, None] * np.eye(3).ravel()).ravel()
    basis = np.tile(np.eye(3).ravel(), F)[None]
    unweighted = box_model(D_mean=D_mean, D_basis=basis, eigenvalues=np.ones(1))
    weighted = box_model(D_mean=D_mean, D_basis=basis, eigenvalues=np.ones(1), D_weights=w)
    est = unweighted.shape_from_vertices(TEMPLATE)
    assert est.shape == (1,) and est[0] == pytest.approx(-c.mean(), rel=1e-6)
    assert weighted.shape_from_vertices(TEMPLATE)[0] == pytest.approx(-(w * c).sum() / w.sum(), rel=1e-6)
    batch = weighted.shape_from_vertices(np.stack([TEMPLATE, TEMPLATE + 5.0]))
    assert batch.shape == (2, 1) and batch[1, 0] == pytest.approx(batch[0, 0], rel=1e-9)
    # float32 vertices (exact here) are converted first: the float64 result to the last bit
    mesh = rest_box(0.5, 0.25)
    assert weighted.shape_from_vertices(mesh.astype(np.float32))[0] == weighted.shape_from_vertices(mesh)[0]


def test_sample_shapes_draws_from_the_prior():
    m = box_model()
    want = np.random.default_rng(5).standard_normal((3, 2)) * [2.0, 0.5]
    np.testing.assert_array_equal(m.sample_shapes(3, 5), want)
    np.testing.assert_array_equal(m.sample_shapes(3, 5, scale=2.0), 2 * want)


def test_arrays_are_converted_to_their_documented_types():
    a = box_arrays()
    m = box_model(template=a["template"].astype(np.float32), faces=a["faces"].astype(np.int32),
                  parts=a["parts"].astype(np.int32), face_parts=a["face_parts"].astype(np.uint8),
                  D_mean=a["D_mean"].astype(np.float64), D_basis=a["D_basis"].astype(np.float64),
                  eigenvalues=a["eigenvalues"].astype(np.float32), pose_limits=a["pose_limits"].astype(np.float32))
    assert m.template.dtype == np.float64 and m.faces.dtype == np.int64
    assert m.parts.dtype == np.int64 and m.face_parts.dtype == np.int64
    assert m.D_mean.dtype == np.float32 and m.D_basis.dtype == np.float32
    assert m.eigenvalues.dtype == np.float64 and m.pose_limits.dtype == np.float64
    np.testing.assert_array_equal(m.eigenvalues, [4.0, 0.25])


def test_model_arrays_are_checked_at_their_boundaries():
    faces_of = "faces must be \\(F, 3\\) indices into 8 vertices"
    with pytest.raises(BodyModelError, match=f"^{faces_of}$"):
        box_model(faces=np.where(FACES == 7, 8, FACES))  # index V: one past the last vertex
    with pytest.raises(BodyModelError, match=f"^{faces_of}$"):
        box_model(faces=np.concatenate([FACES, FACES[:, :1]], axis=1))  # (F, 4)
    with pytest.raises(BodyModelError, match=f"^{faces_of}$"):
        box_model(faces=FACES[:4].reshape(4, 3, 1).repeat(3, axis=2))  # (4, 3, 3)
    with pytest.raises(BodyModelError, match=r"^faces must be grouped by part \(face_parts non-decreasing\)$"):
        box_model(face_parts=np.array([1, 0] + [1] * (F - 2)))
    with pytest.raises(BodyModelError, match=r"^shape basis must have F\*9 = 108 columns$"):
        box_model(D_basis=np.zeros((2, 5)))
    limits = default_limits()
    limits[10] = [0.5, 0.5]  # equal limits: one allowed value
    assert box_model(pose_limits=limits).pose_limits[10].tolist() == [0.5, 0.5]
    limits[10] = [0.5, 0.4]
    with pytest.raises(BodyModelError, match=r"^pose_limits must be \(30, 2\) with low <= high$"):
        box_model(pose_limits=limits)


def test_pose_limits_are_inclusive_to_1e9():
    m = box_model()
    lo, hi = m.pose_limits[:, 0], m.pose_limits[:, 1]
    s = np.zeros(2)
    i = 23  # lowerleg_l hinge angle
    for value in (lo[i], hi[i], lo[i] - 1e-9, hi[i] + 1e-9):
        pose = m.default_pose()
        pose[i] = value
        assert m.check_pose(pose)[i] == value
    for value in (lo[i] - 2e-9, hi[i] + 2e-9):
        pose = m.default_pose()
        pose[i] = value
        with pytest.raises(BodyModelError, match=r"^pose entry 23 \(lowerleg_l hinge angle\) outside its limits"):
            m.check_pose(pose)
    batch = np.zeros((3, POSE_SIZE))
    batch[2, 14] = hi[14] + 1.0
    with pytest.raises(BodyModelError, match=r"^pose entry 14 \(hand_l hinge angle\) outside its limits"):
        m.check_pose(batch, batch=True)
    low_high = m.default_pose()
    low_high[[13, 23]] = [lo[13] - 1.0, hi[23] + 1.0]
    clipped = m.check_pose(low_high, clip=True)
    assert clipped[13] == lo[13] and clipped[23] == hi[23] and not clipped[[0, 1, 2]].any()
    np.testing.assert_array_equal(m.clip_pose(low_high), clipped)


def test_input_messages_name_the_expected_shape():
    m = box_model()
    with pytest.raises(BodyModelError, match=r"^shape must have shape \(2,\) for the box model, got \(3,\)$"):
        m.check_shape(np.zeros(3))
    with pytest.raises(BodyModelError, match=r"^shape must have shape \(B, 2\) for the box model, got \(2,\)$"):
        m.check_shape(np.zeros(2), batch=True)
    with pytest.raises(BodyModelError, match=r"^shape contains NaN or infinite values$"):
        m.check_shape([np.nan, 0.0])
    with pytest.raises(BodyModelError, match=r"^pose must have shape \(30,\), got \(7,\)$"):
        m.check_pose(np.zeros(7))
    with pytest.raises(BodyModelError, match=r"^pose must have shape \(B, 30\), got \(30,\)$"):
        m.check_pose(np.zeros(30), batch=True)
    with pytest.raises(BodyModelError, match=r"^pose contains NaN or infinite values$"):
        m.check_pose(np.full(30, np.inf))
    with pytest.raises(BodyModelError, match=r"^unknown gender 'robot': expected one of male, female, neutral$"):
        BodyModel.load("robot")


def test_pose_entry_names():
    assert [pose_entry_name(i) for i in (0, 2, 3, 5, 6, 8, 9, 23, 29, 30)] == [
        "root translation x", "root translation z", "pelvis rotation x", "pelvis rotation z",
        "torso rotation x", "torso rotation z", "head hinge angle", "lowerleg_l hinge angle",
        "foot_r hinge angle", "entry 30"]


def _write_model(path, *, quantised: bool):
    a = box_arrays(q=1.5)
    g = "neutral"
    arrays = {
        "template": a["template"].astype(np.float32), "faces": a["faces"].astype(np.int32),
        "vertex_parts": a["parts"].astype(np.uint8), "face_parts": a["face_parts"].astype(np.uint8),
        f"{g}/D_mean": a["D_mean"].astype(np.float32), f"{g}/eigenvalues": a["eigenvalues"],
        "hinge_axes": a["hinge_axes"], "pose_limits": a["pose_limits"],
        "joint_regressor": a["joint_regressor"].astype(np.float32), "joint_pairs": a["joint_pairs"].astype(np.int32),
        "Q_coef": a["Q_coef"].astype(np.float16),
    }
    if quantised:  # 108 values a row in blocks of 96: q · scale per block
        q = np.zeros((2, F * 9), np.int8)
        q[:, ::4] = 100
        q[1, 1::4] = -7
        arrays[f"{g}/D_basis_q"] = q
        arrays[f"{g}/D_basis_scale"] = np.array([[0.01, 0.02], [0.03, 0.005]], np.float16)
        arrays["D_weights"] = np.linspace(1.0, 2.0, F)
        arrays[f"{g}/meas_shapes"] = np.arange(6.0).reshape(3, 2)
        arrays[f"{g}/meas_values"] = np.arange(3.0)
    else:
        arrays[f"{g}/D_basis"] = a["D_basis"].astype(np.float32)
    np.savez(path, **arrays)
    return arrays


def test_load_reads_every_field(tmp_path):
    stored = _write_model(tmp_path / "q.npz", quantised=True)
    m = BodyModel.load(path=tmp_path / "q.npz")  # the default gender is neutral
    assert m.gender == "neutral"
    for name, key in [("template", "template"), ("faces", "faces"), ("parts", "vertex_parts"),
                      ("face_parts", "face_parts"), ("D_mean", "neutral/D_mean"), ("eigenvalues", "neutral/eigenvalues"),
                      ("hinge_axes", "hinge_axes"), ("pose_limits", "pose_limits"),
                      ("joint_regressor", "joint_regressor"), ("joint_pairs", "joint_pairs"), ("Q_coef", "Q_coef"),
                      ("D_weights", "D_weights")]:
        np.testing.assert_array_equal(getattr(m, name), stored[key], err_msg=name)
    assert m.parts.dtype == m.face_parts.dtype == m.joint_pairs.dtype == np.int64
    assert m.joint_regressor.dtype == m.Q_coef.dtype == np.float64
    q, scale = stored["neutral/D_basis_q"], stored["neutral/D_basis_scale"].astype(np.float32)
    want = np.empty((2, F * 9), np.float32)
    for k in range(2):
        want[k, :96] = q[k, :96] * scale[k, 0]
        want[k, 96:] = q[k, 96:] * scale[k, 1]
    np.testing.assert_array_equal(m.D_basis, want)
    shapes, values = m.measurement_samples
    np.testing.assert_array_equal(shapes, stored["neutral/meas_shapes"])
    np.testing.assert_array_equal(values, stored["neutral/meas_values"])
    # the pose deformation was read: Q = 1.5·I scales the box
    np.testing.assert_allclose(m.vertices(np.zeros(2)), 1.5 * rest_box(0, 0) + [0, 0, 2.25], atol=2e-6)

    stored = _write_model(tmp_path / "plain.npz", quantised=False)
    plain = BodyModel.load("neutral", tmp_path / "plain.npz")
    assert plain is not m and BodyModel.load("neutral", tmp_path / "plain.npz") is plain  # cached by path
    np.testing.assert_array_equal(plain.D_basis, stored["neutral/D_basis"])
    assert plain.D_weights is None and plain.measurement_samples is None


def test_anny_correspondence_reads_its_size(tmp_path):
    common = dict(template=np.zeros((3, 3)), anny_map_weights=np.array([0.25, 0.75, 1.0, 1.0], np.float32),
                  anny_map_indices=np.array([0, 4, 2, 1], np.int32), anny_map_indptr=np.array([0, 2, 3, 4]))
    np.savez(tmp_path / "sized.npz", anny_n_vertices=5, **common)
    np.savez(tmp_path / "default.npz", **common)
    M = anny_correspondence(tmp_path / "sized.npz")
    assert M.shape == (3, 5) and M.dtype == np.float64
    np.testing.assert_array_equal(M.toarray(), [[0.25, 0, 0, 0, 0.75], [0, 0, 1, 0, 0], [0, 1, 0, 0, 0]])
    assert anny_correspondence(tmp_path / "default.npz").shape == (3, 13348)
