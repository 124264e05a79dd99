"""Estimating the light(s) from bodies and segmented shadows over several frames (thesis §5.7).

1. Refuse scenes whose shadows cannot fix a light: fewer than ``MIN_SHADOW_FRAMES`` frames with
   at least ``MIN_SHADOW_PIXELS`` observed shadow pixels in some view (:class:`LightError`).
2. Search each candidate kind — ``point``, ``directional``, or both for ``auto`` — on the coarse
   grid (288 hypotheses, every other frame, images at ``level`` + 1 if large enough) then 7×7×7
   refinements down to 5 mm, the last on every frame (:func:`studio.light.search.search_lights`,
   eq. 5.9).
3. ``auto`` keeps the kind with the lower Bayesian information criterion
   ``n ln(E/n) + k ln n`` (n the frame × view terms, k the parameters): a point light far away
   casts the shadows of a directional one, and then the simpler model wins.
4. A light that leaves most of the shadow unexplained (E above ``MAX_UNEXPLAINED`` × the cost
   of casting no shadow at all) is refused: the shadows are not those of such a light.
5. Optionally (``refine_floor``) the ground plane from the shadows, alternating with the
   light's last refinement (:mod:`studio.light.floor`).
6. The posterior by emcee (:mod:`studio.light.posterior`): credible intervals, effective sample
   size; a sample scoring below the search's answer replaces it.
"""

from __future__ import annotations

import functools
import logging
import time
from dataclasses import dataclass, field

import numpy as np

from studio.light.objective import ShadowFrame
from studio.light.params import KINDS, N_PARAMS, Frame, direction_of, to_light
from studio.light.pool import evaluators
from studio.light.posterior import sample_posterior, summarise
from studio.light.search import polish_lights, search_lights

__all__ = ["GRID_MIN_PIXELS", "LightError", "LightEstimate", "MAX_UNEXPLAINED", "MIN_SHADOW_FRAMES",
           "MIN_SHADOW_PIXELS", "coarse_level", "estimate_light"]

log = logging.getLogger(__name__)

#: A frame counts as showing a shadow with at least this many shadow pixels in some view.
MIN_SHADOW_PIXELS = 150
#: At least this many frames must show a shadow.
MIN_SHADOW_FRAMES = 2
#: Refuse a light whose cost is above this fraction of the no-shadow cost.
MAX_UNEXPLAINED = 0.5
#: At most this many posterior samples are stored in light.json (thinned evenly), for the figures.
MAX_STORED_SAMPLES = 400
#: Give up after the coarse grid when its best costs more than this fraction of no shadow.
HOPELESS = 0.8
#: Floor refinement: alternations of the floor's grid (light held) and the light's last stage (floor held).
FLOOR_SWEEPS = 2
#: The coarse grid scores images half the working level's size while their smaller side keeps this many pixels.
GRID_MIN_PIXELS = 60


def coarse_level(cameras, level: int) -> int:
    """The pyramid level of the coarse grid and its first rounds: ``level`` + 1 when the smallest
    view is still ``GRID_MIN_PIXELS`` across there, else ``level``."""
    smallest = min(min(c.size) for c in cameras)
    return level + 1 if level < 8 and smallest / 2 ** (level + 1) >= GRID_MIN_PIXELS else level


class LightError(ValueError):
    """The light cannot be estimated from these frames; the message says why."""


