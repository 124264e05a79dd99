"""A seat in the silhouettes (studio.fit.props): found under a seated body on a stool, not
under a squat or a standing body, and its ignored pixels are the stool's."""

import numpy as np
import pytest

from studio.body import BodyModel
from studio.fit.library import family_pose, stand_on_floor
from studio.body.skeleton import PART_NAMES
from studio.fit.props import MIN_THIGH_ANGLE, SEAT_PARTS, find_support, seat_of, thigh_angles
from studio.render import silhouette
from studio.simulate.props import STOOL_RADIUS, stool_mesh

from test_fit_frame import ring_cameras


@pytest.fixture(scope="module")
def model():
    return BodyModel.load("male")


def posed(model, family, yaw=0.7):
    pose = family_pose(model, family)
    pose[:2], pose[5] = [0.1, -0.05], yaw
    pose = stand_on_floor(model, model.mean_shape(), pose[None])[0]
    return pose, model.vertices(model.mean_shape(), pose)


def test_support_found_under_a_seated_body_and_only_the_stool_ignored(model):
    cams = ring_cameras()
    pose, V = posed(model, "seated")
    x, y, top = seat_of(V, model.parts, STOOL_RADIUS)  # where the simulator puts its stool
    assert seat_of(V, model.parts) == pytest.approx((x, y, top))  # one definition of the seat
    Vs, Fs = stool_mesh(x, y, top)
    body = [silhouette(c, V, model.faces) for c in cams]
    stool = [silhouette(c, Vs, Fs) for c in cams]
    support = find_support(model, cams, [b | s for b, s in zip(body, stool)], model.mean_shape(), pose)
    assert support is not None and support.seat == pytest.approx(top)
    import cv2

    rest = model.faces[~np.isin(model.face_parts, [PART_NAMES.index(p) for p in SEAT_PARTS])]
    for c, b, s, ign in zip(cams, body, stool, support.ignore):
        # every visible stool pixel, less a 2-pixel rim around the body, and nothing of the body
        # but what its seat parts (pelvis, thighs) cover: a stool hidden behind a calf is the calf's
        rim = cv2.dilate(b.view(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
        limbs = cv2.dilate(silhouette(c, V, rest).view(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
        assert not (s & ~rim & ~ign).any() and not (ign & limbs).any() and not (ign & ~(b | s)).any()
        assert (ign & b).any()  # the seat parts' pixels over the stool are left to the prop
    # a body fitted 4 cm low sits on the stool's seat: the seat's pixels it covers stay out of
    # the cost (before, only what the body left uncovered did, and the seat pulled the hips down)
    low = pose.copy()
    low[2] -= 0.04
    sunk = find_support(model, cams, [b | s for b, s in zip(body, stool)], model.mean_shape(), low)
    assert sunk is not None
    for s, ign in zip(stool, sunk.ignore):
        seat_rim = s & ~ign
        # 0.21–0.26 of the stool's pixels; with the whole body's silhouette left in (before) 0.33–0.49
        assert seat_rim.sum() < 0.3 * s.sum(), (seat_rim.sum(), s.sum())
    js = support.to_json([c.name for c in cams])
    assert js["seat_height_m"] == pytest.approx(top, abs=1e-4) and set(js["views"]) == {c.name for c in cams}


@pytest.mark.parametrize("family", ["half_squat", "a_pose"])
def test_no_support_without_a_prop(model, family):
    cams = ring_cameras()
    pose, V = posed(model, family)
    masks = [silhouette(c, V, model.faces) for c in cams]
    assert find_support(model, cams, masks, model.mean_shape(), pose) is None
    angles = thigh_angles(model, model.mean_shape(), pose)
    if family == "a_pose":  # standing: not a sitting posture at all
        assert max(angles) < MIN_THIGH_ANGLE
    else:  # a squat sits as low as a stool; nothing is observed under it
        assert min(angles) > MIN_THIGH_ANGLE


def test_a_seated_start_searches_with_the_stool_left_out(model, monkeypatch):
    """A library start that sits on a stool the silhouettes hold: the search itself leaves the
    pixels under its seat out (not only the Nelder–Mead stages after it), so the legs are not
    dragged onto the stool: the search's cost no longer counts the stool."""
    import studio.fit.frame as frame
    from studio.fit import FitOptions
    from studio.fit.evaluate import surface_distance

    cams = ring_cameras()
    pose, V = posed(model, "seated")
    Vs, Fs = stool_mesh(*seat_of(V, model.parts, STOOL_RADIUS))
    masks = [silhouette(c, V, model.faces) | silhouette(c, Vs, Fs) for c in cams]
    opts = FitOptions(levels=(2, 2, 2), n_particles=12, n_layers=2, nm_evaluations=10, final_evaluations=10,
                      n_shape_free=0, partition_particles=0, partition_layers=0, limb_particles=0,
                      rival_heading=False, retries=0)
    seen, real = [], frame.find_support

    def spy(model, cameras, masks, shape, pose, late_only=False):
        seen.append(min(thigh_angles(model, shape, pose)))
        return None if late_only and len(seen) == 1 else real(model, cameras, masks, shape, pose)

    monkeypatch.setattr(frame, "find_support", spy)
    fit = frame.fit_frame(model, cams, masks, shape=model.mean_shape(), options=opts, seed=2)
    assert fit.costs["start_family"] == "seated" and len(seen) == 2 and seen[0] > MIN_THIGH_ANGLE
    assert "support" in fit.quality
    seen.clear()
    monkeypatch.setattr(frame, "find_support", lambda *a: spy(*a, late_only=True))
    late = frame.fit_frame(model, cams, masks, shape=model.mean_shape(), options=opts, seed=2)
    assert late.costs["start_family"] == "seated" and "support" in late.quality
    # the stool searched as body costs the search; left out, the search's best costs far less
    assert fit.costs["search"] < 0.8 * late.costs["search"], (fit.costs["search"], late.costs["search"])
    for f in (fit, late):  # both end on the seated body (own model, stool left out at the end)
        assert surface_distance(model.vertices(f.shape, f.pose), model.faces, V, model.faces, n=8000) < 0.03
