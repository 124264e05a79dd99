"""The multi-pose batch fit (thesis eq. 6.5–6.9) on silhouettes of our own model (tight clothing)."""

import numpy as np
import pytest

from studio.body import BodyModel, measure
from studio.body.skeleton import pose_slices
from studio.fit import FitOptions, fit_frame
from studio.fit.frame import build_targets
from studio.fit.batch import BatchFrame, BatchOptions, batch_fit, convert_shape, on_floor
from studio.fit.batch_frames import FLAG_FRAMES, choose_frames, trimmed_spread, two_people
from studio.fit.batch_gender import (GENDER_MARGIN_FLOOR, GENDER_PRIOR_WEIGHT, gender_scores, gender_test,
                                     stature_evidence)
from studio.fit.batch_session import batch_quality, gender_warning
from studio.fit.errors import FitError
from studio.fit.init import standing_pose
from studio.render import silhouette

from test_fit_frame import ring_cameras

#: the single-frame fits are the batch's starts, with a short least-squares polish (issue 13): the fit
#: searches on the model's search body and the polish refines the answer on the model itself
#: (BodyModel.search_model); with no polish a tiny budget left A0's single fit at 1.33× the cost of
#: the batch's shared shape, and the batch of two people went unflagged
TINY = FitOptions(levels=(2, 2, 1), n_particles=24, n_layers=3, nm_evaluations=25, final_evaluations=30,
                  n_shape_free=3, limb_particles=0, partition_particles=0, rival_heading=False, polish_iterations=5)
BATCH = BatchOptions(clothing="tight", levels=(2, 1), rounds=1, pose_evaluations=40, shape_evaluations=60,
                     final_evaluations=30, n_shape_free=3, gender_shape_free=3)


def person(model, size: float, short: float, arm: float, leg: float, heading: float, xy):
    """``size`` σ on the first shape component (girth), ``short`` σ on the third (stature down)."""
    sl = pose_slices()
    shape = model.mean_shape()
    shape[0] = size * np.sqrt(model.eigenvalues[0])
    shape[2] = short * np.sqrt(model.eigenvalues[2])
    pose = standing_pose(model)
    pose[:3] = [*xy, 0.0]
    pose[5] = heading
    pose[sl[3]] += [arm, 0.0, 0.0]
    pose[sl[9]] = [leg, 0.0, 0.0]
    return shape, model.clip_pose(pose)


@pytest.fixture(scope="module")
def frames():
    """Person A in two postures, person B (14 cm shorter, slimmer) in one, each fitted alone."""
    model = BodyModel.load("female")
    cams = ring_cameras()
    truth = {"A0": person(model, 1.0, -0.8, 0.3, 0.3, 0.5, (0.1, -0.1)),
             "A1": person(model, 1.0, -0.8, -0.4, -0.25, 2.0, (-0.1, 0.05)),
             "B0": person(model, -1.5, 1.5, 0.2, 0.2, -1.0, (0.0, 0.1))}
    out = {}
    for i, (name, (shape, pose)) in enumerate(truth.items()):
        V = model.vertices(shape, pose)
        masks = [silhouette(c, V, model.faces) for c in cams]
        fit = fit_frame(model, cams, masks, frame=i, options=TINY, seed=1)
        out[name] = (BatchFrame(i, cams, masks, None, fit.pose, fit.shape, "female"), shape, pose, fit)
    return model, out


