"""Shape under clothing: the multi-pose batch vs single-pose fits (thesis ch. 6, §6.4).

Generated Anny people (seeds from 2000 up, never used for tuning — ``--split dev`` draws seeds
from 3000 up into its own cache folder to choose settings on; both sexes alternate, adult
ages, Anny's population statures and BMIs), each in ``--poses`` lab postures (standing families
of ``studio.simulate.truth_build.LAB_POSES``, jittered, random heading), rendered twice: **tight**
(short sleeves, trousers, no looseness) and **loose** (3.5 cm, a garment drawn per person: long
shirt, jacket, wide trousers, skirt). Each session is segmented, every frame fitted alone from its
silhouettes (``studio fit``'s single-frame fit, gender auto on the first frame), then the batch
(``studio.fit.batch_session.fit_batch_session``: clothing cost of the condition, gender by batch)
over the frames the quality gates pass; single-pose figures are over the same frames.

Per subject × condition (cached as JSON with the digests of the fitting and the segmentation code: a rerun does
what is missing or was done by other code or on other masks):

- stature, chest, waist and hip girth errors of the batch shape and of each single-pose fit
  against the true body measured by the same definitions, and the mean surface distance of the
  batch body (in each frame's batch pose) and of each single-frame body to the true mesh;
- shape constancy (§6.4.2): the spread of the single-pose measurements across poses relative to
  the spread across subjects;
- gender: single pose (neutral body of the frame's fit, then female and male shape steps with the
  pose fixed, §6.4.5), vote (majority of the single poses, ties to the summed margin), batch;
  how many batches the paired test over the frames (with its floor on the margin) calls uncertain,
  and how many of those are wrong;
- skin: precision / recall against the simulator's true skin pixels of the segmentation's
  self-trained classifier (fig. 6.3 box) and of the session-adapted one (fitted hands and face);
  on the real SFA / abdomen masks via ``benchmarks/segmentation.py``'s skin section.

Anchors: thesis 86 / 90.6 / 94.3 % gender accuracy single / vote / batch over 53 trials of 11
poses; issue targets: loose batch stature within 10 mm, surface ≤ 15 mm median, batch better than
single-pose on every measurement, gender by batch ≥ 98 %.

    ANNY_CACHE_DIR=~/.cache/anny /path/to/python-with-anny benchmarks/clothing.py build --subjects 20 --poses 11
    .venv/bin/python benchmarks/clothing.py run --subjects 20 --poses 11 --workers 2
    # two processes side by side (about twice the throughput on 2 cores: much of a run is serial)
    ... run --subjects 20 --poses 11 --only 0 1 2 3 4 5 6 7 8 9 & ... run --subjects 20 --poses 11 --only 10 11 …
    .venv/bin/python benchmarks/clothing.py table
    # longer than one machine lives: --ledger on run and table keeps the finished subjects in
    # benchmarks/ledger/clothing/full/ (commit them); the next machine's run (same fitting code) skips them
    ... run --subjects 20 --poses 11 --ledger --only … ; ... table --subjects 20 --poses 11 --ledger
    # everyday subset: 2 subjects (one of each sex) × 4 postures, tight and loose
    ... build --quick ; ... run --quick ; ... table
    # --clothing auto's coverage threshold: the loose batch body's share of the clothing pixels
    ... coverage --split dev --subjects 4 --poses 4
    # the two-people flag: batches mixing each subject's frames with the next one's (after `run`)
    ... pairs --subjects 20 --poses 11 --ledger ; ... pairs --split dev --cache dev-p4 --subjects 28 --poses 4
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

FIRST_SEED = 2000
#: First seed of each split: ``report`` (the reported figures, never tuned on), ``dev`` (settings
#: are chosen on these; its own cache folder).
SPLIT_SEEDS = {"report": FIRST_SEED, "dev": 3000}
FAMILIES = ("a_pose", "t_pose", "arms_overhead", "hands_on_hips", "arm_forward", "wide_stance", "lunge",
            "torso_twist", "walk", "run", "arms_crossed")
QUICK_FAMILIES = ("t_pose", "hands_on_hips", "wide_stance", "walk")
GARMENTS = (("long_shirt", "trousers"), ("jacket", "wide_trousers"), ("shirt", "skirt"), ("jacket", "trousers"),
            ("long_shirt", "wide_trousers"))
MEASURES = ("stature", "chest_circumference", "waist_circumference", "hip_circumference")
THESIS_GENDER = {"single": 86.0, "vote": 90.6, "batch": 94.3}


#: ``full`` or ``quick`` (set by ``--quick``), ``dev-`` in front for the dev split, ``-x<S>`` behind for a rig of
#: S× the pixels (``pixels``, ``--pixels``): separate caches; ``ledger``: also keep the results in the repository
#: (``--ledger``).
RUN = {"name": "full", "first_seed": FIRST_SEED, "ledger": False, "pixels": 1}
#: Results kept in the repository, per cache name: the full run takes longer than a machine of ours
#: lives (about 3.5 h on 2 cores), so each machine commits the subjects it finished and the next
#: one, with the same fitting code, continues from them (``run --ledger``; ``table --ledger``).
LEDGER = ROOT / "benchmarks" / "ledger" / "clothing"


def select_run(cache: str | None, quick: bool, split: str, ledger: bool, pixels: int = 1) -> None:
    """Set :data:`RUN` from the command line: the cache's name (``cache``, else ``quick`` or
    ``full``; ``<split>-`` in front off the report split, ``-x<pixels>`` behind on a finer rig),
    the split's first seed, the ledger, the rig's pixels."""
    if pixels < 1:
        raise SystemExit(f"--pixels: expected an integer >= 1, got {pixels}")
    RUN["name"] = cache or ("quick" if quick else "full")
    if split != "report":
        RUN["name"] = f"{split}-{RUN['name']}"
    if pixels != 1:
        RUN["name"] = f"{RUN['name']}-x{pixels}"
    RUN["pixels"] = pixels
    RUN["first_seed"] = SPLIT_SEEDS[split]
    RUN["ledger"] = ledger


def cache_arguments(ap: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The options of a script that reads this benchmark's cache (``clothing_parts.py``,
    ``clothing_pixel.py``); :func:`select_run` then takes them."""
    ap.add_argument("--subjects", type=int, default=20)
    ap.add_argument("--poses", type=int, default=11)
    ap.add_argument("--quick", action="store_true", help="the quick cache (2 subjects × 4 postures)")
    ap.add_argument("--cache", default=None, metavar="NAME", help="as clothing.py's --cache")
    ap.add_argument("--split", choices=sorted(SPLIT_SEEDS), default="report")
    ap.add_argument("--ledger", action="store_true", help="take the results kept in the ledger too")
    ap.add_argument("--pixels", type=int, default=1, metavar="S", help="as clothing.py's --pixels")
    return ap


