"""CDnet 2014 *highway* part of ``benchmarks/segmentation.py``: the toolkit beside OpenCV's
subtractors, same frames, same protocol, one run.

Protocol (fixed before any evaluation figure of it was computed; the previous protocol tuned on
470–699 every 10th — 913 shadow pixels, one car — and added a tighter FPR-S margin after seeing the
evaluation figure of the plain rule). Ground truth starts at frame 470 (``temporalROI.txt``) and
the data ends at 1200.

* **Fixed split**: settings chosen on every frame 470–699 (230 frames, 7,848 shadow pixels in 96
  frames), scored on 700–1200 (every frame; ``--quick`` every 4th frame everywhere).
* **Blocked cross-validation** over the evaluation frames: 700–1200 cut into blocks of 50
  consecutive frames (1150–1200 the last), alternating between two folds
  (:func:`studio.segment.tuning.blocked_folds`). Each fold's frames are scored with settings
  chosen on 470–699 plus the other fold, without the frames within ``GAP`` = 10 frames of a
  scored frame (a car crosses a block boundary; :func:`~studio.segment.tuning.fold_tuning_frames`);
  the reported figure pools both folds' counts, so every evaluation frame is scored with settings
  never chosen on it.
* **Pick rule** (the target's own, no margin): the best tuning F among the points whose tuning
  FPR-S is ≤ 0.30 (:func:`~studio.segment.tuning.pick_operating_point`). The target — ONE
  operating point with F above GSOC's and FPR-S ≤ 0.30 on 700–1200 — is checked at that point
  under each protocol.

Methods:

* **toolkit, adaptive** (:meth:`studio.segment.BackgroundModel.apply`): started on frame 1 and
  run over every frame 1–1200 as the OpenCV subtractors are. For each tuning set: detection
  settings (noise band, distance; 3 × 3 grid) by best F without a shadow label; the shadow tint
  learned from the tuning set's shadow pixels (:func:`studio.segment.learn_tint`) and the
  object-to-shadow direction from its truth (:func:`studio.segment.learn_shadow_direction`);
  then 16 colour gates (value ratio × chroma), each alone and with cast-shadow geometry
  (:func:`studio.segment.shadow_geometry`, chord fraction 0.1–0.3), 96 points
  (``cdnet_adaptive.py``: one model pass per detection setting, gates replayed on the kept
  pixels). Three points: best F (detection or colour gate, no limit), the best colour gate with
  tuning FPR-S ≤ 0.30, and the **target point**: the pick rule over all 97 points.
* **toolkit, adaptive, label-free tint / direction** (added after the protocol above, issue 18):
  the same detection pick, gate grid and pick rule, but the tint and direction learned from the
  model's own foreground without any truth (:func:`studio.segment.learn_stream_shadows`, its
  defaults) over the stream before the evaluation frames and the set's own tuning frames, every
  ``STREAM_STEP``-th frame from ``STREAM_START`` (fixed split: 60–699, 320 frames). Its method
  and defaults were chosen on the tuning split 470–699 only (see that module); its evaluation
  figures were computed once, with that release's final code (before the rim and the strip's
  interior, next item), and are reported as measured (load 6–7):
  fixed split F 0.973, FPR-S 0.297 — target met, by 0.003 (the labelled tint / direction: 0.972,
  0.324); cross-validated F 0.971, FPR-S 0.270 (folds 0.204 / 0.320; labelled 0.973, 0.267).
* **Shadow rim and the strip's interior** (issue 18, second change; both chosen on 470–699 only,
  before any evaluation figure with them was computed): every gate of the grid grows its shadow
  by a 1-px rim (:class:`studio.segment.AdaptiveSettings` ``penumbra`` = 1: person pixels next to
  gated shadow that pass a loose gate — value ratio up to 0.6, chroma 0.4 — become shadow), and
  the label-free tint is learned from the kept strip's interior (``learn_stream_shadows``
  ``interior`` = 1). The rows above (both tint sources, both protocols) are all rerun with them;
  grids, pick rule and protocol are otherwise unchanged. The previous run's figures are in the
  README beside this run's. Evaluation figures computed once, with the final code, reported as
  measured (load 6–7): label-free fixed split F 0.973, FPR-S 0.308 — target missed (0.297 before);
  cross-validated F 0.972, FPR-S 0.259, folds 0.172 / 0.323 (fold 2 misses); labelled fixed split
  F 0.971, FPR-S 0.370 (missed; 0.324 before), cross-validated 0.972 / 0.254, folds 0.162 / 0.322.
  The tuning split had promised more (label-free tuning FPR-S 0.168 → 0.122 at F 0.9867 → 0.9875):
  the target does not hold in every fold and protocol.
* **Cast-shadow geometry, fourth evaluation** (issue 18, third change): the geometry's loss was
  broken down and variants of the chord test compared on 470–699 only (``cdnet_geometry.py``):
  there the test returns 259 of 7,848 shadow pixels (FPR-S 0.033 of 0.122) and no variant beats it
  under the pick rule, so the grid and the rule are unchanged. The one change the evaluation sees:
  the test's walks are no longer capped at 96 px (:func:`studio.segment.shadow_geometry` ``reach``
  None; identical counts at every grid point of 470–699). This is the **fourth evaluation of
  700–1200 across releases**, computed once with the final code (load 5.5–7.8): every toolkit
  figure is the previous release's to the last count — label-free fixed split F 0.973, FPR-S 0.308,
  cross-validated 0.972 / 0.259 (folds 0.172 / 0.323); labelled 0.971 / 0.370, 0.972 / 0.254
  (folds 0.162 / 0.322). The target still does not hold in every fold and protocol.
* **Unseen frames 1201–1700** (issue 18, fifth change; ``--cdnet-unseen DIR``): the shared copy
  ends at 1200; the sequence it was cut from (``SOURCE.md`` beside it: github.com/ZZZZZZZJJHHH/
  FrameDifference at 07919e2e…, ``highway/``, 1700 frames, truth 470–1700; extract it with
  ``git archive 07919e2e highway | tar -x --strip-components=1 -C DIR``) holds 500 more labelled
  frames (176,263 shadow pixels in 498 of them) that no choice of this toolkit ever saw. Checked
  byte for byte against the shared copy over 1–1200 (:func:`_same_sequence`), then scored under two
  protocols, each once (:func:`bench_unseen`): the fixed split's picks (chosen on 470–699) and an
  **extended split** — the same grids and pick rule tuned on every labelled frame of the shared copy
  (470–1200, 185,495 shadow pixels, 24× the fixed split's), fixed and blocked cross-validated over
  1201–1700. The extended split was added after the first figure of the first protocol had been
  seen (FPR-S 0.313, label-free), for the reason the fourth change had found (the fixed split's 96
  shadow frames hold almost none of the geometry's loss); nothing is chosen on 1201–1700. Measured
  (load ~1): picks from 470–699 F 0.975 / 0.973 (label-free / labelled) vs GSOC 0.950, FPR-S 0.313
  / 0.390 (missed); extended split F 0.975 / 0.976, FPR-S **0.251 / 0.273** (met); extended,
  cross-validated F 0.975 / 0.975, FPR-S 0.288 / 0.271 (folds 0.315 / 0.258 and 0.286 / 0.254).
* **toolkit, fixed** (:meth:`~studio.segment.BackgroundModel.classify`, eq. 5.4–5.5): background
  learned robustly from frames 1–469 (every 3rd), eq. 5.5 thresholds tuned on 470–699 (fixed
  split only).
* **OpenCV MOG2, KNN** (shadow detection on), **CNT**, **GSOC** (opencv-contrib ``bgsegm``):
  default parameters (nothing tuned), run over frames 1–1200.

Scores: CDnet recall / precision / F (motion vs static + shadow, inside the ROI, unknown
excluded), FPR-S (shadow pixels labelled foreground) and shadow precision / recall for methods
that label shadows; frames/s single view on 320×240 (wall clock of the same run).
"""

