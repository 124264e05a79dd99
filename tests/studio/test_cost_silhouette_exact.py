"""SilhouetteTarget / silhouette_cost (eq. 4.4–4.6) on hand-computed pixels.

Each case is small enough to compute on paper: single pixels at known offsets (distances 1,
√2, OpenCV's documented 3×3 knight-move weight 0.955 + 1.3693), pixels beyond τ costing τ,
windows that meet the image border and observed pixels left of and above the model's window
(the summed-area count). The documented limits (pyramid level 0..8, 1..9 levels, a block kept
at exactly half its pixels) are tested at the boundary.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from studio.cost import SilhouetteCost, SilhouetteTarget, downsample_mask, silhouette_cost, silhouette_pyramid

TAU_EXACT = 1.0 + 2.0**-20  # float32-exact; n·τ is exact in float64, not when accumulated in float32


def pixels(shape, *where) -> np.ndarray:
    m = np.zeros(shape, bool)
    for rc in where:
        m[rc] = True
    return m


def test_far_pixels_cost_tau_to_the_last_bit_in_both_directions():
    """Accumulated in float64: 60 000 pixels each at τ give a mean of exactly τ."""
    corners = pixels((300, 400), (0, 0), (299, 399))
    block = np.zeros((300, 400), bool)
    block[50:250, 50:350] = True
    cost = silhouette_cost(SilhouetteTarget.build([corners], tau=TAU_EXACT), [block])
    assert cost.model_to_observed[0] == TAU_EXACT  # the model's block, all beyond τ of two corner pixels
    cost = silhouette_cost(SilhouetteTarget.build([block], tau=TAU_EXACT), [corners])
    assert cost.observed_to_model[0] == TAU_EXACT  # the observed block, all beyond τ of the model
    assert cost.model_to_observed[0] == TAU_EXACT


def test_observed_pixels_above_left_of_the_window_are_counted_once():
    """Model pixel (20, 20), τ = 2: its window is rows/columns 18..22. Observed: a 3×3 block at the
    top-left corner (9 pixels at τ, outside the window), (20, 21) at 1, (20, 22) at 2 = τ and
    (22, 22) at 2√2 → τ: (9·2 + 1 + 2 + 2) / 12."""
    observed = pixels((40, 40), (20, 21), (20, 22), (22, 22))
    observed[:3, :3] = True
    cost = silhouette_cost(SilhouetteTarget.build([observed], tau=2.0), [pixels((40, 40), (20, 20))])
    assert cost.observed_to_model[0] == pytest.approx(23 / 12, rel=1e-12)
    assert cost.model_to_observed[0] == pytest.approx(1.0, rel=1e-12)


def test_window_at_the_image_border():
    """Model pixel (1, 1), τ = 2: the window is clipped at row 0 and column 0, where observed pixels
    at distance 1, 1 and √2 lie."""
    observed = pixels((12, 12), (0, 1), (1, 0), (0, 0))
    cost = silhouette_cost(SilhouetteTarget.build([observed], tau=2.0), [pixels((12, 12), (1, 1))])
    assert cost.observed_to_model[0] == pytest.approx((1 + 1 + math.sqrt(2)) / 3, rel=1e-6)
    assert cost.model_to_observed[0] == pytest.approx(1.0, rel=1e-12)


def test_one_observed_pixel():
    cost = silhouette_cost(SilhouetteTarget.build([pixels((10, 12), (5, 5))], tau=10.0), [pixels((10, 12), (5, 8))])
    assert cost.observed_to_model[0] == 3.0
    assert cost.model_to_observed[0] == 3.0
    assert cost.total == 6.0


def test_counts_include_the_last_row_and_column():
    observed = np.zeros((7, 9), bool)
    observed[-1, :] = True
    observed[:, -1] = True
    target = SilhouetteTarget.build([observed])
    assert target.counts == (9 + 7 - 1,)
    assert target.summed_areas[0].dtype == np.int64 and target.summed_areas[0][-1, -1] == 15
    cost = silhouette_cost(target, [observed])
    assert cost.model_counts.dtype == np.int64
    assert cost.model_counts.tolist() == [15]


def test_mask_size_reaches_both_directions():
    """With OpenCV's 3×3 mask a knight move is 0.955 + 1.3693 (not √5) both ways."""
    knight = 0.955 + 1.3693
    observed, model = pixels((9, 9), (4, 4)), pixels((9, 9), (5, 6))
    target = SilhouetteTarget.build([observed], tau=10.0, mask_size=3)
    assert target.distance_maps[0][5, 6] == pytest.approx(knight, abs=1e-6)
    cost = silhouette_cost(target, [model])
    assert cost.model_to_observed[0] == pytest.approx(knight, abs=1e-6)
    assert cost.observed_to_model[0] == pytest.approx(knight, abs=1e-6)
    (level0,) = silhouette_pyramid([observed], levels=1, tau=10.0, mask_size=3)
    assert level0.mask_size == 3
    assert silhouette_cost(level0, [model]).total == pytest.approx(2 * knight, abs=1e-6)


