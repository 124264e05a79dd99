"""Benchmark of the SCAPE body model learned from Anny (thesis ch. 3, fig. 3.10).

Runs on the shipped model plus the held-out sets the build writes to its scratch folder
(``studio model build --scratch DIR``; default ``$STUDIO_BODY_SCRATCH`` or
``~/.cache/studio/body-scratch``). Anchors:

- generalisation: mean vertex error on held-out Anny adults vs number of components
  (thesis fig. 3.9 shows 6–20 components; TenBo reports ~3.7 mm); target ≤ 5 mm at 20;
- pose: mean vertex error vs Anny's own posing of the reference body in held-out poses,
  rigid parts (Q = I, thesis fig. 3.8c) vs the regressed Q;
- measurements vs Anny's anthropometry on held-out bodies: stature within 5 mm, mass 2 %;
- population statistics vs ANSUR II;
- speed: one body ≤ 2 ms, 64 bodies ≤ 60 ms, load ≤ 0.5 s.

Writes ``benchmarks/results/body_model.json`` and pictures into ``benchmarks/results/``.
"""

from __future__ import annotations

import csv
import json
import os
import sys
import time
from pathlib import Path

# single-threaded BLAS: on a shared, loaded machine threads only add contention (reported)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from studio.body import GENDERS, MEASUREMENT_NAMES, PART_NAMES, BodyModel, measure, mesh_volume  # noqa: E402
from studio.body import model as model_mod  # noqa: E402

ROOT = Path(__file__).resolve().parent
RESULTS = ROOT / "results"
SCRATCH = Path(os.environ.get("STUDIO_BODY_SCRATCH", Path.home() / ".cache" / "studio" / "body-scratch"))
ANSUR = Path(os.environ.get("STUDIO_ANSUR", ROOT.parent.parent / "shared/data/anthropometry/ansur2"))


def project(model: BodyModel, Y: np.ndarray, k: int) -> np.ndarray:
    """Shape coefficients (N, n_shape) of rest bodies Y (N, V, 3), keeping the first k."""
    beta = model.shape_from_vertices(Y)
    beta[:, k:] = 0.0
    return beta


