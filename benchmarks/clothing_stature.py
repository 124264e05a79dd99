"""Where the loose batch body loses stature (issue 15 follow-up): a diagnosis on the dev split.

For each subject × condition of ``benchmarks/clothing.py``'s dev caches (sessions already rendered
and segmented, single-frame fits cached by ``fit_batch_session``), runs the batch with the given
settings (``--variant``: a name and :class:`~studio.fit.batch.BatchOptions` overrides) and writes a
JSON per subject with, per frame, the batch body, the single-frame body and the true body:

- head top and sole heights (max / min z, world metres, floor z = 0) and their errors;
- segment lengths from the joint regressor (thigh, shank, trunk pelvis→neck) and the neck→top
  height of the rest body;
- knee and hip flexion (angle between thigh and shank, trunk and thigh, degrees);
- rest-pose statures of the batch, single-frame and true bodies.

    .venv/bin/python benchmarks/clothing_stature.py run --subjects 0 1 5 6 --conditions loose --variant base
    .venv/bin/python benchmarks/clothing_stature.py table --variant base
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
sys.path.insert(0, str(ROOT / "benchmarks"))

#: joint indices (studio.body.skeleton.PART_NAMES order: the joint of each part with its parent)
PELVIS, HEAD = 0, 2
HIPS, KNEES, ANKLES = (9, 12), (10, 13), (11, 14)
#: variants: BatchOptions overrides
VARIANTS: dict[str, dict] = {"base": {"floor": False}, "release": {"floor": False}, "floor": {"floor": True},
                             "default": {}, "knee": {"knee_weight": 0.05}, "head": {"head_skin": 0.05},
                             "straight": {"straight_knees": 0.05}}


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    c = float(np.dot(a, b) / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-12))
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def body_figures(model, V: np.ndarray, rest: np.ndarray | None = None) -> dict:
    """Heights, segment lengths and flexions of one posed mesh (V, 3) in world metres."""
    J = model.joint_regressor @ V
    neck = J[HEAD]
    out = {"top_z": float(V[:, 2].max()), "sole_z": float(V[:, 2].min()),
           "trunk": float(np.linalg.norm(neck - J[PELVIS])),
           "thigh": float(np.mean([np.linalg.norm(J[k] - J[h]) for h, k in zip(HIPS, KNEES, strict=True)])),
           "shank": float(np.mean([np.linalg.norm(J[a] - J[k]) for k, a in zip(KNEES, ANKLES, strict=True)])),
           "knee_flex": [180.0 - _angle(J[h] - J[k], J[a] - J[k]) for h, k, a in zip(HIPS, KNEES, ANKLES, strict=True)],
           "hip_flex": [_angle(neck - J[PELVIS], J[k] - J[h]) for h, k in zip(HIPS, KNEES, strict=True)]}
    out["hip_flex"] = [180.0 - v for v in out["hip_flex"]]
    if rest is not None:
        Jr = model.joint_regressor @ rest
        out["rest_head"] = float(rest[:, 2].max() - Jr[HEAD, 2])
        out["rest_leg"] = float(np.mean(Jr[list(HIPS), 2]) - rest[:, 2].min())
        out["rest_trunk"] = float(Jr[HEAD, 2] - np.mean(Jr[list(HIPS), 2]))
    return out


def diagnose(ws, batch: dict) -> dict:
    from studio.body import BodyModel, measure
    from studio.fit import load_fits
    from studio.fit.evaluate import surface_distance, true_mesh
    from studio.report.measurements import load_truth

    truth = load_truth(ws.layout)
    bmodel = BodyModel.load(batch["gender"])
    bshape = np.asarray(batch["shape"])
    fits = load_fits(ws, batch["frames"])
    out = {"sex": truth["sex"], "gender": batch["gender"], "true_stature": truth["studio"]["stature"],
           "batch_stature": measure(bmodel, bshape)["stature"], "frames": {},
           "shape": [float(v) for v in bshape], "poses": batch["poses"],
           "batch_rest": body_figures(bmodel, bmodel.vertices(bshape), bmodel.vertices(bshape))}
    for f in batch["frames"]:
        fit = fits[f]
        smodel = BodyModel.load(fit.gender)
        Vt = true_mesh(ws.path, f)
        Vb = bmodel.vertices(bshape, np.asarray(batch["poses"][str(f)]))
        Vs = smodel.vertices(fit.shape, fit.pose)
        out["frames"][str(f)] = {"true": body_figures(bmodel, Vt), "batch": body_figures(bmodel, Vb),
                                 "single": body_figures(smodel, Vs),
                                 "single_rest": body_figures(smodel, smodel.vertices(fit.shape), smodel.vertices(fit.shape)),
                                 "single_stature": measure(smodel, fit.shape)["stature"], "single_status": fit.status,
                                 "cost": batch["costs"][str(f)],
                                 "surface_mm": 1000 * surface_distance(Vb, bmodel.faces, Vt, bmodel.faces)}
    return out


def results_dir(variant: str) -> Path:
    import clothing

    return clothing.bench_root() / "results_stature" / variant


def run(args) -> int:
    import clothing
    from rigs.atomic import atomic_write_json
    from studio.fit.batch import BatchOptions
    from studio.fit.batch_session import fit_batch_session
    from studio.fit.units import fit_code_digest
    from studio.segment import segment_session
    from studio.simulate import ensure_rendered
    from studio.workspace import Workspace

    code = fit_code_digest()
    clothing.RUN.update(name="dev-full", first_seed=clothing.SPLIT_SEEDS["dev"])
    people = clothing.subjects(max(args.subjects) + 1, args.poses, False)
    out_dir = results_dir(args.variant)
    out_dir.mkdir(parents=True, exist_ok=True)
    for i in args.subjects:
        p = people[i]
        for cond in args.conditions:
            path = out_dir / f"{p['name']}_{cond}.json"
            if path.is_file() and json.loads(path.read_text()).get("code") == code:
                continue  # a result of other fitting code is redone, not mixed into the table
            folder = clothing.bench_root() / p["name"] / cond
            t = time.process_time()
            session = ensure_rendered(folder / "spec.yaml", seed=0, cache_dir=folder / "render")
            segment_session(session, workers=1)
            ws = Workspace.open(session)
            options = BatchOptions(clothing=cond, **VARIANTS[args.variant])
            batch = fit_batch_session(ws, n_frames=len(p["poses"]), clothing=cond, gender="auto",
                                      workers=args.workers, chain_length=1, options=options)
            d = diagnose(ws, batch)
            d.update(subject=p["name"], condition=cond, garment=p["garment"], variant=args.variant,
                     batch_wall_s=batch["wall_time"], cpu_s=time.process_time() - t, code=code)
            atomic_write_json(path, d)
            print(f"{p['name']} {cond} {args.variant}: stature {1000 * (d['batch_stature'] - d['true_stature']):+.1f} mm",
                  flush=True)
    return table(args)


def _mm(x: float) -> str:
    return f"{1000 * x:+6.1f}"


def table(args) -> int:
    import clothing

    clothing.RUN.update(name="dev-full", first_seed=clothing.SPLIT_SEEDS["dev"])
    rows = [json.loads(p.read_text()) for p in sorted(results_dir(args.variant).glob("*.json"))]
    print("subject cond sex/g  stat_b stat_s | per frame: top_b sole_b top_s sole_s (mm vs truth), "
          "knee_b/knee_t hip_b/hip_t (deg), thigh shank trunk b-t (mm)")
    for d in rows:
        singles = [v["single_stature"] for v in d["frames"].values()]
        print(f"{d['subject']} {d['condition']:5s} {d['sex'][0]}/{d['gender'][0]} {_mm(d['batch_stature'] - d['true_stature'])} "
              f"{_mm(np.mean(singles) - d['true_stature'])}  rest head/trunk/leg "
              f"{1000 * d['batch_rest']['rest_head']:.0f}/{1000 * d['batch_rest']['rest_trunk']:.0f}/"
              f"{1000 * d['batch_rest']['rest_leg']:.0f}")
        for f, v in d["frames"].items():
            t, b, s = v["true"], v["batch"], v["single"]
            print(f"   f{f} {_mm(b['top_z'] - t['top_z'])} {_mm(b['sole_z'] - t['sole_z'])} {_mm(s['top_z'] - t['top_z'])} "
                  f"{_mm(s['sole_z'] - t['sole_z'])}  knee {np.mean(b['knee_flex']):4.0f}/{np.mean(t['knee_flex']):4.0f} "
                  f"hip {np.mean(b['hip_flex']):4.0f}/{np.mean(t['hip_flex']):4.0f}  "
                  f"{_mm(b['thigh'] - t['thigh'])} {_mm(b['shank'] - t['shank'])} {_mm(b['trunk'] - t['trunk'])}  "
                  f"single {_mm(v['single_stature'] - d['true_stature'])} {v['single_status']} sole_t {_mm(t['sole_z'])}")
    for cond in ("tight", "loose"):
        rs = [d for d in rows if d["condition"] == cond]
        if rs:
            e = np.array([d["batch_stature"] - d["true_stature"] for d in rs]) * 1000
            surf = [np.median([v["surface_mm"] for v in d["frames"].values()]) for d in rs if
                    all("surface_mm" in v for v in d["frames"].values())]
            print(f"{cond}: batch stature mean {e.mean():+.1f} mm, |err| {np.abs(e).mean():.1f} mm over {len(rs)}"
                  + (f"; surface median {np.median(surf):.1f} mm (per subject {', '.join(f'{x:.1f}' for x in surf)})"
                     if surf else ""))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("step", choices=["run", "table"])
    ap.add_argument("--subjects", type=int, nargs="+", default=[0, 1, 5, 6])
    ap.add_argument("--poses", type=int, default=4)
    ap.add_argument("--conditions", nargs="+", default=["loose"], choices=["tight", "loose"])
    ap.add_argument("--variant", default="base", choices=sorted(VARIANTS))
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    return {"run": run, "table": table}[args.step](args)


if __name__ == "__main__":
    sys.exit(main())
