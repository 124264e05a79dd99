"""The model's ceiling on the pose benchmark's dev people: the best our SCAPE model can do.

No silhouettes and no tuning: for every dev frame of ``benchmarks/pose_accuracy.py`` our model
(the true sex) is fitted directly to the true Anny body in 3-D — pose (30) and the first ``k``
shape coefficients minimising the vertex residuals to the true mesh mapped into our topology
(:func:`studio.fit.evaluate.true_mesh`, the correspondence the model was learned with; box
bounds: the pose limits, shape within ±4 σ), started from the benchmark's own fit of the frame and
from the library posture of the frame's true family (and its mirror image) at the true heading,
the lowest vertex residual kept (a local optimum: an upper bound of the model's error).
Each ceiling body is then measured exactly as the benchmark measures a fit: mean surface distance
to the true mesh, silhouette precision / recall against the simulator's true person labels in
the session's cameras (:func:`studio.render.silhouette`), stature of the fitted shape.

Also measured, to locate the silhouette misses:

* ``anny``: the true Anny mesh (its own faces) through our projection and rasteriser against the
  true labels — a projection or half-pixel convention mismatch would show here (1.0 / 1.0 when
  there is none; a seated frame's precision < 1 where the stool hides the body);
* ``topology``: the true mesh mapped into our topology (what a perfect fit of our mesh gives);
* ``segmentation``: the masks the fitter sees, against the true labels;
* per body part, the share of the ceiling's missed (true, not drawn) and extra (drawn, not
  true) pixels, by the part of the true / fitted mesh seen at that pixel;
* the fit's own cost (eq. 4.6 at full resolution on the segmented masks, a seated body's stool
  left out) at the ceiling body and at the benchmark's fit of the frame — lower at the ceiling
  means the search stopped short of a better body the cost already prefers;
* ``polished``: the fit's last Nelder–Mead stage run from the ceiling body (where the cost's own
  minimum near the truth lies).

    .venv/bin/python benchmarks/pose_ceiling.py [--shape 10 30] [--people 0 1 ...]

Writes ``benchmarks/results/pose_ceiling.json`` (dev figures: the reference for how far the
silhouette fit can go, not a tuned result).
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

#: part groups of the miss breakdown (PART_NAMES prefixes)
GROUPS = {"head": ("head",), "torso": ("pelvis", "torso"), "arms": ("upperarm", "lowerarm"), "hands": ("hand",),
          "legs": ("upperleg", "lowerleg"), "feet": ("foot",)}


def fit_to_mesh(model, target: np.ndarray, shape0: np.ndarray, pose0: np.ndarray, k: int,
                max_nfev: int = 60, keep_tail: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Pose (30,) and shape (first ``k`` coefficients free, the rest 0 — or ``shape0``'s with
    ``keep_tail``: ``k`` = 0 then poses the body of ``shape0``) minimising Σ‖V(β, θ) − target‖²
    over the vertices (eq. 3.23 bodies; trust-region least squares with a finite-difference
    Jacobian computed as one batch of bodies)."""
    from scipy.optimize import least_squares

    n = model.pose_size
    lo = np.concatenate([model.pose_limits[:, 0], -4 * np.sqrt(model.eigenvalues[:k])])
    hi = np.concatenate([model.pose_limits[:, 1], 4 * np.sqrt(model.eigenvalues[:k])])
    x0 = np.clip(np.concatenate([pose0, shape0[:k]]), lo + 1e-9, hi - 1e-9)
    tail = np.asarray(shape0, dtype=np.float64)[k:] if keep_tail else np.zeros(model.n_shape - k)

    def bodies(X):
        S = np.concatenate([X[:, n:], np.broadcast_to(tail, (len(X), len(tail)))], axis=1)
        return model.vertices_batch(S, X[:, :n], free_shape=k)

    def res(x):
        return (bodies(x[None])[0] - target).ravel()

    def jac(x):
        h = np.where(np.arange(len(x)) < 3, 1e-5, 1e-4)  # metres / radians / shape units
        h = np.where(x + h > hi, -h, h)
        X = np.concatenate([x[None], x[None] + np.diag(h)])
        V = bodies(X).reshape(len(X), -1)
        return ((V[1:] - V[0]) / h[:, None]).T

    r = least_squares(res, x0, jac=jac, bounds=(lo, hi), x_scale="jac", max_nfev=max_nfev, xtol=1e-6, ftol=1e-7)
    shape = np.concatenate([r.x[n:], tail])
    return shape, r.x[:n]


