"""Validation and bound handling shared by the optimisers."""

from __future__ import annotations

import numpy as np

__all__ = ["CostError", "apply_bounds", "check_bounds", "check_vector", "make_rng"]


class CostError(RuntimeError):
    """The cost function returned something unusable (NaN, wrong shape)."""


def make_rng(seed) -> np.random.Generator:
    """A Generator from a seed, ``None`` (fresh entropy) or an existing Generator."""
    if isinstance(seed, np.random.Generator):
        return seed
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer))):
        raise ValueError(f"seed: expected an int, None or numpy.random.Generator, got {type(seed).__name__}")
    return np.random.default_rng(seed)


def check_vector(value, name: str, size: int | None = None) -> np.ndarray:
    """A finite ``(D,)`` float64 copy of ``value`` or a ValueError naming ``name``."""
    arr = np.array(value, dtype=np.float64)
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"{name}: expected a non-empty 1-D parameter vector, got shape {arr.shape}")
    if size is not None and arr.shape[0] != size:
        raise ValueError(f"{name}: expected {size} values, got {arr.shape[0]}")
    if not np.isfinite(arr).all():
        j = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise ValueError(f"{name}: non-finite value {arr[j]} at index {j}")
    return arr


def check_bounds(bounds, d: int) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` as two ``(D,)`` arrays; ``None`` means unbounded; ``±inf`` allowed."""
    if bounds is None:
        return np.full(d, -np.inf), np.full(d, np.inf)
    try:
        lo, hi = bounds
    except (TypeError, ValueError):
        raise ValueError("bounds: expected a pair (lo, hi) of (D,) arrays") from None
    lo = np.broadcast_to(np.asarray(lo, dtype=np.float64), (d,)).copy() if np.ndim(lo) == 0 else np.array(lo, float)
    hi = np.broadcast_to(np.asarray(hi, dtype=np.float64), (d,)).copy() if np.ndim(hi) == 0 else np.array(hi, float)
    if lo.shape != (d,) or hi.shape != (d,):
        raise ValueError(f"bounds: expected lo and hi of shape ({d},), got {lo.shape} and {hi.shape}")
    if np.isnan(lo).any() or np.isnan(hi).any():
        raise ValueError("bounds: NaN in lo or hi (use -inf/inf for an unbounded parameter)")
    if (lo > hi).any():
        j = int(np.flatnonzero(lo > hi)[0])
        raise ValueError(f"bounds: parameter {j} has lo {lo[j]} > hi {hi[j]}")
    return lo, hi


def apply_bounds(x: np.ndarray, lo: np.ndarray, hi: np.ndarray, mode: str) -> np.ndarray:
    """Bring samples ``(..., D)`` inside ``[lo, hi]``.

    ``"reflect"`` folds a sample back from the violated bound (repeatedly, so any
    overshoot lands inside; with one infinite side it mirrors about the finite
    one); ``"clip"`` projects onto the box; ``"none"`` leaves samples alone (soft
    constraints: the cost itself penalises limits, e.g. with eq. 6.9).
    """
    if mode == "none":
        return x
    if mode == "clip":
        return np.clip(x, lo, hi)
    x = np.array(x, dtype=np.float64, copy=True)
    both = np.isfinite(lo) & np.isfinite(hi)
    if both.any():
        base = np.where(both, lo, 0.0)
        width = np.where(both, hi - lo, 1.0)
        period = np.where(width > 0, 2.0 * width, 1.0)
        y = np.mod(np.where(both, x, 0.0) - base, period)
        y = np.where(y > width, period - y, y)
        folded = np.where(width > 0, base + y, base)
        x = np.where(both, folded, x)
    low_only = np.isfinite(lo) & ~np.isfinite(hi)
    x = np.where(low_only & (x < lo), 2 * lo - x, x)
    high_only = ~np.isfinite(lo) & np.isfinite(hi)
    x = np.where(high_only & (x > hi), 2 * hi - x, x)
    return x


BOUNDARY_MODES = ("reflect", "clip", "none")