def bench_root() -> Path:
    from studio.simulate.samples import cache_root

    return cache_root() / "bench" / "clothing" / RUN["name"]


def rendered_session(name: str, condition: str):
    """The workspace of subject ``name``'s rendered session in ``condition`` (written by `run`)."""
    from studio.workspace import Workspace

    return Workspace.open(bench_root() / name / condition / "render" / "seed0")


def subjects(n: int, n_poses: int, quick: bool) -> list[dict]:
    fams = QUICK_FAMILIES if quick else FAMILIES
    out = []
    first = RUN["first_seed"]
    for i in range(n):
        rng = np.random.default_rng(first + i)
        female = bool(i % 2)
        garments = [g for g in GARMENTS if female or g[1] != "skirt"]
        top, bottom = garments[int(rng.integers(len(garments)))]
        out.append({
            "name": f"subject_{i:03d}", "seed": first + i, "gender": float(female),
            "poses": [fams[(i + j) % len(fams)] for j in range(min(n_poses, len(fams)))],
            "skin_tone": round(float(rng.uniform(0.05, 0.95)), 2),
            "top": [int(v) for v in rng.integers(20, 220, 3)], "bottom": [int(v) for v in rng.integers(20, 160, 3)],
            "garment": [top, bottom], "sleeves": str(rng.choice(["short", "long"])),
        })
    return out


def _spec(p: dict, condition: str) -> str:
    if condition == "tight":
        person = (f"  top: {{color: {p['top']}, sleeves: short, kind: shirt}}\n"
                  f"  bottom: {{color: {p['bottom']}, length: long, kind: trousers}}\n  looseness: 0.0\n")
    else:
        top, bottom = p["garment"]
        person = (f"  top: {{color: {p['top']}, sleeves: {p['sleeves']}, kind: {top}}}\n"
                  f"  bottom: {{color: {p['bottom']}, length: long, kind: {bottom}}}\n  looseness: 0.035\n")
    from pose_accuracy import bench_spec

    return bench_spec(f"clothing_{p['name']}_{condition}", "../body.npz", p["seed"],
                      f"  skin_tone: {p['skin_tone']}\n{person}", pixels=RUN["pixels"])


def _check_poses(folder: Path, p: dict) -> str | None:
    """Why ``folder``'s built body cannot serve subject ``p`` (other postures: a cache built with
    another ``--poses``), or None."""
    with np.load(folder / "body.npz") as z:
        have = [str(s) for s in z["pose_names"]] if "pose_names" in z.files else None
    if have is not None and have != p["poses"]:
        return (f"{folder / 'body.npz'}: built with postures {have}, asked for {p['poses']} — ask for the "
                f"--poses it was built with, give another --cache, or remove {folder} (its renders and results go "
                f"with it) and build again")
    return None