def test_two_frames_of_one_person_agree_with_their_single_frame_fits(frames):
    model, fr = frames
    res = batch_fit([fr["A0"][0], fr["A1"][0]], gender="female", options=BATCH)
    true_stature = measure(model, fr["A0"][1])["stature"]
    singles = [measure(model, fr[k][3].shape)["stature"] for k in ("A0", "A1")]
    batch = measure(model, res.shape)["stature"]
    # the shared shape sits with the single-frame statures (a few cm off the truth at 328×246 with
    # a tiny budget) and no farther from the truth than they are; no pose moves far from its own
    assert abs(batch - np.mean(singles)) < 0.035, (batch, singles)
    assert abs(batch - true_stature) <= max(abs(s - true_stature) for s in singles) + 0.01, (batch, singles)
    # the poses no farther from the truth than the single fits': A0 24 mm (single 29), A1 (the
    # single fit's wrong heading) 327 mm (322) — the pose polish moves it 72 mm from its single fit
    # at a lower cost (4.65 → 3.65; without the polish 27 mm and no lower)
    for p, k in enumerate(("A0", "A1")):
        J_true = model.joints(fr[k][1], fr[k][2])
        J_single = model.joints(fr[k][3].shape, fr[k][3].pose)
        J_batch = model.joints(res.shape, res.poses[p])
        off_single, off_batch = (np.linalg.norm(J - J_true, axis=1).mean() for J in (J_single, J_batch))
        assert off_batch < off_single + 0.01, (k, off_batch, off_single)
        assert np.linalg.norm(J_batch - J_single, axis=1).mean() < (0.04 if k == "A0" else 0.1)
    assert not res.consistency["flagged"], res.consistency
    assert res.total == pytest.approx(res.costs.sum(), rel=0.05)
    obj = res.to_json()
    assert obj["frames"] == [0, 1] and obj["gender"] == "female" and obj["gender_margin"] is None
    assert set(obj["poses"]) == {"0", "1"} and len(obj["shape"]) == model.n_shape


def test_on_floor_moves_each_mesh_so_its_lowest_vertex_is_at_z0():
    V = np.array([[[0.0, 0.0, 0.05], [1.0, 2.0, 1.8]], [[0.0, 0.0, -0.03], [0.5, 0.5, 1.0]]])
    out = on_floor(V)
    assert np.allclose(out[:, :, 2], [[0.0, 1.75], [0.0, 1.03]])
    assert np.array_equal(out[:, :, :2], V[:, :, :2]) and V[0, 0, 2] == 0.05  # x, y kept; input untouched


def test_batch_stands_every_body_on_the_floor(frames):
    """Single-frame starts floating 4 cm above the floor (and sunk 3 cm into it): with ``floor``
    (the default under loose clothing) every batch body's lowest vertex is at z = 0 and the pose
    search leaves the root height alone; without it the starts' heights stay off the floor."""
    from dataclasses import replace

    model, fr = frames
    shifted = []
    for k, dz in (("A0", 0.04), ("A1", -0.03)):
        f = fr[k][0]
        pose = f.pose.copy()
        pose[2] += dz - model.vertices(f.shape, f.pose)[:, 2].min()
        shifted.append(replace(f, pose=pose))
    opts = replace(BATCH, rounds=1, pose_evaluations=20, shape_evaluations=20, final_evaluations=0, floor=True)
    on = batch_fit(shifted, gender="female", options=opts)
    assert BatchOptions(clothing="loose").stands and not BatchOptions(clothing="tight").stands
    assert on.to_json()["settings"]["floor"] is True
    for shape_pose in on.poses:
        assert abs(model.vertices(on.shape, shape_pose)[:, 2].min()) < 1e-9
    off = batch_fit(shifted, gender="female", options=replace(opts, floor=False))
    lows = [model.vertices(off.shape, p)[:, 2].min() for p in off.poses]
    assert max(abs(z) for z in lows) > 0.01, lows


def test_a_batch_mixing_two_people_is_flagged(frames):
    model, fr = frames
    res = batch_fit([fr["A0"][0], fr["B0"][0]], gender="female", options=BATCH)
    cons = res.consistency
    assert cons["flagged"], cons
    assert cons["stature_spread_m"] > 0.1
    assert any("spread" in r or "shared shape costs" in r for r in cons["reasons"])


