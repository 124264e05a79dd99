"""Uncertainty of the reported measurements: three independent sources, combined.

1. **Frames**: the spread of the per-frame values over the frames used (the body's shape does
   not change between frames), as the standard error of their mean, ``std / √n``.
2. **Calibration**: a reprojection error of ``e`` px at distance ``Z`` with focal length ``f``
   moves a silhouette's back-projected boundary by ``e·Z / f`` metres; ``N`` views averaging
   independent errors give ``σ_b = sqrt(mean_i (e_i Z_i / f_i)²) / √N`` per surface point.
   A height, breadth, depth or length spans two such points: ``√2·σ_b``; a girth moves with the
   section's radius: ``2π·σ_b``; the volume with the surface area: ``A·σ_b`` (× density for
   mass); BMI by first-order propagation from mass and stature. The reprojection error per
   camera comes from the calibration's metadata (bundle adjustment or intrinsic RMS);
   a simulated session's calibration is exact (0 px); an unknown one is taken as
   :data:`ASSUMED_RMS_PX` and said so.
3. **Fit posterior** (Laplace approximation): the silhouette cost (eq. 4.6) as a negative log
   likelihood at a temperature (:func:`load_model_error`; cost units, i.e. pixels of mean silhouette
   disagreement) plus the model's Gaussian shape prior N(0, σ²) on the leading
   :data:`N_LEADING` shape coefficients (those the fitter frees), pose held at the fit; its
   Hessian by central differences of the cost at full resolution (the level the fit ends at)
   with steps of ``STEP`` σ (:func:`shape_hessian`), the covariance carried into every
   measurement through its Jacobian (central differences of :func:`studio.body.measure`).
4. **Model**: what the first three do not see — the body model's and the fit's own error on
   people it never saw (a SCAPE body is not an Anny body: e.g. girths +25 mm, arm span −29 mm on
   the pose benchmark's dev people, the same sign for nearly everyone). One standard uncertainty
   per measurement (:data:`MODEL_ERROR_FILE`), learned by ``benchmarks/measurement_intervals.py
   calibrate`` on the dev split of ``benchmarks/pose_accuracy.py`` as the root mean square error
   the other three leave unexplained; its coverage is measured on the held-out split.

The combined standard uncertainty is the root sum of squares, the 95 % interval ±1.96 of it.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

import numpy as np

__all__ = [
    "ASSUMED_RMS_PX",
    "MODEL_ERROR_FILE",
    "N_LEADING",
    "calibration_rms",
    "calibration_sigma",
    "calibration_terms",
    "combine",
    "laplace_shape_covariance",
    "load_model_error",
    "measurement_jacobian",
    "measurement_sd",
    "posterior_covariance",
    "session_uncertainty",
    "shape_hessian",
]

log = logging.getLogger(__name__)

#: reprojection error assumed for a calibration that records none (pixels)
ASSUMED_RMS_PX = 0.5
#: shape coefficients the posterior covers (the leading PCA directions)
N_LEADING = 10
#: finite-difference step in prior standard deviations: the cost at full resolution is smooth over
#: ±2 σ of a coefficient (dev frames), a 0.25 σ step moves it by 0.004–0.05, near the rasterisation's noise
STEP = 0.5
#: the model-error calibration (module doc, 4.): temperature and {measurement: σ (SI)}
MODEL_ERROR_FILE = Path(__file__).with_name("data") / "model_error.json"


def load_model_error(path: Path = MODEL_ERROR_FILE) -> dict:
    """The shipped calibration: ``{"temperature": T, "model_sigma": {name: σ SI}, "source": ...}``.

    ``temperature``: cost units per unit of negative log likelihood (module doc, 3.), chosen so that
    a single frame's posterior explains the spread of its measurements over the person's other frames
    (pooled median |z| = 0.674 on the pose benchmark's dev people); ``model_sigma`` (module doc, 4.)."""
    try:
        obj = json.loads(Path(path).read_text())
        return {"temperature": float(obj["temperature"]), "model_sigma": {k: float(v) for k, v in obj["model_sigma"].items()},
                "source": str(obj.get("source", path))}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: not a model-error calibration ({exc}); rebuild it with "
                         "`benchmarks/measurement_intervals.py calibrate`") from exc


