"""Honest measurement intervals on people the body model never saw: learn, then check.

The report's 95 % intervals (:mod:`studio.report.uncertainty`) combine the spread over frames,
the calibration, the fit's Laplace posterior at a temperature T, and the model's own error on
unseen people. The last two are learned here from the pose benchmark's generated Anny people
(``benchmarks/pose_accuracy.py``: 4 postures each, every frame fitted alone; their stored fits are
reused, nothing is refitted):

- ``calibrate`` (dev split only): T is chosen so that a single frame's posterior explains the
  spread of that person's measurement over the other frames (z = (value − person's mean) /
  (σ_post · √((n−1)/n)), pooled median |z| = 0.674 over every measurement in mm; heights over
  the frames the report uses for them); then, per measurement, the model error σ_model is the root
  mean square error the frames, calibration and posterior terms leave unexplained (0 if none).
  Writes ``studio/report/data/model_error.json``.
- ``check`` (any split; the held-out one is the report): the report's own code path
  (:func:`~studio.report.uncertainty.session_uncertainty`, :func:`~studio.report.measurements.measurement_table`)
  with the shipped calibration: per measurement mean error, mean |error|, mean σ, 95 % coverage.

    .venv/bin/python benchmarks/measurement_intervals.py calibrate --variant dev-48 --people 48
    .venv/bin/python benchmarks/measurement_intervals.py check --split held-out --variant hybrid --people 30

Anchor: 95 % of the truths inside the 95 % intervals (pooled over the lengths), each measurement
not far below.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

#: the temperatures ``calibrate`` chooses among
T_GRID = np.geomspace(0.002, 2.0, 61)
#: median of |z| for a standard normal
HALF_NORMAL_MEDIAN = 0.6745


def _person(job: dict) -> dict | None:
    """Worker: one pose-benchmark person's stored fits, truth and (calibrate) per-frame Hessians, or
    (check) the report's table with the shipped calibration."""
    import pose_accuracy as pa
    from studio.body import BodyModel
    from studio.body.iso7250 import ISO_NAMES
    from studio.fit.result import FrameFit
    from studio.report import uncertainty as U
    from studio.report.measurements import frames_used, load_truth, measurement_table
    from studio.simulate.session import default_cache_dir
    from studio.simulate.spec import load_spec
    from studio.workspace import Workspace

    root = pa.bench_root(job["split"])
    rows = [json.loads(p.read_text()) for p in sorted((root / "results" / job["variant"]).glob(f"{job['name']}_*.json"))]
    rows = [r for r in rows if "shape" in r]
    if not rows:
        return None
    ws = Workspace.open(default_cache_dir(load_spec(root / job["name"] / "spec.yaml")) / "seed0")
    sex = rows[0]["sex"]
    model = BodyModel.load(sex)
    fits = {r["frame"]: FrameFit(frame=r["frame"], gender=sex, shape=np.asarray(r["shape"]), pose=np.asarray(r["pose"]),
                                 joints=np.zeros((15, 3)), costs={}, timings={}, n_evaluations=0,
                                 quality=r.get("quality") or {}) for r in rows}
    used, _ = frames_used(fits)
    truth = load_truth(ws.layout)
    out = {"name": job["name"], "sex": sex, "used": used}
    if job["step"] == "check":
        unc = U.session_uncertainty(model, ws.cameras, ws.calibration, fits, used, ws.person_masks)
        out["table"] = measurement_table(model, fits, truth, unc, sex=sex)
        return out
    table = measurement_table(model, fits, truth, None, sex=sex)
    out["rows"] = {n: {k: r[k] for k in ("error", "frames_used", "per_frame", "sigma_frames")}
                   for n, r in table.items() if r["error"] is not None}
    frames = {}
    for f in used:
        H, sigma = U.shape_hessian(model, ws.cameras, ws.person_masks(f), fits[f].shape, fits[f].pose)
        frames[f] = {"H": H.tolist(), "sigma": sigma.tolist(),
                     "J": U.measurement_jacobian(model, fits[f].shape, ISO_NAMES).tolist()}
    out["frames"] = frames
    out["J_mean"] = U.measurement_jacobian(model, np.mean([fits[f].shape for f in used], axis=0), ISO_NAMES).tolist()
    out["names"] = list(ISO_NAMES)
    return out


def _run(step: str, args) -> list[dict]:
    import pose_accuracy as pa
    from rich.progress import track
    from studio.workers import worker_pool

    jobs = [{"step": step, "split": args.split, "variant": args.variant, "name": p["name"]}
            for p in pa.people(args.people, 4, args.split)]
    with worker_pool(args.workers) as pool:
        done = list(track(pool.map(_person, jobs), total=len(jobs), description=f"{step}: {args.split} people"))
    return [d for d in done if d is not None]