def test_downsample_keeps_a_block_at_exactly_half():
    """Level 2 (4×4 blocks, "block average ≥ 1/2"): 8 of 16 pixels kept, 7 of 16 dropped."""
    mask = np.zeros((4, 8), bool)
    mask[:2, :4] = True  # 8 of the first block's 16
    mask[:1, 4:8] = True
    mask[1, 4:7] = True  # 7 of the second block's 16
    np.testing.assert_array_equal(downsample_mask(mask, 2), [[True, False]])
    mask[1, 7] = False
    mask[0, 7] = False  # 6 of 16
    np.testing.assert_array_equal(downsample_mask(mask, 2), [[True, False]])


def test_pyramid_limits_and_defaults():
    """Level: 0..8 inclusive; levels: 1..9 inclusive; defaults 3 levels and ξ = 1; names and
    mask size reach every level."""
    masks = [pixels((8, 8), (3, 3)), pixels((8, 8), (4, 4))]
    assert SilhouetteTarget.build(masks, level=8).image_size == (1, 1)
    with pytest.raises(ValueError, match=r"^level: expected an integer pyramid level in 0\.\.8, got 9$"):
        SilhouetteTarget.build(masks, level=9)
    assert len(silhouette_pyramid(masks, levels=1)) == 1
    assert [t.level for t in silhouette_pyramid(masks, levels=9)] == list(range(9))
    for bad in (10, 0, 2.5, True):
        with pytest.raises(ValueError, match=r"^levels: expected the number of pyramid levels in 1\.\.9"):
            silhouette_pyramid(masks, levels=bad)
    default = silhouette_pyramid(masks, names=["left", "right"], mask_size=5)
    assert len(default) == 3
    assert all(t.xi == 1.0 and t.names == ("left", "right") and t.mask_size == 5 for t in default)


def test_messages_name_the_argument():
    observed = [pixels((6, 6), (2, 2))] * 2
    target = SilhouetteTarget.build(observed, names=["a", "b"])
    with pytest.raises(ValueError, match=r"^masks: expected a sequence of \(H, W\) masks, one per view, "
                                         r"got a single 2-D array$"):
        SilhouetteTarget.build(observed[0])
    with pytest.raises(ValueError, match=r"^names: give either a \{name: mask\} mapping or names, not both$"):
        SilhouetteTarget.build({"a": observed[0]}, names=["a"])
    with pytest.raises(ValueError, match=r"^masks: at least one observed view is needed$"):
        SilhouetteTarget.build([])
    with pytest.raises(ValueError, match=r"^observed mask of view 'view0': expected a 2-D \(H, W\) mask"):
        SilhouetteTarget.build([np.zeros((6, 6, 3), bool), observed[1]])
    with pytest.raises(ValueError, match=r"^ignore mask of view 'a': expected a bool"):
        SilhouetteTarget.build(observed, names=["a", "b"], ignore=[np.zeros((6, 6)), None])
    with pytest.raises(ValueError, match=r"^ignore mask of view 'a': mask size \(1, 6\) \(H, W\) does not match"):
        SilhouetteTarget.build(observed, names=["a", "b"], ignore=[np.ones((1, 6), bool), None])
    with pytest.raises(ValueError, match=r"^model_masks: expected a sequence of \(H, W\) masks, one per view, "
                                         r"got a single 2-D array$"):
        silhouette_cost(target, observed[0])
    with pytest.raises(TypeError, match=r"^target: expected a SilhouetteTarget, got list$"):
        silhouette_cost(observed, observed)
    with pytest.raises(ValueError, match=r"^mask: expected a 2-D \(H, W\) mask"):
        downsample_mask(np.zeros((2, 2, 2), bool), 1)


def test_report_refuses_terms_of_different_lengths():
    cost = SilhouetteCost(names=("a", "b"), model_to_observed=np.array([1.0]), observed_to_model=np.array([2.0]),
                          model_counts=np.array([3]))
    with pytest.raises(ValueError, match="zip"):
        cost.as_dict()
