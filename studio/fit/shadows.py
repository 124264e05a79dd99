"""The shadow term of the fitting cost (thesis eq. 5.7).

    E(s) = Σ_k D(F^e_k(s), F^o_k) + w · (1/K) Σ_k D(S^e_k(s, ℓ, g), S^o_k)              (5.7)

``S^e_k`` is the visible shadow of the body hypothesis through the known light(s) ℓ onto the
ground g (eq. 5.2) in camera k (eq. 5.3) less the body's own silhouette there (shadows first,
then the body, §5.6); ``S^o_k`` the segmented shadow (label 2). The K views of the one "shadow
camera" are averaged, not summed: they are not independent observations. ``w`` (``weight``,
1 in the thesis) is this toolkit's knob.

As in the light's objective (:mod:`studio.light.objective`, eq. 5.9), the term is scored in each
camera's *ideal* image (the lens distortion taken out: the observed shadows undistorted once, the
body's silhouette looked up through the lens at the shadow's pixels only), where a floor outline
reaches the image by one 3×4 projection: one call of the compiled
:func:`studio.light._kernels.shadow_chamfer` per body hypothesis.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from studio.cost import SilhouetteTarget
from studio.light.objective import ideal_camera, lens_index, observed_arrays, projection_matrices, shadow_distances
from studio.render.pyramid import level_camera

__all__ = ["ShadowTerm"]


@dataclass(frozen=True, eq=False)
class ShadowTerm:
    """Observed shadows of one frame seen by ``cameras`` (full resolution), as ``targets``
    {level: SilhouetteTarget} in the cameras' ideal images, the ``lights`` casting them, the
    ``ground`` (None: the floor z = 0) and the term's ``weight``."""

    lights: tuple
    cameras: tuple
    targets: dict
    ground: object = None
    weight: float = 1.0

    @classmethod
    def build(cls, lights, cameras: Sequence, shadow_masks: Sequence[np.ndarray], levels, *, tau: float = 20.0,
              xi: float = 1.0, ground=None, weight: float = 1.0) -> ShadowTerm:
        """``shadow_masks`` (H, W) bool per camera of ``cameras`` (full resolution, the fit's
        order); ``levels`` the pyramid levels."""
        if not weight >= 0:
            raise ValueError(f"shadow weight: expected >= 0, got {weight}")
        lights = tuple(lights)
        if not lights:
            raise ValueError("lights: the shadow term needs at least one light")
        cameras = tuple(cameras)
        if len(cameras) != len(shadow_masks):
            raise ValueError(f"shadow_masks: expected one per camera ({len(cameras)}), got {len(shadow_masks)}")
        ideal = [c.undistort_image(np.asarray(m, bool)) for c, m in zip(cameras, shadow_masks, strict=True)]
        targets = {lvl: SilhouetteTarget.build(ideal, tau=tau, xi=xi, level=lvl, names=[c.name for c in cameras])
                   for lvl in sorted(set(levels))}
        return cls(lights, cameras, targets, ground, float(weight))

    def __post_init__(self):
        from studio.render.shadow import _plane

        cams = {lvl: [level_camera(ideal_camera(c), lvl) for c in self.cameras] for lvl in self.targets}
        object.__setattr__(self, "_ideal", cams)
        object.__setattr__(self, "_matrices", {lvl: projection_matrices(c) for lvl, c in cams.items()})
        object.__setattr__(self, "_observed", {lvl: observed_arrays(t) for lvl, t in self.targets.items()})
        # the body's silhouettes come through the lens: looked up at the ideal image's pixels
        object.__setattr__(self, "_lens", {lvl: np.stack([lens_index(level_camera(c, lvl)) for c in self.cameras])
                                           for lvl in self.targets})
        object.__setattr__(self, "_plane", np.append(*_plane(self.ground)))

    def per_view(self, vertices, faces, body_masks, level: int) -> np.ndarray:
        """(K,) ``D(S^e_k, S^o_k)`` (full-resolution units); ``body_masks`` the body's silhouettes
        in the fit's ``level`` cameras (through the lens)."""
        from studio.render.spans import _topology, face_normals

        V = np.asarray(vertices, dtype=np.float64)
        F = np.asarray(faces, dtype=np.int64)
        occ = np.stack([np.asarray(m, bool).ravel() for m in body_masks])
        return shadow_distances(V, F, face_normals(V, F), _topology(F, len(V)), [self.lights], self._plane,
                                self.ground, self._ideal[level], self._matrices[level], (occ, self._lens[level]),
                                self.targets[level], self._observed[level])[0]

    def cost(self, vertices, faces, body_masks, level: int) -> float:
        """``w · (1/K) Σ_k D(S^e_k, S^o_k)`` (eq. 5.7, second term)."""
        return self.weight * float(np.mean(self.per_view(vertices, faces, body_masks, level)))
