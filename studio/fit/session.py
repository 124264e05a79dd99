"""Fitting a capture session: frames as units of work, chains of tracked frames side by side
(thesis §4.7, §4.8.6).

Plan of :func:`fit_session`:

1. The requested frames are cut into contiguous **chains** of at most ``chain_length`` frames
   (near-equal lengths), and wherever two frames are too far apart to track
   (:func:`plan_chains`). A chain's first frame is fitted from its silhouettes alone with the
   shape free; each next frame of the chain starts from the previous frame's pose and the
   chain's shape with a smaller spread (tracking), as the unit of :mod:`studio.fit.units`
   describes. The **key frame** is the first fitted frame of the first chain; with
   ``gender="auto"`` it is fitted with both models first (§4.7.2) and every chain then uses
   the chosen one.
2. The units run on a runner of :mod:`studio.execution`: in this process (``workers=1``), in
   ``workers`` local processes, or on a Dask cluster (``scheduler="tcp://HOST:PORT"`` or
   ``"local:N"``). The plan depends only on the frames and ``chain_length``, never on who runs
   it or how many workers there are, so the same seed gives the same results everywhere. Chains
   trade work for parallelism: a chain's first frame costs a broad search (~2× a tracked frame),
   one chain of 24 frames has one, four chains of 6 have four but run on four workers at once.
3. Each frame writes ``fit/NNNNNN.ply`` and ``fit/overlay/<cam>/NNNNNN.png``, then
   ``fit/NNNNNN.json`` (shape, pose, per-term costs, joints, timings, settings) last: a frame
   whose JSON exists is complete. The session's shape is the mean of the per-frame estimates
   (their spread is the measurement spread of §4.8.6); the summary is ``fit/sequence.json``.
4. A rerun keeps the frames already fitted with the same settings (gender, seed, options, key
   frame) and continues each chain from its last stored pose, so a fit killed half-way ends as
   if it had never stopped; ``force`` fits them again. Local worker processes die with the
   command (:mod:`studio.workers`); on Dask a lost worker's unit is run again elsewhere.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable

import numpy as np

from studio.fit.errors import FitError
from studio.fit.frame import FitOptions
from studio.fit.result import FrameFit
from studio.fit.quality import summary_line
from studio.fit.units import MAX_TRACK_GAP, fit_unit, frame_fit_code_digest, segmentation_identity, stored_fit

__all__ = ["CHAIN_LENGTH", "fit_session", "load_fits", "load_quality", "open_workspace", "plan_chains"]

log = logging.getLogger(__name__)


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


#: Default longest chain of tracked frames (:func:`plan_chains`).
CHAIN_LENGTH = 6


def plan_chains(frames: list[int], chain_length: int = CHAIN_LENGTH) -> list[list[int]]:
    """``frames`` (in the order given) cut into chains: first wherever the next frame is more
    than ``MAX_TRACK_GAP`` away (it could not be tracked anyway), then each run into the fewest
    chains of at most ``chain_length`` frames, of near-equal lengths.

    >>> plan_chains(list(range(8)), 6)
    [[0, 1, 2, 3], [4, 5, 6, 7]]
    >>> plan_chains([0, 6, 12, 13, 14, 15], 3)
    [[0], [6], [12, 13], [14, 15]]
    """
    runs, run = [], []
    for f in frames:
        if run and abs(int(f) - run[-1]) > MAX_TRACK_GAP:
            runs.append(run)
            run = []
        run.append(int(f))
    runs.append(run)
    out = []
    for run in runs:
        n = -(-len(run) // int(chain_length))
        out += [[int(f) for f in c] for c in np.array_split(np.asarray(run, dtype=int), n) if len(c)]
    return out


def _key_first(runner, spec: dict, chains: list[list[int]], starts: list, progress, total: int) -> tuple[list, dict]:
    """``gender="auto"``: run the chains' frames in order, one at a time, until one is fitted (both
    models, the lower cost wins); returns the states of the frames done and the spec for the rest."""
    states = []
    for i, chain in enumerate(chains):
        while chain:
            state = runner.submit(fit_unit, spec, chain.pop(0), starts[i]).result()
            states.append(state)
            starts[i] = state
            if progress:
                progress(len(states), total)
            if state.get("pose") is not None:
                return states, spec | {"gender": state["gender"]}
    return states, spec


def fit_session(
    source,
    *,
    frames: list[int] | None = None,
    gender: str = "auto",
    workers: int = 1,
    scheduler: str | None = None,
    chain_length: int = CHAIN_LENGTH,
    options: FitOptions = FitOptions(),
    seed: int = 0,
    progress: Callable[[int, int], None] | None = None,
    force: bool = False,
    out=None,
    shadows: float | None = None,
) -> dict:
    """Fit ``frames`` (default all) of a session (a :class:`~studio.workspace.Workspace` or a
    folder; outputs to ``out``, default the session); returns the summary dict (also written
    to ``fit/sequence.json``). Frames fitted before with the same settings are kept unless
    ``force``. ``workers`` local processes, or the Dask cluster ``scheduler`` (see
    :func:`studio.execution.open_runner`); ``chain_length`` the longest chain of tracked frames
    (:func:`plan_chains`; part of the settings a rerun compares). ``shadows`` (a weight) adds the
    shadow term of eq. 5.7 with the light of ``light/light.json`` (:func:`studio.light.load_light`)."""
    from rigs.atomic import atomic_write_json
    from studio.body import GENDERS
    from studio.execution import ExecutionError, open_runner, run_chains
    from studio.workspace import WorkspaceError

    if gender != "auto" and gender not in GENDERS:
        raise FitError(f"gender: expected 'auto' or one of {', '.join(GENDERS)}, got {gender!r}")
    for name, value in (("workers", workers), ("chain_length", chain_length)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise FitError(f"{name}: expected an integer >= 1, got {value!r}")
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
    t0 = time.perf_counter()
    total = len(frames)
    run = {"gender": gender, "seed": int(seed), "key_frame": frames[0], "options": options.to_dict(),
           "code": frame_fit_code_digest(), "segmentation": segmentation_identity(ws.layout)}
    plan = plan_chains(frames, chain_length)
    if len(plan) > 1:  # recorded only when it splits: results of one chain keep their old settings
        run["chains"] = plan
    if shadows is not None:
        from studio.light import LightError, load_light

        try:
            _, light = load_light(ws.layout.light_json)
        except LightError as exc:
            raise FitError(str(exc)) from None
        run["shadows"] = {"weight": float(shadows), "lights": light["lights"]}
    kept = [] if force else [f for f in frames if stored_fit(ws.layout, f, run) is not None]
    if force:  # a frame's JSON marks it complete: gone, so that every unit fits again
        for f in frames:
            ws.layout.fit_json(f).unlink(missing_ok=True)
    if kept:
        log.info("%d of %d frame(s) already fitted with the same settings: kept (--force fits them again)",
                 len(kept), total)
    spec = {"path": str(ws.path), "out": str(ws.layout.root), "gender": gender, "options": options.to_dict(),
            "seed": int(seed), "run": run}
    if shadows is not None:
        spec["shadows"] = {"weight": float(shadows)}
    try:
        with open_runner(min(workers, len(plan)), scheduler) as runner:
            todo = [list(c) for c in plan]
            starts = [None] * len(todo)
            states = []
            if gender == "auto":
                states, spec = _key_first(runner, spec, todo, starts, progress, total)
            for chain in run_chains(runner, fit_unit, todo, spec=spec, starts=starts, progress=progress,
                                    done=len(states), total=total):
                states.extend(chain)
            where = runner.where
    except ExecutionError as exc:
        raise FitError(str(exc)) from None
    results = {s["frame"]: s["record"] for s in states}
    fitted = [f for f in frames if results[f].get("fitted", True)]
    if not fitted:
        raise FitError(f"{ws.path}: no frame passed the segmentation checks ({summary_line(_qualities(results))}); "
                       f"results in {ws.layout.fit_dir}")
    key = fitted[0]
    key_fit = FrameFit.from_json(results[key])
    starts_fitted = [next((f for f in c if results[f].get("fitted", True)), None) for c in plan]
    summary = {
        "format": "studio.fit-sequence",
        "version": 1,
        "gender": key_fit.gender,
        "gender_costs": key_fit.costs.get("gender_costs"),
        "key_shape": key_fit.shape.tolist(),
        "shape": np.mean([results[f]["shape"] for f in fitted], axis=0).tolist(),
        "key_frame": key,
        "frames": sorted(results),
        "kept": sorted(kept),
        "chains": plan,
        "chain_starts": [f for f in starts_fitted if f is not None],
        "costs": {str(f): results[f]["costs"]["total"] for f in sorted(fitted)},
        "quality": {str(f): (results[f].get("quality") or {}).get("status", "unchecked") for f in sorted(results)},
        "quality_summary": summary_line(_qualities(results)),
        "workers": workers if scheduler is None else None,
        "executor": where,
        "wall_time": round(time.perf_counter() - t0, 3),
        "settings": options.to_dict(),
        "run": run,
        "shape_strategy": "each chain's first frame fitted from the silhouettes with the shape free, the next "
                          "frames of the chain tracked from it; session shape = mean over fitted frames",
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
    out, refused = {}, {}
    for p in sorted(root.glob("[0-9]*.json")):
        if frames is None or int(p.stem) in frames:
            obj = json.loads(p.read_text())
            if obj.get("fitted", True):  # frames the quality gates refused carry no body
                out[int(p.stem)] = FrameFit.from_json(obj)
            elif obj.get("quality"):
                refused[int(p.stem)] = obj["quality"]
    if not out and refused:
        raise FitError(f"{root}: no body to report — the quality gates refused every frame "
                       f"({summary_line(refused)}); see fit/NNNNNN.json for every reason")
    if not out:
        raise FitError(f"{root}: no fitted frames — run `studio fit {lay.source}` first")
    return out
