"""The shadow term of the fitting cost (thesis eq. 5.7).

    E(s) = Σ_k D(F^e_k(s), F^o_k) + w · (1/K) Σ_k D(S^e_k(s, ℓ, g), S^o_k)              (5.7)

``S^e_k`` is the visible shadow of the body hypothesis through the known light(s) ℓ onto the
ground g (eq. 5.2) in camera k (eq. 5.3) less the body's own silhouette there (shadows first,
then the body, §5.6); ``S^o_k`` the segmented shadow (label 2). The K views of the one "shadow
camera" are averaged, not summed: they are not independent observations. ``w`` (``weight``,
1 in the thesis) is this toolkit's knob.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from studio.cost import SilhouetteTarget, silhouette_cost
from studio.render.shadow import shadow_silhouettes

__all__ = ["ShadowTerm"]


@dataclass(frozen=True, eq=False)
class ShadowTerm:
    """Observed shadows of one frame (``targets`` {level: SilhouetteTarget}), the ``lights``
    casting them, the ``ground`` (None: the floor z = 0) and the term's ``weight``."""

    lights: tuple
    targets: dict
    ground: object = None
    weight: float = 1.0

    @classmethod
    def build(cls, lights, shadow_masks: Sequence[np.ndarray], names: Sequence[str], levels, *, tau: float = 20.0,
              xi: float = 1.0, ground=None, weight: float = 1.0) -> ShadowTerm:
        """``shadow_masks`` (H, W) bool per camera (``names`` order); ``levels`` the pyramid levels."""
        if not weight >= 0:
            raise ValueError(f"shadow weight: expected >= 0, got {weight}")
        lights = tuple(lights)
        if not lights:
            raise ValueError("lights: the shadow term needs at least one light")
        targets = {lvl: SilhouetteTarget.build([np.asarray(m, bool) for m in shadow_masks], tau=tau, xi=xi,
                                               level=lvl, names=list(names)) for lvl in sorted(set(levels))}
        return cls(lights, targets, ground, float(weight))

    def predicted(self, cameras: Sequence, vertices: np.ndarray, faces: np.ndarray,
                  body_masks: Sequence[np.ndarray]) -> list[np.ndarray]:
        """Visible predicted shadows (H_l, W_l) bool in the level ``cameras``."""
        return shadow_silhouettes(cameras, vertices, faces, self.lights, self.ground, occluders=body_masks)

    def per_view(self, cameras, vertices, faces, body_masks, level: int) -> np.ndarray:
        """(K,) ``D(S^e_k, S^o_k)`` (full-resolution units)."""
        return silhouette_cost(self.targets[level], self.predicted(cameras, vertices, faces, body_masks)).per_view

    def cost(self, cameras, vertices, faces, body_masks, level: int) -> float:
        """``w · (1/K) Σ_k D(S^e_k, S^o_k)`` (eq. 5.7, second term)."""
        return self.weight * float(np.mean(self.per_view(cameras, vertices, faces, body_masks, level)))