@dataclass(frozen=True, eq=False)
class LightEstimate:
    """The estimated light(s): ``kind``, ``lights`` (PointLight / DirectionalLight), ``thetas``
    their parameters, ``cost`` E at the answer, ``intervals`` one :func:`summarise` dict per
    light, ``posterior`` (:class:`~studio.light.posterior.Posterior`), ``centre`` the subject's
    centre, ``candidates`` {kind: {cost, bic, ...}}, ``timings`` (s), ``floor`` the refined
    ground plane against the calibration's (:func:`studio.light.floor.describe_floor`; None
    unless asked for)."""

    kind: str
    lights: list
    thetas: list
    cost: float
    empty_cost: float
    intervals: list
    posterior: object
    centre: np.ndarray
    candidates: dict
    timings: dict
    frames: list
    n_evaluations: int
    settings: dict = field(default_factory=dict)
    floor: dict | None = None

    def to_json(self) -> dict:
        frame = Frame(self.centre)
        lights = []
        for light, theta, ci in zip(self.lights, self.thetas, self.intervals, strict=True):
            entry = {"kind": self.kind, "direction": direction_of(light, frame).round(9).tolist(),
                     "azimuth_deg": float(np.degrees(theta[0])), "elevation_deg": float(np.degrees(theta[1])),
                     "direction_ci_deg": ci["direction_ci_deg"]}
            if self.kind == "point":
                entry["position"] = light.position.round(6).tolist()
                entry["distance_m"] = float(theta[2])
                entry["distance_ci"] = ci["distance_ci"]
                entry["distance_ci_m"] = ci["distance_ci_m"]
            entry["samples"] = {k: ci[k] for k in ("parameter_mean", "parameter_sd", "direction_sd_deg")}
            lights.append(entry)
        post = self.posterior
        out = {"format": "studio.light", "version": 1, "kind": self.kind, "n_lights": len(self.lights)}
        out.update({k: v for k, v in lights[0].items() if k != "kind"})
        out.update({
            "lights": lights,
            "credible_level": 0.95,
            "units": {"position": "m", "direction_ci_deg": "degrees", "distance_ci": "percent of distance_m"},
            "centre": self.centre.round(6).tolist(),
            "cost": self.cost,
            "no_shadow_cost": self.empty_cost,
            "candidates": self.candidates,
            "samples_summary": {
                "sampler": "emcee EnsembleSampler (DE + snooker moves)", "parameters": self.parameter_names(),
                "n_walkers": post.n_walkers, "n_steps": post.n_steps, "burn_in": post.burn,
                "n_samples": int(len(post.samples)), "acceptance": post.acceptance,
                "autocorr_steps": post.autocorr.tolist(), "effective_sample_size": post.ess,
                "chain_over_autocorr": float((post.n_steps - post.burn) / max(float(np.max(post.autocorr)), 1.0)),
                "temperature": post.temperature,
            },
            "samples": np.round(post.samples[:: max(1, len(post.samples) // MAX_STORED_SAMPLES)], 6).tolist(),
            "frames": self.frames,
            "n_evaluations": self.n_evaluations,
            "timings": {k: round(v, 3) for k, v in self.timings.items()},
            "settings": self.settings,
        })
        if self.floor is not None:
            out["floor"] = self.floor
        return out

    def parameter_names(self) -> list[str]:
        names = ["azimuth_rad", "elevation_rad"] + (["distance_m"] if self.kind == "point" else [])
        if len(self.lights) == 1:
            return names
        return [f"{n}_{i}" for i in range(len(self.lights)) for n in names]


def _bic(cost: float, n: int, k: int) -> float:
    return float(n * np.log(max(cost, 1e-9) / n) + k * np.log(n))


def check_shadows(shadow_masks: list, frames: list[int]) -> list[int]:
    """Frames (of ``frames``) whose observed shadow masks show a shadow; LightError if too few."""
    counts = [max(int(np.count_nonzero(m)) for m in masks) for masks in shadow_masks]
    shown = [f for f, c in zip(frames, counts, strict=True) if c >= MIN_SHADOW_PIXELS]
    if len(shown) < MIN_SHADOW_FRAMES:
        raise LightError(f"no visible shadow: {len(shown)} of {len(frames)} frame(s) show a cast shadow of at least "
                         f"{MIN_SHADOW_PIXELS} pixels in some view (largest: {max(counts, default=0)} px), "
                         f"{MIN_SHADOW_FRAMES} are needed to estimate a light — is the scene lit by a point or "
                         "directional light, and was it segmented with shadows (label 2)?")
    return shown


def _refine_floor(evaluate, kind: str, thetas: list, frame: Frame, top: float, ground, stop_m: float):
    """Alternate the floor's refinement (light held, :func:`studio.light.floor.refine_floor`) and
    the light's last stage (floor held, :func:`studio.light.search.polish_lights`), twice: the
    second sweep starts a third finer. → (thetas, cost, plane, floor summary, evaluations)."""
    from calibration import GroundPlane
    from studio.light.floor import FLOOR_STEP, describe_floor, plane_of, refine_floor

    base = GroundPlane.floor() if ground is None else ground
    x, step, n = None, None, 0
    for _ in range(FLOOR_SWEEPS):
        x, _, _, e = refine_floor(evaluate, [to_light(kind, th, frame) for th in thetas], base, frame.centre, x,
                                  step=step)
        plane = plane_of(x, base, frame.centre)
        thetas, cost, e2 = polish_lights(functools.partial(evaluate, ground=plane), kind, frame, top, thetas,
                                         stop_m=stop_m)
        n, step = n + e + e2, FLOOR_STEP
    summary = describe_floor(plane, base, frame.centre) | {"parameters": np.round(x, 9).tolist(), "evaluations": n}
    return thetas, cost, plane, summary, n


def estimate_light(bodies, cameras, shadow_masks, *, frames: list[int] | None = None, kind: str = "point",
                   n_lights: int = 1, ground=None, level: int = 2, workers: int = 1, n_steps: int = 40,
                   stop_m: float = 0.005, refine_floor: bool = False, seed=0) -> LightEstimate:
    """Estimate the light(s) casting ``shadow_masks`` (per frame, per camera (H, W) bool) of
    ``bodies`` (per frame (vertices (V, 3), faces (F, 3))), seen by ``cameras``.

    ``kind`` ``point``, ``directional`` or ``auto``; ``n_lights`` 1 or 2; ``ground`` the plane
    (None: floor z = 0); ``level`` the pyramid level the silhouettes are compared at (the coarse
    grid and its first rounds at :func:`coarse_level`); ``workers`` processes score the
    hypotheses; ``stop_m`` the refinement's last spacing (5 mm as the thesis);
    ``refine_floor`` also refines the ground plane from the shadows (:mod:`studio.light.floor`),
    the posterior then sampled on the refined plane (``LightEstimate.floor``).
    """
    t0, cpu0 = time.perf_counter(), time.process_time()
    if kind not in (*KINDS, "auto"):
        raise LightError(f"kind: expected 'point', 'directional' or 'auto', got {kind!r}")
    if n_lights not in (1, 2):
        raise LightError(f"lights: expected 1 or 2, got {n_lights}")
    frames = list(range(len(bodies))) if frames is None else [int(f) for f in frames]
    if not (len(frames) == len(bodies) == len(shadow_masks)):
        raise LightError(f"need one body and one set of shadow masks per frame: {len(frames)} frames, "
                         f"{len(bodies)} bodies, {len(shadow_masks)} mask sets")
    shown = set(check_shadows(shadow_masks, frames))
    keep = [i for i, f in enumerate(frames) if f in shown]
    cameras = list(cameras)
    sf = [ShadowFrame.build(frames[i], bodies[i][0], bodies[i][1], cameras, shadow_masks[i], level=level)
          for i in keep]
    grid_level = coarse_level(cameras, level)
    sg = [ShadowFrame.build(frames[i], bodies[i][0], bodies[i][1], cameras, shadow_masks[i], level=grid_level)
          for i in keep[::2]]
    centre = np.mean([f.vertices.mean(axis=0) for f in sf], axis=0)
    if ground is None:
        centre[2] = 0.0
    else:
        centre = ground.project_onto(centre[None])[0]
    frame = Frame(centre, ground)
    top = float(max(f.vertices[:, 2].max() for f in sf))
    timings = {"prepare": time.perf_counter() - t0}
    kinds = list(KINDS) if kind == "auto" else [kind]
    with evaluators({"all": sf, "coarse": sf[::2], "grid": sg}, cameras, ground, workers) as ev:
        from studio.light.objective import ShadowObjective

        probe = ShadowObjective(sf, cameras, ground)
        empty = probe.empty_cost()
        empty_coarse = ShadowObjective(sg, cameras, ground).empty_cost()
        n_terms = probe.n_terms
        results = {}
        for k in kinds:
            t = time.perf_counter()
            results[k] = search_lights(ev["all"], k, frame, top, n_lights, coarse=ev["coarse"], grid=ev["grid"],
                                       stop_m=stop_m, hopeless=lambda c: c > HOPELESS * empty_coarse)
            timings[f"search_{k}"] = time.perf_counter() - t
        candidates = {k: {"cost": r.cost, "coarse_cost": r.coarse_cost, "n_evaluations": r.n_evaluations,
                          "bic": _bic(r.cost, n_terms, N_PARAMS[k] * n_lights),
                          "thetas": [np.asarray(th).tolist() for th in r.thetas]} for k, r in results.items()}
        best = min(results, key=lambda k: candidates[k]["bic"])
        res = results[best]
        if res.cost > MAX_UNEXPLAINED * empty:
            what = (f"its cost {res.cost:.1f} is {res.cost / empty:.0%} of casting no shadow ({empty:.1f})"
                    if np.isfinite(res.cost) else
                    f"the best of the coarse grid costs {res.coarse_cost / empty_coarse:.0%} of casting no shadow")
            raise LightError(f"the shadows are not explained by a {best} light: {what}; are the shadows "
                             f"segmented correctly and the bodies fitted?")
        thetas, cost = [np.asarray(t, float) for t in res.thetas], res.cost
        floor, evaluate, n_floor = None, ev["all"], 0
        if refine_floor:
            t = time.perf_counter()
            thetas, cost, plane, floor, n_floor = _refine_floor(ev["all"], best, thetas, frame, top, ground, stop_m)
            evaluate = functools.partial(ev["all"], ground=plane)
            timings["floor"] = time.perf_counter() - t
        t = time.perf_counter()
        last = np.asarray(res.rounds[-1]["rounds"][-1]["step"]) if res.rounds else np.full(N_PARAMS[best], 0.01)
        post = sample_posterior(evaluate, best, thetas, cost, frame, top, n_frames=len(sf),
                                step=np.maximum(last * 2.0, 1e-4), n_steps=n_steps, seed=seed)
        timings["posterior"] = time.perf_counter() - t
    i = int(np.argmin(post.costs))
    if post.costs[i] < cost:  # the sampler found a better light than the grid
        d = N_PARAMS[best]
        thetas = [post.samples[i][j * d:(j + 1) * d].copy() for j in range(n_lights)]
        cost = float(post.costs[i])
    d = N_PARAMS[best]
    intervals = [summarise(best, th, post.samples[:, j * d:(j + 1) * d], frame) for j, th in enumerate(thetas)]
    timings["total"] = time.perf_counter() - t0
    timings["cpu_this_process"] = time.process_time() - cpu0
    n_eval = sum(r.n_evaluations for r in results.values()) + post.n_evaluations + n_floor
    log.info("light: %s at %s, cost %.2f, %d evaluations in %.1f s", best,
             [to_light(best, th, frame) for th in thetas], cost, n_eval, timings["total"])
    return LightEstimate(best, [to_light(best, th, frame) for th in thetas], thetas, cost, empty, intervals, post,
                         centre, candidates, timings, [frames[i] for i in keep], n_eval,
                         {"kind": kind, "n_lights": n_lights, "level": level, "grid_level": grid_level,
                          "workers": workers, "n_steps": n_steps, "stop_m": stop_m, "seed": seed,
                          "refine_floor": refine_floor}, floor)
