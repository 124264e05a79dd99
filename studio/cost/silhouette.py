"""Multi-view silhouette cost against a precomputed observation (thesis eq. 4.4–4.6).

A :class:`SilhouetteTarget` holds, for one frame, everything about the OBSERVED
silhouettes ``F^o_k`` that does not depend on the model: the masks, their
truncated distance transforms ``C^τ(F^o_k)`` and summed-area tables. It is built
once per frame; :func:`silhouette_cost` then scores the model silhouettes
``F^e_k`` rendered for one parameter vector:

- ``d̃^τ(F^e, F^o)`` sums the precomputed ``C^τ(F^o)`` over the model's pixels
  (restricted to the model's bounding box);
- ``d̃^τ(F^o, F^e)`` needs ``C^τ(F^e)``, which changes with every hypothesis. It is
  computed only on the model's bounding box grown by ``ceil(τ)`` pixels: every
  pixel outside that window is more than τ from the model, so it contributes
  exactly τ, and the number of observed pixels outside the window comes from the
  summed-area table in O(1). The result equals the full-image computation.

The distance transform of the observed silhouette's complement is not needed by
eq. 4.5 (neither direction measures distances inside ``F^o``), so it is not
stored.

Typical use, once per frame and then once per hypothesis::

    target = SilhouetteTarget.build(observed_masks, tau=20.0, xi=1.0, names=camera_names)
    cost = silhouette_cost(target, [render(camera, params) for camera in cameras])
    cost.total, cost.per_view, cost.as_dict()

Pyramid levels (coarse-to-fine, thesis §7.2.3): a target at level ``l`` holds
the observed masks reduced by ``s = 2^l`` (block average ≥ 1/2, padded with
background to a multiple of ``s``), with τ expressed in level pixels (τ/s). The
model must then be rendered at the level's ``image_size`` with intrinsics
``K_l = [[1/s, 0, (1/s − 1)/2], [0, 1/s, (1/s − 1)/2], [0, 0, 1]] · K`` (pixel
centres: ``x_l = (x + 0.5)/s − 0.5``). Costs are reported in FULL-resolution
units: a level-``l`` value is multiplied by ``s^(3 − 2ξ)`` (distances scale by
``s``, pixel counts by ``s²``), so levels are comparable (exactly so for ξ = 3/2).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from .chamfer import _check_tau, _check_xi, _distance_to, _mask_flag, as_mask, normalise_chamfer
from .view_terms import view_numerators

__all__ = [
    "DEFAULT_TAU",
    "SilhouetteCost",
    "SilhouetteTarget",
    "downsample_mask",
    "silhouette_cost",
    "silhouette_pyramid",
]

#: Default truncation τ in full-resolution pixels (thesis: 20 px for 800×600 images).
DEFAULT_TAU = 20.0


def downsample_mask(mask: np.ndarray, level: int) -> np.ndarray:
    """Reduce a bool mask by ``2**level`` (block average ≥ 1/2).

    The mask is padded with background to a multiple of the block size, so the
    result is ``(ceil(H / s), ceil(W / s))`` bool and pixel ``(i, j)`` of the result
    covers full-resolution pixels ``[s·i, s·i + s) × [s·j, s·j + s)``.

    A block exactly half covered counts as covered, so a reduced silhouette is about half a
    full-resolution pixel wider per edge than the model's own silhouette rendered at that level
    (:func:`studio.render.pyramid.level_camera` samples at block centres): measured on fitted
    bodies, +3.2 % of the area at level 1, +2.0 % at level 2. Breaking the ties on a checkerboard
    of blocks removes it (+0.1 %), but was not better for the fit on dev (README, *Shape under
    clothing*: the search is chosen with this pyramid and every fit ends at full resolution).
    """
    level = _check_level(level)
    mask = as_mask(mask, "mask")
    if level == 0:
        return mask.copy()
    s = 1 << level
    h, w = mask.shape
    hl, wl = -(-h // s), -(-w // s)
    padded = np.zeros((hl * s, wl * s), dtype=np.uint8)
    padded[:h, :w] = mask
    counts = padded.reshape(hl, s, wl, s).sum(axis=(1, 3), dtype=np.int32)
    return counts * 2 >= s * s


def _check_level(level: int) -> int:
    if isinstance(level, bool) or not isinstance(level, (int, np.integer)) or not 0 <= level <= 8:
        raise ValueError(f"level: expected an integer pyramid level in 0..8, got {level!r}")
    return int(level)


def _summed_area(mask: np.ndarray) -> np.ndarray:
    """``(H + 1, W + 1) int64`` table with ``A[i, j] = Σ mask[:i, :j]``."""
    table = np.zeros((mask.shape[0] + 1, mask.shape[1] + 1), dtype=np.int64)
    np.cumsum(np.cumsum(mask, axis=0, dtype=np.int64), axis=1, out=table[1:, 1:])
    return table


def _window_sum(table: np.ndarray, r0: int, r1: int, c0: int, c1: int) -> int:
    """``Σ mask[r0:r1, c0:c1]`` from its :func:`_summed_area` table."""
    return int(table[r1, c1] - table[r0, c1] - table[r1, c0] + table[r0, c0])


@dataclass(frozen=True, eq=False)
class SilhouetteTarget:
    """Observed silhouettes of one frame, precomputed for fast scoring (eq. 4.4–4.6).

    Build with :meth:`build` (or :func:`silhouette_pyramid`). All per-view arrays
    are read-only and live at the target's pyramid ``level``.

    Attributes
    ----------
    names : tuple[str, ...]
        View (camera) names, in the order model masks must be given.
    masks : tuple[(H_l, W_l) bool, ...]
        Observed silhouettes ``F^o_k`` at this level that the model must explain (the
        observed-to-model direction): the silhouettes less any ``ignore`` region.
    distance_maps : tuple[(H_l, W_l) float32, ...]
        ``C^τ(F^o_k)`` of the whole observed silhouettes, ignored regions included, in level
        pixels (0 inside, capped at ``tau_level``): the model may cover them freely.
    summed_areas : tuple[(H_l + 1, W_l + 1) int64, ...]
        Summed-area tables of the observed masks.
    counts : tuple[int, ...]
        ``|F^o_k|`` at this level.
    tau : float
        Truncation threshold τ in full-resolution pixels.
    xi : float
        Normalisation exponent ξ of eq. 4.4 (1 or 3/2).
    level : int
        Pyramid level; the image is reduced by ``2**level``.
    full_size : (int, int)
        Full-resolution image size ``(H, W)``.
    mask_size : 3, 5 or "precise"
        OpenCV distance mask used for both directions.
    """

    names: tuple[str, ...]
    masks: tuple[np.ndarray, ...]
    distance_maps: tuple[np.ndarray, ...]
    summed_areas: tuple[np.ndarray, ...]
    counts: tuple[int, ...]
    tau: float
    xi: float
    level: int
    full_size: tuple[int, int]
    mask_size: object

    @classmethod
    def build(
        cls,
        masks: Sequence[np.ndarray],
        *,
        tau: float = DEFAULT_TAU,
        xi: float = 1.0,
        level: int = 0,
        names: Sequence[str] | None = None,
        mask_size="precise",
        ignore: Sequence[np.ndarray | None] | None = None,
    ) -> SilhouetteTarget:
        """Precompute the observed side of eq. 4.5 for every view.

        Parameters
        ----------
        masks : sequence of (H, W) bool, or mapping {view name: (H, W) bool}
            Observed full-resolution silhouettes ``F^o_k``, one per view, all the
            same size.
        tau : float
            Truncation τ in full-resolution pixels.
        xi : float
            Exponent ξ of eq. 4.4 (1: mean distance; 3/2: depth invariant).
        level : int
            Pyramid level to score at (0 = full resolution).
        names : sequence of str, optional
            View names (default ``"view0"``, ``"view1"``, ...).
        mask_size : {3, 5, "precise"}
            OpenCV distance mask.
        ignore : sequence of (H, W) bool or None, optional
            Per view, observed pixels the model need not explain — e.g. a stool under a
            seated person (:func:`studio.fit.props.find_support`): left out of the
            observed-to-model direction, still inside the silhouette for the model-to-observed
            one (the model may cover them; a prop can hide the body).
        """
        tau = _check_tau(tau)
        xi = _check_xi(xi)
        level = _check_level(level)
        flag = _mask_flag(mask_size)
        if isinstance(masks, np.ndarray) and masks.ndim == 2:
            raise ValueError("masks: expected a sequence of (H, W) masks, one per view, got a single 2-D array")
        if isinstance(masks, Mapping):
            if names is not None:
                raise ValueError("names: give either a {name: mask} mapping or names, not both")
            names = list(masks.keys())
            masks = list(masks.values())
        masks = list(masks)
        if not masks:
            raise ValueError("masks: at least one observed view is needed")
        if names is None:
            names = [f"view{k}" for k in range(len(masks))]
        names = tuple(str(n) for n in names)
        if len(names) != len(masks):
            raise ValueError(f"names: got {len(names)} names for {len(masks)} observed masks")
        full = as_mask(masks[0], f"observed mask of view {names[0]!r}")
        full_size = full.shape
        tau_level = tau / (1 << level)
        ignore = [None] * len(masks) if ignore is None else list(ignore)
        if len(ignore) != len(masks):
            raise ValueError(f"ignore: got {len(ignore)} masks for {len(masks)} observed views")
        level_masks, dmaps, tables, counts = [], [], [], []
        for name, mask, skip in zip(names, masks, ignore, strict=True):
            mask = as_mask(mask, f"observed mask of view {name!r}", shape=full_size)
            mask = downsample_mask(mask, level) if level else mask.copy()
            dist = _distance_to(mask, tau_level, flag)
            if skip is not None:
                skip = as_mask(skip, f"ignore mask of view {name!r}", shape=full_size)
                mask &= ~(downsample_mask(skip, level) if level else skip)
            table = _summed_area(mask)
            for arr in (mask, dist, table):
                arr.flags.writeable = False
            level_masks.append(mask)
            dmaps.append(dist)
            tables.append(table)
            counts.append(int(table[-1, -1]))
        return cls(
            names=names,
            masks=tuple(level_masks),
            distance_maps=tuple(dmaps),
            summed_areas=tuple(tables),
            counts=tuple(counts),
            tau=tau,
            xi=xi,
            level=level,
            full_size=(int(full_size[0]), int(full_size[1])),
            mask_size=mask_size,
        )

    @property
    def image_size(self) -> tuple[int, int]:
        """``(H_l, W_l)``: the size model masks must have at this level."""
        return self.masks[0].shape

    @property
    def scale(self) -> int:
        """Reduction factor ``s = 2**level``."""
        return 1 << self.level

    @property
    def tau_level(self) -> float:
        """τ in this level's pixels."""
        return self.tau / self.scale

    @property
    def unit_factor(self) -> float:
        """Factor ``s^(3 − 2ξ)`` converting level values of eq. 4.4 to full-resolution units."""
        return float(self.scale) ** (3.0 - 2.0 * self.xi)

    def __len__(self) -> int:
        return len(self.masks)


