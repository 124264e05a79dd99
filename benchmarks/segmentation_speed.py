"""Throughput part of ``benchmarks/segmentation.py``: 4 views, the toolkit beside OpenCV GSOC and
MOG2 on the same frames, in one run.

Frames: the real UU capture's four ``video.avi`` (644×486, ``../shared/data``) when present,
else the 656×490 synthetic scene. Each method keeps one model per camera and runs its cameras
sequentially (one OpenCV thread):

* single process: all four cameras in one process → ms per multi-frame, multi-frames/s;
* 2 processes (the 2-core target): two cameras per process, started together; multi-frames/s =
  multi-frames / the slower process's wall time.

Toolkit rows: ``apply`` (adaptive model + morphology), ``classify`` (fixed eq. 5.5 model +
morphology), and multi-view shadow voting (§5.5.2) timed on its own (it needs all four views in
one place: a fifth stage after the per-camera ones; timed on the synthetic rig at the same image
size, since the UU capture's calibration is made by the tests, not shipped), compiled beside the
``cv2.remap`` reference (``ShadowVoter.vote(method="remap")``, the same labels). The last row,
``apply + voting``, is the 2-core pipeline in wall clock: each process runs ``apply`` on its two
cameras and votes every other multi-frame (the hand-over of the labels between the processes is
not timed).
"""

from __future__ import annotations

import os
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import cv2
import numpy as np

METHODS = ("toolkit apply (adaptive)", "toolkit classify (fixed)", "OpenCV GSOC", "OpenCV MOG2")


def uu_frames(data: Path, n: int, start: int = 100) -> dict[str, list[np.ndarray]] | None:
    root = data / "multiview" / "uu_infomcv_4cam_person"
    if not root.is_dir():
        return None
    out = {}
    for cam in ("cam1", "cam2", "cam3", "cam4"):
        cap = cv2.VideoCapture(str(root / cam / "video.avi"))
        cap.set(cv2.CAP_PROP_POS_FRAMES, start)
        frames = []
        while len(frames) < n:
            ok, f = cap.read()
            if not ok:
                break
            frames.append(cv2.cvtColor(f, cv2.COLOR_BGR2RGB))
        cap.release()
        if not frames:
            return None
        out[cam] = frames
    return out