def part_breakdown(model, cameras, V_true, V_fit, masks_fit, masks_true) -> dict:
    """Share of missed / extra pixels per part group, parts read off the true / fitted mesh."""
    from studio.render import rasterize

    part_of = {}
    for g, prefixes in GROUPS.items():
        for i, name in enumerate(model.part_names):
            if name.startswith(prefixes):
                part_of[i] = g
    counts = {"missed": dict.fromkeys(GROUPS, 0), "extra": dict.fromkeys(GROUPS, 0)}
    counts["missed"]["none"] = counts["extra"]["none"] = 0
    for cam, mf, mt in zip(cameras, masks_fit, masks_true, strict=True):
        for kind, V, sel in (("missed", V_true, mt & ~mf), ("extra", V_fit, mf & ~mt)):
            ras = rasterize(cam, V, model.faces)
            face = ras.face[sel]
            hit = face >= 0
            counts[kind]["none"] += int((~hit).sum())
            parts = model.face_parts[face[hit]]
            for i, g in part_of.items():
                counts[kind][g] += int((parts == i).sum())
    return counts


def silhouette_objective(model, cameras, masks, shape: np.ndarray, n_free: int = 10, ignore=None):
    """The fit's own full-resolution objective (eq. 4.6 with its priors) on the observed masks,
    the shape's first ``n_free`` coefficients free (the rest held at ``shape``'s); ``ignore``: a
    seat's don't-care pixels per view (:func:`studio.fit.props.find_support`), as the fit has them."""
    from studio.fit import FitOptions
    from studio.fit.frame import build_targets
    from studio.fit.objective import FrameObjective

    targets = build_targets(masks, [c.name for c in cameras], FitOptions(levels=(0, 0, 0)), ignore=ignore)
    return FrameObjective(model, cameras, targets, shape, n_free)


def polish(obj, shape: np.ndarray, pose: np.ndarray, evaluations: int = 900) -> tuple[np.ndarray, np.ndarray]:
    """The fit's last stage (root + shape + trunk and upper limbs, Nelder–Mead at full
    resolution, :func:`studio.fit.frame.fit_frame`) started from ``shape``, ``pose``."""
    from studio.body.skeleton import POSE_SIZE
    from studio.fit.objective import pose_bounds
    from studio.fit.search import _part_groups
    from studio.optimize import Stage, staged_nelder_mead

    model = obj.model
    sig = np.sqrt(model.eigenvalues[: obj.n_shape_free])
    lo, hi = pose_bounds(model, pose[:2])
    blo, bhi = np.concatenate([lo, -3 * sig]), np.concatenate([hi, 3 * sig])
    idx = tuple(range(6)) + tuple(range(POSE_SIZE, obj.size)) + tuple(_part_groups()[0])
    step = np.concatenate([np.full(POSE_SIZE, 0.04), 0.25 * sig])
    step[:3] = 0.015
    x0 = np.clip(obj.pack(shape, pose), blo, bhi)
    r = staged_nelder_mead(obj.scalar(0), x0, [Stage(idx, evaluations, "final")], bounds=(blo, bhi), step=step,
                           adaptive=True)
    shapes, poses = obj.split(r.x[None])
    return shapes[0], model.clip_pose(poses[0])


