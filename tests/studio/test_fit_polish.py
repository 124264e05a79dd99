"""Issue 13: the least-squares polish of a fitted frame (:mod:`studio.fit.polish`)."""

import numpy as np
import pytest

from studio.body import BodyModel
from studio.body.skeleton import POSE_SIZE, pose_slices
from studio.fit import FitOptions
from studio.fit.evaluate import joint_error
from studio.fit.frame import build_targets
from studio.fit.objective import FrameObjective, pose_bounds
from studio.fit.polish import _root, contour_residuals, lsq_polish
from studio.render import silhouette

from test_fit_frame import ring_cameras, true_body


@pytest.fixture(scope="module")
def frame():
    """An own-model body in 4 views (328×246), its objective at full resolution (3 shape
    coefficients free) and a start 2–3 cm and 0.1–0.15 rad off."""
    model = BodyModel.load("female")
    cams = ring_cameras()
    shape, pose = true_body(model)
    masks = [silhouette(c, model.vertices(shape, pose), model.faces) for c in cams]
    targets = build_targets(masks, [c.name for c in cams], FitOptions(levels=(0, 0, 0)))
    obj = FrameObjective(model, cams, targets, shape, 3)
    sl = pose_slices()
    start = pose.copy()
    start[:2] += [0.02, -0.03]
    start[5] += 0.1
    start[sl[3]] += [0.15, -0.1, 0.0]  # left upper arm
    start[sl[10]] += 0.15  # left knee
    start[sl[13]] += 0.1  # right knee
    sig = np.sqrt(model.eigenvalues[:3])
    lo, hi = pose_bounds(model, pose[:2])
    bounds = (np.concatenate([lo, -3 * sig]), np.concatenate([hi, 3 * sig]))
    step = np.concatenate([np.full(POSE_SIZE, 0.08), 0.5 * sig])
    step[:3] = 0.03
    x0 = obj.pack(shape, model.clip_pose(start))
    return model, obj, shape, pose, x0, bounds, step


def test_the_residuals_square_to_the_distances_and_the_jacobian_matches_differences(frame):
    model, obj, shape, pose, x0, bounds, step = frame
    d = np.array([0.0, 0.5, 3.0, 20.0])
    r, slope = _root(d, 1.0)
    np.testing.assert_allclose(r**2, d**2 / (d + 1))  # ≈ d far from 0, as eq. 4.4 sums distances
    np.testing.assert_allclose(slope, (_root(d + 1e-6, 1.0)[0] - r) / 1e-6, rtol=1e-4)
    res, jac = contour_residuals(obj)
    x_true = obj.pack(shape, pose)
    # the true body explains its masks (cost 0; the stand-in 0.132 against 1.50: outline vertices
    # read the distance map bilinearly across the outline's pixel), and reading their distance
    # beyond the outline of the observed pixels the stand-in nearly vanishes there (0.014 against 1.13)
    assert np.sum(res(x_true) ** 2) < 0.1 * np.sum(res(x0) ** 2)
    res_outline = contour_residuals(obj, outline=True)[0]
    assert np.sum(res_outline(x_true) ** 2) < 0.02 < 0.1 < np.sum(res(x_true) ** 2)
    J = jac(x0, 0.05 * step)
    assert J.shape == (len(res(x0)), obj.size)
    # along the steepest descent of the squared sum, the sum falls as J predicts (within 2×)
    r0 = res(x0)
    d = -(J.T @ r0) * step**2
    d *= 0.01 / np.max(np.abs(d[3:POSE_SIZE]))  # the largest joint turn 0.01 rad
    predicted = 2 * r0 @ (J @ d)
    measured = np.sum(res(x0 + d) ** 2) - np.sum(r0**2)
    assert predicted < 0 and 0.5 * predicted > measured > 2 * predicted


def test_a_vertex_reads_its_distance_beyond_the_outline_of_the_observed_pixels():
    """The observed pixels' region ends half a pixel past their centres: a vertex there reads 0
    (both silhouettes hold the same pixels), half a pixel further 0.5, anywhere inside 0."""
    from studio.cost.chamfer import truncated_distance_map
    from studio.fit.polish import _bilinear, outline_distance

    mask = np.zeros((9, 12), bool)
    mask[:, :5] = True  # observed pixel centres x = 0 … 4: the outline at x = 4.5
    d = outline_distance(truncated_distance_map(mask, 6.0))
    read = np.maximum(_bilinear(d, np.array([[2.0, 4.0], [4.0, 4.0], [4.5, 4.0], [5.0, 4.0], [6.5, 4.0]])), 0)
    np.testing.assert_allclose(read, [0.0, 0.0, 0.0, 0.5, 2.0])


