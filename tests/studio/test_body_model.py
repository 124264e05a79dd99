"""The shipped SCAPE models: loading, consistency, generation, input checks."""

import numpy as np
import pytest

from studio.body import GENDERS, PART_NAMES, POSE_SIZE, BodyModel, BodyModelError
from studio.body.model import DATA_FILE
from calibration.rotation import rotvec_to_matrix


@pytest.fixture(scope="module")
def model():
    return BodyModel.load("neutral")


def test_shipped_file_is_small_and_all_genders_load():
    assert DATA_FILE.is_file()
    total = sum(p.stat().st_size for p in DATA_FILE.parent.iterdir() if p.is_file())
    assert total < 30e6
    for g in GENDERS:
        m = BodyModel.load(g)
        assert m.gender == g and m.n_shape >= 20
        assert np.all(m.eigenvalues > 0) and np.all(np.diff(m.eigenvalues) <= 0)
    assert BodyModel.load("male") is BodyModel.load("male")  # cached


def test_arrays_are_consistent(model):
    V, F = model.n_vertices, len(model.faces)
    assert 5000 <= V <= 10000
    assert model.faces.shape == (F, 3) and model.faces.max() == V - 1
    assert model.parts.shape == (V,) and set(np.unique(model.parts)) == set(range(15))
    assert model.part_names == PART_NAMES and len(PART_NAMES) == 15
    assert model.pose_size == POSE_SIZE == 30
    lim = model.pose_limits
    assert lim.shape == (30, 2) and np.all(lim[:, 0] <= lim[:, 1])
    p0 = model.default_pose()
    assert np.all((p0 >= lim[:, 0]) & (p0 <= lim[:, 1]))
    # watertight: every edge shared by exactly two triangles
    f = model.faces
    e = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    assert np.all(counts == 2)
    # left/right symmetric template
    from scipy.spatial import cKDTree

    d, _ = cKDTree(model.template).query(model.template * [-1, 1, 1])
    assert d.max() < 1e-6


def test_default_pose_stands_on_floor_facing_minus_y(model):
    v = model.vertices(model.mean_shape())
    assert abs(v[:, 2].min()) < 1e-5
    assert 1.5 < v[:, 2].max() < 2.0
    pelvis = v[model.parts == PART_NAMES.index("pelvis")].mean(axis=0)
    assert np.allclose(pelvis[:2], 0.0, atol=1e-5)
    head = v[model.parts == PART_NAMES.index("head")]
    nose = head[np.argmax(-head[:, 1])]
    assert nose[1] < pelvis[1] - 0.05  # the face points to -y
    J = model.joints(model.mean_shape())
    assert J[PART_NAMES.index("upperarm_l"), 0] > 0.1  # subject's left at +x


def test_translation_and_root_rotation_move_the_body_rigidly(model):
    s = model.sample_shapes(1, 0)[0]
    p = model.default_pose()
    v0 = model.vertices(s, p)
    p[:3] = [0.5, -1.0, 0.2]
    assert np.allclose(model.vertices(s, p), v0 + [0.5, -1.0, 0.2], atol=1e-9)
    p = model.default_pose()
    p[3:6] = [0, 0, np.pi / 2]
    v1 = model.vertices(s, p)
    c = v0[model.parts == 0].mean(axis=0)
    R = rotvec_to_matrix(np.array([0, 0, np.pi / 2]))
    assert np.abs(v1 - ((v0 - c) @ R.T + c)).max() < 1e-3


def test_batch_equals_single(model):
    rng = np.random.default_rng(4)
    S = model.sample_shapes(3, rng)
    P = np.tile(model.default_pose(), (3, 1))
    lim = model.pose_limits
    P[:, 6:] = lim[6:, 0] + rng.uniform(0.3, 0.7, (3, 24)) * (lim[6:, 1] - lim[6:, 0])
    batch = model.vertices_batch(S, P)
    assert batch.shape == (3, model.n_vertices, 3)
    for i in range(3):
        assert np.abs(batch[i] - model.vertices(S[i], P[i])).max() < 1e-6
    J = model.joints_batch(S, P)
    assert np.allclose(J[1], model.joints(S[1], P[1]))


