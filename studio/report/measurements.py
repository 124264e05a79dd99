"""Measurement table of a fitted session: ISO 7250-1 definitions, honest uncertainty, population.

One row per measurement of :data:`studio.body.iso7250.DEFINITIONS` (the fit and the truth by
the same definitions): per-frame values, mean, spread over frames, the four uncertainty
components of :mod:`studio.report.uncertainty` combined into a 95 % interval, the ISO
20685-1:2018 maximum allowable error and whether the interval's half-width meets it, the
ANSUR II percentile and z-score by sex, quality status with the reasons, and (simulated
sessions) the truth and the error.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from studio.body.iso7250 import DEFINITIONS, ISO_NAMES

__all__ = ["LOOSE_FLAGS", "REPORTED", "STANDING_GAP", "STANDING_WINDOW", "UNITS", "frames_used", "load_truth",
           "loose_flag", "loose_stature", "measurement_table", "standing_height", "use_batch_shape",
           "write_measurements", "write_measurements_csv"]

#: Measurements reported, in order (:data:`studio.body.iso7250.ISO_NAMES`).
REPORTED = ISO_NAMES
_DEF = {d.name: d for d in DEFINITIONS}
#: report unit and factor from SI, per measurement
UNITS = {d.name: {"m": ("mm", 1000.0), "kg": ("kg", 1.0), "kg/m²": ("kg/m²", 1.0)}[d.unit] for d in DEFINITIONS}
#: names whose definition did not change with ISO 7250-1 (a truth file written before it still counts)
_STABLE = ("stature", "arm_span", "waist_circumference", "hip_circumference", "mass")


def _same_definition_truth(truth: dict | None) -> dict:
    studio = (truth or {}).get("studio") or {}
    if not isinstance(studio, dict):
        raise ValueError(f"truth measurements: 'studio' must be a mapping name → value, got {type(studio).__name__}")
    if not studio or all(n in studio for n in ISO_NAMES):
        return studio
    same = {n: studio[n] for n in _STABLE if n in studio}  # written before the ISO definitions
    if "inseam" in studio:
        same["crotch_height"] = studio["inseam"]
    return same


def frames_used(fits: dict) -> tuple[list, str]:
    """(frames the measurements rest on, their status): the ``ok`` (or unchecked) frames, with
    none the ``suspect`` ones, with none the ``failed`` ones."""
    status = {f: getattr(fit, "status", "ok").replace("unchecked", "ok") for f, fit in fits.items()}
    for level in ("ok", "suspect", "failed"):
        used = [f for f in sorted(fits) if status[f] == level]
        if used:
            return used, level
    raise ValueError("no fitted frames to measure")


#: A frame whose thighs are both at least this far (rad) from the downward vertical sits or squats
#: (:func:`studio.fit.props.thigh_angles`; the pose benchmark's dev fits: seated and half squat
#: 55–93°, every other family at most 38°). Our model's hips shorten such bodies: their fitted
#: stature came out −32 mm median (−2 to −74 mm) on the dev people, −34 (seated) and −26 mm (half
#: squat) on the held-out ones, where the standing families are within 10 mm; the model fitted to
#: the true bodies in 3-D is short there too (``benchmarks/pose_ceiling.py``). So the heights
#: (:data:`BENT_KINDS`) are measured on the frames that do not sit or squat, and flagged when no
#: frame does.
BENT_LEGS = np.radians(45.0)
BENT_KINDS = ("height",)
BENT_FLAG = ("suspect: every frame behind it sits or squats, and the body model shortens such bodies "
             "(pose benchmark: stature −26 to −34 mm median)")


def bent_frames(model, fits: dict) -> set:
    """The frames of ``fits`` {frame: FrameFit} whose body sits or squats (:data:`BENT_LEGS`); a
    fit without a pose (a shape alone) is not one of them."""
    from studio.fit.props import thigh_angles

    return {f for f, fit in fits.items()
            if getattr(fit, "pose", None) is not None and min(thigh_angles(model, fit.shape, fit.pose)) >= BENT_LEGS}


def measurement_table(model, fits: dict, truth: dict | None = None, uncertainty: dict | None = None,
                      sex: str | None = None) -> dict:
    """{name: row} (module doc), lengths in millimetres, mass in kilograms, BMI in kg/m².

    ``fits`` {frame: FrameFit}; ``truth`` the session's ``truth/measurements.json`` or None:
    ``truth`` is its ``"studio"`` entry (the true person by the same definitions,
    :func:`studio.simulate.session.studio_truth`), else Anny's own value (``truth_source``
    says which); ``truth_anny`` / ``error_anny`` always Anny's. ``uncertainty`` {component:
    {name: σ (SI)}} for ``calibration``, ``posterior`` and ``model`` (:mod:`studio.report.uncertainty`);
    ``sex`` for the population (default: the model's gender).

    Quality (:mod:`studio.fit.quality`): the mean is over the ``ok`` (or unchecked) frames;
    with none, the ``suspect``, then the ``failed`` ones. ``status`` is the worst status of the
    frames used, raised by the value's own ANSUR II z-score; ``flags`` say why. A figure is
    never clean when its frames or its value are not. The heights are measured on the frames
    used that do not sit or squat (:data:`BENT_LEGS`), and are ``suspect`` when all of them do.
    """
    from studio.body import measure
    from studio.fit.quality import POPULATION_Z, status_of
    from studio.report.population import population_context
    from studio.report.uncertainty import combine

    per = {f: measure(model, fit.shape) for f, fit in sorted(fits.items())}
    status = {f: getattr(fit, "status", "ok").replace("unchecked", "ok") for f, fit in fits.items()}
    used, level = frames_used(fits)
    base_flags = []
    if level != "ok":
        base_flags.append(f"no clean frame: mean over {len(used)} {level} frame(s)")
    elif len(used) < len(per):
        base_flags.append(f"{len(per) - len(used)} flagged frame(s) left out of the mean")
    bent = bent_frames(model, {f: fits[f] for f in used})
    upright = [f for f in used if f not in bent]
    same = _same_definition_truth(truth)
    unc = uncertainty or {}
    sex = sex or model.gender
    out = {}
    for name in REPORTED:
        d = _DEF[name]
        unit, scale = UNITS[name]
        rows = used
        flags = list(base_flags)
        severities = [] if level == "ok" else [level]
        if bent and d.kind in BENT_KINDS:
            if upright:
                rows = upright
                flags.append(f"{len(bent)} sitting or squatting frame(s) left out of the mean")
            else:
                severities.append("suspect")
                flags.append(BENT_FLAG)
        vals = np.array([per[f][name] for f in rows]) * scale
        mean = float(vals.mean())
        std = float(vals.std(ddof=1)) if len(vals) > 1 else 0.0
        pop = population_context(name, mean / scale, sex)
        if pop is not None and abs(pop["z"]) > POPULATION_Z[0]:
            severities.append("failed" if abs(pop["z"]) > POPULATION_Z[1] else "suspect")
            flags.append(f"{severities[-1]}: {pop['z']:+.1f} σ from ANSUR II ({pop['sex']}): implausible")
        s_frames = std / np.sqrt(len(vals))
        s_cal = unc.get("calibration", {}).get(name)
        s_post = unc.get("posterior", {}).get(name)
        s_model = unc.get("model", {}).get(name)
        sigma = combine(s_frames, *(None if s is None else s * scale for s in (s_cal, s_post, s_model)))
        mae = None if d.max_error is None else d.max_error * scale
        row = {
            "title": d.title, "clause": d.clause, "kind": d.kind, "definition": d.text, "unit": unit,
            "per_frame": {str(f): float(per[f][name] * scale) for f in per},
            "per_frame_status": {str(f): status[f] for f in per},
            "frames_used": [int(f) for f in rows],
            "status": status_of([{"severity": s} for s in severities]),
            "flags": flags,
            "mean": mean, "std": std,
            "sigma_frames": float(s_frames),
            "sigma_calibration": None if s_cal is None else float(s_cal * scale),
            "sigma_posterior": None if s_post is None else float(s_post * scale),
            "sigma_model": None if s_model is None else float(s_model * scale),
            "sigma": sigma,
            "ci95": [mean - 1.96 * sigma, mean + 1.96 * sigma],
            "iso20685_max_error": mae,
            "iso20685_ok": None if mae is None else bool(1.96 * sigma <= mae),
            "population": pop,
            "population_z": None if pop is None else pop["z"],
            "truth": None, "error": None, "truth_source": None, "truth_anny": None, "error_anny": None,
        }
        if truth is not None and truth.get(name) is not None:
            row["truth_anny"] = float(truth[name]) * scale
            row["error_anny"] = mean - row["truth_anny"]
        if same.get(name) is not None:
            row["truth"], row["truth_source"] = float(same[name]) * scale, "studio"
        elif row["truth_anny"] is not None:
            row["truth"], row["truth_source"] = row["truth_anny"], "anny"
        if row["truth"] is not None:
            row["error"] = mean - row["truth"]
            row["truth_in_ci95"] = bool(row["ci95"][0] <= row["truth"] <= row["ci95"][1])
        out[name] = row
    return out


#: Measurement kinds a loose garment hides: under loose clothes the batch body is bounded only from
#: outside there (the inside term, eq. 6.2; the skin pulls at hands and face only), so the figure is
#: an upper bound. ``benchmarks/clothing.py --quick``: loose batch girths +75 to +171 mm, moving by up
#: to 90 mm between runs.
LOOSE_BOUNDED_KINDS = ("large_girth", "small_girth", "depth", "mass", "index")
LOOSE_BOUNDED_NAMES = ("hip_breadth",)
#: … and the heights and lengths: they hang on joints a loose garment hides (knees and crotch under
#: wide trousers, skirts and long shirts, elbows in long sleeves). ``benchmarks/clothing_stature.py``
#: on the dev split (seeds 3000, 3001, 3003, 3005–3007, loose, standing on the floor): batch stature
#: −4 to +50 mm, 3 of 6 people beyond 10 mm, while the posed head tops of the upright frames lay within
#: 10 mm of the truth: the knees bent 15–48° where the truth stood at 4–8°, thighs up to 100 mm long
#: and shanks up to 82 mm short.
LOOSE_JOINT_KINDS = ("height", "length")
LOOSE_FLAGS = {"bounded": "suspect: loose clothing hides the body here — an upper bound",
               "joints": ("suspect: loose clothing hides the joints this hangs on (knees, crotch, elbows) — "
                          "an estimate")}
#: Frames whose head top lies within this much (m) of the highest are the standing ones
#: (:func:`standing_height`): a lunge, squat or stride lowers the head by 50–150 mm, a standing
#: posture by 0–25 mm (the dev split's true bodies).
STANDING_WINDOW = 0.03
#: A standing height this much (m) below the rest body's stature means no frame stood (every one a
#: lunge, squat or stride: the head 50–150 mm lower); the dev split's loose batches stood 6 mm above
#: to 41 mm below their rest bodies.
STANDING_GAP = 0.06


def standing_height(model, shape, poses) -> tuple[float, list[int]]:
    """Stature as ISO 7250-1 defines it — the vertical distance from the floor to the highest
    point of the head of the person standing — read off posed bodies: per pose (P, POSE_SIZE) the
    highest head vertex above the floor (world z = 0, the calibrated ground plane), then the median
    over the poses within :data:`STANDING_WINDOW` of the highest. Returns the height (m) and the
    indices of the poses used.

    Under loose clothes this is the stature a batch can vouch for: the head top is seen in every
    view, the knees and crotch are not. On the clothing benchmark's dev split (seeds 3000–3007, 8
    loose batches standing on the floor) it was off the true stature by +0.6 to +10.7 mm (mean
    +3.9), the rest body's stature by −4.0 to +46.9 mm (mean +23.0: knees bent where the truth stood
    straight, on longer thighs); tight batches: |7.1| vs |5.2| mm, so tight ones keep the rest body's."""
    from studio.body.skeleton import PART_NAMES

    poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
    V = model.vertices_batch(np.repeat(np.asarray(shape, dtype=np.float64)[None], len(poses), axis=0), poses)
    tops = V[:, np.asarray(model.parts) == PART_NAMES.index("head"), 2].max(axis=1)
    used = np.flatnonzero(tops >= tops.max() - STANDING_WINDOW)
    return float(np.median(tops[used])), [int(i) for i in used]


