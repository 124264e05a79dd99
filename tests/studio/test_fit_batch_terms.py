"""The loose batch's extra terms (issue 15): knees held near the single fit, the head counted as skin."""

import numpy as np
import pytest

from studio.body.skeleton import POSE_SIZE, pose_slices
from studio.cost import ClothingTarget, clothing_cost
from studio.fit.batch import BatchOptions
from studio.fit.batch_terms import KNEE_INDICES, KNEE_SIGMA, STRAIGHT_CAP, head_band, knee_term, with_head_skin


def test_knee_indices_are_the_knee_hinges():
    sl = pose_slices()
    assert KNEE_INDICES == (sl[10].start, sl[13].start)  # lowerleg_l, lowerleg_r
    assert sl[10].stop - sl[10].start == 1 and sl[13].stop - sl[13].start == 1


def test_knee_term_numbers():
    ref = np.zeros(POSE_SIZE)
    poses = np.zeros((3, POSE_SIZE))
    poses[1, KNEE_INDICES[0]] = KNEE_SIGMA  # one knee one sigma off
    poses[2, list(KNEE_INDICES)] = 2 * KNEE_SIGMA  # both two sigma off
    poses[2, 0:23] = 1.0  # other coordinates are not the term's business
    np.testing.assert_allclose(knee_term(poses, ref, 0.05), [0.0, 0.05, 0.4])
    np.testing.assert_allclose(knee_term(poses[1], ref, 0.0), [0.0])
    ref[KNEE_INDICES[0]] = KNEE_SIGMA
    np.testing.assert_allclose(knee_term(poses[1], ref, 0.05), [0.0])


def test_straight_knee_term_is_capped_about_the_rest_pose():
    poses = np.zeros((4, POSE_SIZE))
    poses[1, KNEE_INDICES[1]] = -2 * KNEE_SIGMA  # one knee 20 degrees (either way)
    poses[2, KNEE_INDICES[0]] = 3 * KNEE_SIGMA  # at the cap
    poses[3, list(KNEE_INDICES)] = np.radians(100.0)  # a lunge: both knees cost the cap, no more
    np.testing.assert_allclose(knee_term(poses, None, 0.05, cap=STRAIGHT_CAP), [0.0, 0.2, 0.45, 0.9])
    np.testing.assert_allclose(knee_term(poses[3], None, 0.05)[0], 0.05 * 2 * (np.radians(100.0) / KNEE_SIGMA) ** 2)


def test_head_band_takes_the_top_rows_of_the_silhouette():
    m = np.zeros((40, 20), bool)
    m[10:30, 5:15] = True  # 20 rows tall
    m[12, 2] = True
    band = head_band(m, 0.1)  # 2 rows
    assert band.sum() == 2 * 10
    assert band[10:12, 5:15].all() and not band[12:].any()
    assert not head_band(m, 0.0).any() and not head_band(np.zeros((5, 5), bool), 0.5).any()
    assert head_band(m, 1.0).sum() == m.sum()


def test_head_skin_switches_the_head_to_full_expansion():
    """A body mask 4 rows short of the silhouette's top: under loose settings (τ_c 4, λ_c 0.01)
    the missing head costs ~nothing when it is clothing, the full τ-truncated distance as skin."""
    obs = np.zeros((60, 30), bool)
    obs[10:50, 10:20] = True
    model = obs.copy()
    model[10:14] = False
    assert with_head_skin([obs], None, 0.0) is None
    skin = with_head_skin([obs], None, 0.1)
    assert skin[0].sum() == 4 * 10
    plain = ClothingTarget.build([obs], None, tau=20.0, tau_cloth=4.0, cloth_weight=0.01)
    head = ClothingTarget.build([obs], skin, tau=20.0, tau_cloth=4.0, cloth_weight=0.01)
    c_plain, c_head = clothing_cost(plain, [model]).total, clothing_cost(head, [model]).total
    assert c_plain == pytest.approx(0.0025) and c_head == pytest.approx(0.25)  # λ_c = 0.01 → 1
    assert clothing_cost(head, [obs]).total == pytest.approx(0.0, abs=1e-12)


def test_options_default_off():
    o = BatchOptions()
    assert o.knee_weight == 0.0 and o.head_skin == 0.0 and o.straight_knees == 0.0
    assert o.to_dict()["knee_weight"] == 0.0


def test_stature_direction_predicts_the_statures_of_prior_bodies():
    from studio.body import BodyModel, measure
    from studio.fit.batch_terms import stature_direction

    model = BodyModel.load("female")
    g = stature_direction(model, 10)
    assert g.shape == (10,)
    sigma = np.sqrt(model.eigenvalues)
    base = measure(model, np.zeros(model.n_shape))["stature"]
    rng = np.random.default_rng(7)  # bodies not among the stored samples
    z = rng.standard_normal((6, 10))
    shapes = np.zeros((6, model.n_shape))
    shapes[:, :10] = z * sigma[:10]
    true = np.array([measure(model, s)["stature"] for s in shapes]) - base
    pred = z @ g
    assert np.std(true) > 0.02  # the statures spread by centimetres
    assert np.sqrt(np.mean((pred - true) ** 2)) < 0.25 * np.std(true)


def test_build_prior_is_free_along_the_stature_and_mahalanobis_across_it():
    from studio.fit.batch_terms import build_prior

    sigma = np.array([2.0, 1.0, 0.5])
    g = np.array([3.0, 4.0, 0.0])
    assert build_prior(g * 0.5 * sigma, sigma, g) == pytest.approx(0.0, abs=1e-12)
    across = np.array([4.0, -3.0, 0.0]) / 5 * sigma  # unit z orthogonal to g
    assert build_prior(across, sigma, g) == pytest.approx(1.0)
    assert build_prior(np.array([0.0, 0.0, 1.0]), sigma, g) == pytest.approx(4.0)  # z = 2 off the stature
    both = np.stack([across, 2 * across, np.zeros(3)])
    np.testing.assert_allclose(build_prior(both, sigma, g), [1.0, 4.0, 0.0])
    # only the first len(g) coefficients count
    assert build_prior(np.r_[across, 5.0], np.r_[sigma, 1.0], g) == pytest.approx(1.0)


def test_shrink_build_keeps_the_stature_and_scales_the_build():
    from studio.fit.batch_terms import build_prior, shrink_build

    sigma = np.array([2.0, 1.0, 0.5, 3.0])
    g = np.array([3.0, 4.0, 0.0])
    beta = np.array([1.0, -2.0, 0.7, 9.0])  # the last coefficient is past len(g)
    z = beta[:3] / sigma[:3]
    np.testing.assert_allclose(shrink_build(beta, sigma, g, 1.0), beta)
    mean = shrink_build(beta, sigma, g, 0.0)
    assert build_prior(mean, sigma, g) == pytest.approx(0.0, abs=1e-12)  # the mean body of its stature
    assert (mean[:3] / sigma[:3]) @ g == pytest.approx(z @ g)  # the stature's coordinate kept
    assert mean[3] == 9.0
    half = shrink_build(beta, sigma, g, 0.5)
    assert build_prior(half, sigma, g) == pytest.approx(0.25 * build_prior(beta, sigma, g))
    assert np.all(beta == np.array([1.0, -2.0, 0.7, 9.0]))  # the input untouched

