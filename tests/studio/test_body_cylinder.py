"""The coarse cylinder model (thesis §4.8.1)."""

import numpy as np
import pytest

from studio.body import PART_NAMES, BodyModel, BodyModelError, CylinderModel
from calibration.rotation import rotvec_to_matrix


@pytest.fixture(scope="module")
def cyl():
    model = BodyModel.load("female")
    return CylinderModel.from_shape(model, model.mean_shape())


def test_cones_are_sized_from_the_body(cyl):
    assert cyl.ends.shape == (15, 2, 3) and cyl.radii.shape == (15, 2)
    P = {n: i for i, n in enumerate(PART_NAMES)}
    lengths = np.linalg.norm(cyl.ends[:, 1] - cyl.ends[:, 0], axis=1)
    assert 0.3 < lengths[P["upperleg_l"]] < 0.55 and 0.2 < lengths[P["upperarm_l"]] < 0.4
    assert np.all(cyl.radii > 0.01) and np.all(cyl.radii < 0.25)
    assert cyl.radii[P["upperleg_l"], 0] > cyl.radii[P["lowerleg_l"], 1]  # thigh wider than ankle
    # symmetric body: left and right cones mirror each other
    assert np.allclose(cyl.ends[P["upperarm_l"]] * [-1, 1, 1], cyl.ends[P["upperarm_r"]], atol=5e-3)
    ends, radii = cyl.segments(cyl.model.default_pose())
    assert np.allclose(ends, cyl.ends, atol=1e-9)


def test_cones_follow_the_pose(cyl):
    pose = cyl.model.default_pose()
    pose[:3] = [1.0, 2.0, 0.0]
    pose[3:6] = [0, 0, 0.7]
    ends, _ = cyl.segments(pose)
    v = cyl.model.vertices(cyl.shape)
    c = v[cyl.model.parts == 0].mean(axis=0)  # the root rotates about the pelvis centroid
    R = rotvec_to_matrix(np.array([0, 0, 0.7]))
    assert np.allclose(ends, (cyl.ends - c) @ R.T + c + [1.0, 2.0, 0.0], atol=1e-6)
    # the joints stay connected: the upper leg's distal end is the lower leg's proximal end
    pose = cyl.model.default_pose()
    pose[6 + 3 + 1 + 5 + 5: 6 + 3 + 1 + 5 + 5 + 3] = [-0.8, 0.0, 0.0]  # left hip flexion
    ends, _ = cyl.segments(pose)
    P = {n: i for i, n in enumerate(PART_NAMES)}
    assert np.allclose(ends[P["upperleg_l"], 1], ends[P["lowerleg_l"], 0], atol=1e-9)
    assert ends[P["lowerleg_l"], 1, 1] < cyl.ends[P["lowerleg_l"], 1, 1] - 0.2  # foot moved forward (-y)
    v, f = cyl.mesh(pose)
    assert f.max() == len(v) - 1
    # geometry: each cone's rings lie on circles of its radii around its axis, caps on the ends
    sides = 12
    radii = cyl.radii
    for p in range(15):
        a, b = ends[p]
        u = (b - a) / np.linalg.norm(b - a)
        block = v[p * (2 * sides + 2):(p + 1) * (2 * sides + 2)]
        for ring, centre, r in ((block[:sides], a, radii[p, 0]), (block[sides:2 * sides], b, radii[p, 1])):
            d = ring - centre
            np.testing.assert_allclose(d @ u, 0.0, atol=1e-12)
            np.testing.assert_allclose(np.linalg.norm(d, axis=1), r, rtol=1e-12)
        np.testing.assert_allclose(block[-2:], [a, b], atol=1e-12)
    with pytest.raises(BodyModelError, match="pose must have shape"):
        cyl.segments(np.zeros(4))
