"""Annealed particle filter (thesis §4.7.3) on known multimodal functions."""

import doctest

import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.special import logsumexp

import studio.optimize.annealed as annealed_module
from studio.optimize import CostError, annealed_particle_filter, survival_rate
from studio.optimize._common import apply_bounds, check_bounds, make_rng


def rastrigin(x):
    """Rastrigin function, global minimum 0 at the origin; every other local minimum costs >= 0.99."""
    x = np.atleast_2d(x)
    return 10.0 * x.shape[1] + np.sum(x**2 - 10.0 * np.cos(2 * np.pi * x), axis=1)


A6 = np.full(6, 1.0)
B6 = np.full(6, -1.0)


def two_modes(x):
    """6-D: a deep mode at +1 (cost 0) and a shallower one at -1 (cost 1.2) of equal width."""
    x = np.atleast_2d(x)
    la = -np.sum((x - A6) ** 2, axis=1) / (2 * 0.6**2)
    lb = np.log(0.3) - np.sum((x - B6) ** 2, axis=1) / (2 * 0.6**2)
    return -logsumexp(np.stack([la, lb]), axis=0)


BOX2 = (np.full(2, -5.12), np.full(2, 5.12))


@pytest.mark.parametrize("seed", range(5))
def test_finds_global_minimum_of_2d_rastrigin(seed):
    x0 = np.array([3.0, 3.0])
    local = minimize(lambda x: rastrigin(x)[0], x0, method="Nelder-Mead")
    assert local.fun > 10.0  # a local search from x0 is trapped
    res = annealed_particle_filter(rastrigin, x0, 3.0, bounds=BOX2, n_particles=200, n_layers=15,
                                   vectorized=True, seed=seed)
    assert np.abs(res.x).max() < 0.1
    assert res.cost < 0.99  # below every non-global local minimum
    assert res.cost == pytest.approx(rastrigin(res.x)[0])
    assert res.n_evaluations == 200 * 15


def test_ess_definition_also_finds_rastrigin_minimum_precisely():
    for seed in range(3):
        res = annealed_particle_filter(rastrigin, [3.0, 3.0], 3.0, bounds=BOX2, n_particles=200, n_layers=15,
                                       vectorized=True, seed=seed, survival="ess")
        assert np.abs(res.x).max() < 0.01
        np.testing.assert_allclose(res.survival_rates, 0.5, atol=1e-3)


def test_prefers_the_deeper_of_two_modes_in_6d():
    x0 = np.full(6, -0.3)  # nearer the shallow mode: a local search ends there
    assert np.linalg.norm(minimize(lambda x: two_modes(x)[0], x0, method="Nelder-Mead").x - B6) < 0.01
    wins = 0
    for seed in range(10):
        res = annealed_particle_filter(two_modes, x0, 1.0, bounds=(np.full(6, -4.0), np.full(6, 4.0)),
                                       n_particles=200, n_layers=10, vectorized=True, seed=seed)
        wins += np.linalg.norm(res.x - A6) < np.linalg.norm(res.x - B6)
        # the annealing runs downhill: the layer's best cost ends far below the first layer's mean
        assert res.layers[-1].best_cost < res.layers[0].mean_cost
    assert wins >= 8


def test_same_seed_same_result_and_generator_accepted():
    kwargs = dict(bounds=BOX2, n_particles=50, n_layers=5, vectorized=True)
    a = annealed_particle_filter(rastrigin, [2.0, -1.0], 1.0, seed=42, **kwargs)
    b = annealed_particle_filter(rastrigin, [2.0, -1.0], 1.0, seed=42, **kwargs)
    c = annealed_particle_filter(rastrigin, [2.0, -1.0], 1.0, seed=np.random.default_rng(42), **kwargs)
    d = annealed_particle_filter(rastrigin, [2.0, -1.0], 1.0, seed=43, **kwargs)
    np.testing.assert_array_equal(a.x, b.x)
    np.testing.assert_array_equal(a.particles, c.particles)
    assert a.layers == b.layers
    assert not np.array_equal(a.particles, d.particles)


def test_scalar_cost_path_equals_vectorised_path():
    def scalar(x):
        return float(rastrigin(x)[0])

    kw = dict(bounds=BOX2, n_particles=30, n_layers=4, seed=5)
    a = annealed_particle_filter(scalar, [1.0, 1.0], 1.0, **kw)
    b = annealed_particle_filter(rastrigin, [1.0, 1.0], 1.0, vectorized=True, **kw)
    np.testing.assert_allclose(a.x, b.x)
    assert a.cost == pytest.approx(b.cost)


