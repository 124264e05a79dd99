"""The multi-pose batch fit under clothing (thesis §6.3, eq. 6.5–6.9) and gender by batch (§6.4.5).

One shape ``β`` shared by the P frames of a person, one pose ``θ^p`` per frame, minimising

    E_clothes(β, Θ) = Σ_p Σ_k E^k_1pose(β, θ^p) + E_shape(β) + Σ_p E_pose(θ^p)      (eq. 6.5–6.7)

with ``E^k_1pose`` the clothing-robust cost (:mod:`studio.cost.clothing`, eq. 6.1–6.4), the shape
prior of eq. 6.8 and the joint-limit term of eq. 6.9. As in the thesis it alternates: a **pose
step** (each frame's pose by staged Nelder–Mead with the shape held; frames are independent, so
they run side by side on a runner of :mod:`studio.execution`) and a **shape step** (Nelder–Mead
on the shared coefficients with every pose held), starting from the single-frame fits; under
tight clothing every pose is polished by least squares at full resolution at the end, as the
single fits are.

**Gender by batch** (§6.4.5), by ``BatchOptions.gender_step``: ``"neutral"`` (the thesis' step,
the default under loose clothing) fits the neutral model first (poses and shape alternate), then,
poses fixed, re-estimates the first ``gender_shape_free`` coefficients of the female and of the
male model from the neutral body; the lower score wins and is refined by one more round.
``"full"`` (the default under tight clothing) fits a complete batch of each gender from the
single fits and the lower final total wins. Either way the margin is reported. The score is the
batch cost (eq. 6.7) per frame plus
:data:`~studio.fit.batch_gender.GENDER_PRIOR_WEIGHT` × −2 log-likelihood of the neutral body's
stature among that sex in ANSUR II (:func:`gender_scores`). The weight is 0, the thesis' rule
(the lower cost wins): from the mean build of its stature the loose cost separates the sexes,
and a stature prior calls tall women male (the constant says how it was chosen).
Whether the frames agree is tested too (:func:`~studio.fit.batch_gender.gender_test`: a paired
t interval over the per-frame cost differences of the two fits); a margin within that noise, or
below :data:`~studio.fit.batch_gender.GENDER_MARGIN_FLOOR` whatever the interval, is
``uncertain``, and ``fit/batch.json``'s quality and ``studio report`` say so.

**Consistency** (§6.4.2: shape varies little with pose, much across people): the frames' own
single-frame bodies and the batch body are scored by the same cost; when the shared shape
explains two frames much worse than their own shapes, or the single-frame statures (one outlying
frame left out) spread far more than pose and fitting noise do for one person, the batch is
flagged (:func:`studio.fit.batch_frames.consistency`).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from studio.body import BodyModel
from studio.body.skeleton import POSE_SIZE
from studio.cost import shape_prior
from studio.fit.batch_frames import consistency
from studio.fit.batch_gender import gender_scores, gender_test
from studio.fit.batch_terms import (KNEE_INDICES, BatchOptions, ClothedObjective, build_prior,
                                    clothing_residuals, clothing_targets, on_floor, shrink_build,
                                    stature_direction)
from studio.fit.errors import FitError
from studio.fit.library import stand_on_floor
from studio.fit.objective import parameter_box, pose_bounds
from studio.optimize import Stage, staged_nelder_mead

__all__ = ["BatchFrame", "BatchOptions", "BatchResult", "ClothedObjective", "batch_fit", "compare_genders",
           "convert_shape", "start_shape", "clothing_targets", "on_floor", "pose_polish", "pose_step"]

log = logging.getLogger(__name__)

@dataclass(frozen=True, eq=False)
class BatchFrame:
    """One frame of a batch: its cameras and observed masks (views the screening kept), the
    detected skin per view (or None), and a starting ``pose`` and ``shape`` of model ``gender``
    (its single-frame fit)."""

    frame: int
    cameras: list
    masks: list
    skin: list | None
    pose: np.ndarray
    shape: np.ndarray
    gender: str


def convert_shape(source: BodyModel, shape: np.ndarray, target: BodyModel) -> np.ndarray:
    """Coefficients of ``target`` whose rest body is closest to ``source``'s body ``shape``
    (least squares on the deformation gradients, :meth:`BodyModel.shape_from_vertices`),
    clipped to ±3 σ."""
    if source.gender == target.gender:
        return np.asarray(shape, dtype=np.float64).copy()
    beta = target.shape_from_vertices(source.vertices(shape))
    sig = np.sqrt(target.eigenvalues)
    return np.clip(beta, -3 * sig, 3 * sig)


def _pose_groups() -> list[tuple[int, ...]]:
    from studio.fit.frame import _part_groups

    groups = _part_groups()
    return [tuple(range(6)) + tuple(groups[0]), tuple(groups[1]), tuple(groups[2])]


def pose_step(model: BodyModel, frame: BatchFrame, shape: np.ndarray, pose: np.ndarray, options: BatchOptions,
              targets: dict | None = None) -> tuple[np.ndarray, float]:
    """One frame's pose (POSE_SIZE,) by staged Nelder–Mead with ``shape`` held (the pose step of
    the alternation) and its cost (clothing cost + joint limits) at the work level."""
    targets = clothing_targets(frame, options) if targets is None else targets
    obj = ClothedObjective(model, frame.cameras, targets, shape, 0, options.prior_weight, floor=options.stands,
                           knee_weight=options.knee_weight, knee_ref=np.asarray(frame.pose, dtype=np.float64),
                           straight_weight=options.straight_knees)
    level = options.levels[0]
    lo, hi = pose_bounds(model, pose[:2], xy_margin=0.3)
    skip = 2 if options.stands else -1  # on the floor the root height follows from the body
    groups = [tuple(i for i in g if i != skip) for g in _pose_groups()]
    b = options.pose_evaluations
    stages = [Stage(groups[0], max(1, b // 3), "root+torso"), Stage(groups[1] + groups[2], max(1, b // 4), "limbs"),
              Stage(tuple(i for i in range(POSE_SIZE) if i != skip), max(1, b - b // 3 - b // 4), "pose")]
    step = np.full(POSE_SIZE, 0.05)
    step[:3] = 0.015
    starts = [pose]
    if options.straight_knees > 0:  # the legs searched again from straight knees (see BatchOptions)
        starts.append(np.array(pose, dtype=np.float64))
        starts[-1][list(KNEE_INDICES)] = 0.0
    runs = [staged_nelder_mead(obj.scalar(level), np.clip(model.clip_pose(p), lo, hi), stages, bounds=(lo, hi),
                               step=step, adaptive=True) for p in starts]
    res = min(runs, key=lambda r: r.cost)
    pose = model.clip_pose(res.x)
    return (stand_on_floor(model, shape, pose[None])[0] if options.stands else pose), float(res.cost)


def pose_polish(model: BodyModel, frame: BatchFrame, shape: np.ndarray, pose: np.ndarray,
                options: BatchOptions) -> tuple[np.ndarray, float]:
    """One frame's pose (POSE_SIZE,) by trust-region least squares on
    :func:`~studio.fit.batch_terms.clothing_residuals` at the final level with ``shape`` held
    (``options.polish_iterations`` iterations; the single-frame polish's steps: 0.08 rad, 3 cm at the
    root), keeping the iterate the clothing cost likes best, and that cost. The pose steps search
    at the work level; this brings each frame's pose to full resolution as the single fits' polish
    does."""
    from studio.fit.polish import lsq_polish

    level = options.levels[-1]
    obj = ClothedObjective(model, frame.cameras, clothing_targets(frame, options), shape, 0, options.prior_weight,
                           floor=options.stands)
    box, scale = parameter_box(model, *pose_bounds(model, pose[:2], xy_margin=0.3), 0)
    x, cost, _ = lsq_polish(obj, model.clip_pose(pose), box, scale, level=level,
                            max_nfev=options.polish_iterations, residuals=clothing_residuals(obj, level))
    pose = model.clip_pose(x)
    return (stand_on_floor(model, shape, pose[None])[0] if options.stands else pose), cost


def _pose_unit(payload: dict) -> tuple[list, float]:
    """Worker side of a pose step (picklable payload: model gender, frame, shape, pose, options)."""
    from studio.blas import limit_blas_threads

    limit_blas_threads()
    model = BodyModel.load(payload["gender"])
    step = pose_polish if payload["polish"] else pose_step
    pose, cost = step(model, payload["frame"], np.asarray(payload["shape"]), np.asarray(payload["pose"]),
                      payload["options"])
    return pose.tolist(), cost


class _Batch:
    """The P frames' objectives for one model (shape step and batch costs)."""

    def __init__(self, model: BodyModel, frames: list[BatchFrame], options: BatchOptions):
        self.model, self.frames, self.options = model, frames, options
        self.targets = [clothing_targets(f, options) for f in frames]
        self.objs = [ClothedObjective(model, f.cameras, t, model.mean_shape(), 0, options.prior_weight)
                     for f, t in zip(frames, self.targets, strict=True)]  # (meshes stood on the floor in per_frame)
        self.sigma = np.sqrt(np.asarray(model.eigenvalues, dtype=np.float64))
        self.direction = stature_direction(model, options.n_shape_free) if options.build > 0 else None
        self.n_evaluations = 0

    def prior(self, shape: np.ndarray) -> float:
        """The shared shape's prior: eq. 6.8 (``prior_weight``) and, under ``build_weight``, the
        build at its own stature (:func:`~studio.fit.batch_terms.build_prior`)."""
        out = self.options.prior_weight * shape_prior(shape, self.sigma)
        if self.direction is not None:
            out += self.options.build * build_prior(shape, self.sigma, self.direction)
        return float(out)

    def per_frame(self, shape: np.ndarray, poses: np.ndarray, level: int) -> np.ndarray:
        """Clothing cost + joint-limit term (P,) of every frame for one shared shape."""
        poses = self.model.clip_pose(np.asarray(poses, dtype=np.float64))
        V = self.model.vertices_batch(np.repeat(shape[None], len(poses), axis=0), poses)
        V = on_floor(V) if self.options.stands else V
        out = np.empty(len(poses))
        for p, (obj, v) in enumerate(zip(self.objs, V, strict=True)):
            _, lp = obj.priors(obj.pack(shape, poses[p])[None])
            out[p] = obj.silhouettes(v[None], level)[0] + self.options.prior_weight * lp[0]
        self.n_evaluations += 1
        return out

    def total(self, shape: np.ndarray, poses: np.ndarray, level: int) -> float:
        """``E_clothes`` (eq. 6.7)."""
        return float(self.per_frame(shape, poses, level).sum() + self.prior(shape))

    def shape_step(self, shape: np.ndarray, poses: np.ndarray, n_free: int, evaluations: int,
                   level: int | None = None) -> tuple[np.ndarray, float]:
        """The shared shape's first ``n_free`` coefficients by Nelder–Mead, poses held (at the work
        level unless ``level`` is given)."""
        level = self.options.levels[0] if level is None else level
        n_free = min(n_free, self.model.n_shape)
        base = np.asarray(shape, dtype=np.float64).copy()
        sig = self.sigma[:n_free]

        def f(b):
            s = base.copy()
            s[:n_free] = b
            return self.total(s, poses, level)

        res = staged_nelder_mead(f, base[:n_free], [Stage(tuple(range(n_free)), evaluations, "shape")],
                                 bounds=(-3 * sig, 3 * sig), step=0.4 * sig, adaptive=True)
        base[:n_free] = res.x
        return base, float(res.cost)