def test_polish_lowers_the_cost_and_recovers_the_pose(frame):
    """From 2–3 cm and 0.1–0.15 rad off, 15 least-squares iterations take the cost from 1.59 px
    to 0.21 and the joints from 41 to 12 mm off the truth (with the vertices reading their distance
    beyond the observed outline, ``outline``: 0.13 px, 10 mm); Nelder–Mead over the same 33
    parameters with 200 evaluations reaches 0.51 px, 22 mm."""
    from studio.optimize import Stage, staged_nelder_mead

    model, obj, shape, pose, x0, bounds, step = frame
    V_true = model.vertices(shape, pose)

    def joints_off(x):
        s, p = obj.split(x[None])
        return joint_error(model, model.vertices(s[0], model.clip_pose(p[0])), V_true)[0]

    c0 = float(obj(x0[None], 0)[0])
    x, c, rec = lsq_polish(obj, x0, bounds, step, max_nfev=15)
    nm = staged_nelder_mead(obj.scalar(0), x0, [Stage(tuple(range(obj.size)), 200)], bounds=bounds, step=step * 0.5,
                            adaptive=True)
    assert rec["cost_before"] == pytest.approx(c0) and c0 > 1.5
    assert c < 0.25 and c == pytest.approx(float(obj(x[None], 0)[0])) and c == pytest.approx(min(rec["costs"]))
    assert joints_off(x0) > 0.035 and joints_off(x) < 0.013
    x_o, c_o, _ = lsq_polish(obj, x0, bounds, step, max_nfev=15, outline=True)
    assert c_o < 0.15 < c and joints_off(x_o) < 0.011 < joints_off(x)
    assert np.all(x >= bounds[0]) and np.all(x <= bounds[1])
    assert nm.cost > 2 * c and joints_off(nm.x) > joints_off(x)


def test_the_shape_prior_rows_are_zero_inside_the_threshold_and_pull_back_beyond_it(frame):
    """The polish's shape-prior rows (eq. 6.8 with a lower threshold): 0 within ``threshold`` σ on
    every free coefficient, √w·(|β|/σ − threshold) beyond, and their Jacobian the exact slope."""
    from studio.fit.polish import shape_residuals

    model, obj, shape, pose, x0, bounds, step = frame
    sig = np.sqrt(model.eigenvalues[:3])
    res, jac = shape_residuals(obj, 0.25, 2.0)
    x = x0.copy()
    x[-3:] = [1.5, -1.9, 0.0] * sig
    assert np.all(res(x) == 0) and np.all(jac(x) == 0)
    x[-3:] = [2.5, -3.0, 0.0] * sig
    np.testing.assert_allclose(res(x), [0.25, 0.5, 0.0])  # √0.25 × (2.5 − 2), √0.25 × (3 − 2)
    J = jac(x)
    assert J.shape == (3, obj.size) and np.all(J[:, :-3] == 0)
    np.testing.assert_allclose(np.diag(J[:, -3:]), [0.5 / sig[0], -0.5 / sig[1], 0.0])
    # the polish from a start with the first coefficient at the 3 σ bound: the prior brings it in
    x_start = x0.copy()
    x_start[-3] = 3 * sig[0]
    free, _, _ = lsq_polish(obj, x_start, bounds, step, max_nfev=15)
    pulled, _, _ = lsq_polish(obj, x_start, bounds, step, max_nfev=15, shape_prior=(1.0, 0.5))
    assert abs(pulled[-3]) < abs(free[-3])


@pytest.mark.parametrize("bad, field", [({"polish_shape_prior": (0.05,)}, "polish_shape_prior"),
                                        ({"polish_shape_prior": (-1.0, 2.0)}, "polish_shape_prior"),
                                        ({"polish_shape_prior": (0.05, float("nan"))}, "polish_shape_prior"),
                                        ({"retries": -1}, "retries"), ({"retries": 1.5}, "retries"),
                                        ({"polish_shape_free": -1}, "polish_shape_free"),
                                        ({"polish_shape_free": True}, "polish_shape_free"),
                                        ({"polish_outline": 1}, "polish_outline"),
                                        ({"search_model": "cones"}, "search_model"), ({"start": "hull"}, "start")])
def test_bad_fit_options_name_the_field(bad, field):
    from studio.fit import FitError

    with pytest.raises(FitError, match=f"^{field}: expected"):
        FitOptions(**bad)
    assert FitOptions(**{field: getattr(FitOptions(), field)}).to_dict() == FitOptions().to_dict()


def test_the_polish_frees_more_shape_coefficients_than_the_search_when_asked():
    """``FitOptions.polish_shape_free`` above ``n_shape_free``: the polish moves the extra
    coefficients (within ±3 σ), the final stage keeps them as polished and frees the search's
    again, the coefficients beyond stay at the start's; everything before the polish is the same
    fit as without it (same seed)."""
    from dataclasses import replace

    from studio.fit import fit_frame

    model = BodyModel.load("female")
    cams = ring_cameras()
    shape, pose = true_body(model)
    masks = [silhouette(c, model.vertices(shape, pose), model.faces) for c in cams]
    tiny = FitOptions(levels=(2, 2, 0), n_particles=8, n_layers=1, nm_evaluations=4, final_evaluations=4,
                      n_shape_free=2, polish_shape_free=0, polish_iterations=4, partition_particles=0,
                      partition_layers=0, limb_particles=0, rival_heading=False, find_support=False, retries=0,
                      frontal_twin=False)
    base = fit_frame(model, cams, masks, options=tiny, seed=5)
    wide = fit_frame(model, cams, masks, options=replace(tiny, polish_shape_free=6), seed=5)
    assert wide.costs["polish"][0] == base.costs["polish"][0]  # the same body reached the polish
    sig = np.sqrt(model.eigenvalues)
    moved = np.abs(wide.shape[2:6] - base.shape[2:6]) / sig[2:6]
    assert np.any(moved > 0.05) and np.all(np.abs(wide.shape[:6] / sig[:6]) <= 3 + 1e-9)
    np.testing.assert_array_equal(wide.shape[6:], base.shape[6:])  # never freed: the start's
