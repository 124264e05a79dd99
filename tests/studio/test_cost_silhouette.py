"""SilhouetteTarget / silhouette_cost (eq. 4.4-4.6): fast path equals the whole-image definition."""

import numpy as np
import pytest

from studio.cost import (
    SilhouetteTarget,
    downsample_mask,
    silhouette_cost,
    silhouette_pyramid,
    symmetric_chamfer,
    truncated_chamfer,
)

H, W = 60, 84


def ellipse(cy, cx, a, b, shape=(H, W)):
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    return ((yy - cy) / a) ** 2 + ((xx - cx) / b) ** 2 < 1


def views():
    observed = [ellipse(30, 40, 20, 9) | ellipse(14, 40, 5, 18), ellipse(32, 30, 18, 12), ellipse(28, 60, 22, 8)]
    model = [ellipse(32, 43, 18, 10) | ellipse(15, 44, 4, 16), ellipse(30, 33, 19, 11), ellipse(5, 5, 4, 4)]
    return observed, model


@pytest.mark.parametrize("xi", [1.0, 1.5])
@pytest.mark.parametrize("tau", [4.0, 7.5, 100.0])
def test_fast_cost_equals_whole_image_definition(xi, tau):
    observed, model = views()
    target = SilhouetteTarget.build(observed, tau=tau, xi=xi, names=["a", "b", "c"])
    cost = silhouette_cost(target, model)
    for k in range(3):
        assert cost.model_to_observed[k] == pytest.approx(truncated_chamfer(model[k], observed[k], tau, xi), rel=1e-6)
        assert cost.observed_to_model[k] == pytest.approx(truncated_chamfer(observed[k], model[k], tau, xi), rel=1e-6)
    expected_total = sum(symmetric_chamfer(m, o, tau, xi) for m, o in zip(model, observed))
    assert cost.total == pytest.approx(expected_total, rel=1e-6)
    np.testing.assert_allclose(cost.per_view, cost.model_to_observed + cost.observed_to_model)
    np.testing.assert_array_equal(cost.model_counts, [m.sum() for m in model])


def test_model_touching_border_and_far_away():
    observed = [ellipse(30, 40, 10, 10)]
    model = np.zeros((H, W), dtype=bool)
    model[:, W - 3 :] = True  # touches three borders, > tau from the observation
    target = SilhouetteTarget.build(observed, tau=6.0)
    cost = silhouette_cost(target, [model])
    assert cost.model_to_observed[0] == pytest.approx(6.0)
    assert cost.observed_to_model[0] == pytest.approx(6.0)
    assert cost.total == pytest.approx(symmetric_chamfer(model, observed[0], 6.0))


def test_perfect_fit_costs_zero_and_empty_views():
    observed, _ = views()
    target = SilhouetteTarget.build(observed, tau=5.0)
    assert silhouette_cost(target, observed).total == 0.0
    empty = [np.zeros((H, W), bool)] * 3
    cost = silhouette_cost(target, empty)
    # a model that left every view: each observed pixel costs tau, model term is 0
    np.testing.assert_allclose(cost.observed_to_model, 5.0)
    np.testing.assert_allclose(cost.model_to_observed, 0.0)
    np.testing.assert_array_equal(cost.model_counts, 0)
    # nothing observed: only model pixels outside (all of them, at tau) count
    blank = SilhouetteTarget.build(empty, tau=5.0)
    cost = silhouette_cost(blank, observed)
    np.testing.assert_allclose(cost.model_to_observed, 5.0)
    np.testing.assert_allclose(cost.observed_to_model, 0.0)


def test_downsample_mask_block_average():
    mask = np.zeros((5, 7), dtype=bool)
    mask[0:2, 0:2] = True  # full block
    mask[2, 2] = True  # 1 of 4 pixels: dropped
    mask[4, 6] = True  # padded corner block: 1 of 4 -> dropped
    mask[2:4, 4] = True  # 2 of 4: kept
    small = downsample_mask(mask, 1)
    assert small.shape == (3, 4)
    expected = np.zeros((3, 4), dtype=bool)
    expected[0, 0] = True
    expected[1, 2] = True
    np.testing.assert_array_equal(small, expected)
    np.testing.assert_array_equal(downsample_mask(mask, 0), mask)


@pytest.mark.parametrize("xi", [1.0, 1.5])
def test_pyramid_levels_are_consistent_and_in_full_resolution_units(xi):
    big_obs = [ellipse(120, 160, 80, 36, (240, 320))]
    big_mod = [ellipse(132, 178, 70, 44, (240, 320))]  # misfit of ~10 px, large against a level-2 pixel
    levels = silhouette_pyramid(big_obs, levels=3, tau=16.0, xi=xi)
    assert [t.level for t in levels] == [0, 1, 2]
    assert [t.image_size for t in levels] == [(240, 320), (120, 160), (60, 80)]
    assert levels[2].tau_level == 4.0
    assert levels[1].unit_factor == pytest.approx(2.0 ** (3 - 2 * xi))
    costs = []
    for target in levels:
        model = [downsample_mask(m, target.level) for m in big_mod]
        cost = silhouette_cost(target, model)
        # equals the whole-image definition at that level, scaled to full resolution
        ref = symmetric_chamfer(model[0], target.masks[0], target.tau_level, xi) * target.unit_factor
        assert cost.total == pytest.approx(ref, rel=1e-6)
        costs.append(cost.total)
    # coarse levels approximate the full-resolution value (within discretisation)
    assert costs[1] == pytest.approx(costs[0], rel=0.05)
    assert costs[2] == pytest.approx(costs[0], rel=0.2)


