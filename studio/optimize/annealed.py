"""Annealed particle filter for stochastic search (thesis §4.7.3, eq. 4.7–4.16).

The state density is ``f(s) = exp(−E(s))`` for a cost ``E``. Each layer ``r``:

1. evaluates the cost of the N particles (one batched call when ``vectorized``);
2. weights them by the annealed density ``π_i ∝ f(s_i)^{β_r}`` (eq. 4.14), optionally
   divided by the proposal density ``f̂^{(r−1)}(s_i)`` as eq. 4.14 writes it
   (``importance_correction=True``; Deutscher & Reid's APF omits it, the default);
3. chooses the annealing exponent ``β_r`` by root finding so that the survival
   rate equals ``survival_target`` (0.5: "about half the particles survive");
4. resamples N particles (multinomial) and diffuses them with a Gaussian of
   covariance ``Σ^{(r)} = α^r Σ^{(0)}`` (eq. 4.13, α = 0.5), i.e. draws from the
   Gaussian-mixture estimator ``f̂^{(r)}`` of eq. 4.11.

Two survival-rate definitions are offered (``survival=``):

- ``"resampled"`` (default, the thesis's wording): the expected fraction of
  particles drawn at least once by the multinomial resampling,
  ``(1/N) Σ_i [1 − (1 − π_i)^N]``. Its maximum, for uniform weights, is
  ``1 − (1 − 1/N)^N ≈ 0.632``, so a target of 0.5 is always attainable;
- ``"ess"``: Deutscher & Reid's (IJCV 2005) particle survival rate
  ``α = (Σ_i π_i²)^{−1} / N``, the normalised effective sample size.

Bounds: samples outside ``[lo, hi]`` are reflected back by default
(``boundary="reflect"``), or clipped, or left alone (``"none"``: soft constraints
only, as in Zhang et al. 2013 and the thesis, where joint limits enter the cost
through the pose prior eq. 6.9). Reflection keeps the diffusion symmetric and does
not pile particles up on the limits as clipping does.

Everything random comes from one ``numpy.random.Generator``, so a seed gives the
same particles, costs and result.

Chaining (thesis §4.7.1: a coarse search on the cylinder model, then SCAPE): pass
the first run's final ``particles`` (or its ``x``) as ``x0`` of the second run,
with the second cost and a smaller ``sigma0``.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solve_triangular
from scipy.optimize import brentq
from scipy.special import logsumexp

from ._common import BOUNDARY_MODES, CostError, apply_bounds, check_bounds, check_vector, make_rng

__all__ = ["AnnealedResult", "LayerStats", "annealed_particle_filter", "survival_rate"]

log = logging.getLogger(__name__)

SURVIVAL_DEFINITIONS = ("resampled", "ess")


@dataclass(frozen=True)
class LayerStats:
    """What happened in one annealing layer.

    Attributes
    ----------
    layer : int
        0-based layer index.
    beta : float
        Annealing exponent ``β_r`` (``t^{(r)}`` of eq. 4.14) in 1/cost units.
    survival : float
        Survival rate of the chosen weights under the selected definition.
    resampled_fraction : float
        Fraction of distinct particles actually drawn by the resampling (NaN on the
        last layer, which is not resampled).
    best_cost, mean_cost : float
        Lowest and mean (finite) cost of the layer's particles.
    sigma_scale : float
        ``sqrt(α)^r``: standard deviation of the diffusion that produced this layer,
        relative to ``sigma0``.
    n_evaluations : int
        Cumulative number of cost evaluations after this layer.
    """

    layer: int
    beta: float
    survival: float
    resampled_fraction: float
    best_cost: float
    mean_cost: float
    sigma_scale: float
    n_evaluations: int


@dataclass(frozen=True, eq=False)
class AnnealedResult:
    """Outcome of :func:`annealed_particle_filter`.

    Attributes
    ----------
    x : (D,) float64
        Best particle seen over all layers (lowest cost).
    cost : float
        Its cost.
    mean_x : (D,) float64
        Weighted mean of the final layer (eq. 4.15).
    map_x : (D,) float64
        Highest-weight particle of the final layer (eq. 4.16).
    particles : (N, D) float64
        Final layer's particles.
    weights : (N,) float64
        Their normalised weights.
    costs : (N,) float64
        Their costs.
    layers : tuple[LayerStats, ...]
        Per-layer history (best/mean cost, β, survival rates).
    n_evaluations : int
        Total number of cost evaluations.
    stopped_early : bool
        The callback asked to stop.
    """

    x: np.ndarray
    cost: float
    mean_x: np.ndarray
    map_x: np.ndarray
    particles: np.ndarray
    weights: np.ndarray
    costs: np.ndarray
    layers: tuple[LayerStats, ...]
    n_evaluations: int
    stopped_early: bool

    @property
    def best_costs(self) -> np.ndarray:
        """Per-layer best cost, ``(R,) float64``."""
        return np.array([s.best_cost for s in self.layers])

    @property
    def survival_rates(self) -> np.ndarray:
        """Per-layer survival rate, ``(R,) float64``."""
        return np.array([s.survival for s in self.layers])


def _normalised(logw: np.ndarray) -> np.ndarray:
    w = np.exp(logw - logsumexp(logw))
    return w / w.sum()


def survival_rate(weights: np.ndarray, definition: str = "resampled") -> float:
    """Survival rate of normalised weights ``(N,)`` (see the module docstring).

    >>> round(survival_rate(np.full(4, 0.25), "ess"), 6)
    1.0
    >>> round(survival_rate(np.array([1.0, 0.0, 0.0, 0.0]), "resampled"), 6)
    0.25
    """
    w = np.asarray(weights, dtype=np.float64)
    n = w.shape[0]
    if definition == "ess":
        return float(1.0 / (n * np.sum(w**2)))
    if definition == "resampled":
        # 1 − (1 − w)^N, accurate for tiny w; w = 1 gives 1.
        with np.errstate(divide="ignore"):
            drawn = -np.expm1(n * np.log1p(-np.minimum(w, 1.0)))
        return float(np.mean(drawn))
    raise ValueError(f"survival: expected one of {SURVIVAL_DEFINITIONS}, got {definition!r}")


def _solve_beta(delta: np.ndarray, log_q: np.ndarray, target: float, definition: str) -> tuple[float, np.ndarray]:
    """Annealing exponent ``β >= 0`` with survival ≈ target, and the weights it gives.

    ``delta`` holds ``E_i − min E`` (``inf`` for unusable particles), ``log_q`` the
    log proposal densities to divide by (zeros without importance correction).
    """
    finite = np.isfinite(delta)

    def weights(beta: float) -> np.ndarray:
        logw = np.full(delta.shape, -np.inf)
        logw[finite] = -beta * delta[finite] - log_q[finite]
        return _normalised(logw)

    def excess(beta: float) -> float:
        return survival_rate(weights(beta), definition) - target

    if excess(0.0) <= 0.0:
        return 0.0, weights(0.0)
    spread = float(np.std(delta[finite]))
    if spread == 0.0:  # all finite costs equal: any β gives the same weights
        return 0.0, weights(0.0)
    hi = 1.0 / spread
    for _ in range(200):
        if excess(hi) <= 0.0:
            break
        hi *= 2.0
    else:
        # Survival stays above the target however large β: more than the target's share of the
        # particles tie at the lowest cost. The weights of the largest β tried (uniform over the
        # tied best) come closest; β = 0 would weigh the worst particles like the best.
        return hi, weights(hi)
    # β in [0, hi]; hi itself when the excess is exactly 0 there (the best tie at exactly the
    # target's share, e.g. half of the particles for 0.5: the target is met only in the limit).
    beta = brentq(excess, 0.0, hi, xtol=1e-12, rtol=1e-6, maxiter=200)
    return float(beta), weights(beta)


def _cov_factor(sigma0, d: int) -> np.ndarray:
    """Lower-triangular ``L`` with ``L Lᵀ = Σ^{(0)}`` from per-parameter sigmas or a covariance."""
    arr = np.asarray(sigma0, dtype=np.float64)
    if arr.ndim == 0:
        arr = np.full(d, float(arr))
    if arr.shape == (d,):
        if not np.isfinite(arr).all() or (arr < 0).any():
            raise ValueError("sigma0: per-parameter standard deviations must be finite and >= 0")
        return np.diag(arr)
    if arr.shape == (d, d):
        if not np.isfinite(arr).all() or not np.allclose(arr, arr.T):
            raise ValueError("sigma0: a (D, D) covariance must be finite and symmetric")
        try:
            return np.linalg.cholesky(arr)
        except np.linalg.LinAlgError:
            raise ValueError("sigma0: the (D, D) covariance is not positive definite") from None
    raise ValueError(f"sigma0: expected a scalar, ({d},) sigmas or a ({d}, {d}) covariance, got shape {arr.shape}")


def _log_mixture_density(x: np.ndarray, centres: np.ndarray, log_weights: np.ndarray, chol: np.ndarray) -> np.ndarray:
    """``log Σ_j w_j N(x_i; c_j, L Lᵀ)`` up to a constant common to all ``i``, ``(N,)``.

    Directions with zero variance are ignored (the density is taken over the
    diffused subspace).
    """
    keep = np.abs(np.diag(chol)) > 0
    if not keep.any():
        return np.zeros(x.shape[0])
    sub = chol[np.ix_(keep, keep)]
    out = np.empty(x.shape[0])
    for start in range(0, x.shape[0], 64):  # bounded memory: (64, M, d) at a time
        diff = x[start : start + 64, None, keep] - centres[None, :, keep]
        white = solve_triangular(sub, diff.reshape(-1, diff.shape[-1]).T, lower=True).T.reshape(diff.shape)
        maha = np.sum(white**2, axis=-1)
        out[start : start + 64] = logsumexp(log_weights[None, :] - 0.5 * maha, axis=1)
    return out


def _evaluate(f, x: np.ndarray, vectorized: bool, layer: int) -> np.ndarray:
    if vectorized:
        costs = np.asarray(f(x), dtype=np.float64)
        if costs.shape != (x.shape[0],):
            raise CostError(
                f"cost function: with vectorized=True it must map ({x.shape[0]}, {x.shape[1]}) particles "
                f"to ({x.shape[0]},) costs, got shape {costs.shape}"
            )
    else:
        costs = np.array([float(f(row)) for row in x])
    if np.isnan(costs).any():
        i = int(np.flatnonzero(np.isnan(costs))[0])
        raise CostError(f"cost function returned NaN in layer {layer} for particle {i}: {x[i].tolist()}")
    return costs


def annealed_particle_filter(
    f: Callable[[np.ndarray], float | np.ndarray],
    x0,
    sigma0,
    *,
    bounds=None,
    n_particles: int = 200,
    n_layers: int = 10,
    alpha: float = 0.5,
    survival_target: float = 0.5,
    survival: str = "resampled",
    boundary: str = "reflect",
    importance_correction: bool = False,
    vectorized: bool = False,
    seed=None,
    callback: Callable[[LayerStats], bool | None] | None = None,
) -> AnnealedResult:
    """Minimise ``f`` by annealed particle filtering (thesis §4.7.3).

    Parameters
    ----------
    f : callable
        Cost ``E(x)``: ``(D,) -> float``, or ``(N, D) -> (N,)`` with ``vectorized=True``.
        ``inf`` marks an impossible state (weight 0); NaN raises :class:`CostError`.
    x0 : (D,) or (N0, D) float
        Initial estimate(s). Layer 0 holds each of them once unperturbed and the
        rest of the N particles drawn around them in turn with covariance
        ``Σ^{(0)}`` (the mixture of eq. 4.12 with equal weights; the first layer's
        annealing then weighs them by cost).
    sigma0 : float, (D,) or (D, D)
        Initial diffusion: per-parameter standard deviations or a covariance ``Σ^{(0)}``.
    bounds : (lo, hi), optional
        Per-parameter limits (``±inf`` allowed); see ``boundary``.
    n_particles : int
        N, particles per layer.
    n_layers : int
        Number of annealing layers R (cost evaluations: ``N · R``).
    alpha : float
        Covariance scale per layer, eq. 4.13 (thesis: 0.5).
    survival_target : float
        Target survival rate for choosing ``β`` (thesis: about half).
    survival : {"resampled", "ess"}
        Survival-rate definition (module docstring).
    boundary : {"reflect", "clip", "none"}
        How samples outside ``bounds`` are brought back.
    importance_correction : bool
        Divide the weights by the proposal density as in eq. 4.14.
    vectorized : bool
        ``f`` takes all particles of a layer at once.
    seed : int, Generator or None
        Source of randomness.
    callback : callable, optional
        Called with each :class:`LayerStats`; returning True stops after that layer.
    """
    if boundary not in BOUNDARY_MODES:
        raise ValueError(f"boundary: expected one of {BOUNDARY_MODES}, got {boundary!r}")
    if survival not in SURVIVAL_DEFINITIONS:
        raise ValueError(f"survival: expected one of {SURVIVAL_DEFINITIONS}, got {survival!r}")
    starts = np.array(x0, dtype=np.float64)
    if starts.ndim == 1:
        starts = starts[None, :]
    if starts.ndim != 2 or starts.size == 0:
        raise ValueError(f"x0: expected a (D,) vector or (N0, D) initial estimates, got shape {np.shape(x0)}")
    for i, row in enumerate(starts):
        check_vector(row, f"x0[{i}]" if len(starts) > 1 else "x0")
    d = starts.shape[1]
    chol0 = _cov_factor(sigma0, d)
    lo, hi = check_bounds(bounds, d)
    if isinstance(n_particles, bool) or not isinstance(n_particles, (int, np.integer)) or n_particles < 2:
        raise ValueError(f"n_particles: expected an integer >= 2, got {n_particles!r}")
    if isinstance(n_layers, bool) or not isinstance(n_layers, (int, np.integer)) or n_layers < 1:
        raise ValueError(f"n_layers: expected an integer >= 1, got {n_layers!r}")
    if not (0.0 < float(alpha) <= 1.0):
        raise ValueError(f"alpha: expected a covariance scale in (0, 1], got {alpha}")
    if not (0.0 < float(survival_target) < 1.0):
        raise ValueError(f"survival_target: expected a rate in (0, 1), got {survival_target}")
    rng = make_rng(seed)
    n = int(n_particles)
    n_layers = int(n_layers)
    step = math.sqrt(float(alpha))

    # Layer 0: every start once, then draws around the starts in turn (eq. 4.12).
    owners = np.arange(n) % len(starts)
    x = starts[owners] + rng.standard_normal((n, d)) @ chol0.T
    n_exact = min(len(starts), n)
    x[:n_exact] = starts[:n_exact]
    x = apply_bounds(x, lo, hi, boundary)
    log_q = np.zeros(n)

    best_x, best_cost = None, math.inf
    history: list[LayerStats] = []
    n_eval = 0
    stopped = False
    weights = np.full(n, 1.0 / n)
    costs = np.zeros(n)
    for layer in range(n_layers):
        costs = _evaluate(f, x, vectorized, layer)
        n_eval += n
        finite = np.isfinite(costs)
        if not finite.any():
            raise CostError(f"cost function returned only infinite costs in layer {layer}")
        i_best = int(np.argmin(costs))
        if costs[i_best] < best_cost:
            best_cost, best_x = float(costs[i_best]), x[i_best].copy()
        beta, weights = _solve_beta(costs - costs[finite].min(), log_q, float(survival_target), survival)
        last = layer == n_layers - 1
        resampled_fraction = math.nan
        sigma_scale = step**layer
        if not last:
            parents = rng.choice(n, size=n, p=weights)
            resampled_fraction = np.unique(parents).size / n
            chol = chol0 * step ** (layer + 1)
            new_x = x[parents] + rng.standard_normal((n, d)) @ chol.T
            new_x = apply_bounds(new_x, lo, hi, boundary)
            if importance_correction:
                with np.errstate(divide="ignore"):
                    log_q = _log_mixture_density(new_x, x, np.log(weights), chol)
        stats = LayerStats(
            layer=layer,
            beta=beta,
            survival=survival_rate(weights, survival),
            resampled_fraction=resampled_fraction,
            best_cost=float(costs[i_best]),
            mean_cost=float(costs[finite].mean()),
            sigma_scale=sigma_scale,
            n_evaluations=n_eval,
        )
        history.append(stats)
        log.debug("APF layer %d: beta=%.4g survival=%.3f best=%.6g mean=%.6g", layer, beta,
                  stats.survival, stats.best_cost, stats.mean_cost)
        if callback is not None and callback(stats):
            stopped = not last
            break
        if not last:
            x = new_x

    mean_x = weights @ x
    map_x = x[int(np.argmax(weights))].copy()
    for arr in (best_x, mean_x, map_x, x, weights, costs):
        arr.flags.writeable = False
    return AnnealedResult(
        x=best_x,
        cost=best_cost,
        mean_x=mean_x,
        map_x=map_x,
        particles=x,
        weights=weights,
        costs=costs,
        layers=tuple(history),
        n_evaluations=n_eval,
        stopped_early=stopped,
    )
