"""The posture-library start (studio.fit.library): deterministic, within the joint limits, and
finding posture, heading and stature of bodies it was not built from."""

import numpy as np
import pytest

from studio.body import BodyModel
from studio.fit import FitError, FitOptions
from studio.fit.library import FAMILIES, _mirror, family_pose, frontal_twin, library_match, pose_library, stand_on_floor
from studio.render import silhouette

from test_fit_frame import ring_cameras


@pytest.fixture(scope="module")
def model():
    return BodyModel.load("female")


def test_library_is_deterministic_within_limits_and_mirrored(model):
    poses, names = pose_library(model)
    again, _ = pose_library(model)
    np.testing.assert_array_equal(poses, again)
    assert set(names) == set(FAMILIES) and len(poses) == 2 * 6 * len(FAMILIES)
    lo, hi = model.pose_limits[:, 0], model.pose_limits[:, 1]
    assert np.all(poses >= lo - 1e-12) and np.all(poses <= hi + 1e-12)
    p = family_pose(model, "arm_forward")
    np.testing.assert_allclose(_mirror(_mirror(p)), p)
    # the mirror image of the left arm forward is the right arm forward, seen in the mesh
    V, Vm = (model.vertices(model.mean_shape(), q) for q in (p, _mirror(p)))
    Vm_flipped = Vm.copy()
    Vm_flipped[:, 0] *= -1
    assert V[:, 1].min() < -0.45  # the hand reaches forward (-y)
    assert abs(V[:, 1].min() - Vm[:, 1].min()) < 0.03
    assert np.sign(V[np.argmin(V[:, 1]), 0]) == -np.sign(Vm[np.argmin(Vm[:, 1]), 0])
    with pytest.raises(ValueError, match="unknown posture family"):
        family_pose(model, "cartwheel")
    with pytest.raises(FitError, match="start"):
        FitOptions(start="magic")


@pytest.mark.parametrize("family,yaw,scale_shape", [("arms_overhead", 2.3, 1.5), ("half_squat", -0.7, -1.0),
                                                      ("lunge", 1.1, 0.0)])
def test_match_finds_posture_heading_and_stature(model, family, yaw, scale_shape):
    """A jittered, turned body: the library's best match is its family, facing within 30° (or
    its front/back rival: a lunge seen from behind with the other leg forward fills the same
    silhouettes; the fit searches both), its stature within 7 % (the start of the shape
    search) — the hull's top would be 25 cm off for arms overhead, 50 cm for a squat."""
    rng = np.random.default_rng(7)
    cams = ring_cameras()
    shape = model.mean_shape()
    shape[0] = scale_shape * np.sqrt(model.eigenvalues[0])
    pose = family_pose(model, family)
    pose[6:] += rng.normal(0.0, 0.08, pose.size - 6)
    pose = model.clip_pose(pose)
    pose[:2], pose[5] = [0.2, -0.1], yaw
    pose = stand_on_floor(model, shape, pose[None])[0]
    V = model.vertices(shape, pose)
    assert abs(V[:, 2].min()) < 1e-9
    masks = [silhouette(c, V, model.faces) for c in cams]
    from studio.fit.init import hull_centroid

    m = library_match(model, cams, masks, hull_centroid(cams, masks))
    assert m["families"][0] == family
    best = m["poses"][0]
    from calibration.rotation import rotvec_to_matrix

    heading = lambda p: np.arctan2(*(rotvec_to_matrix(p[3:6]) @ [0.0, -1.0, 0.0])[[1, 0]])  # noqa: E731
    d = np.angle(np.exp(1j * (heading(best) - heading(pose))))
    assert min(abs(d), np.pi - abs(d)) < np.radians(30)
    upright = model.vertices(shape)
    assert m["stature"] == pytest.approx(np.ptp(upright[:, 2]), rel=0.07)