def test_target_is_read_only_and_reports():
    observed, model = views()
    target = SilhouetteTarget.build(observed, tau=5.0, names=["c0", "c1", "c2"])
    with pytest.raises(ValueError, match="read-only"):
        target.distance_maps[0][0, 0] = 1.0
    assert len(target) == 3 and target.scale == 1 and target.full_size == (H, W)
    assert target.counts == tuple(int(o.sum()) for o in observed)
    report = silhouette_cost(target, model).as_dict()
    assert set(report["views"]) == {"c0", "c1", "c2"}
    assert report["views"]["c1"]["model_pixels"] == int(model[1].sum())
    assert report["total"] == pytest.approx(sum(
        v["model_to_observed"] + v["observed_to_model"] for v in report["views"].values()))


def test_masks_by_view_name():
    observed, model = views()
    target = SilhouetteTarget.build({"left": observed[0], "right": observed[1]}, tau=5.0)
    assert target.names == ("left", "right")
    by_name = silhouette_cost(target, {"right": model[1], "left": model[0], "unused": model[2]})
    by_order = silhouette_cost(target, model[:2])
    np.testing.assert_array_equal(by_name.per_view, by_order.per_view)
    with pytest.raises(ValueError, match=r"model_masks: no model mask for views \['right'\]"):
        silhouette_cost(target, {"left": model[0]})
    with pytest.raises(ValueError, match="names: give either a"):
        SilhouetteTarget.build({"left": observed[0]}, names=["x"])


def test_bad_inputs():
    observed, model = views()
    target = SilhouetteTarget.build(observed, tau=5.0, names=["a", "b", "c"])
    small = [m[:-1] for m in model]
    with pytest.raises(ValueError, match=r"model mask of view 'a' \(level 0\): mask size \(59, 84\) .*\(60, 84\)"):
        silhouette_cost(target, small)
    with pytest.raises(ValueError, match=r"got 2 model masks for 3 observed views \['a', 'b', 'c'\]"):
        silhouette_cost(target, model[:2])
    with pytest.raises(ValueError, match="model_masks: expected a sequence"):
        silhouette_cost(target, model[0])
    with pytest.raises(TypeError, match="target: expected a SilhouetteTarget"):
        silhouette_cost(observed, model)
    with pytest.raises(ValueError, match="observed mask of view 'view1': mask size"):
        SilhouetteTarget.build([observed[0], observed[1][:, :-2]])
    with pytest.raises(ValueError, match="masks: expected a sequence"):
        SilhouetteTarget.build(observed[0])
    with pytest.raises(ValueError, match="at least one observed view"):
        SilhouetteTarget.build([])
    with pytest.raises(ValueError, match="names: got 1 names for 3"):
        SilhouetteTarget.build(observed, names=["x"])
    with pytest.raises(ValueError, match="level: expected an integer"):
        SilhouetteTarget.build(observed, level=-1)
    with pytest.raises(ValueError, match="level: expected an integer"):
        downsample_mask(observed[0], 1.5)
    with pytest.raises(ValueError, match="levels: expected the number"):
        silhouette_pyramid(observed, levels=0)
    with pytest.raises(ValueError, match="xi: "):
        SilhouetteTarget.build(observed, xi=float("inf"))
    with pytest.raises(ValueError, match="mask_size: "):
        SilhouetteTarget.build(observed, mask_size="fast")


def test_ignored_pixels_need_no_explaining_but_may_be_covered():
    """``ignore``: the observed-to-model term is the whole-image definition against the observed
    silhouette less the ignored region; the model-to-observed term still counts the ignored
    pixels as observed (a model covering them pays nothing)."""
    observed, model = views()
    prop = [ellipse(50, 40, 8, 20), np.zeros((H, W), bool), ellipse(50, 60, 6, 6)]
    seen = [o | p for o, p in zip(observed, prop)]
    tau = 7.5
    target = SilhouetteTarget.build(seen, tau=tau, ignore=[prop[0], None, prop[2]])
    cost = silhouette_cost(target, model)
    for k in range(3):
        assert cost.model_to_observed[k] == pytest.approx(truncated_chamfer(model[k], seen[k], tau), rel=1e-9)
        assert cost.observed_to_model[k] == pytest.approx(truncated_chamfer(seen[k] & ~prop[k], model[k], tau), rel=1e-9)
    assert cost.observed_to_model[0] < truncated_chamfer(seen[0], model[0], tau) - 0.5
    # the body alone explains all but the prop, and covering the prop is free
    assert silhouette_cost(target, observed).total == 0.0
    assert silhouette_cost(target, seen).total == 0.0
    # coarser levels ignore the blocks the downsampled prop covers
    coarse = SilhouetteTarget.build(seen, tau=tau, ignore=[prop[0], None, prop[2]], level=1)
    np.testing.assert_array_equal(coarse.masks[0], downsample_mask(seen[0], 1) & ~downsample_mask(prop[0], 1))
    with pytest.raises(ValueError, match="ignore: got 1 masks for 3"):
        SilhouetteTarget.build(seen, tau=tau, ignore=[prop[0]])