@dataclass(frozen=True)
class SilhouetteCost:
    """Per-view terms of the silhouette cost, in full-resolution units (see module docstring).

    Attributes
    ----------
    names : tuple[str, ...]
        View names.
    model_to_observed : (K,) float64
        ``d̃^τ(F^e_k, F^o_k)``: model pixels outside the observed silhouette (eq. 4.4).
    observed_to_model : (K,) float64
        ``d̃^τ(F^o_k, F^e_k)``: observed pixels the model does not explain.
    model_counts : (K,) int64
        ``|F^e_k|`` at the target's level (0 flags a model that left the view).
    """

    names: tuple[str, ...]
    model_to_observed: np.ndarray
    observed_to_model: np.ndarray
    model_counts: np.ndarray

    @property
    def per_view(self) -> np.ndarray:
        """``D(F^e_k, F^o_k)`` per view (eq. 4.5), ``(K,) float64``."""
        return self.model_to_observed + self.observed_to_model

    @property
    def total(self) -> float:
        """``E = Σ_k D(F^e_k, F^o_k)`` (eq. 4.6)."""
        return float(self.per_view.sum())

    def as_dict(self) -> dict:
        """Plain-Python per-term report (for ``fit/<frame>.json``)."""
        return {
            "total": self.total,
            "views": {
                name: {
                    "model_to_observed": float(a),
                    "observed_to_model": float(b),
                    "model_pixels": int(n),
                }
                for name, a, b, n in zip(
                    self.names, self.model_to_observed, self.observed_to_model, self.model_counts, strict=True
                )
            },
        }