def test_two_people_needs_the_evidence_of_two_frames():
    """One failed single-frame fit among eleven (its stature 300 mm off, the shared shape costing it
    1.9× its own: a loose-clothed frame) is not a second person; two frames are (FLAG_FRAMES)."""
    labels = list(range(11))
    ratios = np.array([0.6, 0.7, 0.5, 0.8, 0.9, 1.9, 0.6, 0.7, 0.8, 0.5, 0.6])
    statures = np.full(11, 1.70) + np.linspace(-0.01, 0.01, 11)
    statures[5] = 2.00
    assert FLAG_FRAMES == 2 and trimmed_spread(statures) == pytest.approx(0.02)
    assert two_people(labels, ratios, statures) == []
    # the same outlier twice: both reasons, the frames worst first
    r2, s2 = ratios.copy(), statures.copy()
    r2[[5, 8]], s2[8] = [1.9, 2.4], 1.95
    assert two_people(labels, r2, s2) == [
        "frames 8, 5: the shared shape costs 2.40x, 1.90x their own single-frame shapes (> 1.6 on 2 or more)",
        "single-frame statures spread 260 mm without the farthest frame (> 60 mm) and the shared shape explains "
        "2 frames worse than their own"]
    # a spread the shared shape explains better than the frames' own shapes is their fits' error
    s3 = statures.copy()
    s3[:5] = 1.60
    assert trimmed_spread(s3) == pytest.approx(0.11) and two_people(labels, ratios, s3) == []
    r3 = ratios.copy()
    r3[[0, 1]] = 1.05
    assert two_people(labels, r3, s3) == ["single-frame statures spread 110 mm without the farthest frame "
                                          "(> 60 mm) and the shared shape explains 3 frames worse than their own"]
    # a batch of two frames: both must agree; nothing is left out of its spread
    assert trimmed_spread([1.6, 1.75]) == pytest.approx(0.15)
    assert two_people([0, 1], [1.7, 1.8], [1.6, 1.61]) == [
        "frames 1, 0: the shared shape costs 1.80x, 1.70x their own single-frame shapes (> 1.6 on 2 or more)"]
    assert two_people([0, 1], [1.7, 0.9], [1.6, 1.75]) == []


def test_gender_by_batch_reports_both_costs_and_the_margin(frames):
    """A female body: both gender models are fitted with the poses fixed (the thesis' step,
    ``gender_step`` neutral), the lower cost wins."""
    model, fr = frames
    opts = BatchOptions(clothing="tight", levels=(2, 2), rounds=0, pose_evaluations=10, shape_evaluations=30,
                        n_shape_free=3, gender_shape_free=3, gender_step="neutral")
    res = batch_fit([fr["A0"][0], fr["A1"][0]], gender="auto", options=opts)
    assert set(res.gender_costs) == {"female", "male"}
    assert res.gender == min(res.gender_costs, key=res.gender_costs.get)
    assert res.margin == pytest.approx(abs(res.gender_costs["female"] - res.gender_costs["male"]))
    assert res.gender == "female" and res.margin > 0
    terms = res.gender_terms
    for g in ("female", "male"):
        # the batch cost per frame (2 frames) plus the stature evidence
        assert terms[g]["score"] == pytest.approx(terms[g]["cost"] / 2 + GENDER_PRIOR_WEIGHT * terms[g]["stature"])
        assert terms[g]["score"] == res.gender_costs[g]
    assert res.to_json()["gender_terms"] == terms
    # the paired test over the two frames: its per-frame margins average to the decision's margin
    test = res.to_json()["gender_test"]
    assert test["winner"] == res.gender and len(test["per_frame"]) == 2
    assert np.mean(test["per_frame"]) == pytest.approx(res.margin, abs=1e-5) and test["margin"] == res.margin
    lo, hi = test["interval"]
    assert lo < res.margin < hi and test["uncertain"] is (lo <= 0 or res.margin < GENDER_MARGIN_FLOOR)
    # the default rule is the thesis' (§6.4.5): the lower batch cost wins, the stature evidence only reported
    assert GENDER_PRIOR_WEIGHT == 0.0 and res.gender == min(terms, key=lambda g: terms[g]["cost"])


def test_gender_by_two_full_batches(frames):
    """``gender_step`` full: a complete batch of each gender, the lower total per frame wins; the
    result is the winner's own batch, both totals are its scores' costs, and the paired test runs
    over the two batches' final per-frame costs. The default under tight clothing; loose keeps
    the thesis' step."""
    model, fr = frames
    opts = BatchOptions(clothing="tight", levels=(2, 2), rounds=1, pose_evaluations=10, shape_evaluations=30,
                        n_shape_free=3, gender_shape_free=3, pose_iterations=0, gender_step="full")
    bf = [fr["A0"][0], fr["A1"][0]]
    res = batch_fit(bf, gender="auto", options=opts)
    own = {g: batch_fit(bf, gender=g, options=opts) for g in ("female", "male")}
    for g in own:
        assert res.gender_terms[g]["cost"] == pytest.approx(own[g].total, rel=1e-9)
        assert res.gender_costs[g] == pytest.approx(own[g].total / 2)
    assert res.gender == "female" and res.margin == pytest.approx(own["male"].total / 2 - own["female"].total / 2)
    assert res.shape == pytest.approx(own["female"].shape) and res.total == pytest.approx(own["female"].total)
    assert np.mean(res.gender_test["per_frame"]) == pytest.approx(res.margin, abs=1e-5)
    assert res.gender_test["per_frame"][0] == pytest.approx(
        own["male"].costs[0] - own["female"].costs[0] + res.margin - np.mean(own["male"].costs - own["female"].costs),
        abs=1e-5)
    assert res.to_json()["settings"]["gender_step"] == "full" and {"female", "male"} <= set(res.timings)
    assert BatchOptions(clothing="tight").gender_fit == "full" and BatchOptions(clothing="loose").gender_fit == "neutral"
    with pytest.raises(FitError, match="gender_step: expected one of neutral, full or None, got 'both'"):
        BatchOptions(gender_step="both")