def _scores_reference(points, cameras, masks, yaws, xy, factor):
    """library_scores written plainly: project every candidate's points, count the points in
    the pooled silhouette and the distinct silhouette cells they reach (sets, not stamps)."""
    out = np.zeros((len(points), len(yaws)))
    for k, (cam, mask) in enumerate(zip(cameras, masks)):
        h, w = mask.shape
        hc, wc = -(-h // factor), -(-w // factor)
        coarse = np.zeros((hc, wc), bool)
        ys, xs = np.nonzero(mask)
        coarse[ys // factor, xs // factor] = True
        K = cam.K.copy()
        K[:2] /= factor
        for p in range(len(points)):
            for j, yaw in enumerate(yaws):
                c, s = np.cos(yaw), np.sin(yaw)
                P = points[p] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]).T + [xy[0], xy[1], 0]
                X = P @ cam.R.T + cam.t.ravel()
                u = np.floor((K[0, 0] * X[:, 0] + K[0, 1] * X[:, 1]) / X[:, 2] + K[0, 2]).astype(int)
                v = np.floor(K[1, 1] * X[:, 1] / X[:, 2] + K[1, 2]).astype(int)
                ok = (X[:, 2] > 0) & (u >= 0) & (u < wc) & (v >= 0) & (v < hc)
                hit = [(a, b) for a, b, o in zip(v, u, ok) if o and coarse[a, b]]
                out[p, j] += 1 - len(hit) / len(X) + 1 - len(set(hit)) / max(coarse.sum(), 1)
    return out


def test_scores_equal_a_plain_reference(model):
    """The compiled descriptor scores equal a plain per-candidate computation, including
    points far outside the images."""
    from studio.fit.library import library_scores

    rng = np.random.default_rng(3)
    cams = ring_cameras()[:3]
    V = model.vertices(model.mean_shape())
    masks = [silhouette(c, V, model.faces) for c in cams]
    pts = V[rng.choice(len(V), 60)][None] * [[[1.0, 1.0, 1.0]], [[1.3, 0.7, 1.1]]]
    pts[1, :5] += [0.0, 0.0, 8.0]  # far above every view
    yaws = np.array([0.0, 1.0, -2.5])
    got = library_scores(pts, cams, masks, yaws, (0.05, -0.1), factor=8)
    np.testing.assert_allclose(got, _scores_reference(pts, cams, masks, yaws, (0.05, -0.1), 8), rtol=0, atol=1e-12)
    assert got[0, 0] < got[1, 0]  # the body itself matches better than a distorted copy


def _shadow_scores_reference(points, cameras, masks, shadow_masks, lights, weight, yaws, xy, factor):
    """The shadow camera's views of library_scores written plainly: every point's shadow by the
    renderer's eq. 5.2 (studio.render.shadow.shadow_vertices), projected by K[R|t] into the
    pooled masks; inside = shadow or person, reached = shadow cells; weight / cameras each."""
    from studio.render.shadow import shadow_vertices

    out = np.zeros((len(points), len(yaws)))
    for cam, mask, smask in zip(cameras, masks, shadow_masks):
        h, w = mask.shape
        hc, wc = -(-h // factor), -(-w // factor)
        pooled = {}
        for key, m in (("in", mask | smask), ("want", smask)):
            pooled[key] = np.zeros((hc, wc), bool)
            ys, xs = np.nonzero(m)
            pooled[key][ys // factor, xs // factor] = True
        K = cam.K.copy()
        K[:2] /= factor
        for light in lights:
            for p in range(len(points)):
                for j, yaw in enumerate(yaws):
                    c, s = np.cos(yaw), np.sin(yaw)
                    P = points[p] @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]).T + [xy[0], xy[1], 0]
                    S, valid = shadow_vertices(P, light)
                    X = S @ cam.R.T + cam.t.ravel()
                    u = np.floor((K[0, 0] * X[:, 0] + K[0, 1] * X[:, 1]) / X[:, 2] + K[0, 2]).astype(int)
                    v = np.floor(K[1, 1] * X[:, 1] / X[:, 2] + K[1, 2]).astype(int)
                    ok = valid & (X[:, 2] > 0) & (u >= 0) & (u < wc) & (v >= 0) & (v < hc)
                    hit = [(a, b) for a, b, o in zip(v, u, ok) if o and pooled["in"][a, b]]
                    reached = {(a, b) for a, b in hit if pooled["want"][a, b]}
                    out[p, j] += weight / len(cameras) * (
                        1 - len(hit) / len(X) + 1 - len(reached) / max(pooled["want"].sum(), 1))
    return out


