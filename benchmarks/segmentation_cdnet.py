"""CDnet 2014 *highway* part of ``benchmarks/segmentation.py``: the toolkit beside OpenCV's
subtractors, same frames, same protocol, one run.

Protocol. Ground truth starts at frame 470 (``temporalROI.txt``); frames 470–699 (every 10th)
are the tuning split, 700–1200 the evaluation split (every frame; ``--quick`` every 4th).

* **toolkit, adaptive** (:meth:`studio.segment.BackgroundModel.apply`): started on frame 1 and
  run over every frame 1–1200 as the OpenCV subtractors are. Its detection settings
  (noise band, distance) are picked on the tuning split; the shadow gate likewise, with the
  shadow tint learned from the tuning split's shadow pixels (:func:`studio.segment.learn_tint`).
  Four operating points are reported: best F on the tuning split (colour gate only), best F
  among colour gates whose tuning-split FPR-S is ≤ 0.30 (the issue's shadow target), and best F
  among colour gates with cast-shadow geometry (:func:`studio.segment.shadow_geometry`, the
  object-to-shadow direction learned from the tuning split by
  :func:`studio.segment.learn_shadow_direction`, chord fraction 0.15 / 0.2 / 0.25) whose
  tuning-split FPR-S is ≤ 0.30, and the same with tuning-split FPR-S ≤ 0.15 (``GEOMETRY_MARGIN``)
  — the point the target is checked at.
* **toolkit, fixed** (:meth:`~studio.segment.BackgroundModel.classify`, eq. 5.4–5.5): background
  learned robustly from frames 1–469 (every 3rd), eq. 5.5 thresholds tuned on the tuning split.
* **OpenCV MOG2, KNN** (shadow detection on), **CNT**, **GSOC** (opencv-contrib ``bgsegm``):
  default parameters, run over frames 1–1200.

Scores: CDnet recall / precision / F (motion vs static + shadow, inside the ROI, unknown
excluded), FPR-S (shadow pixels labelled foreground) and shadow precision / recall for methods
that label shadows; frames/s single view on 320×240 (wall clock of the same run).
"""

from __future__ import annotations

import itertools
import time
from pathlib import Path

import cv2
import numpy as np

from studio.segment import (PERSON, SHADOW, AdaptiveSettings, BackgroundModel, learn_shadow_direction, learn_tint,
                            tune_thresholds)  # fmt: skip
from studio.segment.metrics import cdnet_scores


# The target point's tuning-split FPR-S limit: half the target's 0.30, a margin for an estimate made
# from 913 shadow pixels in 4 frames (470-699 every 10th; shadows only in 660-690). The plain
# "FPR-S <= 0.30 on the tuning split" pick is reported too.
GEOMETRY_MARGIN = 0.15
TARGET_POINT = "toolkit adaptive + geometry (FPR-S≤0.15)"


def _fmt(x) -> str:
    return "  —  " if x is None else f"{x:.3f}"


def _load(root: Path, last: int):
    frames = [cv2.cvtColor(cv2.imread(str(root / "input" / f"in{i:06d}.jpg")), cv2.COLOR_BGR2RGB)
              for i in range(1, last + 1)]  # fmt: skip
    return frames


def _run_adaptive(frames, settings: AdaptiveSettings, keep: set[int], want_means=False):
    """Labels (and running means) of the frames in ``keep`` (1-based), running from frame 1."""
    model = BackgroundModel.start(frames[0], adaptive=settings)
    out, means = {}, {}
    t0 = time.perf_counter()
    last = max(keep)
    for i in range(1, last + 1):
        labels = model.apply(frames[i - 1])
        if i in keep:
            out[i] = labels
            if want_means:
                means[i] = model.running_mean.copy()
    return out, means, last / (time.perf_counter() - t0)


def _run_opencv(frames, make, keep: set[int]):
    sub = make()
    out = {}
    t0 = time.perf_counter()
    last = max(keep)
    for i in range(1, last + 1):
        mask = sub.apply(cv2.cvtColor(frames[i - 1], cv2.COLOR_RGB2BGR))
        if i in keep:
            out[i] = np.where(mask == 255, PERSON, np.where(mask == 127, SHADOW, 0)).astype(np.uint8)
    return out, last / (time.perf_counter() - t0)


