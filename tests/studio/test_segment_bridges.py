"""Shadow that splits a person mask, put back by the other views (studio.segment.bridges).

The scene is exact: a vertical cylinder (a leg, 0.1 m radius, 1.7 m tall) standing on the floor
z = 0 behind which a floor shadow lies (a 0.6 × 0.8 m rectangle), seen by four cameras on a ring;
labels are traced per pixel (the cylinder hit first, else the floor inside the rectangle).
"""

import numpy as np
import pytest

from calibration import Camera
from calibration.ground import GroundPlane
from studio.segment.bridges import bridge_regions, shadow_bridges
from studio.segment.classify import BACKGROUND, PERSON, SHADOW

SIZE = (160, 120)
RADIUS, HEIGHT = 0.10, 1.7


def _cameras():
    cams = {}
    for k, az in enumerate(np.radians([20.0, 110.0, 200.0, 290.0])):
        centre = [3.0 * np.cos(az), 3.0 * np.sin(az), 1.6]
        cams[f"cam{k}"] = Camera.look_at(f"cam{k}", centre, [0.0, 0.0, 0.8], 140.0, SIZE)
    return cams


def _trace(cam):
    """(labels, height of the cylinder point seen per pixel, NaN elsewhere)."""
    w, h = SIZE
    u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    o, d = cam.pixel_rays(np.stack([u.ravel(), v.ravel()], axis=1))
    # cylinder x² + y² = r², 0 ≤ z ≤ H: the nearer root
    a = d[:, 0] ** 2 + d[:, 1] ** 2
    b = 2 * (o[:, 0] * d[:, 0] + o[:, 1] * d[:, 1])
    c = o[:, 0] ** 2 + o[:, 1] ** 2 - RADIUS**2
    disc = b * b - 4 * a * c
    with np.errstate(invalid="ignore"):
        t = (-b - np.sqrt(disc)) / (2 * a)
    z = o[:, 2] + t * d[:, 2]
    body = (disc > 0) & (t > 0) & (z >= 0) & (z <= HEIGHT)
    tf = -o[:, 2] / d[:, 2]
    fx, fy = o[:, 0] + tf * d[:, 0], o[:, 1] + tf * d[:, 1]
    shadow = ~body & (tf > 0) & (fx > 0.05) & (fx < 0.65) & (np.abs(fy) < 0.4)
    labels = np.where(body, PERSON, np.where(shadow, SHADOW, BACKGROUND)).astype(np.uint8).reshape(h, w)
    return labels, np.where(body, z, np.nan).reshape(h, w)


@pytest.fixture(scope="module")
def scene():
    cams = _cameras()
    traced = {n: _trace(c) for n, c in cams.items()}
    return cams, {n: t[0] for n, t in traced.items()}, {n: t[1] for n, t in traced.items()}


def test_legs_labelled_shadow_are_put_back_and_the_floor_shadow_stays(scene):
    cams, truth, heights = scene
    labels = dict(truth)
    # one view labels the leg between 0.1 and 0.6 m shadow (grey trousers in front of the shadow):
    # its person mask falls apart into the foot and the rest
    wrong = (heights["cam0"] > 0.1) & (heights["cam0"] < 0.6)
    labels["cam0"] = truth["cam0"].copy()
    labels["cam0"][wrong] = SHADOW
    assert bridge_regions(labels["cam0"], min_area=5).any() and not bridge_regions(truth["cam0"], min_area=5).any()
    new, changed = shadow_bridges(labels, cams, plane=GroundPlane.floor(), min_area=5)
    put_back = np.count_nonzero(wrong & (new["cam0"] == PERSON)) / np.count_nonzero(wrong)
    floor_shadow = truth["cam0"] == SHADOW
    taken = np.count_nonzero(floor_shadow & (new["cam0"] == PERSON)) / np.count_nonzero(floor_shadow)
    assert put_back > 0.9, put_back
    assert taken < 0.1, taken
    assert changed["cam0"] == np.count_nonzero(new["cam0"] != labels["cam0"]) > 0
    assert all(changed[n] == 0 and np.array_equal(new[n], labels[n]) for n in ("cam1", "cam2", "cam3"))
    assert np.array_equal(labels["cam0"][wrong], np.full(np.count_nonzero(wrong), SHADOW))  # inputs untouched


def test_nothing_changes_when_the_person_is_in_one_piece_or_no_other_view_sees_a_solid(scene):
    cams, truth, heights = scene
    new, changed = shadow_bridges(truth, cams, plane=GroundPlane.floor(), min_area=5)
    assert sum(changed.values()) == 0 and all(np.array_equal(new[n], truth[n]) for n in truth)
    # the other views see no person there (the leg gone from them): the split view stays as it is
    labels = {n: np.where(t == PERSON, BACKGROUND, t).astype(np.uint8) for n, t in truth.items()}
    wrong = (heights["cam0"] > 0.1) & (heights["cam0"] < 0.6)
    labels["cam0"] = truth["cam0"].copy()
    labels["cam0"][wrong] = SHADOW
    new, changed = shadow_bridges(labels, cams, plane=GroundPlane.floor(), min_area=5)
    assert changed["cam0"] == 0
