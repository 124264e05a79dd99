"""Settings of a single-frame fit (:class:`FitOptions`), with the measurements behind the defaults."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from studio.fit.errors import FitError

__all__ = ["FitOptions"]


@dataclass(frozen=True)
class FitOptions:
    """Settings of a single-frame fit (defaults: the ≤ 60 s budget on one core).

    Defaults measured on the walk sample (``benchmarks/fit_accuracy.py``): with the contour
    renderer a level-1 evaluation costs about what a level-2 one did, and searching at level 1
    (forearms ~6 px wide instead of ~3) with 240 + 450 Nelder–Mead evaluations took the
    stature error from −17.7 to −5.9 mm and the surface distance from 16.4 to 9.8 mm. Doubling the
    full-resolution stage to 900 evaluations (it had not converged: cost 0.72 → 0.52) took the
    silhouette precision / recall vs the true labels from 0.935 / 0.950 to 0.950 / 0.957, the
    surface distance to 7.8 mm and the joint error from 24.4 to 20.2 mm (frames 0, 6, 12, 18).
    Measured without gain: 15 free shape coefficients (24-frame walk: arm span error +31.8 →
    +18.9 mm, but stature −8.8 → −10.5 mm, precision 0.965 → 0.962, joints 15.6 → 19.2 mm),
    20 free shape coefficients (frame 0: precision 0.927 → 0.910), a
    ">1/2" instead of "≥1/2" coarse observed mask (frame 0: 0.927 → 0.927), a root + shape
    polish after the final stage (0.927 → 0.926). The shape prior (eq. 6.8) is flat within 3 σ
    and the shape is bounded to ±3 σ, so ``prior_weight`` does not act on the shape.

    ``levels``: (search, refine, final) pyramid levels. ``n_shape_free``: shape
    coefficients optimised (by decreasing eigenvalue). ``fit_shape``: False holds the shape.
    ``search_model``: the body the global particle filter scores — ``"cylinder"`` (the 15-cone
    model of §4.8.1 sized from the starting shape) or ``"scape"``; the heading search, the
    partitioned passes and Nelder–Mead always score SCAPE. ``limb_particles`` × ``limb_layers``:
    the per-limb re-search after the middle-level Nelder–Mead (0 turns it off).
    ``rival_heading``: also search from the opposite heading when fitting from the silhouettes.
    Measured on the held-out pose benchmark (``benchmarks/pose_accuracy.py``, variant
    ``no-rival``): without it a frame takes ~6 s less (of ~36 s), but walk frames went from
    9.5 to 17.7 mm and runs from 10.2 to 13.1 mm median surface distance (a stride facing away
    is the library's blind spot). Kept on: a six-posture dev set without strides had shown no
    loss; the strides do.
    ``find_support``: look for a prop under the searched body when it sits
    (:mod:`studio.fit.props`); when one is found, the observed pixels under the seat are left
    out of the observed-to-model term from the Nelder–Mead stages on (own-model seated body on
    a stool: 15.6 mm surface distance with the stool fitted as body, 6.9 mm without; held out,
    two seated frames: 16.3 → 12.5 mm median).
    ``start``: how a frame fitted from its silhouettes starts — ``"library"`` (the lab posture
    library matched to the silhouettes, :mod:`studio.fit.library`) or ``"stride"`` (12 headings
    × standing / stride postures, :func:`studio.fit.init.initial_poses`).
    ``distal_share``: a full-resolution Nelder–Mead stage of the distal joints (forearms, shins,
    hands, feet, head) before the final one, of ``distal_share × final_evaluations`` evaluations
    (tracking: × ``tracking_budget`` too; 0 turns it off). The fit's own
    cost is lower at the model's ceiling (``benchmarks/pose_ceiling.py``: our model fitted to the true
    body in 3-D) than at the fit on 31 of 32 dev frames, so the fit stops short; 400 distal + 600
    more final evaluations from the benchmark's dev fits lowered the cost of every one of them
    (median surface 9.0 → 8.6 mm, precision / recall +0.005, ~3 s CPU). With it (0.45: 405
    evaluations): walk frame 12 cost 0.441 → 0.346, surface 8.1 → 7.1 mm, +1.0 s CPU; held out
    (120 frames, once) median surface 10.0 → 9.6 mm, 80 frames closer, 100 at a lower cost.
    Off by default since the least-squares polish below (it covers those joints too).
    ``polish_iterations``: trust-region least squares (:func:`studio.fit.polish.lsq_polish`, at
    most this many iterations, 0 turns it off) on every parameter at full resolution after the
    per-limb search, before the final Nelder–Mead stage; the residuals are a smooth stand-in of
    eq. 4.5 (model vertices in the observed distance map, uncovered observed pixels to the
    nearest model vertex), the best iterate by the cost itself kept. Local optimisers compared
    from the benchmark's dev fits (``benchmarks/polish_compare.py``, 8 dev frames of 8
    families, 600 evaluations each): the fit's final stage run again lowered the median cost
    0.726 → 0.693 (surface 10.3 → 10.2 mm), Nelder–Mead over all 40 parameters → 0.621 (10.0),
    the same restarted halfway → 0.653 (10.0), Nelder–Mead per block (root + shape, spine +
    head, each limb, cycled twice) → 0.520 (9.7), least squares alone (15 iterations, 1.2 s
    CPU against 2.0–2.1 s for 600 evaluations in the same run) → 0.317 (7.8 mm, every frame lower and
    closer), least squares then the final stage → 0.282 (7.4 mm, P/R 0.938/0.948 →
    0.965/0.967, 3.2 s); CMA-ES not tried (``cma`` not installed). The stand-in had first counted
    every observed pixel near the outline, covered or not: it shrank the body (recall 0.936)
    and raised the cost on 2 of 8 frames. In the fit (16 dev frames, 4 people, side by side
    with the distal stage in one run at load 5–7): every frame at a lower cost and closer to
    the true body, median surface 9.1 → 6.2 mm (mean 11.5 → 9.3, worst 36.2 → 34.7: a half squat
    from the wrong start), P/R 0.939/0.951 → 0.962/0.962, joints 31.0 → 22.4 mm, CPU 12.9 →
    11.3 s per frame; with the final stage kept at 900 evaluations 6.2 mm, 12.7 s (so 500).
    Held out (120 frames, once, variant ``lsq-polish``): 119 frames closer and at a lower cost,
    median surface 9.6 → 6.3 mm, p90 17.3 → 12.2, P/R 0.935/0.945 → 0.961/0.962, ``ok`` 67 → 83 %,
    CPU 12.6 → 11.0 s per frame (mean).
    ``polish_shape_prior``: (weight, threshold σ) of a shape-prior stand-in in the polish's
    residuals (:func:`studio.fit.polish.shape_residuals`, eq. 6.8 with the threshold lowered;
    weight 0 turns it off). The least squares drove shape coefficients onto the ±3 σ bounds to
    make up for pose errors (held out: 14 of 120 frames at a bound, each flagged by the shape
    gate, 6 of them closer than 10 mm). Dev people (64 frames, 16 people, side by side): (0.05, 2)
    frames at a bound 2 → 0, median surface 6.73 → 6.75 mm, mean 8.38 → 8.36, p90 13.8 → 13.5;
    (0.2, 2) the same within 0.1 mm, so the weaker one.
    ``polish_shape_free``: shape coefficients the polish frees (0 or fewer than ``n_shape_free``:
    those of the search); the final stage then frees the search's again, the rest stay as polished.
    The model's ceiling (``benchmarks/pose_ceiling.py``) had put P/R 0.967/0.968 with the search's
    10 coefficients against 0.975/0.972 with all 30; Nelder–Mead had not gained from more (above),
    least squares pay one Jacobian column per coefficient. Dev people (64 frames, side by side in
    one run): 10 → 20 median surface 6.72 → 6.40 mm (mean 7.74 → 7.53, p90 11.5 → 11.2, 31 frames
    closer and 11 farther by more than 0.2 mm), P/R 0.964/0.964 → 0.968/0.965, median stature
    −4.3 → 0.0 mm, ``ok`` 95.3 → 96.9 %, CPU 12.3 → 13.2 s per frame; 30: the same within noise
    (6.42 mm, P/R 0.968/0.965, ``ok`` 95.3 %) at 13.8 s, and with 25 iterations instead of 15 (on
    58 of the frames) 4 frames closer, none farther, at +2.4 s CPU: so 20 and 15.
    ``polish_outline``: the polish's vertices read their distance beyond the outline of the
    observed pixels, half a pixel past their centres (:func:`studio.fit.polish.outline_distance`),
    instead of the distance map itself, where a vertex on that outline counts ½ px; off by default.
    On a body our model can represent exactly (the polish tests' scene) the stand-in at the true
    body falls 0.132 → 0.014 and the polish from 2–3 cm / 0.15 rad off ends at cost 0.13 instead
    of 0.21, joints 10 mm instead of 12 mm off (the previous model: 0.10 / 0.19, 7 / 11 mm). On the
    benchmark's Anny people (the previous model) it lowered the fit's
    own cost (dev: 49 of 64 frames, median −3.4 %) and balanced precision and recall (held out P/R
    0.972 / 0.966 → 0.970 / 0.970; dev 0.974 / 0.967 → 0.972 / 0.971) without bringing the
    bodies closer (dev mean surface 6.24 → 6.29 mm, 4 frames closer and 8 farther by more than
    0.3 mm; held out, once, 6.39 → 6.42 mm, p90 8.9 → 9.3, 11 closer and 17 farther; seated median
    9.4 → 9.7 mm, arms-overhead stature +10.6 → +12.0 mm): where our model cannot follow Anny's
    outline, a closer fit to the observed silhouettes is a fatter body, not a truer one.
    ``frontal_twin``: a frame fitted from its silhouettes also polishes the front/back twin of the
    polished answer (:func:`studio.fit.library.frontal_twin`: reflected through its own frontal
    plane, facing the other way, sides swapped) and keeps the lower cost: a body fitted facing
    the wrong way (a T-pose or hands on hips: every limb in the frontal plane) explains the
    silhouettes nearly as well, and no local search turns it round. Dev (64 frames, with the
    shape prior above): a hands-on-hips frame fitted backwards (joints 441 mm off) 22.7 → 6.7 mm,
    a T-pose 18.5 → 16.3 mm; the 62 others unchanged; mean surface 8.36 → 8.08 mm, ~1.5 s CPU.
    ``stature_steps``: relative stature changes searched around the library's stature with its
    best start (:func:`studio.fit.init.stature_search`, e.g. its ``STATURE_STEPS``); off by
    default. On the dev people (28 frames, with the distal stage and the library without mirror
    twins) it took the seated stature from −60 to −33 mm (median; a seated frame −99 → −59 mm) but
    the fits changed chaotically: median surface 9.8 → 9.8 mm, 90th percentile 13.1 → 17.7 mm,
    `ok` 89 → 82 %, a half squat +52 mm tall (−6 before).
    ``retries``: a frame of several views fitted from its silhouettes whose body explains them
    poorly (the agreement gates) or at a high cost for its silhouettes' size
    (:func:`studio.fit.result.search_again`) is searched again up to this many times, with other random
    draws and from the library's postures other than those the last attempt started from; the
    lowest total cost is kept (one view: ``studio.fit.frame.MONOCULAR_RETRIES``). Before the
    least-squares polish, on the dev people (24 frames, 4 flagged) one retry kept the first
    attempt on 3 flagged frames and on the 4th reached a lower cost but a worse body (half squat
    34.4 → 37.3 mm). With the polish (each attempt ends nearer its own minimum, so their costs
    compare fairly) one retry is on: dev, 64 frames with the shape prior and the front/back twin,
    5 flagged: an arm forward started as arms crossed 17.5 → 5.1 mm, a T-pose 16.3 → 9.8 mm, a
    half squat 33.4 → 30.8 mm; `ok` 92.2 → 95.3 %, mean surface 8.08 → 7.74 mm, p90 12.4 → 11.5;
    a flagged frame takes twice the time (mean 12.3 → 14.2 s per frame, two at once). Still flagged
    or costly after the retry, a frame is searched a third time (the library's other postures,
    each at its own stature) and, costly still, a fourth (the first attempt's posture at the
    library's other statures of it): :func:`studio.fit.frame.fit_frame`.

    Frames fitted alone from the silhouettes (walk, frames 0/6/12/18/21): with the cone search,
    stride postures and the limb re-search the joint error was 17/13/29/29/21 mm; SCAPE search
    with standing-only starts and no limb re-search gave 22/45/37/16/— mm (frame 6 fitted alone
    had started 120° off: 241 mm), frame 12's right wrist 205 mm off before the limb re-search.
    """

    levels: tuple[int, int, int] = (1, 1, 0)
    tau: float = 20.0
    xi: float = 1.0
    n_particles: int = 80
    n_layers: int = 8
    n_particles_tracking: int = 48
    n_layers_tracking: int = 5
    nm_evaluations: int = 240
    final_evaluations: int = 500
    distal_share: float = 0.0
    polish_iterations: int = 15
    polish_shape_prior: tuple[float, float] = (0.05, 2.0)
    polish_shape_free: int = 20
    polish_outline: bool = False
    frontal_twin: bool = True
    stature_steps: tuple[float, ...] = ()
    partition_particles: int = 40
    tracking_budget: float = 0.5
    partition_layers: int = 4
    limb_particles: int = 32
    limb_layers: int = 4
    rival_heading: bool = True
    n_shape_free: int = 10
    fit_shape: bool = True
    prior_weight: float = 1.0
    search_model: str = "cylinder"
    start: str = "library"
    find_support: bool = True
    retries: int = 1

    def __post_init__(self):
        if self.search_model not in ("scape", "cylinder"):
            raise FitError(f"search_model: expected 'scape' or 'cylinder', got {self.search_model!r}")
        if self.start not in ("library", "stride"):
            raise FitError(f"start: expected 'library' or 'stride', got {self.start!r}")
        prior = self.polish_shape_prior
        if (len(prior) != 2 or not all(np.isfinite(float(v)) and float(v) >= 0 for v in prior)):
            raise FitError(f"polish_shape_prior: expected (weight >= 0, threshold σ >= 0), got {prior!r}")
        if isinstance(self.polish_shape_free, bool) or not isinstance(self.polish_shape_free, int) \
                or self.polish_shape_free < 0:
            raise FitError(f"polish_shape_free: expected an integer >= 0, got {self.polish_shape_free!r}")
        if not isinstance(self.polish_outline, bool):
            raise FitError(f"polish_outline: expected True or False, got {self.polish_outline!r}")
        if isinstance(self.retries, bool) or not isinstance(self.retries, int) or self.retries < 0:
            raise FitError(f"retries: expected an integer >= 0, got {self.retries!r}")

    def to_dict(self) -> dict:
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}
