"""Visual-hull consistency of the person masks across views.

A person is one solid seen by every camera; clutter in one view — an edge of the room after a
camera nudge, a tripod that moved, a flickering lamp — has no counterpart in the others. The
person masks of all views are carved into a coarse visual hull (the grid of the fit's quality
gates, :func:`studio.fit.quality.hull_hits`), the hull is projected back into each view, and a
person component of which less than ``min_share`` lies on that projection is relabelled
background. A real object every view sees (a chair the person sits on) is consistent and stays.
"""

from __future__ import annotations

import logging

import cv2
import numpy as np

from studio.segment.classify import BACKGROUND, PERSON

__all__ = ["hull_filter"]

log = logging.getLogger(__name__)


def hull_filter(labels: dict[str, np.ndarray], cameras: dict, *, min_share: float = 0.5, step: float = 0.04,
                factor: int = 4) -> tuple[dict[str, np.ndarray], dict[str, int]]:
    """Drop person components the visual hull of all views does not explain.

    Parameters
    ----------
    labels : ``{camera: (H, W) uint8}`` labels 0/1/2 (inputs are not changed).
    cameras : ``{camera: calibration.Camera}`` at the labels' resolution.
    min_share : share of a component's pooled cells the hull's projection must cover.

    Returns ``(labels, dropped)``: new labels and the person pixels dropped per camera. When the
    views share no hull point at all (a person out of some view, a bad calibration) nothing is
    dropped.
    """
    from studio.fit.errors import FitError
    from studio.fit.quality import hull_hits

    names = list(labels)
    masks = [labels[n] == PERSON for n in names]
    if sum(bool(m.any()) for m in masks) < 2:
        return dict(labels), {n: 0 for n in names}
    try:
        hits = hull_hits([cameras[n] for n in names], masks, step=step, factor=factor)
    except FitError as exc:
        log.info("hull filter skipped: %s", exc)
        return dict(labels), {n: 0 for n in names}
    out, dropped = {}, {}
    for name, mask, hit in zip(names, masks, hits):
        n, cc, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
        if n <= 1:
            out[name], dropped[name] = labels[name], 0
            continue
        h, w = mask.shape
        # each pixel looks up its pooled cell
        covered = hit[np.arange(h)[:, None] // factor, np.arange(w)[None, :] // factor]
        share = np.bincount(cc[mask], weights=covered[mask], minlength=n) / np.maximum(stats[:, cv2.CC_STAT_AREA], 1)
        bad = share < min_share
        bad[0] = False
        if bad[1:].all() or not bad.any():  # nothing explained: leave the view to the quality gates
            out[name], dropped[name] = labels[name], 0
            continue
        lab = labels[name].copy()
        drop = bad[cc] & mask
        lab[drop] = BACKGROUND
        out[name], dropped[name] = lab, int(drop.sum())
    return out, dropped