def _pose_steps(runner, model: BodyModel, frames: list[BatchFrame], shape, poses, options,
                polish: bool = False) -> np.ndarray:
    """Every frame's pose step (``polish``: :func:`pose_polish`) side by side on ``runner``."""
    payloads = [{"gender": model.gender, "frame": f, "shape": np.asarray(shape).tolist(), "pose": np.asarray(p).tolist(),
                 "options": options, "polish": polish} for f, p in zip(frames, poses, strict=True)]
    if runner is None:
        step = pose_polish if polish else pose_step
        results = [step(model, f, shape, p, options) for f, p in zip(frames, poses, strict=True)]
    else:
        futures = [runner.submit(_pose_unit, pl) for pl in payloads]
        results = [fut.result() for fut in futures]
    return np.array([np.asarray(r[0], dtype=np.float64) for r in results])


def _alternate(runner, model, frames, shape, poses, options, rounds, n_free, history, label):
    batch = _Batch(model, frames, options)
    for r in range(rounds):
        t = time.perf_counter()
        poses = _pose_steps(runner, model, frames, shape, poses, options)
        t_pose = time.perf_counter() - t
        shape, cost = batch.shape_step(shape, poses, n_free, options.shape_evaluations)
        history.append({"model": label, "round": r, "cost": cost, "pose_step_s": round(t_pose, 3),
                        "shape_step_s": round(time.perf_counter() - t - t_pose, 3)})
        log.info("batch %s round %d: cost %.3f", label, r, cost)
    return shape, poses, batch


