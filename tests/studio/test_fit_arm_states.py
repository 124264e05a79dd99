"""Issue 13: the library's arm states in the per-limb search."""

import numpy as np
import pytest

from studio.body import BodyModel
from studio.fit.search import _arm_states, _partitioned_search, _partitions


@pytest.fixture(scope="module")
def model():
    return BodyModel.load("female")


def test_arm_states_hold_the_library_arms(model):
    limbs = _partitions()[1:]
    states = _arm_states(model, limbs)
    assert sorted(states) == [0, 1]  # the two arms, not the legs
    assert states[0].shape == states[1].shape == (17, 5)
    left, right = (np.round(states[g][:, :4], 2).tolist() for g in (0, 1))
    assert [-1.45, 0.5, 0.0, -0.5] in left  # arm_forward's left arm
    assert [-1.45, -0.5, 0.0, -0.5] in right  # and its mirror image
    assert [-0.3, 0.3, -0.9, 1.1] in left and [-0.3, -0.3, 0.9, 1.1] in right  # arms crossed


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
