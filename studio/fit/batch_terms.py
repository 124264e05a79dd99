"""Extra terms of the loose batch fit (issue 15: where the loose batch body loses stature).

- :func:`knee_term`: a per-frame pose prior (in the spirit of eq. 6.9) holding each frame's knee
  hinges near that frame's single-frame fit. The single fits see each frame alone at full
  resolution; under a long shirt over wide trousers the batch bent knees they kept straight
  (dev split: 17–41° where the truth stood at 6–8°), trading stature for pose.
- :func:`head_band`: the top of each observed silhouette (head and hair) counted as skin, so the
  full expansion of eq. 6.3 (τ, λ = 1) pulls the head up into it; hair is not skin-coloured and
  under the clothing weight λ_c the head stayed 10–38 mm below the silhouette's top.
"""

from __future__ import annotations

import numpy as np

from studio.body.skeleton import PART_NAMES, pose_slices

__all__ = ["KNEE_INDICES", "KNEE_SIGMA", "head_band", "knee_term", "with_head_skin"]

#: pose-vector indices of the knee hinges (the lower legs' joint angles)
KNEE_INDICES = tuple(pose_slices()[PART_NAMES.index(p)].start for p in ("lowerleg_l", "lowerleg_r"))
#: scale of the knee term (rad): a deviation of this much from the single fit costs ``weight``
KNEE_SIGMA = float(np.radians(10.0))


def knee_term(poses: np.ndarray, reference: np.ndarray, weight: float, sigma: float = KNEE_SIGMA) -> np.ndarray:
    """``weight · Σ_knees ((θ_k − θ_k^single) / σ)²`` per pose (N,) of poses (N, POSE_SIZE),
    ``reference`` the single-frame fit's pose (POSE_SIZE,)."""
    poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
    idx = list(KNEE_INDICES)
    d = (poses[:, idx] - np.asarray(reference, dtype=np.float64)[idx]) / sigma
    return float(weight) * np.sum(d * d, axis=1)


def head_band(mask: np.ndarray, fraction: float) -> np.ndarray:
    """The pixels of ``mask`` (H, W) within ``fraction`` of its height (top row to bottom row)
    below its top row (image rows grow downwards: the head of an upright person)."""
    mask = np.asarray(mask, dtype=bool)
    rows = np.flatnonzero(mask.any(axis=1))
    out = np.zeros_like(mask)
    if fraction <= 0 or rows.size == 0:
        return out
    top, bottom = rows[0], rows[-1]
    last = top + int(np.floor(fraction * (bottom - top + 1)))
    out[top:last] = mask[top:last]
    return out


def with_head_skin(masks: list, skin: list | None, fraction: float) -> list | None:
    """``skin`` per view with each observed mask's :func:`head_band` added (unchanged when
    ``fraction`` is 0)."""
    if fraction <= 0:
        return skin
    skin = [None] * len(masks) if skin is None else list(skin)
    return [head_band(m, fraction) | (np.zeros(np.shape(m), bool) if s is None else np.asarray(s, bool))
            for m, s in zip(masks, skin, strict=True)]
