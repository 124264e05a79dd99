"""The frames of a batch fit (split from :mod:`studio.fit.batch`): which to take
(:func:`choose_frames`) and whether the batch's frames show one person (:func:`consistency`,
§6.4.2, decided by :func:`two_people`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from studio.body import BodyModel
from studio.fit.batch_terms import BatchOptions, ClothedObjective, clothing_targets
from studio.fit.errors import FitError

if TYPE_CHECKING:
    from studio.fit.batch import BatchFrame

__all__ = ["CLOTHES_CHECKS", "COST_RATIO_FLAG", "FLAG_FRAMES", "STATURE_SPREAD_FLAG", "choose_frames", "consistency",
           "trimmed_spread", "two_people"]

#: Quality checks whose ``failed`` verdict a loosely clothed single-frame fit may earn from the
#: clothes alone (a body fattened to fill them: implausible mass or girths, silhouettes explained
#: poorly) — the batch is what corrects it, so such frames stay usable for a loose batch.
CLOTHES_CHECKS = frozenset({"population", "shape_prior", "agreement"})

#: Flag a batch when the shared shape costs ``FLAG_FRAMES`` frames this many times their own
#: single-frame shapes …
COST_RATIO_FLAG = 1.6
#: … or the single-frame statures, one outlying frame left out, spread (max − min) more than this
#: (m) while the shared shape explains ``FLAG_FRAMES`` frames worse than their own. Within one person
#: the single-frame fits of the held-out benchmark spread about ±15 mm; two adults differ by ~70 mm
#: on average.
STATURE_SPREAD_FLAG = 0.06
#: Frames that must bear the evidence (all of them in a smaller batch): one frame is not told from one
#: failed single-frame fit. Under loose clothing the single fits are of the clothes and one of 11
#: often fails (its stature 100–350 mm off, the shared shape costing it 1.7–2.0× its own): taking
#: any one frame's evidence, 6 of 20 one-person loose batches of the clothing ledger were flagged as
#: two people. Chosen on the dev split (4 postures, at most 4 frames a person, gender given; the
#: ring of `benchmarks/clothing.py pairs --split dev` and 10 pairs picked to span 15–272 mm of
#: stature): loose one-person batches flagged 1 → 0 of 10, tight 0 → 0 of 21; loose batches of two
#: people differing by ≥ 60 mm in stature 12 → 12 of 13, by less 2 → 1 of 7.
FLAG_FRAMES = 2


def _failed_by_clothes(fit) -> bool:
    failed = {r.get("check") for r in fit.quality.get("reasons", []) if r.get("severity") == "failed"}
    return bool(failed) and failed <= CLOTHES_CHECKS


def choose_frames(fits: dict, n: int = 8, loose: bool = False) -> list[int]:
    """Up to ``n`` frames for a batch from single-frame fits {frame: FrameFit}: status ``ok`` first
    (``suspect`` only if fewer than two are ok; ``failed`` never, except — ``loose`` clothing,
    fewer than two otherwise — frames failed only by :data:`CLOTHES_CHECKS`), then the most diverse
    postures (farthest-point sampling on the joint angles, root heading and position left out),
    starting from the frame with the lowest cost."""
    usable = {f: fit for f, fit in fits.items() if fit.status in ("ok", "unchecked")}
    if len(usable) < 2:
        usable.update({f: fit for f, fit in fits.items() if fit.status == "suspect"})
    if len(usable) < 2 and loose:
        usable.update({f: fit for f, fit in fits.items() if fit.status == "failed" and _failed_by_clothes(fit)})
    if not usable:
        raise FitError("batch fit: no single-frame fit passed the quality gates")
    order = sorted(usable)
    X = np.array([usable[f].pose[6:] for f in order])
    costs = np.array([usable[f].costs.get("total", 0.0) for f in order])
    chosen = [int(np.argmin(costs))]
    dist = np.linalg.norm(X - X[chosen[0]], axis=1)
    while len(chosen) < min(n, len(order)):
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(X - X[k], axis=1))
    return sorted(order[k] for k in chosen)


def consistency(batch_model: BodyModel, shape: np.ndarray, poses: np.ndarray, frames: list[BatchFrame],
                options: BatchOptions) -> dict:
    """How well one shape explains every frame (§6.4.2): each frame scored at the final level by
    the same clothing cost with the batch body and with the frame's own single-frame body, and the
    single-frame statures; ``flagged`` with the reasons when the frames look like more than one
    person (:func:`two_people`)."""
    from studio.body import measure

    level = options.levels[-1]
    ratios, statures = [], []
    for f, pose in zip(frames, poses, strict=True):
        targets = clothing_targets(f, options)
        own_model = BodyModel.load(f.gender)
        own = ClothedObjective(own_model, f.cameras, targets, f.shape, 0, options.prior_weight, floor=options.stands)
        mine = ClothedObjective(batch_model, f.cameras, targets, shape, 0, options.prior_weight, floor=options.stands)
        c_own = float(own(own.pack(f.shape, f.pose)[None], level)[0])
        c_batch = float(mine(mine.pack(shape, pose)[None], level)[0])
        ratios.append(c_batch / max(c_own, 1e-9))
        statures.append(measure(own_model, f.shape)["stature"])
    labels = [f.frame for f in frames]
    reasons = two_people(labels, ratios, statures)
    return {"cost_ratio": {str(k): round(r, 4) for k, r in zip(labels, ratios, strict=True)},
            "single_statures_m": {str(k): round(s, 4) for k, s in zip(labels, statures, strict=True)},
            "stature_spread_m": round(float(np.ptp(statures)), 4) if statures else 0.0,
            "stature_spread_trimmed_m": round(trimmed_spread(statures), 4), "flagged": bool(reasons),
            "reasons": reasons, "thresholds": {"cost_ratio": COST_RATIO_FLAG, "stature_spread_m": STATURE_SPREAD_FLAG,
                                               "frames": FLAG_FRAMES}}


def two_people(labels, ratios, statures) -> list[str]:
    """Why frames ``labels`` look like more than one person (§6.4.2), from each frame's cost
    ratio (shared shape / its own single-frame shape) and single-frame stature (m); empty: one
    person. The evidence must come from ``FLAG_FRAMES`` frames (all, in a smaller batch): the
    ratio over ``COST_RATIO_FLAG`` on that many, or the :func:`trimmed_spread` of the statures over
    ``STATURE_SPREAD_FLAG`` while that many frames are explained worse by the shared shape than by
    their own (ratio > 1) — when the shared shape explains the frames at least as well, a spread
    is the single-frame fits' own error (a poor single fit, not a second person)."""
    ratios = np.asarray(ratios, dtype=np.float64)
    need = min(FLAG_FRAMES, ratios.size)
    order = np.argsort(ratios)[::-1]
    over = [i for i in order if ratios[i] > COST_RATIO_FLAG]
    worse = int((ratios > 1.0).sum())
    trimmed = trimmed_spread(statures)
    reasons = []
    if over and len(over) >= need:
        reasons.append(f"frames {', '.join(str(labels[i]) for i in over)}: the shared shape costs "
                       f"{', '.join(f'{ratios[i]:.2f}x' for i in over)} their own single-frame shapes "
                       f"(> {COST_RATIO_FLAG} on {need} or more)")
    if trimmed > STATURE_SPREAD_FLAG and worse and worse >= need:
        left_out = " without the farthest frame" if len(statures) >= 3 else ""
        reasons.append(f"single-frame statures spread {trimmed * 1000:.0f} mm{left_out} (> "
                       f"{STATURE_SPREAD_FLAG * 1000:.0f} mm) and the shared shape explains {worse} frames worse "
                       f"than their own")
    return reasons


def trimmed_spread(values) -> float:
    """max − min of ``values`` without the one farthest from their median (all of them when
    there are fewer than three): one failed single-frame fit does not make a spread."""
    v = np.asarray(values, dtype=np.float64)
    if v.size < 3:
        return float(np.ptp(v)) if v.size else 0.0
    return float(np.ptp(np.delete(v, np.argmax(np.abs(v - np.median(v))))))
