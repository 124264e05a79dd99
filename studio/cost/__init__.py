"""Cost terms for fitting a body to silhouettes (thesis §4.6, §6.3.2–6.3.3).

- :mod:`~studio.cost.chamfer`: truncated chamfer distance ``d̃^τ`` (eq. 4.4) and the
  symmetric silhouette distance (eq. 4.5) on whole masks (reference implementation);
- :mod:`~studio.cost.silhouette`: :class:`SilhouetteTarget`, the observed frame
  precomputed once, and :func:`silhouette_cost`, the fast multi-view score (eq. 4.6),
  with pyramid levels for coarse-to-fine fitting;
- :mod:`~studio.cost.clothing`: the clothing-robust cost (eq. 6.1–6.4): inside term plus
  skin / clothing expansion with their own truncations and weights;
- :mod:`~studio.cost.priors`: shape prior (eq. 6.8), pose prior (eq. 6.9) and the
  term-by-term report of the combined objective (eq. 6.7).
"""

from .chamfer import (
    DISTANCE_MASKS,
    as_mask,
    symmetric_chamfer,
    truncated_chamfer,
    truncated_distance_map,
)
from .clothing import CLOTHING_PRESETS, ClothingCost, ClothingTarget, clothing_cost, inside_term
from .priors import (
    CostTerms,
    PosePrior,
    PriorTerms,
    combine_costs,
    gaussian_penalty,
    mahalanobis_squared,
    pose_deviation_penalty,
    pose_limit_penalty,
    shape_prior,
)
from .silhouette import (
    DEFAULT_TAU,
    SilhouetteCost,
    SilhouetteTarget,
    downsample_mask,
    silhouette_cost,
    silhouette_pyramid,
)

__all__ = [
    "CLOTHING_PRESETS",
    "ClothingCost",
    "ClothingTarget",
    "clothing_cost",
    "inside_term",
    "DEFAULT_TAU",
    "DISTANCE_MASKS",
    "CostTerms",
    "PosePrior",
    "PriorTerms",
    "SilhouetteCost",
    "SilhouetteTarget",
    "as_mask",
    "combine_costs",
    "downsample_mask",
    "gaussian_penalty",
    "mahalanobis_squared",
    "pose_deviation_penalty",
    "pose_limit_penalty",
    "shape_prior",
    "silhouette_cost",
    "silhouette_pyramid",
    "symmetric_chamfer",
    "truncated_chamfer",
    "truncated_distance_map",
]