def calibration_rms(calibration) -> tuple[dict[str, float], str]:
    """({camera: reprojection RMS px}, where it came from) of a :class:`~calibration.RigCalibration`."""
    meta = dict(getattr(calibration, "metadata", {}) or {})
    names = list(calibration.cameras)
    ext = meta.get("extrinsics")
    if isinstance(ext, dict) and isinstance(ext.get("camera_rms_px"), dict):
        per = ext["camera_rms_px"]
        return {n: float(per.get(n, ext.get("rms_px", ASSUMED_RMS_PX))) for n in names}, "bundle adjustment"
    intr = meta.get("intrinsics")
    if isinstance(intr, dict) and all(isinstance(intr.get(n), dict) and "rms_px" in intr[n] for n in names):
        return {n: float(intr[n]["rms_px"]) for n in names}, "intrinsic calibration"
    if meta.get("source") == "studio simulate":
        return {n: 0.0 for n in names}, "simulated (exact calibration)"
    return {n: ASSUMED_RMS_PX for n in names}, f"none recorded: {ASSUMED_RMS_PX} px assumed"


def calibration_sigma(cameras, rms: dict, centre) -> float:
    """σ_b (metres) of a surface point at ``centre`` (3,) (module doc, 2.)."""
    c = np.asarray(centre, dtype=np.float64)
    terms = []
    for cam in cameras:
        z = float((cam.R @ c + np.ravel(cam.t))[2])
        f = float(0.5 * (cam.K[0, 0] + cam.K[1, 1]))
        terms.append((rms.get(cam.name, ASSUMED_RMS_PX) * abs(z) / f) ** 2)
    return float(np.sqrt(np.mean(terms) / len(terms))) if terms else 0.0


def calibration_terms(sigma_b: float, values: dict, area: float, density: float = 980.0) -> dict[str, float]:
    """{measurement: standard uncertainty (SI)} from a surface uncertainty ``sigma_b`` (module doc, 2.)."""
    from studio.body.iso7250 import DEFINITIONS

    out = {}
    for d in DEFINITIONS:
        if d.kind in ("height", "breadth", "depth", "length"):
            out[d.name] = np.sqrt(2.0) * sigma_b
        elif d.kind in ("small_girth", "large_girth"):
            out[d.name] = 2 * np.pi * sigma_b
    out["mass"] = density * area * sigma_b
    m, s = values["mass"], values["stature"]
    out["bmi"] = float(np.hypot(out["mass"] / s**2, 2 * m / s**3 * out["stature"]))
    return {k: float(v) for k, v in out.items()}


def measurement_jacobian(model, shape, names, k: int = N_LEADING) -> np.ndarray:
    """(M, k) derivatives of measurements ``names`` w.r.t. the first ``k`` shape coefficients
    (central differences of 0.1 σ)."""
    from studio.body import measure

    sigma = np.sqrt(np.asarray(model.eigenvalues, dtype=np.float64))
    J = np.zeros((len(names), k))
    for i in range(k):
        h = 0.1 * sigma[i]
        d = np.zeros_like(np.asarray(shape, dtype=np.float64))
        d[i] = h
        hi, lo = measure(model, shape + d), measure(model, shape - d)
        J[:, i] = [(hi[n] - lo[n]) / (2 * h) for n in names]
    return J


def shape_hessian(model, cameras, masks, shape, pose, *, level: int = 0, k: int = N_LEADING):
    """((k, k) Hessian of the silhouette cost in the first ``k`` shape coefficients, (k,) their prior
    σ) at one fitted frame, pose held (module doc, 3.).

    Central differences with steps ``h = STEP`` σ: the diagonal from ``±h e_i``, each pair from
    ``±(h e_i + h e_j)``; a direction whose curvature comes out ≤ 0 (the cost's kinks: the sum of
    the pair terms is not exactly quadratic) is measured again along itself, so no direction
    falls back on the prior. (The first release fitted a quadratic to random sign vectors at
    level 1, where the cost's minimum is not at the fit: 3–5 of 10 curvatures came out ≤ 0 on every
    dev frame and the prior's population spread stood as the posterior, waist σ 84 mm.)
    """
    from studio.fit.frame import FitOptions, build_targets
    from studio.fit.objective import FrameObjective

    targets = build_targets(list(masks), [c.name for c in cameras], FitOptions(levels=(level, level, level)))
    obj = FrameObjective(model, list(cameras), targets, np.asarray(shape, dtype=np.float64), n_shape_free=k)
    x0 = obj.pack(shape, pose)
    sigma = np.sqrt(np.asarray(model.eigenvalues, dtype=np.float64))[:k]
    h = STEP * sigma

    def costs(D):
        X = np.repeat(x0[None], len(D), axis=0)
        X[:, -k:] += D * h
        return obj(X, level)

    i, j = np.triu_indices(k, 1)
    pairs = np.zeros((len(i), k))
    pairs[np.arange(len(i)), i] = pairs[np.arange(len(i)), j] = 1.0
    c = costs(np.concatenate([np.zeros((1, k)), np.eye(k), -np.eye(k), pairs, -pairs]))
    c0, axis = c[0], c[1:1 + k] + c[1 + k:1 + 2 * k]
    H = np.diag(axis - 2 * c0)
    cross = c[1 + 2 * k:1 + 2 * k + len(i)] + c[1 + 2 * k + len(i):]
    H[i, j] = H[j, i] = 0.5 * (cross - axis[i] - axis[j] + 2 * c0)
    w, V = np.linalg.eigh(H)
    bad = np.flatnonzero(w <= 0)
    if len(bad):
        again = costs(np.concatenate([V[:, bad].T, -V[:, bad].T]))
        w[bad] = np.maximum(again[:len(bad)] + again[len(bad):] - 2 * c0, 0.0)
    return (V * w) @ V.T / np.outer(h, h), sigma