from __future__ import annotations

import time
from pathlib import Path

import cv2
import numpy as np

from cdnet_adaptive import (FPRS_LIMIT, DetectionRun, detection_grid, detection_settings, gate_grid,
                            label_free_shadows, labelled_shadows, picks, tint_purity, tuning_points)  # fmt: skip
from studio.segment import PERSON, SHADOW, BackgroundModel, tune_thresholds
from studio.segment.metrics import cdnet_scores
from studio.segment.tuning import blocked_folds, cdnet_counts, fold_tuning_frames, pick_operating_point, scores_from_counts

SPLIT, LAST = 700, 1200  # evaluation frames SPLIT..LAST, tuning split temporalROI start..SPLIT-1
UNSEEN = (1201, 1700)  # frames past the shared copy's end (``--cdnet-unseen``): scored once, never tuned on
BLOCK = 50  # frames per cross-validation block
GAP = 10  # frames next to a scored frame left out of its fold's tuning set
STREAM_START, STREAM_STEP = 60, 2  # label-free tint / direction: every 2nd frame from twice the warm-up
TARGET = "target"  # the pick whose evaluation figures the target is checked at
LABEL_FREE = "target, label-free"  # the same rule with the tint / direction learned without labels
POINTS = {"best F": "toolkit adaptive (best F)", "colour, FPR-S≤0.3": "toolkit adaptive, colour (FPR-S≤0.3)",
          TARGET: "toolkit adaptive, target pick (FPR-S≤0.3)",
          LABEL_FREE: "toolkit adaptive, target, label-free"}  # fmt: skip