def _score_tuning(frames, truths, roi, tune, settings, rows):
    out, _, _ = _run_adaptive(frames, settings, set(tune))
    sc = cdnet_scores([out[i] for i in tune], [truths[i] for i in tune], roi)
    rows.append((settings.to_dict(), sc["f_measure"], sc["fpr_shadow"]))
    return sc["f_measure"], sc["fpr_shadow"]


def tune_adaptive(frames, truths, roi, tune: list[int]) -> tuple[dict, list]:
    """Detection grid, then shadow-gate grid (tint learned from the tuning GT), then the gates
    with cast-shadow geometry (direction learned from the tuning GT), all on the tuning split."""
    keep = set(tune)
    rows = []
    best_det, best_f = None, -1.0
    for k, dist in itertools.product((1.5, 2.0, 2.5), (8.0, 12.0, 16.0)):
        s = AdaptiveSettings(noise_scale=k, distance=dist, value_ratio=(0.0, 1e-3))  # no shadow label
        out, means, _ = _run_adaptive(frames, s, keep, want_means=best_det is None)
        if best_det is None:
            tint_means = means
        sc = cdnet_scores([out[i] for i in tune], [truths[i] for i in tune], roi)
        rows.append((s.to_dict(), sc["f_measure"], sc["fpr_shadow"]))
        if sc["f_measure"] > best_f:
            best_det, best_f = s, sc["f_measure"]
    tint = learn_tint([frames[i - 1] for i in tune], [tint_means[i] for i in tune],
                      [(truths[i] == 50) & roi for i in tune])  # fmt: skip
    direction = learn_shadow_direction([truths[i] == 255 for i in tune], [(truths[i] == 50) & roi for i in tune])
    best = {"f": (best_det, best_f, 1.0), "shadow": None, "geometry": None, "geometry_margin": None}
    for vr, chroma in itertools.product(((0.05, 0.2), (0.05, 0.3), (0.08, 0.4)), (0.05, 0.1, 0.2, 0.3)):
        gate = {**best_det.to_dict(), "value_ratio": vr, "chroma": chroma, "tint": tint}
        s = AdaptiveSettings.from_dict(gate)
        f, fprs = _score_tuning(frames, truths, roi, tune, s, rows)
        if f > best["f"][1]:
            best["f"] = (s, f, fprs)
        if fprs <= 0.30 and (best["shadow"] is None or f > best["shadow"][1]):
            best["shadow"] = (s, f, fprs)
        for fraction in (0.15, 0.2, 0.25):
            s = AdaptiveSettings.from_dict({**gate, "shadow_direction": direction, "shadow_fraction": fraction})
            f, fprs = _score_tuning(frames, truths, roi, tune, s, rows)
            for key, limit in (("geometry", 0.30), ("geometry_margin", GEOMETRY_MARGIN)):
                if fprs <= limit and (best[key] is None or f > best[key][1]):
                    best[key] = (s, f, fprs)
    return best, rows


