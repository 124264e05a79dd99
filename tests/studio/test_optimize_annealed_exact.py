"""Annealed particle filter (eq. 4.11–4.14) against independent references and at its limits.

- the proposal density of the importance correction against scipy.stats.multivariate_normal,
  on a covariance with a zero-variance direction and more particles than one 64-row chunk;
- layer 0 (eq. 4.12) drawn by hand from the same seed: the starts once, then ``x0 + L z``;
- β and its weights against ``exp(−β δ − log q)`` normalised by hand; ties at the lowest cost
  (piecewise-constant silhouette costs make them likely late in the annealing): the survival
  target is met, not dropped;
- documented limits (N >= 2, R >= 1, α in (0, 1], target in (0, 1)) at the boundary, defaults.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import logsumexp
from scipy.stats import multivariate_normal

import studio.optimize.annealed as annealed
from studio.optimize import annealed_particle_filter, survival_rate


def test_proposal_density_is_the_gaussian_mixture():
    rng = np.random.default_rng(0)
    centres = rng.normal(size=(7, 3))
    log_w = np.log(rng.dirichlet(np.ones(7)))
    chol = np.array([[0.5, 0.0, 0.0], [0.2, 0.0, 0.0], [-0.3, 0.0, 0.7]])  # no variance along axis 1
    x = rng.normal(size=(150, 3))  # three chunks of at most 64 rows
    got = annealed._log_mixture_density(x, centres, log_w, chol)
    keep = [0, 2]
    cov = chol[np.ix_(keep, keep)] @ chol[np.ix_(keep, keep)].T
    ref = logsumexp([lw + multivariate_normal(c[keep], cov).logpdf(x[:, keep]) for lw, c in zip(log_w, centres)],
                    axis=0)
    assert np.ptp(got - ref) < 1e-9  # equal up to one constant for all particles


def test_normalised_weights_of_large_log_weights():
    np.testing.assert_allclose(annealed._normalised(np.array([800.0, 800.0 - np.log(3.0)])), [0.75, 0.25],
                               rtol=1e-12)


def test_beta_weights_divide_by_the_proposal_density():
    delta = np.array([0.0, 0.5, 1.0, 2.0, 4.0, np.inf])
    log_q = np.array([0.3, -0.2, 0.1, 0.0, -1.0, 0.0])
    beta, w = annealed._solve_beta(delta, log_q, 0.5, "ess")
    want = np.zeros(6)
    want[:5] = np.exp(-beta * delta[:5] - log_q[:5])
    np.testing.assert_allclose(w, want / want.sum(), rtol=1e-12)
    assert survival_rate(w, "ess") == pytest.approx(0.5, abs=1e-5)


def test_unreachable_target_gives_beta_zero_and_uniform_weights():
    """With N = 4 at most 1 − (3/4)⁴ = 0.684 of the particles survive resampling: a target of 0.7
    cannot be met, β = 0."""
    beta, w = annealed._solve_beta(np.array([0.0, 1.0, 2.0, 3.0]), np.zeros(4), 0.7, "resampled")
    assert beta == 0.0
    np.testing.assert_array_equal(w, 0.25)


@pytest.mark.parametrize("n_tied, survival", [(4, 0.5), (6, 0.75)])
def test_ties_at_the_lowest_cost_keep_the_selection(n_tied, survival):
    """Half (or more) of 8 particles tie at the lowest cost: ESS → n_tied/8 as β grows, never below.
    The weights are uniform over the tied best (the target's limit), not uniform over all 8 —
    before the fix β = 0 weighed the worst particles like the best."""
    delta = np.concatenate([np.zeros(n_tied), 1.0 + np.arange(8 - n_tied)])
    beta, w = annealed._solve_beta(delta, np.zeros(8), 0.5, "ess")
    assert beta > 0
    np.testing.assert_allclose(w[:n_tied], 1.0 / n_tied, rtol=1e-9)
    assert w[n_tied:].max() < 1e-12
    assert survival_rate(w, "ess") == pytest.approx(survival, rel=1e-9)
    # all costs equal: any β, reported as 0
    beta, w = annealed._solve_beta(np.zeros(8), np.zeros(8), 0.5, "ess")
    assert beta == 0.0 and np.all(w == 0.125)


def test_layer_zero_is_the_starts_then_gaussian_draws_around_them():
    x0 = np.array([[1.0, 2.0], [-1.0, 0.0]])
    sigma = np.array([0.5, 2.0])
    res = annealed_particle_filter(lambda x: np.sum(x**2, axis=1), x0, sigma, n_particles=5, n_layers=1,
                                   vectorized=True, seed=3)
    want = x0[np.arange(5) % 2] + np.random.default_rng(3).standard_normal((5, 2)) * sigma
    want[:2] = x0
    np.testing.assert_array_equal(res.particles, want)
    # clipped into the bounds, not reflected
    lo, hi = np.array([-1.0, -1.0]), np.array([1.0, 1.0])
    res = annealed_particle_filter(lambda x: np.sum(x**2, axis=1), x0, sigma, bounds=(lo, hi), n_particles=5,
                                   n_layers=1, vectorized=True, seed=3, boundary="clip")
    np.testing.assert_array_equal(res.particles, np.clip(want, lo, hi))


def test_later_layers_are_clipped_too():
    res = annealed_particle_filter(lambda x: np.sum(x**2, axis=1), [0.0, 0.0], 3.0, bounds=([-0.5, -0.5], [0.5, 0.5]),
                                   n_particles=40, n_layers=2, vectorized=True, seed=1, boundary="clip")
    assert (np.abs(res.particles) == 0.5).any()  # clipping piles particles on the bound; reflection would not


def test_constant_costs_keep_the_first_start():
    """A flat cost: uniform weights, β = 0, and the best particle is the first seen — the
    unperturbed start."""
    res = annealed_particle_filter(lambda x: np.full(len(x), 7.0), [0.25, -0.5], 1.0, n_particles=8,
                                   n_layers=3, vectorized=True, seed=0)
    np.testing.assert_array_equal(res.x, [0.25, -0.5])
    assert res.cost == 7.0 and all(s.beta == 0.0 for s in res.layers)
    np.testing.assert_array_equal(res.weights, 0.125)
    assert res.stopped_early is False
    for arr in (res.x, res.mean_x, res.map_x, res.particles, res.weights, res.costs):
        assert not arr.flags.writeable


def test_final_weights_are_the_annealed_density_of_the_final_costs():
    """Eq. 4.14 at the last layer: π_i ∝ exp(−β (E_i − min E)), on costs of 1e9 + small (the
    minimum is subtracted exactly; adding it instead would round the differences away)."""
    res = annealed_particle_filter(lambda x: 1e9 + 1e-6 * np.sum(x**2, axis=1), [0.0, 0.0], 1.0, n_particles=50,
                                   n_layers=3, vectorized=True, seed=2)
    beta = res.layers[-1].beta
    want = np.exp(-beta * (res.costs - res.costs.min()))
    np.testing.assert_allclose(res.weights, want / want.sum(), rtol=1e-9)
    assert survival_rate(res.weights) == pytest.approx(0.5, abs=1e-4)


def test_defaults_and_float64_costs():
    res = annealed_particle_filter(lambda x: np.rint(10 * np.sum(x**2, axis=1)).astype(np.int32), [0.0], 1.0,
                                   vectorized=True, seed=0)
    assert res.n_evaluations == 200 * 10 and len(res.layers) == 10 and res.particles.shape == (200, 1)
    assert res.costs.dtype == np.float64


def test_importance_correction_with_impossible_particles_raises_no_warning():
    """Zero weights (infinite costs) enter log(weights) without a divide-by-zero warning (an error here)."""
    def cost(x):
        return np.where(x[:, 0] > 0.0, np.inf, np.sum(x**2, axis=1))

    res = annealed_particle_filter(cost, [-0.5, 0.0], 1.0, n_particles=30, n_layers=3, vectorized=True, seed=4,
                                   importance_correction=True)
    assert np.isfinite(res.cost)


def test_limits_at_their_boundaries():
    f = lambda x: np.sum(x**2, axis=1)  # noqa: E731
    res = annealed_particle_filter(f, [1.0], 1.0, n_particles=2, n_layers=1, alpha=1.0, vectorized=True, seed=0)
    assert res.particles.shape == (2, 1) and len(res.layers) == 1
    cases = [
        (dict(n_particles=3.0), r"^n_particles: expected an integer >= 2, got 3\.0$"),
        (dict(n_particles=1), r"^n_particles: expected an integer >= 2, got 1$"),
        (dict(n_layers=2.0), r"^n_layers: expected an integer >= 1, got 2\.0$"),
        (dict(alpha=0.0), r"^alpha: expected a covariance scale in \(0, 1\], got 0\.0$"),
        (dict(survival_target=0.0), r"^survival_target: expected a rate in \(0, 1\), got 0\.0$"),
    ]
    for kwargs, message in cases:
        with pytest.raises(ValueError, match=message):
            annealed_particle_filter(f, [1.0], 1.0, vectorized=True, **kwargs)
    with pytest.raises(ValueError, match=r"^x0: expected a \(D,\) vector or \(N0, D\) initial estimates, "
                                         r"got shape \(2, 2, 2\)$"):
        annealed_particle_filter(f, np.zeros((2, 2, 2)), 1.0)
    for sigma0, message in [([1.0, -1.0], r"^sigma0: per-parameter standard deviations must be finite and >= 0$"),
                            ([[1.0, 0.5], [0.0, 1.0]], r"^sigma0: a \(D, D\) covariance must be finite and symmetric$"),
                            ([[1.0, 2.0], [2.0, 1.0]], r"^sigma0: the \(D, D\) covariance is not positive definite$")]:
        with pytest.raises(ValueError, match=message):
            annealed_particle_filter(f, [0.0, 0.0], sigma0)


def test_survival_rate_default_and_float64():
    w = np.array([0.5, 0.25, 0.125, 0.125])
    assert survival_rate(w) == survival_rate(w, "resampled") == pytest.approx(
        np.mean(1 - (1 - w) ** 4), rel=1e-12)
    w32 = np.array([0.1, 0.2, 0.3, 0.4], np.float32)
    for definition in ("ess", "resampled"):
        assert survival_rate(w32, definition) == survival_rate(w32.astype(np.float64), definition)