def aligned_error(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Mean vertex distance (per body) after the optimal translation."""
    d = A - B
    d = d - d.mean(axis=-2, keepdims=True)
    return np.linalg.norm(d, axis=-1).mean(axis=-1)


def rigid_error(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Mean vertex distance (per body) after the optimal rotation and translation of A onto B
    (what a fit's free root can absorb)."""
    from studio.body.scape import procrustes_rotation

    R = procrustes_rotation(A, B)
    a = (A - A.mean(axis=-2, keepdims=True)) @ np.swapaxes(R, -1, -2)
    return np.linalg.norm(a + B.mean(axis=-2, keepdims=True) - B, axis=-1).mean(axis=-1)


def generalisation(results: dict) -> None:
    table = {}
    for g in GENDERS:
        m = BodyModel.load(g)
        z = np.load(SCRATCH / f"heldout_{g}.npz")
        Y = z["vertices"].astype(np.float64)
        row = {}
        for k in (1, 2, 4, 6, 10, 15, 20, 25, m.n_shape):
            beta = project(m, Y, k)
            rec = m.rest_vertices_batch(beta)
            row[k] = float(aligned_error(rec, Y).mean() * 1000)
        # floor: least-squares reconstruction from the exact D (no PCA truncation)
        table[g] = row
    results["generalisation_mm"] = table
    print("\nGeneralisation: mean vertex error (mm) on 100 held-out Anny adults per population")
    ks = list(table["male"].keys())
    print("  comps " + " ".join(f"{k:>6d}" for k in ks))
    for g, row in table.items():
        print(f"  {g:8s}" + " ".join(f"{row[k]:6.2f}" for k in ks))
    print("  anchor: TenBo ~3.7 mm; target <= 5 mm at 20 components")


def pose_error(results: dict) -> None:
    """The reference body (the template, D = I) in the build's held-out poses, near rest and
    across each joint's whole range (``wide_``), against Anny's skinning: Q = I vs the regressed Q."""
    z = np.load(SCRATCH / "heldout_poses.npz")
    neutral = BodyModel.load("neutral")
    F = len(neutral.faces)
    # the reference body is the template itself: D = I exactly, so only pose error remains
    ref = BodyModel(
        gender="reference", template=neutral.template, faces=neutral.faces, parts=neutral.parts,
        face_parts=neutral.face_parts, D_mean=np.tile(np.eye(3).ravel(), F),
        D_basis=np.zeros((1, F * 9)), eigenvalues=np.ones(1), hinge_axes=neutral.hinge_axes,
        pose_limits=neutral.pose_limits, joint_regressor=neutral.joint_regressor,
        joint_pairs=neutral.joint_pairs, Q_coef=neutral.Q_coef,
    )
    J = ref.joint_regressor @ ref.template
    near = np.min(np.linalg.norm(ref.template[:, None] - J[None], axis=-1), axis=1) < 0.08
    for key, label in (("", "pose_mm"), ("wide_", "wide_pose_mm")):
        if key + "poses" not in z.files:
            continue
        truth = z[key + "vertices"].astype(np.float64)
        poses = z[key + "poses"]
        s = np.zeros((len(poses), 1))
        out = {}
        for name, use_q in (("rigid_Q=I", False), ("with_Q", True)):
            V = ref.vertices_batch(s, poses, use_q=use_q)
            err = aligned_error(V, truth)
            # error near the joints (vertices within 8 cm of a rest joint centre)
            d = V - truth
            d = d - d.mean(axis=1, keepdims=True)
            near_err = np.linalg.norm(d[:, near], axis=-1).mean()
            out[name] = {"mean_mm": float(err.mean() * 1000), "max_body_mm": float(err.max() * 1000),
                         "near_joints_mm": float(near_err * 1000)}
        rest = aligned_error(np.broadcast_to(ref.template, truth.shape), truth)
        out["unposed_template_mm"] = float(rest.mean() * 1000)
        out["n_poses"] = int(len(poses))
        results[label] = out
        print(f"\nPose: mean vertex error vs Anny's skinning, {len(poses)} held-out {key or 'near-rest '}poses"
              " of the reference body")
        for k, v in out.items():
            print(f"  {k:22s} {v}")


def lab_postures(results: dict) -> None:
    """The pose library's families (what a lab records: seated, arms overhead, half squat, ...) on
    4 + 4 held-out adults at the true pose, model vs Anny's posing of the same person (shape
    fitted at rest, no alignment): with the regressed Q, the search body's
    (:meth:`studio.body.BodyModel.search_model`) and rigid (Q = I)."""
    if "--no-anny" in sys.argv:
        return
    try:
        from studio.body.anny_adapter import anny_truth_meshes
    except ImportError:
        return
    from studio.fit.library import pose_library

    errs: dict[str, dict[str, list]] = {"with_Q": {}, "with_Q_root_aligned": {}, "search_body": {}, "rigid_Q=I": {}}
    for g in ("male", "female"):
        m = BodyModel.load(g)
        phen = np.load(SCRATCH / f"heldout_{g}.npz")["phenotypes"][:4]
        P, names = pose_library(m, variants=2)
        P, names = P[::2], names[::2]  # without the mirror twins
        beta = m.shape_from_vertices(anny_truth_meshes(phen, np.zeros((len(phen), P.shape[1])))["vertices"])
        for i in range(len(phen)):
            truth = anny_truth_meshes(np.repeat(phen[i : i + 1], len(P), 0), P)["vertices"]
            for name, body, use_q in (("with_Q", m, True), ("search_body", m.search_model(), True), ("rigid_Q=I", m, False)):
                V = body.vertices_batch(np.repeat(beta[i : i + 1], len(P), 0), P, use_q=use_q)
                for fam, e in zip(names, np.linalg.norm(V - truth, axis=-1).mean(axis=1)):
                    errs[name].setdefault(fam, []).append(float(e * 1000))
                if name == "with_Q":
                    for fam, e in zip(names, rigid_error(V, truth)):
                        errs["with_Q_root_aligned"].setdefault(fam, []).append(float(e * 1000))
    out = {k: {fam: float(np.mean(v)) for fam, v in d.items()} for k, d in errs.items()}
    for k in out:
        out[k]["mean"] = float(np.mean(list(out[k].values())))
    results["lab_postures_mm"] = out
    print("\nLab postures: mean vertex error (mm) vs Anny at the true pose, 8 held-out adults (placed by the"
          " pelvis; root-aligned: after the rotation and translation that fit it best)")
    for fam in out["with_Q"]:
        print(f"  {fam:16s} {out['with_Q'][fam]:6.2f}   (root-aligned {out['with_Q_root_aligned'][fam]:6.2f}, "
              f"search body {out['search_body'][fam]:6.2f}, rigid {out['rigid_Q=I'][fam]:6.2f})")


def posed_truth(results: dict) -> None:
    """End to end: held-out phenotypes posed by Anny (truth) vs the model (shape fitted at rest)."""
    if "--no-anny" in sys.argv:
        return
    try:
        from studio.body.build import anny_truth_meshes, sample_poses
    except ImportError:
        return
    out = {}
    rng = np.random.default_rng(7)
    for g in GENDERS:
        m = BodyModel.load(g)
        z = np.load(SCRATCH / f"heldout_{g}.npz")
        phen = z["phenotypes"][:8]
        # unseen poses from the pose distribution of the build (new seed)
        P = sample_poses(len(phen), m.pose_limits, rng)
        P[0, 6:] = 0.0
        rest = anny_truth_meshes(phen, np.zeros_like(P))
        truth = anny_truth_meshes(phen, P)
        beta = m.shape_from_vertices(rest["vertices"])
        V = m.vertices_batch(beta, P)
        err = np.linalg.norm(V - truth["vertices"], axis=-1).mean(axis=1)
        jerr = np.linalg.norm(m.joints_batch(beta, P) - truth["joints"], axis=-1).mean(axis=1)
        out[g] = {"vertex_mm_mean": float(err.mean() * 1000), "joint_mm_mean": float(jerr.mean() * 1000),
                  "n": int(len(phen)), "note": "no alignment: same placement convention"}
        print(f"  {g:8s} {out[g]}")
    results["posed_truth_vs_anny"] = out


def measurements_vs_anny(results: dict) -> None:
    out = {}
    print("\nMeasurements vs Anny's anthropometry on held-out bodies (model fit = all components)")
    for g in GENDERS:
        m = BodyModel.load(g)
        z = np.load(SCRATCH / f"heldout_{g}.npz")
        Y = z["vertices"].astype(np.float64)
        n = min(40, len(Y))
        beta = project(m, Y[:n], m.n_shape)
        meas = [measure(m, b) for b in beta]
        st = np.array([x["stature"] for x in meas])
        ms = np.array([x["mass"] for x in meas])
        st_ref = z["anny_vertices_height"][:n]
        ms_ref = z["anny_mass"][:n]
        dec_vol = mesh_volume(Y[:n], m.faces)
        out[g] = {
            "stature_mean_abs_err_mm": float(np.abs(st - st_ref).mean() * 1000),
            "stature_max_abs_err_mm": float(np.abs(st - st_ref).max() * 1000),
            "mass_mean_abs_err_pct": float((np.abs(ms - ms_ref) / ms_ref).mean() * 100),
            "mass_bias_pct": float(((ms - ms_ref) / ms_ref).mean() * 100),
            "decimated_mesh_volume_bias_pct": float(((dec_vol - z["anny_volume"][:n]) / z["anny_volume"][:n]).mean() * 100),
            "n": n,
        }
        print(f"  {g:8s} {out[g]}")
    print("  targets: stature within 5 mm, mass within 2 %")
    results["measurements_vs_anny"] = out


def ansur(results: dict) -> None:
    cols = {
        "stature": ("stature", 1e-3), "arm_span": ("span", 1e-3), "shoulder_breadth": ("bideltoidbreadth", 1e-3),
        "chest_circumference": ("chestcircumference", 1e-3), "waist_circumference": ("waistcircumference", 1e-3),
        "hip_circumference": ("buttockcircumference", 1e-3), "inseam": ("crotchheight", 1e-3), "mass": ("weightkg", 0.1),
    }
    out = {}
    print("\nPopulation (prior samples shipped with the model) vs ANSUR II: mean ± sd")
    for g, fname in (("male", "ANSUR_II_MALE_Public.csv"), ("female", "ANSUR_II_FEMALE_Public.csv")):
        path = ANSUR / fname
        if not path.is_file():
            print(f"  ANSUR file {path} missing: skipped")
            return
        with open(path, encoding="latin-1") as fh:
            rows = list(csv.DictReader(fh))
        m = BodyModel.load(g)
        if m.measurement_samples is None:
            return
        vals = m.measurement_samples[1].astype(np.float64)
        out[g] = {}
        for k, (col, scale) in cols.items():
            a = np.array([float(r[col]) for r in rows]) * scale
            ours = vals[:, MEASUREMENT_NAMES.index(k)]
            out[g][k] = {"model": [float(ours.mean()), float(ours.std())], "ansur": [float(a.mean()), float(a.std())]}
            print(f"  {g:6s} {k:20s} model {ours.mean():7.3f} ± {ours.std():6.3f}   ANSUR {a.mean():7.3f} ± {a.std():6.3f}")
    results["ansur"] = out


def speed(results: dict) -> None:
    model_mod._CACHE.clear()
    t = time.perf_counter()
    m = BodyModel.load("male")
    t_load = time.perf_counter() - t
    s = m.sample_shapes(64, 0)
    rng = np.random.default_rng(1)
    lim = m.pose_limits
    P = np.zeros((64, m.pose_size))
    P[:, 6:] = lim[6:, 0] + rng.uniform(0.35, 0.65, (64, 24)) * (lim[6:, 1] - lim[6:, 0])

    def best(f, n):
        ts = []
        for _ in range(n):
            t0 = time.perf_counter()
            f()
            ts.append(time.perf_counter() - t0)
        return float(np.median(ts))

    t1 = best(lambda: m.vertices(s[0], P[0]), 30)  # pose change, same shape (fitting)
    k = iter(range(10**6))
    t1_new = best(lambda: m.vertices(s[next(k) % 64], P[0]), 30)  # a new shape each call
    t64 = best(lambda: m.vertices_batch(s, P), 7)
    tj = best(lambda: m.joints_batch(s, P), 10)
    t_anny = anny_speed()
    results["speed"] = {"anny_torch_batch64_ms": t_anny, "blas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
                        "load_s": t_load, "single_ms": t1 * 1000, "single_new_shape_ms": t1_new * 1000, "batch64_ms": t64 * 1000,
                        "joints64_ms": tj * 1000, "cpu_count": os.cpu_count(),
                        "loadavg": list(os.getloadavg())}
    print(f"\nSpeed (median; machine load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    print(f"  load {t_load:.3f} s (target 0.5) | one body {t1 * 1000:.2f} ms (new shape {t1_new * 1000:.2f}; target 2) | "
          f"64 bodies {t64 * 1000:.1f} ms (target 60) | 64 joint sets {tj * 1000:.2f} ms")
    if t_anny is not None:
        print(f"  Anny + torch on this machine now: 64 posed bodies {t_anny:.1f} ms")


def anny_speed() -> float | None:
    """Anny's own forward pass for 64 bodies (rest + skinning) on this machine, if installed."""
    if "--no-anny" in sys.argv:
        return None
    try:
        import anny
        import torch
    except ImportError:
        return None
    os.environ.setdefault("ANNY_CACHE_DIR", str(Path.home() / ".cache" / "anny"))
    torch.set_grad_enabled(False)
    m = anny.Anny(topology="anny-noeyes-notongue", local_changes="all")  # the build's (cached) config
    ph = {k: torch.rand(64, dtype=m.dtype) * 0.4 + 0.3 for k in m.phenotype_labels}
    m(phenotype_kwargs=ph)
    ts = []
    for _ in range(5):
        t0 = time.perf_counter()
        m(phenotype_kwargs=ph)
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts) * 1000)


