"""The cylinder-model search objective (thesis §4.8.1) and its batched cone meshes."""

import numpy as np
import pytest

from calibration import Camera
from studio.body import BodyModel
from studio.cost import SilhouetteTarget
from studio.fit import FitError, FitOptions
from studio.body.cylinder import cone_faces, cone_meshes
from studio.fit.objective import CylinderObjective, FrameObjective
from studio.render import silhouette


def _cams():
    out = []
    for k, ang in enumerate(np.radians([0.0, 90.0, 200.0])):
        c, s = np.cos(ang), np.sin(ang)
        R = np.array([[-s, c, 0.0], [0.0, 0.0, -1.0], [-c, -s, 0.0]])
        C = np.array([3.0 * c, 3.0 * s, 0.9])
        K = np.array([[70.0, 0, 39.5], [0, 70.0, 59.5], [0, 0, 1]])
        out.append(Camera(name=f"c{k}", K=K, dist=np.zeros(5), R=R, t=-R @ C, size=(80, 120)))
    return out


@pytest.fixture(scope="module")
def setup():
    model = BodyModel.load("female")
    rng = np.random.default_rng(2)
    pose = model.default_pose().astype(float)
    pose[6:] += rng.normal(0, 0.2, pose[6:].shape)
    pose = model.clip_pose(pose)
    shape = model.mean_shape().copy()
    shape[:3] = [0.8, -0.5, 0.3]
    cams = _cams()
    V = model.vertices(shape, pose)
    masks = [silhouette(c, V, model.faces) for c in cams]
    targets = {lvl: SilhouetteTarget.build(masks, level=lvl, names=[c.name for c in cams], tau=8.0)
               for lvl in (0, 1)}
    return model, shape, pose, cams, targets


def test_batched_cones_equal_cylinder_model_mesh(setup):
    model, shape, pose, cams, targets = setup
    obj = CylinderObjective(model, cams, targets, shape)
    poses = np.stack([pose, model.default_pose()])
    V = obj.meshes(poses)
    for k, p in enumerate(poses):
        Vr, Fr = obj.cylinder.mesh(p)
        assert np.abs(V[k] - Vr).max() < 1e-12
        assert np.array_equal(Fr, obj.faces)
    ends, radii = obj.cylinder.segments_batch(poses)
    assert np.abs(cone_meshes(ends, radii) - V).max() < 1e-12
    assert cone_faces(6, 2).shape == (48, 3)


def test_cylinder_cost_prefers_the_true_pose(setup):
    model, shape, pose, cams, targets = setup
    cyl = CylinderObjective(model, cams, targets, shape)
    scape = FrameObjective(model, cams, targets, shape)
    wrong = pose.copy()
    wrong[5] += 0.6  # turned by 34°
    wrong[0] += 0.08
    for obj in (cyl, scape):
        c_true, c_wrong = obj(np.stack([pose, wrong]), 1)
        assert c_true < 0.8 * c_wrong
    # the cones stand in for the body: a few pixels of cost, not zero
    assert 0.0 < cyl(pose[None], 0)[0] < 6.0
    assert scape(pose[None], 0)[0] < 0.05 + scape.priors(pose[None])[0].sum() + scape.priors(pose[None])[1].sum()


def test_bad_options_are_named(setup):
    model, shape, pose, cams, targets = setup
    with pytest.raises(FitError, match="search_model"):
        FitOptions(search_model="cones")
    with pytest.raises(ValueError, match="n_shape_free"):
        CylinderObjective(model, cams, targets, shape, 3)
