"""Registration of frames to the background (phase correlation) and the person-mask quality figures."""

import numpy as np
import pytest

from studio.segment import PERSON, SHADOW, BackgroundModel
from studio.segment.morphology import person_components
from studio.segment.registration import estimate_shift, shift_hsv, shift_image


def _room(h=120, w=160, seed=0):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w]
    img = np.stack([120 + 60 * np.sin(xx / 5) * np.cos(yy / 7), 110 + 50 * np.cos(xx / 9), 90 + 40 * np.sin(yy / 4)], -1)
    img[30:50, 40:70] = (230, 230, 240)  # a ceiling light: strong edges
    return np.clip(img + rng.normal(0, 1.5, img.shape), 0, 255).astype(np.uint8)


def test_estimate_shift_recovers_a_subpixel_translation():
    room = _room().astype(np.float32)
    for dx, dy in ((0.7, -1.2), (-2.2, 0.3)):  # near half pixels the peak centroid is biased (~0.3 px)
        moved = shift_image(room[..., 1], dx, dy)
        got = estimate_shift(room[..., 1], moved)
        assert got[0] == pytest.approx(dx, abs=0.1) and got[1] == pytest.approx(dy, abs=0.1) and got[2] > 0.3


def test_shifted_model_removes_the_edges_a_nudge_makes_foreground():
    frames = [_room(seed=s) for s in range(6)]
    model = BackgroundModel.fit(frames)
    nudged = [shift_image(f, 1.3, -0.8) for f in frames[:3]]
    before = np.mean([(model.classify(f) > 0).mean() for f in nudged])
    dx, dy = model.estimate_shift(nudged)
    assert dx == pytest.approx(1.3, abs=0.15) and dy == pytest.approx(-0.8, abs=0.15)
    after = np.mean([(model.shifted(dx, dy).classify(f) > 0).mean() for f in nudged])
    assert before > 0.02 and after < 0.002  # measured ~0.08 before, 0 after


def test_shift_hsv_interpolates_hue_around_the_circle():
    hsv = np.zeros((4, 8, 3), np.float32)
    hsv[:, :4, 0], hsv[:, 4:, 0] = 0.98, 0.02  # red either side of the wrap
    out = shift_hsv(hsv, 0.5, 0)
    assert min(out[0, 4, 0], 1 - out[0, 4, 0]) < 0.001  # halfway between 0.98 and 0.02 is 0, not 0.5


def test_person_components_figures_and_keep_largest():
    labels = np.zeros((50, 60), np.uint8)
    labels[5:35, 5:25] = PERSON  # 600 px
    labels[40:46, 40:50] = PERSON  # 60 px of clutter
    labels[30:45, 20:40][labels[30:45, 20:40] == 0] = SHADOW
    out, fig = person_components(labels)
    assert out is labels and fig == {"person_fraction": 0.22, "components": 2, "clutter": round(60 / 660, 6)}
    kept, _ = person_components(labels, keep_largest=True)
    assert (kept == PERSON).sum() == 600 and (kept[40:46, 40:50] == 0).all() and (kept == SHADOW).sum() > 0
    assert person_components(np.zeros((5, 5), np.uint8))[1] == {"person_fraction": 0.0, "components": 0, "clutter": 0.0}


def test_hull_filter_leaves_views_alone_when_the_views_share_no_hull():
    from studio.segment.hull import hull_filter
    from studio.segment.synthetic import ring_calibration

    calib = ring_calibration(3, (96, 72))
    cams = {n: calib[n] for n in calib.camera_names}
    labels = {n: np.zeros((72, 96), np.uint8) for n in cams}
    for k, n in enumerate(cams):  # a blob in a different corner of every view: no common 3-D point
        labels[n][2 + 30 * (k % 2) : 20 + 30 * (k % 2), 2 + 40 * k // 2 : 20 + 40 * k // 2] = PERSON
    out, dropped = hull_filter(labels, cams)
    assert dropped == {n: 0 for n in cams} and all((out[n] == labels[n]).all() for n in cams)
    one = {n: (labels[n] if k == 0 else np.zeros_like(labels[n])) for k, n in enumerate(cams)}
    assert hull_filter(one, cams)[1] == {n: 0 for n in cams}  # a single view with a person: nothing to check