@dataclass(frozen=True, eq=False)
class BatchResult:
    """The batch fit: ``gender`` (chosen or given) with ``gender_costs`` (the decision's scores:
    :func:`gender_scores`), ``gender_terms`` (cost, Mahalanobis distance and score per gender) and
    ``margin`` (loser − winner score) with ``gender_test`` (:func:`gender_test`: is the margin above
    the frames' spread; all None when the gender was given), the shared ``shape``, per-frame ``poses``
    (P, POSE_SIZE) and ``costs`` (P,) at the final level, ``total`` (eq. 6.7), ``consistency``,
    ``start`` (:func:`start_shape`: the shape it started from, in the first model's coefficients)."""

    gender: str
    shape: np.ndarray
    frames: list
    poses: np.ndarray
    costs: np.ndarray
    total: float
    gender_costs: dict | None
    margin: float | None
    consistency: dict
    history: list
    options: dict
    timings: dict = field(default_factory=dict)
    gender_terms: dict | None = None
    gender_test: dict | None = None
    start: np.ndarray | None = None

    def to_json(self) -> dict:
        return {
            "format": "studio.fit-batch",
            "version": 1,
            "gender": self.gender,
            "gender_costs": self.gender_costs,
            "gender_margin": self.margin,
            "gender_terms": self.gender_terms,
            "gender_test": self.gender_test,
            "shape": [float(v) for v in self.shape],
            "frames": [int(f) for f in self.frames],
            "poses": {str(f): [float(v) for v in p] for f, p in zip(self.frames, self.poses, strict=True)},
            "costs": {str(f): float(c) for f, c in zip(self.frames, self.costs, strict=True)},
            "total": float(self.total),
            "consistency": self.consistency,
            "history": self.history,
            "settings": self.options,
            "timings": self.timings,
        }