# ----------------------------------------------------------------------------- pictures
PART_COLORS = np.array([
    [0.55, 0.35, 0.65], [0.35, 0.55, 0.8], [0.95, 0.75, 0.55], [0.9, 0.4, 0.35], [0.95, 0.6, 0.3],
    [0.95, 0.85, 0.4], [0.35, 0.75, 0.45], [0.45, 0.85, 0.65], [0.75, 0.9, 0.5], [0.85, 0.35, 0.55],
    [0.95, 0.55, 0.7], [0.7, 0.5, 0.4], [0.3, 0.6, 0.6], [0.4, 0.75, 0.8], [0.5, 0.5, 0.75],
])


def draw(ax, v, f, colors=None, view=(0.0, 1.0, 0.0)):
    """Flat-shaded orthographic view looking along ``view`` (painter's algorithm); the body faces -y."""
    from matplotlib.collections import PolyCollection

    d = np.asarray(view, float)
    d /= np.linalg.norm(d)
    right = np.cross(d, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, d)
    tri = v[f]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-12
    vis = n @ -d > 0
    depth = (tri.mean(axis=1) @ d)
    order = np.argsort(-depth)
    order = order[vis[order]]
    xy = np.stack([tri @ right, tri @ up], axis=-1)[order]
    light = np.clip(0.25 + 0.75 * (n[order] @ (-d + 0.4 * up + 0.3 * right)) / np.linalg.norm(-d + 0.4 * up + 0.3 * right), 0.15, 1.0)
    base = np.full((len(f), 3), 0.8) if colors is None else colors
    fc = base[order] * light[:, None]
    ax.add_collection(PolyCollection(xy, facecolors=fc, edgecolors=fc, linewidths=0.3))
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.axis("off")