class _Model:
    """Stand-in of a gender model for :func:`gender_scores`: its PCA's variances only."""

    n_shape = 4

    def __init__(self, sigma):
        self.eigenvalues = np.square(np.asarray(sigma, dtype=np.float64))


def test_gender_decision_adds_the_stature_evidence():
    """A loosely dressed 1.86 m man (costs of dev subject 3002): the cost alone favours the female
    model by 0.027; among ANSUR II adults 1.86 m is z = 3.61 for a woman, 1.51 for a man, so a
    stature weight of 0.1 (the previous default; score = cost + 0.1 × (z² + 2 ln σ)) calls him male
    by 1.03. At 1.69 m the evidence is nearly even (0.015 for the female model) and the cost decides."""
    female, male = _Model([1.0, 2.0, 0.5, 1.0]), _Model([2.0, 1.0, 1.0, 1.0])
    # (model, re-estimated shape, batch cost, the batch body in that model's coefficients)
    cands = {"female": (female, np.array([0.5, 0.0, 0.0, 9.0]), 3.236, np.array([2.0, 1.6, 0.0, 9.0])),
             "male": (male, np.array([3.0, 0.0, 0.0, 9.0]), 3.263, np.array([1.8, 0.0, 0.0, 9.0]))}
    terms = gender_scores(cands, 1.86, 3, weight=0.1)
    assert terms["female"]["stature"] == pytest.approx(3.606**2 + 2 * np.log(0.0642), abs=0.02)
    assert terms["male"]["stature"] == pytest.approx(1.513**2 + 2 * np.log(0.0686), abs=0.02)
    assert terms["female"]["score"] == pytest.approx(3.236 + 0.1 * terms["female"]["stature"])
    win = min(terms, key=lambda g: terms[g]["score"])
    assert win == "male" and terms["female"]["score"] - terms["male"]["score"] == pytest.approx(1.03, abs=0.01)
    # Mahalanobis distances reported: the batch body female (2/1)² + (1.6/2)² = 4.64, male
    # (1.8/2)² = 0.81 (the 4th coefficient not counted); the re-estimated shapes 0.25 and 2.25
    assert terms["female"]["mahalanobis"] == pytest.approx(4.64)
    assert terms["male"]["mahalanobis"] == pytest.approx(0.81)
    assert terms["female"]["mahalanobis_fit"] == pytest.approx(0.25)
    assert terms["male"]["mahalanobis_fit"] == pytest.approx(2.25)
    # at 1.69 m the stature favours neither much (0.015 for the female model), a cost lead of
    # 0.027 for the male model decides
    swapped = {"female": cands["female"][:2] + (3.263,) + cands["female"][3:],
               "male": cands["male"][:2] + (3.236,) + cands["male"][3:]}
    even = gender_scores(swapped, 1.69, 3, weight=0.1)
    assert 0.01 < 0.1 * (even["male"]["stature"] - even["female"]["stature"]) < 0.02
    assert min(even, key=lambda g: even[g]["score"]) == "male"
    plain = gender_scores(cands, 1.86, 3, weight=0.0)  # the thesis' rule: the lower cost
    assert min(plain, key=lambda g: plain[g]["score"]) == "female"
    assert stature_evidence(1.62, "female") < stature_evidence(1.62, "male")
    with pytest.raises(FitError, match="gender prior weight: expected a finite number >= 0"):
        gender_scores(cands, 1.86, 3, weight=-1.0)
    with pytest.raises(FitError, match="gender decision: expected a batch of at least 1 frame, got 0"):
        gender_scores(cands, 1.86, 3, n_frames=0)
    # the cost is a sum over frames, the stature evidence one per person: a batch of 11 frames
    # that each cost what this one-frame batch costs scores the same, so the same gender wins
    eleven = {g: c[:2] + (11 * c[2],) + c[3:] for g, c in cands.items()}
    many = gender_scores(eleven, 1.86, 3, weight=0.1, n_frames=11)
    for g in terms:
        assert many[g]["score"] == pytest.approx(terms[g]["score"]) and many[g]["cost"] == pytest.approx(11 * terms[g]["cost"])