def test_knee_bend_moves_only_the_leg_and_q_changes_the_joint(model):
    s = model.mean_shape()
    p = model.default_pose()
    i = 6 + 3 + 1 + 5 + 5 + 3  # lowerleg_l hinge
    assert "lowerleg_l" in __import__("studio.body.model", fromlist=["pose_entry_name"]).pose_entry_name(i)
    p[i] = 1.2
    v0, v1 = model.vertices(s), model.vertices(s, p)
    moved = np.linalg.norm(v1 - v0, axis=1)
    foot = model.parts == PART_NAMES.index("foot_l")
    head = model.parts == PART_NAMES.index("head")
    assert moved[foot].mean() > 0.2 and moved[head].mean() < 0.01
    rigid = model.vertices(s, p, use_q=False)
    assert np.abs(rigid - v1).max() > 1e-3  # Q deforms near the knee


def test_bad_inputs_raise_clear_errors(model):
    s = model.mean_shape()
    with pytest.raises(BodyModelError, match="shape must have shape"):
        model.vertices(np.zeros(3))
    with pytest.raises(BodyModelError, match="NaN"):
        model.vertices(np.full(model.n_shape, np.nan))
    with pytest.raises(BodyModelError, match="pose must have shape"):
        model.vertices(s, np.zeros(7))
    bad = model.default_pose()
    bad[10] = np.inf
    with pytest.raises(BodyModelError, match="pose contains NaN"):
        model.vertices(s, bad)
    bad = model.default_pose()
    knee = 6 + 3 + 1 + 5 + 5 + 3
    bad[knee] = -1.0
    with pytest.raises(BodyModelError, match="lowerleg_l hinge angle.*outside its limits"):
        model.vertices(s, bad)
    assert model.clip_pose(bad)[knee] == model.pose_limits[knee, 0]
    with pytest.raises(BodyModelError, match="same batch size"):
        model.vertices_batch(np.zeros((2, model.n_shape)), np.zeros((3, 30)))
    with pytest.raises(BodyModelError, match="unknown gender"):
        BodyModel.load("robot")
    with pytest.raises(BodyModelError, match="not found"):
        BodyModel.load("male", "/nonexistent/model.npz")


def test_mesh_export_round_trip(model, tmp_path):
    from studio.body import read_ply

    v = model.vertices(model.mean_shape())
    path = model.save_mesh(tmp_path / "body.ply", v)
    v2, f2 = read_ply(path)
    assert np.allclose(v2, v, atol=1e-6) and np.array_equal(f2, model.faces)
    obj = model.save_mesh(tmp_path / "body.obj", v).read_text().splitlines()
    assert sum(line.startswith("v ") for line in obj) == model.n_vertices
    with pytest.raises(ValueError, match=r"must be \.ply, \.obj or \.glb"):
        model.save_mesh(tmp_path / "body.stl", v)


def test_shape_from_vertices_recovers_a_body(model):
    s = model.sample_shapes(2, 6)
    v = model.vertices_batch(s, np.zeros((2, 30)))
    est = model.shape_from_vertices(v)
    assert est.shape == (2, model.n_shape)
    back = model.vertices_batch(est, np.zeros((2, 30)))
    d = back - v
    err = np.linalg.norm(d - d.mean(axis=1, keepdims=True), axis=-1)  # up to translation
    assert err.mean() < 1.5e-3 and err.max() < 6e-3  # the LS mesh is not exactly its own D
    with pytest.raises(BodyModelError, match="template correspondence"):
        model.shape_from_vertices(np.zeros((10, 3)))


