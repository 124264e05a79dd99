"""Shape and pose priors (thesis eq. 6.8, 6.9) and the combined cost report.

Units: the priors are dimensionless squared (hinged) Mahalanobis distances:
the shape coefficients are divided by the PCA standard deviations
``σ_b = sqrt(eigenvalue_b)``, pose parameters (radians, metres for the root) by
per-parameter sigmas in the same units, or whitened by a full covariance. The
silhouette term is in pixels (see :mod:`studio.cost.chamfer`), so the weights
of :func:`combine_costs` carry units of pixels per unit Mahalanobis².

All functions accept one vector ``(D,)`` or a batch ``(..., D)`` and return a
float or an array of the leading shape (useful for particle filters).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "CostTerms",
    "PosePrior",
    "PriorTerms",
    "combine_costs",
    "gaussian_penalty",
    "mahalanobis_squared",
    "pose_deviation_penalty",
    "pose_limit_penalty",
    "shape_prior",
]


def _vector(value, name: str, size: int | None = None, *, allow_inf: bool = False) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D vector, got shape {arr.shape}")
    if size is not None and arr.shape[0] != size:
        raise ValueError(f"{name}: expected {size} values, got {arr.shape[0]}")
    bad = np.isnan(arr) if allow_inf else ~np.isfinite(arr)
    if bad.any():
        what = "NaN" if allow_inf else "NaN or infinite"
        raise ValueError(f"{name}: {what} value at index {int(np.flatnonzero(bad)[0])}")
    return arr


def _params(value, name: str, size: int | None = None) -> np.ndarray:
    """Parameters ``(..., D)`` float64, finite."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        raise ValueError(f"{name}: expected a parameter vector (D,) or batch (..., D), got a scalar")
    if size is not None and arr.shape[-1] != size:
        raise ValueError(f"{name}: expected {size} parameters in the last axis, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name}: parameters contain NaN or infinite values")
    return arr


def _positive(value, name: str, size: int | None) -> np.ndarray:
    arr = _vector(value, name, size)
    if (arr <= 0).any():
        raise ValueError(f"{name}: standard deviations must be positive, got {arr[arr <= 0][0]} at index "
                         f"{int(np.flatnonzero(arr <= 0)[0])}")
    return arr


def _out(value: np.ndarray):
    return float(value) if value.ndim == 0 else value


def mahalanobis_squared(x, mean, sigma):
    """Squared Mahalanobis distance with a diagonal covariance: ``Σ_j ((x_j − μ_j)/σ_j)²``.

    ``x`` is ``(D,)`` or ``(..., D)``; ``mean`` and ``sigma`` are ``(D,)``.

    >>> mahalanobis_squared([1.0, -4.0], [0.0, 0.0], [1.0, 2.0])
    5.0
    """
    x = _params(x, "x")
    d = x.shape[-1]
    mean = _vector(mean, "mean", d)
    sigma = _positive(sigma, "sigma", d)
    return _out(np.sum(((x - mean) / sigma) ** 2, axis=-1))


def shape_prior(beta, sigma, threshold: float = 3.0):
    """Shape prior of eq. 6.8: ``Σ_b max(0, |β_b|/σ_b − σ_thresh)²``.

    Flat for shapes within ``threshold`` standard deviations of the mean on every
    PCA axis; ``threshold = 0`` gives the squared Mahalanobis distance to the mean
    shape (the Gaussian prior the thesis avoids because it biases toward the mean).

    Parameters
    ----------
    beta : (B,) or (..., B) float
        Shape coefficients.
    sigma : (B,) float
        PCA standard deviations ``sqrt(eigenvalue)`` in the units of ``beta``.
    threshold : float
        ``σ_β^thresh`` (thesis: 3).
    """
    beta = _params(beta, "beta")
    sigma = _positive(sigma, "sigma", beta.shape[-1])
    threshold = _threshold(threshold)
    excess = np.maximum(0.0, np.abs(beta) / sigma - threshold)
    return _out(np.sum(excess**2, axis=-1))


def _threshold(value) -> float:
    value = float(value)
    if not np.isfinite(value) or value < 0:
        raise ValueError(f"threshold: expected a finite number of standard deviations >= 0, got {value}")
    return value