def build(args) -> int:
    """Truth bodies (Anny) and the two specs of every subject (needs torch + anny)."""
    from rigs.atomic import atomic_write_text
    from studio.simulate.truth_build import build_truth

    root = bench_root()
    todo = {}
    for p in subjects(args.subjects, args.poses, args.quick):
        folder = root / p["name"]
        for cond in ("tight", "loose"):
            (folder / cond).mkdir(parents=True, exist_ok=True)
            atomic_write_text(folder / cond / "spec.yaml", _spec(p, cond))
        if (folder / "body.npz").is_file():
            if (why := _check_poses(folder, p)) is not None:
                print(why, file=sys.stderr)
                return 1
        else:
            todo[p["name"]] = {"kind": "lab", "poses": p["poses"], "seed": p["seed"], "gender": p["gender"],
                               "age_years": (20.0, 60.0)}
    if todo:
        build_truth(root, list(todo), sequences=todo)
    print(f"{args.subjects} subjects ready in {root} ({len(todo)} built now)")
    return 0


def _gender_single(frame, options) -> dict:
    """§6.4.5 on one pose: the frame's fit → neutral body → female / male shape steps, pose fixed."""
    from studio.body import BodyModel, measure
    from studio.fit.batch import compare_genders, convert_shape
    from studio.fit.batch_gender import gender_scores

    neutral = BodyModel.load("neutral")
    shape = convert_shape(BodyModel.load(frame.gender), frame.shape, neutral)
    terms = gender_scores(compare_genders([frame], neutral, shape, frame.pose[None], options),
                          measure(neutral, shape)["stature"], options.gender_shape_free)
    costs = {g: v["score"] for g, v in terms.items()}
    return {"gender": min(costs, key=costs.get), "costs": costs, "terms": terms}


def run_one(p: dict, condition: str, workers: int) -> dict:
    from rigs.imageio import read_image
    from studio.body import BodyModel, measure
    from studio.fit import load_fits
    from studio.fit.batch import BatchFrame, BatchOptions
    from studio.fit.batch_session import fit_batch_session, session_skin
    from studio.fit.evaluate import surface_distance, true_mesh
    from studio.report.measurements import load_truth
    from studio.segment import segment_session
    from studio.segment.metrics import binary_scores
    from studio.simulate import ensure_rendered
    from studio.workspace import Workspace

    folder = bench_root() / p["name"] / condition
    t0 = time.perf_counter()
    session = ensure_rendered(folder / "spec.yaml", seed=0, cache_dir=folder / "render")
    segment_session(session, workers=1)
    t_seg = time.perf_counter() - t0
    ws = Workspace.open(session)
    frames = list(range(len(p["poses"])))
    options = BatchOptions(clothing=condition)
    # every frame fitted alone; the batch takes the frames the quality gates pass (choose_frames)
    batch = fit_batch_session(ws, n_frames=len(frames), clothing=condition, gender="auto", workers=workers,
                              chain_length=1, options=options)
    truth = load_truth(ws.layout)
    true_m = {k: truth["studio"][k] for k in MEASURES}
    fits = load_fits(ws, frames)
    bmodel = BodyModel.load(batch["gender"])
    bshape = np.asarray(batch["shape"])
    bm = measure(bmodel, bshape)
    out = {"subject": p["name"], "condition": condition, "sex": truth["sex"], "garment": p["garment"] if
           condition == "loose" else ["shirt", "trousers"], "poses": p["poses"], "frames": batch["frames"],
           "batch": {"gender": batch["gender"], "gender_costs": batch["gender_costs"],
                     "gender_terms": batch.get("gender_terms"), "gender_test": batch.get("gender_test"),
                     "quality": batch.get("quality"), "clothing_auto": batch.get("clothing_auto"),
                     "margin": batch["gender_margin"], "errors_mm": {k: 1000 * (bm[k] - true_m[k]) for k in MEASURES},
                     "consistency": batch["consistency"], "timings": batch["timings"]},
           "single": {}, "time_segment_s": t_seg, "time_batch_s": batch["wall_time"],
           "frames_left_out": {str(f): fits[f].status for f in frames if f not in batch["frames"]}}
    surf_b = []
    cams = ws.cameras
    opts_gender = BatchOptions(clothing=condition)
    for f in batch["frames"]:
        fit = fits[f]
        m = BodyModel.load(fit.gender)
        Vt = true_mesh(ws.path, f)
        sm = measure(m, fit.shape)
        surf_s = 1000 * surface_distance(m.vertices(fit.shape, fit.pose), m.faces, Vt, m.faces)
        surf_b.append(1000 * surface_distance(bmodel.vertices(bshape, np.asarray(batch["poses"][str(f)])),
                                              bmodel.faces, Vt, bmodel.faces))
        masks = ws.person_masks(f)
        bf = BatchFrame(f, cams, masks, None, fit.pose, fit.shape, fit.gender)
        g = _gender_single(bf, opts_gender)
        out["single"][str(f)] = {"gender_fit": fit.gender, "status": fit.status, "surface_mm": surf_s,
                                 "errors_mm": {k: 1000 * (sm[k] - true_m[k]) for k in MEASURES},
                                 "measures_m": {k: sm[k] for k in MEASURES}, "gender_single": g["gender"],
                                 "gender_single_costs": g["costs"], "gender_single_terms": g["terms"]}
    out["batch"]["loose_stature_error_mm"] = _loose_stature_error_mm(batch, true_m["stature"])
    out["batch"]["surface_mm"] = float(np.median(surf_b))
    out["batch"]["surface_per_frame_mm"] = surf_b
    # skin: segmentation's self-trained model and the session-adapted one vs the true skin
    cameras_of = {f: cams for f in batch["frames"]}
    adapted, info = session_skin(ws, fits, batch["frames"], cameras_of)
    pred_a, pred_s, truth_s = [], [], []
    for f in batch["frames"]:
        for k, c in enumerate(cams):
            person = ws.person_masks(f)[k]
            truth_s.append((read_image(ws.layout.truth_skin(c.name, f)) > 0) & person)
            seg = ws.layout.skin(c.name, f)
            pred_s.append(read_image(seg) > 0 if seg.is_file() else np.zeros_like(person))
            pred_a.append(adapted[f][k] if adapted[f][k] is not None else np.zeros_like(person))
    out["skin"] = {"segmentation": binary_scores(pred_s, truth_s), "session": binary_scores(pred_a, truth_s),
                   "session_info": info}
    return out