def measure_frame(session: Path, frame: int, start: dict | None, ks: tuple[int, ...]) -> dict:
    from studio.body import BodyModel, measure
    from studio.fit.evaluate import silhouette_agreement, surface_distance, true_mesh, true_person_masks
    from studio.fit.props import find_support
    from studio.render import silhouette
    from studio.report.measurements import load_truth
    from studio.workspace import Workspace

    ws = Workspace.open(session)
    truth = load_truth(ws.layout)
    model = BodyModel.load(truth["sex"])
    Vt = true_mesh(ws.path, frame)
    tm = true_person_masks(ws.path, frame, ws.cameras)
    out = {"frame": frame}
    with np.load(ws.layout.truth_body(frame)) as z:
        anny = z["vertices"].astype(np.float64)
    body_npz = ws.layout.truth_dir / "scene.json"
    faces = _anny_faces(json.loads(body_npz.read_text()))
    pr = lambda masks: [round(v, 4) for v in silhouette_agreement(masks, tm)]  # noqa: E731
    out["anny"] = pr([silhouette(c, anny, faces) for c in ws.cameras])
    topo = [silhouette(c, Vt, model.faces) for c in ws.cameras]
    out["topology"] = pr(topo)
    out["segmentation"] = pr([m > 0 for m in ws.person_masks(frame)])
    out["family_seen"] = family = _family(ws, frame)
    starts = family_starts(model, ws.path, frame, Vt, family)
    if start is not None:
        starts.insert(0, (np.asarray(start["shape"]), model.clip_pose(np.asarray(start["pose"]))))
    prev = None
    for k in ks:
        t = time.process_time()
        best = None
        for s0, p0 in (starts if prev is None else [prev]):  # the next k from the last one's answer
            shape, pose = fit_to_mesh(model, Vt, s0, p0, k)
            rms = float(np.sqrt(((model.vertices(shape, pose) - Vt) ** 2).sum(axis=1).mean()))
            if best is None or rms < best[0]:
                best = (rms, shape, pose)
        _, shape, pose = best
        prev = (shape, pose)
        V = model.vertices(shape, pose)
        masks = [silhouette(c, V, model.faces) for c in ws.cameras]
        out[f"k{k}"] = {
            "surface_mm": 1000 * surface_distance(V, model.faces, Vt, model.faces),
            "vertex_rms_mm": 1000 * float(np.sqrt(((V - Vt) ** 2).sum(axis=1).mean())),
            "part_rms_mm": {n: round(1000 * float(np.sqrt(((V - Vt)[model.parts == i] ** 2).sum(axis=1).mean())), 1)
                            for i, n in enumerate(model.part_names)},
            "pr": pr(masks), "stature_error_mm": 1000 * (measure(model, shape)["stature"] - truth["studio"]["stature"]),
            "parts": part_breakdown(model, ws.cameras, Vt, V, masks, tm), "cpu_s": time.process_time() - t,
            "pose": pose.tolist(), "shape": shape.tolist(),
        }
    # the fit's own cost at the ceiling body and at the benchmark's fit (lower at the ceiling:
    # the search missed it; higher: the cost prefers a body farther from the truth), then the
    # fit's last stage run from the ceiling body (where the cost's own minimum near the truth lies);
    # a seated body's stool left out as the fit leaves it out
    seg = [m > 0 for m in ws.person_masks(frame)]
    shape, pose = np.asarray(out[f"k{ks[0]}"]["shape"]), np.asarray(out[f"k{ks[0]}"]["pose"])
    support = find_support(model, ws.cameras, seg, shape, pose)  # a stool under a seated body
    ignore = None if support is None else support.ignore
    obj = silhouette_objective(model, ws.cameras, seg, shape, ignore=ignore)

    def cost(s, p):  # of the whole shape (a fit's coefficients past the 10th are not zero)
        o = silhouette_objective(model, ws.cameras, seg, s, 0, ignore=ignore)
        return float(o(o.pack(s, p)[None], 0)[0])

    out["cost_ceiling"] = cost(shape, pose)
    if start is not None:
        out["cost_fit"] = cost(np.asarray(start["shape"]), model.clip_pose(np.asarray(start["pose"])))
    t = time.process_time()
    ps, pp = polish(obj, shape, pose)
    V = model.vertices(ps, pp)
    out["polished"] = {"surface_mm": 1000 * surface_distance(V, model.faces, Vt, model.faces),
                       "pr": pr([silhouette(c, V, model.faces) for c in ws.cameras]), "cost": cost(ps, pp),
                       "stature_error_mm": 1000 * (measure(model, ps)["stature"] - truth["studio"]["stature"]),
                       "cpu_s": time.process_time() - t}
    return out