PEERS = {"OpenCV GSOC": lambda: cv2.bgsegm.createBackgroundSubtractorGSOC(),
         "OpenCV MOG2 + shadows": lambda: cv2.createBackgroundSubtractorMOG2(detectShadows=True),
         "OpenCV KNN + shadows": lambda: cv2.createBackgroundSubtractorKNN(detectShadows=True),
         "OpenCV CNT": lambda: cv2.bgsegm.createBackgroundSubtractorCNT()}  # fmt: skip


def _fmt(x) -> str:
    return "  —  " if x is None else f"{x:.3f}"


def _round(v) -> tuple:
    return tuple(round(float(x), 3) for x in v)


def _angle(a, b) -> float:
    """Degrees between two image directions."""
    c = (a[0] * b[0] + a[1] * b[1]) / (np.hypot(*a) * np.hypot(*b))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def _load(root: Path, last: int, first: int = 1) -> list:
    """RGB frames ``first``..``last`` (1-based, both included) of ``root``'s ``input/``."""
    return [cv2.cvtColor(cv2.imread(str(root / "input" / f"in{i:06d}.jpg")), cv2.COLOR_BGR2RGB)
            for i in range(first, last + 1)]  # fmt: skip


def _truths(root: Path, frames) -> dict:
    return {i: cv2.imread(str(root / "groundtruth" / f"gt{i:06d}.png"), cv2.IMREAD_GRAYSCALE) for i in frames}


def _run_adaptive(frames, settings, keep: set[int]):
    """Labels of the frames in ``keep`` (1-based) from ``apply``, running from frame 1."""
    model = BackgroundModel.start(frames[0], adaptive=settings)
    out = {}
    t0 = time.perf_counter()
    last = max(keep)
    for i in range(1, last + 1):
        labels = model.apply(frames[i - 1])
        if i in keep:
            out[i] = labels
    return out, last / (time.perf_counter() - t0)


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