def run(args) -> int:
    from rigs.atomic import atomic_write_json
    from studio.fit.units import fit_code_digest
    from studio.segment.session import segmentation_code_digest

    root = bench_root()
    results = root / "results"
    results.mkdir(parents=True, exist_ok=True)
    code = fit_code_digest()
    seg = segmentation_code_digest()
    people = subjects(args.subjects, args.poses, args.quick)
    for p in [people[i] for i in args.only] if args.only else people:
        if not (root / p["name"] / "body.npz").is_file():
            print(f"{p['name']}: no truth body — run `build` first with torch + anny", file=sys.stderr)
            return 1
        if (why := _check_poses(root / p["name"], p)) is not None:
            print(why, file=sys.stderr)
            return 1
        for cond in args.conditions:
            path = results / f"{p['name']}_{cond}.json"
            if path.is_file() and _same_code(json.loads(path.read_text()), code, seg):
                keep_in_ledger(path)
                continue  # done by this code (results of other code or masks are redone, as its fits are)
            kept = ledger_result(path.name, code, seg)
            if kept is not None:  # done on an earlier machine by this code on these masks
                atomic_write_json(path, kept)
                continue
            t = time.perf_counter()
            r = run_one(p, cond, args.workers)
            r["time_total_s"] = time.perf_counter() - t
            r["code"], r["segmentation"] = code, seg
            atomic_write_json(path, r)
            keep_in_ledger(path)
            print(f"{p['name']} {cond}: done in {r['time_total_s']:.0f} s", flush=True)
    return table(args)


def keep_in_ledger(path: Path, folder: str = "") -> None:
    """Result file ``path`` copied into the ledger (its ``folder`` there) when ``--ledger`` is on
    (and it is not there already)."""
    from rigs.atomic import atomic_write_bytes

    if not RUN["ledger"]:
        return
    kept, data = LEDGER / RUN["name"] / folder / path.name, path.read_bytes()
    if not kept.is_file() or kept.read_bytes() != data:
        atomic_write_bytes(kept, data, mkdir=True)


def _same_code(result: dict, code: str, seg: str) -> bool:
    """Whether ``result`` was written by fitting code ``code`` on masks of segmentation code ``seg``
    (results from before the segmentation's digest was recorded count as other masks)."""
    return result.get("code") == code and result.get("segmentation") == seg


def ledger_result(name: str, code: str, seg: str) -> dict | None:
    """Result ``name`` from the repository's ledger when ``--ledger`` is on and it was written by
    fitting code ``code`` on masks of segmentation code ``seg``, else None."""
    path = LEDGER / RUN["name"] / name
    if not RUN["ledger"] or not path.is_file():
        return None
    r = json.loads(path.read_text())
    return r if _same_code(r, code, seg) else None


def coverage(args) -> int:
    """``--clothing auto``'s evidence: every subject × condition fitted ``auto`` (a loose batch,
    then tight if its body covers at least ``TIGHT_RECALL`` of the clothing pixels); prints the
    coverage per condition and writes ``coverage.json``. Reuses the sessions of ``run``
    (single-frame fits cached); overwrites their ``fit/batch.json``."""
    from rigs.atomic import atomic_write_json
    from studio.fit.batch_session import TIGHT_RECALL, fit_batch_session
    from studio.segment import segment_session
    from studio.simulate import ensure_rendered
    from studio.workspace import Workspace

    out = {}
    for p in subjects(args.subjects, args.poses, args.quick):
        for cond in args.conditions:
            folder = bench_root() / p["name"] / cond
            session = ensure_rendered(folder / "spec.yaml", seed=0, cache_dir=folder / "render")
            segment_session(session, workers=1)
            obj = fit_batch_session(Workspace.open(session), n_frames=len(p["poses"]), clothing="auto", gender="auto",
                                    workers=args.workers, chain_length=1)
            out[f"{p['name']}_{cond}"] = {"condition": cond, **obj["clothing_auto"]}
            print(f"{p['name']} {cond}: coverage {obj['clothing_auto']['clothing_recall']:.3f} -> "
                  f"{obj['clothing_auto']['chosen']}", flush=True)
    for cond in args.conditions:
        cov = sorted(v["clothing_recall"] for v in out.values() if v["condition"] == cond)
        print(f"{cond}: coverage {', '.join(f'{c:.3f}' for c in cov)} (threshold {TIGHT_RECALL})")
    atomic_write_json(bench_root() / "coverage.json", out)
    return 0


