"""The posture-library start (studio.fit.library): deterministic, within the joint limits, and
finding posture, heading and stature of bodies it was not built from."""

import numpy as np
import pytest

from studio.body import BodyModel
from studio.fit import FitError, FitOptions
from studio.fit.library import FAMILIES, _mirror, family_pose, library_match, pose_library, stand_on_floor
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