def adaptive_protocol(frames, truths: dict, roi, gt_frames: list[int], evaluate: list[int]) -> dict:
    """The adaptive model's picks under the fixed split and the blocked cross-validation.

    Returns ``{"tuning_sets": {name: frames}, "picks": {set: {point: (settings, f, fprs)}},
    "counts": {set: {point: (N, 8) counts over gt_frames}}, "folds": [...], ...}``.
    """
    row = {i: r for r, i in enumerate(gt_frames)}
    shadow_masks = {i: (truths[i] == 50) & roi for i in gt_frames}
    base = [i for i in gt_frames if i < evaluate[0]]
    folds = blocked_folds(evaluate, BLOCK)
    sets = {"fixed": base, **{f"fold {k + 1}": fold_tuning_frames(base, folds, k, GAP) for k in range(len(folds))}}
    det_table = detection_grid(frames, gt_frames, truths, roi)
    runs: dict = {}
    stream = range(STREAM_START, evaluate[-1] + 1, STREAM_STEP)
    out = {"tuning_sets": sets, "folds": folds, "picks": {}, "counts": {}, "tint": {}, "direction": {},
           "label_free": {}, "detection": {}, "shadow_pixels": {}, "purity": {}}  # fmt: skip
    for name, tune in sets.items():
        rows = np.asarray([row[i] for i in tune])
        det_key, det_f, det_fprs = pick_operating_point(tuning_points(det_table, rows))
        if det_key not in runs:
            runs.clear()  # one run's kept pixels at a time
            runs[det_key] = DetectionRun(frames, detection_settings(*det_key), gt_frames, extra=shadow_masks,
                                         stream=stream)  # fmt: skip
        run = runs[det_key]
        tint, direction = labelled_shadows(run, tune, truths, shadow_masks)
        table = gate_grid(run, gt_frames, truths, roi, tint, direction)
        det_point = (run.det, det_f, det_fprs)
        chosen = picks([det_point], tuning_points(table, rows))
        # label-free: the stream before the evaluation range and the set's own frames (no truth)
        own = set(tune)
        learned_from = [i for i in stream if i < evaluate[0] or i in own]
        learned = label_free_shadows(run, learned_from)
        out["purity"][name] = tint_purity(run, learned, learned_from, {i: truths[i] for i in tune})
        free_table = gate_grid(run, gt_frames, truths, roi, learned.tint, learned.direction)
        chosen[LABEL_FREE] = pick_operating_point([det_point, *tuning_points(free_table, rows)], FPRS_LIMIT)
        table.update(free_table)
        table[run.det] = det_table[det_key]
        out["picks"][name] = chosen
        out["counts"][name] = {p: table[c[0]] for p, c in chosen.items() if c is not None}
        out["tint"][name], out["direction"][name], out["detection"][name] = tint, direction, det_key
        out["label_free"][name] = learned
        out["shadow_pixels"][name] = int(sum(np.count_nonzero(shadow_masks[i]) for i in tune))
    return out


def cv_scores(proto: dict, gt_frames: list[int]) -> dict:
    """Per point: the pooled scores of the folds (each fold scored with its own pick) and each fold's."""
    row = {i: r for r, i in enumerate(gt_frames)}
    res = {}
    for point in POINTS:
        pooled, per_fold = [], []
        for k, scored in enumerate(proto["folds"]):
            counts = proto["counts"][f"fold {k + 1}"].get(point)
            if counts is None:
                break
            c = counts[[row[i] for i in scored]]
            pooled.append(c)
            per_fold.append(scores_from_counts(c))
        else:
            res[point] = {**scores_from_counts(np.concatenate(pooled)), "folds": per_fold}
    return res


def _fixed_model(frames, truths, roi, tune, evaluate, first_gt):
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
    fps = len(evaluate) / (time.perf_counter() - t0)
    return cdnet_scores([out[i] for i in evaluate], [truths[i] for i in evaluate], roi), fps, fixed_best, tuned


