"""Cast-shadow geometry under one fixed light: a shadow lies at the light-opposite end of its object.

The colour gate of eq. 5.5 (:mod:`studio.segment.adaptive`) keeps a pixel "shadow" when it is
uniformly darker than the background. Outdoors (CDnet *highway*) hard shadows keep ~14 % of the
road's brightness, as dark as dark car paint, so the gate also takes the dark body of a car.
The light, though, is fixed (the sun; a studio lamp): in the image every cast shadow is offset
from its object along one direction ``d``, the projection of the light direction onto the
ground (thesis §5.5's shadow camera, in 2-D). The test here: walk from a shadow-gated pixel
along ``d`` to where the foreground ends (``exit``) and back along ``-d`` to where it starts
(``entry``); the pixel stays shadow only when it lies in the last ``fraction`` of that chord,

    exit ≤ fraction · (exit + entry − 1),

i.e. in the strip the object casts beyond itself, whatever the object's size in the image
(perspective scales chord and strip alike). A dark pixel inside the car's outline has the rest
of the car (and its shadow) ahead of it along ``d``: it is person again.

``d`` is learned from pixels known to be shadow beside their object
(:func:`learn_shadow_direction`: CDnet's labelled tuning frames, or multi-view voting agreement
of §5.5.2 in a studio). The walk is one compiled pass over the shadow pixels only (numba).
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from numba import njit

from studio.segment.classify import PERSON, SHADOW
from studio.segment.errors import SegmentationError

__all__ = ["learn_shadow_direction", "shadow_geometry"]


@njit(cache=True, nogil=True)
def _walk(labels: np.ndarray, y: int, x: int, dx: float, dy: float, reach: int) -> int:
    """Steps along (dx, dy) from (y, x) to the first background pixel (leaving the image counts
    as background); ``reach`` when none is met within ``reach`` steps."""
    h, w = labels.shape
    for t in range(1, reach):
        yy = int(math.floor(y + t * dy + 0.5))
        xx = int(math.floor(x + t * dx + 0.5))
        if yy < 0 or yy >= h or xx < 0 or xx >= w or labels[yy, xx] == 0:
            return t
    return reach


@njit(cache=True, nogil=True)
def _relabel(labels: np.ndarray, out: np.ndarray, dx: float, dy: float, fraction: float, reach: int) -> int:
    """Shadow stays shadow iff ``ahead <= fraction * (ahead + behind - 1)``, i.e.
    ``behind >= need = ahead / fraction - ahead + 1``: the walk back stops after ``need`` steps."""
    h, w = labels.shape
    changed = 0
    for y in range(h):
        for x in range(w):
            if labels[y, x] != SHADOW:
                continue
            ahead = _walk(labels, y, x, dx, dy, reach)
            need = ahead / fraction - ahead + 1.0
            if need <= 1.0:
                continue  # behind >= 1 always
            if need > reach or _walk(labels, y, x, -dx, -dy, int(math.ceil(need))) < need:
                out[y, x] = PERSON
                changed += 1
    return changed


def shadow_geometry(
    labels: np.ndarray, direction: tuple[float, float], fraction: float = 0.2, reach: int | None = None
) -> np.ndarray:
    """Shadow pixels not at the light-opposite end of their foreground region become person.

    Parameters
    ----------
    labels : (H, W) uint8 labels 0 background / 1 person / 2 shadow (after morphology: the
        chord is measured on the non-background mask).
    direction : (dx, dy) image direction from an object to its cast shadow (need not be unit).
    fraction : largest share of the chord through a pixel along ``direction`` that may lie
        ahead of a shadow pixel (0.2: the shadow strip is the last fifth of object + shadow).
    reach : longest walk in pixels each way (longer chords count as ``reach``); None (default):
        ``H + W``, longer than any chord, so the test is the chord share at every object size.
        (Until issue 18's fourth CDnet evaluation the default was 96: a shadow pixel with more than
        ~17 px of foreground ahead, at fraction 0.15, went back to the object whenever the chord
        was over 96 px, however long the object.)

    Returns
    -------
    (H, W) uint8 new labels (person unchanged, some shadow turned person).
    """
    labels = np.asarray(labels)
    if labels.ndim != 2 or labels.dtype != np.uint8:
        raise SegmentationError(f"shadow_geometry: labels must be (H, W) uint8, got {labels.shape} {labels.dtype}")
    dx, dy = (float(v) for v in direction)
    norm = math.hypot(dx, dy)
    if not (math.isfinite(norm) and norm > 0):
        raise SegmentationError(f"shadow_geometry: direction must be a non-zero (dx, dy), got {direction!r}")
    if not (0.0 < fraction <= 1.0):
        raise SegmentationError(f"shadow_geometry: fraction must be in (0, 1], got {fraction!r}")
    if reach is None:
        reach = labels.shape[0] + labels.shape[1]
    out = labels.copy()
    _relabel(labels, out, dx / norm, dy / norm, float(fraction), int(max(reach, 2)))
    return out


def learn_shadow_direction(
    object_masks, shadow_masks, join_radius: int = 2, min_pixels: int = 20
) -> tuple[float, float]:
    """The unit image direction (dx, dy) from objects to their cast shadows.

    Over the connected regions of object ∪ shadow (dilated by ``join_radius`` so a thin
    unlabelled band between them, CDnet's 170 "unknown", does not split them), the shadow's
    centroid minus the object's centroid, weighted by the shadow's pixel count; regions with
    fewer than ``min_pixels`` of either are skipped.

    Parameters
    ----------
    object_masks, shadow_masks : sequences of (H, W) bool masks (CDnet: truth 255 and 50).
    """
    total = np.zeros(2)
    used = 0
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * join_radius + 1,) * 2)
    for obj, sh in zip(object_masks, shadow_masks):
        obj, sh = np.asarray(obj, bool), np.asarray(sh, bool)
        if obj.sum() < min_pixels or sh.sum() < min_pixels:
            continue
        union = cv2.dilate((obj | sh).view(np.uint8), kernel)
        n, cc = cv2.connectedComponents(union, connectivity=8)
        for c in range(1, n):
            region = cc == c
            ys, xs = np.nonzero(region & sh)
            yo, xo = np.nonzero(region & obj)
            if len(ys) < min_pixels or len(yo) < min_pixels:
                continue
            total += len(ys) * np.array([xs.mean() - xo.mean(), ys.mean() - yo.mean()])
            used += 1
    norm = float(np.hypot(*total))
    if used == 0 or norm == 0:
        raise SegmentationError(
            f"learn_shadow_direction: no region with at least {min_pixels} object and shadow pixels"
        )
    return float(total[0] / norm), float(total[1] / norm)
