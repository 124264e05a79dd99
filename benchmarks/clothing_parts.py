"""Where the clothing benchmark's surface error lives: per body region, batch beside single fits.

``benchmarks/clothing.py`` reports one surface distance per frame (the symmetric mean distance of
the fitted body to the true one). This splits it by region of the body model's parts — legs
(thighs, shins, feet), arms (upper arms, forearms, hands), trunk (pelvis, torso) and head — and by
garment, for the batch shape and for the single-frame fits of the same frames. A region's figure
is symmetric as the whole one is: the mean distance of samples on the fitted region to the whole
true surface and of samples on the true region to the whole fitted surface, halved (both meshes
share the model's topology, so a region is the same faces on both).

It reads what ``clothing.py run`` left on this machine (each subject's session with its
``fit/batch.json`` and single fits; the results from the ledger or the cache) and fits nothing;
a session whose batch is not the result's (other frames or gender) stops it with the path::

    .venv/bin/python benchmarks/clothing_parts.py --subjects 20 --poses 11 --ledger

Prints a table per condition and writes ``parts.json`` beside the benchmark's ``summary.json``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import clothing  # noqa: E402  (the benchmark's cache, subjects and ledger)

#: body regions by the model's part names (``studio.body.skeleton.PART_NAMES``)
REGIONS = {
    "legs": ("upperleg_l", "lowerleg_l", "foot_l", "upperleg_r", "lowerleg_r", "foot_r"),
    "arms": ("upperarm_l", "lowerarm_l", "hand_l", "upperarm_r", "lowerarm_r", "hand_r"),
    "trunk": ("pelvis", "torso"),
    "head": ("head",),
}
SAMPLES = 60000  # as studio.fit.evaluate.surface_distance (the samples' spacing adds ~2 mm at 30000)


def region_faces(model) -> dict[str, np.ndarray]:
    """Boolean face selections (F,) of :data:`REGIONS` for ``model``."""
    parts = np.asarray(model.face_parts)
    names = list(model.part_names)
    return {r: np.isin(parts, [names.index(n) for n in ns]) for r, ns in REGIONS.items()}


def region_distances(fitted: np.ndarray, true: np.ndarray, faces: np.ndarray, regions: dict,
                     n: int = SAMPLES, seed: int = 0) -> dict[str, float]:
    """Symmetric mean surface distance (m) per region between two meshes of one topology, and
    ``"whole"`` (as :func:`studio.fit.evaluate.surface_distance`)."""
    from scipy.spatial import cKDTree

    from studio.fit.evaluate import surface_samples

    rng = np.random.default_rng(seed)
    tree_f = cKDTree(surface_samples(fitted, faces, n, rng))
    tree_t = cKDTree(surface_samples(true, faces, n, rng))
    out = {}
    for name, sel in {"whole": np.ones(len(faces), bool), **regions}.items():
        m = max(n // 4, int(n * sel.mean()))
        a = tree_t.query(surface_samples(fitted, faces[sel], m, rng))[0].mean()
        b = tree_f.query(surface_samples(true, faces[sel], m, rng))[0].mean()
        out[name] = float(0.5 * (a + b))
    return out


def subject_parts(r: dict) -> dict:
    """Per-frame region distances (mm) of one benchmark result's batch and single fits."""
    from studio.body import BodyModel
    from studio.fit import load_fits
    from studio.fit.evaluate import true_mesh

    ws, b = clothing.session_batch(r)
    bmodel = BodyModel.load(b["gender"])
    regions = region_faces(bmodel)
    shape = np.asarray(b["shape"])
    fits = load_fits(ws, r["frames"])
    out = {"batch": [], "single": []}
    for f in r["frames"]:
        Vt = true_mesh(ws.path, f)
        vb = bmodel.vertices(shape, np.asarray(b["poses"][str(f)]))
        out["batch"].append({k: 1000 * v for k, v in region_distances(vb, Vt, bmodel.faces, regions).items()})
        m = BodyModel.load(fits[f].gender)
        vs = m.vertices(fits[f].shape, fits[f].pose)
        out["single"].append({k: 1000 * v for k, v in region_distances(vs, Vt, m.faces, regions).items()})
    return out


def summarise(rows: list[dict], parts: dict) -> dict:
    """Median over frames per condition, and per garment (loose), of each region's distance."""
    names = ("whole", *REGIONS)
    out: dict = {}
    for r in rows:
        p = parts[f"{r['subject']}_{r['condition']}"]
        keys = [r["condition"]] + ([f"{r['condition']} · {g}" for g in r["garment"]] if r["condition"] == "loose" else [])
        for key in keys:
            acc = out.setdefault(key, {"frames": 0, "batch": {n: [] for n in names}, "single": {n: [] for n in names}})
            acc["frames"] += len(p["batch"])
            for fit in ("batch", "single"):
                for n in names:
                    acc[fit][n] += [d[n] for d in p[fit]]
    return {k: {"frames": out[k]["frames"], **{fit: {n: float(np.median(out[k][fit][n])) for n in names}
                                             for fit in ("batch", "single")}}
            for k in sorted(out, key=lambda k: (k.split(" ")[0] != "tight", k))}


def main(argv=None) -> int:
    from rich.progress import track

    from rigs.atomic import atomic_write_json

    ap = clothing.cache_arguments(argparse.ArgumentParser(description=__doc__,
                                                          formatter_class=argparse.RawDescriptionHelpFormatter))
    ap.add_argument("--conditions", nargs="+", default=["tight", "loose"], choices=["tight", "loose"])
    args = ap.parse_args(argv)
    clothing.select_run(args.cache, args.quick, args.split, args.ledger, args.pixels)
    rows = [r for r in clothing.result_rows() if r["condition"] in args.conditions]
    if not rows:
        print("no results yet: run `clothing.py build` then `clothing.py run`")
        return 1
    parts = {f"{r['subject']}_{r['condition']}": subject_parts(r)
             for r in track(rows, description="region distances")}
    summary = summarise(rows, parts)
    names = ("whole", *REGIONS)
    print(f"{'median over frames, mm':<30} {'frames':>6}  " + "  ".join(f"{n:>13}" for n in names))
    print(f"{'(batch / single)':<30} {'':>6}")
    for key, s in summary.items():
        print(f"{key:<30} {s['frames']:>6}  " + "  ".join(f"{s['batch'][n]:>6.1f} /{s['single'][n]:>5.1f}"
                                                           for n in names))
    out = clothing.bench_root() / "parts.json"
    atomic_write_json(out, {"regions": REGIONS, "summary": summary, "per_result": parts})
    print(f"\nparts: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
