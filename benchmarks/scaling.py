"""Fitting throughput with 1 and 2 local worker processes and a 2-worker Dask cluster (issue 20).

The same consecutive frames of the simulated walk (default: 12, female model, chains of 6) are
fitted three times through ``studio.fit.fit_session``: in this process, by 2 local processes and
by a ``LocalCluster`` of 2 processes — the same plan of chains each time, so the same results,
which the script checks. It prints frames/hour, the speed-up over one worker (target ≥ 1.8× with
2 workers; the anchor is ideal scaling, 2×) and an estimate of a 100-participant study's wall
time on N workers from the measured per-frame costs: a session's F frames are cut into
``ceil(F / L)`` chains of about L frames, a chain's first frame fitted from the silhouettes
(``t_start``), the others tracked (``t_track``); the chains run in ``ceil(chains / N)`` waves
on N workers, plus the session's segmentation and report (sessions one after another).
It also prints the CPU seconds a frame costs in each runner (``timings["cpu"]`` of the fit
results): the same work must cost the same wherever it runs, and unlike wall times that figure
holds on a busy machine (a Dask worker's frames cost 1.5× more before :mod:`studio.allocator`).

Usage: ``.venv/bin/python benchmarks/scaling.py [--frames 12] [--chain-length 6] [--quick]
[--per-participant 24]`` (needs ``pip install .[dask]``).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

TARGET = 1.8


def _fit(session: Path, out: Path, frames, options, chain_length, **where) -> tuple[float, dict, dict]:
    from studio.fit import fit_session

    shutil.copytree(session / "segmentation", out / "segmentation")
    t = time.perf_counter()
    summary = fit_session(session, frames=frames, gender="female", options=options, out=out, force=True,
                          chain_length=chain_length, **where)
    wall = time.perf_counter() - t
    results = {f: json.loads((out / "fit" / f"{f:06d}.json").read_text()) for f in frames}
    return wall, summary, results


def _estimate(t_start: float, t_track: float, t_segment: float, frames: int, chain_length: int,
              participants: int = 100, t_report: float = 5.0) -> list[dict]:
    """Wall time per session and for the study on N workers (see the module docstring)."""
    chains = math.ceil(frames / chain_length)
    per_chain = t_start + (math.ceil(frames / chains) - 1) * t_track
    rows = []
    for n in (1, 2, 4, 8, 16, 32):
        session = math.ceil(chains / n) * per_chain + frames * t_segment / min(n, frames) + t_report
        rows.append({"workers": n, "session_s": round(session, 1), "study_h": round(participants * session / 3600, 2)})
    return rows


def main(argv=None) -> int:
    from rigs.atomic import atomic_write_json
    from studio.cli.commands.fit import QUICK
    from studio.fit import FitOptions
    from studio.fit.session import CHAIN_LENGTH
    from studio.segment import segment_session
    from studio.simulate import ensure_rendered
    from studio.threads import set_threads
    from studio.workspace import Workspace

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spec", type=Path, default=ROOT / "studio" / "samples" / "walk" / "spec.yaml")
    ap.add_argument("--frames", type=int, default=12, help="consecutive frames fitted by each runner")
    ap.add_argument("--chain-length", type=int, default=CHAIN_LENGTH, help="longest chain of tracked frames")
    ap.add_argument("--per-participant", type=int, default=24, help="frames per participant in the study estimate")
    ap.add_argument("--quick", action="store_true", help="the fit's --quick settings")
    args = ap.parse_args(argv)
    # one worker is one core: the fitting process keeps its batches on one thread, as every worker
    # process does (a frame's batches on both cores are benchmarks/fit_speed.py's)
    set_threads(1)
    options = FitOptions(**QUICK) if args.quick else FitOptions()
    session = ensure_rendered(args.spec, seed=0)
    frames = list(range(min(args.frames, 24)))
    ws = Workspace.open(session)
    t = time.perf_counter()
    segment_session(ws, frames=frames, workers=2, force=True)
    t_segment = (time.perf_counter() - t) / len(frames)
    res = {"benchmark": "scaling", "frames": frames, "options": options.to_dict(), "runs": {}}
    outputs = {}
    tmp = Path(tempfile.mkdtemp(prefix="scaling-"))
    try:
        for name, where in (("1 local worker", {"workers": 1}), ("2 local workers", {"workers": 2}),
                            ("Dask LocalCluster, 2 workers", {"scheduler": "local:2"})):
            wall, summary, results = _fit(session, tmp / name.replace(" ", "_").replace(",", ""), frames, options,
                                          args.chain_length, **where)
            outputs[name] = results
            res["runs"][name] = {"wall_s": round(wall, 2), "frames_per_hour": round(3600 * len(frames) / wall, 1),
                                 "load_average_1min": round(os.getloadavg()[0], 2),
                                 "chains": summary["chains"], "executor": summary["executor"],
                                 "frame_s": {str(f): r["timings"]["total"] for f, r in results.items()},
                                 "frame_cpu_s": {str(f): r["timings"].get("cpu") for f, r in results.items()}}
            print(f"  {name:30s} {wall:7.1f} s  {3600 * len(frames) / wall:6.1f} frames/h  chains {summary['chains']}",
                  flush=True)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    # the same plan everywhere: the same poses and shapes (up to last-bit float noise)
    same = max(float(np.max(np.abs(np.subtract(outputs[n][f][k], outputs["1 local worker"][f][k]))))
               for n in outputs for f in frames for k in ("shape", "pose"))
    base = res["runs"]["1 local worker"]["wall_s"]
    one = res["runs"]["1 local worker"]
    # the plan's own bound: all the work over the longest chain (two workers, chains in turn)
    frame_s = {int(f): v for f, v in one["frame_s"].items()}
    loads = [0.0, 0.0]
    for c in one["chains"]:
        loads[loads.index(min(loads))] += sum(frame_s[f] for f in c)
    res["plan_bound_2_workers"] = round(sum(frame_s.values()) / max(loads), 2)
    heads = {c[0] for c in one["chains"]}
    starts = [v for f, v in one["frame_s"].items() if int(f) in heads]
    tracked = [v for f, v in one["frame_s"].items() if int(f) not in heads]
    t_start, t_track = sum(starts) / len(starts), sum(tracked) / max(len(tracked), 1)
    res.update(max_pose_shape_difference=same, t_start_s=round(t_start, 2), t_track_s=round(t_track, 2),
               segment_s_per_frame=round(t_segment, 3),
               estimate_100_participants=_estimate(t_start, t_track, t_segment, args.per_participant,
                                                   args.chain_length),
               target_speedup=TARGET)
    print(f"\nfit scaling — walk sample, {len(frames)} frames, 4 cameras 656×490 "
          f"({'--quick' if args.quick else 'default'} settings)")
    print(f"  {'runner':30s} {'wall s':>8s} {'frames/h':>9s} {'speed-up':>9s} {'CPU s/frame':>12s}")
    for name, r in res["runs"].items():
        r["speedup"] = round(base / r["wall_s"], 2)
        r["cpu_s_per_frame"] = round(float(np.mean(list(r["frame_cpu_s"].values()))), 2)
        print(f"  {name:30s} {r['wall_s']:8.1f} {r['frames_per_hour']:9.1f} {r['speedup']:8.2f}× "
              f"{r['cpu_s_per_frame']:12.2f}")
    ok = all(r["speedup"] >= TARGET for n, r in res["runs"].items() if "2" in n)
    print(f"  the plan's bound with 2 workers (work / busiest worker, from the 1-worker frame times): "
          f"{res['plan_bound_2_workers']:.2f}×; load average during the runs: "
          f"{', '.join(str(r['load_average_1min']) for r in res['runs'].values())} (2 cores)")
    print(f"  target ≥ {TARGET}× with 2 workers (anchor: ideal 2×): {'OK' if ok else 'MISSED'}; "
          f"largest difference in pose or shape between the runners: {same:.1e}")
    print(f"\nestimate: 100 participants × {args.per_participant} frames in chains of ≤ {args.chain_length}, from "
          f"t_start {t_start:.1f} s, t_track {t_track:.1f} s per frame, segmentation {t_segment:.2f} s per frame "
          f"(2 processes), ~5 s report:")
    for row in res["estimate_100_participants"]:
        print(f"  {row['workers']:3d} workers: {row['session_s']:7.1f} s per participant, study {row['study_h']:6.2f} h")
    out = ROOT / "benchmarks" / "results" / "scaling.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out, res)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