def test_anny_correspondence_is_barycentric(model):
    from studio.body import anny_correspondence

    M = anny_correspondence()
    assert M.shape == (model.n_vertices, 13348)
    assert np.allclose(np.asarray(M.sum(axis=1)).ravel(), 1.0, atol=1e-6)
    assert M.getnnz(axis=1).max() <= 3
    with pytest.raises(BodyModelError, match="not found"):
        anny_correspondence("/nonexistent.npz")


def cube_model(**over):
    """A one-part BodyModel on a unit cube: D = (1 + s)·I, no pose deformation."""
    from studio.body.skeleton import default_limits

    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], dtype=float)
    f = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                  [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]])
    F = len(f)
    args = dict(
        gender="cube", template=v, faces=f, parts=np.zeros(8, int), face_parts=np.zeros(F, int),
        D_mean=np.tile(np.eye(3).ravel(), F), D_basis=np.tile(np.eye(3).ravel(), F)[None],
        eigenvalues=np.ones(1), hinge_axes=np.tile([1.0, 0, 0], (15, 1)), pose_limits=default_limits(),
        joint_regressor=np.full((15, 8), 1 / 8), joint_pairs=np.zeros((F, 2), int), Q_coef=None,
    )
    args.update(over)
    return BodyModel(**args)


def test_generation_on_an_analytic_cube():
    m = cube_model()
    v = m.vertices(np.array([0.5]))
    # scaled by 1.5, standing on the floor, centred over the origin
    assert np.allclose(v.min(axis=0), [-0.75, -0.75, 0.0], atol=1e-9)
    assert np.allclose(v.max(axis=0), [0.75, 0.75, 1.5], atol=1e-9)
    pose = m.default_pose()
    pose[3:6] = [np.pi / 2, 0, 0]
    pose[:3] = [1, 2, 3]
    w = m.vertices(np.array([0.0]), pose)
    R = rotvec_to_matrix(np.array([np.pi / 2, 0, 0]))
    ref = (m.vertices(np.array([0.0])) - [0, 0, 0.5]) @ R.T + [1, 2, 3.5]
    assert np.allclose(w, ref, atol=1e-6)
    assert np.allclose(m.joints(np.array([0.0]), pose)[0], [1, 2, 3.5], atol=1e-6)


def test_inconsistent_model_arrays_are_rejected():
    with pytest.raises(BodyModelError, match="faces must be"):
        cube_model(faces=np.array([[0, 1, 99]]))
    with pytest.raises(BodyModelError, match="parts must be"):
        cube_model(parts=np.zeros(3, int))
    with pytest.raises(BodyModelError, match="grouped by part"):
        cube_model(face_parts=np.array([1, 0] + [1] * 10))
    with pytest.raises(BodyModelError, match="F\\*9"):
        cube_model(D_mean=np.zeros(5))
    with pytest.raises(BodyModelError, match="pose_limits"):
        cube_model(pose_limits=np.zeros((3, 2)))


def test_model_file_without_the_gender_is_rejected(tmp_path):
    path = tmp_path / "partial.npz"
    np.savez(path, template=np.zeros((3, 3)))
    with pytest.raises(BodyModelError, match="no model for gender 'male'"):
        BodyModel.load("male", path)


def test_mesh_io_rejects_bad_arrays_and_formats(tmp_path):
    from studio.body import read_ply, write_mesh

    with pytest.raises(ValueError, match="vertices must be"):
        write_mesh(tmp_path / "a.ply", np.zeros((4, 2)), np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="faces must be"):
        write_mesh(tmp_path / "a.ply", np.zeros((4, 3)), np.array([[0, 1, 9]]))
    colored = write_mesh(tmp_path / "c.ply", np.eye(3), np.array([[0, 1, 2]]), colors=np.full((3, 3), 200))
    with pytest.raises(ValueError, match="colored PLY"):
        read_ply(colored)
    ascii_ply = tmp_path / "ascii.ply"
    ascii_ply.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 0\nelement face 0\nend_header\n")
    with pytest.raises(ValueError, match="binary little-endian"):
        read_ply(ascii_ply)