def bench_cdnet(data: Path, quick: bool, unseen: Path | None = None) -> dict | None:
    root = data / "segmentation" / "cdnet2014_highway"
    if not root.is_dir():
        print(f"\n== 2. CDnet: data not found at {root}, skipped")
        return None
    roi = cv2.imread(str(root / "ROI.bmp"), cv2.IMREAD_GRAYSCALE) > 0
    first_gt = int((root / "temporalROI.txt").read_text().split()[0])
    if unseen is not None:  # before the long part: a wrong folder is named at once
        _same_sequence(unseen, root, first_gt)
    step = 4 if quick else 1
    gt_frames = list(range(first_gt, LAST + 1, step))
    evaluate = [i for i in gt_frames if i >= SPLIT]
    tune = [i for i in gt_frames if i < SPLIT]
    # with --cdnet-unseen: its frames past LAST appended, and every run below goes on through them
    later = [i for i in range(first_gt, UNSEEN[1] + 1, step) if i >= UNSEEN[0]] if unseen is not None else []
    frames = _load(root, LAST) + (_load(unseen, UNSEEN[1], LAST + 1) if later else [])
    truths = _truths(root, gt_frames) | (_truths(unseen, later) if later else {})
    gts = [truths[i] for i in evaluate]
    keep = set(evaluate) | set(later)
    rows, speed, cv_rows, outs = {}, {}, {}, {}

    # toolkit, adaptive: both protocols from one set of grids
    t0, c0 = time.perf_counter(), time.process_time()
    proto = adaptive_protocol(frames, truths, roi, gt_frames, evaluate)
    grid_wall, grid_cpu = time.perf_counter() - t0, time.process_time() - c0
    ev_rows = [gt_frames.index(i) for i in evaluate]
    mismatch = {}
    for point, name in POINTS.items():
        pick = proto["picks"]["fixed"][point]
        if pick is None:
            continue
        out, fps = _run_adaptive(frames, pick[0], keep)  # the fixed split's picks run through apply itself
        outs[name] = out
        real = np.stack([cdnet_counts(out[i], truths[i], roi) for i in evaluate])
        mismatch[name] = int(np.abs(real - proto["counts"]["fixed"][point][ev_rows]).sum())
        rows[name] = scores_from_counts(real)
        speed[name] = fps
    for point, sc in cv_scores(proto, gt_frames).items():
        cv_rows[POINTS[point]] = sc

    # toolkit, fixed model of eq. 5.4-5.5 (fixed split only)
    name = "toolkit fixed (eq. 5.5)"
    rows[name], speed[name], fixed_best, fixed_model = _fixed_model(frames, truths, roi, tune, evaluate, first_gt)

    # OpenCV peers
    for name, make in PEERS.items():
        out, fps = _run_opencv(frames, make, keep)
        outs[name] = out
        shadow = None if name in ("OpenCV GSOC", "OpenCV CNT") else SHADOW
        rows[name] = cdnet_scores([out[i] for i in evaluate], gts, roi, shadow=shadow)
        rows[name]["folds"] = [cdnet_scores([out[i] for i in fold], [truths[i] for i in fold], roi, shadow=shadow)
                               for fold in proto["folds"]]  # fmt: skip
        speed[name] = fps
    res = _report(proto, rows, cv_rows, speed, mismatch, fixed_best, tune, evaluate, grid_wall, grid_cpu, max(keep))
    if later:
        res["unseen"] = bench_unseen(frames, truths, roi, list(range(first_gt, later[-1] + 1, step)), later, outs,
                                     fixed_model, speed, str(unseen))  # fmt: skip
    else:
        print(f"   unseen frames {UNSEEN[0]}–{UNSEEN[1]}: not scored (--cdnet-unseen DIR, the full sequence: "
              "see benchmarks/segmentation_cdnet.py)")
    return res


