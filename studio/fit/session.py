"""Fitting a capture session: frames in parallel processes, shape shared (thesis §4.7, §4.8.6).

Plan of :func:`fit_session`:

1. The **key frame** (the first requested frame) is fitted from the silhouettes alone with the
   shape free (and the gender chosen by fitting both models when ``gender="auto"``, §4.7.2).
2. Its shape **starts** every other frame's fit (one person per session); each frame refines
   it, and the session's shape is the mean of the per-frame estimates (their spread is the
   measurement spread of §4.8.6). The remaining frames are cut into ``workers`` contiguous chunks fitted in parallel processes. The first
   frame of a chunk is initialised from its silhouettes like the key frame (a broad
   particle-filter search, with the key frame's pose as one more start); each next frame of
   the chunk starts from the previous frame's pose with a smaller spread (tracking) when at
   most ``MAX_TRACK_GAP`` frames apart — otherwise a broad search with the previous pose as a
   hint — and is searched again from the silhouettes when tracking ends with a cost above
   ``RECOVERY_FACTOR`` × the key frame's cost.
3. Each frame writes ``fit/NNNNNN.ply`` and ``fit/overlay/<cam>/NNNNNN.png``, then
   ``fit/NNNNNN.json`` (shape, pose, per-term costs, joints, timings, settings) last: a frame
   whose JSON exists is complete. The session summary is ``fit/sequence.json``.
4. A rerun keeps the frames already fitted with the same settings (gender, seed, options, key
   frame), so a fit killed half-way continues where it stopped; ``force`` fits them again.
   Worker processes die with the command (:mod:`studio.workers`).
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable

import numpy as np

from studio.fit.errors import FitError, UnusableFrame
from studio.fit.frame import FitOptions, FrameFit, fit_frame, fit_frame_gender
from studio.fit.output import write_frame_fit, write_unfitted
from studio.fit.quality import screen_masks, summary_line
from studio.workers import worker_pool

__all__ = ["fit_session", "load_fits", "load_quality", "open_workspace"]

log = logging.getLogger(__name__)

#: Frames further apart than this are not tracked (broad search, previous pose as a hint).
MAX_TRACK_GAP = 2
#: A tracked frame costing more than this × the key frame's cost is searched again.
RECOVERY_FACTOR = 3.0


def open_workspace(source, out=None):
    """A :class:`studio.workspace.Workspace` for fitting: calibrated and segmented, or a FitError."""
    from studio.workspace import Workspace, WorkspaceError

    try:
        ws = source if isinstance(source, Workspace) else Workspace.open(source, out=out)
        ws.require_calibration("fitting")
        if not ws.layout.segmentation_dir.is_dir():
            raise WorkspaceError(f"{ws.path}: no segmentation/ folder — run `studio segment {ws.path}` first")
    except WorkspaceError as exc:
        raise FitError(str(exc)) from None
    return ws


def _masks(ws, frame: int) -> list[np.ndarray]:
    from studio.workspace import WorkspaceError

    try:
        return ws.person_masks(frame)
    except WorkspaceError as exc:
        raise FitError(str(exc)) from None


def _images(ws, frame: int):
    try:
        return ws.images(frame)
    except Exception as exc:  # noqa: BLE001 - overlays fall back to a grey background
        log.warning("frame %d: no camera images for the overlays (%s)", frame, exc)
        return None


def _fit_chunk(job: dict) -> list[dict]:
    """Worker: fit consecutive frames (the first from a broad search), write results."""
    from studio.body import BodyModel

    ws = open_workspace(job["path"], job["out"])
    cameras = ws.cameras
    model = BodyModel.load(job["gender"])
    options = FitOptions(**{k: tuple(v) if isinstance(v, list) else v for k, v in job["options"].items()})
    shape = np.asarray(job["shape"], float)
    prev, prev_frame = None, None
    out = []
    for frame in job["frames"]:
        masks = _masks(ws, frame)
        screen = screen_masks(cameras, masks)  # once for both fits below
        track = prev is not None and abs(frame - prev_frame) <= MAX_TRACK_GAP
        hint = prev if prev is not None else job.get("hint_pose")
        try:
            fit = fit_frame(model, cameras, masks, frame=frame, shape=shape,
                            previous_pose=prev if track else None, hint_pose=None if track else hint,
                            options=options, seed=job["seed"] + frame, screen=screen)
        except UnusableFrame as err:
            log.warning("%s", err)
            out.append(write_unfitted(ws.layout, err, run=job["run"]))
            continue
        if track and fit.costs["total"] > RECOVERY_FACTOR * job["key_cost"]:
            # tracking lost the body: search again from the silhouettes, keep the better fit
            log.info("frame %d: tracking cost %.2f, re-initialising from the silhouettes", frame, fit.costs["total"])
            again = fit_frame(model, cameras, masks, frame=frame, shape=shape, hint_pose=prev,
                              options=options, seed=job["seed"] + frame + 1, screen=screen)
            if again.costs["total"] < fit.costs["total"]:
                fit = again
        write_frame_fit(ws.layout, fit, model, cameras, masks, _images(ws, frame), run=job["run"])
        prev, prev_frame = fit.pose, frame
        out.append(fit.to_json())
    return out


def _done(ws, frames: list[int], run: dict) -> dict[int, dict]:
    """Fits of ``frames`` already on disk from a run with the same settings (``run``)."""
    done = {}
    for f in frames:
        p = ws.layout.fit_json(f)
        try:
            obj = json.loads(p.read_text())
        except (OSError, ValueError):
            continue
        if obj.get("run") == run:
            done[f] = obj
    return done


def fit_session(
    source,
    *,
    frames: list[int] | None = None,
    gender: str = "auto",
    workers: int = 1,
    options: FitOptions = FitOptions(),
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    force: bool = False,
    out=None,
) -> dict:
    """Fit ``frames`` (default all) of a session (a :class:`~studio.workspace.Workspace` or a
    folder; outputs to ``out``, default the session); returns the summary dict (also written
    to ``fit/sequence.json``). Frames fitted before with the same settings are kept unless
    ``force``."""
    from rigs.atomic import atomic_write_json
    from studio.body import GENDERS, BodyModel
    from studio.workspace import WorkspaceError

    if gender != "auto" and gender not in GENDERS:
        raise FitError(f"gender: expected 'auto' or one of {', '.join(GENDERS)}, got {gender!r}")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise FitError(f"workers: expected an integer >= 1, got {workers!r}")
    ws = open_workspace(source, out)
    frames = ws.frame_indices if frames is None else list(dict.fromkeys(int(f) for f in frames))
    if not frames:
        raise FitError(f"{ws.path}: no frames to fit")
    try:
        ws.check_frames(frames)
        ws.check_segmented(frames)
        ws.check_writable(ws.layout.fit_dir)
    except WorkspaceError as exc:
        raise FitError(str(exc)) from None
    cameras = ws.cameras
    t0 = time.perf_counter()
    total = len(frames)
    key = frames[0]
    run = {"gender": gender, "seed": int(seed), "key_frame": key, "options": options.to_dict()}
    done = {} if force else _done(ws, frames, run)
    if done:
        log.info("%d of %d frame(s) already fitted with the same settings: kept (--force fits them again)",
                 len(done), total)
    results = {f: done[f] for f in done}
    # 1. key frame: shape free, gender chosen — the first frame the quality gates let through
    key_fit = None
    for key in frames:
        if key in done:
            if done[key].get("fitted", True):
                key_fit = FrameFit.from_json(done[key])
                break
            continue
        masks = _masks(ws, key)
        try:
            key_fit = fit_frame_gender(cameras, masks, gender, frame=key, options=options, seed=seed + key)
        except UnusableFrame as err:
            log.warning("%s", err)
            results[key] = write_unfitted(ws.layout, err, run=run)
            if progress:
                progress(len(results), total)
            continue
        model = BodyModel.load(key_fit.gender)
        write_frame_fit(ws.layout, key_fit, model, cameras, masks, _images(ws, key), run=run)
        break
    if key_fit is None:
        raise FitError(f"{ws.path}: no frame passed the segmentation checks ({summary_line(_qualities(results))}); "
                       f"results in {ws.layout.fit_dir}")
    results[key] = key_fit.to_json() | {"run": run}
    if progress:
        progress(len(results), total)
    # 2. other frames, shape held, in contiguous chunks
    rest = [f for f in frames if f not in results]
    n_chunks = max(1, min(workers, len(rest)))
    chunks = [list(c) for c in np.array_split(np.asarray(rest, dtype=int), n_chunks) if len(c)]
    jobs = [{"path": str(ws.path), "out": str(ws.layout.root), "gender": key_fit.gender,
             "shape": key_fit.shape.tolist(), "frames": [int(f) for f in c], "options": options.to_dict(),
             "seed": int(seed), "hint_pose": key_fit.pose.tolist(), "key_cost": float(key_fit.costs["total"]),
             "run": run} for c in chunks]
    if jobs:
        if workers <= 1 or len(jobs) == 1:
            for job in jobs:
                for r in _fit_chunk(job):
                    results[r["frame"]] = r
                    if progress:
                        progress(len(results), total)
        else:
            with worker_pool(len(jobs)) as pool:
                futures = [pool.submit(_fit_chunk, job) for job in jobs]
                for fut in futures:
                    for r in fut.result():
                        results[r["frame"]] = r
                        if progress:
                            progress(len(results), total)
    summary = {
        "format": "studio.fit-sequence",
        "version": 1,
        "gender": key_fit.gender,
        "gender_costs": key_fit.costs.get("gender_costs"),
        "key_shape": key_fit.shape.tolist(),
        "shape": np.mean([results[f]["shape"] for f in results if "shape" in results[f]], axis=0).tolist(),
        "key_frame": key,
        "frames": sorted(results),
        "kept": sorted(done),
        "costs": {str(f): results[f]["costs"]["total"] for f in sorted(results) if "costs" in results[f]},
        "quality": {str(f): (results[f].get("quality") or {}).get("status", "unchecked") for f in sorted(results)},
        "quality_summary": summary_line(_qualities(results)),
        "workers": workers,
        "wall_time": round(time.perf_counter() - t0, 3),
        "settings": options.to_dict(),
        "run": run,
        "shape_strategy": "key frame fitted first; every other frame refines the key shape; session shape = mean over frames",
    }
    atomic_write_json(ws.layout.fit_sequence, summary)
    return summary


def _qualities(results: dict) -> dict:
    return {f: r.get("quality") or {"status": "unchecked", "reasons": []} for f, r in results.items()}


def load_quality(source, frames: list[int] | None = None) -> dict[int, dict]:
    """The ``quality`` objects of a session's ``fit/NNNNNN.json`` by frame, frames the gates
    refused to fit included (their status ``failed``); ``frames`` as for :func:`load_fits`.
    Results written before the gates have status ``unchecked``."""
    lay = _layout(source)
    if frames is None and lay.fit_sequence.is_file():
        frames = json.loads(lay.fit_sequence.read_text()).get("frames")
    out = {}
    for p in sorted(lay.fit_dir.glob("[0-9]*.json")) if lay.fit_dir.is_dir() else []:
        if frames is None or int(p.stem) in frames:
            out[int(p.stem)] = json.loads(p.read_text()).get("quality") or {"status": "unchecked", "reasons": []}
    return out


def _layout(source):
    from studio.workspace import Layout, Workspace

    return source.layout if isinstance(source, Workspace) else source if isinstance(source, Layout) else Layout(source)


def load_fits(source, frames: list[int] | None = None) -> dict[int, FrameFit]:
    """The ``fit/NNNNNN.json`` results of a session (a Workspace, a Layout or a folder), by frame:
    ``frames``, or those of the last :func:`fit_session` run (``fit/sequence.json``), or else
    every result in the folder."""
    lay = _layout(source)
    root = lay.fit_dir
    if not root.is_dir():
        raise FitError(f"{lay.root}: no fit/ folder — run `studio fit {lay.source}` first")
    if frames is None and lay.fit_sequence.is_file():
        frames = json.loads(lay.fit_sequence.read_text()).get("frames")
    out = {}
    for p in sorted(root.glob("[0-9]*.json")):
        if frames is None or int(p.stem) in frames:
            obj = json.loads(p.read_text())
            if obj.get("fitted", True):  # frames the quality gates refused carry no body
                out[int(p.stem)] = FrameFit.from_json(obj)
    if not out:
        raise FitError(f"{root}: no fitted frames — run `studio fit {lay.source}` first")
    return out