def _family(ws, frame: int) -> str:
    with np.load(ws.layout.truth_body(frame)) as z:
        return str(z["pose_names"])


def family_starts(model, session, frame: int, Vt: np.ndarray, family: str) -> list:
    """Starts of the 3-D fit besides the benchmark's fit: the library posture of the frame's
    true family (and its mirror image) turned to the true heading, on the mean shape, its pelvis
    on the true one."""
    from studio.fit.library import FAMILIES, _mirror, family_pose
    from studio.workspace import Layout

    if family not in FAMILIES:
        return []
    with np.load(Layout(session).truth_body(frame)) as z:
        yaw = float(z["yaw"])
    out = []
    for pose in (family_pose(model, family), _mirror(family_pose(model, family))):
        pose[3:6] = [0.0, 0.0, yaw]
        V = model.vertices(model.mean_shape(), pose)
        pelvis = model.parts == 0
        pose[:3] += Vt[pelvis].mean(axis=0) - V[pelvis].mean(axis=0)
        out.append((model.mean_shape(), model.clip_pose(pose)))
    return out


def _anny_faces(scene: dict) -> np.ndarray:
    """Faces of the Anny mesh a session was rendered from (its spec's body file)."""
    spec = scene["spec"]
    from studio.simulate.samples import cache_root

    root = cache_root() / "bench" / "pose_accuracy" / "dev"
    name = spec["name"].removeprefix("bench_dev_")
    with np.load(root / name / spec["body"], allow_pickle=True) as z:
        return np.asarray(z["faces"], np.int64)


def main(argv=None) -> int:
    import pose_accuracy as pa
    from rigs.atomic import atomic_write_json
    from studio.simulate.samples import cache_root

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--shape", type=int, nargs="+", default=[10, 30], help="free shape coefficients")
    ap.add_argument("--people", type=int, nargs="*", default=None)
    ap.add_argument("--starts", nargs="+", default=["arm-states", "arm-v3", "full"], help="dev result variants to start from")
    args = ap.parse_args(argv)
    root = pa.bench_root("dev")
    rows = []
    for p in pa.people(10, 4, "dev"):
        i = int(p["name"][-3:])
        session = cache_root() / "renders" / p["render"] / "seed0"
        if (args.people is not None and i not in args.people) or not session.is_dir():
            continue
        for f, fam in enumerate(p["poses"]):
            start = next((json.loads(q.read_text()) for v in args.starts
                          if (q := root / "results" / v / f"{p['name']}_{f}.json").is_file()), None)
            r = {"person": p["name"], "family": fam, **measure_frame(session, f, start, tuple(args.shape))}
            if start is not None:
                r["benchmark"] = {"surface_mm": start["surface_mm"], "pr": [start["precision"], start["recall"]],
                                  "stature_error_mm": start["stature_error_mm"]}
            rows.append(r)
            print(_line(r, args.shape), flush=True)
    summary = _summary(rows, args.shape)
    print(_table(summary, args.shape))
    out = ROOT / "benchmarks" / "results" / "pose_ceiling.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_json(out, {"benchmark": "pose_ceiling", "split": "dev", "summary": summary, "frames": rows})
    print(f"wrote {out}")
    return 0


