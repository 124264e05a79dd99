"""Where CDnet *highway*'s labelled shadow pixels are lost, and variants of the cast-shadow geometry,
on the tuning split only (frames 470–699; issue 18).

Nothing here reads a frame from 700–1200. The settings are those the fixed split of
``segmentation_cdnet.py`` picks on 470–699 (detection noise 2.0 / distance 12; label-free tint and
direction from the stream 60–699, every 2nd frame; gate value ratio 0.05–0.2, chroma 0.2, rim 1,
geometry fraction 0.15), and, for comparison, the previous release's gate (0.05–0.3, chroma 0.3).

1. **Breakdown**: per frame, the labelled shadow pixels (truth 50 inside the ROI) labelled person
   after the colour gate, after the shadow rim (:func:`studio.segment.adaptive.penumbra_rim`),
   after the morphology and after the geometry (:func:`studio.segment.shadow_geometry`), and the
   car pixels (truth 255) still labelled shadow; the geometry's give-back sorted by what lies on
   the walk ahead of the pixel (another person pixel, or shadow only to the background).
2. **Variants** of the geometry, each over the grid's 16 gates × 5 fractions, chosen by the pick
   rule (best tuning F with tuning FPR-S ≤ 0.30) inside 470–699: one block of 23 frames left out
   at a time (gap 10), its counts scored with the pick made on the rest, pooled — the check the
   shadow rim was chosen by. Variants: ``chord`` (the test as it is), ``reach 96`` (the walk
   capped at 96 px, the default before this release), ``trim`` (the walk ahead ends at the last
   shadow pixel: a lighter rim labelled person at the strip's far edge does not lengthen it),
   ``wide`` (the walk behind is the longest of three parallel lines 1 px apart: a strip pixel at
   the object's corner sees the object), ``grow k`` (a pixel the test turned person is shadow
   again when shadow the test kept lies within k steps ahead through gated pixels: the strip's
   near edge), ``far edge`` (also kept: a pixel with only shadow ahead whose shadow run behind
   ends at an object at least 4 times as long as the run, 90 % person).

This release's run (load 5.5, 35 s of CPU): at the pick, person after gate / rim / morphology /
geometry 2,930 / 789 / 698 / 957 of 7,848 (FPR-S 0.373 / 0.101 / 0.089 / 0.122): the geometry gives
back 259 (184 with a person pixel ahead, 75 shadow only) and returns 71,240 of the 75,214 car
pixels the gate took; at the previous gate it gives back 322. Inner cross-validation (F / FPR-S):
chord 0.9875 / 0.122; reach 96 identical; trim 0.9839 / 0.142; wide 0.9868 / 0.118; grow 2
0.9815 / 0.168; grow 4 0.9631 / 0.118; far edge 0.9671 / 0.062; each with the chord test in the same
grid the rule picks the chord test (trim: in nine blocks of ten). No variant kept.

Run: ``.venv/bin/python benchmarks/cdnet_geometry.py``; writes ``benchmarks/results/cdnet_geometry.json``.
"""

from __future__ import annotations

import itertools
import json
import math
import sys
import time
from collections import Counter
from pathlib import Path

import cv2
import numpy as np
from numba import njit

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))

from cdnet_adaptive import (CHROMAS, FRACTIONS, FPRS_LIMIT, VALUE_RATIOS, DetectionRun,  # noqa: E402
                            detection_settings, label_free_shadows)  # fmt: skip
from rigs.atomic import atomic_write_text  # noqa: E402
from studio.segment import PERSON, SHADOW, AdaptiveSettings, clean_labels, shadow_geometry  # noqa: E402
from studio.segment.adaptive import adaptive_step, penumbra_rim  # noqa: E402
from studio.segment.tuning import blocked_folds, cdnet_counts, fold_tuning_frames, pick_operating_point, scores_from_counts  # noqa: E402,E501