def test_gender_test_is_a_paired_t_interval_over_the_frames():
    """Per-frame costs of the two gender fits (poses shared): the margin is the mean of the
    per-frame differences plus the per-batch terms; its 95 % interval is Student's t over the
    frames (scipy's paired test gives the same t). Frames that all favour one sex make a sure
    decision; frames split both ways around a small lead make it uncertain."""
    from scipy.stats import ttest_rel

    female = np.array([3.0, 2.8, 3.1, 2.9, 3.05])
    male = female + np.array([0.04, 0.05, 0.03, 0.06, 0.04])  # every frame favours the female fit
    scores = {"female": female.mean(), "male": male.mean() + 0.01}  # + a shape prior difference / P
    t = gender_test({"female": female, "male": male}, scores)
    assert t["winner"] == "female" and t["margin"] == pytest.approx(0.054)
    d = np.array(t["per_frame"])
    assert d == pytest.approx(male - female + 0.01) and d.mean() == pytest.approx(t["margin"])
    assert t["se"] == pytest.approx(np.std(male - female, ddof=1) / np.sqrt(5))
    # t_{0.975, 4} = 2.776
    assert t["interval"] == pytest.approx([0.054 - 2.776 * t["se"], 0.054 + 2.776 * t["se"]], abs=1e-4)
    assert t["uncertain"] is False and t["frames_for_winner"] == 5 and gender_warning(t) is None
    assert ttest_rel(male + 0.01, female).statistic == pytest.approx(t["margin"] / t["se"])
    # the same lead with frames split both ways: the interval reaches 0
    split = female + np.array([0.30, -0.25, 0.28, -0.22, 0.09])
    u = gender_test({"female": female, "male": split}, {"female": female.mean(), "male": split.mean()})
    assert u["winner"] == "female" and u["margin"] == pytest.approx(0.04) and u["uncertain"] is True
    assert u["interval"][0] < 0 < u["interval"][1] and u["frames_for_winner"] == 3
    why = gender_warning(u)
    assert why.startswith("gender uncertain: female by 0.040 per frame, 95 % interval -") and "3 of 5 frames" in why
    # every frame agreeing on a lead below the floor (GENDER_MARGIN_FLOOR): the interval clears 0,
    # the decision is still uncertain, and the warning says why
    small = female + np.array([0.02, 0.03, 0.01, 0.04, 0.02])
    f = gender_test({"female": female, "male": small}, {"female": female.mean(), "male": small.mean()})
    assert f["margin"] == pytest.approx(0.024) and f["interval"][0] > 0 and f["floor"] == GENDER_MARGIN_FLOOR == 0.05
    assert f["uncertain"] is True and gender_warning(f) == (
        "gender uncertain: female by 0.024 per frame, below the 0.050 the frames' agreement can vouch for "
        "(5 of 5 frames favour female)")
    assert gender_test({"female": female, "male": small}, {"female": female.mean(), "male": small.mean()},
                       floor=0.02)["uncertain"] is False
    # a male winner: the differences are female − male
    m = gender_test({"female": male, "male": female}, {"female": male.mean(), "male": female.mean()})
    assert m["winner"] == "male" and np.array(m["per_frame"]) == pytest.approx(male - female)
    assert gender_test({"female": female[:1], "male": male[:1]}, {"female": 3.0, "male": 3.04}) is None
    # fit/batch.json's quality: suspect with each reason, ok without
    assert batch_quality({"consistency": {"reasons": []}, "gender_test": t}) == {"status": "ok", "reasons": []}
    q = batch_quality({"consistency": {"reasons": ["frame 3: two people"]}, "gender_test": u})
    assert q == {"status": "suspect", "reasons": ["frame 3: two people", why]}
    assert batch_quality({"consistency": None, "gender_test": None}) == {"status": "ok", "reasons": []}


