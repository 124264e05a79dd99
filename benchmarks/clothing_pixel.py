"""The tight batch on masks rendered from the body model itself: what is left when the person *is* the model.

``benchmarks/clothing.py`` measures the fits against the simulator's true (Anny) bodies, which the model
reproduces only approximately, seen through segmented images. This takes each tight subject's true body into
the model: its rest body as the model's shape (:func:`model_space_truth`, linear least squares over every
coefficient), each frame's posed true body as a model pose of that shape (``pose_ceiling.fit_to_mesh``, bounded
least squares on the vertices, from the frame's single fit), and renders the silhouettes of that model body in the
session's cameras. Single-frame fits and the batch then run on those masks (tight clothing, the true sex given),
and their girths are compared with the model-space truth's — no model mismatch, no segmentation, no clothes, the
truth's own cost 0. Beside them the same subjects' figures on the real masks (the benchmark's results) and the
cameras' millimetres per pixel at the person.

It reads what ``clothing.py run`` left on this machine (each subject's rendered session with its single fits,
the result, ``body.npz``) and fits only on the rendered masks; about 3 minutes a subject::

    .venv/bin/python benchmarks/clothing_pixel.py --split dev --cache dev-p4 --subjects 6

Prints a table and writes ``pixel.json`` beside the benchmark's ``summary.json``. README, *Shape under
clothing* (stop 63), gives the figures and why they matter: the batch's extra tight hip is below a pixel.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import clothing  # noqa: E402  (the benchmark's cache, subjects and results)
from pose_ceiling import fit_to_mesh  # noqa: E402  (the model posed onto a true body in 3-D)

MEASURES = ("stature", "chest_circumference", "waist_circumference", "hip_circumference")


def model_space_truth(model, rest: np.ndarray) -> tuple[np.ndarray, float]:
    """The shape (n_shape,) whose default-pose body is closest to ``rest`` (V, 3; the model's topology) up to
    a translation — the model's body is linear in its coefficients at the default pose — and the rms
    vertex distance (m) left."""
    pose = model.default_pose()
    sig = np.sqrt(np.asarray(model.eigenvalues, dtype=np.float64))
    base = model.vertices(np.zeros(model.n_shape), pose)
    B = np.stack([(model.vertices(np.eye(model.n_shape)[i] * sig[i], pose) - base).ravel()
                  for i in range(model.n_shape)], axis=1)
    A = np.concatenate([B, np.tile(np.eye(3), (len(base), 1))], axis=1)
    x, *_ = np.linalg.lstsq(A, (np.asarray(rest, dtype=np.float64) - base).ravel(), rcond=None)
    shape = x[:model.n_shape] * sig
    rms = float(np.sqrt(np.mean(np.sum((model.vertices(shape, pose) + x[model.n_shape:] - rest) ** 2, axis=1))))
    return shape, rms


def finer_cameras(cameras, scale: int) -> list:
    """``cameras`` with ``scale`` × as many pixels each way (the inverse of :func:`studio.render.pyramid.level_camera`:
    pixel centres at ``scale · x + (scale − 1) / 2``)."""
    A = np.array([[scale, 0.0, (scale - 1) / 2], [0.0, scale, (scale - 1) / 2], [0.0, 0.0, 1.0]])
    return [c.replace(K=A @ np.asarray(c.K, dtype=np.float64), size=(int(c.size[0]) * scale, int(c.size[1]) * scale))
            for c in cameras]


def mm_per_pixel(cameras, point=(0.0, 0.0, 1.0)) -> float:
    """Mean over ``cameras`` of the size (mm) of one pixel at ``point`` (world, m): distance / focal length."""
    return float(np.mean([1000 * np.linalg.norm(c.center - np.asarray(point)) / float(c.K[0, 0]) for c in cameras]))


def subject_pixel(r: dict, scale: int = 1) -> dict:
    """One tight result's subject on model-rendered masks (in the session's cameras, or with ``scale`` × finer
    pixels: :func:`finer_cameras`): the batch's and the single fits' errors (mm) against the model-space truth,
    the batch's cost per frame, the registration's rms."""
    from studio.body import BodyModel, anny_correspondence, measure
    from studio.fit import load_fits
    from studio.fit.batch import BatchFrame, BatchOptions, batch_fit
    from studio.fit.evaluate import true_mesh
    from studio.fit.frame import fit_frame
    from studio.render import silhouette

    ws = clothing.rendered_session(r["subject"], "tight")
    cameras = finer_cameras(ws.cameras, scale) if scale > 1 else ws.cameras
    model = BodyModel.load(r["sex"])
    with np.load(clothing.bench_root() / r["subject"] / "body.npz") as z:
        rest = anny_correspondence() @ (z["rest_q"].astype(np.float64) * float(z["scale"]))
    shape, rest_rms = model_space_truth(model, rest)
    truth = measure(model, shape)

    def errors(s):
        m = measure(model, s)
        return {k: 1000 * (m[k] - truth[k]) for k in MEASURES}

    fits = load_fits(ws, r["frames"])
    frames, singles, rms = [], [], []
    for f in r["frames"]:
        Vt = true_mesh(ws.path, f)
        _, pose = fit_to_mesh(model, Vt, shape, fits[f].pose, 0, max_nfev=300, keep_tail=True)
        V = model.vertices(shape, pose)
        rms.append(1000 * float(np.sqrt(np.mean(np.sum((V - Vt) ** 2, axis=1)))))
        masks = [silhouette(c, V, model.faces) for c in cameras]
        fit = fit_frame(model, cameras, masks, frame=f)
        singles.append(errors(fit.shape))
        frames.append(BatchFrame(f, cameras, masks, None, fit.pose, fit.shape, fit.gender))
    t = time.perf_counter()
    res = batch_fit(frames, gender=r["sex"], options=BatchOptions(clothing="tight"))
    return {"sex": r["sex"], "mm_per_px": mm_per_pixel(cameras), "rest_rms_mm": 1000 * rest_rms,
            "pose_rms_mm": rms, "batch": errors(res.shape), "single": singles,
            "batch_cost_per_frame": [float(c) for c in res.costs],
            "batch_time_s": time.perf_counter() - t,
            "real": {"batch": {k: r["batch"]["errors_mm"][k] for k in MEASURES},
                     "single": {k: float(np.mean([abs(r["single"][str(f)]["errors_mm"][k]) for f in r["frames"]]))
                                for k in MEASURES}}}


def summarise(out: dict) -> dict:
    """Over the subjects {name: :func:`subject_pixel`}: on the model's masks the batch's and the single fits'
    mean |error| and mean signed error per measurement (mm); on the real masks the mean |error|."""
    def stats(errs):
        e = np.asarray(errs, dtype=np.float64)
        return {"mean_abs": float(np.mean(np.abs(e))), "mean": float(np.mean(e))}

    return {k: {"batch": stats([o["batch"][k] for o in out.values()]),
                "single": stats([s[k] for o in out.values() for s in o["single"]]),
                "real_batch_abs": float(np.mean([abs(o["real"]["batch"][k]) for o in out.values()])),
                "real_single_abs": float(np.mean([o["real"]["single"][k] for o in out.values()]))}
            for k in MEASURES}


def main(argv=None) -> int:
    from rich.progress import track

    from rigs.atomic import atomic_write_json

    ap = clothing.cache_arguments(argparse.ArgumentParser(description=__doc__,
                                                          formatter_class=argparse.RawDescriptionHelpFormatter))
    ap.add_argument("--scale", type=int, default=1, metavar="S",
                    help="cameras with S times as many pixels each way (finer pixels, the same lenses)")
    args = ap.parse_args(argv)
    if args.scale < 1:
        ap.error(f"--scale: expected an integer >= 1, got {args.scale}")
    clothing.select_run(args.cache, args.quick, args.split, args.ledger, args.pixels)
    names = {p["name"] for p in clothing.subjects(args.subjects, args.poses, args.quick)}
    rows = [r for r in clothing.result_rows() if r["condition"] == "tight" and r["subject"] in names]
    if not rows:
        print("no tight results yet: run `clothing.py build` then `clothing.py run`")
        return 1
    out = {r["subject"]: subject_pixel(r, args.scale) for r in track(rows, description="fits on model-rendered masks")}
    short = ("stature", "chest", "waist", "hip")
    print(f"{'tight, error mm':<18} {'mm/px':>5}  {'batch on model masks':>27}  {'single mean |err|':>23}  "
          f"{'real masks: batch':>23}  {'single mean |err|':>23}")
    print(f"{'':<18} {'':>5}  {' / '.join(short):>27}")
    for name, o in out.items():
        single = {k: float(np.mean([abs(s[k]) for s in o["single"]])) for k in MEASURES}
        cells = [o["batch"], single, o["real"]["batch"], o["real"]["single"]]
        print(f"{name + ' ' + o['sex'][0].upper():<18} {o['mm_per_px']:>5.1f}  "
              + "  ".join(f"{' / '.join(f'{c[k]:+.1f}' if i % 2 == 0 else f'{c[k]:.1f}' for k in MEASURES):>27}"
                          for i, c in enumerate(cells)))
    summary = summarise(out)
    print(f"\n{len(out)} subjects, mean |err| (signed) mm; a pixel at the person: "
          f"{np.mean([o['mm_per_px'] for o in out.values()]):.1f} mm")
    print(f"{'':<10} {'model masks: batch':>20} {'single':>16} {'real masks: batch':>18} {'single':>7}")
    for k, v in summary.items():
        print(f"{k.split('_')[0]:<10} {v['batch']['mean_abs']:>11.1f} ({v['batch']['mean']:+5.1f}) "
              f"{v['single']['mean_abs']:>7.1f} ({v['single']['mean']:+5.1f}) {v['real_batch_abs']:>18.1f} "
              f"{v['real_single_abs']:>7.1f}")
    path = clothing.bench_root() / ("pixel.json" if args.scale == 1 else f"pixel_x{args.scale}.json")
    atomic_write_json(path, {"measures": MEASURES, "scale": args.scale, "summary": summary, "per_subject": out})
    print(f"pixel: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