DATA = REPO.parent / "shared" / "data" / "segmentation" / "cdnet2014_highway"
RESULTS = REPO / "benchmarks" / "results" / "cdnet_geometry.json"
TUNE = range(470, 700)
STREAM = range(60, 700, 2)
PICKED = ((0.05, 0.2), 0.2, 0.15)  # the fixed split's pick on 470-699 (value ratio, chroma, fraction)
PREVIOUS = ((0.05, 0.3), 0.3, 0.15)  # the previous release's pick


@njit(cache=True, nogil=True)
def _walk(labels, y, x, dx, dy, reach, stop_not):
    """Steps from (y, x) along (dx, dy) to the first pixel whose label is not ``stop_not`` (0: to
    background, any foreground continues; 2: to the end of the shadow run) or off the image;
    returns (steps, label met, -1 off the image)."""
    h, w = labels.shape
    for t in range(1, reach):
        yy, xx = int(math.floor(y + t * dy + 0.5)), int(math.floor(x + t * dx + 0.5))
        if yy < 0 or yy >= h or xx < 0 or xx >= w:
            return t, -1
        v = labels[yy, xx]
        if (stop_not == 0 and v == 0) or (stop_not == 2 and v != 2):
            return t, v
    return reach, stop_not


@njit(cache=True, nogil=True)
def _variant(labels, geo, dx, dy, fraction, reach, kind, k):
    """Geometry variants (module docstring): kind 1 trim, 2 wide, 3 grow k, 4 far edge."""
    out = geo.copy() if kind >= 3 else labels.copy()
    h, w = labels.shape
    for y in range(h):
        for x in range(w):
            if labels[y, x] != SHADOW:
                continue
            if kind == 1 or kind == 2:
                ahead, _ = _walk(labels, y, x, dx, dy, reach, 0)
                behind, _ = _walk(labels, y, x, -dx, -dy, reach, 0)
                if kind == 1:
                    last = 1
                    for t in range(1, ahead):
                        yy, xx = int(math.floor(y + t * dy + 0.5)), int(math.floor(x + t * dx + 0.5))
                        if labels[yy, xx] == SHADOW:
                            last = t + 1
                    ahead = last
                else:
                    for o in (-1, 1):
                        yy, xx = int(math.floor(y + o * dx + 0.5)), int(math.floor(x - o * dy + 0.5))
                        if 0 <= yy < h and 0 <= xx < w and labels[yy, xx] != 0:
                            behind = max(behind, _walk(labels, yy, xx, -dx, -dy, reach, 0)[0])
                if ahead > fraction * (ahead + behind - 1):
                    out[y, x] = PERSON
            elif geo[y, x] != SHADOW and kind == 3:
                for t in range(1, k + 1):
                    yy, xx = int(math.floor(y + t * dy + 0.5)), int(math.floor(x + t * dx + 0.5))
                    if yy < 0 or yy >= h or xx < 0 or xx >= w or labels[yy, xx] != SHADOW:
                        break
                    if geo[yy, xx] == SHADOW:
                        out[y, x] = SHADOW
                        break
            elif geo[y, x] != SHADOW and kind == 4:
                _, met = _walk(labels, y, x, dx, dy, reach, 2)
                run, obj = _walk(labels, y, x, -dx, -dy, reach, 2)
                if met == PERSON or obj != PERSON:
                    continue
                oy, ox = int(math.floor(y - run * dy + 0.5)), int(math.floor(x - run * dx + 0.5))
                length, person = 0, 0
                for t in range(0, reach):
                    yy, xx = int(math.floor(oy - t * dy + 0.5)), int(math.floor(ox - t * dx + 0.5))
                    if yy < 0 or yy >= h or xx < 0 or xx >= w or labels[yy, xx] == 0:
                        break
                    length += 1
                    person += labels[yy, xx] == PERSON
                if run <= 0.25 * length and person >= 0.9 * length:
                    out[y, x] = SHADOW
    return out