def test_shapes_convert_between_gender_models():
    female, neutral = BodyModel.load("female"), BodyModel.load("neutral")
    shape = female.mean_shape()
    shape[0] = 1.5 * np.sqrt(female.eigenvalues[0])
    beta = convert_shape(female, shape, neutral)
    assert abs(measure(neutral, beta)["stature"] - measure(female, shape)["stature"]) < 0.015


def test_frame_choice_and_bad_options(frames):
    _, fr = frames
    fits = {i: fr[k][3] for i, k in enumerate(("A0", "A1", "B0"))}
    chosen = choose_frames(fits, 2)
    assert len(chosen) == 2 and chosen == sorted(chosen)
    with pytest.raises(FitError, match="clothing: expected one of tight, loose"):
        BatchOptions(clothing="baggy")
    with pytest.raises(FitError, match="pose_evaluations: expected an integer >= 1"):
        BatchOptions(pose_evaluations=0)
    with pytest.raises(FitError, match="rounds: expected an integer >= 0"):
        BatchOptions(rounds=-1)
    for bad in (1.5, -0.1, float("nan"), True, "half"):
        with pytest.raises(FitError, match=r"start_build: expected a share in \[0, 1\] or None"):
            BatchOptions(start_build=bad)
    with pytest.raises(FitError, match="batch fit: no frames"):
        batch_fit([])
    with pytest.raises(FitError, match="gender: expected auto"):
        batch_fit([fr["A0"][0]], gender="robot")


def test_loose_batch_takes_frames_failed_only_by_the_clothes(frames):
    """Loose clothing fattens single-frame fits past the population gate: with fewer than two
    usable frames a loose batch takes those (never a frame failed by its views or segmentation)."""
    from dataclasses import replace

    _, fr = frames

    def failed(fit, *checks):
        reasons = [{"check": c, "severity": "failed", "view": None, "message": c} for c in checks]
        return replace(fit, quality={"version": 1, "status": "failed", "reasons": reasons})

    base = [fr[k][3] for k in ("A0", "A1", "B0")]
    fits = {0: failed(base[0], "population"), 1: failed(base[1], "agreement", "population"),
            2: failed(base[2], "hull")}
    assert choose_frames(fits, 3, loose=True) == [0, 1]
    with pytest.raises(FitError, match="no single-frame fit passed the quality gates"):
        choose_frames(fits, 3)
    fits[2] = base[2]  # one good frame: still fewer than two, the clothes-failed ones join it
    assert choose_frames(fits, 3, loose=True) == [0, 1, 2] and choose_frames(fits, 3) == [2]


def test_auto_clothing_threshold_separates_tight_from_loose_coverage():
    """``--clothing auto`` on the dev split with this release's fit: tightly dressed people's loose
    batches covered 91.1–95.2 % of their clothing pixels, loosely dressed ones 62–87 % (87.1 %: a
    long shirt over ordinary trousers, which the former 80 % called tight)."""
    from studio.fit.batch_session import TIGHT_RECALL, clothing_from_coverage

    assert 0.871 < TIGHT_RECALL < 0.911
    assert clothing_from_coverage(0.911) == "tight"
    assert clothing_from_coverage(0.871) == "loose" and clothing_from_coverage(0.816) == "loose"
    assert clothing_from_coverage(0.5, threshold=0.4) == "tight"
    with pytest.raises(FitError, match=r"clothing coverage: expected a share in \[0, 1\]"):
        clothing_from_coverage(1.5)


def test_auto_clothing_refuses_tight_when_the_tight_cost_makes_the_body_implausible():
    """``--clothing auto`` on the shipped ``clothing_11`` sample (a woman, long shirt over a skirt)
    covered 0.83 of the clothing pixels and was called tight; the tight refit's hip girth came out
    1326 mm (truth 994 mm, +4.0 σ of ANSUR II's women): such a call is refused. A person as large
    under the loose cost keeps the tight call, and so does a plausible tight body."""
    from studio.fit.batch_session import implausible_tight
    from studio.fit.quality import POPULATION_Z, population_z

    loose = {"stature": 1.600, "mass": 62.0, "chest_circumference": 0.950, "waist_circumference": 0.760,
             "hip_circumference": 1.020}
    tight = {**loose, "mass": 84.0, "chest_circumference": 1.098, "waist_circumference": 0.903,
             "hip_circumference": 1.326}
    assert population_z(tight, "female")["hip_circumference"] > POPULATION_Z[0] > abs(
        population_z(loose, "female")["hip_circumference"])
    why = implausible_tight(loose, tight, "female")
    assert len(why) == 1 and why[0].startswith("hip circumference +4.0 σ from ANSUR II with the tight cost")
    assert implausible_tight(tight, tight, "female") == []  # as large when loose: a large person, not the clothes
    assert implausible_tight(loose, loose, "female") == []