def _report(proto, rows, cv_rows, speed, mismatch, fixed_best, tune, evaluate, grid_wall, grid_cpu, last) -> dict:
    print(f"\n== 2. CDnet 2014 highway (real, single view 320×240): fixed split tuned on {len(tune)} GT frames "
          f"{tune[0]}–{tune[-1]}, blocked {len(proto['folds'])}-fold CV over {len(evaluate)} frames "
          f"{evaluate[0]}–{evaluate[-1]} (blocks of {BLOCK}, gap {GAP}); adaptive grids {grid_cpu:.0f} s CPU / "
          f"{grid_wall:.0f} s wall; every method run over frames 1–{last} in this run")  # fmt: skip
    _print_rows({**rows, **{f"{n} [CV]": m for n, m in cv_rows.items()}}, speed)
    gsoc = rows["OpenCV GSOC"]
    verdict = {}
    for point, protocol, res in [(p, pr, r) for p in (TARGET, LABEL_FREE)
                                 for pr, r in (("fixed split", rows), ("blocked CV", cv_rows))]:  # fmt: skip
        key = protocol if point == TARGET else f"{protocol}, label-free"
        ours = res.get(POINTS[point])
        if ours is None:
            print(f"   target ({key}): no point with tuning FPR-S ≤ 0.30 → MISSED")
            verdict[key] = {"f_met": False, "shadow_met": False}
            continue
        verdict[key] = _verdict(key, ours, gsoc)
    for name, tune_set in proto["tuning_sets"].items():
        free = proto["label_free"][name]
        print(f"   tuning set {name}: {len(tune_set)} frames, {proto['shadow_pixels'][name]} shadow pixels; "
              f"detection {proto['detection'][name]}, tint {_round(proto['tint'][name])} direction "
              f"{_round(proto['direction'][name])} from labels; label-free from {free.frames} stream frames: "
              f"tint {_round(free.tint)} direction {_round(free.direction)} "
              f"({_angle(free.direction, proto['direction'][name]):.1f}° apart; {free.pixels} pixels, "
              f"{free.regions} regions)")  # fmt: skip
        pur = proto["purity"][name]
        print(f"      label-free tint's pixels on the set's own truth: {pur['shadow']} shadow, {pur['car']} car, "
              f"{pur['unknown']} unknown → purity {pur['purity']:.3f}")  # fmt: skip
        for point, pick in proto["picks"][name].items():
            if pick is not None:
                s = pick[0]
                print(f"      {point}: value_ratio {s.value_ratio} chroma {s.chroma} fraction "
                      f"{s.shadow_fraction if s.shadow_direction else '—'} (tuning F {pick[1]:.3f}, FPR-S {pick[2]:.3f})")
    _print_folds({**cv_rows, "OpenCV GSOC": gsoc})
    print(f"   cached grid vs apply (fixed split picks, summed |count differences|): {mismatch}")
    return {"tuning_frames": tune, "eval_frames": [evaluate[0], evaluate[-1], len(evaluate)],
            "protocol": {"block": BLOCK, "gap": GAP, "folds": proto["folds"], "tuning_sets": proto["tuning_sets"],
                         "tuning_shadow_pixels": proto["shadow_pixels"]},
            "methods": rows, "cross_validation": cv_rows, "frames_per_second": speed,
            "fixed_thresholds": fixed_best.to_dict(),
            "adaptive_picks": _picks_dict(proto),
            "learned": {name: {"labelled": {"tint": proto["tint"][name], "direction": proto["direction"][name]},
                               "label_free": {"tint": f.tint, "direction": f.direction, "pixels": f.pixels,
                                              "regions": f.regions, "frames": f.frames},
                               "label_free_purity": proto["purity"][name]}
                        for name, f in proto["label_free"].items()},
            "cache_mismatch": mismatch, "target": verdict, "grid_cpu_s": grid_cpu, "grid_wall_s": grid_wall}  # fmt: skip


def _same_sequence(full: Path, shared: Path, first_gt: int) -> None:
    """Raise unless ``full`` holds the shared copy's frames 1–``LAST`` and truth from ``first_gt`` on,
    byte for byte (the picks are chosen on them and the models run from frame 1)."""
    names = [f"input/in{i:06d}.jpg" for i in range(1, LAST + 1)]
    names += [f"groundtruth/gt{i:06d}.png" for i in range(first_gt, LAST + 1)] + ["ROI.bmp"]
    for name in names:
        a, b = full / name, shared / name
        if not a.is_file():
            raise SystemExit(f"{a}: missing; expected the full CDnet 2014 highway sequence (frames 1–{UNSEEN[1]})")
        if a.read_bytes() != b.read_bytes():
            raise SystemExit(f"{a}: differs from {b}; expected the sequence the shared copy was cut from")
    for i in range(UNSEEN[0], UNSEEN[1] + 1):
        for name in (f"input/in{i:06d}.jpg", f"groundtruth/gt{i:06d}.png"):
            if not (full / name).is_file():
                raise SystemExit(f"{full / name}: missing; expected frames and truth {UNSEEN[0]}–{UNSEEN[1]}")