def _vote(single: dict) -> str:
    votes = [s["gender_single"] for s in single.values()]
    f, m = votes.count("female"), votes.count("male")
    if f != m:
        return "female" if f > m else "male"
    margin = sum(s["gender_single_costs"]["male"] - s["gender_single_costs"]["female"] for s in single.values())
    return "female" if margin > 0 else "male"


def _loose_stature_error_mm(batch: dict, true_stature: float) -> float:
    """The stature ``studio report`` gives ``batch`` (``fit/batch.json``'s content) under loose
    clothes (:func:`studio.report.measurements.loose_stature`: its standing height) minus the true
    stature (mm)."""
    from studio.body import BodyModel
    from studio.report.measurements import loose_stature

    poses = [batch["poses"][str(f)] for f in batch["frames"]]
    height, _ = loose_stature(BodyModel.load(batch["gender"]), np.asarray(batch["shape"]), poses)
    return 1000 * (height - true_stature)


def session_batch(r: dict):
    """(workspace, ``fit/batch.json`` content) of result ``r``'s session on this machine; stops with the
    path when the session's batch is missing or not the result's (other frames or gender)."""
    ws = rendered_session(r["subject"], r["condition"])
    path = ws.layout.fit_dir / "batch.json"
    if not path.is_file():
        raise SystemExit(f"{path}: missing; run `clothing.py run` for {r['subject']} {r['condition']} first")
    b = json.loads(path.read_text())
    if b["frames"] != r["frames"] or b["gender"] != r["batch"]["gender"]:
        raise SystemExit(f"{path}: frames {b['frames']} / gender {b['gender']}, the result has {r['frames']} / "
                         f"{r['batch']['gender']}: run the subject again")
    return ws, b


def loose_stature_error_mm(r: dict) -> float:
    """:func:`_loose_stature_error_mm` of result ``r``: recorded, or for a result written before it
    was, from the session's ``fit/batch.json`` (:func:`session_batch`)."""
    if "loose_stature_error_mm" in r["batch"]:
        return r["batch"]["loose_stature_error_mm"]
    from studio.report.measurements import load_truth

    ws, b = session_batch(r)
    return _loose_stature_error_mm(b, load_truth(ws.layout)["studio"]["stature"])


def summarise(rows: list[dict]) -> dict:
    out = {}
    for cond in ("tight", "loose"):
        rs = [r for r in rows if r["condition"] == cond]
        if not rs:
            continue
        s = {"subjects": len(rs), "frames": sum(len(r["single"]) for r in rs)}
        for k in MEASURES:
            b = np.array([r["batch"]["errors_mm"][k] for r in rs])
            si = np.array([v["errors_mm"][k] for r in rs for v in r["single"].values()])
            s[k] = {"batch_mean_abs": float(np.mean(np.abs(b))), "batch_mean": float(np.mean(b)),
                    "single_mean_abs": float(np.mean(np.abs(si))), "single_mean": float(np.mean(si))}
        # the stature `studio report` gives: a loose batch's standing height, a tight one's rest body
        rep = np.array([loose_stature_error_mm(r) if cond == "loose" else r["batch"]["errors_mm"]["stature"] for r in rs])
        s["stature_reported"] = {"batch_mean_abs": float(np.mean(np.abs(rep))), "batch_mean": float(np.mean(rep)),
                                 "batch_max_abs": float(np.max(np.abs(rep))),
                                 "within_10mm": int(np.sum(np.abs(rep) <= 10.0))}
        s["surface_mm"] = {"batch_median": float(np.median([r["batch"]["surface_mm"] for r in rs])),
                           "single_median": float(np.median([v["surface_mm"] for r in rs for v in r["single"].values()]))}
        # shape constancy (§6.4.2): spread across poses vs across subjects, per measurement
        cons = {}
        for k in MEASURES:
            per = [np.array([v["measures_m"][k] for v in r["single"].values()]) for r in rs]
            within = float(np.mean([x.var() for x in per]))
            across = float(np.var([x.mean() for x in per])) if len(per) > 1 else None
            cons[k] = {"within_pose_sd_mm": 1000 * np.sqrt(within),
                       "across_subject_sd_mm": None if across is None else 1000 * np.sqrt(across)}
        s["constancy"] = cons
        single_ok = [v["gender_single"] == r["sex"] for r in rs for v in r["single"].values()]
        s["gender_pct"] = {"single": 100 * float(np.mean(single_ok)),
                           "vote": 100 * float(np.mean([_vote(r["single"]) == r["sex"] for r in rs])),
                           "batch": 100 * float(np.mean([r["batch"]["gender"] == r["sex"] for r in rs]))}
        # the same batches decided by the cost alone (eq. 6.7, the thesis' rule), where recorded
        terms = [(r["batch"].get("gender_terms"), r["sex"]) for r in rs]
        if all(t for t, _ in terms):
            s["gender_pct"]["batch_cost_only"] = 100 * float(np.mean(
                [min(t, key=lambda g, t=t: t[g]["cost"]) == sex for t, sex in terms]))
        # the paired test over the frames (gender_test): batches whose gender it calls uncertain
        tests = [(r["batch"].get("gender_test"), r["batch"]["gender"] == r["sex"]) for r in rs]
        if all(t for t, _ in tests):
            flagged = [ok for t, ok in tests if t["uncertain"]]
            sure = [ok for t, ok in tests if not t["uncertain"]]
            s["gender_uncertain"] = {"flagged": len(flagged), "wrong_flagged": flagged.count(False),
                                     "right_flagged": flagged.count(True), "sure": len(sure),
                                     "wrong_sure": sure.count(False)}
        s["flagged"] = sum(bool(r["batch"]["consistency"]["flagged"]) for r in rs)
        s["skin"] = {k: {m: float(np.mean([r["skin"][k][m] for r in rs])) for m in ("precision", "recall")}
                     for k in ("segmentation", "session")}
        s["time_batch_s"] = float(np.mean([r["time_batch_s"] for r in rs]))
        out[cond] = s
    return out