def test_clothing_residuals_are_the_polish_residuals_under_tight_clothing_and_weight_the_clothes_when_loose(frames):
    """The batch's least-squares stand-in of eq. 6.1–6.4 is, with τ_c = τ and λ_c = 1, exactly
    the single-frame polish's stand-in of eq. 4.5 (residuals and Jacobian); under loose clothing
    its clothing samples are truncated at τ_c and weighted by √λ_c."""
    from studio.fit.batch import ClothedObjective, clothing_targets
    from studio.fit.batch_terms import clothing_residuals
    from studio.fit.objective import FrameObjective
    from studio.fit.polish import contour_residuals

    model, fr = frames
    f, shape, pose, _ = fr["A0"]
    start = pose.copy()
    start[:2] += [0.12, -0.09]  # the body 15 cm off: both directions nonzero
    opts = BatchOptions(clothing="tight", levels=(1, 1))
    sil = FrameObjective(model, f.cameras, build_targets(f.masks, [c.name for c in f.cameras],
                                                         FitOptions(levels=(1, 1, 1), tau=opts.tau)), shape, 0)
    tight = ClothedObjective(model, f.cameras, clothing_targets(f, opts), shape, 0)
    r_sil, j_sil = contour_residuals(sil, 1)
    r_cl, j_cl = clothing_residuals(tight, 1)
    h = np.full(len(start), 0.004)
    assert np.abs(r_sil(start)).sum() > 1.0
    np.testing.assert_allclose(r_cl(start), r_sil(start), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(j_cl(start, h), j_sil(start, h), rtol=1e-12, atol=1e-12)
    # loose, no skin seen: every observed sample is clothing, truncated at τ_c and weighted √λ_c
    loose_opts = BatchOptions(clothing="loose", levels=(1, 1))
    tau_c, lam = loose_opts.cloth
    loose = ClothedObjective(model, f.cameras, clothing_targets(f, loose_opts), shape, 0)
    r_lo = clothing_residuals(loose, 1)[0](start)
    assert len(r_lo) == len(r_cl(start))
    # model → observed rows (the inside term) and covered samples equal; an uncovered clothing
    # sample nearer than τ_c scaled by √λ_c, a farther one capped below that
    full, part = r_cl(start), r_lo
    same = np.isclose(part, full)
    scaled = np.isclose(part, np.sqrt(lam) * full) & ~same
    capped = ~same & ~scaled
    assert same.sum() > 0.4 * len(full) and scaled.sum() > 20 and capped.sum() > 20, (same.sum(), scaled.sum())
    assert np.all(part[capped] < np.sqrt(lam) * full[capped])


def test_pose_polish_brings_a_bent_knee_back(frames):
    """A frame's knee bent 0.3 rad more than the truth, the true shape held: the batch's pose
    polish (least squares on the clothing residuals at full resolution) brings it back within
    0.05 rad (cost 0.89 → 0.10, the truth's 0); the polish runs by default under tight clothing
    only."""
    from dataclasses import replace

    from studio.fit.batch import _Batch, pose_polish

    model, fr = frames
    opts = BatchOptions(clothing="tight", levels=(0, 0), pose_iterations=10)
    assert BatchOptions(clothing="tight").polish_iterations == 12 and BatchOptions(clothing="loose").polish_iterations == 0
    assert BatchOptions(clothing="loose", pose_iterations=5).to_dict()["pose_iterations"] == 5
    frame, shape, pose = fr["A0"][:3]
    knee = pose_slices()[10]
    off = pose.copy()
    off[knee] += 0.3
    c_true, c_off = _Batch(model, [frame] * 2, opts).per_frame(shape, np.array([pose, off]), 0)
    polished, c = pose_polish(model, replace(frame, pose=off), shape, off, opts)
    assert c_true < 1e-6 and c < 0.25 * c_off, (c, c_true, c_off)
    assert np.abs(polished[knee] - pose[knee]).max() < 0.05, polished[knee] - pose[knee]


def test_loose_build_prior_pulls_the_hidden_build_to_the_mean_at_its_stature(frames):
    """Under loose clothing nothing in the silhouettes holds a build the clothes hide: started from
    a body 2.8 σ wide on the first coefficient, with a tail of the single fit's coefficients, the
    batch with the build prior (the default under loose clothing: weight and a reset tail) ends
    with a build nearer the mean body of its stature than the batch without it, at the same
    stature."""
    from dataclasses import replace

    from studio.body import measure
    from studio.fit.batch_terms import LOOSE_BUILD_WEIGHT, build_prior, stature_direction

    model, fr = frames
    f = fr["A0"][0]
    sigma = np.sqrt(model.eigenvalues)
    start = f.shape.copy()
    start[0] = 2.8 * sigma[0]
    start[3:8] = 1.5 * sigma[3:8]
    opts = replace(BATCH, clothing="loose", rounds=1, pose_evaluations=10, shape_evaluations=60, final_evaluations=0)
    assert opts.build == LOOSE_BUILD_WEIGHT > 0 and opts.tail_reset
    assert opts.to_dict()["build_weight"] == LOOSE_BUILD_WEIGHT and opts.to_dict()["reset_tail"] is True
    assert BatchOptions(clothing="tight").build == 0.0 and not BatchOptions(clothing="tight").tail_reset
    frame = replace(f, shape=start)
    on = batch_fit([frame], gender="female", options=opts)
    off = batch_fit([frame], gender="female", options=replace(opts, build_weight=0.0, reset_tail=False,
                                                              start_build=1.0))
    g = stature_direction(model, opts.n_shape_free)
    assert np.all(on.shape[opts.n_shape_free:] == 0.0)
    np.testing.assert_array_equal(off.shape[opts.n_shape_free:], start[opts.n_shape_free:])
    b_on, b_off = build_prior(on.shape, sigma, g), build_prior(off.shape, sigma, g)
    assert b_on < 0.5 * b_off, (b_on, b_off)
    h_on, h_off = measure(model, on.shape)["stature"], measure(model, off.shape)["stature"]
    # (20 mm apart since the loose batch also starts at the mean build: the stature's linear fit and
    # the tail's reset move a 2.8 σ start by that much; 6 mm before)
    assert abs(h_on - h_off) < 0.025, (h_on, h_off)


def test_loose_batch_starts_from_the_mean_build_of_the_single_fits_stature(frames):
    """With no alternation and no final step the batch's shape is its start: under loose clothing
    the single fit's stature with the mean build (and the tail at the mean), under tight the single
    fit's shape itself; ``start_build`` 1 keeps the build under loose clothing too."""
    from dataclasses import replace

    from studio.body import measure
    from studio.fit.batch_terms import build_prior, stature_direction

    model, fr = frames
    f = fr["A0"][0]
    sigma = np.sqrt(model.eigenvalues)
    start = f.shape.copy()
    start[0] = 2.5 * sigma[0]
    frame = replace(f, shape=start)
    opts = replace(BATCH, clothing="loose", rounds=0, final_evaluations=0, pose_iterations=0)
    assert opts.start_share == 0.0 and replace(opts, clothing="tight").start_share == 1.0
    assert replace(opts, start_build=0.25).start_share == 0.25 == replace(opts, start_build=0.25).to_dict()["start_build"]
    assert opts.to_dict()["start_build"] == 0.0  # the share in force is written, not None
    g = stature_direction(model, opts.n_shape_free)
    loose = batch_fit([frame], gender="female", options=opts).shape
    assert build_prior(start, sigma, g) > 4.0
    assert build_prior(loose, sigma, g) == pytest.approx(0.0, abs=1e-9)
    assert np.all(loose[opts.n_shape_free:] == 0.0)
    # the stature kept to the linear fit's accuracy (R² 0.97) and the tail's reset: 20 mm off here
    # for a start 2.5 σ wide
    assert abs(measure(model, loose)["stature"] - measure(model, start)["stature"]) < 0.025
    kept = batch_fit([frame], gender="female", options=replace(opts, start_build=1.0)).shape
    np.testing.assert_allclose(kept[:opts.n_shape_free], start[:opts.n_shape_free])
    tight = batch_fit([frame], gender="female", options=replace(opts, clothing="tight")).shape
    np.testing.assert_allclose(tight, start)