def test_posed_edges_are_r_d_q_v_of_every_triangle(model):
    """eq. 3.11 term by term in float64 for a handful of triangles of every part: Q from its
    regression on the two adjacent joints' rotations (eq. 3.16: each rotation matrix's entries
    minus the identity, :func:`studio.body.skeleton.joint_features`), D from the shape
    basis (eq. 3.22), R the part's rotation — against the compiled kernel with the full map
    (the fit's reduced map is held to it below)."""
    from studio.body import posed, scape, skeleton

    rng = np.random.default_rng(7)
    S = model.sample_shapes(2, rng)
    P = np.tile(model.default_pose(), (2, 1))
    lim = model.pose_limits
    P[:, 6:] = lim[6:, 0] + rng.uniform(0.2, 0.8, (2, 24)) * (lim[6:, 1] - lim[6:, 0])
    G = model.part_rotations(P)
    got = posed.posed_edges_planar(posed.slot_regressors(model._joint_features(G), model._slots), posed.planar_q(model._Qc),
                                   model._slot, model._shape_gradients(S), G.astype(np.float32), model._part_start)
    assert model.Q_coef.shape[1] == 19
    rv = np.stack([[np.zeros(9)] + [(np.linalg.inv(g[parent]) @ g[p] - np.eye(3)).ravel()
                                    for p, parent in enumerate(skeleton.PART_PARENTS) if parent >= 0] for g in G])
    edges = scape.triangle_edges(model.template, model.faces)  # (F, 3, 2)
    F = len(model.faces)
    faces = np.concatenate([np.flatnonzero(model.face_parts == p)[:3] for p in range(15)])
    for b in range(2):
        D = (model.D_mean.astype(np.float64) + S[b] @ model.D_basis.astype(np.float64)).reshape(F, 3, 3)
        for f in faces:
            x = np.concatenate([rv[b, model.joint_pairs[f, 0]], rv[b, model.joint_pairs[f, 1]], [1.0]])
            Q = (x @ model.Q_coef[f]).reshape(3, 3)
            want = G[b, model.face_parts[f]] @ D[f] @ Q @ edges[f]
            assert np.abs(got[b, :, :, f] - want).max() < 2e-5 * max(1.0, np.abs(want).max())
    rigid = model._posed_edges(S[:1], P[:1], use_q=False)
    f = faces[5]
    want = G[0, model.face_parts[f]] @ (model.D_mean.astype(np.float64) + S[0] @ model.D_basis).reshape(F, 3, 3)[f] @ edges[f]
    assert np.abs(rigid[0, :, :, f] - want).max() < 2e-5


def test_free_shape_hint_equals_the_full_shape_deformation():
    """``free_shape``: the fixed coefficients folded into a cached base give the full
    product's shape deformations and meshes to float32 rounding, for single bodies and
    batches (equal and unequal fixed tails), and the hint is not needed for correctness."""
    model = BodyModel.load("female")
    rng = np.random.default_rng(11)
    sig = np.sqrt(model.eigenvalues)
    base = rng.normal(size=model.n_shape) * sig
    poses = model.clip_pose(rng.normal(size=(4, POSE_SIZE)) * 0.3)
    for free in (1, 6, 10):
        shapes = np.repeat(base[None], 4, axis=0)
        shapes[:, :free] += rng.normal(size=(4, free)) * sig[:free]
        model._D_cache = None
        full = np.array(model._shape_gradients(shapes))
        model._D_cache = None
        split = np.array(model._shape_gradients(shapes, free))
        assert np.abs(full).max() > 0.5
        np.testing.assert_allclose(split, full, rtol=0, atol=2e-6)
        for b in range(4):  # one body at a time, as Nelder–Mead asks
            got = model.vertices_batch(shapes[b:b + 1], poses[b:b + 1], free_shape=free)
            want = model.vertices_batch(shapes[b:b + 1], poses[b:b + 1])
            np.testing.assert_allclose(got, want, rtol=0, atol=2e-6)
    # fixed tails that differ across the batch: the full product is used
    shapes = rng.normal(size=(3, model.n_shape)) * sig
    model._D_cache = None
    mixed = np.array(model._shape_gradients(shapes, 5))
    model._D_cache = None
    np.testing.assert_array_equal(mixed, np.array(model._shape_gradients(shapes)))