def _bbox(mask: np.ndarray) -> tuple[int, int, int, int] | None:
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return None
    cols = np.flatnonzero(mask.any(axis=0))
    return int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1


def _score_view(target: SilhouetteTarget, k: int, model: np.ndarray) -> tuple[float, float, int]:
    """Numerators of both directions and ``|F^e|`` for view ``k`` (level units): the compiled
    pass of :mod:`studio.cost.view_terms` for the exact distance (``mask_size="precise"``),
    else :func:`_score_view_reference`."""
    if target.mask_size != "precise":
        return _score_view_reference(target, k, model)
    return view_numerators(model, target.masks[k], target.distance_maps[k], target.tau_level, target.counts[k])


def _score_view_reference(target: SilhouetteTarget, k: int, model: np.ndarray) -> tuple[float, float, int]:
    """:func:`_score_view` in NumPy and OpenCV: masked sums over the model's box and the
    distance transform of the model on the box grown by ``ceil(τ)``."""
    tau = target.tau_level
    n_obs = target.counts[k]
    box = _bbox(model)
    if box is None:
        return 0.0, tau * n_obs, 0
    r0, r1, c0, c1 = box
    model_box = model[r0:r1, c0:c1]
    n_model = int(np.count_nonzero(model_box))
    # d(F^e, F^o): sum the precomputed C^τ(F^o) over the model's pixels.
    forward = float(np.sum(target.distance_maps[k][r0:r1, c0:c1], where=model_box, dtype=np.float64))
    if n_obs == 0:
        return forward, 0.0, n_model
    # d(F^o, F^e): C^τ(F^e) on the model's box grown by ceil(τ); outside it, every pixel is > τ away.
    h, w = model.shape
    m = int(math.ceil(tau))
    R0, R1, C0, C1 = max(r0 - m, 0), min(r1 + m, h), max(c0 - m, 0), min(c1 + m, w)
    table = target.summed_areas[k]
    n_inside = _window_sum(table, R0, R1, C0, C1)
    dist = _distance_to(model[R0:R1, C0:C1], tau, _mask_flag(target.mask_size))
    backward = tau * (n_obs - n_inside) + float(
        np.sum(dist, where=target.masks[k][R0:R1, C0:C1], dtype=np.float64)
    )
    return forward, backward, n_model


