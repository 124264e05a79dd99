"""Fitting one frame: particle filter on the pose, then staged Nelder–Mead (thesis §4.7).

1. The observed silhouettes become a pyramid of :class:`~studio.cost.SilhouetteTarget`
   (coarse level for the search, full resolution for the end, §7.2.3).
0. The silhouettes are screened (:func:`studio.fit.quality.screen_masks`): a view with an
   empty or all-image mask is left out, a frame with no usable view or views the visual hull
   cannot reconcile is refused (:class:`~studio.fit.errors.UnusableFrame`); one view is fitted
   when a light's shadow (eq. 5.7) stands in for the second (§5.5), or flagged ``suspect`` on a
   one-camera rig; a rig left with one view and no light is refused.
2. Without a previous pose, the start comes from the silhouettes: floor position from the
   visual hull (:mod:`studio.fit.init`), then (``start="library"``, the default) the lab
   posture library (:mod:`studio.fit.library`) matched over posture × stature × heading, its
   shortlist scored with SCAPE, the best 4 seeding the filter; the match's stature starts
   the shape. With one view (§5.5) the library also searches the floor point along the
   camera's line of sight (``MONOCULAR_DEPTHS``), sees the shadow camera when a light is known,
   and its 120 best matches with the heading grid's strides are scored by the cost to choose
   the starts. ``start="stride"`` (the first wave's start, kept for comparison): 12 headings ×
   standing / stride postures, the stature from the hull's top — an arms-overhead person
   started 339 mm (joint error) off and ended there, a squat 132 mm.
3. The annealed particle filter (§4.7.3) searches the pose (shape held) at the coarse level on
   the 15-cone model of §4.8.1 (``search_model="cylinder"``, the default: ~3× cheaper per
   evaluation than SCAPE), started from the heading hypotheses (or from the previous frame's
   pose with a smaller spread); SCAPE keeps the cone answer only if it beats the best start.
   Then a partitioned pass on SCAPE (Deutscher's partitioned APF) re-searches root + spine +
   head, then each arm and each leg, the others held. Without a previous pose the same search
   runs again from the heading opposite its answer (facing the other way with the other leg
   forward fills nearly the same volume) and the lower SCAPE cost wins.
   Without a given shape, the shape starts from the library's stature (or with
   ``start="stride"`` the top of the visual hull, :func:`studio.fit.init.hull_height`) →
   :func:`studio.body.shape_from_measurements`.
   A body that sits on something the silhouettes also hold (a stool, :mod:`studio.fit.props`)
   has the observed pixels under its seat left out of the cost from here on.
4. Staged Nelder–Mead (§4.7.4, :func:`studio.optimize.thesis_stages`) refines root + shape,
   the limbs outward, then everything, at the middle level; each limb is then re-searched by a
   small partitioned particle filter (a forearm bent the wrong way is a minimum Nelder–Mead
   cannot leave); at full resolution every parameter is then polished by trust-region least
   squares on a smooth stand-in of the cost (:mod:`studio.fit.polish`; Nelder–Mead over ~40
   parameters stalls short of the cost's minimum), and root + shape + trunk are refined last
   by Nelder–Mead (``distal_share``: a Nelder–Mead stage of the distal joints before it, off by
   default). Joint limits are optimiser bounds, so they always hold. Steps 2–4 up to the polish
   score the model's search body (:meth:`studio.body.BodyModel.search_model`: its pose
   deformation learned near rest); the polish and the last stage refine that answer with the
   model itself, whose deformation is closer to the true body in deep postures but misled the
   search (dev people: 17 fits closer, 3 farther; seated median 8.7 → 7.0 mm).
5. The quality gates (:func:`studio.fit.quality.fit_quality`) judge the result: ``quality``
   in the result, status ``ok`` / ``suspect`` / ``failed`` with the reasons.
"""

from __future__ import annotations

from dataclasses import replace
import functools
import logging
import time
import numpy as np

from studio.blas import one_blas_thread
from studio.body import BodyModel
from studio.body.skeleton import POSE_SIZE
from studio.cost import SilhouetteTarget
from studio.fit.errors import FitError, UnusableFrame
from studio.fit.init import costs_at_statures, hull_centroid, hull_height, initial_poses, stature_search, stature_shape
from studio.fit.library import frontal_twin, library_match, stand_on_floor
from studio.fit.objective import CylinderObjective, FrameObjective, parameter_box, pose_bounds
from studio.fit.options import FitOptions
from studio.fit.polish import polish_frame
from studio.fit.props import find_support
from studio.fit.quality import fit_quality, refused_quality, screen_masks
from studio.fit.result import FrameFit, keep_best, search_again
from studio.fit.search import _arm_states, _heading, _part_groups, _partitioned_search, _partitions, _pose_sigma
from studio.optimize import Stage, annealed_particle_filter, staged_nelder_mead, thesis_stages