@pytest.mark.parametrize("n_bodies", [1, 16])
def test_planar_posed_edges_equal_the_per_face_kernel_bit_for_bit(n_bodies):
    """The model's kernel (maps faces last, part by part, regressors per joint pair) with the
    full map gives the per-face kernel's float32 edges exactly, with one shared or one D per body."""
    from studio.body import posed
    from studio.body.kinematics import chain_rotations

    model = BodyModel.load("female")
    rng = np.random.default_rng(n_bodies)
    shapes = rng.normal(size=(n_bodies, model.n_shape)) * np.sqrt(model.eigenvalues)
    poses = model.clip_pose(rng.normal(size=(n_bodies, POSE_SIZE)) * 0.5)
    G, rv = chain_rotations(poses, model.hinge_axes)
    rv, G = model._joint_features(G, rv), G.astype(np.float32)
    x = posed.slot_regressors(rv, model._slots)
    for D in (model._shape_gradients(shapes), model._shape_gradients(shapes[:1])):
        want = posed.posed_edges(rv, model._Qc, model.joint_pairs, D, G, model.face_parts)
        got = posed.posed_edges_planar(x, posed.planar_q(model._Qc), model._slot, D, G, model._part_start)
        assert np.abs(want).max() > 0.01
        np.testing.assert_array_equal(got, want)


def test_pose_deformation_of_either_width_loads_and_another_is_rejected():
    """Q_coef on rotation vectors (F, 7, 9) or on rotation entries minus I (F, 19, 9, the shipped
    model's); any other width is refused by name. A constant-only map of either width is the
    rigid model."""
    from studio.body.model import BodyModelError

    pose = cube_model().default_pose()
    pose[6:9] = [0.4, 0.1, 0.0]
    rigid = cube_model().vertices(np.array([0.2]), pose)
    for width in (7, 19):
        Q = np.zeros((12, width, 9))
        Q[:, -1] = np.eye(3).ravel()
        np.testing.assert_allclose(cube_model(Q_coef=Q).vertices(np.array([0.2]), pose), rigid, atol=1e-9)
    with pytest.raises(BodyModelError, match="Q_coef must be"):
        cube_model(Q_coef=np.zeros((12, 11, 9)))
    assert BodyModel.load("female").Q_coef.shape[1:] == (19, 9)


def test_wide_training_poses_reach_what_a_lab_records():
    """The build's wide poses stay inside the joint limits, cap ball joints at 2.6 rad, and reach
    a seated hip (flexion beyond 1.2 rad) and arms overhead (abduction beyond 1.5 rad), which the
    near-rest poses never do."""
    from studio.body.build import sample_poses, sample_wide_poses

    lim = BodyModel.load("female").pose_limits
    wide = sample_wide_poses(400, lim, np.random.default_rng(0))
    near = sample_poses(400, lim, np.random.default_rng(0))
    assert np.all(wide >= lim[:, 0]) and np.all(wide <= lim[:, 1]) and np.all(wide[:, :6] == 0)
    from studio.body.skeleton import pose_slices

    hip, shoulder = (pose_slices()[PART_NAMES.index(n)] for n in ("upperleg_l", "upperarm_l"))
    assert np.linalg.norm(wide[:, hip], axis=1).max() <= 2.6 + 1e-12
    assert np.mean(wide[:, hip.start] < -1.2) > 0.15 and np.all(near[:, hip.start] > -1.2)
    assert np.mean(wide[:, shoulder.start + 1] < -1.5) > 0.1 and np.all(near[:, shoulder.start + 1] > -1.5)