def _verdict(key: str, ours: dict, gsoc: dict) -> dict:
    """The target at one pick (F above GSOC's on the same frames, FPR-S ≤ 0.30), printed; with
    ``folds`` (cross-validation, pooled) each fold's too (:func:`_print_folds` prints them)."""
    f_met, shadow_met = ours["f_measure"] > gsoc["f_measure"], ours["fpr_shadow"] <= 0.30
    out = {"f_met": f_met, "shadow_met": shadow_met}
    if "folds" in ours:  # each fold on its own: its point against GSOC on the same frames
        out["per_fold"] = [{"f_met": o["f_measure"] > g["f_measure"], "shadow_met": o["fpr_shadow"] <= 0.30}
                           for o, g in zip(ours["folds"], gsoc["folds"])]  # fmt: skip
    kind = "one point per fold, pooled" if "folds" in ours else "one point"
    print(f"   target ({key}, {kind}): F above GSOC {ours['f_measure']:.3f} vs {gsoc['f_measure']:.3f} → "
          f"{'MET' if f_met else 'MISSED'}; FPR-S ≤ 0.30: {ours['fpr_shadow']:.3f} → "
          f"{'MET' if shadow_met else 'MISSED'}")  # fmt: skip
    return out


def _picks_dict(proto: dict) -> dict:
    """{tuning set: {point: settings and tuning figures, or None}} of :func:`adaptive_protocol`."""
    return {name: {p: None if c is None else {"settings": c[0].to_dict(), "tuning_f": c[1], "tuning_fpr_shadow": c[2]}
                   for p, c in ps.items()} for name, ps in proto["picks"].items()}


def _print_folds(rows: dict) -> None:
    for point, sc in rows.items():
        print(f"   {point} per fold: " + "; ".join(f"F {f['f_measure']:.3f} FPR-S {f['fpr_shadow']:.3f}"
                                                   for f in sc["folds"]))


def _print_rows(rows: dict, speed: dict) -> None:
    print(f"{'method':<52} {'recall':>7} {'precis.':>7} {'F':>7} {'FPR-S':>7} {'shadowP':>7} {'shadowR':>7} {'fps':>6}")
    for name, m in rows.items():
        fps = f"{speed[name]:6.0f}" if name in speed else "     —"
        print(f"{name:<52} {_fmt(m['recall']):>7} {_fmt(m['precision']):>7} {_fmt(m['f_measure']):>7} "
              f"{_fmt(m['fpr_shadow']):>7} {_fmt(m['shadow_precision']):>7} {_fmt(m['shadow_recall']):>7} {fps}")  # fmt: skip