def result_rows() -> list[dict]:
    """The cache's results, and under ``--ledger`` the ledger's this machine has not (fetched by
    `run` when it redoes nothing), by file name."""
    paths = {p.name: p for p in sorted((bench_root() / "results").glob("*.json"))}
    if RUN["ledger"]:
        paths = {p.name: p for p in sorted((LEDGER / RUN["name"]).glob("*.json"))} | paths
    return [json.loads(paths[k].read_text()) for k in sorted(paths)]


def table(args) -> int:
    from rigs.atomic import atomic_write_json

    rows = result_rows()
    if not rows:
        print("no results yet: run `build` then `run`")
        return 1
    summary = summarise(rows)
    codes = Counter(f"{r.get('code', 'not recorded')} / {r.get('segmentation', 'not recorded')}" for r in rows)
    from pose_accuracy import RIG_SIZE

    w, h = (n * RUN["pixels"] for n in RIG_SIZE)
    print(f"rig: 4 cameras of {w}x{h} px (cache {RUN['name']})")
    print("fitting / segmentation code: " + ", ".join(f"{c} ({n} results)" for c, n in codes.most_common())
          + ("  — MIXED: the results are not one code's; `run` redoes the others" if len(codes) > 1 else ""))
    for cond, s in summary.items():
        print(f"\n== {cond} clothing: {s['subjects']} subjects, {s['frames']} frames")
        print(f"{'measure':<22} {'batch |err| mm':>15} {'single |err| mm':>16} {'batch bias':>11} {'single bias':>12}")
        for k in MEASURES:
            m = s[k]
            print(f"{k:<22} {m['batch_mean_abs']:>15.1f} {m['single_mean_abs']:>16.1f} {m['batch_mean']:>+11.1f} "
                  f"{m['single_mean']:>+12.1f}")
        sr = s["stature_reported"]
        print(f"{'stature as reported':<22} {sr['batch_mean_abs']:>15.1f} {'':>16} {sr['batch_mean']:>+11.1f}   "
              f"(worst {sr['batch_max_abs']:.1f}, {sr['within_10mm']} of {s['subjects']} within 10 mm; "
              f"{'standing height' if cond == 'loose' else 'rest body'})")
        print(f"{'surface (median) mm':<22} {s['surface_mm']['batch_median']:>15.1f} {s['surface_mm']['single_median']:>16.1f}")
        print("shape constancy (sd across poses / across subjects, mm): " + ", ".join(
            f"{k.split('_')[0]} {v['within_pose_sd_mm']:.1f}/"
            f"{'–' if v['across_subject_sd_mm'] is None else format(v['across_subject_sd_mm'], '.1f')}"
            for k, v in s["constancy"].items()))
        g = s["gender_pct"]
        print(f"gender accuracy single / vote / batch: {g['single']:.0f} / {g['vote']:.0f} / {g['batch']:.0f} % "
              f"(thesis {THESIS_GENDER['single']} / {THESIS_GENDER['vote']} / {THESIS_GENDER['batch']} %)"
              + (f"; batch by the cost alone {g['batch_cost_only']:.0f} %" if "batch_cost_only" in g else ""))
        if (u := s.get("gender_uncertain")) is not None:
            print(f"gender flagged uncertain (95 % paired interval reaches 0, or margin below the floor): "
                  f"{u['flagged']} of {s['subjects']} "
                  f"({u['wrong_flagged']} wrong, {u['right_flagged']} right); not flagged: {u['sure']}, "
                  f"{u['wrong_sure']} wrong")
        sk = s["skin"]
        print(f"skin P/R: segmentation (self-trained box) {sk['segmentation']['precision']:.2f}/"
              f"{sk['segmentation']['recall']:.2f}, session-adapted {sk['session']['precision']:.2f}/"
              f"{sk['session']['recall']:.2f}; batches flagged as two people: {s['flagged']}; "
              f"batch time {s['time_batch_s']:.0f} s")
    if getattr(args, "real_skin", False):
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from segmentation import bench_skin

        summary["real_skin"] = bench_skin()
    atomic_write_json(bench_root() / "summary.json", summary)
    print(f"\nsummary: {bench_root() / 'summary.json'}")
    return 0