def laplace_shape_covariance(model, cameras, masks, shape, pose, *, level: int = 0, k: int = N_LEADING,
                             temperature: float | None = None) -> np.ndarray:
    """(k, k) posterior covariance of the first ``k`` shape coefficients of one fitted frame
    (module doc, 3.): the cost's Hessian (:func:`shape_hessian`) over T (default: the shipped
    calibration's, :func:`load_model_error`), plus the prior's 1/σ²."""
    temperature = load_model_error()["temperature"] if temperature is None else float(temperature)
    return posterior_covariance(*shape_hessian(model, cameras, masks, shape, pose, level=level, k=k), temperature)


def posterior_covariance(H, sigma, temperature: float) -> np.ndarray:
    """(k, k) Laplace covariance from the cost's Hessian ``H`` (k, k) at temperature T and the prior's
    σ (k,): ``(H / T + diag(1/σ²))⁻¹`` (module doc, 3.)."""
    return np.linalg.inv(np.asarray(H) / temperature + np.diag(1.0 / np.asarray(sigma) ** 2))


def measurement_sd(J, C) -> np.ndarray:
    """(M,) standard deviations of measurements with Jacobian ``J`` (M, k) under covariance ``C`` (k, k)."""
    J = np.asarray(J)
    return np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", J, C, J), 0.0))


def combine(*sigmas) -> float:
    """Root sum of squares of the standard uncertainties given (None skipped)."""
    return float(np.sqrt(sum(s * s for s in sigmas if s is not None)))


def session_uncertainty(model, cameras, calibration, fits: dict, frames, masks_of, *, max_frames: int = 3,
                        temperature: float | None = None) -> dict:
    """The calibration, posterior and model components (module doc) of a fitted session:
    ``{"calibration": {name: σ}, "posterior": {name: σ}, "model": {name: σ}, "info": {...}}`` (SI units).

    ``fits`` {frame: FrameFit}; ``frames`` the frames the measurements rest on; ``masks_of``
    ``frame -> list of (H, W) bool`` in ``cameras`` order, or None (no posterior: the session's
    segmentation is not at hand). The posterior averages the Laplace covariances of at most
    ``max_frames`` of ``frames``; ``temperature`` defaults to the shipped calibration's.
    """
    from studio.body import measure
    from studio.body.iso7250 import ISO_NAMES

    frames = list(frames)
    model_error = load_model_error()
    temperature = model_error["temperature"] if temperature is None else float(temperature)
    shape = np.mean([fits[f].shape for f in frames], axis=0)
    rms, source = calibration_rms(calibration)
    first = fits[frames[0]]
    V = model.vertices(first.shape, first.pose)
    sigma_b = calibration_sigma(cameras, rms, V.mean(axis=0))
    rest = model.vertices(shape)
    a, b, c = (rest[model.faces[:, i]] for i in range(3))
    area = float(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())
    values = measure(model, shape)
    out = {"calibration": calibration_terms(sigma_b, values, area), "posterior": {},
           "model": model_error["model_sigma"],
           "info": {"calibration_rms_px": rms, "calibration_rms_source": source,
                    "surface_sigma_mm": 1000 * sigma_b, "posterior_frames": [], "n_leading": N_LEADING,
                    "temperature": temperature, "model_error_source": model_error["source"]}}
    if masks_of is None:
        out["info"]["posterior_note"] = "no segmentation at hand: fit posterior not computed"
        return out
    covs = []
    for f in frames[:max_frames]:
        try:
            covs.append(laplace_shape_covariance(model, cameras, masks_of(f), fits[f].shape, fits[f].pose,
                                                 temperature=temperature))
            out["info"]["posterior_frames"].append(int(f))
        except (OSError, ValueError) as exc:
            log.warning("frame %s: no posterior (%s)", f, exc)
    if not covs:
        out["info"]["posterior_note"] = "no frame's silhouettes could be read: fit posterior not computed"
        return out
    C = np.mean(covs, axis=0)
    J = measurement_jacobian(model, shape, ISO_NAMES)
    sd = measurement_sd(J, C)
    out["posterior"] = {n: float(s) for n, s in zip(ISO_NAMES, sd, strict=True)}
    return out