def variants(direction) -> dict:
    """``{name: labels -> (fraction -> new labels)}`` for every geometry variant."""
    dx, dy = direction

    def v(kind, k=0, reach=None):
        def apply(lab, f):
            geo = shadow_geometry(lab, direction, f, reach=reach)
            return geo if kind == 0 else _variant(lab, geo, dx, dy, f, lab.shape[0] + lab.shape[1], kind, k)
        return apply

    return {"chord": v(0), "reach 96": v(0, reach=96), "trim": v(1), "wide": v(2), "grow 2": v(3, 2),
            "grow 4": v(3, 4), "far edge": v(4)}  # fmt: skip


def _stages(run: DetectionRun, i: int, gate: AdaptiveSettings):
    """Labels of frame ``i`` after the gate (rim candidates person), the rim and the morphology."""
    idx, values, mean, dev = run.pixels[i]
    sub, _ = adaptive_step(values, mean.copy(), dev.copy(), gate, 10**9, rim=False)
    raw = np.zeros(run.shape, np.uint8)
    raw.reshape(-1)[idx] = sub[0]
    gated = np.where(raw == 3, PERSON, raw).astype(np.uint8)
    rim = penumbra_rim(raw, gate.penumbra)
    return gated, rim, clean_labels(rim)


def breakdown(run, truths, roi, tint, direction, point) -> dict:
    """Stage counts over 470–699 at ``point`` (value ratio, chroma, fraction), per frame and summed."""
    vr, chroma, fraction = point
    gate = AdaptiveSettings.from_dict({**run.det.to_dict(), "value_ratio": vr, "chroma": chroma, "tint": tint, "penumbra": 1})
    per, ahead = [], Counter()
    dx, dy = direction
    for i in TUNE:
        sh, car = (truths[i] == 50) & roi, (truths[i] == 255) & roi
        gated, rim, clean = _stages(run, i, gate)
        geo = shadow_geometry(clean, direction, fraction)
        per.append([i, int(sh.sum())] + [int((sh & (lab == PERSON)).sum()) for lab in (gated, rim, clean, geo)]
                   + [int((car & (lab == SHADOW)).sum()) for lab in (clean, geo)])  # fmt: skip
        for y, x in zip(*np.nonzero(sh & (clean == SHADOW) & (geo == PERSON))):
            n, met = _walk(clean, y, x, dx, dy, 10**4, 2)
            ahead["person ahead" if met == PERSON else "shadow only ahead"] += 1
    per = np.asarray(per)
    total = per[:, 1:].sum(0)
    names = ("gate", "rim", "morphology", "geometry")
    return {"shadow_pixels": int(total[0]), "person_after": dict(zip(names, map(int, total[1:5]))),
            "fpr_s_after": {n: float(v / total[0]) for n, v in zip(names, total[1:5])},
            "car_as_shadow": {"morphology": int(total[5]), "geometry": int(total[6])},
            "geometry_give_back": int(total[4] - total[3]), "give_back_by_ahead": dict(ahead),
            "frames_most_given_back": [[int(r[0]), int(r[5] - r[4])] for r in per[np.argsort(-(per[:, 5] - per[:, 4]))[:8]]]}  # fmt: skip


def variant_table(run, truths, roi, tint, direction) -> dict:
    """Counts (230, 8) of every (value ratio, chroma, variant, fraction) and of each gate alone."""
    table, rules = {}, variants(direction)
    for vr, chroma in itertools.product(VALUE_RATIOS, CHROMAS):
        gate = AdaptiveSettings.from_dict({**run.det.to_dict(), "value_ratio": vr, "chroma": chroma, "tint": tint,
                                           "penumbra": 1})  # fmt: skip
        rows: dict = {}
        for i in TUNE:
            lab = run.gated_labels(i, gate)
            rows.setdefault((vr, chroma, None, None), []).append(cdnet_counts(lab, truths[i], roi))
            for name, rule in rules.items():
                for f in FRACTIONS:
                    rows.setdefault((vr, chroma, name, f), []).append(cdnet_counts(rule(lab, f), truths[i], roi))
        table.update({key: np.stack(v) for key, v in rows.items()})
    return table