def pictures(results: dict) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    fig, axes = plt.subplots(2, 7, figsize=(14, 5.2))
    for r, g in enumerate(("male", "female")):
        m = BodyModel.load(g)
        cols = [("mean", np.zeros(m.n_shape))]
        for c in range(3):
            for sgn in (-3, 3):
                s = np.zeros(m.n_shape)
                s[c] = sgn * np.sqrt(m.eigenvalues[c])
                cols.append((f"PC{c + 1} {'+' if sgn > 0 else '-'}3σ", s))
        for i, (title, s) in enumerate(cols):
            ax = axes[r, i]
            draw(ax, m.vertices(s), m.faces, view=(-0.3, 1.0, 0.0))
            ax.set_xlim(-0.7, 0.7)
            ax.set_ylim(-0.05, 2.05)
            ax.set_title(f"{g} {title}", fontsize=8)
    fig.suptitle("SCAPE shape space learned from Anny (cf. thesis fig. 3.10)")
    fig.tight_layout()
    p = RESULTS / "body_shape_space.png"
    fig.savefig(p, dpi=70)
    plt.close(fig)
    paths.append(p)

    m = BodyModel.load("female")
    pose = m.default_pose()
    sl = __import__("studio.body.skeleton", fromlist=["pose_slices"]).pose_slices()
    P = {n: i for i, n in enumerate(PART_NAMES)}
    pose[sl[P["torso"]]] = [0.15, 0.0, 0.25]
    pose[sl[P["upperarm_l"]]] = [-0.9, -0.6, 0.0]
    pose[sl[P["lowerarm_l"]]] = [1.2]
    pose[sl[P["upperarm_r"]]] = [0.4, 0.3, 0.0]
    pose[sl[P["upperleg_l"]]] = [-0.9, 0.0, 0.0]
    pose[sl[P["lowerleg_l"]]] = [1.3]
    pose[sl[P["upperleg_r"]]] = [0.2, 0.0, 0.0]
    pose[sl[P["lowerleg_r"]]] = [0.3]
    pose[sl[P["head"]]] = [0.3]
    pose = m.clip_pose(pose)
    fig, axes = plt.subplots(1, 3, figsize=(9, 4.2))
    colors = PART_COLORS[m.face_parts]
    for ax, use_q, title in ((axes[0], True, "front"), (axes[1], True, "side, with Q"), (axes[2], False, "side, rigid (Q = I)")):
        v = m.vertices(m.mean_shape(), pose, use_q=use_q)
        draw(ax, v, m.faces, colors, view=(0, 1, 0) if title == "front" else (-1, 0, 0))
        ax.set_title(title, fontsize=9)
    fig.suptitle("Posed body with its 15 parts (female mean shape)")
    fig.tight_layout()
    p = RESULTS / "body_posed_parts.png"
    fig.savefig(p, dpi=70)
    plt.close(fig)
    paths.append(p)
    results["pictures"] = [str(x) for x in paths]
    return paths