def test_history_survival_and_diffusion_schedule():
    res = annealed_particle_filter(rastrigin, [3.0, 3.0], 2.0, bounds=BOX2, n_particles=100, n_layers=8,
                                   vectorized=True, seed=1, alpha=0.5)
    assert len(res.layers) == 8
    np.testing.assert_allclose(res.survival_rates, 0.5, atol=1e-3)  # "about half the particles survive"
    np.testing.assert_allclose([s.sigma_scale for s in res.layers], np.sqrt(0.5) ** np.arange(8))
    fractions = [s.resampled_fraction for s in res.layers[:-1]]
    assert all(0.3 < f < 0.7 for f in fractions)  # realised distinct survivors, near the expected 0.5
    assert np.isnan(res.layers[-1].resampled_fraction)
    assert all(s.beta > 0 for s in res.layers)
    assert [s.n_evaluations for s in res.layers] == list(range(100, 900, 100))
    assert res.cost == pytest.approx(res.best_costs.min())
    assert res.weights.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(res.mean_x, res.weights @ res.particles)  # eq. 4.15
    np.testing.assert_array_equal(res.map_x, res.particles[np.argmax(res.weights)])  # eq. 4.16


@pytest.mark.parametrize("boundary", ["reflect", "clip"])
def test_samples_stay_within_bounds(boundary):
    lo, hi = np.array([0.0, -1.0, 2.0]), np.array([1.0, 1.0, 2.0])  # last parameter fixed
    seen = []

    def cost(x):
        seen.append(x.copy())
        return np.sum((x - np.array([5.0, 0.0, 0.0])) ** 2, axis=1)  # minimum outside the box

    res = annealed_particle_filter(cost, [0.5, 0.0, 2.0], 2.0, bounds=(lo, hi), n_particles=40, n_layers=6,
                                   vectorized=True, seed=0, boundary=boundary)
    pts = np.concatenate(seen)
    assert (pts >= lo).all() and (pts <= hi).all()
    assert res.x[0] > 0.9 and res.x[2] == 2.0


def test_soft_constraints_leave_samples_alone():
    seen = []

    def cost(x):
        seen.append(x.copy())
        return np.sum(x**2, axis=1)

    annealed_particle_filter(cost, [0.5], 2.0, bounds=([0.0], [1.0]), n_particles=40, n_layers=2,
                             vectorized=True, seed=0, boundary="none")
    pts = np.concatenate(seen)
    assert (pts < 0).any() or (pts > 1).any()


def test_apply_bounds_reflection():
    lo, hi = np.array([0.0, 0.0, -np.inf, 1.0]), np.array([1.0, np.inf, 2.0, 1.0])
    x = np.array([[1.25, -0.5, 3.0, 7.0], [-2.25, 4.0, -9.0, 0.0], [3.5, 0.0, 2.0, 1.0]])
    out = apply_bounds(x, lo, hi, "reflect")
    np.testing.assert_allclose(out, [[0.75, 0.5, 1.0, 1.0], [0.25, 4.0, -9.0, 1.0], [0.5, 0.0, 2.0, 1.0]])
    np.testing.assert_allclose(apply_bounds(x, lo, hi, "clip")[0], [1.0, 0.0, 2.0, 1.0])
    assert apply_bounds(x, lo, hi, "none") is x


def test_importance_correction_and_multiple_starts():
    starts = np.array([[3.0, 3.0], [-0.2, 0.1], [2.0, -2.0]])
    res = annealed_particle_filter(rastrigin, starts, 0.5, bounds=BOX2, n_particles=60, n_layers=6,
                                   vectorized=True, seed=2, importance_correction=True)
    assert res.cost < rastrigin(starts[1])[0]  # improves on the best start (kept unperturbed in layer 0)
    assert np.all(np.isfinite(res.weights))
    assert res.weights.sum() == pytest.approx(1.0)


def test_covariance_sigma_and_infinite_costs():
    def cost(x):
        c = np.sum(x**2, axis=1)
        return np.where(x[:, 0] > 1.0, np.inf, c)  # an impossible region

    cov = np.array([[1.0, 0.3], [0.3, 0.5]])
    res = annealed_particle_filter(cost, [0.5, 0.5], cov, n_particles=60, n_layers=6, vectorized=True, seed=3)
    assert np.isfinite(res.cost) and res.cost < 0.05
    assert np.all(res.weights[~np.isfinite(res.costs)] == 0.0)


def test_flat_cost_and_zero_diffusion():
    # all costs equal: no annealing exponent can discriminate, weights stay uniform
    res = annealed_particle_filter(lambda x: np.ones(len(x)), [0.0, 0.0], 1.0, n_particles=10, n_layers=3,
                                   vectorized=True, seed=0)
    assert all(s.beta == 0.0 for s in res.layers)
    np.testing.assert_allclose(res.weights, 0.1)
    # zero diffusion with the importance correction: particles never move
    res = annealed_particle_filter(rastrigin, [0.5, 0.5], 0.0, n_particles=10, n_layers=3, vectorized=True,
                                   seed=0, importance_correction=True)
    np.testing.assert_array_equal(res.particles, 0.5)