def silhouette_cost(target: SilhouetteTarget, model_masks: Sequence[np.ndarray]) -> SilhouetteCost:
    """Score model silhouettes against a precomputed observation (eq. 4.4–4.6).

    Parameters
    ----------
    target : SilhouetteTarget
        The observed frame (at some pyramid level).
    model_masks : sequence of (H_l, W_l) bool, or mapping {view name: mask}
        Model silhouettes ``F^e_k``, one per view in ``target.names`` order (or
        by name), at the target's ``image_size``.

    Returns
    -------
    SilhouetteCost
        Both directions per view in full-resolution units; ``.total`` is eq. 4.6.
    """
    if not isinstance(target, SilhouetteTarget):
        raise TypeError(f"target: expected a SilhouetteTarget, got {type(target).__name__}")
    if isinstance(model_masks, np.ndarray) and model_masks.ndim == 2:
        raise ValueError("model_masks: expected a sequence of (H, W) masks, one per view, got a single 2-D array")
    if isinstance(model_masks, Mapping):
        missing = [name for name in target.names if name not in model_masks]
        if missing:
            raise ValueError(f"model_masks: no model mask for views {missing} (have {list(model_masks)})")
        model_masks = [model_masks[name] for name in target.names]
    model_masks = list(model_masks)
    if len(model_masks) != len(target):
        raise ValueError(
            f"model_masks: got {len(model_masks)} model masks for {len(target)} observed views {list(target.names)}"
        )
    k_views = len(target)
    forward = np.empty(k_views)
    backward = np.empty(k_views)
    counts = np.empty(k_views, dtype=np.int64)
    for k, (name, model) in enumerate(zip(target.names, model_masks, strict=True)):
        model = as_mask(model, f"model mask of view {name!r} (level {target.level})", shape=target.image_size)
        fwd, bwd, n_model = _score_view(target, k, model)
        forward[k] = normalise_chamfer(fwd, n_model, target.xi)
        backward[k] = normalise_chamfer(bwd, target.counts[k], target.xi)
        counts[k] = n_model
    factor = target.unit_factor
    return SilhouetteCost(
        names=target.names,
        model_to_observed=forward * factor,
        observed_to_model=backward * factor,
        model_counts=counts,
    )


def silhouette_pyramid(
    masks: Sequence[np.ndarray],
    *,
    levels: int = 3,
    tau: float = DEFAULT_TAU,
    xi: float = 1.0,
    names: Sequence[str] | None = None,
    mask_size="precise",
) -> tuple[SilhouetteTarget, ...]:
    """Targets at levels ``0 .. levels - 1`` (finest first) for coarse-to-fine fitting (§7.2.3)."""
    if isinstance(levels, bool) or not isinstance(levels, (int, np.integer)) or not 1 <= levels <= 9:
        raise ValueError(f"levels: expected the number of pyramid levels in 1..9, got {levels!r}")
    return tuple(
        SilhouetteTarget.build(masks, tau=tau, xi=xi, level=level, names=names, mask_size=mask_size)
        for level in range(int(levels))
    )
