"""Fit accuracy on the simulated walk (thesis §4.8, fig. 4.10; anchors in ANCHORS).

Renders (once) the walk sample, segments the frames, fits them with ``studio.fit.fit_session``
(given gender, 2 workers), then compares with the truth:

- measurements (every reported one: stature, arm span, shoulder breadth, chest/waist/hip
  circumference, inseam, arm length, mass) as mean ± spread over frames, error = mean − truth,
  where the truth is the true body measured by the SAME definitions as the fit
  (``truth/measurements.json`` "studio" entry, see ``studio.simulate.session.studio_truth``);
  the simulator's Anny-definition values (waist from Anny's anthropometry, chest/hips from
  slices of Anny's T-pose, T-pose stature) are shown beside them as ``truth_anny``;
- mean surface distance fitted ↔ true mesh (symmetric, point-to-surface via dense samples);
- mean joint position error (eq. 4.17): our joint regressor applied to the fitted mesh and to
  the true Anny mesh mapped into our topology (``anny_correspondence``);
- silhouette precision / recall of the fitted silhouettes against the TRUE person labels;
- robustness (fig. 4.10): joint error after re-fitting one frame from its fitted pose with
  Gaussian noise of increasing σ added to every joint angle.

Usage: ``.venv/bin/python benchmarks/fit_accuracy.py [--frames 0:24:4] [--workers 2] [--quick]``
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

ANCHORS = {
    "stature_error_mm": ("|err| ≤ 10 (thesis: 7 mm, spread ±15 mm over 33 frames)", 10.0),
    "surface_distance_mm": ("≤ 15", 15.0),
    "silhouette_precision": ("≥ 0.95 (thesis 0.88)", 0.95),
    "silhouette_recall": ("≥ 0.95 (thesis 0.85)", 0.95),
}


MEASUREMENT_KEYS = ("mean", "std", "unit", "truth", "error", "truth_source", "truth_anny", "error_anny")


def measurement_lines(table: dict) -> list[str]:
    """Rows of the measurement block: mean ± std, same-definition truth and error, Anny truth and error."""
    fmt = (lambda v, sign="": "n/a" if v is None else f"{v:{sign}.1f}")  # noqa: E731
    lines = [f"{'measurement':22s} {'unit':>4s} {'mean':>8s} {'std':>6s} {'truth':>8s} {'error':>7s}"
             f"   {'truth_anny':>10s} {'err_anny':>8s}"]
    for name, r in table.items():
        src = "" if r.get("truth_source") in (None, "studio") else f" ({r['truth_source']} def.)"
        lines.append(f"{name:22s} {r['unit']:>4s} {r['mean']:8.1f} {r['std']:6.1f} {fmt(r['truth']):>8s} "
                     f"{fmt(r['error'], '+'):>7s}   {fmt(r.get('truth_anny')):>10s} "
                     f"{fmt(r.get('error_anny'), '+'):>8s}{src}")
    return lines


def main(argv=None) -> int:
    from rigs.atomic import atomic_write_text

    from studio.body import BodyModel
    from studio.cli.commands.fit import QUICK
    from studio.fit import FitOptions, fit_frame, fit_session, load_fits
    from studio.workspace import Workspace
    from studio.workspace.frames import select_frames
    from studio.fit.evaluate import joint_error, silhouette_agreement, surface_distance, true_mesh, true_person_masks
    from studio.render import silhouette
    from studio.report.measurements import load_truth, measurement_table
    from studio.segment import segment_session
    from studio.simulate import ensure_rendered

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spec", type=Path, default=ROOT / "studio" / "samples" / "walk" / "spec.yaml")
    ap.add_argument("--frames", default="0:24:4")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--noise", default="0,0.1,0.2,0.4", help="robustness σ values (rad)")
    ap.add_argument("--no-robustness", action="store_true")
    args = ap.parse_args(argv)
    options = FitOptions(**QUICK) if args.quick else FitOptions()

    t0 = time.perf_counter()
    session = ensure_rendered(args.spec, seed=0)
    ws = Workspace.open(session)
    frames = select_frames(args.frames, ws.frame_indices)
    segment_session(ws, frames=frames, workers=args.workers, force=True)
    t_fit = time.perf_counter()
    summary = fit_session(ws, frames=frames, gender="female", workers=args.workers, options=options, force=True)
    t_fit = time.perf_counter() - t_fit
    model = BodyModel.load(summary["gender"])
    fits = load_fits(session)
    fits = {f: fits[f] for f in frames}
    cameras = ws.cameras
    rows = []
    for f, fit in fits.items():
        V = model.vertices(fit.shape, fit.pose)
        Vt = true_mesh(session, f)
        truth_masks = true_person_masks(session, f, cameras)
        model_masks = [silhouette(c, V, model.faces) for c in cameras]
        prec, rec = silhouette_agreement(model_masks, truth_masks)
        rows.append({
            "frame": f,
            "cost": fit.costs["total"],
            "surface_distance_mm": 1000 * surface_distance(V, model.faces, Vt, model.faces),
            "joint_error_mm": 1000 * joint_error(model, V, Vt)[0],
            "silhouette_precision": prec,
            "silhouette_recall": rec,
            "fit_time_s": fit.timings["total"],
        })
    table = measurement_table(model, fits, load_truth(session))

    robustness = []
    if not args.no_robustness:
        f = frames[0]
        fit = fits[f]
        masks = ws.person_masks(f)
        Vt = true_mesh(session, f)
        rng = np.random.default_rng(0)
        for sigma in [float(s) for s in args.noise.split(",")]:
            start = fit.pose.copy()
            start[6:] += rng.normal(0, sigma, start[6:].shape) if sigma > 0 else 0.0
            start = model.clip_pose(start)
            e0 = 1000 * joint_error(model, model.vertices(fit.shape, start), Vt)[0]
            refit = fit_frame(model, cameras, masks, frame=f, shape=fit.shape, previous_pose=start,
                              options=options, seed=1)
            e1 = 1000 * joint_error(model, model.vertices(refit.shape, refit.pose), Vt)[0]
            robustness.append({"sigma_rad": sigma, "joint_error_before_mm": e0, "joint_error_after_mm": e1,
                               "cost": refit.costs["total"]})

    agg = {k: float(np.mean([r[k] for r in rows])) for k in rows[0] if k != "frame"}
    st = table["stature"]
    result = {
        "benchmark": "fit_accuracy",
        "session": str(session),
        "frames": frames,
        "options": options.to_dict(),
        "fit_wall_time_s": t_fit,
        "workers": args.workers,
        "per_frame": rows,
        "mean": agg,
        "measurements": {k: {kk: v.get(kk) for kk in MEASUREMENT_KEYS} for k, v in table.items()},
        "stature_error_mm": st["error"],
        "arm_span_error_mm": table["arm_span"]["error"],
        "stature_spread_mm": st["std"],
        "robustness": robustness,
        "anchors": {k: v[0] for k, v in ANCHORS.items()},
        "total_time_s": time.perf_counter() - t0,
    }
    out = ROOT / "benchmarks" / "results" / "fit_accuracy.json"
    atomic_write_text(out, json.dumps(result, indent=2) + "\n", mkdir=True)

    print(f"fit accuracy — walk sample, frames {frames}, {len(frames)} fits in {t_fit:.0f} s ({args.workers} workers)")
    print(f"{'quantity':34s} {'value':>14s}   anchor")
    checks = {
        "stature_error_mm": (abs(st["error"]), lambda v: v <= 10),
        "surface_distance_mm": (agg["surface_distance_mm"], lambda v: v <= 15),
        "silhouette_precision": (agg["silhouette_precision"], lambda v: v >= 0.95),
        "silhouette_recall": (agg["silhouette_recall"], lambda v: v >= 0.95),
    }
    for k, (v, ok) in checks.items():
        print(f"{k:34s} {v:14.3f}   {ANCHORS[k][0]}  {'OK' if ok(v) else 'MISSED'}")
    print(f"{'stature spread (std) mm':34s} {st['std']:14.1f}   thesis ±15")
    print(f"{'joint error (eq. 4.17) mm':34s} {agg['joint_error_mm']:14.1f}")
    for line in measurement_lines(table):
        print(line)
    for r in robustness:
        print(f"robustness σ={r['sigma_rad']:.2f} rad: joint error {r['joint_error_before_mm']:.0f} → "
              f"{r['joint_error_after_mm']:.0f} mm")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