def main() -> int:
    from rigs.atomic import atomic_write_text

    RESULTS.mkdir(parents=True, exist_ok=True)
    results: dict = {"anchor": "thesis fig. 3.9/3.10 (6-20 components), TenBo ~3.7 mm; Anny+torch ~60 ms / 64 bodies"}
    speed(results)
    if SCRATCH.is_dir():
        generalisation(results)
        pose_error(results)
        print("\nEnd to end vs Anny truth bodies (8 held-out phenotypes, unseen poses, first one unposed; shape fitted at rest)")
        posed_truth(results)
        lab_postures(results)
        measurements_vs_anny(results)
    else:
        print(f"held-out sets not found in {SCRATCH}: run `studio model build --scratch DIR` and set STUDIO_BODY_SCRATCH")
    ansur(results)
    if "--no-pictures" not in sys.argv:
        import shutil

        docs = ROOT.parent / "docs" / "images"
        docs.mkdir(parents=True, exist_ok=True)
        for p in pictures(results):
            shutil.copyfile(p, docs / p.name)
            print(f"picture: {p} (copied to {docs / p.name}, {p.stat().st_size / 1e3:.0f} kB)")
    path = RESULTS / "body_model.json"
    atomic_write_text(path, json.dumps(results, indent=1), mkdir=True)
    print(f"\nwrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
