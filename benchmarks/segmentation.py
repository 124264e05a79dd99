"""Segmentation benchmark (thesis §5.5, §6.3.4): accuracy on simulated and real data, speed.

Parts, one run, side by side:

1. **Simulated multi-view session** with truth (``truth/labels/<cam>/NNNNNN.png``): person and
   shadow precision / recall / F1 per camera before and after multi-view voting. Targets:
   person F1 ≥ 0.97, shadow F1 ≥ 0.90 after voting. ``--session DIR`` picks the session;
   without it, a simulator session under ``studio/samples/`` (or ``--search``) is used if one
   has truth labels, else the box scene of :mod:`studio.segment.synthetic` (said so).
2. **CDnet 2014 highway** (real, single view; ``segmentation_cdnet.py``): the adaptive model
   (:meth:`BackgroundModel.apply`) and the fixed eq. 5.5 model beside OpenCV GSOC, MOG2, KNN,
   CNT, all run over the same frames in this run; settings tuned on GT frames 470–699 (fixed
   split) and by blocked cross-validation over 700–1200, scores on 700–1200: CDnet recall /
   precision / F, FPR-S (shadow pixels labelled foreground), shadow precision / recall, frames/s.
   Targets: F above GSOC's, FPR-S ≤ 0.30.
3. **Skin** (real SFA faces + abdomen masks, threshold 128): train on even-indexed images of
   each set, test on the odd ones; HS-histogram classifier (posterior ranking and the literal
   eq. 6.10 density rule) vs a fixed YCrCb box (Cr 133–173, Cb 77–127).
4. **Speed**: classification + morphology + voting of 4 × 656×490 multi-frames; target ≥ 20
   multi-frames/s. Reported single-process wall clock, CPU time per multi-frame (one OpenCV
   thread) and the throughput of 2 worker processes.

5. **Throughput** (``segmentation_speed.py``): 4 views, toolkit vs GSOC vs MOG2, same frames.
6. **UU capture** (``segmentation_uu.py``): empty-scene false positives per frame, registration
   and mask quality on the person frames, the chair case as a picture.

Run: ``.venv/bin/python benchmarks/segmentation.py [--session DIR] [--quick] [--skip PART]``.
Writes ``benchmarks/results/segmentation.json`` (a part skipped with ``--skip`` keeps the figures
of the last run that measured it).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
# benchmarks/calibration.py would shadow the calibration package: drop this folder from the path
DATA = REPO.parent / "shared" / "data"
RESULTS = REPO / "benchmarks" / "results" / "segmentation.json"

from rigs.atomic import atomic_write_text  # noqa: E402
from studio.segment import (  # noqa: E402
    PERSON,
    SHADOW,
    STUDIO_MORPHOLOGY,
    BackgroundModel,
    ShadowVoter,
    SkinClassifier,
    Thresholds,
    binary_scores,
    tune_thresholds,
    ycrcb_skin,
)
from studio.segment.metrics import label_scores  # noqa: E402
from studio.workspace import Layout  # noqa: E402


def _fmt(x: float) -> str:
    return f"{x:.3f}"


# ---------------------------------------------------------------------- 1. simulated
_STAGES = {"before": "before", "after_labels_only": "vote-lab", "after": "vote", "adaptive_before": "apply",
           "adaptive_after": "apply+v"}


def find_sim_session(search: list[Path]) -> Path | None:
    for root in search:
        if not root.is_dir():
            continue
        for sj in sorted(root.rglob("session.json")):
            if (sj.parent / "truth" / "labels").is_dir():
                return sj.parent
    return None


def bench_simulated(session_path: Path | None, quick: bool) -> dict:
    from rigs.imageio import read_image
    from rigs.session import Session
    from studio.segment.synthetic import write_session

    source = "simulator session"
    tmp = None
    if session_path is None:
        tmp = tempfile.TemporaryDirectory()
        session_path = write_session(Path(tmp.name) / "box", n_cameras=4, size=(328, 245), frames=4 if quick else 8)
        source = "box scene (studio.segment.synthetic) — no simulator session with truth found"
    session = Session.open(session_path)
    from calibration import RigCalibration

    calib = RigCalibration.load(session.calibration_path)
    cams = session.cameras
    models = {c: BackgroundModel.fit(session.backgrounds(c), morphology=STUDIO_MORPHOLOGY) for c in cams}
    voter = ShadowVoter(calib, cams)
    frames = session.frame_indices[: (4 if quick else 20)]
    lay = Layout(session.path)
    before = {c: [] for c in cams}
    labels_only = {c: [] for c in cams}
    after = {c: [] for c in cams}
    truth = {c: [] for c in cams}
    for index in frames:
        images = session.frame(index)
        analysed = {c: models[c].analyse(images[c]) for c in cams}
        labels = {c: a[0] for c, a in analysed.items()}
        plain = voter.vote(labels).labels
        voted = voter.vote(labels, {c: a[1] for c, a in analysed.items()}).labels
        for c in cams:
            before[c].append(labels[c])
            labels_only[c].append(plain[c])
            after[c].append(voted[c])
            truth[c].append(read_image(lay.truth_labels(c, index)))
    # the adaptive model (BackgroundModel.apply: started from the same fit, updated every frame)
    running = {c: models[c].with_settings() for c in cams}
    ad_before, ad_after, ad_truth = [], [], []
    for index in frames:
        images = session.frame(index)
        analysed = {c: running[c].apply_analyse(images[c]) for c in cams}
        voted = voter.vote({c: a[0] for c, a in analysed.items()}, {c: a[1] for c, a in analysed.items()}).labels
        for c in cams:
            ad_before.append(analysed[c][0])
            ad_after.append(voted[c])
            ad_truth.append(read_image(lay.truth_labels(c, index)))
    per_camera = {}
    for c in cams:
        per_camera[c] = {"before": label_scores(before[c], truth[c]), "after": label_scores(after[c], truth[c])}
    overall = {
        "before": label_scores(sum(before.values(), []), sum(truth.values(), [])),
        "after_labels_only": label_scores(sum(labels_only.values(), []), sum(truth.values(), [])),
        "after": label_scores(sum(after.values(), []), sum(truth.values(), [])),
        "adaptive_before": label_scores(ad_before, ad_truth),
        "adaptive_after": label_scores(ad_after, ad_truth),
    }
    print(f"\n== 1. Simulated multi-view session: {source}\n   {session.path}, {len(frames)} frames × {len(cams)} cameras")
    print("   stages: before = single view + morphology; vote-lab = voting on labels only; "
          "vote = voting with photometric consistency (what `studio segment` does); apply / apply+v = the "
          "adaptive model (BackgroundModel.apply) before / after voting")
    print(f"{'camera':<8} {'stage':<8} {'person P':>9} {'R':>6} {'F1':>6}   {'shadow P':>9} {'R':>6} {'F1':>6}")
    for c, rows in list(per_camera.items()) + [("all", overall)]:
        for stage in [k for k in ("before", "after_labels_only", "after", "adaptive_before", "adaptive_after") if k in rows]:
            p, s = rows[stage]["person"], rows[stage]["shadow"]
            print(
                f"{c:<8} {_STAGES[stage]:<8} {_fmt(p['precision']):>9} {_fmt(p['recall']):>6} {_fmt(p['f1']):>6}   "
                f"{_fmt(s['precision']):>9} {_fmt(s['recall']):>6} {_fmt(s['f1']):>6}"
            )
    # fig. 5.3's point: a permissive shadow gate (the outdoor CDnet-like one) mislabels dark
    # clothing as shadow; voting gives it back to the person
    loose = Thresholds(6.0, 8.0, (0.08, 0.9))
    lb, la, lt = [], [], []
    for index in frames:
        images = session.frame(index)
        analysed = {c: models[c].with_settings(loose).analyse(images[c]) for c in cams}
        voted = voter.vote({c: a[0] for c, a in analysed.items()}, {c: a[1] for c, a in analysed.items()}).labels
        for c in cams:
            lb.append(analysed[c][0])
            la.append(voted[c])
            lt.append(read_image(lay.truth_labels(c, index)))
    permissive = {"thresholds": loose.to_dict(), "before": label_scores(lb, lt), "after": label_scores(la, lt)}
    for stage in ("before", "after"):
        p, s_ = permissive[stage]["person"], permissive[stage]["shadow"]
        print(f"{'loose':<8} {stage.replace('after', 'vote'):<8} {_fmt(p['precision']):>9} {_fmt(p['recall']):>6} "
              f"{_fmt(p['f1']):>6}   {_fmt(s_['precision']):>9} {_fmt(s_['recall']):>6} {_fmt(s_['f1']):>6}")  # fmt: skip
    print(f"   (loose = all cameras with the permissive outdoor gate {loose.value_ratio}: dark trousers "
          "become shadow, voting gives them back — the fig. 5.3 effect)")
    # skin, self-trained per camera from the session's own frames (§6.3.4): first half of the
    # frames to train (person masks from our segmentation, no labels), second half to test
    skin_truth_root = lay.truth_dir / "skin"
    skin = None
    if skin_truth_root.is_dir():
        half = len(frames) // 2
        preds, truths_s = [], []
        for c in cams:
            imgs = [session.image(c, i) for i in frames]
            persons = [lab == PERSON for lab in after[c]]
            model = SkinClassifier().self_train(imgs[:half], persons[:half])
            for im, pm, i in zip(imgs[half:], persons[half:], frames[half:]):
                preds.append(model.predict(im, pm))
                truths_s.append(read_image(lay.truth_skin(c, i)) > 0)
        skin = {"self_trained": binary_scores(preds, truths_s),
                "ycrcb_in_person": binary_scores(
                    [ycrcb_skin(session.image(c, i)) & (after[c][k] == PERSON)
                     for c in cams for k, i in enumerate(frames) if k >= half],
                    [read_image(lay.truth_skin(c, i)) > 0
                     for c in cams for k, i in enumerate(frames) if k >= half])}  # fmt: skip
        st, yc = skin["self_trained"], skin["ycrcb_in_person"]
        print(f"   skin (self-trained per camera on {half} frames, tested on {len(frames) - half}): "
              f"P {_fmt(st['precision'])} R {_fmt(st['recall'])} F1 {_fmt(st['f1'])}; "
              f"YCrCb inside the person: F1 {_fmt(yc['f1'])}")  # fmt: skip
    pf, sf = overall["after"]["person"]["f1"], overall["after"]["shadow"]["f1"]
    print(f"   targets after voting: person F1 ≥ 0.97 → {_fmt(pf)} {'MET' if pf >= 0.97 else 'MISSED'}; "
          f"shadow F1 ≥ 0.90 → {_fmt(sf)} {'MET' if sf >= 0.90 else 'MISSED'}")  # fmt: skip
    if tmp is not None:
        tmp.cleanup()
    return {"source": source, "session": str(session_path), "frames": len(frames), "per_camera": per_camera,
            "overall": overall, "thresholds": Thresholds().to_dict(), "permissive_gate": permissive, "skin": skin}  # fmt: skip


# ---------------------------------------------------------------------- 3. skin
def _skin_set(folder: Path):
    names = sorted(p.stem for p in (folder / "skin_val2019").glob("*.jpeg"))
    images, masks = [], []
    for name in names:
        images.append(cv2.cvtColor(cv2.imread(str(folder / "skin_val2019" / f"{name}.jpeg")), cv2.COLOR_BGR2RGB))
        m = cv2.imread(str(folder / "annotations" / f"{name}_skin_{name}.png"), cv2.IMREAD_GRAYSCALE)
        masks.append(m >= 128)
    return images, masks


def bench_skin() -> dict | None:
    root = DATA / "skin" / "sfa_abd_val"
    if not root.is_dir():
        print(f"\n== 3. Skin: data not found at {root}, skipped")
        return None
    sets = {name: _skin_set(root / name / "val") for name in ("coco-sfa", "coco-abdomen")}
    train_im, train_m = [], []
    for images, masks in sets.values():
        train_im += images[0::2]
        train_m += masks[0::2]
    posterior = SkinClassifier().train(train_im, train_m, rule="posterior")
    density = SkinClassifier().train(train_im, train_m, rule="density")
    results = {}
    test_all = {"posterior": [], "density": [], "ycrcb": [], "truth": []}
    for name, (images, masks) in sets.items():
        test_im, test_m = images[1::2], masks[1::2]
        preds = {
            "posterior": [posterior.predict(im) for im in test_im],
            "density": [density.predict(im) for im in test_im],
            "ycrcb": [ycrcb_skin(im) for im in test_im],
        }
        results[name] = {k: binary_scores(v, test_m) for k, v in preds.items()}
        for k, v in preds.items():
            test_all[k] += v
        test_all["truth"] += test_m
    results["both"] = {k: binary_scores(test_all[k], test_all["truth"]) for k in ("posterior", "density", "ycrcb")}
    print(f"\n== 3. Skin (real SFA + abdomen masks): trained on {len(train_im)} even-indexed images, "
          f"tested on the {len(test_all['truth'])} odd-indexed ones")  # fmt: skip
    print(f"{'set':<14} {'method':<28} {'P':>6} {'R':>6} {'F1':>6}")
    labels = {"posterior": "HS histogram, P(skin|H,S)", "density": "HS histogram, eq. 6.10", "ycrcb": "YCrCb fixed box"}
    for name, rows in results.items():
        for k, s in rows.items():
            print(f"{name:<14} {labels[k]:<28} {_fmt(s['precision']):>6} {_fmt(s['recall']):>6} {_fmt(s['f1']):>6}")
    results["train_images"] = len(train_im)
    results["thresholds"] = {"posterior": posterior.threshold, "density": density.threshold}
    return results


# ---------------------------------------------------------------------- 4. speed
_SPEED: dict = {}


def _speed_init(models, calib):
    from studio.blas import limit_blas_threads

    cv2.setNumThreads(1)
    limit_blas_threads()  # as studio segment's workers do
    _SPEED["models"] = models
    _SPEED["voter"] = ShadowVoter(calib)


def _speed_job(frame) -> int:
    analysed = {c: _SPEED["models"][c].analyse(frame[c]) for c in frame}
    labels = {c: a[0] for c, a in analysed.items()}
    return _SPEED["voter"].vote(labels, {c: a[1] for c, a in analysed.items()}).iterations


def bench_speed(quick: bool, workers: int) -> dict:
    from studio.segment.synthetic import SyntheticScene

    scene = SyntheticScene.build(4, (656, 490), torso_color=(82, 74, 52))
    backgrounds = scene.backgrounds(4)
    frame, _, _ = scene.render(seed=5)
    models = {c: BackgroundModel.fit(backgrounds[c], morphology=STUDIO_MORPHOLOGY) for c in backgrounds}
    voter = ShadowVoter(scene.calibration)
    n = 10 if quick else 30

    def one():
        analysed = {c: models[c].analyse(frame[c]) for c in frame}
        return voter.vote({c: a[0] for c, a in analysed.items()}, {c: a[1] for c, a in analysed.items()})

    one()
    t0 = time.perf_counter()
    for _ in range(n):
        one()
    wall = (time.perf_counter() - t0) / n
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    c0 = time.process_time()
    for _ in range(n):
        one()
    cpu = (time.process_time() - c0) / n
    cv2.setNumThreads(threads)
    jobs = [frame] * (2 * n)
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn"), initializer=_speed_init,
                             initargs=(models, scene.calibration)) as pool:  # fmt: skip
        list(pool.map(_speed_job, [frame] * workers))  # warm up every worker
        t0 = time.perf_counter()
        list(pool.map(_speed_job, jobs))
        parallel = len(jobs) / (time.perf_counter() - t0)
    load = os.getloadavg()[0]
    print(f"\n== 4. Speed: 4 × 656×490 multi-frames, classification + morphology + voting "
          f"(load average {load:.1f} on {os.cpu_count()} cores)")  # fmt: skip
    print(f"   single process wall clock : {1 / wall:6.1f} multi-frames/s ({wall * 1e3:.1f} ms each)")
    print(f"   CPU time, one thread      : {cpu * 1e3:6.1f} ms per multi-frame → {1 / cpu:.1f} per core-second")
    print(f"   {workers} worker processes        : {parallel:6.1f} multi-frames/s")
    best = max(1 / wall, parallel)
    print(f"   target ≥ 20 multi-frames/s → {best:.1f} {'MET' if best >= 20 else 'MISSED'} (wall clock, "
          f"best of single/parallel; {1 / cpu:.1f} per core-second of CPU)")  # fmt: skip
    return {"single_process_fps": 1 / wall, "cpu_ms_per_multiframe": cpu * 1e3, "per_core_fps": 1 / cpu,
            "parallel_fps": parallel, "workers": workers, "load_average": load}  # fmt: skip


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--session", type=Path, default=None, help="simulated session with truth/labels")
    ap.add_argument("--search", type=Path, action="append", default=None,
                    help="folders to search for a simulated session (default: studio/samples/)")  # fmt: skip
    ap.add_argument("--quick", action="store_true", help="fewer frames everywhere")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--skip", action="append", default=[], choices=["sim", "cdnet", "skin", "speed", "throughput", "uu"])
    ap.add_argument("--cdnet-unseen", type=Path, default=None, metavar="DIR",
                    help="the full 1700-frame CDnet 2014 highway sequence (input/, groundtruth/, ROI.bmp): also "
                         "score frames 1201-1700, which the shared copy lacks, at the fixed split's picks and "
                         "under an extended split tuned on 470-1200, beside the peers (see segmentation_cdnet.py)")  # fmt: skip
    args = ap.parse_args(argv)
    # parts skipped in this run keep the figures of the last run that measured them
    results = json.loads(RESULTS.read_text()) if args.skip and RESULTS.exists() else {}
    results["date"] = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    if "sim" not in args.skip:
        session = args.session or find_sim_session(args.search or [REPO / "studio" / "samples"])
        results["simulated"] = bench_simulated(session, args.quick)
    if "cdnet" not in args.skip:
        from segmentation_cdnet import bench_cdnet  # this folder is on the path when run as a script

        results["cdnet_highway"] = bench_cdnet(DATA, args.quick, args.cdnet_unseen)
    if "skin" not in args.skip:
        results["skin"] = bench_skin()
    if "speed" not in args.skip:
        results["speed"] = bench_speed(args.quick, args.workers)
    if "uu" not in args.skip:
        from segmentation_uu import bench_uu

        results["uu_capture"] = bench_uu(DATA, RESULTS.parent, args.quick)
        if results["uu_capture"] is not None:
            from segmentation_uu import bench_uu_chair, bench_uu_pipeline

            results["uu_capture"]["chair"] = bench_uu_chair(DATA, RESULTS.parent, args.quick)

            results["uu_capture"]["pipeline"] = bench_uu_pipeline(DATA, args.quick)
    if "throughput" not in args.skip:
        from segmentation_speed import bench_throughput

        results["throughput"] = bench_throughput(DATA, args.quick)
    atomic_write_text(RESULTS, json.dumps(results, indent=2, default=float) + "\n", mkdir=True)
    print(f"\nwrote {RESULTS}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