def test_shadow_views_equal_a_plain_reference(model):
    """With the shadow camera (§5.5), the descriptor adds one view per camera and light: the
    compiled scores equal the plain camera views plus the plain shadow views, a point and a
    directional light alike, points above the point light counting as outside."""
    import lightkit
    from studio.fit.library import library_scores
    from studio.render import DirectionalLight, PointLight

    rng = np.random.default_rng(5)
    cams = ring_cameras()[:2]
    V = model.vertices(model.mean_shape())
    lights = [PointLight([1.2, -0.8, 2.2]), DirectionalLight([0.4, 0.3, -1.0])]
    labels = [lightkit.labels([c], (V, model.faces), lights)[0] for c in cams]
    masks, shadows = [lab == 1 for lab in labels], [lab == 2 for lab in labels]
    pts = V[rng.choice(len(V), 60)][None] * [[[1.0, 1.0, 1.0]], [[1.2, 0.8, 1.1]]]
    pts[1, :4, 2] += 3.0  # above the point light: no shadow
    yaws, xy = np.array([0.0, 0.8, -2.0]), (0.05, -0.1)
    got = library_scores(pts, cams, masks, yaws, xy, factor=8,
                         shadows={"lights": lights, "masks": shadows, "weight": 0.7})
    want = (_scores_reference(pts, cams, masks, yaws, xy, 8)
            + _shadow_scores_reference(pts, cams, masks, shadows, lights, 0.7, yaws, xy, 8))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    plain = library_scores(pts, cams, masks, yaws, xy, factor=8)
    assert np.all(got > plain)  # the shadow views add their own (non-zero) distances
    assert got[0, 0] < got[1, 0]
    with pytest.raises(ValueError, match="shining upwards"):
        library_scores(pts, cams, masks, yaws, xy, shadows={"lights": [DirectionalLight([0, 0, 1.0])],
                                                             "masks": shadows})


def _squat_180(model):
    """(cameras, shape, pose, masks) of a 1.80 m body in a half squat, turned and on the floor."""
    from studio.fit.init import stature_shape

    cams = ring_cameras()
    shape = stature_shape(model, 1.80)
    pose = family_pose(model, "half_squat")
    pose[:2], pose[5] = [0.1, 0.05], 0.6
    pose = stand_on_floor(model, shape, pose[None])[0]
    return cams, shape, pose, [silhouette(c, model.vertices(shape, pose), model.faces) for c in cams]


def test_stature_search_recovers_a_squat_stature(model):
    """A half squat of a 1.80 m body started 6 % short (one step of the library's scale grid):
    the stature search with the true posture lands within 1.5 % (one of its steps) — the cost
    of eq. 4.6 tells the stature apart once the posture is right."""
    from studio.fit import FitOptions
    from studio.fit.frame import build_targets
    from studio.fit.init import stature_search, stature_shape
    from studio.fit.objective import FrameObjective

    cams, shape, pose, masks = _squat_180(model)
    targets = build_targets(masks, [c.name for c in cams], FitOptions(levels=(1, 1, 1)))
    start = 1.80 * 0.94
    height, found = stature_search(model, lambda s: FrameObjective(model, cams, targets, s, 0), pose, start, 1)
    assert abs(height - 1.80) <= 0.016 * 1.80
    np.testing.assert_allclose(found, stature_shape(model, height))
    assert abs(start - 1.80) > 0.1  # the start itself was 10 cm off