def _pair_frames(frames: list[int], k: int) -> list[int]:
    """At most ``k`` of a batch's ``frames``, spread evenly over them."""
    idx = np.linspace(0, len(frames) - 1, min(k, len(frames))).round().astype(int)
    return [frames[i] for i in dict.fromkeys(idx)]


def _fit_pair(names: tuple[str, str], cond: str, rows: dict, k: int) -> dict:
    """One batch over the batch frames of two subjects (at most ``k`` each; the first one's sex given)."""
    from dataclasses import replace

    from studio.fit import load_fits
    from studio.fit.batch import BatchOptions, batch_fit
    from studio.fit.batch_session import session_batch_frames
    from studio.report.measurements import load_truth

    frames, people = [], []
    for i, name in enumerate(names):
        r = rows[f"{name}_{cond}"]
        ws = rendered_session(name, cond)
        chosen = _pair_frames(r["frames"], k)
        fr, _ = session_batch_frames(ws, load_fits(ws, chosen), chosen)
        frames += [replace(f, frame=100 * i + f.frame) for f in fr]  # the second subject's frames from 100
        people.append({"subject": name, "sex": r["sex"], "stature_m": load_truth(ws.layout)["studio"]["stature"],
                       "frames": chosen})
    t = time.perf_counter()
    res = batch_fit(frames, gender=people[0]["sex"], options=BatchOptions(clothing=cond))
    return {"condition": cond, "people": people, "consistency": res.consistency,
            "time_s": round(time.perf_counter() - t, 1)}


