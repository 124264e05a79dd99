"""benchmarks/body_model.py: the lab postures' error after the root's best rotation and translation."""

import sys
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from body_model import aligned_error, rigid_error  # noqa: E402

from studio.body import BodyModel  # noqa: E402


def test_rigid_error_absorbs_the_root_only():
    model = BodyModel.load("female")
    V = model.vertices(model.mean_shape())
    R = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    moved = V @ R.T + [0.3, -0.1, 0.05]
    np.testing.assert_allclose(rigid_error(moved[None], V[None]), [0.0], atol=1e-9)
    assert aligned_error(moved[None], V[None])[0] > 0.02  # translation alone cannot undo the turn
    bent = V.copy()
    bent[V[:, 2] > np.median(V[:, 2]), 0] += 0.01  # the upper half 10 mm aside: not rigid
    e = rigid_error(np.stack([moved, bent]), np.stack([V, V]))
    assert e[0] < 1e-9
    # a turn takes up part of the shift (translation alone leaves 5 mm), not all of it
    assert 0.002 < e[1] < aligned_error(bent[None], V[None])[0] - 0.001
