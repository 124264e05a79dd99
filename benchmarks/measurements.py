"""Measurement accuracy and honest uncertainty on simulated people (ISO 7250-1 definitions).

People: the walk sample (an Anny woman: the model never saw her, so model mismatch counts)
at a few frames, and people drawn from the model's own shape prior (both sexes, rendered as
exact silhouettes by a 4-camera ring like the walk's: the fitter's error alone). Every fit is
cached (``<cache>/bench/measurements``), a rerun fits only what is missing.

Per measurement (:data:`studio.body.iso7250.DEFINITIONS`): mean error (fit − truth, the
truth being the true body measured by the SAME definitions), its spread, the share of people
whose truth falls in the report's 95 % interval (:mod:`studio.report.uncertainty`), and
whether the mean |error| meets the ISO 20685-1:2018 maximum allowable error. Anchors:
SMPL-Anthropometry's published ~3.5 cm mean error over its measurements, and the thesis'
7 mm stature error (§4.8.6).

Usage::

    .venv/bin/python benchmarks/measurements.py fit [--people 4] [--workers 2]
    .venv/bin/python benchmarks/measurements.py table
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

WALK_FRAMES = (0, 8, 16)
FIRST_SEED = 7000  # model-prior people: these seeds are only ever measured
ANCHORS = {"smpl_anthropometry_mean_error_mm": 35.0, "thesis_stature_error_mm": 7.0}


def bench_root() -> Path:
    from studio.simulate.samples import cache_root

    return cache_root() / "bench" / "measurements"


def _prior_person(root: Path, index: int) -> dict:
    """A session of one model-prior person: 2 frames (standing, mid-stride), exact silhouettes
    as segmentation, the walk's 4-camera ring (656×490, f = 560 px)."""
    from calibration import RigCalibration
    from calibration.synthetic import camera_ring
    from studio.body import BodyModel
    from studio.fit.init import stride_poses
    from studio.simulate.silhouettes import write_silhouette_session

    rng = np.random.default_rng(FIRST_SEED + index)
    sex = ("female", "male")[index % 2]
    model = BodyModel.load(sex)
    shape = model.sample_shapes(1, rng)[0]
    path = root / f"prior_{index:02d}"
    info = {"name": path.name, "sex": sex, "shape": shape.tolist(), "frames": [0, 1], "kind": "model prior"}
    if (path / "person.json").is_file():
        return json.loads((path / "person.json").read_text())
    cams = list(camera_ring(4, radius=3.6, height=2.3, target=(0.0, 0.0, 0.9), size=(656, 490), focal=560.0,
                            dist=(0, 0, 0, 0, 0), start=np.pi / 4, principal_offset=(0.0, 0.0)).values())
    calib = root / f"{path.name}-calibration.json"
    RigCalibration(cameras={c.name: c for c in cams}).save(calib)
    poses = [model.default_pose(), stride_poses(model)[1]]
    for pose in poses:
        pose[:2] = rng.uniform(-0.2, 0.2, 2)
        pose[5] = rng.uniform(-np.pi, np.pi)
    write_silhouette_session(path, model, shape, poses, cams, calib)
    from rigs.atomic import atomic_write_json

    atomic_write_json(path / "person.json", info)
    return info


def cmd_fit(args) -> int:
    from studio.fit import FitOptions, fit_session
    from studio.segment import segment_session
    from studio.simulate import ensure_rendered
    from studio.workspace import Workspace

    root = bench_root()
    root.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    walk = ensure_rendered(ROOT / "studio" / "samples" / "walk" / "spec.yaml", seed=0)
    ws = Workspace.open(walk, out=root / "walk")
    segment_session(ws, frames=list(WALK_FRAMES), workers=args.workers)
    fit_session(ws, frames=list(WALK_FRAMES), gender="female", workers=args.workers, options=FitOptions())
    print(f"walk fitted ({time.perf_counter() - t0:.0f} s)", flush=True)
    for i in range(args.people):
        p = _prior_person(root, i)
        fit_session(root / p["name"], frames=p["frames"], gender=p["sex"], workers=args.workers,
                    options=FitOptions())
        print(f"{p['name']} ({p['sex']}) fitted ({time.perf_counter() - t0:.0f} s)", flush=True)
    return 0


def _people(root: Path, n: int) -> list[dict]:
    """(name, workspace, model, truth {name: SI}) of every cached person."""
    from studio.body import BodyModel, measure
    from studio.simulate import ensure_rendered
    from studio.simulate.session import studio_truth
    from studio.workspace import Workspace

    walk = ensure_rendered(ROOT / "studio" / "samples" / "walk" / "spec.yaml", seed=0)
    with np.load(ROOT / "studio" / "samples" / "walk" / "body.npz") as z:
        extra = {k: z[k] for k in z.files}
    out = [{"name": "walk (Anny woman)", "ws": Workspace.open(walk, out=root / "walk"), "sex": "female",
            "truth": studio_truth(extra, "female"), "frames": list(WALK_FRAMES)}]
    for i in range(n):
        p = root / f"prior_{i:02d}"
        if not (p / "person.json").is_file():
            continue
        info = json.loads((p / "person.json").read_text())
        model = BodyModel.load(info["sex"])
        out.append({"name": f"{p.name} (model prior, {info['sex']})", "ws": Workspace.open(p), "sex": info["sex"],
                    "truth": measure(model, np.asarray(info["shape"])), "frames": info["frames"]})
    return out