def pairs(args) -> int:
    """The two-people flag (§6.4.2) on batches that do mix two people: per condition, each subject's
    batch frames (at most ``--pair-frames``, spread over them) with the next subject's (a ring: 0+1,
    1+2, …, last+0), fitted as one batch with the first subject's sex given; flagged or not, by the
    true stature difference, beside how many of `run`'s one-person batches this rule flags (on their
    recorded cost ratios and single-frame statures, whatever code recorded them). Needs `run`'s
    sessions and results; each pair cached with the fitting digest (``pairs/``, and the ledger's
    ``pairs/`` under ``--ledger``); writes ``pairs.json`` (the summaries of this call's conditions; other
    conditions' kept from the previous file)."""
    from rigs.atomic import atomic_write_json
    from studio.fit.batch_frames import STATURE_SPREAD_FLAG, two_people
    from studio.fit.units import fit_code_digest

    code = fit_code_digest()
    rows = {f"{r['subject']}_{r['condition']}": r for r in result_rows()}
    out = bench_root() / "pairs.json"
    summary = json.loads(out.read_text()) if out.is_file() else {}  # other conditions' summaries stay
    for cond in args.conditions:
        names = [p["name"] for p in subjects(args.subjects, args.poses, args.quick)
                 if f"{p['name']}_{cond}" in rows]
        if len(names) < 2:
            print(f"{cond}: fewer than two subjects with results: run `run` first")
            continue
        ring = list(zip(names, names[1:] + names[:1]))[:len(names) if len(names) > 2 else 1]
        records = []
        for a, b in ring:
            if args.only and int(a.rsplit("_", 1)[1]) not in args.only:
                continue  # another process's pairs
            path = bench_root() / "pairs" / f"{a}+{b}_{cond}.json"
            kept = LEDGER / RUN["name"] / "pairs" / path.name
            rec = next((json.loads(q.read_text()) for q in (path, kept) if q.is_file()), None)
            if rec is None or rec.get("code") != code or rec.get("pair_frames") != args.pair_frames:
                rec = _fit_pair((a, b), cond, rows, args.pair_frames) | {"code": code, "pair_frames": args.pair_frames}
                atomic_write_json(path, rec, mkdir=True)
                print(f"{a}+{b} {cond}: {'flagged' if rec['consistency']['flagged'] else 'not flagged'} "
                      f"in {rec['time_s']:.0f} s", flush=True)
            elif not path.is_file():
                atomic_write_json(path, rec, mkdir=True)
            keep_in_ledger(path, "pairs")
            records.append(rec)
        print(f"\n== {cond} clothing: batches of two people ({len(records)} pairs, at most {args.pair_frames} "
              f"frames each; spread: of the single-frame statures without the farthest)")
        print(f"{'pair':<16} {'sexes':>5} {'Δstature mm':>11} {'frames':>6} {'max ratio':>9} {'spread mm':>9}  flagged")
        for rec in records:
            a, b = rec["people"]
            c = rec["consistency"]
            d = 1000 * abs(a["stature_m"] - b["stature_m"])
            print(f"{a['subject'] + '+' + b['subject'][-3:]:<16} {a['sex'][0].upper() + '+' + b['sex'][0].upper():>5} "
                  f"{d:>11.0f} {len(c['cost_ratio']):>6} {max(c['cost_ratio'].values()):>9.2f} "
                  f"{1000 * c.get('stature_spread_trimmed_m', c['stature_spread_m']):>9.0f}  "
                  f"{'yes' if c['flagged'] else 'no'}")
        gaps = [abs(r["people"][0]["stature_m"] - r["people"][1]["stature_m"]) for r in records]
        far = [r["consistency"]["flagged"] for r, g in zip(records, gaps) if g >= STATURE_SPREAD_FLAG]
        near = [r["consistency"]["flagged"] for r, g in zip(records, gaps) if g < STATURE_SPREAD_FLAG]
        # the one-person batches of `run` judged by this code's rule on their recorded ratios and statures
        one = [bool(two_people(list(c["cost_ratio"]), list(c["cost_ratio"].values()),
                               list(c["single_statures_m"].values())))
               for c in (rows[f"{n}_{cond}"]["batch"]["consistency"] for n in names)]
        summary[cond] = {"pairs": len(records), "flagged": sum(far) + sum(near),
                         "far": {"pairs": len(far), "flagged": sum(far)},
                         "near": {"pairs": len(near), "flagged": sum(near)},
                         "one_person": {"batches": len(one), "flagged": sum(one)}, "pair_frames": args.pair_frames,
                         "records": records}
        print(f"two people flagged: {sum(far) + sum(near)} of {len(records)} ({sum(far)} of {len(far)} differing by "
              f">= {STATURE_SPREAD_FLAG * 1000:.0f} mm in stature, {sum(near)} of {len(near)} by less); one-person "
              f"batches of `run` flagged by this rule: {sum(one)} of {len(one)}")
    atomic_write_json(out, summary)
    print(f"\npairs: {out}")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("step", choices=["build", "run", "table", "coverage", "pairs"])
    ap.add_argument("--subjects", type=int, default=20)
    ap.add_argument("--poses", type=int, default=11)
    ap.add_argument("--quick", action="store_true", help="2 subjects × 4 postures (overrides --subjects/--poses)")
    ap.add_argument("--conditions", nargs="+", default=["tight", "loose"], choices=["tight", "loose"])
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--only", type=int, nargs="+", metavar="I",
                    help="run: these subjects only (indices below --subjects), e.g. a second process over the "
                         "other half of the people: results are per subject, so two runs side by side do not collide; "
                         "pairs: the pairs these subjects lead")
    ap.add_argument("--cache", default=None, metavar="NAME",
                    help="the cache folder's name (default: full, or quick with --quick; dev- in front for the dev "
                         "split), e.g. another posture count than a cache was built with")
    ap.add_argument("--ledger", action="store_true",
                    help=f"also keep the results in {LEDGER.relative_to(ROOT)}/<cache>/ (commit them) and take "
                         "those of this fitting code from there: a run longer than one machine's life continues "
                         "on the next")
    ap.add_argument("--pair-frames", type=int, default=4, metavar="K",
                    help="pairs: at most this many of each subject's batch frames in a two-people batch")
    ap.add_argument("--real-skin", action="store_true", help="also the skin classifier on ../shared/data/skin")
    ap.add_argument("--split", choices=sorted(SPLIT_SEEDS), default="report",
                    help="report: seeds 2000+ (the reported figures); dev: seeds 3000+ (choose settings here)")
    ap.add_argument("--pixels", type=int, default=1, metavar="S",
                    help="a rig of S times as many pixels each way through the same lenses (1312x980 for 2; the "
                         "sample rig is the thesis' 656x490): its own cache and ledger folder, <cache>-x<S>")
    args = ap.parse_args(argv)
    if args.quick:
        args.subjects, args.poses = 2, 4
    if args.only and not all(0 <= i < args.subjects for i in args.only):
        ap.error(f"--only: expected subject indices in 0..{args.subjects - 1}, got {args.only}")
    select_run(args.cache, args.quick, args.split, args.ledger, args.pixels)
    if args.pair_frames < 1:
        ap.error(f"--pair-frames: expected an integer >= 1, got {args.pair_frames}")
    return {"build": build, "run": run, "table": table, "coverage": coverage, "pairs": pairs}[args.step](args)


if __name__ == "__main__":
    sys.exit(main())