__all__ = ["FitOptions", "FrameFit", "fit_frame", "fit_frame_gender"]

log = logging.getLogger(__name__)

#: A frame fitted from one view: the particle filter's particles are multiplied by this and its
#: layers increased by ``MONOCULAR_LAYERS`` (benchmarks/monocular.py, 6 frames with their shadow:
#: mean joint error 144 → 77 mm, frames within 40 mm 2 → 3, +6 % CPU).
MONOCULAR_PARTICLES = 2
MONOCULAR_LAYERS = 2
#: A frame fitted from one view scores this many of the library's best matches (and the heading
#: grid's strides) by its silhouette and shadow cost to choose its starts: with one view the
#: descriptor ranks the true family anywhere in the first 70 (12 with several views).
MONOCULAR_SHORTLIST = 120
#: ... and searches the floor point along the camera's line of sight by these offsets (m) from
#: the point under the silhouette's feet (:func:`studio.fit.init.feet_on_floor`).
MONOCULAR_DEPTHS = (-0.3, -0.2, -0.1, 0.0, 0.1, 0.2, 0.3)
#: A frame fitted from one view whose body explains the silhouette poorly (the quality gates'
#: agreement checks) is searched again this many times with other random draws; the lower total
#: cost is kept. The search from one view is chaotic: costs changed by 1e-9 (a faster cost, same
#: arithmetic) turned a 43 mm fit into a 246 mm one, and the fit's own cost tells them apart.
MONOCULAR_RETRIES = 1
#: A frame of several views searched again (``FitOptions.retries``) scores this many of the
#: library's best matches, the families the last attempt started from left out.
RETRY_SHORTLIST = 24
#: Library families whose start looks for a seat before the search (:func:`studio.fit.props.find_support`).
SEATED_STARTS = ("seated",)


def build_targets(masks, names, options: FitOptions, ignore=None) -> dict:
    """{level: SilhouetteTarget} of the observed ``masks`` at the levels of ``options``
    (``ignore``: per view, observed pixels the body need not explain, e.g. a stool)."""
    return {lvl: SilhouetteTarget.build(masks, tau=options.tau, xi=options.xi, level=lvl, names=names, ignore=ignore)
            for lvl in sorted(set(options.levels))}