def _line(r: dict, ks) -> str:
    s = f"{r['person']} {r['frame']} {r['family']:14s} anny {r['anny']} topo {r['topology']} seg {r['segmentation']}"
    for k in ks:
        c = r[f"k{k}"]
        s += f" | k{k}: {c['surface_mm']:.1f} mm P/R {c['pr']} stat {c['stature_error_mm']:+.0f}"
    if "benchmark" in r:
        b = r["benchmark"]
        s += f" | fit {b['surface_mm']:.1f} mm P/R {[round(v, 3) for v in b['pr']]} stat {b['stature_error_mm']:+.0f}"
    return s


def _summary(rows: list[dict], ks) -> dict:
    out = {}
    for fam in sorted({r["family"] for r in rows}) + ["all"]:
        rs = [r for r in rows if fam in ("all", r["family"])]
        d = {"frames": len(rs)}
        for key in ("anny", "topology", "segmentation"):
            d[key] = np.mean([r[key] for r in rs], axis=0).round(4).tolist()
        for k in ks:
            c = [r[f"k{k}"] for r in rs]
            d[f"k{k}"] = {"surface_median_mm": float(np.median([x["surface_mm"] for x in c])),
                          "surface_worst_mm": float(np.max([x["surface_mm"] for x in c])),
                          "pr": np.mean([x["pr"] for x in c], axis=0).round(4).tolist(),
                          "stature_error_median_mm": float(np.median([x["stature_error_mm"] for x in c]))}
            miss = {kind: {g: sum(x["parts"][kind][g] for x in c) for g in c[0]["parts"][kind]}
                    for kind in ("missed", "extra")}
            d[f"k{k}"]["parts"] = {kind: {g: round(v / max(sum(m.values()), 1), 3) for g, v in m.items()}
                                   for kind, m in miss.items()}
        pol = [r["polished"] for r in rs]
        d["polished"] = {"surface_median_mm": float(np.median([x["surface_mm"] for x in pol])),
                         "surface_worst_mm": float(np.max([x["surface_mm"] for x in pol])),
                         "pr": np.mean([x["pr"] for x in pol], axis=0).round(4).tolist(),
                         "stature_error_median_mm": float(np.median([x["stature_error_mm"] for x in pol]))}
        b = [r["benchmark"] for r in rs if "benchmark" in r]
        if b:
            d["benchmark"] = {"surface_median_mm": float(np.median([x["surface_mm"] for x in b])),
                              "surface_worst_mm": float(np.max([x["surface_mm"] for x in b])),
                              "pr": np.mean([x["pr"] for x in b], axis=0).round(4).tolist(),
                              "stature_error_median_mm": float(np.median([x["stature_error_mm"] for x in b]))}
            d["cost_lower_at_ceiling"] = int(sum(r["cost_ceiling"] < r["cost_fit"] for r in rs if "cost_fit" in r))
        out[fam] = d
    return out


def _table(summary: dict, ks) -> str:
    def fig(c):
        return (f"{c['surface_median_mm']:4.1f}/{c['surface_worst_mm']:4.1f} mm {c['pr'][0]:.3f}/{c['pr'][1]:.3f}"
                f" {c['stature_error_median_mm']:+4.0f}")

    cols = [f"k{k}" for k in ks] + ["polished", "benchmark"]
    lines = [f"{'family':14s} {'n':>2s} {'anny P/R':>11s} {'topo P/R':>11s} {'seg P/R':>11s} | "
             + " | ".join(f"{c}: surf med/max, P/R, stature" for c in cols) + " | cost lower at ceiling"]
    for fam, d in summary.items():
        row = f"{fam:14s} {d['frames']:2d} " + " ".join(f"{d[key][0]:.3f}/{d[key][1]:.3f}" for key in
                                                       ("anny", "topology", "segmentation"))
        row += " | " + " | ".join(fig(d[c]) if c in d else "-" for c in cols)
        row += f" | {d.get('cost_lower_at_ceiling', '-')}/{d['frames']}"
        lines.append(row)
    for k in ks:
        lines.append(f"k{k} misses by part (share of missed / extra pixels): {summary['all'][f'k{k}']['parts']}")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
