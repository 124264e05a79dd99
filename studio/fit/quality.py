"""Quality gates: can the toolkit vouch for a fitted frame? (figures, reasons, a status)

A fit always returns numbers; these checks say whether to believe them. Every check gives
its figures, and past a threshold a *reason* with a severity (``suspect`` or ``failed``);
the frame's ``status`` is the worst severity, ``ok`` when there is none.

1. **Segmentation sanity**, before any fitting (:func:`screen_masks`), per view: the share of
   the image the mask covers (most of the image: the background model failed, "all person"),
   an empty or tiny mask, disconnected blobs, a silhouette cut by the image border, and the
   share of each silhouette the visual hull of all views explains (a view that the others
   cannot explain has a wrong calibration or a wrong mask). A frame ``failed`` here is not
   fitted at all: a 2.2 m person read off an all-person mask is never produced.
2. **Silhouette agreement** of the fitted body with the observed masks (pixel precision and
   recall, pooled and per view) and the silhouette cost per view (eq. 4.6).
3. **Shape prior**: the shape coefficients' distance from the mean in σ (eq. 6.8); a
   coefficient at the optimiser's ±3 σ bound means the model could not explain the person.
4. **Population plausibility**: z-scores of stature, mass and chest / waist / hip girths
   against the ANSUR II survey (:data:`POPULATION_FILE`, a summary rebuilt from the survey's
   CSVs by :func:`summarise_ansur`), the sex of the fitted model (both sexes for ``neutral``:
   the smaller |z|).

Thresholds are module constants below, set from what the simulator's clean frames and the
purpose-made bad inputs of ``tests/test_quality.py`` give — never from the benchmark's
held-out people.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

__all__ = [
    "POPULATION_FILE",
    "QUALITY_VERSION",
    "Reason",
    "fit_quality",
    "population",
    "pool_any",
    "population_z",
    "refused_quality",
    "screen_masks",
    "status_of",
    "summarise_ansur",
    "summary_line",
]

QUALITY_VERSION = 1
POPULATION_FILE = Path(__file__).resolve().parent / "data" / "ansur2_summary.json"

#: share of the image a silhouette may cover before the mask is "most of the image"
MAX_COVERAGE = 0.45
#: fewer silhouette pixels than this share of the image: an empty / vanishing mask
MIN_COVERAGE = 2e-4
#: a second blob counts when its area is at least this share of the largest
BLOB_SHARE = 0.05
#: silhouette pixels on the image border (share of the mask's height + width) before "cut off"
BORDER_SHARE = 0.05
#: share of a view's silhouette the visual hull must explain (suspect, failed)
HULL_EXPLAINED = (0.80, 0.55)
#: pooled silhouette precision / recall of the fitted body (suspect below, failed below). Chosen
#: on the dev people of benchmarks/pose_accuracy.py (32 fits, never the held-out ones): every fit
#: closer than 10 mm to the true body had min(P, R) ≥ 0.936; at 0.90, 8 of the 13 fits worse than
#: 15 mm were flagged, at 0.93 12 of 13 (the one left: 15.0 mm at 0.941), plus two at 11.7 and
#: 12.9 mm (0.922, 0.919).
AGREEMENT = (0.93, 0.75)
#: one view's precision or recall below this: suspect
VIEW_AGREEMENT = 0.80
#: a shape coefficient this many σ from the mean is at the optimiser's bound (±3 σ)
SHAPE_BOUND_SIGMA = 2.9
#: |z| against ANSUR II (suspect above, failed above)
POPULATION_Z = (3.5, 5.0)
#: a frame fitted from one view and its shadow takes its depth from the light: an estimated light
#: whose 95 % interval is wider than this (direction in degrees, distance in percent either way)
#: makes it suspect. The walk's light from 10 frames of 4 views: 2.0°, −10..+8 %; the monocular
#: sample's light from its own silhouette-only fits: 7.1°, −21..+81 % (those fits: 110 mm off).
LIGHT_CI = (3.0, 15.0)

#: our measurement name → (ANSUR II column, factor to SI units)
ANSUR_COLUMNS = {
    "stature": ("stature", 1e-3),
    "mass": ("weightkg", 0.1),
    "chest_circumference": ("chestcircumference", 1e-3),
    "waist_circumference": ("waistcircumference", 1e-3),
    "hip_circumference": ("buttockcircumference", 1e-3),
}


@dataclass(frozen=True)
class Reason:
    """Why a frame is not ``ok``: ``check`` (e.g. ``"coverage"``), ``severity`` (``suspect`` or
    ``failed``), ``view`` (camera name or None), ``message`` (a sentence with the figure)."""

    check: str
    severity: str
    message: str
    view: str | None = None

    def to_json(self) -> dict:
        return {"check": self.check, "severity": self.severity, "view": self.view, "message": self.message}


def status_of(reasons) -> str:
    """``failed`` if any reason is, else ``suspect`` if there is any reason, else ``ok``."""
    sev = {r["severity"] if isinstance(r, dict) else r.severity for r in reasons}
    return "failed" if "failed" in sev else "suspect" if sev else "ok"


# --------------------------------------------------------------------------- population
def read_ansur(folder: str | Path, columns: dict[str, tuple[str, float]]) -> dict[str, dict[str, np.ndarray]]:
    """Per sex, ``{name: values (SI units)}`` of ANSUR II's public CSVs in ``folder``
    (``ANSUR_II_{FEMALE,MALE}_Public.csv``) for ``columns`` {name: (CSV column, factor to SI)};
    a missing file, column or number is named in the error."""
    import csv

    folder = Path(folder)
    out = {}
    for sex in ("female", "male"):
        path = folder / f"ANSUR_II_{sex.upper()}_Public.csv"
        if not path.is_file():
            raise FileNotFoundError(f"{path}: ANSUR II CSV not found")
        with path.open(newline="", encoding="latin-1") as fh:
            rows = list(csv.DictReader(fh))
        cols = {}
        for name, (column, factor) in columns.items():
            try:
                cols[name] = np.array([float(r[column]) for r in rows]) * factor
            except KeyError:
                raise ValueError(f"{path}: no column {column!r}") from None
            except ValueError as exc:
                raise ValueError(f"{path}: column {column!r}: {exc}") from None
        out[sex] = cols
    return out


#: Where :func:`read_ansur` read its figures from.
ANSUR_SOURCE = "ANSUR II public release (US Army 2012), ANSUR_II_{FEMALE,MALE}_Public.csv"


def summarise_ansur(folder: str | Path) -> dict:
    """Summary statistics (SI units) of ANSUR II's public CSVs in ``folder``, per sex:
    ``{"female"|"male": {name: {"n", "mean", "std", "p01", "p99", "min", "max"}}}``."""
    sexes = {
        sex: {name: {"n": int(len(v)), "mean": float(v.mean()), "std": float(v.std(ddof=1)),
                     "p01": float(np.percentile(v, 1)), "p99": float(np.percentile(v, 99)),
                     "min": float(v.min()), "max": float(v.max())} for name, v in cols.items()}
        for sex, cols in read_ansur(folder, ANSUR_COLUMNS).items()
    }
    return {"format": "studio.population", "version": 1, "source": ANSUR_SOURCE, "sexes": sexes}


@lru_cache(maxsize=1)
def population() -> dict:
    """The shipped ANSUR II summary (:data:`POPULATION_FILE`)."""
    return json.loads(POPULATION_FILE.read_text())


def population_z(measurements: dict, gender: str) -> dict[str, float]:
    """z-scores of ``measurements`` (metres, kg; names of :func:`studio.body.measure`) against
    ANSUR II of ``gender`` (``neutral``: the sex giving the smaller |z| per measurement)."""
    sexes = population()["sexes"]
    use = [gender] if gender in sexes else list(sexes)
    out = {}
    for name in ANSUR_COLUMNS:
        if measurements.get(name) is None or not np.isfinite(measurements[name]):
            continue
        zs = [(measurements[name] - sexes[s][name]["mean"]) / sexes[s][name]["std"] for s in use]
        out[name] = float(min(zs, key=abs))
    return out


# --------------------------------------------------------------------------- segmentation
def pool_any(mask: np.ndarray, factor: int) -> np.ndarray:
    """(ceil(H / factor), ceil(W / factor)) bool: cells holding any pixel of ``mask``."""
    h, w = mask.shape
    out = np.zeros((-(-h // factor), -(-w // factor)), dtype=bool)
    ys, xs = np.nonzero(mask)
    out[ys // factor, xs // factor] = True
    return out


def _blobs(mask: np.ndarray) -> list[int]:
    import cv2

    n, _, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    return sorted((int(a) for a in stats[1:, cv2.CC_STAT_AREA]), reverse=True)


def hull_hits(cameras, masks, *, step: float = 0.03, factor: int = 4) -> list[np.ndarray]:
    """Per view, the cells (masks pooled by ``factor``, :func:`pool_any`) onto which the visual
    hull of all views projects: a coarse grid of ``step`` m around the hull's floor centroid,
    carved by every mask, projected back and closed by one cell."""
    import cv2

    from studio.fit.init import _in_mask, hull_centroid

    xy = hull_centroid(cameras, masks)
    g = np.arange(-1.3, 1.3 + 1e-9, step)
    zs = np.arange(0.0, 2.5, step)
    X, Y, Z = np.meshgrid(xy[0] + g, xy[1] + g, zs, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    inside = np.ones(len(pts), dtype=bool)
    for cam, mask in zip(cameras, masks, strict=True):
        inside[inside] = _in_mask(cam, mask, pts[inside])
    hull = pts[inside]
    out = []
    for cam, mask in zip(cameras, masks, strict=True):
        h, w = mask.shape
        hit = np.zeros(pool_any(mask, factor).shape, dtype=bool)
        if len(hull):
            uv, _, front = cam.project_points(hull)
            ok = front & np.isfinite(uv).all(axis=1)
            u = np.clip(np.rint(uv[ok, 0]).astype(int), 0, w - 1) // factor
            v = np.clip(np.rint(uv[ok, 1]).astype(int), 0, h - 1) // factor
            hit[v, u] = True
            # the grid is coarser than a pooled pixel far from the camera: close the gaps
            hit = cv2.dilate(hit.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        out.append(hit)
    return out


def _hull_explained(cameras, masks, *, step: float = 0.03, factor: int = 4) -> list[float]:
    """Share of every view's silhouette covered by the projection of the visual hull of all
    views (:func:`hull_hits`). A view inconsistent with the others (wrong calibration, wrong
    mask) is carved away by them and comes out poorly explained."""
    out = []
    for mask, hit in zip(masks, hull_hits(cameras, masks, step=step, factor=factor), strict=True):
        coarse = pool_any(mask, factor)
        n = int(np.count_nonzero(coarse))
        out.append(float(np.count_nonzero(hit & coarse) / n) if n else 0.0)
    return out


def screen_masks(cameras, masks, *, shadow: bool = False, light: dict | None = None) -> dict:
    """Segmentation sanity of one frame before fitting: ``{"views": {name: figures}, "reasons": [...],
    "status", "dropped": [names]}`` (see the module doc). ``cameras`` full-resolution, ``masks``
    (H, W) bool, same order.

    A view whose mask is empty or covers most of the image is *dropped*: the fit uses the
    others (the frame is then ``suspect``), or none when no view remains (``failed``). One view
    alone leaves the depth along its rays unobserved: with ``shadow`` (a known light, the shadow
    term of eq. 5.7) the cast shadow is the second view (thesis §5.5, the shadow camera);
    without it a one-camera frame is fitted but ``suspect``, the reason naming the view, and a
    rig left with one usable view is refused (``failed``: its segmentation failed). ``light``: the
    estimated light's 95 % intervals (``{"direction_ci_deg", "distance_ci": [lo, hi] %}``, see
    :func:`studio.light.light_uncertainty`; None: the light is known): one view with a light less
    certain than :data:`LIGHT_CI` is ``suspect``, the shadow's depth no better than the light.
    """
    from studio.fit.errors import FitError

    reasons: list[Reason] = []
    views = {}
    dropped = []
    for cam, m in zip(cameras, masks, strict=True):
        m = np.asarray(m, dtype=bool)
        h, w = m.shape
        n = int(np.count_nonzero(m))
        cover = n / float(h * w)
        blobs = _blobs(m) if n else []
        significant = [a for a in blobs if a >= BLOB_SHARE * blobs[0]] if blobs else []
        border = int(np.count_nonzero(m[0]) + np.count_nonzero(m[-1]) + np.count_nonzero(m[:, 0])
                     + np.count_nonzero(m[:, -1]))
        ys, xs = np.nonzero(m)
        extent = (ys.max() - ys.min() + 1) + (xs.max() - xs.min() + 1) if n else 1
        views[cam.name] = {"coverage": round(cover, 5), "blobs": len(significant),
                           "border_share": round(border / float(extent), 4)}
        if cover > MAX_COVERAGE:
            dropped.append(cam.name)
            reasons.append(Reason("coverage", "suspect", f"the silhouette covers {100 * cover:.0f}% of the image "
                                  f"(more than {100 * MAX_COVERAGE:.0f}%): background subtraction failed; view dropped",
                                  cam.name))
        elif cover < MIN_COVERAGE:
            dropped.append(cam.name)
            reasons.append(Reason("coverage", "suspect", f"the silhouette is empty or vanishing ({n} pixels); "
                                  "view dropped", cam.name))
        else:
            if len(significant) > 1:
                reasons.append(Reason("blobs", "suspect", f"{len(significant)} disconnected blobs in the silhouette",
                                      cam.name))
            if border / float(extent) > BORDER_SHARE:
                reasons.append(Reason("border", "suspect", f"the silhouette is cut by the image border ({border} "
                                      "pixels on the edge): part of the person is out of view", cam.name))
    used = [i for i, c in enumerate(cameras) if c.name not in dropped]
    if not used:
        reasons.append(Reason("views", "failed", "0 usable view(s): at least one (with a light) or two are needed"))
    elif len(used) == 1 and not shadow and len(cameras) > 1:  # a rig's views lost: a segmentation failure
        reasons.append(Reason("views", "failed", f"1 usable view of {len(cameras)}: at least two are needed "
                              "without a light's shadow"))
    elif len(used) == 1 and not shadow:
        name = cameras[used[0]].name
        reasons.append(Reason("views", "suspect", f"one usable view ({name}) and no shadow term: the depth along "
                              "its rays is unobserved (a second camera or a light's shadow fixes it)", name))
    else:
        if len(used) == 1 and light is not None:
            reasons += _light_reasons(light, cameras[used[0]].name)
        cams, ms = [cameras[i] for i in used], [masks[i] for i in used]
        try:
            explained = _hull_explained(cams, ms)
        except FitError as exc:
            explained = [0.0] * len(ms)
            reasons.append(Reason("hull", "failed", f"the views do not agree on any point in space ({exc})"))
        for cam, e in zip(cams, explained, strict=True):
            views[cam.name]["hull_explained"] = round(e, 4)
            sev = "failed" if e < HULL_EXPLAINED[1] else "suspect" if e < HULL_EXPLAINED[0] else None
            if sev:
                reasons.append(Reason("hull", sev, f"only {100 * e:.0f}% of the silhouette is explained by the visual "
                                      "hull of all views: wrong calibration or wrong mask in some view", cam.name))
    out = [r.to_json() for r in reasons]
    return {"views": views, "reasons": out, "status": status_of(out), "dropped": dropped,
            **({"shadow_view": True} if shadow and len(used) == 1 else {})}


def _light_reasons(light: dict, name: str) -> list[Reason]:
    """A reason when the light that gives one view its depth is too uncertain (:data:`LIGHT_CI`)."""
    direction = float(light.get("direction_ci_deg") or 0.0)
    lo, hi = light.get("distance_ci") or (0.0, 0.0)
    if direction <= LIGHT_CI[0] and max(-float(lo), float(hi)) <= LIGHT_CI[1]:
        return []
    return [Reason("light", "suspect", f"one view ({name}): its depth comes from the shadow, and the light is "
                   f"uncertain (95 % interval: direction {direction:.1f}°, distance {float(lo):+.0f}..{float(hi):+.0f} %; "
                   f"within {LIGHT_CI[0]:.0f}° and ±{LIGHT_CI[1]:.0f} % expected)", name)]


def refused_quality(screen: dict) -> dict:
    """The ``quality`` object of a frame the screen refused (status ``failed``): no body."""
    return {"version": QUALITY_VERSION, "status": "failed", "reasons": screen["reasons"], "views": screen["views"],
            "dropped_views": screen["dropped"], "segmentation_status": "failed"}


# --------------------------------------------------------------------------- the fitted frame
def fit_quality(model, cameras, masks, shape, pose, costs: dict, screen: dict | None = None,
                measurements: dict | None = None, ignore=None) -> dict:
    """The ``quality`` object of a fitted frame (format in the module doc): silhouette agreement
    with the observed ``masks``, cost per view, shape σ, population z-scores, the segmentation
    ``screen`` (:func:`screen_masks`, computed when None), ``reasons`` and ``status``.
    ``ignore``: per view, pixels the agreement leaves out, in the masks and in the body's
    silhouettes alike — the cost's don't-care region (a prop, :func:`studio.fit.props.find_support`)."""
    from studio.body import measure
    from studio.fit.evaluate import silhouette_agreement
    from studio.render import silhouette

    screen = screen_masks(cameras, masks) if screen is None else screen
    reasons: list[Reason] = []
    V = model.vertices(shape, pose)
    sils = [silhouette(cam, V, model.faces) for cam in cameras]
    if ignore is not None:
        sils = [s & ~i for s, i in zip(sils, ignore, strict=True)]
        masks = [np.asarray(m, dtype=bool) & ~i for m, i in zip(masks, ignore, strict=True)]
    per_view = {}
    for cam, sil, obs in zip(cameras, sils, masks, strict=True):
        p, r = silhouette_agreement([sil], [obs])
        per_view[cam.name] = {"precision": round(p, 4), "recall": round(r, 4),
                              "cost": round(float(costs.get("silhouette_per_view", {}).get(cam.name, np.nan)), 4)}
        if min(p, r) < VIEW_AGREEMENT:
            reasons.append(Reason("view_agreement", "suspect", f"the fitted body matches this view poorly "
                                  f"(precision {p:.2f}, recall {r:.2f})", cam.name))
    precision, recall = silhouette_agreement(sils, masks)
    worst = min(precision, recall)
    sev = "failed" if worst < AGREEMENT[1] else "suspect" if worst < AGREEMENT[0] else None
    if sev:
        reasons.append(Reason("agreement", sev, f"the fitted body explains the silhouettes poorly (precision "
                              f"{precision:.2f}, recall {recall:.2f}; {AGREEMENT[0]:.2f} expected)"))
    sigma = np.sqrt(np.asarray(model.eigenvalues, dtype=np.float64))
    s = np.asarray(shape, dtype=np.float64) / sigma
    max_sigma = float(np.max(np.abs(s)))
    if max_sigma >= SHAPE_BOUND_SIGMA:
        k = int(np.argmax(np.abs(s)))
        reasons.append(Reason("shape_prior", "suspect", f"shape coefficient {k} at {s[k]:+.1f} σ, the bound of "
                              "the model: it could not explain this person"))
    meas = measure(model, shape) if measurements is None else measurements
    z = population_z(meas, model.gender)
    for name, v in z.items():
        sev = "failed" if abs(v) > POPULATION_Z[1] else "suspect" if abs(v) > POPULATION_Z[0] else None
        if sev:
            unit, scale = ("kg", 1.0) if name == "mass" else ("mm", 1000.0)
            reasons.append(Reason("population", sev, f"{name.replace('_', ' ')} {scale * meas[name]:.0f} {unit} is "
                                  f"{v:+.1f} σ from ANSUR II ({model.gender}): implausible"))
    reasons = [dict(r) for r in screen["reasons"]] + [r.to_json() for r in reasons]
    return {
        "version": QUALITY_VERSION,
        "status": status_of(reasons),
        "reasons": reasons,
        "silhouette_precision": round(precision, 4),
        "silhouette_recall": round(recall, 4),
        "views": {name: per_view.get(name, {}) | figures for name, figures in screen["views"].items()},
        "dropped_views": list(screen.get("dropped", [])),
        "shape_sigma_max": round(max_sigma, 3),
        "shape_sigma_norm": round(float(np.linalg.norm(s)), 3),
        "population_z": {k: round(v, 2) for k, v in z.items()},
        "segmentation_status": screen["status"],
    }


def summary_line(qualities: dict) -> str:
    """One line over ``{frame: quality}``: counts by status and the flagged frames with their
    first reason, e.g. ``"22 ok, 1 suspect, 1 failed — frame 7 failed: ..."``."""
    counts = {s: 0 for s in ("ok", "suspect", "failed", "unchecked")}
    flagged = []
    for f in sorted(qualities):
        q = qualities[f]
        counts[q["status"]] += 1
        if q["status"] in ("suspect", "failed"):
            r = q["reasons"][0]
            flagged.append(f"frame {f} {q['status']}: {(r['view'] + ': ') if r.get('view') else ''}{r['message']}")
    head = ", ".join(f"{n} {s}" for s, n in counts.items() if n)
    if not flagged:
        return head
    more = f" (+{len(flagged) - 3} more)" if len(flagged) > 3 else ""
    return head + " — " + "; ".join(flagged[:3]) + more