def bench_unseen(frames: list, truths: dict, roi, gt_frames: list[int], scored: list[int], outs: dict,
                 fixed_model, speed: dict, source: str) -> dict:
    """Frames ``UNSEEN`` (past the shared copy's end; ``scored``) under two protocols, each scored once.

    * **picks from 470–699**: the fixed split's picks, the OpenCV peers at their defaults and the
      fixed eq. 5.5 model — ``outs`` (labels by method name) and ``speed`` of :func:`bench_cdnet`'s
      runs, which went on through these frames — nothing was ever chosen on, or looked at in,
      these frames before this was computed;
    * **extended split**: the same protocol (:func:`adaptive_protocol`, pick rule, grids) with every
      labelled frame of the shared copy (470–1200: 24 times the fixed split's shadow pixels) as the
      tuning set and ``scored`` as the evaluation frames, fixed and blocked cross-validated — the
      evidence the fixed split lacks (its 96 shadow frames hold almost none of the geometry's loss).

    ``frames`` 1..``scored[-1]``, ``truths`` over ``gt_frames`` (470..``scored[-1]``), both checked
    against the shared copy first (:func:`_same_sequence`)."""
    gts, keep = [truths[i] for i in scored], set(scored)
    t0, c0 = time.perf_counter(), time.process_time()
    extended = adaptive_protocol(frames, truths, roi, gt_frames, scored)
    grid_wall, grid_cpu = time.perf_counter() - t0, time.process_time() - c0
    first_gt = gt_frames[0]
    rows, speed = {}, dict(speed)
    for name in [n for n in POINTS.values() if n in outs]:
        rows[f"{name}, picks from 470–699"] = scores_from_counts(
            np.stack([cdnet_counts(outs[name][i], truths[i], roi) for i in scored]))
        speed[f"{name}, picks from 470–699"] = speed[name]
    for point, name in POINTS.items():
        pick = extended["picks"]["fixed"][point]
        if pick is not None:
            out, speed[f"{name}, extended split"] = _run_adaptive(frames, pick[0], keep)
            rows[f"{name}, extended split"] = scores_from_counts(
                np.stack([cdnet_counts(out[i], truths[i], roi) for i in scored]))
    cv_rows = {f"{POINTS[p]}, extended [CV]": sc for p, sc in cv_scores(extended, gt_frames).items()}
    t0 = time.perf_counter()
    out = {i: fixed_model.classify(frames[i - 1]) for i in scored}
    speed["toolkit fixed (eq. 5.5)"] = len(scored) / (time.perf_counter() - t0)
    rows["toolkit fixed (eq. 5.5)"] = cdnet_scores([out[i] for i in scored], gts, roi)
    for name in PEERS:
        shadow = None if name in ("OpenCV GSOC", "OpenCV CNT") else SHADOW
        rows[name] = cdnet_scores([outs[name][i] for i in scored], gts, roi, shadow=shadow)
        rows[name]["folds"] = [cdnet_scores([outs[name][i] for i in fold], [truths[i] for i in fold], roi,
                                            shadow=shadow) for fold in extended["folds"]]  # fmt: skip
    shadow_px = int(sum(np.count_nonzero((truths[i] == 50) & roi) for i in scored))
    shadow_frames = sum(bool(np.any((truths[i] == 50) & roi)) for i in scored)
    print(f"\n== 2b. CDnet 2014 highway, unseen frames {scored[0]}–{scored[-1]} ({len(scored)} frames, "
          f"{shadow_px} shadow pixels in {shadow_frames}): the fixed split's picks (470–699) and the extended "
          f"split's (tuned on {extended['shadow_pixels']['fixed']} shadow pixels of {first_gt}–{scored[0] - 1}; "
          f"grids {grid_cpu:.0f} s CPU / {grid_wall:.0f} s wall)")  # fmt: skip
    _print_rows({**rows, **cv_rows}, speed)
    verdict = {k: _verdict(k, m, rows["OpenCV GSOC"]) for k, m in {**rows, **cv_rows}.items() if "target" in k}
    _print_folds({**cv_rows, "OpenCV GSOC": rows["OpenCV GSOC"]})
    for point, pick in extended["picks"]["fixed"].items():
        if pick is not None:
            s = pick[0]
            print(f"   extended split, {point}: value_ratio {s.value_ratio} chroma {s.chroma} fraction "
                  f"{s.shadow_fraction if s.shadow_direction else '—'} (tuning F {pick[1]:.3f}, FPR-S {pick[2]:.3f})")
    return {"frames": [scored[0], scored[-1], len(scored)], "shadow_pixels": shadow_px, "shadow_frames": shadow_frames,
            "source": source, "methods": rows, "cross_validation": cv_rows,
            "frames_per_second": {k: v for k, v in speed.items() if k in rows},
            "target": verdict, "extended_tuning_shadow_pixels": extended["shadow_pixels"],
            "extended_picks": _picks_dict(extended),
            "grid_cpu_s": grid_cpu, "grid_wall_s": grid_wall}