class GenderFit(NamedTuple):
    """One gender's fit in the gender decision: its ``model``, ``shape``, batch ``cost`` (eq.
    6.7), ``start`` (the body it started from, in its coefficients) and each frame's cost
    ``per_frame`` (P,)."""

    model: BodyModel
    shape: np.ndarray
    cost: float
    start: np.ndarray
    per_frame: np.ndarray


def compare_genders(frames: list[BatchFrame], source: BodyModel, shape: np.ndarray, poses: np.ndarray,
                    options: BatchOptions) -> dict[str, GenderFit]:
    """§6.4.5: with the poses fixed, the first ``gender_shape_free`` coefficients of the female
    and of the male model, started from ``source``'s body ``shape``, by a shape step each (work
    level); ``{gender: GenderFit}`` with ``start`` the source body in that model's coefficients.
    :func:`gender_scores` decides, :func:`gender_test` says whether the frames agree. With one
    frame this is the thesis' single-pose gender classification."""
    out = {}
    for g in ("female", "male"):
        m = BodyModel.load(g)
        start = convert_shape(source, shape, m)
        batch = _Batch(m, frames, options)
        s, _ = batch.shape_step(start, poses, options.gender_shape_free, options.shape_evaluations)
        per_frame = batch.per_frame(s, poses, options.levels[0])
        out[g] = GenderFit(m, s, float(per_frame.sum() + batch.prior(s)), start, per_frame)
    return out


def _decide(cands: dict[str, GenderFit], stature: float, n_coefficients: int, n_frames: int, history: list):
    """The gender decision over ``cands``: (winner, scores, terms, margin, paired test)."""
    terms = gender_scores(cands, stature, n_coefficients, n_frames=n_frames)
    history += [{"model": g, "round": "gender", **v} for g, v in terms.items()]
    scores = {g: v["score"] for g, v in terms.items()}
    win = min(scores, key=scores.get)
    margin = float(max(scores.values()) - scores[win])
    return win, scores, terms, margin, gender_test({g: c.per_frame for g, c in cands.items()}, scores)


def start_shape(frames: list[BatchFrame], model: BodyModel, options: BatchOptions) -> np.ndarray:
    """The batch's starting shape in ``model``'s coefficients: the mean of the frames'
    single-frame bodies (under loose clothing: its tail at the mean, ``reset_tail``, and its build
    at the mean of its stature, ``start_build``)."""
    shape0 = np.mean([convert_shape(BodyModel.load(f.gender), f.shape, model) for f in frames], axis=0)
    if options.tail_reset:
        shape0[options.n_shape_free:] = 0.0
    if options.start_share != 1.0:  # the single fits' build under loose clothes is the clothes'
        sig = np.sqrt(np.asarray(model.eigenvalues, dtype=np.float64))
        shape0 = shrink_build(shape0, sig, stature_direction(model, options.n_shape_free), options.start_share)
    return shape0