def inner_cv(table: dict, det_counts: np.ndarray, allowed: set) -> dict:
    """The pick rule inside 470–699 (leave one block of 23 frames out, gap 10) over the detection
    point, the gates alone and the geometry variants in ``allowed``; pooled scores of the left-out
    blocks and the pick over all of 470–699."""
    tune = list(TUNE)
    folds = blocked_folds(tune, block=23, n_folds=10)
    keys = ["detection"] + [k for k in table if k[2] is None or k[2] in allowed]
    tab = {**table, "detection": det_counts}

    def points(rows):
        return [(k, *(lambda s: (s["f_measure"], s["fpr_shadow"]))(scores_from_counts(tab[k][rows]))) for k in keys]

    pooled, picks = [], []
    for k in range(len(folds)):
        rows = np.asarray([i - tune[0] for i in fold_tuning_frames([], folds, k, gap=10)])
        key = pick_operating_point(points(rows), FPRS_LIMIT)[0]
        pooled.append(tab[key][np.asarray(folds[k]) - tune[0]])
        picks.append(str(key))
    s = scores_from_counts(np.concatenate(pooled))
    whole = pick_operating_point(points(np.arange(len(tune))), FPRS_LIMIT)
    return {"f": s["f_measure"], "fpr_s": s["fpr_shadow"], "picks": Counter(picks).most_common(3),
            "whole": {"key": str(whole[0]), "f": whole[1], "fpr_s": whole[2]}}


def main() -> int:
    c0, t0 = time.process_time(), time.perf_counter()
    roi = cv2.imread(str(DATA / "ROI.bmp"), cv2.IMREAD_GRAYSCALE) > 0
    frames = [cv2.cvtColor(cv2.imread(str(DATA / "input" / f"in{i:06d}.jpg")), cv2.COLOR_BGR2RGB) for i in range(1, TUNE[-1] + 1)]
    truths = {i: cv2.imread(str(DATA / "groundtruth" / f"gt{i:06d}.png"), cv2.IMREAD_GRAYSCALE) for i in TUNE}
    run = DetectionRun(frames, detection_settings(2.0, 12.0), list(TUNE), stream=STREAM)
    free = label_free_shadows(run, list(STREAM))
    det_counts = np.stack([cdnet_counts(run.detection_labels(i), truths[i], roi) for i in TUNE])
    out = {"tint": free.tint, "direction": free.direction, "breakdown": {}, "variants": {}}
    for name, point in (("picked", PICKED), ("previous", PREVIOUS)):
        b = out["breakdown"][name] = breakdown(run, truths, roi, free.tint, free.direction, point)
        print(f"{name} {point}: {b['shadow_pixels']} shadow px; person after gate / rim / morphology / geometry "
              f"{list(b['person_after'].values())} (FPR-S {', '.join(f'{v:.3f}' for v in b['fpr_s_after'].values())}); "
              f"geometry gives back {b['geometry_give_back']} {b['give_back_by_ahead']}; car px as shadow "
              f"{b['car_as_shadow']}; most given back (frame, px) {b['frames_most_given_back'][:5]}")  # fmt: skip
    table = variant_table(run, truths, roi, free.tint, free.direction)
    print(f"{'geometry in the grid':<22} {'inner-CV F':>10} {'FPR-S':>6}   pick on all of 470–699 (F, FPR-S)")
    for name in variants(free.direction):
        for allowed in ({name}, {"chord", name}) if name != "chord" else ({name},):
            r = out["variants"][" or ".join(sorted(allowed))] = inner_cv(table, det_counts, allowed)
            print(f"{' or '.join(sorted(allowed)):<22} {r['f']:10.4f} {r['fpr_s']:6.3f}   {r['whole']['key']} "
                  f"({r['whole']['f']:.4f}, {r['whole']['fpr_s']:.3f})")  # fmt: skip
    out["cpu_s"], out["wall_s"] = time.process_time() - c0, time.perf_counter() - t0
    print(f"{out['cpu_s']:.0f} s CPU, {out['wall_s']:.0f} s wall")
    atomic_write_text(RESULTS, json.dumps(out, indent=2, default=float) + "\n", mkdir=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