def _limits(lower, upper, d: int) -> tuple[np.ndarray, np.ndarray]:
    """Joint limits ``(D,)`` each (``±inf`` allowed, ``lower <= upper``: equal limits fix a parameter)."""
    lower = _vector(lower, "lower", d, allow_inf=True)
    upper = _vector(upper, "upper", d, allow_inf=True)
    if (lower > upper).any():
        j = int(np.flatnonzero(lower > upper)[0])
        raise ValueError(f"lower/upper: limit {j} has lower {lower[j]} > upper {upper[j]}")
    return lower, upper


def pose_limit_penalty(theta, lower, upper, sigma):
    """First term of eq. 6.9: ``Σ_j (max(0, θ_j^min − θ_j, θ_j − θ_j^max) / σ_j)²``.

    Zero inside the joint limits (a uniform prior there). ``lower``/``upper`` may
    hold ``-inf``/``inf`` for unlimited parameters (e.g. root translation).
    """
    theta = _params(theta, "theta")
    d = theta.shape[-1]
    lower, upper = _limits(lower, upper, d)
    sigma = _positive(sigma, "sigma", d)
    excess = np.maximum(0.0, np.maximum(lower - theta, theta - upper))
    return _out(np.sum((excess / sigma) ** 2, axis=-1))


def pose_deviation_penalty(theta, theta0, sigma, threshold: float = 3.0):
    """Second term of eq. 6.9 (without ``w``): ``Σ_j max(0, |θ_j − θ⁰_j|/σ_j − σ_thresh)²``."""
    theta = _params(theta, "theta")
    d = theta.shape[-1]
    theta0 = _vector(theta0, "theta0", d)
    sigma = _positive(sigma, "sigma", d)
    threshold = _threshold(threshold)
    excess = np.maximum(0.0, np.abs(theta - theta0) / sigma - threshold)
    return _out(np.sum(excess**2, axis=-1))


def gaussian_penalty(x, mean, cov, threshold: float = 0.0):
    """Hinged Mahalanobis penalty with a full covariance: ``max(0, r − thresh)²``, ``r² = dᵀ Σ⁻¹ d``.

    With ``threshold = 0`` this is the squared Mahalanobis distance
    ``(x − μ)ᵀ Σ⁻¹ (x − μ)``, i.e. twice the negative log-density of a Gaussian pose
    prior up to a constant. ``cov`` must be symmetric positive definite.
    """
    x = _params(x, "x")
    d = x.shape[-1]
    mean = _vector(mean, "mean", d)
    chol = _cholesky(cov, d)
    return _hinged_whitened(x - mean, chol, _threshold(threshold))


def _cholesky(cov, d: int) -> np.ndarray:
    cov = np.asarray(cov, dtype=np.float64)
    if cov.shape != (d, d):
        raise ValueError(f"cov: expected a ({d}, {d}) covariance, got shape {cov.shape}")
    if not np.isfinite(cov).all() or not np.allclose(cov, cov.T, rtol=1e-10, atol=1e-12):
        raise ValueError("cov: the covariance must be finite and symmetric")
    try:
        return np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        raise ValueError("cov: the covariance is not positive definite") from None


def _hinged_whitened(diff: np.ndarray, chol: np.ndarray, threshold: float):
    """``max(0, r − threshold)²`` with ``r² = dᵀ (L Lᵀ)⁻¹ d`` for differences ``d`` ``(..., D)``."""
    from scipy.linalg import solve_triangular

    d = chol.shape[0]
    white = solve_triangular(chol, diff.reshape(-1, d).T, lower=True)
    r = np.sqrt(np.sum(white**2, axis=0)).reshape(diff.shape[:-1])
    return _out(np.maximum(0.0, r - threshold) ** 2)


@dataclass(frozen=True)
class PriorTerms:
    """Terms of a pose prior: ``limits`` and ``deviation`` (already multiplied by ``weight``)."""

    limits: float | np.ndarray
    deviation: float | np.ndarray

    @property
    def total(self):
        return self.limits + self.deviation


