"""Scores of segmentations against truth masks, and threshold tuning from labelled frames.

The thesis says the eq. 5.5 thresholds are "determined empirically from data";
:func:`tune_thresholds` does that by grid search on a labelled tuning split.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Callable, Sequence

import numpy as np

from studio.segment.classify import PERSON, SHADOW, Thresholds

__all__ = ["binary_scores", "cdnet_scores", "label_scores", "tune_thresholds"]

log = logging.getLogger(__name__)


def binary_scores(pred, truth, valid=None) -> dict[str, float]:
    """Precision, recall, F1 of boolean masks (or lists of masks), counted over all pixels.

    ``valid`` masks (same shapes) restrict the count (e.g. CDnet's ROI / unknown labels).
    Empty denominators give 0 (no prediction and no truth gives F1 = 1).
    """
    preds = pred if isinstance(pred, (list, tuple)) else [pred]
    truths = truth if isinstance(truth, (list, tuple)) else [truth]
    valids = valid if isinstance(valid, (list, tuple)) else [valid] * len(preds)
    tp = fp = fn = 0
    for p, t, v in zip(preds, truths, valids):
        p, t = np.asarray(p, bool), np.asarray(t, bool)
        if v is not None:
            p, t = p & v, t & v
        tp += int(np.count_nonzero(p & t))
        fp += int(np.count_nonzero(p & ~t))
        fn += int(np.count_nonzero(~p & t))
    precision = tp / (tp + fp) if tp + fp else 0.0
    recall = tp / (tp + fn) if tp + fn else 0.0
    f1 = 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else 1.0
    return {"precision": precision, "recall": recall, "f1": f1, "tp": tp, "fp": fp, "fn": fn}


def label_scores(pred: Sequence[np.ndarray], truth: Sequence[np.ndarray]) -> dict[str, dict[str, float]]:
    """Person and shadow scores of 0/1/2 label images against 0/1/2 truth."""
    return {
        "person": binary_scores([p == PERSON for p in pred], [t == PERSON for t in truth]),
        "shadow": binary_scores([p == SHADOW for p in pred], [t == SHADOW for t in truth]),
    }


def cdnet_scores(labels: Sequence[np.ndarray], truths: Sequence[np.ndarray], roi: np.ndarray | None = None,
                 foreground: int = PERSON, shadow: int | None = SHADOW) -> dict[str, float]:
    """The CDnet 2014 scores of label images against CDnet ground truth.

    Truth: 0 static, 50 hard shadow, 85 outside the temporal ROI, 170 unknown, 255 motion.
    Recall / precision / F-measure of ``labels == foreground`` against motion (255) versus static
    and shadow (0, 50), inside ``roi`` and without 85 / 170; FPR-S is the fraction of shadow
    pixels (50, inside ``roi``) labelled foreground; shadow precision / recall compare
    ``labels == shadow`` with the shadow pixels (None: a method without a shadow label).
    """
    from studio.segment.tuning import COUNT_FIELDS, cdnet_counts, scores_from_counts

    counts = np.zeros(len(COUNT_FIELDS), np.int64)
    for lab, t in zip(labels, truths):
        counts += cdnet_counts(lab, t, roi, foreground, shadow)
    out = scores_from_counts(counts)
    if shadow is None:
        out["shadow_precision"] = out["shadow_recall"] = None
    return out


def _default_objective(pred, truth) -> float:
    s = label_scores(pred, truth)
    return 0.5 * (s["person"]["f1"] + s["shadow"]["f1"])


def tune_thresholds(
    classify: Callable[[Thresholds, int], np.ndarray],
    truths: Sequence[np.ndarray],
    *,
    hsv: Sequence[float] = (3.0, 4.0, 5.0, 6.0, 8.0),
    saturation: Sequence[float] = (2.0, 3.0, 4.0, 6.0, 8.0),
    value_ratio: Sequence[tuple[float, float]] = ((0.25, 0.95), (0.3, 0.9), (0.4, 0.95), (0.0, np.inf)),
    objective: Callable[[list, Sequence], float] = _default_objective,
) -> tuple[Thresholds, list[tuple[Thresholds, float]]]:
    """Grid search of the eq. 5.5 thresholds on labelled tuning frames.

    Parameters
    ----------
    classify : ``classify(thresholds, i) -> (H, W) uint8`` labels of tuning frame ``i``
        (e.g. a background model's classification, possibly followed by voting).
    truths : truth of each tuning frame, in whatever form ``objective`` expects (0/1/2 labels
        for the default objective: mean of person and shadow F1).

    Returns
    -------
    The best :class:`Thresholds` and every ``(thresholds, score)`` tried, best first.
    """
    table = []
    for t_hsv, t_s, vr in itertools.product(hsv, saturation, value_ratio):
        th = Thresholds(hsv=float(t_hsv), saturation=float(t_s), value_ratio=tuple(vr))
        pred = [classify(th, i) for i in range(len(truths))]
        table.append((th, float(objective(pred, truths))))
    table.sort(key=lambda row: -row[1])
    log.info("threshold tuning: best %s (score %.4f) of %d", table[0][0], table[0][1], len(table))
    return table[0][0], table