def _full_genders(frames: list[BatchFrame], options: BatchOptions, runner) -> "BatchResult":
    """Gender by two complete batches (``gender_step`` ``"full"``): the female and the male batch
    each fitted from the single fits to the end (final level, polish), the lower total per frame
    wins; the paired test over the frames' final costs. The stature evidence (reported, weight 0)
    is of the mean of the two bodies' statures (there is no neutral body here). Returns the
    winner's batch with the decision's fields."""
    from studio.body import measure

    t0 = time.perf_counter()
    fits = {g: batch_fit(frames, gender=g, options=options, runner=runner) for g in ("female", "male")}
    cands = {g: GenderFit(BodyModel.load(g), r.shape, r.total, r.start, r.costs) for g, r in fits.items()}
    stature = float(np.mean([measure(c.model, c.shape)["stature"] for c in cands.values()]))
    history = fits["female"].history + fits["male"].history
    win, scores, terms, margin, test = _decide(cands, stature, options.n_shape_free, len(frames), history)
    timings = {g: r.timings["total"] for g, r in fits.items()} | {"total": round(time.perf_counter() - t0, 3)}
    return replace(fits[win], gender_costs=scores, margin=margin, history=history, timings=timings,
                   gender_terms=terms, gender_test=test)


def batch_fit(frames: list[BatchFrame], *, gender: str = "auto", options: BatchOptions = BatchOptions(),
              runner=None) -> BatchResult:
    """Fit one shape and P poses to the frames (eq. 6.5–6.9), gender by batch when ``"auto"``
    (``options.gender_fit``).

    ``runner`` (:func:`studio.execution.open_runner`) runs the per-frame pose steps side by side;
    None runs them here. Starts from each frame's single-frame pose and :func:`start_shape`.
    """
    if not frames:
        raise FitError("batch fit: no frames")
    if gender not in ("auto", "female", "male", "neutral"):
        raise FitError(f"gender: expected auto, female, male or neutral, got {gender!r}")
    if gender == "auto" and options.gender_fit == "full":
        return _full_genders(frames, options, runner)
    t0 = time.perf_counter()
    first = BodyModel.load("neutral" if gender == "auto" else gender)
    poses = np.array([f.pose for f in frames], dtype=np.float64)
    history: list = []
    start = start_shape(frames, first, options)
    shape, poses, batch = _alternate(runner, first, frames, start, poses, options, options.rounds,
                                     options.n_shape_free, history, first.gender)
    gender_costs, gender_terms, margin, test, model = None, None, None, None, first
    timings = {"first_model": round(time.perf_counter() - t0, 3)}
    if gender == "auto":
        t = time.perf_counter()
        cands = compare_genders(frames, first, shape, poses, options)
        from studio.body import measure

        win, gender_costs, gender_terms, margin, test = _decide(cands, measure(first, shape)["stature"],
                                                                options.gender_shape_free, len(frames), history)
        model, shape = cands[win].model, cands[win].shape
        timings["gender"] = round(time.perf_counter() - t, 3)
        t = time.perf_counter()
        shape, poses, batch = _alternate(runner, model, frames, shape, poses, options, 1, options.n_shape_free,
                                         history, f"{win} refine")
        timings["refine"] = round(time.perf_counter() - t, 3)
    final = options.levels[-1]
    if options.final_evaluations and final != options.levels[0]:
        # the shared shape once more at the final level (full resolution: a coarse level's
        # silhouettes are a pixel fatter, measured +20-70 mm on girths without this step)
        t = time.perf_counter()
        shape, cost = batch.shape_step(shape, poses, options.n_shape_free, options.final_evaluations, level=final)
        history.append({"model": model.gender, "round": "final", "cost": cost})
        timings["final"] = round(time.perf_counter() - t, 3)
    if options.polish_iterations:
        # every pose polished at the final level, then the shape once more (the single fits end with
        # a full-resolution polish of pose and shape; the batch's pose steps search the work level)
        t = time.perf_counter()
        poses = _pose_steps(runner, model, frames, shape, poses, options, polish=True)
        if options.final_evaluations:
            shape, cost = batch.shape_step(shape, poses, options.n_shape_free, options.final_evaluations, level=final)
            history.append({"model": model.gender, "round": "polish", "cost": cost})
        timings["polish"] = round(time.perf_counter() - t, 3)
    if options.stands:
        poses = stand_on_floor(model, shape, poses)
    costs = batch.per_frame(shape, poses, final)
    total = float(costs.sum() + batch.prior(shape))
    t = time.perf_counter()
    cons = consistency(model, shape, poses, frames, options)
    timings["consistency"] = round(time.perf_counter() - t, 3)
    timings["total"] = round(time.perf_counter() - t0, 3)
    return BatchResult(gender=model.gender, shape=shape, frames=[f.frame for f in frames], poses=poses, costs=costs,
                       total=total, gender_costs=gender_costs, margin=margin, consistency=cons, history=history,
                       options=options.to_dict(), timings=timings, gender_terms=gender_terms,
                       gender_test=test, start=start)
