"""Monocular fitting with and without the shadow term (thesis §5.5, §5.8.2).

Anchor: the thesis fitted a person seen by ONE camera, with and without the shadow a point light
casts on the floor (the shadow as a second, "shadow" camera, eq. 5.7): mean joint error 122 mm
without the shadow, 63 mm with it. Target here: ≤ 40 mm with the shadow.

Session: the ``mono_shadow`` sample (one 656×490 camera, a point light to the side, the walk's
person), rendered once (cache), segmented (person label 1, shadow label 2; ``--labels truth``: the
simulator's labels). Every chosen frame is fitted ALONE (no tracking, the true sex) on the same
silhouettes, as variants:

- ``silhouette``: the silhouette term only (a monocular frame: the quality gates flag it);
- ``shadow``: plus the shadow term (eq. 5.7, weight 1) with the simulator's true light;
- ``silhouette_sequence``, ``shadow_sequence`` (``--sequence``): the same two, the frames fitted
  in order, each also started from the previous frame's answer (one more start, not tracking);
- ``shadow_estimated`` (``--estimated``): plus the shadow term with the light estimated by
  :func:`studio.light.estimate_light` from the ``silhouette`` fits and the segmented shadows
  (the thesis' procedure: fit without shadows, estimate the light, fit again); the estimate's
  95 % intervals go to the quality gates (a light less certain than 3° / ±15 % flags the frames).

Joint error: eq. 4.17, the mean over the 15 joints of our joint regressor applied to the fitted
mesh and to the true body mapped into our topology (as ``benchmarks/fit_accuracy.py``). Each
fitted frame is cached as JSON under ``benchmarks/results/monocular/<labels>/<fitting code digest>/``
(a rerun fits only what is missing); the summary goes to ``benchmarks/results/monocular.json``.

    .venv/bin/python benchmarks/monocular.py [--frames 0:24:4] [--workers 2] [--sequence] [--estimated] [--quick]
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

SPEC = ROOT / "studio" / "samples" / "mono_shadow" / "spec.yaml"
THESIS = {"silhouette_mm": 122.0, "shadow_mm": 63.0}
TARGET_MM = 40.0


def _masks(ws, frame: int, labels: str) -> tuple[list, list]:
    """(person masks, shadow masks) of the session's cameras for ``frame``."""
    from rigs.imageio import read_image

    if labels == "truth":
        labs = [np.asarray(read_image(ws.layout.truth_labels(c, frame))) for c in ws.camera_names]
        labs = [lab[..., 0] if lab.ndim == 3 else lab for lab in labs]
    else:
        labs = [ws.labels(c, frame) for c in ws.camera_names]
    return [lab == 1 for lab in labs], [lab == 2 for lab in labs]


def _fit_one(job: dict) -> dict:
    """Worker: fit one frame alone (one variant) and measure it against the truth."""
    from studio.body import BodyModel
    from studio.fit import FitOptions, fit_frame
    from studio.fit.evaluate import joint_error, true_mesh
    from studio.render import light_from_dict
    from studio.workspace import Workspace

    ws = Workspace.open(job["session"])
    model = BodyModel.load(job["sex"])
    f = job["frame"]
    masks, shadows = _masks(ws, f, job["labels"])
    extra = {}
    if job["lights"]:
        extra = {"lights": [light_from_dict(d) for d in job["lights"]], "shadow_masks": shadows,
                 "ground": getattr(ws.calibration, "ground", None), "light_uncertainty": job.get("light_uncertainty")}
    t, c = time.perf_counter(), time.process_time()
    hint = None if job.get("hint_pose") is None else np.asarray(job["hint_pose"], float)
    fit = fit_frame(model, ws.cameras, masks, frame=f, options=FitOptions(**job["options"]), seed=job.get("seed", f),
                    hint_pose=hint, **extra)
    V, Vt = model.vertices(fit.shape, fit.pose), true_mesh(ws.path, f)
    err, per_joint = joint_error(model, V, Vt)
    return {"frame": f, "variant": job["variant"], "sex": job["sex"], "joint_mm": 1000 * err,
            "per_joint_mm": np.round(1000 * per_joint, 1).tolist(), "root_error_mm": float(1000 * per_joint[0]),
            "status": fit.quality["status"], "reasons": [r["message"] for r in fit.quality["reasons"]],
            "costs": {k: v for k, v in fit.costs.items() if isinstance(v, float)},
            "time_s": time.perf_counter() - t, "cpu_s": time.process_time() - c, "timings": fit.timings,
            "start_family": fit.costs.get("start_family"),
            "shape": fit.shape.tolist(), "pose": fit.pose.tolist(), "lights": job["lights"]}