def loose_stature(model, shape, poses, rest: float | None = None) -> tuple[float, list[int] | None]:
    """The stature a loose batch reports (m): :func:`standing_height` over its ``poses``, or the rest
    body's (``rest``, measured when None) when that lies more than :data:`STANDING_GAP` above it (no
    frame stood); with the indices of the standing poses, or None."""
    from studio.body import measure

    rest = measure(model, shape)["stature"] if rest is None else float(rest)
    height, used = standing_height(model, shape, poses)
    return (height, used) if height >= rest - STANDING_GAP else (rest, None)


def loose_flag(name: str) -> str | None:
    """The flag of measurement ``name`` on a loose batch body (:data:`LOOSE_FLAGS`), or None."""
    kind = _DEF[name].kind
    if kind in LOOSE_BOUNDED_KINDS or name in LOOSE_BOUNDED_NAMES:
        return LOOSE_FLAGS["bounded"]
    return LOOSE_FLAGS["joints"] if kind in LOOSE_JOINT_KINDS else None


def _flag(row: dict, flag: str) -> None:
    """Append ``flag`` to a table row's flags and make it at least ``suspect`` (failed stays failed)."""
    row["flags"] = [*row.get("flags", []), flag]
    row["status"] = "failed" if row.get("status") == "failed" else "suspect"