def bench_cdnet(data: Path, quick: bool) -> dict | None:
    root = data / "segmentation" / "cdnet2014_highway"
    if not root.is_dir():
        print(f"\n== 2. CDnet: data not found at {root}, skipped")
        return None
    roi = cv2.imread(str(root / "ROI.bmp"), cv2.IMREAD_GRAYSCALE) > 0
    first_gt = int((root / "temporalROI.txt").read_text().split()[0])
    tune = list(range(first_gt, 700, 10))
    evaluate = list(range(700, 1201, 4 if quick else 1))
    frames = _load(root, max(evaluate))
    truths = {i: cv2.imread(str(root / "groundtruth" / f"gt{i:06d}.png"), cv2.IMREAD_GRAYSCALE) for i in tune + evaluate}
    gts = [truths[i] for i in evaluate]
    keep = set(evaluate)
    rows, speed = {}, {}

    # toolkit, adaptive
    t0 = time.perf_counter()
    best, table = tune_adaptive(frames, truths, roi, tune)
    tune_s = time.perf_counter() - t0
    picks = [("toolkit adaptive (best F)", best["f"])]
    if best["shadow"] is not None:
        picks.append(("toolkit adaptive (FPR-S≤0.3)", best["shadow"]))
    if best["geometry"] is not None:
        picks.append(("toolkit adaptive + geometry", best["geometry"]))
    if best["geometry_margin"] is not None:
        picks.append((TARGET_POINT, best["geometry_margin"]))
    for name, (settings, _, _) in picks:
        out, _, fps = _run_adaptive(frames, settings, keep)
        rows[name] = cdnet_scores([out[i] for i in evaluate], gts, roi)
        speed[name] = fps

    # toolkit, fixed model of eq. 5.4-5.5
    bg_frames = list(range(1, first_gt, 3))
    model = BackgroundModel.fit([frames[i - 1] for i in bg_frames])

    def objective(preds, gts_):
        s = cdnet_scores(preds, gts_, roi)
        return 0.5 * (s["f_measure"] + (s["shadow_precision"] + s["shadow_recall"]) / 2)

    fixed_best, _ = tune_thresholds(
        lambda th, k: model.with_settings(th).classify(frames[tune[k] - 1]), [truths[i] for i in tune],
        hsv=(4.0, 6.0, 8.0), saturation=(4.0, 8.0, 12.0, 16.0),
        value_ratio=((0.05, 0.95), (0.08, 0.5), (0.2, 0.9), (0.0, np.inf)), objective=objective)  # fmt: skip
    tuned = model.with_settings(fixed_best)
    t0 = time.perf_counter()
    out = {i: tuned.classify(frames[i - 1]) for i in evaluate}
    speed["toolkit fixed (eq. 5.5)"] = len(evaluate) / (time.perf_counter() - t0)
    rows["toolkit fixed (eq. 5.5)"] = cdnet_scores([out[i] for i in evaluate], gts, roi)

    # OpenCV peers
    peers = {"OpenCV GSOC": cv2.bgsegm.createBackgroundSubtractorGSOC,
             "OpenCV MOG2 + shadows": lambda: cv2.createBackgroundSubtractorMOG2(detectShadows=True),
             "OpenCV KNN + shadows": lambda: cv2.createBackgroundSubtractorKNN(detectShadows=True),
             "OpenCV CNT": cv2.bgsegm.createBackgroundSubtractorCNT}  # fmt: skip
    for name, make in peers.items():
        out, fps = _run_opencv(frames, make, keep)
        shadow = None if name in ("OpenCV GSOC", "OpenCV CNT") else SHADOW
        rows[name] = cdnet_scores([out[i] for i in evaluate], gts, roi, shadow=shadow)
        speed[name] = fps

    print(f"\n== 2. CDnet 2014 highway (real, single view 320×240): tuned on {len(tune)} GT frames "
          f"{tune[0]}–{tune[-1]} ({tune_s:.0f} s for the adaptive grid), evaluated on {len(evaluate)} "
          f"frames 700–1200; every method run over frames 1–{evaluate[-1]} in this run")  # fmt: skip
    print(f"{'method':<40} {'recall':>7} {'precis.':>7} {'F':>7} {'FPR-S':>7} {'shadowP':>7} {'shadowR':>7} {'fps':>6}")
    for name, m in rows.items():
        print(f"{name:<40} {_fmt(m['recall']):>7} {_fmt(m['precision']):>7} {_fmt(m['f_measure']):>7} "
              f"{_fmt(m['fpr_shadow']):>7} {_fmt(m['shadow_precision']):>7} {_fmt(m['shadow_recall']):>7} "
              f"{speed[name]:6.0f}")  # fmt: skip
    # the issue's target: ONE operating point (chosen on the tuning split) with F above GSOC's
    # and FPR-S <= 0.30 on the evaluation split
    point = TARGET_POINT if TARGET_POINT in rows else "toolkit adaptive (best F)"
    ours, gsoc = rows[point], rows["OpenCV GSOC"]
    f_met = ours["f_measure"] > gsoc["f_measure"]
    shadow_met = ours["fpr_shadow"] <= 0.30
    print(f"   target, one point ({point}): F above GSOC {ours['f_measure']:.3f} vs {gsoc['f_measure']:.3f} → "
          f"{'MET' if f_met else 'MISSED'}; FPR-S ≤ 0.30: {ours['fpr_shadow']:.3f} → {'MET' if shadow_met else 'MISSED'}")
    for name, (s, f, fprs) in picks:
        print(f"   {name}: {s.to_dict()} (tuning split F {f:.3f}, FPR-S {fprs:.3f})")
    return {"tuning_frames": tune, "eval_frames": [evaluate[0], evaluate[-1], len(evaluate)], "methods": rows,
            "frames_per_second": speed, "fixed_thresholds": fixed_best.to_dict(),
            "adaptive_settings": {name: s.to_dict() for name, (s, _, _) in picks},
            "adaptive_tuning": table, "target_point": point, "target_f_met": f_met,
            "target_shadow_met": shadow_met}  # fmt: skip
