"""Honest operating points from labelled frames: per-frame CDnet counts, blocked cross-validation
folds over a frame range, and the pick rule "best F among points that meet a shadow limit".

The eq. 5.5 thresholds are "determined empirically from data" (thesis §5.5); on a video the frames
of one car are strongly correlated, so a tuning split of a few frames is a small sample and a
random split leaks. The helpers here keep every scored frame away from the frames its settings
were chosen on:

* :func:`cdnet_counts` — the integer counts of one frame (:func:`studio.segment.metrics.cdnet_scores`
  sums them and scores them by :func:`scores_from_counts`), so a grid can be scored once per
  frame and summed over any subset of frames;
* :func:`blocked_folds` — consecutive frames cut into blocks, blocks alternating between folds;
  :func:`fold_tuning_frames` — the frames a fold's settings may be chosen on (a base split plus
  the other folds, minus a ``gap`` of frames next to any scored frame);
* :func:`pick_operating_point` — the best tuning F among points whose tuning FPR-S is within a limit.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from studio.segment.classify import PERSON, SHADOW
from studio.segment.errors import SegmentationError

__all__ = ["COUNT_FIELDS", "blocked_folds", "cdnet_counts", "fold_tuning_frames", "pick_operating_point",
           "scores_from_counts"]  # fmt: skip

# tp / fp / fn of the foreground label against motion (255); shadow pixels inside the ROI and those of
# them labelled foreground; tp / fp / fn of the shadow label against shadow (50)
COUNT_FIELDS = ("tp", "fp", "fn", "shadow_pixels", "shadow_as_fg", "shadow_tp", "shadow_fp", "shadow_fn")


def cdnet_counts(labels: np.ndarray, truth: np.ndarray, roi: np.ndarray | None = None,
                 foreground: int = PERSON, shadow: int | None = SHADOW) -> np.ndarray:  # fmt: skip
    """The counts (:data:`COUNT_FIELDS`, (8,) int64) of one label image against CDnet truth
    (0 static, 50 hard shadow, 85 outside the temporal ROI, 170 unknown, 255 motion), with the
    conventions of :func:`studio.segment.metrics.cdnet_scores`."""
    lab, t = np.asarray(labels), np.asarray(truth)
    if lab.shape != t.shape:
        raise SegmentationError(f"cdnet_counts: labels {lab.shape} and truth {t.shape} differ in shape")
    inside = np.ones(t.shape, bool) if roi is None else np.asarray(roi, bool)
    valid = inside & (t != 85) & (t != 170)
    fg, motion = (lab == foreground) & valid, (t == 255) & valid
    sh_truth = t == 50
    sh = (lab == shadow) & valid if shadow is not None else np.zeros(t.shape, bool)
    sh_t = sh_truth & valid
    sh_roi = inside & sh_truth
    c = [np.count_nonzero(fg & motion), np.count_nonzero(fg & ~motion), np.count_nonzero(~fg & motion),
         np.count_nonzero(sh_roi), np.count_nonzero((lab == foreground) & sh_roi),
         np.count_nonzero(sh & sh_t), np.count_nonzero(sh & ~sh_t), np.count_nonzero(~sh & sh_t)]  # fmt: skip
    return np.asarray(c, np.int64)


def scores_from_counts(counts: np.ndarray) -> dict[str, float]:
    """Recall / precision / F, FPR-S and shadow precision / recall of summed counts.

    ``counts`` is (8,) or (N, 8) (summed over the first axis). Empty denominators give 0 (F 1 when
    there is neither prediction nor truth), as :func:`studio.segment.metrics.binary_scores`.
    """
    c = np.asarray(counts, np.int64)
    if c.ndim == 2:
        c = c.sum(axis=0)
    if c.shape != (len(COUNT_FIELDS),):
        raise SegmentationError(f"scores_from_counts: expected (..., {len(COUNT_FIELDS)}) counts, got {c.shape}")
    tp, fp, fn, n_sh, sh_fg, stp, sfp, sfn = (int(v) for v in c)

    def ratio(a, b):
        return a / b if b else 0.0

    return {"recall": ratio(tp, tp + fn), "precision": ratio(tp, tp + fp),
            "f_measure": 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else 1.0,
            "fpr_shadow": sh_fg / max(n_sh, 1), "shadow_pixels": n_sh,
            "shadow_precision": ratio(stp, stp + sfp), "shadow_recall": ratio(stp, stp + sfn)}  # fmt: skip


def blocked_folds(frames: Sequence[int], block: int = 50, n_folds: int = 2) -> list[list[int]]:
    """Frames cut into blocks of ``block`` consecutive frame numbers (counted from the first
    frame; a last block shorter than half a block joins the one before), block ``b`` in fold
    ``b mod n_folds``. Returns the frames of each fold, in order.

    >>> [f[:2] + f[-1:] for f in blocked_folds(range(700, 1201), block=50)]
    [[700, 701, 1149], [750, 751, 1200]]
    """
    frames = sorted(int(i) for i in frames)
    if block < 1 or n_folds < 2:
        raise SegmentationError(f"blocked_folds: need block >= 1 and n_folds >= 2, got {block}, {n_folds}")
    if len(frames) < n_folds:
        raise SegmentationError(f"blocked_folds: {len(frames)} frames cannot make {n_folds} folds")
    first, last = frames[0], frames[-1]
    n_blocks = (last - first) // block + 1
    if n_blocks > 1 and (last - first + 1) - (n_blocks - 1) * block < block / 2:
        n_blocks -= 1  # a short tail joins the block before
    folds: list[list[int]] = [[] for _ in range(n_folds)]
    for i in frames:
        b = min((i - first) // block, n_blocks - 1)
        folds[b % n_folds].append(i)
    if any(not f for f in folds):
        raise SegmentationError(f"blocked_folds: {n_blocks} blocks of {block} frames leave a fold empty")
    return folds


def fold_tuning_frames(base: Iterable[int], folds: Sequence[Sequence[int]], k: int, gap: int = 0) -> list[int]:
    """The frames fold ``k``'s settings may be chosen on: ``base`` and every other fold's frames,
    without any frame within ``gap`` frames of one of fold ``k``'s (the scored frames)."""
    scored = np.asarray(sorted(folds[k]), np.int64)
    others = (int(i) for j, f in enumerate(folds) if j != k for i in f)
    pool = sorted(({int(i) for i in base} | set(others)) - set(scored.tolist()))
    if gap <= 0 or not len(scored):
        return pool
    p = np.asarray(pool, np.int64)
    pos = np.searchsorted(scored, p)
    left, right = scored[np.clip(pos - 1, 0, len(scored) - 1)], scored[np.clip(pos, 0, len(scored) - 1)]
    near = np.minimum(np.abs(p - left), np.abs(p - right))
    return [int(i) for i, d in zip(p, near) if d > gap]


def pick_operating_point(points: Sequence[tuple[object, float, float]], fprs_limit: float | None = None):
    """The point with the best tuning F among ``points`` whose tuning FPR-S is ≤ ``fprs_limit``
    (None: no limit), as ``(key, f, fprs)``; ties go to the first listed. None when no point
    meets the limit.

    >>> pick_operating_point([("a", 0.97, 0.4), ("b", 0.95, 0.3), ("c", 0.95, 0.1)], 0.30)
    ('b', 0.95, 0.3)
    """
    best = None
    for key, f, fprs in points:
        if fprs_limit is not None and not fprs <= fprs_limit:
            continue
        if best is None or f > best[1]:
            best = (key, float(f), float(fprs))
    return best