@one_blas_thread  # measured: 2 OpenBLAS threads only spin (see studio.blas)
def fit_frame(
    model: BodyModel,
    cameras,
    masks,
    *,
    frame: int = 0,
    shape=None,
    previous_pose=None,
    hint_pose=None,
    options: FitOptions = FitOptions(),
    seed=0,
    screen: dict | None = None,
    lights=None,
    shadow_masks=None,
    shadow_weight: float = 1.0,
    ground=None,
    light_uncertainty: dict | None = None,
    _attempt: int = 0,
    _avoid: tuple = (),
    _own_statures: bool = False,
    _family: str | None = None,
) -> FrameFit:
    """Fit ``model`` to one frame's observed silhouettes.

    ``cameras`` list of full-resolution cameras, ``masks`` list of (H, W) bool in the same
    order. ``shape`` (n_shape,) starting/held shape (default: mean). ``previous_pose``
    (POSE_SIZE,) initialises a tracking fit (smaller spread, fewer layers); without it the
    pose is initialised from the silhouettes; ``hint_pose`` (e.g. another frame's fitted pose)
    then joins the heading hypotheses as one more start, moved to the silhouettes' floor
    centroid. Deterministic for a given ``seed``.

    The silhouettes are screened first (``screen``: :func:`studio.fit.quality.screen_masks`,
    computed when None): views with an empty or all-image mask are left out, and a frame with
    no usable view (or one of several, without ``lights``) raises
    :class:`~studio.fit.errors.UnusableFrame`; one camera without ``lights`` is fitted and flagged
    ``suspect``. The result
    carries the quality gates (:attr:`FrameFit.quality`).

    With ``lights`` (known point / directional lights) and ``shadow_masks`` (observed shadows,
    (H, W) bool per camera), the cost gains the shadow term of eq. 5.7 (weight
    ``shadow_weight``, cast on ``ground``; :class:`studio.fit.shadows.ShadowTerm`), reported as
    ``costs["shadow"]``. ``light_uncertainty``: an estimated light's 95 % intervals
    (:func:`studio.light.light_uncertainty`), for the screen's check of a one-view frame.
    """
    cameras = list(cameras)
    masks = [np.asarray(m, dtype=bool) for m in masks]
    given = (cameras, masks)
    if len(cameras) != len(masks) or not cameras:
        raise FitError(f"need one mask per camera: got {len(masks)} masks for {len(cameras)} cameras")
    for c, m in zip(cameras, masks, strict=True):
        if m.shape != (c.size[1], c.size[0]):
            raise FitError(f"camera {c.name}: mask is {m.shape[1]}x{m.shape[0]}, calibration says {c.size[0]}x{c.size[1]}")
    if screen is None:
        screen = screen_masks(cameras, masks, shadow=bool(lights), light=light_uncertainty)
    if screen["status"] == "failed":
        raise UnusableFrame(frame, refused_quality(screen))
    used = [i for i, c in enumerate(cameras) if c.name not in screen["dropped"]]
    cameras, masks = [cameras[i] for i in used], [masks[i] for i in used]
    # the search scores the search body (the pose deformation learned near rest); the polish and
    # the final stage refine its answer with the model itself (BodyModel.search_model)
    final_model, model = model, model.search_model()
    shadow = None
    if lights:
        from studio.fit.shadows import ShadowTerm

        if shadow_masks is None or len(shadow_masks) != len(used) + len(screen["dropped"]):
            raise FitError("shadow_masks: one observed shadow mask per camera is needed with lights")
        shadow = ShadowTerm.build(lights, cameras, [shadow_masks[i] for i in used], options.levels,
                                  tau=options.tau, xi=options.xi, ground=ground, weight=shadow_weight)
    rng = np.random.default_rng(seed)
    t_start, cpu_start = time.perf_counter(), time.process_time()
    timings = {}
    init_height = None
    xy = hull_centroid(cameras, masks) if previous_pose is None or shape is None else None
    match = None
    if previous_pose is None and options.start == "library":
        # the lab posture library matched to the silhouettes: postures, headings and stature
        views = None if shadow is None else {"lights": shadow.lights, "masks": [shadow_masks[i] for i in used],
                                             "ground": ground, "weight": shadow_weight}
        floor = xy
        if len(cameras) == 1:  # one view leaves the depth along its rays open: the library searches it
            axis = xy - np.asarray(cameras[0].center, dtype=np.float64)[:2]
            floor = xy + np.outer(MONOCULAR_DEPTHS, axis / np.linalg.norm(axis))
        match = library_match(model, cameras, masks, floor, shape=shape, shadows=views,
                              shortlist=(RETRY_SHORTLIST if _avoid else 12) if len(cameras) > 1 else MONOCULAR_SHORTLIST)
        xy = match["xy"]
    if shape is not None:
        base_shape = model.check_shape(shape)
    elif options.fit_shape and model.measurement_samples is not None:
        # stature → conditional-mean shape (§4.7.2-style init): from the library's best match,
        # else from the top of the visual hull (wrong for a seated or arms-overhead person)
        init_height = match["stature"] if match is not None else hull_height(cameras, masks, xy)
        base_shape = stature_shape(model, init_height)
    else:
        base_shape = model.mean_shape()
    search, refine, final = options.levels
    targets = build_targets(masks, [c.name for c in cameras], options)
    n_free = options.n_shape_free if options.fit_shape else 0
    n_free = min(n_free, model.n_shape)

    def scape_of(shape):
        """The SCAPE pose objective (eq. 4.6, no free shape coefficient) of ``shape`` on the current targets."""
        return FrameObjective(model, cameras, targets, shape, 0, options.prior_weight, shadow=shadow)

    def objectives(targets):
        """(SCAPE, search) objectives of the pose: the global search scores the 15-cone model
        (§4.8.1) by default; the heading grid, the check of the cones' answer and the
        partitioned passes score SCAPE."""
        scape = FrameObjective(model, cameras, targets, base_shape, 0, options.prior_weight, shadow=shadow)
        return scape, (CylinderObjective(model, cameras, targets, base_shape, 0, options.prior_weight, shadow=shadow)
                       if options.search_model == "cylinder" else scape)

    def spent() -> int:
        """Evaluations of the current pose objectives (counted before they are replaced)."""
        return pose_obj.n_evaluations + (apf_obj.n_evaluations if apf_obj is not pose_obj else 0)

    pose_obj, apf_obj = objectives(targets)
    early, n_early = None, 0
    timings["targets"] = time.perf_counter() - t_start

    # -- initialisation + particle filter on the pose (shape held)
    t = time.perf_counter()
    start_family = None
    if previous_pose is None:
        grid, _ = initial_poses(pose_obj, cameras, masks, search, keep=None, xy=xy)
        starts = grid[:4]
        if match is not None:  # the library's shortlist, scored by the silhouette cost (eq. 4.6)
            poses, families, statures = match["poses"], list(match["families"]), np.asarray(match["statures"])
            # a retry: the postures the last attempts started from are left out — whole families
            # (names) or a family at the stature it was tried at ((name, m)); ``_family``: only its
            # postures (when the shortlist has any left)
            keep = [i for i, (f, h) in enumerate(zip(families, statures, strict=True))
                    if f not in _avoid and not any(a[0] == f and abs(a[1] - h) < 1e-6 for a in _avoid if isinstance(a, tuple))]
            if _family is not None and any(families[i] == _family for i in keep):
                keep = [i for i in keep if families[i] == _family]
            if len(keep) < len(families) and keep:
                poses, families, statures = poses[keep], [families[i] for i in keep], statures[keep]
            if _own_statures and init_height is not None and shape is None:
                # the last resort of a flagged frame: each candidate scored at the stature the
                # library matched it at (otherwise all on the best match's body): a squat matched at
                # full scale, scored on the short body of a standing posture matched at 0.88, had
                # cost 22.4 against its own 12.6 and never started the search (dev half squat: 33.5
                # → 6.6 mm). Not on the first attempt or the retry: the coarse level's cost compares
                # statures poorly (held out, on every frame: 8 fits closer, 5 farther, a walk's cost
                # 0.24 → 0.74; on the retry: a torso twist 8 → 33 mm)
                own, n_own = costs_at_statures(model, scape_of, poses, statures, search)
                n_early += n_own
                if statures[np.argmin(own)] != init_height:
                    n_early += spent()
                    init_height = float(statures[np.argmin(own)])
                    base_shape = stature_shape(model, init_height)
                    pose_obj, apf_obj = objectives(targets)
            cand = stand_on_floor(model, base_shape, poses)
            X = np.stack([pose_obj.pack(base_shape, p) for p in cand])
            if len(cameras) == 1:  # one view: the heading grid's strides compete with the library's postures
                X, families = np.vstack([X, grid]), families + ["stride"] * len(grid)
            order = np.argsort(pose_obj(X, search))[:4]
            starts, start_family = X[order], families[order[0]]
        if hint_pose is not None:
            hint = np.asarray(hint_pose, dtype=np.float64).copy()
            hint[:2] = starts[0, :2]
            starts = np.vstack([hint[None], starts])
        if options.find_support and start_family in SEATED_STARTS:
            # a start that sits on a prop the silhouettes hold (a stool): the search leaves the
            # pixels under its seat out too, else it drags the legs onto the stool (dev seated
            # frames: 57.8 / 52.1 → 23.4 / 13.3 mm). Not from a squat start: placed roughly, its
            # own calves fill the region under its seat (dev half squat 11.6 → 13.4 mm)
            early = find_support(model, cameras, masks, base_shape, model.clip_pose(starts[0]))
            if early is not None:
                targets = build_targets(masks, [c.name for c in cameras], options, ignore=early.ignore)
                n_early += spent()
                pose_obj, apf_obj = objectives(targets)
        if match is not None and init_height is not None and len(cameras) > 1 and options.stature_steps:
            # the library's stature refined with its best start (a stool left out as above)
            init_height, base_shape = stature_search(model, scape_of, starts[int(hint_pose is not None)], init_height,
                                                     search, options.stature_steps)
            starts = stand_on_floor(model, base_shape, starts)
            n_early += len(options.stature_steps) + spent()
            pose_obj, apf_obj = objectives(targets)
        sigma = _pose_sigma(1.0)
        n_p, n_l = options.n_particles, options.n_layers
        if len(cameras) == 1:  # one view leaves depth, heading and which leg is which open: search wider
            n_p, n_l = MONOCULAR_PARTICLES * n_p, n_l + MONOCULAR_LAYERS
    else:
        starts = np.asarray(previous_pose, dtype=np.float64)[None]
        sigma = _pose_sigma(0.4)
        n_p, n_l = options.n_particles_tracking, options.n_layers_tracking
    timings["init"] = time.perf_counter() - t
    t = time.perf_counter()
    lo, hi = pose_bounds(model, starts[0, :2])

    def search_from(starts):
        """Global particle filter from ``starts`` (cones or SCAPE), then the partitioned SCAPE
        pass; → (pose, SCAPE cost at the search level, particle filter's own best cost)."""
        starts = np.clip(starts, lo, hi)
        apf = annealed_particle_filter(lambda X: apf_obj(X, search), starts, sigma, bounds=(lo, hi),
                                       n_particles=n_p, n_layers=n_l, vectorized=True, seed=rng)
        x = apf.x.copy()
        if apf_obj is not pose_obj:  # keep the cone search's answer only if SCAPE agrees it is better
            c_apf, c_start = pose_obj(np.stack([x, starts[0]]), search)
            if c_start < c_apf:
                x = starts[0].copy()
        # partitioned refinement (Deutscher's partitioned APF): torso+root, then limb by limb
        if options.partition_particles and options.partition_layers:
            scale = 0.5 if previous_pose is None else 0.3
            x, c = _partitioned_search(lambda X: pose_obj(X, search), x, sigma * scale, lo, hi, _partitions(),
                                       n_particles=options.partition_particles, n_layers=options.partition_layers,
                                       rng=rng)
        else:
            c = float(pose_obj(x[None], search)[0])
        return x, c, float(apf.cost)

    x_pose, c_pose, apf_cost = search_from(starts)
    rival_cost = None
    if previous_pose is None and options.rival_heading:
        # the front/back rival: facing the other way with the other leg forward fills nearly the
        # same volume (a stride is almost symmetric under a half turn); search from the heading
        # opposite the answer and keep the lower SCAPE cost
        yaw = _heading(x_pose) + np.pi
        k = int(np.argmin(np.abs(np.angle(np.exp(1j * (grid[:, 5] - yaw))))))
        rival = grid[k].copy()
        rival[:2] = x_pose[:2]
        x_r, rival_cost, apf_r = search_from(rival[None])
        if rival_cost < c_pose:
            x_pose, c_pose, apf_cost = x_r, rival_cost, apf_r
    timings["particle_filter"] = time.perf_counter() - t

    support = None
    if options.find_support:
        # a seated body rests on something the silhouettes hold too (a stool): what is observed
        # under its seat becomes a don't-care region of the cost from here on
        support = find_support(model, cameras, masks, base_shape, model.clip_pose(x_pose)) or early
        if support is not None:
            targets = build_targets(masks, [c.name for c in cameras], options, ignore=support.ignore)

    # -- staged Nelder–Mead on pose + shape
    t = time.perf_counter()
    obj = FrameObjective(model, cameras, targets, base_shape, n_free, options.prior_weight, shadow=shadow)
    x0 = obj.pack(base_shape, x_pose)
    sig = np.sqrt(model.eigenvalues[:n_free])
    (blo, bhi), step = parameter_box(model, lo, hi, n_free)
    shape_idx = list(range(POSE_SIZE, POSE_SIZE + n_free))
    stages = thesis_stages(list(range(6)), _part_groups(), shape_idx, n_shape_first=min(6, n_free),
                           n_shape_second=n_free, max_evaluations=options.nm_evaluations)
    if previous_pose is not None:  # tracking: a smaller local budget
        stages = [Stage(st.indices, max(1, int(st.max_evaluations * options.tracking_budget)), st.name)
                  for st in stages]
    nm = staged_nelder_mead(obj.scalar(refine), x0, stages, bounds=(blo, bhi), step=step, adaptive=True)
    x_nm = nm.x
    if options.limb_particles and options.limb_layers:
        # limbs re-searched once torso and shape have settled: a forearm stuck bent the wrong
        # way is a local minimum Nelder–Mead cannot leave (measured on the walk: wrist 205 mm off).
        # Tracking too: without it the 24-frame walk's joint error went 17.2 → 19.1 mm and
        # precision 0.961 → 0.956 (the cost rose on 17 of 23 tracked frames)
        # a fit from the silhouettes alone also starts each arm from the library's arm states: the
        # whole-body search left the dev arm_forward frames' raised arm hanging (start family
        # arms_crossed / arms_down: a forward arm a few cm off costs more than a missing one)
        limbs = _partitions()[1:]
        x_nm, _ = _partitioned_search(lambda X: obj(X, refine), x_nm, np.concatenate([sigma, sig]) * 0.5, blo, bhi,
                                   limbs, n_particles=options.limb_particles, n_layers=options.limb_layers, rng=rng,
                                   extra=_arm_states(model, limbs) if previous_pose is None else None)
    timings["nelder_mead"] = time.perf_counter() - t
    t = time.perf_counter()
    if final_model is not model:
        n_early += obj.n_evaluations
        model, obj = final_model, replace(obj, model=final_model, n_evaluations=0)
    polish = twin_costs = None
    if options.polish_iterations:
        # trust-region least squares on a smooth stand-in of the cost, every parameter at once at
        # full resolution (Nelder–Mead over ~40 parameters stalls short of the cost's minimum);
        # its best iterate by the cost itself is kept
        # (with more shape coefficients than the search when ``polish_shape_free`` says so: the
        # least squares handle them at the cost of a Jacobian column each); the front/back twin
        # of the answer (reflected through its frontal plane) polished too and the lower cost
        # kept: a body facing the wrong way explains the silhouettes nearly as well, and no local
        # search turns it round
        n_polish = min(max(options.polish_shape_free, n_free), model.n_shape) if n_free else 0
        box, pstep = parameter_box(model, lo, hi, n_polish)
        twin = ((lambda s, p: frontal_twin(model, s, model.clip_pose(p)))
                if options.frontal_twin and previous_pose is None else None)
        obj, x_nm, polish, twin_costs, n_copy = polish_frame(obj, x_nm, box, pstep, level=final,
                                                             iterations=options.polish_iterations,
                                                             shape_prior=options.polish_shape_prior, twin=twin,
                                                             outline=options.polish_outline)
        n_early += n_copy
    timings["polish"] = time.perf_counter() - t
    t = time.perf_counter()
    last = [Stage(tuple(range(6)) + tuple(shape_idx) + tuple(i for g in _part_groups()[:1] for i in g),
                  options.final_evaluations, "final")]
    n_distal = options.distal_share * options.final_evaluations
    n_distal *= 1.0 if previous_pose is None else options.tracking_budget
    if n_distal >= 1:  # forearms, shins, hands, feet and head at full resolution first
        last.insert(0, Stage(tuple(i for g in _part_groups()[1:] for i in g), int(n_distal), "distal"))
    fin = staged_nelder_mead(obj.scalar(final), x_nm, last, bounds=(blo, bhi), step=step * 0.5, adaptive=True)
    timings["final"] = time.perf_counter() - t
    shapes, poses = obj.split(fin.x[None])
    shape_out, pose_out = shapes[0], model.clip_pose(poses[0])
    if support is not None and options.polish_iterations:
        # the stool's region was found from the search's body; found again from the final body it
        # may differ (a body risen on the seat uncovers its rim): then the polish once more under it
        # (its box as before: ``obj`` frees the search's coefficients again). Dev seated frames:
        # 6 of 15 closer to the true body, none farther; no support under a standing body
        again = find_support(model, cameras, masks, shape_out, pose_out)
        if again is not None and any((a != b).any() for a, b in zip(again.ignore, support.ignore, strict=True)):
            t = time.perf_counter()
            support = again
            targets = build_targets(masks, [c.name for c in cameras], options, ignore=support.ignore)
            n_early += obj.n_evaluations
            obj = replace(obj, targets=targets, n_evaluations=0)
            obj, x_re, _, _, n_copy = polish_frame(obj, obj.pack(shape_out, pose_out), box, pstep, level=final,
                                                   iterations=options.polish_iterations,
                                                   shape_prior=options.polish_shape_prior,
                                                   outline=options.polish_outline)
            n_early += n_copy
            shapes, poses = obj.split(x_re[None])
            shape_out, pose_out = shapes[0], model.clip_pose(poses[0])
            timings["support_polish"] = time.perf_counter() - t
    costs = obj.terms(obj.pack(shape_out, pose_out), final)
    t = time.perf_counter()
    quality = fit_quality(model, cameras, masks, shape_out, pose_out, costs, screen,
                          ignore=None if support is None else support.ignore)
    if support is not None:
        quality["support"] = support.to_json([c.name for c in cameras])
    timings["quality"] = time.perf_counter() - t
    costs["particle_filter_best"] = apf_cost
    costs["search"] = c_pose
    if rival_cost is not None:
        costs["search_rival_heading"] = rival_cost
    costs["nelder_mead_refine"] = float(nm.cost)
    if twin_costs is not None:
        costs["frontal_twin"] = twin_costs  # the polished answer's cost and its front/back twin's
    if polish is not None:
        costs["polish"] = [polish["cost_before"], min([polish["cost_before"], *polish["costs"]])]
    if start_family is not None:
        costs["start_family"] = start_family
    if init_height is not None:
        costs["init_stature_m"] = init_height
    timings["total"] = time.perf_counter() - t_start
    timings["cpu"] = time.process_time() - cpu_start  # this process's CPU time: comparable on a busy machine
    log.info("frame %d (%s): cost %.3f in %.1f s", frame, model.gender, costs["total"], timings["total"])
    fit = FrameFit(
        frame=int(frame), gender=model.gender, shape=shape_out, pose=pose_out,
        joints=model.joints(shape_out, pose_out), costs=costs, timings={k: round(v, 4) for k, v in timings.items()},
        n_evaluations=int(n_early + spent() + obj.n_evaluations), settings=options.to_dict(),
        quality=quality,
    )
    retries = MONOCULAR_RETRIES if len(cameras) == 1 else options.retries
    if previous_pose is None and _attempt < retries and search_again(quality, cameras):
        # a body that explains the silhouettes poorly (or at a high cost) is searched again with other random draws
        # (several views: from the library's other postures too) and the lower total cost is kept
        log.info("frame %d: the fitted body explains its views poorly or at a high cost: searching again", frame)
        avoid = _avoid + ((start_family,) if len(cameras) > 1 and start_family is not None else ())
        attempt = functools.partial(fit_frame, model, given[0], given[1], frame=frame, shape=shape, hint_pose=hint_pose,
                                    options=options, screen=screen, lights=lights, shadow_masks=shadow_masks,
                                    shadow_weight=shadow_weight, ground=ground, light_uncertainty=light_uncertainty)
        again = attempt(seed=np.random.default_rng(seed).integers(2**31), _attempt=_attempt + 1, _avoid=avoid)
        fit = keep_best(fit, again)
        if (_attempt == 0 and len(cameras) > 1 and match is not None and shape is None
                and search_again(fit.quality, cameras)):
            # still flagged or costly: once more from the library's other postures, each at its own stature
            avoid += tuple(f for f in (again.costs.get("start_family"),) if f is not None)
            draws = np.random.default_rng(seed).integers(2**31, size=3)
            last = attempt(seed=draws[1], _attempt=retries, _avoid=avoid, _own_statures=True)
            fit = keep_best(fit, last)
            if start_family is not None and init_height is not None and search_again(fit.quality, cameras):
                # and still: the first attempt's posture (the descriptor's best) from the library's
                # other statures of it, each at its own. The library's statures step 6 % and a squat's
                # is ambiguous: a dev half squat started at 1.79 m (true 1.71) ended 44.6 mm off and
                # its other postures' attempts 54.1 / 20.6 mm; from the half squat at 1.69, 4.5 mm
                other = attempt(seed=draws[2], _attempt=retries, _avoid=((start_family, init_height),),
                                _own_statures=True, _family=start_family)
                fit = keep_best(fit, other)
    return fit


def fit_frame_gender(cameras, masks, gender: str = "auto", **kwargs) -> FrameFit:
    """:func:`fit_frame` with a given gender, or ``"auto"``: fit the female and the male model
    and keep the lower total cost (thesis §4.7.2)."""
    if gender != "auto":
        return fit_frame(BodyModel.load(gender), cameras, masks, **kwargs)
    if kwargs.get("screen") is None:
        kwargs["screen"] = screen_masks(cameras, [np.asarray(m, dtype=bool) for m in masks],
                                        shadow=bool(kwargs.get("lights")), light=kwargs.get("light_uncertainty"))
    fits = [fit_frame(BodyModel.load(g), cameras, masks, **kwargs) for g in ("female", "male")]
    best = min(fits, key=lambda f: f.costs["total"])
    best.costs["gender_costs"] = {f.gender: f.costs["total"] for f in fits}
    return best
