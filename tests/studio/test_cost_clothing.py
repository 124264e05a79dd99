"""Clothing-robust cost (thesis eq. 6.1–6.4) against the reference chamfer of eq. 4.4."""

import numpy as np
import pytest

from studio.cost import ClothingTarget, clothing_cost, downsample_mask, inside_term, truncated_chamfer


def disc(shape, centre, radius):
    yy, xx = np.mgrid[: shape[0], : shape[1]]
    return (yy - centre[0]) ** 2 + (xx - centre[1]) ** 2 <= radius**2


SHAPE = (120, 160)


def scene():
    """A clothed 'person' (large disc) with a bare 'arm' (a skin bar) and a smaller body."""
    observed = disc(SHAPE, (60, 70), 35)
    arm = np.zeros(SHAPE, bool)
    arm[55:65, 70:140] = True
    observed |= arm
    skin = arm.copy()
    return observed, skin


def test_matches_the_reference_chamfer_per_region():
    observed, skin = scene()
    model = disc(SHAPE, (60, 72), 28) | (np.pad(np.ones((8, 60), bool), ((56, 56), (75, 25))))
    target = ClothingTarget.build([observed], [skin], tau=20.0, tau_cloth=4.0, cloth_weight=0.1, normalise="region")
    cost = clothing_cost(target, [model])
    cloth = observed & ~skin
    assert cost.inside[0] == pytest.approx(truncated_chamfer(model, observed, 20.0), rel=1e-5)
    assert cost.expansion["skin"][0] == pytest.approx(truncated_chamfer(skin, model, 20.0), rel=1e-5)
    assert cost.expansion["clothing"][0] == pytest.approx(truncated_chamfer(cloth, model, 4.0), rel=1e-5)
    assert cost.total == pytest.approx(cost.inside[0] + cost.expansion["skin"][0]
                                       + 0.1 * cost.expansion["clothing"][0])
    # at a pyramid level: the level's masks, τ in level pixels, distances back in full-resolution units
    down = lambda m: downsample_mask(m, 1)  # noqa: E731
    coarse = clothing_cost(ClothingTarget.build([observed], [skin], tau=20.0, tau_cloth=4.0, level=1, normalise="region"),
                           [down(model)])
    assert coarse.expansion["clothing"][0] == pytest.approx(
        2 * truncated_chamfer(down(observed & ~skin), down(model), 2.0), rel=1e-5)
    assert coarse.inside[0] == pytest.approx(2 * truncated_chamfer(down(model), down(observed), 10.0), rel=1e-5)


def test_silhouette_normalisation_makes_tight_clothing_eq_4_5():
    """Normalised by the whole silhouette, τ_c = τ and λ_c = 1 give the symmetric cost of eq. 4.5;
    each region's share is its numerator over |F^o|."""
    from studio.cost import SilhouetteTarget, silhouette_cost

    observed, skin = scene()
    model = disc(SHAPE, (60, 72), 28)
    tight = clothing_cost(ClothingTarget.build([observed], [skin], cloth_weight=1.0), [model])
    plain = silhouette_cost(SilhouetteTarget.build([observed]), [model])
    assert tight.total == pytest.approx(plain.total, rel=1e-6)
    region = clothing_cost(ClothingTarget.build([observed], [skin], cloth_weight=1.0, normalise="region"), [model])
    share = skin.sum() / observed.sum()
    assert tight.expansion["skin"][0] == pytest.approx(region.expansion["skin"][0] * share, rel=1e-6)
    with pytest.raises(ValueError, match="normalise: expected 'region' or 'silhouette'"):
        ClothingTarget.build([observed], [skin], normalise="pixels")


def test_inside_term_is_zero_inside_and_grows_outside():
    """Eq. 6.2: a body within its silhouettes costs nothing; leaving them costs more and more."""
    observed, skin = scene()
    target = ClothingTarget.build([observed], [skin])
    body = disc(SHAPE, (60, 70), 25)
    assert inside_term(target, [body]) == 0.0
    values = []
    for shift in (0, 15, 25, 40):
        moved = np.roll(body, shift, axis=1)
        values.append(inside_term(target, [moved]))
    assert values[0] == 0.0
    assert all(b > a for a, b in zip(values, values[1:])), values
    # the observed-side (SilhouetteTarget) and the clothing target agree on it
    from studio.cost import SilhouetteTarget

    assert inside_term(SilhouetteTarget.build([observed]), [np.roll(body, 25, axis=1)]) == pytest.approx(values[2])


def test_loose_clothing_lets_a_smaller_body_cost_less_than_tight():
    """Under clothing the body is smaller than its silhouette: the loose cost (τ_c, λ_c) barely
    penalises the gap, the tight one (eq. 4.5-like) does."""
    observed, skin = scene()
    body = disc(SHAPE, (60, 70), 27) | (np.pad(np.ones((10, 70), bool), ((55, 55), (70, 20))))
    loose = clothing_cost(ClothingTarget.build([observed], [skin], tau_cloth=4.0, cloth_weight=0.1), [body])
    tight = clothing_cost(ClothingTarget.build([observed], [skin], cloth_weight=1.0), [body])
    assert loose.inside[0] == tight.inside[0] == 0.0
    assert loose.expansion["skin"][0] == pytest.approx(tight.expansion["skin"][0])
    assert tight.total > 10 * loose.total
    # filling the silhouette still helps a little in loose mode (the body is asked to expand)
    fuller = clothing_cost(ClothingTarget.build([observed], [skin], tau_cloth=4.0, cloth_weight=0.1),
                           [body | disc(SHAPE, (60, 70), 34)])
    assert fuller.total < loose.total


def test_empty_model_and_bad_inputs():
    observed, skin = scene()
    target = ClothingTarget.build([observed], [skin], tau=20.0, tau_cloth=4.0, normalise="region")
    cost = clothing_cost(target, [np.zeros(SHAPE, bool)])
    assert cost.inside[0] == 0.0
    assert cost.expansion["skin"][0] == pytest.approx(20.0)
    assert cost.expansion["clothing"][0] == pytest.approx(4.0)
    assert cost.as_dict()["expansion"]["clothing"] == pytest.approx(4.0)
    with pytest.raises(ValueError, match="got 2 skin masks for 1 observed views"):
        ClothingTarget.build([observed], [skin, skin])
    with pytest.raises(ValueError, match="region 'hair': weight must be finite"):
        ClothingTarget.build_regions([observed], {"hair": [skin]}, taus={"hair": 3.0}, weights={"hair": -1})
    with pytest.raises(ValueError, match="needs a truncation"):
        ClothingTarget.build_regions([observed], {"hair": [skin]}, taus={}, weights={"hair": 1})
    with pytest.raises(ValueError, match="got 2 model masks for 1 observed views"):
        clothing_cost(target, [observed, observed])
    with pytest.raises(TypeError, match="expected a ClothingTarget"):
        clothing_cost(target.silhouettes, [observed])
    with pytest.raises(ValueError, match="at least one observed view"):
        ClothingTarget.build([])