def cmd_table(args) -> int:
    from studio.body import BodyModel
    from studio.body.iso7250 import DEFINITIONS
    from studio.fit import load_fits
    from studio.report import uncertainty as unc_mod
    from studio.report.measurements import UNITS, frames_used, measurement_table
    from studio.report.uncertainty import session_uncertainty

    args.temperature = unc_mod.load_model_error()["temperature"] if args.temperature is None else args.temperature
    root = bench_root()
    rows = {d.name: [] for d in DEFINITIONS}
    people = []
    t0 = time.perf_counter()
    for person in _people(root, args.people):
        ws = person["ws"]
        try:
            fits = load_fits(ws.layout)
        except Exception as exc:  # noqa: BLE001 - a person not fitted yet is left out, and said so
            print(f"{person['name']}: no fits ({exc})")
            continue
        fits = {f: fits[f] for f in person["frames"] if f in fits}
        model = BodyModel.load(sorted({f.gender for f in fits.values()})[0])
        used, _ = frames_used(fits)
        u = session_uncertainty(model, ws.cameras, ws.calibration, fits, used, ws.person_masks, max_frames=2,
                                temperature=args.temperature)
        table = measurement_table(model, fits, {"studio": person["truth"]}, u, sex=person["sex"])
        people.append({"name": person["name"], "frames": used,
                       "status": {str(f): fits[f].status for f in fits}})
        for name, r in table.items():
            rows[name].append({"person": person["name"], "error": r["error"], "sigma": r["sigma"],
                               "sigma_frames": r["sigma_frames"], "sigma_calibration": r["sigma_calibration"],
                               "sigma_posterior": r["sigma_posterior"], "covered": r.get("truth_in_ci95"),
                               "status": r["status"]})
        print(f"{person['name']}: measured ({time.perf_counter() - t0:.0f} s)", flush=True)
    summary = {}
    print(f"\n{'measurement':28s} {'unit':>5s} {'mean err':>9s} {'spread':>7s} {'mean |err|':>10s} "
          f"{'mean σ':>7s} {'95% cover':>9s} {'ISO limit':>9s} {'meets':>6s}")
    for d in DEFINITIONS:
        r = rows[d.name]
        if not r:
            continue
        err = np.array([x["error"] for x in r])
        cov = np.mean([bool(x["covered"]) for x in r])
        unit, scale = UNITS[d.name]
        mae = None if d.max_error is None else d.max_error * scale
        meets = None if mae is None else bool(np.mean(np.abs(err)) <= mae)
        summary[d.name] = {"unit": unit, "mean_error": float(err.mean()), "spread": float(err.std(ddof=1)) if len(err) > 1 else 0.0,
                           "mean_abs_error": float(np.abs(err).mean()), "mean_sigma": float(np.mean([x["sigma"] for x in r])),
                           "coverage_95": float(cov), "iso20685_max_error": mae, "iso20685_met": meets, "people": r}
        s = summary[d.name]
        print(f"{d.title:28s} {unit:>5s} {s['mean_error']:+9.1f} {s['spread']:7.1f} {s['mean_abs_error']:10.1f} "
              f"{s['mean_sigma']:7.1f} {100 * cov:8.0f}% {'-' if mae is None else f'{mae:.0f}':>9s} "
              f"{'-' if meets is None else ('yes' if meets else 'no'):>6s}")
    lengths = [s for s in summary.values() if s["unit"] == "mm"]
    pooled_mae = float(np.mean([s["mean_abs_error"] for s in lengths]))
    pooled_cov = float(np.mean([x["covered"] for s in lengths for x in s["people"]]))
    z = np.array([x["error"] / x["sigma"] for s in lengths for x in s["people"] if x["sigma"] > 0])
    inflate = float(np.percentile(np.abs(z), 95) / 1.96) if len(z) else float("nan")
    print(f"\nall lengths: mean |error| {pooled_mae:.1f} mm (SMPL-Anthropometry ~{ANCHORS['smpl_anthropometry_mean_error_mm']:.0f} mm); "
          f"stature |error| {summary['stature']['mean_abs_error']:.1f} mm (thesis {ANCHORS['thesis_stature_error_mm']:.0f} mm); "
          f"95 % interval coverage {100 * pooled_cov:.0f} % (target 95 %); "
          f"σ would need ×{inflate:.2f} for 95 %")
    from rigs.atomic import atomic_write_json

    out = atomic_write_json(ROOT / "benchmarks" / "results" / "measurements.json", {
        "benchmark": "measurements", "temperature": args.temperature, "people": people, "anchors": ANCHORS,
        "pooled": {"mean_abs_error_mm": pooled_mae, "coverage_95": pooled_cov, "sigma_inflation_for_95": inflate},
        "measurements": summary}, mkdir=True)
    for group in ("walk", "prior"):
        cov = [x["covered"] for s in lengths for x in s["people"] if x["person"].startswith(group)]
        if cov:
            print(f"coverage on {group} people: {100 * np.mean(cov):.0f} % of {len(cov)} intervals")
    print(f"wrote {out}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fit", help="fit (or reuse) the benchmark people")
    f.add_argument("--people", type=int, default=4)
    f.add_argument("--workers", type=int, default=2)
    t = sub.add_parser("table", help="measure the cached fits against the truth")
    t.add_argument("--people", type=int, default=4)
    t.add_argument("--temperature", type=float, default=None,
                   help="posterior temperature (default: the shipped calibration's, benchmarks/measurement_intervals.py)")
    args = ap.parse_args(argv)
    return cmd_fit(args) if args.cmd == "fit" else cmd_table(args)


if __name__ == "__main__":
    raise SystemExit(main())