def test_callback_can_stop():
    seen = []
    res = annealed_particle_filter(rastrigin, [1.0, 1.0], 1.0, n_particles=20, n_layers=10, vectorized=True,
                                   seed=0, callback=lambda s: seen.append(s.layer) or s.layer == 2)
    assert seen == [0, 1, 2]
    assert res.stopped_early and len(res.layers) == 3 and res.n_evaluations == 60


def test_survival_rate_definitions():
    w = np.array([0.5, 0.5, 0.0, 0.0])
    assert survival_rate(w, "ess") == pytest.approx(0.5)
    assert survival_rate(w, "resampled") == pytest.approx(2 * (1 - 0.5**4) / 4)
    assert survival_rate(np.full(1000, 1e-3), "resampled") == pytest.approx(1 - (1 - 1e-3) ** 1000)
    with pytest.raises(ValueError, match="survival: expected one of"):
        survival_rate(w, "median")


def test_doctests():
    assert doctest.testmod(annealed_module).failed == 0


def test_bad_inputs():
    f = rastrigin
    with pytest.raises(ValueError, match="x0: non-finite value nan at index 1"):
        annealed_particle_filter(f, [0.0, np.nan], 1.0, vectorized=True)
    with pytest.raises(ValueError, match=r"x0\[1\]: non-finite"):
        annealed_particle_filter(f, [[0.0, 0.0], [np.inf, 0.0]], 1.0, vectorized=True)
    with pytest.raises(ValueError, match="x0: expected a"):
        annealed_particle_filter(f, np.zeros((2, 2, 2)), 1.0)
    with pytest.raises(ValueError, match="sigma0: per-parameter standard deviations"):
        annealed_particle_filter(f, [0.0, 0.0], [1.0, -1.0])
    with pytest.raises(ValueError, match=r"sigma0: expected a scalar, \(2,\)"):
        annealed_particle_filter(f, [0.0, 0.0], [1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="sigma0: a .* covariance must be finite and symmetric"):
        annealed_particle_filter(f, [0.0, 0.0], [[1.0, 0.2], [0.0, 1.0]])
    with pytest.raises(ValueError, match="sigma0: the .* covariance is not positive definite"):
        annealed_particle_filter(f, [0.0, 0.0], [[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ValueError, match="bounds: parameter 0 has lo 1.0 > hi 0.0"):
        annealed_particle_filter(f, [0.0, 0.0], 1.0, bounds=([1.0, 0.0], [0.0, 1.0]))
    with pytest.raises(ValueError, match="bounds: NaN"):
        annealed_particle_filter(f, [0.0, 0.0], 1.0, bounds=([np.nan, 0.0], [0.0, 1.0]))
    with pytest.raises(ValueError, match="bounds: expected lo and hi of shape"):
        annealed_particle_filter(f, [0.0, 0.0], 1.0, bounds=([0.0], [1.0]))
    with pytest.raises(ValueError, match="bounds: expected a pair"):
        annealed_particle_filter(f, [0.0, 0.0], 1.0, bounds=[0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="n_particles: expected an integer >= 2"):
        annealed_particle_filter(f, [0.0, 0.0], 1.0, n_particles=1)
    with pytest.raises(ValueError, match="n_layers: expected an integer >= 1"):
        annealed_particle_filter(f, [0.0, 0.0], 1.0, n_layers=0)
    with pytest.raises(ValueError, match="alpha: expected a covariance scale"):
        annealed_particle_filter(f, [0.0, 0.0], 1.0, alpha=1.5)
    with pytest.raises(ValueError, match="survival_target: expected a rate"):
        annealed_particle_filter(f, [0.0, 0.0], 1.0, survival_target=1.0)
    with pytest.raises(ValueError, match="survival: expected one of"):
        annealed_particle_filter(f, [0.0, 0.0], 1.0, survival="half")
    with pytest.raises(ValueError, match="boundary: expected one of"):
        annealed_particle_filter(f, [0.0, 0.0], 1.0, boundary="wrap")
    with pytest.raises(ValueError, match="seed: expected an int, None or numpy.random.Generator"):
        make_rng("abc")
    assert check_bounds(([0.0], 1.0), 1)[1][0] == 1.0


def test_bad_costs_raise_clear_errors():
    with pytest.raises(CostError, match=r"cost function returned NaN in layer 0 for particle 0"):
        annealed_particle_filter(lambda x: np.nan, [0.0], 1.0, n_particles=4, n_layers=2, seed=0)
    with pytest.raises(CostError, match=r"must map \(4, 1\) particles to \(4,\) costs, got shape \(\)"):
        annealed_particle_filter(lambda x: 1.0, [0.0], 1.0, n_particles=4, vectorized=True, seed=0)
    with pytest.raises(CostError, match="only infinite costs in layer 0"):
        annealed_particle_filter(lambda x: np.inf, [0.0], 1.0, n_particles=4, seed=0)