def use_batch_shape(table: dict, model, shape, truth: dict | None = None, sex: str | None = None,
                    frames: list | None = None, clothing: str | None = None, poses=None,
                    warning: str | None = None) -> dict:
    """The table measured on the batch shape (thesis ch. 6: one shape shared by the frames,
    ``fit/batch.json``) instead of the mean of the single-frame shapes: each row's ``mean`` is the
    batch body's value (``model`` the batch's gender), its interval moved with it, the truth error
    and population recomputed; the per-frame values and their spread stay as they were (the
    single-frame fits), ``shape_source`` says ``"batch"``. With ``clothing`` ``"loose"`` (the batch's
    clothing cost) the girths, depths, hip breadth, mass and BMI are at least ``suspect``, flagged as
    upper bounds, and so are the heights and lengths, flagged as estimates (:func:`loose_flag`);
    the shoulder breadth keeps its status. The stature of a loose batch with its ``poses`` (P,
    POSE_SIZE; the frames' order) is :func:`standing_height` instead (``method`` says so), which
    keeps its status — unless it lies more than :data:`STANDING_GAP` below the rest body's (no
    frame stood). A batch-wide ``warning`` (:func:`studio.fit.batch_session.gender_warning`: the
    gender is within the frames' noise, and every value is of that gender's body) flags every row
    and makes it at least ``suspect``. Returns a new table."""
    from studio.body import measure
    from studio.report.population import population_context

    values = dict(measure(model, shape))
    standing = None
    if clothing == "loose" and poses is not None and len(poses):
        values["stature"], used = loose_stature(model, shape, poses, values["stature"])
        if used is not None:
            standing = (f"standing height: the highest point of the head above the floor, median of the "
                        f"{len(used)} standing frame(s) {[int((frames or range(len(poses)))[i]) for i in used]} "
                        f"(loose clothing hides the knees)")
    same = _same_definition_truth(truth)
    out = {}
    for name, row in table.items():
        row = dict(row)
        scale = UNITS[name][1]
        value = float(values[name]) * scale
        delta = value - row["mean"]
        row["mean"] = value
        row["ci95"] = [row["ci95"][0] + delta, row["ci95"][1] + delta]
        row["shape_source"] = "batch"
        row["batch_frames"] = [int(f) for f in frames or []]
        pop = population_context(name, value / scale, sex or model.gender)
        row["population"], row["population_z"] = pop, None if pop is None else pop["z"]
        if row.get("truth_anny") is not None:
            row["error_anny"] = value - row["truth_anny"]
        if row.get("truth") is not None:
            row["error"] = value - row["truth"]
            row["truth_in_ci95"] = bool(row["ci95"][0] <= row["truth"] <= row["ci95"][1])
        elif same.get(name) is not None:
            row["truth"], row["error"] = float(same[name]) * scale, value - float(same[name]) * scale
        if name == "stature" and standing is not None:
            row["method"] = standing
        elif clothing == "loose" and (flag := loose_flag(name)) is not None:
            _flag(row, flag)
        if warning:
            _flag(row, warning)
        out[name] = row
    return out


