"""Clothing-robust silhouette cost: inside term plus region-weighted expansion (thesis eq. 6.1–6.4).

Under loose clothing the observed silhouette ``F^o`` bounds the body but need not touch it, so
the symmetric distance of eq. 4.5 is split (eq. 6.1):

- **inside** (eq. 6.2): ``d̃^τ(F^e, F^o)``, the model pixels outside the observed silhouette —
  zero for a body that lies inside its silhouettes, growing as it leaves them;
- **expansion** (eq. 6.3 / 6.4): ``Σ_g λ_g d̃^{τ_g}(F^g, F^e)`` over regions ``g`` of the
  observed silhouette: skin ``F^s`` (``τ_s ≐ τ``, ``λ = 1``: bare skin bounds the body
  tightly) and clothing ``F^o \\ F^s`` with a smaller truncation ``τ_c < τ`` and a small weight
  ``λ_c ≪ 1`` (thesis: 0.1; here 0.01, :data:`CLOTHING_PRESETS`), so the model is only weakly
  asked to fill clothes.

Normalisation (a choice the thesis leaves open): eq. 6.3 as printed divides each region's sum by
that region's own pixel count, so a few hundred skin pixels weigh as much as the whole clothing;
in a 3-frame batch of a tightly clothed simulated man that inflated the chest, waist and hip
girths by 100–120 mm. By default (``normalise="silhouette"``) every region's sum is divided by
the whole observed silhouette's count: with ``τ_c = τ`` and ``λ_c = 1`` (tight clothing) the cost
is then exactly eq. 4.5 (21–55 mm on the same batch), and skin keeps its full per-pixel weight
while clothing pixels get ``λ_c``. Units are those of :mod:`studio.cost.silhouette`
(full-resolution pixels for ξ = 1; levels of a pyramid are comparable).

The model's truncated distance transform is computed once per view on its bounding box grown by
``ceil(max τ_g)`` and truncated per region; pixels outside that window contribute ``τ_g``
exactly (counted from summed-area tables), so the result equals the full-image computation.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from .chamfer import _check_tau, _distance_to, _mask_flag, as_mask, normalise_chamfer
from .silhouette import DEFAULT_TAU, SilhouetteTarget, _bbox, _summed_area, _window_sum, downsample_mask

__all__ = [
    "CLOTHING_PRESETS",
    "ClothingCost",
    "ClothingTarget",
    "clothing_cost",
    "inside_term",
]

#: (τ_c in full-resolution pixels or None for τ, λ_c) per clothing kind: ``tight`` is chapter 4's
#: full expansion everywhere; ``loose`` the down-weighted, short-range clothing term. The thesis
#: gives λ_c = 0.1; with the flat shape prior (eq. 6.8, nothing inside 3 σ) any pull fills the
#: clothes wherever no posture's silhouette holds the body in, and the pull of a clothing ring
#: scales with λ_c · τ_c. Chosen on the dev split of ``benchmarks/clothing.py`` (seeds 3000+,
#: draped garments, shape step with the batch's poses held): λ_c 0.1 / 0.03 / 0.01 / 0.003 gave
#: surface medians 23.3 / 20.3 / 19.9 / 19.7 mm and waist +104 / +42 / +17 / −1 mm, hip +192 /
#: +117 / +81 / +77 mm; τ_c = 2 at λ_c 0.1 21.9 mm. 0.01 sits inside the plateau.
CLOTHING_PRESETS = {"tight": (None, 1.0), "loose": (4.0, 0.01)}


@dataclass(frozen=True, eq=False)
class ClothingTarget:
    """Observed silhouettes of one frame split into expansion regions (eq. 6.4), at one level.

    Attributes
    ----------
    silhouettes : SilhouetteTarget
        ``F^o`` with ``C^τ(F^o)`` for the inside term (eq. 6.2).
    region_names : tuple[str, ...]
        Names of the regions ``g`` (e.g. ``("skin", "clothing")``).
    region_masks : tuple[tuple[(H_l, W_l) bool, ...], ...]
        ``F^g_k`` per region, per view, at this level.
    region_tables : tuple[tuple[(H_l + 1, W_l + 1) int64, ...], ...]
        Summed-area tables of the region masks.
    region_taus : tuple[float, ...]
        ``τ_g`` in full-resolution pixels.
    region_weights : tuple[float, ...]
        ``λ_g``.
    """

    silhouettes: SilhouetteTarget
    region_names: tuple[str, ...]
    region_masks: tuple
    region_tables: tuple
    region_taus: tuple[float, ...]
    region_weights: tuple[float, ...]
    normalise: str = "silhouette"

    @classmethod
    def build(
        cls,
        masks: Sequence[np.ndarray],
        skin: Sequence[np.ndarray | None] | None = None,
        *,
        tau: float = DEFAULT_TAU,
        tau_skin: float | None = None,
        tau_cloth: float | None = None,
        cloth_weight: float = 0.1,
        xi: float = 1.0,
        level: int = 0,
        names: Sequence[str] | None = None,
        mask_size="precise",
        ignore: Sequence[np.ndarray | None] | None = None,
        normalise: str = "silhouette",
    ) -> ClothingTarget:
        """The skin / clothing split of eq. 6.3.

        Parameters
        ----------
        masks : sequence of (H, W) bool
            Observed silhouettes ``F^o_k`` (full resolution).
        skin : sequence of (H, W) bool or None, optional
            Detected skin ``F^s_k`` per view (restricted to ``F^o_k``); None: no skin seen.
        tau : float
            τ of the inside term (pixels).
        tau_skin : float, optional
            ``τ^s`` (default τ).
        tau_cloth : float, optional
            ``τ^c`` (default τ: tight clothing).
        cloth_weight : float
            ``λ_c`` (thesis: 0.1 for loose clothing; 1 for tight).
        ignore : sequence of (H, W) bool or None, optional
            Observed pixels the body need not explain (a stool): left out of every region.
        """
        masks = list(masks.values()) if isinstance(masks, Mapping) else list(masks)
        if not masks:
            raise ValueError("masks: at least one observed view is needed")
        full = [as_mask(m, f"observed mask {k}") for k, m in enumerate(masks)]
        skin = [None] * len(full) if skin is None else list(skin)
        if len(skin) != len(full):
            raise ValueError(f"skin: got {len(skin)} skin masks for {len(full)} observed views")
        skin_full = [np.zeros_like(m) if s is None else as_mask(s, f"skin mask {k}", shape=m.shape) & m
                     for k, (s, m) in enumerate(zip(skin, full, strict=True))]
        cloth_full = [m & ~s for m, s in zip(full, skin_full, strict=True)]
        return cls.build_regions(
            full, {"skin": skin_full, "clothing": cloth_full},
            taus={"skin": tau if tau_skin is None else tau_skin, "clothing": tau if tau_cloth is None else tau_cloth},
            weights={"skin": 1.0, "clothing": cloth_weight}, tau=tau, xi=xi, level=level, names=names,
            mask_size=mask_size, ignore=ignore, normalise=normalise)

    @classmethod
    def build_regions(
        cls,
        masks: Sequence[np.ndarray],
        regions: Mapping[str, Sequence[np.ndarray]],
        *,
        taus: Mapping[str, float],
        weights: Mapping[str, float],
        tau: float = DEFAULT_TAU,
        xi: float = 1.0,
        level: int = 0,
        names: Sequence[str] | None = None,
        mask_size="precise",
        ignore: Sequence[np.ndarray | None] | None = None,
        normalise: str = "silhouette",
    ) -> ClothingTarget:
        """The general expansion of eq. 6.4: ``regions`` {name: per-view (H, W) masks} with a
        truncation ``taus[name]`` (pixels) and a weight ``weights[name]`` each.

        ``normalise``: ``"region"`` divides each region's sum by its own pixel count (eq. 6.3 as
        printed: a small skin region weighs as much as the whole clothing); ``"silhouette"`` (the
        default) divides every region's sum by the whole observed silhouette's count, so that with
        ``τ_g = τ`` and ``λ_g = 1`` the expansion is exactly the observed-to-model term of eq. 4.5.
        """
        if normalise not in ("region", "silhouette"):
            raise ValueError(f"normalise: expected 'region' or 'silhouette', got {normalise!r}")
        sil = SilhouetteTarget.build(masks, tau=tau, xi=xi, level=level, names=names, mask_size=mask_size,
                                     ignore=ignore)
        shape = sil.full_size
        ignore = [None] * len(sil) if ignore is None else list(ignore)
        rnames, rmasks, rtables, rtaus, rweights = [], [], [], [], []
        for name, per_view in regions.items():
            per_view = list(per_view)
            if len(per_view) != len(sil):
                raise ValueError(f"region {name!r}: got {len(per_view)} masks for {len(sil)} views")
            if name not in taus or name not in weights:
                raise ValueError(f"region {name!r}: needs a truncation in taus and a weight in weights")
            weight = float(weights[name])
            if not math.isfinite(weight) or weight < 0:
                raise ValueError(f"region {name!r}: weight must be finite and >= 0, got {weight}")
            level_masks, tables = [], []
            for k, (m, skip) in enumerate(zip(per_view, ignore, strict=True)):
                m = as_mask(m, f"region {name!r} mask of view {sil.names[k]!r}", shape=shape)
                if skip is not None:
                    m = m & ~as_mask(skip, f"ignore mask of view {sil.names[k]!r}", shape=shape)
                m = downsample_mask(m, level) if level else m.copy()
                table = _summed_area(m)
                m.flags.writeable = False
                table.flags.writeable = False
                level_masks.append(m)
                tables.append(table)
            rnames.append(str(name))
            rmasks.append(tuple(level_masks))
            rtables.append(tuple(tables))
            rtaus.append(_check_tau(taus[name]))
            rweights.append(weight)
        return cls(sil, tuple(rnames), tuple(rmasks), tuple(rtables), tuple(rtaus), tuple(rweights), normalise)

    # the parts of SilhouetteTarget's interface the fitter uses
    @property
    def names(self) -> tuple[str, ...]:
        return self.silhouettes.names

    @property
    def level(self) -> int:
        return self.silhouettes.level

    @property
    def image_size(self) -> tuple[int, int]:
        return self.silhouettes.image_size

    @property
    def masks(self) -> tuple[np.ndarray, ...]:
        return self.silhouettes.masks

    def __len__(self) -> int:
        return len(self.silhouettes)


@dataclass(frozen=True)
class ClothingCost:
    """Per-view terms of eq. 6.1 in full-resolution units.

    ``inside`` (K,) eq. 6.2; ``expansion`` {region: (K,)} the unweighted ``d̃^{τ_g}(F^g, F^e)``;
    ``weights`` {region: λ_g}; ``model_counts`` (K,) ``|F^e_k|`` at the target's level.
    """

    names: tuple[str, ...]
    inside: np.ndarray
    expansion: dict
    weights: dict
    model_counts: np.ndarray

    @property
    def expand(self) -> np.ndarray:
        """``E_expand`` per view (eq. 6.3 / 6.4), (K,)."""
        out = np.zeros(len(self.names))
        for g, value in self.expansion.items():
            out += self.weights[g] * value
        return out

    @property
    def per_view(self) -> np.ndarray:
        """``E^k_1pose = E_inside + E_expand`` (eq. 6.1), (K,)."""
        return self.inside + self.expand

    @property
    def total(self) -> float:
        """Sum over views (eq. 6.6 for one pose)."""
        return float(self.per_view.sum())

    def as_dict(self) -> dict:
        return {
            "total": self.total,
            "inside": float(self.inside.sum()),
            "expansion": {g: float(v.sum()) for g, v in self.expansion.items()},
            "weights": dict(self.weights),
            "views": {n: float(v) for n, v in zip(self.names, self.per_view, strict=True)},
        }


def clothing_cost(target: ClothingTarget, model_masks: Sequence[np.ndarray]) -> ClothingCost:
    """Score model silhouettes ``F^e_k`` (one per view at the target's level) by eq. 6.1–6.4."""
    if not isinstance(target, ClothingTarget):
        raise TypeError(f"target: expected a ClothingTarget, got {type(target).__name__}")
    if isinstance(model_masks, Mapping):
        model_masks = [model_masks[n] for n in target.names]
    model_masks = list(model_masks)
    sil = target.silhouettes
    if len(model_masks) != len(sil):
        raise ValueError(f"model_masks: got {len(model_masks)} model masks for {len(sil)} observed views")
    s = sil.scale
    flag = _mask_flag(sil.mask_size)
    taus = [t / s for t in target.region_taus]
    reach = int(math.ceil(max(taus))) if taus else 0
    by_region = target.normalise == "region"
    inside = np.zeros(len(sil))
    expansion = {g: np.zeros(len(sil)) for g in target.region_names}
    counts = np.zeros(len(sil), dtype=np.int64)
    for k, model in enumerate(model_masks):
        model = as_mask(model, f"model mask of view {sil.names[k]!r} (level {sil.level})", shape=sil.image_size)
        box = _bbox(model)
        n_obs = sil.counts[k]
        if box is None:
            for g, tau_g, tables in zip(target.region_names, taus, target.region_tables, strict=True):
                n_g = int(tables[k][-1, -1])
                expansion[g][k] = normalise_chamfer(tau_g * n_g, n_g if by_region else n_obs, sil.xi)
            continue
        r0, r1, c0, c1 = box
        inner = model[r0:r1, c0:c1]
        counts[k] = int(np.count_nonzero(inner))
        fwd = float(np.sum(sil.distance_maps[k][r0:r1, c0:c1], where=inner, dtype=np.float64))
        inside[k] = normalise_chamfer(fwd, int(counts[k]), sil.xi)
        h, w = model.shape
        R0, R1, C0, C1 = max(r0 - reach, 0), min(r1 + reach, h), max(c0 - reach, 0), min(c1 + reach, w)
        dist = _distance_to(model[R0:R1, C0:C1], max(taus), flag) if taus else None
        for g, tau_g, region, tables in zip(target.region_names, taus, target.region_masks, target.region_tables,
                                            strict=True):
            n_g = int(tables[k][-1, -1])
            if n_g == 0:
                continue
            n_in = _window_sum(tables[k], R0, R1, C0, C1)
            near = float(np.sum(np.minimum(dist, np.float32(tau_g)), where=region[k][R0:R1, C0:C1],
                                dtype=np.float64))
            expansion[g][k] = normalise_chamfer(tau_g * (n_g - n_in) + near, n_g if by_region else n_obs, sil.xi)
    factor = sil.unit_factor
    return ClothingCost(names=sil.names, inside=inside * factor,
                        expansion={g: v * factor for g, v in expansion.items()},
                        weights=dict(zip(target.region_names, target.region_weights, strict=True)),
                        model_counts=counts)


def inside_term(target, model_masks: Sequence[np.ndarray]) -> float:
    """``Σ_k E^k_inside`` (eq. 6.2) of model silhouettes against a :class:`ClothingTarget` or a
    :class:`~studio.cost.SilhouetteTarget`: 0 when every model pixel lies inside the observed
    silhouettes, growing (up to τ per pixel) as the model leaves them."""
    if isinstance(target, ClothingTarget):
        return float(clothing_cost(target, model_masks).inside.sum())
    from .silhouette import silhouette_cost

    return float(silhouette_cost(target, model_masks).model_to_observed.sum())