def _fit_chain(jobs: list[dict], paths: list[str], first: str) -> list[dict]:
    """Worker: fit ``jobs`` (frames in order) one after the other, each started also from the
    previous frame's fitted pose (``hint_pose``: one more start, not tracking); cached in ``paths``.
    The first frame has no previous one: its fit is the one-by-one variant's (``first``) when cached."""
    from rigs.atomic import atomic_write_json

    out, previous = [], None
    for job, path in zip(jobs, paths, strict=True):
        r = json.loads(Path(path).read_text()) if Path(path).is_file() else None
        if r is None and previous is None and Path(first).is_file():
            r = dict(json.loads(Path(first).read_text()), variant=job["variant"])
            atomic_write_json(Path(path), r)
        if r is None:
            r = _fit_one(dict(job, hint_pose=previous))
            atomic_write_json(Path(path), r)
        out.append(r)
        previous = r["pose"]
    return out


def _estimated_light(ws, frames: list[int], rows: dict, labels: str, out: Path) -> tuple[list[dict], dict]:
    """The light estimated from the ``silhouette`` fits (cached in ``out``) and its 95 % intervals."""
    from rigs.atomic import atomic_write_json
    from studio.body import BodyModel
    from studio.light import estimate_light, light_uncertainty

    if out.is_file():
        saved = json.loads(out.read_text())
        return saved["lights"], light_uncertainty(saved["light"])
    bodies = []
    for f in frames:
        r = rows[("silhouette", f)]
        model = BodyModel.load(r.get("sex", "female"))
        bodies.append((model.vertices(np.asarray(r["shape"]), np.asarray(r["pose"])), model.faces))
    est = estimate_light(bodies, ws.cameras, [_masks(ws, f, labels)[1] for f in frames], frames=frames, kind="point",
                         ground=getattr(ws.calibration, "ground", None))
    lights = [{"type": "point", "position": light.position.tolist()} for light in est.lights]
    atomic_write_json(out, {"lights": lights, "light": est.to_json()})
    return lights, light_uncertainty(est.to_json())