def calibrate(args) -> int:
    from rigs.atomic import atomic_write_json
    from studio.report.measurements import UNITS
    from studio.report.uncertainty import MODEL_ERROR_FILE, measurement_sd, posterior_covariance

    if args.split != "dev":
        print("calibrate learns from the dev split only (the held-out people are for `check`)", file=sys.stderr)
        return 2
    people = _run("calibrate", args)
    names = people[0]["names"]
    mm = [n for n in names if UNITS[n][0] == "mm"]
    scales = np.array([UNITS[n][1] for n in names])

    def frame_sd(p, T):  # {frame: (M,) σ in report units}
        return {f: measurement_sd(d["J"], posterior_covariance(d["H"], d["sigma"], T)) * scales
                for f, d in p["frames"].items()}

    def median_z(T):
        z = []
        for p in people:
            sd = frame_sd(p, T)
            for n in mm:
                r = p["rows"].get(n)
                fr = [] if r is None else [str(f) for f in r["frames_used"]]
                if len(fr) < 2:
                    continue
                vals = np.array([r["per_frame"][f] for f in fr])
                s = np.array([sd[int(f)][names.index(n)] for f in fr]) * np.sqrt((len(fr) - 1) / len(fr))
                z += list(np.abs(vals - vals.mean()) / np.maximum(s, 1e-9))
        return float(np.median(z))

    mz = np.array([median_z(T) for T in T_GRID])
    T = float(T_GRID[np.argmin(np.abs(mz - HALF_NORMAL_MEDIAN))])
    model_sigma, report = {}, []
    for i, n in enumerate(names):
        scale = UNITS[n][1]
        e2, known = [], []
        for p in people:
            r = p["rows"].get(n)
            if r is None:
                continue
            # the report's posterior: the covariances of the first 3 frames used, averaged
            C = np.mean([posterior_covariance(d["H"], d["sigma"], T) for d in list(p["frames"].values())[:3]], axis=0)
            post = float(measurement_sd(np.asarray(p["J_mean"])[i:i + 1], C)[0]) * scale
            e2.append(r["error"] ** 2)
            known.append(r["sigma_frames"] ** 2 + post**2)
        model_sigma[n] = float(np.sqrt(max(np.mean(e2) - np.mean(known), 0.0))) / scale
        report.append((n, UNITS[n][0], float(np.sqrt(np.mean(e2))), float(np.sqrt(np.mean(known))), model_sigma[n] * scale))
    print(f"temperature {T:.4g} (pooled median |z| of the frames about their person's mean: {mz.min():.3f} … "
          f"{mz.max():.3f} over the grid; {HALF_NORMAL_MEDIAN} wanted)")
    print(f"{'measurement':26s} {'unit':>5s} {'rms err':>8s} {'rms σ known':>11s} {'σ model':>8s}")
    for n, unit, rms, known, sm in report:
        print(f"{n:26s} {unit:>5s} {rms:8.1f} {known:11.1f} {sm:8.1f}")
    source = (f"benchmarks/measurement_intervals.py calibrate: pose benchmark dev split, variant {args.variant}, "
              f"{len(people)} people")
    atomic_write_json(MODEL_ERROR_FILE, {
        "format": "studio.model-error", "version": 1, "temperature": round(T, 6), "source": source,
        "model_sigma": {n: round(v, 6) for n, v in model_sigma.items()}, "people": len(people),
        "median_z_by_temperature": {f"{t:.4g}": round(float(z), 4) for t, z in zip(T_GRID, mz)}})
    print(f"wrote {MODEL_ERROR_FILE}")
    return 0


def check(args) -> int:
    from rigs.atomic import atomic_write_json
    from studio.report.measurements import UNITS

    people = _run("check", args)
    names = list(people[0]["table"])
    print(f"{'measurement':26s} {'unit':>5s} {'mean err':>9s} {'mean |err|':>10s} {'mean σ':>7s} {'95% cover':>9s}")
    summary = {}
    for n in names:
        rows = [p["table"][n] for p in people if p["table"][n]["error"] is not None]
        err = np.array([r["error"] for r in rows])
        summary[n] = {"unit": UNITS[n][0], "mean_error": float(err.mean()), "mean_abs_error": float(np.abs(err).mean()),
                      "mean_sigma": float(np.mean([r["sigma"] for r in rows])),
                      "coverage_95": float(np.mean([r["truth_in_ci95"] for r in rows])), "n": len(rows)}
        s = summary[n]
        print(f"{n:26s} {s['unit']:>5s} {s['mean_error']:+9.1f} {s['mean_abs_error']:10.1f} {s['mean_sigma']:7.1f} "
              f"{100 * s['coverage_95']:8.0f}%")
    mm = [n for n in names if summary[n]["unit"] == "mm"]
    pooled = float(np.mean([p["table"][n]["truth_in_ci95"] for p in people for n in mm
                            if p["table"][n]["error"] is not None]))
    worst = min(mm, key=lambda n: summary[n]["coverage_95"])
    print(f"\n{len(people)} {args.split} people: pooled 95 % coverage over the lengths {100 * pooled:.1f} % "
          f"(anchor 95 %); lowest {worst} {100 * summary[worst]['coverage_95']:.0f} %")
    out = atomic_write_json(ROOT / "benchmarks" / "results" / f"measurement_intervals_{args.split}.json", {
        "benchmark": "measurement_intervals", "split": args.split, "variant": args.variant, "people": len(people),
        "pooled_coverage_95": pooled, "anchor": 0.95, "measurements": summary}, mkdir=True)
    print(f"wrote {out}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("step", choices=("calibrate", "check"))
    ap.add_argument("--split", choices=("dev", "held-out"), default="dev")
    ap.add_argument("--variant", default="dev-48", help="the pose benchmark's results to read")
    ap.add_argument("--people", type=int, default=48)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    return calibrate(args) if args.step == "calibrate" else check(args)


if __name__ == "__main__":
    raise SystemExit(main())