def write_measurements_csv(path, table: dict) -> Path:
    """The table as CSV: name, unit, mean, std, status, flags, truth, error, truth_anny,
    error_anny, clause, sigma, ci95_low, ci95_high, iso20685_max_error, iso20685_ok, percentile,
    z, then one column per frame."""
    import csv

    from rigs.atomic import atomic_open

    frames = sorted({f for row in table.values() for f in row["per_frame"]}, key=int)
    with atomic_open(path, "w", newline="", mkdir=True) as fh:
        w = csv.writer(fh)
        w.writerow(["name", "unit", "mean", "std", "status", "flags", "truth", "error", "truth_anny", "error_anny",
                    "clause", "sigma", "ci95_low", "ci95_high", "iso20685_max_error", "iso20685_ok", "percentile", "z"]
                   + [f"frame_{f}" for f in frames])
        for name, row in table.items():
            fmt = (lambda v: "" if v is None else f"{v:.2f}")
            ci = row.get("ci95") or [None, None]
            pop = row.get("population") or {}
            ok = row.get("iso20685_ok")
            w.writerow([name, row["unit"], fmt(row["mean"]), fmt(row["std"]), row.get("status", "ok"),
                        "; ".join(row.get("flags", [])), fmt(row["truth"]), fmt(row["error"]),
                        fmt(row.get("truth_anny")), fmt(row.get("error_anny")), row.get("clause", ""),
                        fmt(row.get("sigma")), fmt(ci[0]), fmt(ci[1]), fmt(row.get("iso20685_max_error")),
                        "" if ok is None else ("yes" if ok else "no"), fmt(pop.get("percentile")), fmt(pop.get("z"))]
                       + [fmt(row["per_frame"].get(f)) for f in frames])
    return Path(path)


def write_measurements(layout, table: dict, participant: dict | None = None) -> tuple[Path, Path]:
    """``report/measurements.json`` (with the ``participant``) and ``report/measurements.csv``
    (:func:`write_measurements_csv`) of a session (a :class:`~studio.workspace.Layout` or a
    session folder)."""
    from rigs.atomic import atomic_write_json
    from studio.workspace import Layout

    layout = layout if isinstance(layout, Layout) else Layout(layout)
    layout.report_dir.mkdir(parents=True, exist_ok=True)
    jp = atomic_write_json(layout.report_measurements_json,
                           {"format": "studio.measurements", "version": 2, "participant": participant or {},
                            "measurements": table})
    return jp, write_measurements_csv(layout.report_measurements_csv, table)


def load_truth(layout) -> dict | None:
    """The simulator's true measurements of a session (:class:`~studio.workspace.Layout` or folder), or None."""
    from studio.workspace import Layout

    p = (layout if isinstance(layout, Layout) else Layout(layout)).truth_measurements
    return json.loads(p.read_text()) if p.is_file() else None