def _make(method: str, background: list[np.ndarray]):
    from studio.segment import BackgroundModel

    if method.startswith("toolkit"):
        model = BackgroundModel.fit(background[:: max(1, len(background) // 8)])
        return model.apply if "apply" in method else model.classify
    sub = cv2.bgsegm.createBackgroundSubtractorGSOC() if "GSOC" in method else cv2.createBackgroundSubtractorMOG2()
    for b in background:
        sub.apply(b)
    return sub.apply


def voting_inputs(size: tuple[int, int], n: int = 5):
    """A :class:`ShadowVoter` of the synthetic 4-camera rig at ``size`` and ``n`` analysed multi-frames
    ``[(labels, ratios), ...]`` (the fixed model + morphology, as ``studio segment`` votes them)."""
    from studio.segment import STUDIO_MORPHOLOGY, BackgroundModel, ShadowVoter
    from studio.segment.synthetic import SyntheticScene

    scene = SyntheticScene.build(4, size, torso_color=(82, 74, 52))
    models = {c: BackgroundModel.fit(b, morphology=STUDIO_MORPHOLOGY) for c, b in scene.backgrounds(8).items()}
    inputs = []
    for s in range(n):
        analysed = {c: models[c].analyse(img) for c, img in scene.render(seed=s)[0].items()}
        inputs.append(({c: a[0] for c, a in analysed.items()}, {c: a[1] for c, a in analysed.items()}))
    return ShadowVoter(scene.calibration), inputs


def _worker(method: str, frames: dict, backgrounds: dict, repeats: int, vote_turn: int | None = None,
            barrier=None) -> tuple[float, float]:  # fmt: skip
    """(wall, CPU) seconds to run ``method`` over every frame of its cameras ``repeats`` times (after
    warm-up); with ``vote_turn`` (0 or 1) it also votes every other multi-frame, starting at that one.
    ``barrier``: waited on before the clock starts (processes started together time the same span)."""
    cv2.setNumThreads(1)
    inputs = {c: f if method.startswith("toolkit") else [cv2.cvtColor(x, cv2.COLOR_RGB2BGR) for x in f]
              for c, f in frames.items()}  # fmt: skip
    runners = {c: _make(method, backgrounds[c]) for c in frames}
    for c in frames:
        runners[c](inputs[c][0])  # warm-up (numba compile / load)
    voter, votes = None, []
    if vote_turn is not None:
        voter, votes = voting_inputs(next(iter(frames.values()))[0].shape[1::-1])
        voter.vote(*votes[0])
    if barrier is not None:
        barrier.wait()
    n = len(next(iter(frames.values())))
    t0, c0 = time.perf_counter(), time.process_time()
    for _ in range(repeats):
        for i in range(n):
            for c in frames:
                runners[c](inputs[c][i])
            if voter is not None and i % 2 == vote_turn:
                voter.vote(*votes[i % len(votes)])
    return time.perf_counter() - t0, time.process_time() - c0


def _two_processes(method: str, frames: dict, backgrounds: dict, repeats: int, voting: bool = False) -> float:
    """Wall seconds of the slower of 2 processes, two cameras each, started together."""
    cams = list(frames)
    halves = [cams[: len(cams) // 2], cams[len(cams) // 2 :]]
    ctx = get_context("spawn")
    with ctx.Manager() as manager, ProcessPoolExecutor(2, mp_context=ctx) as pool:
        barrier = manager.Barrier(2)
        futures = [pool.submit(_worker, method, {c: frames[c] for c in h}, {c: backgrounds[c] for c in h}, repeats,
                               turn if voting else None, barrier) for turn, h in enumerate(halves)]  # fmt: skip
        return max(f.result()[0] for f in futures)


def time_voting(voter, inputs, method: str, repeats: int = 3) -> float:
    """CPU ms per multi-frame of ``voter.vote(..., method=method)`` over ``inputs``, one OpenCV thread."""
    threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    voter.vote(*inputs[0], method=method)
    c0 = time.process_time()
    for _ in range(repeats):
        for labels, ratios in inputs:
            voter.vote(labels, ratios, method=method)
    cv2.setNumThreads(threads)
    return 1e3 * (time.process_time() - c0) / (repeats * len(inputs))


def bench_throughput(data: Path, quick: bool) -> dict:
    from studio.segment.synthetic import SyntheticScene

    n = 20 if quick else 60
    frames = uu_frames(data, n)
    if frames is not None:
        source = "UU capture, 4 × 644×486 (real)"
        backgrounds = {}
        for cam in frames:
            cap = cv2.VideoCapture(str(data / "multiview" / "uu_infomcv_4cam_person" / cam / "background.avi"))
            bg = []
            while len(bg) < 24:
                ok, f = cap.read()
                if not ok:
                    break
                bg.append(cv2.cvtColor(f, cv2.COLOR_BGR2RGB))
            cap.release()
            backgrounds[cam] = bg
    else:
        source = "synthetic scene, 4 × 656×490 (UU capture not found)"
        scene = SyntheticScene.build(4, (656, 490), torso_color=(82, 74, 52))
        bgs = scene.backgrounds(8)
        frames = {c: [scene.render(seed=s)[0][c] for s in range(n)] for c in bgs}
        backgrounds = bgs
    cams = list(frames)
    repeats = 1 if quick else 2
    multi = n * repeats
    rows = {}
    ctx = get_context("spawn")
    for method in METHODS:
        with ProcessPoolExecutor(1, mp_context=ctx) as pool:
            single, cpu = pool.submit(_worker, method, frames, backgrounds, repeats).result()
        both = _two_processes(method, frames, backgrounds, repeats)
        rows[method] = {"ms_per_multiframe": 1e3 * single / multi, "cpu_ms_per_multiframe": 1e3 * cpu / multi,
                        "single_process_fps": multi / single, "two_process_fps": multi / both,
                        "two_core_capacity_fps": 2 * multi / cpu}  # fmt: skip
    pipeline_fps = multi / _two_processes(METHODS[0], frames, backgrounds, repeats, voting=True)
    # voting: all four views in one place, on the synthetic rig at the same image size (its own calibration);
    # the compiled path and the cv2.remap reference alternate, so both see the same load
    voter, inputs = voting_inputs(frames[cams[0]][0].shape[1::-1])
    timings = {"compiled": [], "remap": []}
    for _ in range(2 if quick else 4):
        for method, ms in timings.items():
            ms.append(time_voting(voter, inputs, method))
    vote_ms, vote_ref_ms = (float(np.median(timings[m])) for m in ("compiled", "remap"))
    load = os.getloadavg()[0]
    print(f"\n== 5. Throughput: {source}, {n} multi-frames × {repeats}; load average {load:.1f} on {os.cpu_count()} cores "
          "(shared machine: compare rows, not absolute values)")  # fmt: skip
    print("   wall = measured on this (loaded) machine; CPU = process time, capacity = 2 cores / CPU per multi-frame")
    print(f"{'method (per-camera stage)':<28} {'wall ms':>8} {'CPU ms':>7} {'1 proc/s':>9} {'2 proc/s':>9} {'2-core cap./s':>14}")
    for method, r in rows.items():
        print(f"{method:<28} {r['ms_per_multiframe']:8.1f} {r['cpu_ms_per_multiframe']:7.1f} {r['single_process_fps']:9.1f} "
              f"{r['two_process_fps']:9.1f} {r['two_core_capacity_fps']:14.1f}")  # fmt: skip
    adaptive = rows[METHODS[0]]
    combined = 2e3 / (adaptive["cpu_ms_per_multiframe"] + vote_ms)
    print(f"{'toolkit apply + voting':<28} {'':>8} {adaptive['cpu_ms_per_multiframe'] + vote_ms:7.1f} {'':>9} "
          f"{pipeline_fps:9.1f} {combined:14.1f}")  # fmt: skip
    print(f"   multi-view voting (4 views, one thread): {vote_ms:.1f} ms CPU per multi-frame "
          f"(cv2.remap reference, same labels: {vote_ref_ms:.1f} ms; median of {len(timings['compiled'])} alternating runs)")
    met = pipeline_fps >= 60
    print(f"   target ≥ 60 multi-frames/s on 2 cores with voting: measured wall clock {pipeline_fps:.1f} "
          f"{'MET' if met else 'MISSED'}; CPU capacity {combined:.1f} {'MET' if combined >= 60 else 'MISSED'} "
          f"({adaptive['two_core_capacity_fps']:.1f} without voting)")  # fmt: skip
    return {"source": source, "multi_frames": multi, "methods": rows, "voting_ms": vote_ms,
            "voting_reference_ms": vote_ref_ms, "apply_plus_voting_two_process_fps": pipeline_fps,
            "apply_plus_voting_capacity_fps": combined, "load_average": load, "target_met": met}  # fmt: skip