def test_face_parts_out_of_range_are_rejected():
    assert cube_model(face_parts=np.full(12, 14))._part_start[-2:].tolist() == [0, 12]
    with pytest.raises(BodyModelError, match=r"face_parts must lie in 0\.\.14"):
        cube_model(face_parts=np.full(12, 15))
    with pytest.raises(BodyModelError, match=r"face_parts must lie in 0\.\.14"):
        cube_model(face_parts=np.full(12, -1))


def test_the_reduced_pose_deformation_keeps_the_full_one_within_a_few_per_cent():
    """The kernel's map reduced to Q_RANK regressors per joint pair (posed.low_rank_q): at
    poses across every joint's range the posed edges' deformation (what Q adds to the rigid
    model's edges) differs from the full map's by 8 % of itself at rank 8 (measured 7.5 %), 0
    when the rank keeps all 18; at the rest pose (features ~0) the edges are the full map's."""
    from studio.body import posed, skeleton
    from studio.body.model import Q_RANK

    model = BodyModel.load("female")
    assert model._Q_reduce is not None and model._Qp.shape[0] == Q_RANK + 1
    rng = np.random.default_rng(3)
    P = np.concatenate([skeleton.sample_poses(40, model.pose_limits, rng),
                        skeleton.sample_wide_poses(40, model.pose_limits, rng)])
    S = rng.normal(size=(len(P), model.n_shape)) * np.sqrt(model.eigenvalues)
    G = model.part_rotations(P)
    feats, D, Gf = model._joint_features(G), model._shape_gradients(S), G.astype(np.float32)
    full = posed.posed_edges_planar(posed.slot_regressors(feats, model._slots), posed.planar_q(model._Qc),
                                    model._slot, D, Gf, model._part_start)
    rigid = model._posed_edges(S, P, use_q=False, reference=True)
    reduced = model._posed_edges(S, P, reference=True)
    err = np.linalg.norm(reduced - full) / np.linalg.norm(full - rigid)
    assert 0.03 < err < 0.08
    sample = skeleton.joint_features(model.part_rotations(skeleton.sample_wide_poses(100, model.pose_limits, rng)))
    Cp, A = posed.low_rank_q(model._Qc, model._slots, model._slot, sample, 18)
    every = posed.posed_edges_planar(posed.slot_regressors(feats, model._slots, A), Cp, model._slot, D, Gf,
                                     model._part_start)
    np.testing.assert_allclose(every, full, rtol=0, atol=2e-5 * np.abs(full).max())
    rest = model.default_pose()[None]  # features ~0: only the exact constant row is left
    G0 = model.part_rotations(rest)
    at_rest = posed.posed_edges_planar(posed.slot_regressors(model._joint_features(G0), model._slots),
                                       posed.planar_q(model._Qc), model._slot, D[:1], G0.astype(np.float32), model._part_start)
    np.testing.assert_allclose(model._posed_edges(S[:1], rest, reference=True), at_rest, rtol=0, atol=1e-7)


def test_the_search_body_is_the_model_with_its_near_rest_pose_deformation():
    """BodyModel.search_model: the model with ``Q_search`` (eq. 3.16 on rotation vectors, (F, 7,
    9)), made once; the same rest body (both regressions keep Q = I there), a different seated
    one (the deformations differ most in deep postures); a model without ``Q_search`` searches
    with itself."""
    from studio.fit.library import family_pose

    model = BodyModel.load("female")
    search = model.search_model()
    assert search is model.search_model() and search.search_model() is search
    assert search.Q_coef.shape[1:] == (7, 9) and search.Q_search is None and search.gender == "female"
    shape = 0.7 * np.sqrt(model.eigenvalues)
    rest = model.default_pose()
    np.testing.assert_allclose(search.vertices(shape, rest), model.vertices(shape, rest), atol=1e-6)
    seated = family_pose(model, "seated")
    gap = np.linalg.norm(search.vertices(shape, seated) - model.vertices(shape, seated), axis=1)
    assert gap.max() > 0.03, gap.max()  # 61 mm
    lone = cube_model()
    assert lone.search_model() is lone
