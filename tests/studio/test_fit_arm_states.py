"""Issue 13: the library's arm states in the per-limb search; the (optional) shortlist of distinct families."""

import numpy as np
import pytest

from studio.body import BodyModel
from studio.fit.library import _diverse, family_pose, library_match, stand_on_floor
from studio.fit.search import _arm_states, _partitioned_search, _partitions
from studio.render import silhouette

from test_fit_frame import ring_cameras


@pytest.fixture(scope="module")
def model():
    return BodyModel.load("female")


def test_diverse_caps_families_and_skips_mirror_twins():
    fams = ["a", "a", "a", "a", "b", "b", "c", "a"]
    scores = [1.0, 1.0, 1.1, 1.2, 1.3, 1.3, 1.4, 1.5]
    np.testing.assert_array_equal(_diverse(fams, scores, 12, 2), [0, 2, 4, 6])
    np.testing.assert_array_equal(_diverse(fams, scores, 2, 3), [0, 2])
    np.testing.assert_array_equal(_diverse(fams, scores, 12, 9), [0, 2, 3, 4, 6, 7])


def test_shortlist_of_a_symmetric_body_holds_no_twins(model):
    """Arms down (a symmetric posture): the plain shortlist spends pairs on the posture and its
    identical mirror image; the diverse one has 12 distinct candidates, ≤ 3 per family."""
    cams = ring_cameras()
    shape = model.mean_shape()
    pose = family_pose(model, "arms_down")
    pose[:2] = [0.1, 0.0]
    pose = stand_on_floor(model, shape, pose[None])[0]
    masks = [silhouette(c, model.vertices(shape, pose), model.faces) for c in cams]
    from studio.fit.init import hull_centroid

    xy = hull_centroid(cams, masks)
    plain = library_match(model, cams, masks, xy)  # the default
    diverse = library_match(model, cams, masks, xy, per_family=3)
    pairs = lambda m: len(set(zip(m["families"], np.round(m["scores"], 12))))  # noqa: E731
    assert pairs(plain) <= 8  # measured 6: every candidate twice
    assert pairs(diverse) == 12 and len(diverse["families"]) == 12
    assert max(diverse["families"].count(f) for f in set(diverse["families"])) <= 3
    assert len(set(diverse["families"])) >= 5
    assert diverse["families"][0] == plain["families"][0]
    assert diverse["scores"][0] == plain["scores"][0]


def test_arm_states_hold_the_library_arms(model):
    limbs = _partitions()[1:]
    states = _arm_states(model, limbs)
    assert sorted(states) == [0, 1]  # the two arms, not the legs
    assert states[0].shape == states[1].shape == (17, 5)
    left, right = (np.round(states[g][:, :4], 2).tolist() for g in (0, 1))
    assert [-1.45, 0.5, 0.0, -0.5] in left  # arm_forward's left arm
    assert [-1.45, -0.5, 0.0, -0.5] in right  # and its mirror image
    assert [-0.35, 0.7, 0.4, 1.5] in left and [-0.35, -0.7, -0.4, 1.5] in right  # arms crossed


def test_extra_starts_leave_a_local_minimum():
    """A group whose answer sits in a shallow basin: jitter around it keeps the basin (cost
    0.5); a start from another state finds the deeper one (cost ~0)."""
    a, b = np.array([0.0, 0.0]), np.array([2.0, -1.0])

    def cost(X):
        return np.minimum(np.sum((X - a) ** 2, 1) + 0.5, np.sum((X - b) ** 2, 1))

    lo, hi, sigma = np.full(2, -3.0), np.full(2, 3.0), np.full(2, 0.05)
    kw = dict(n_particles=32, n_layers=4)
    x0, c0 = _partitioned_search(cost, a, sigma, lo, hi, [[0, 1]], rng=np.random.default_rng(0), **kw)
    x1, c1 = _partitioned_search(cost, a, sigma, lo, hi, [[0, 1]], rng=np.random.default_rng(0),
                                 extra={0: np.array([[1.9, -1.1], [-2.0, 2.0]])}, **kw)
    assert c0 >= 0.5 and np.linalg.norm(x0 - a) < 0.2
    # the search around the answer is the one without the extra states (same draws first)
    x2, c2 = _partitioned_search(cost, a + 0.01, sigma, lo, hi, [[0, 1]], rng=np.random.default_rng(0), **kw)
    x3, c3 = _partitioned_search(cost, a + 0.01, sigma, lo, hi, [[0, 1]], rng=np.random.default_rng(0),
                                 extra={0: np.array([[-2.5, 2.5]])}, **kw)
    np.testing.assert_array_equal(x2, x3)
    assert c1 < 0.05 and np.linalg.norm(x1 - b) < 0.2