@dataclass(frozen=True, eq=False)
class PosePrior:
    """Generic pose prior: joint limits plus an optional deviation from a reference pose (eq. 6.9).

    ``E_pose(θ) = Σ_j (max(0, θ^min_j − θ_j, θ_j − θ^max_j)/σ_j)² + w · dev(θ)``

    where ``dev`` is eq. 6.9's per-parameter hinge
    ``Σ_j max(0, |θ_j − θ⁰_j|/σ_j − thresh)²`` when no ``cov`` is given, or the
    full-covariance hinge ``max(0, sqrt((θ − θ⁰)ᵀ Σ⁻¹ (θ − θ⁰)) − thresh)²`` when it
    is (with ``threshold = 0`` that is the Gaussian prior's squared Mahalanobis
    distance). Without ``mean`` the deviation term is 0 (the thesis's ``w = 0``
    when no initial pose is known).

    Attributes
    ----------
    lower, upper : (D,) float
        Joint limits (``±inf`` allowed).
    sigma : (D,) float
        Per-parameter standard deviations (radians / metres).
    mean : (D,) float or None
        Reference pose ``θ⁰``.
    cov : (D, D) float or None
        Full covariance for the deviation term.
    weight : float
        ``w`` of eq. 6.9.
    threshold : float
        ``σ_θ^thresh`` (thesis: 3).
    """

    lower: np.ndarray
    upper: np.ndarray
    sigma: np.ndarray
    mean: np.ndarray | None = None
    cov: np.ndarray | None = None
    weight: float = 1.0
    threshold: float = 3.0
    _chol: np.ndarray | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        sigma = _positive(self.sigma, "sigma", None)
        d = sigma.shape[0]
        lower, upper = _limits(self.lower, self.upper, d)
        mean = None if self.mean is None else _vector(self.mean, "mean", d)
        chol = None
        if self.cov is not None:
            if mean is None:
                raise ValueError("cov: a covariance needs a mean (reference pose) to deviate from")
            chol = _cholesky(self.cov, d)
        weight = float(self.weight)
        if not np.isfinite(weight) or weight < 0:
            raise ValueError(f"weight: expected a finite weight >= 0, got {weight}")
        for name, value in (("lower", lower), ("upper", upper), ("sigma", sigma), ("mean", mean)):
            if value is not None:
                value.flags.writeable = False
            object.__setattr__(self, name, value)
        object.__setattr__(self, "weight", weight)
        object.__setattr__(self, "threshold", _threshold(self.threshold))
        object.__setattr__(self, "_chol", chol)

    @property
    def size(self) -> int:
        return self.sigma.shape[0]

    def terms(self, theta) -> PriorTerms:
        """Both terms for ``theta`` ``(D,)`` or ``(..., D)``."""
        theta = _params(theta, "theta", self.size)
        limits = pose_limit_penalty(theta, self.lower, self.upper, self.sigma)
        if self.mean is None or self.weight == 0:
            deviation = np.zeros(theta.shape[:-1]) if theta.ndim > 1 else 0.0
        elif self._chol is None:
            deviation = self.weight * pose_deviation_penalty(theta, self.mean, self.sigma, self.threshold)
        else:
            deviation = self.weight * _hinged_whitened(theta - self.mean, self._chol, self.threshold)
        return PriorTerms(limits=limits, deviation=deviation)

    def __call__(self, theta):
        """``E_pose(θ)`` (eq. 6.9)."""
        return self.terms(theta).total


@dataclass(frozen=True)
class CostTerms:
    """The objective of eq. 6.7 term by term: ``total = silhouette + λ_s·shape + λ_p·pose``.

    ``silhouette`` is in pixels (eq. 4.6), ``shape`` and ``pose`` are
    dimensionless prior values (eq. 6.8, 6.9) *before* weighting.
    """

    silhouette: float
    shape: float
    pose: float
    shape_weight: float
    pose_weight: float

    @property
    def total(self) -> float:
        return self.silhouette + self.shape_weight * self.shape + self.pose_weight * self.pose

    def as_dict(self) -> dict:
        return {
            "silhouette": self.silhouette,
            "shape_prior": self.shape,
            "pose_prior": self.pose,
            "shape_weight": self.shape_weight,
            "pose_weight": self.pose_weight,
            "total": self.total,
        }


def combine_costs(
    silhouette: float, shape: float = 0.0, pose: float = 0.0, *, shape_weight: float = 1.0, pose_weight: float = 1.0
) -> CostTerms:
    """Assemble eq. 6.7's terms (each reported separately) with explicit weights."""
    values = {"silhouette": silhouette, "shape": shape, "pose": pose,
              "shape_weight": shape_weight, "pose_weight": pose_weight}
    for name, value in values.items():
        value = float(value)
        if np.isnan(value):
            raise ValueError(f"{name}: cost term is NaN")
        if name.endswith("weight") and (value < 0 or not np.isfinite(value)):
            raise ValueError(f"{name}: expected a finite weight >= 0, got {value}")
        values[name] = value
    return CostTerms(**values)