def test_shortlist_candidates_are_scored_at_their_own_stature(model):
    """The library matches each candidate at its own scale (``statures``); a retry scores each
    on a body of that stature. A squat of a 1.80 m body scored on the body of a standing match
    at 0.88 of it costs far more than on its own (dev half squat: 22.4 against 12.6, so the
    squat never started the search)."""
    from studio.fit import FitOptions
    from studio.fit.frame import build_targets
    from studio.fit.init import costs_at_statures, hull_centroid
    from studio.fit.objective import FrameObjective

    cams, shape, pose, masks = _squat_180(model)
    m = library_match(model, cams, masks, hull_centroid(cams, masks))
    assert m["statures"][0] == m["stature"]
    ratio = np.asarray(m["statures"]) / np.asarray(m["scales"])
    np.testing.assert_allclose(ratio, ratio[0])  # one library body, scaled
    targets = build_targets(masks, [c.name for c in cams], FitOptions(levels=(1, 1, 1)))
    poses = np.stack([pose, pose])
    own, n = costs_at_statures(model, lambda s: FrameObjective(model, cams, targets, s, 0), poses,
                               np.array([1.80, 0.88 * 1.80]), 1)
    obj = FrameObjective(model, cams, targets, shape, 0)
    assert own[0] == pytest.approx(float(obj(obj.pack(shape, pose)[None], 1)[0]), rel=1e-9)
    assert own[0] < 0.25 * own[1] and n == 2


@pytest.mark.parametrize("family", ["a_pose", "walk", "arms_crossed"])
def test_frontal_twin_is_the_body_reflected_through_its_frontal_plane(model, family):
    """The front/back twin (turned, sides swapped) is the mirror image of the body through the
    vertical plane across its facing direction at its pelvis: the mean shape posed and tilted
    off the axes, every vertex within 7 mm of the reflected body (mean ≤ 2 mm: A-pose 0.1, walk
    1.5, arms crossed 1.1), the pelvis where it was, the twin's twin the pose itself."""
    from scipy.spatial import cKDTree

    from calibration.rotation import rotvec_to_matrix

    shape = np.zeros(len(model.eigenvalues))
    pose = family_pose(model, family).copy()
    pose[:2] = [0.3, -0.2]
    pose[3:6] = [0.05, -0.02, 1.0]
    twin = frontal_twin(model, shape, pose)
    V, Vt = model.vertices(shape, pose), model.vertices(shape, twin)
    pelvis = model.joints(shape, pose)[0]
    f = rotvec_to_matrix(pose[3:6]) @ [0.0, -1.0, 0.0]
    n = np.array([f[0], f[1], 0.0]) / np.hypot(f[0], f[1])
    d = cKDTree(Vt).query(V - 2 * ((V - pelvis) @ n)[:, None] * n)[0]
    assert d.mean() < 0.002 and d.max() < 0.007
    assert np.abs(V - Vt).max() > 0.1  # a different body, not the pose itself
    np.testing.assert_allclose(model.joints(shape, twin)[0], pelvis, atol=1e-5)
    np.testing.assert_allclose(frontal_twin(model, shape, twin), pose, atol=1e-9)


def test_arms_crossed_crosses_the_forearms_in_front_of_the_chest(model):
    """The library's arms crossed (issue 13): each hand past the body's midline, in front of the
    torso at chest height, the elbows out beside it. Until the fix the upper arms were turned
    out and the hands sat beside the shoulders, 0.55 m apart (left hand +274 mm): the family
    every arms-crossed frame started from was not arms crossed."""
    shape = np.zeros(len(model.eigenvalues))
    pose = family_pose(model, "arms_crossed").copy()
    pose[:6] = 0.0  # facing -y, the body's left at +x
    V, J = model.vertices(shape, pose), model.joints(shape, pose)
    hand_l, hand_r = (V[model.parts == model.part_names.index(p)].mean(axis=0) - J[0] for p in ("hand_l", "hand_r"))
    elbow_l = J[model.part_names.index("lowerarm_l")] - J[0]
    assert -0.12 < hand_l[0] < -0.02 and 0.02 < hand_r[0] < 0.12  # crossed: past the midline, not far
    assert hand_l[1] < -0.2 and hand_r[1] < -0.2  # in front of the torso
    assert 0.35 < hand_l[2] < 0.55 and 0.35 < hand_r[2] < 0.55  # chest height above the pelvis
    assert elbow_l[0] > 0.12  # the elbow out at the side