def main(argv=None) -> int:
    from rich.progress import Progress

    from rigs.atomic import atomic_write_json
    from studio.cli.commands.fit import QUICK
    from studio.fit import FitOptions
    from studio.report.measurements import load_truth
    from studio.segment import segment_session
    from studio.simulate import ensure_rendered
    from studio.workers import worker_pool
    from studio.workspace import Workspace
    from studio.workspace.frames import select_frames

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", default="0:24:4", help="frames to fit (default: %(default)s, 6 frames)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--labels", choices=["segmentation", "truth"], default="segmentation")
    ap.add_argument("--estimated", action="store_true", help="also fit with the light estimated from the "
                                                             "silhouette-only fits")
    ap.add_argument("--sequence", action="store_true", help="also fit both variants frame after frame, each "
                                                            "started also from the previous frame's answer")
    ap.add_argument("--quick", action="store_true", help="the fit's quick settings (a smaller budget)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "monocular")
    args = ap.parse_args(argv)

    session = ensure_rendered(SPEC, seed=0)
    ws = Workspace.open(session)
    frames = select_frames(args.frames, ws.frame_indices)
    if args.labels == "segmentation":
        segment_session(ws, frames=frames, workers=1)
    truth = load_truth(ws.layout)
    true_lights = json.loads((ws.layout.truth_dir / "lights.json").read_text())["lights"]
    options = FitOptions(**QUICK) if args.quick else FitOptions()
    from studio.fit.units import frame_fit_code_digest

    tag = f"{args.labels}{'_quick' if args.quick else ''}"
    folder = args.out / tag / frame_fit_code_digest()  # fits of other fitting code (or model) are not reused
    folder.mkdir(parents=True, exist_ok=True)

    def path(variant, f):
        return folder / f"{variant}_{f:06d}.json"

    def run(variant, lights, uncertainty=None):
        jobs = [{"session": str(session), "frame": f, "variant": variant, "sex": truth["sex"], "labels": args.labels,
                 "options": options.to_dict(), "lights": lights, "light_uncertainty": uncertainty}
                for f in frames if not path(variant, f).is_file()]
        if not jobs:
            return
        with Progress() as bar, worker_pool(min(args.workers, len(jobs))) as pool:
            task = bar.add_task(f"fitting ({variant})", total=len(jobs))
            for fut in [pool.submit(_fit_one, j) for j in jobs]:
                r = fut.result()
                atomic_write_json(path(variant, r["frame"]), r)
                bar.advance(task)

    t0 = time.perf_counter()
    run("silhouette", None)
    run("shadow", true_lights)
    variants = ["silhouette", "shadow"]
    if args.sequence:  # both variants again, each frame also started from the previous frame's answer
        chains = {f"{v}_sequence": lights for v, lights in (("silhouette", None), ("shadow", true_lights))}
        with worker_pool(min(args.workers, 2)) as pool:
            futures = [pool.submit(_fit_chain, [{"session": str(session), "frame": f, "variant": v, "sex": truth["sex"],
                                                 "labels": args.labels, "options": options.to_dict(), "lights": lights}
                                                for f in frames], [str(path(v, f)) for f in frames],
                                   str(path(v.removesuffix("_sequence"), frames[0])))
                       for v, lights in chains.items()]
            for fut in futures:
                fut.result()
        variants += list(chains)
    light_note = None
    if args.estimated:
        from studio.light import LightError

        rows = {(r["variant"], r["frame"]): r for r in (json.loads(path("silhouette", f).read_text()) for f in frames)}
        try:
            lights, uncertainty = _estimated_light(ws, frames, rows, args.labels, folder / "light_estimated.json")
        except LightError as exc:  # the silhouette-only bodies may be too wrong to explain any shadow
            light_note = f"light not estimated from the silhouette-only fits: {exc}"
            print(light_note)
        else:
            run("shadow_estimated", lights, uncertainty)
            variants.append("shadow_estimated")
    rows = {(v, f): json.loads(path(v, f).read_text()) for v in variants for f in frames}

    print(f"\nMonocular fit of mono_shadow ({len(frames)} frames, one camera; labels: {args.labels}), joint error mm "
          "(eq. 4.17)")
    print(f"{'frame':>6s} " + " ".join(f"{v:>17s}" for v in variants))
    for f in frames:
        print(f"{f:6d} " + " ".join(f"{rows[(v, f)]['joint_mm']:9.1f} {rows[(v, f)]['status']:>7s}" for v in variants))
    summary = {}
    for v in variants:
        e = np.array([rows[(v, f)]["joint_mm"] for f in frames])
        summary[v] = {"joint_mean_mm": float(e.mean()), "joint_median_mm": float(np.median(e)),
                      "joint_max_mm": float(e.max()),
                      "root_mean_mm": float(np.mean([rows[(v, f)]["root_error_mm"] for f in frames])),
                      "ok_share": float(np.mean([rows[(v, f)]["status"] == "ok" for f in frames])),
                      "cpu_s_per_frame": float(np.mean([rows[(v, f)]["cpu_s"] for f in frames]))}
    print(f"{'mean':>6s} " + " ".join(f"{summary[v]['joint_mean_mm']:9.1f} {'':>7s}" for v in variants))
    print(f"thesis: {THESIS['silhouette_mm']:.0f} mm without the shadow, {THESIS['shadow_mm']:.0f} mm with it; "
          f"target ≤ {TARGET_MM:.0f} mm with it")
    for v in variants:
        s = summary[v]
        print(f"  {v}: mean {s['joint_mean_mm']:.1f} mm (median {s['joint_median_mm']:.1f}, worst "
              f"{s['joint_max_mm']:.1f}; root {s['root_mean_mm']:.1f} mm), ok {s['ok_share']:.0%}, "
              f"{s['cpu_s_per_frame']:.1f} CPU s per frame")
    res = args.out.parent / "monocular.json"
    atomic_write_json(res, {"benchmark": "monocular", "thesis": THESIS, "target_mm": TARGET_MM, "frames": frames,
                            "labels": args.labels, "quick": args.quick, "summary": summary,
                            "true_lights": true_lights, "estimated_light_note": light_note,
                            "rows": [rows[(v, f)] for v in variants for f in frames],
                            "seconds": time.perf_counter() - t0})
    print(f"written {res}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
