"""Measurements: analytic meshes against formulas, the model's bodies, the inverse map."""

import numpy as np
import pytest

from studio.body import BodyModel, measure, mesh_volume, shape_from_measurements, slice_circumference
from studio.body.measure import convex_perimeter, slice_points


def prism(n=24, r=0.15, h=1.0):
    """Closed regular n-gon prism (a faceted cylinder) from z=0 to z=h."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.stack([r * np.cos(a), r * np.sin(a)], axis=1)
    v = np.concatenate([np.c_[ring, np.zeros(n)], np.c_[ring, np.full(n, h)], [[0, 0, 0], [0, 0, h]]])
    i = np.arange(n)
    j = (i + 1) % n
    f = np.concatenate([
        np.stack([i, j, n + j], 1), np.stack([i, n + j, n + i], 1),
        np.stack([np.full(n, 2 * n), j, i], 1), np.stack([np.full(n, 2 * n + 1), n + i, n + j], 1),
    ])
    return v, f


def test_prism_volume_and_circumference_match_formulas():
    n, r, h = 24, 0.15, 1.0
    v, f = prism(n, r, h)
    area = 0.5 * n * r * r * np.sin(2 * np.pi / n)
    assert mesh_volume(v, f) == pytest.approx(area * h, rel=1e-12)
    perimeter = 2 * n * r * np.sin(np.pi / n)
    assert slice_circumference(v, f, 0.37) == pytest.approx(perimeter, rel=1e-12)
    assert slice_circumference(v, f, 1.5) == 0.0


def test_box_and_concave_slice_use_the_convex_hull():
    # unit box [0,2]x[0,1]x[0,3]
    v = np.array([[x, y, z] for x in (0, 2) for y in (0, 1) for z in (0, 3)], float)
    f = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                  [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]])
    assert mesh_volume(v, f) == pytest.approx(6.0)
    assert slice_circumference(v, f, 1.0) == pytest.approx(6.0)
    # an L-shaped outline: the hull bridges the notch
    pts = np.array([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], float)
    assert convex_perimeter(pts) == pytest.approx(2 + 1 + np.sqrt(2) + 1 + 2)
    assert convex_perimeter(pts[:2]) == 0.0
    assert len(slice_points(v, f, 1.0)) >= 4


@pytest.fixture(scope="module")
def male():
    return BodyModel.load("male")


def test_measurements_of_the_mean_male_are_anthropometric(male):
    m = measure(male, male.mean_shape())
    assert 1.65 < m["stature"] < 1.95
    assert 0.95 < m["arm_span"] / m["stature"] < 1.1
    assert 0.85 < m["chest_circumference"] < 1.25
    assert 0.65 < m["waist_circumference"] < m["chest_circumference"]
    assert 0.85 < m["hip_circumference"] < 1.2
    assert 0.38 < m["inseam"] / m["stature"] < 0.52
    assert 0.45 < m["arm_length"] < 0.7
    assert 55 < m["mass"] < 100 and m["mass"] == pytest.approx(980 * m["volume"])
    assert measure(male, male.mean_shape(), density=1000.0)["mass"] == pytest.approx(1000 * m["volume"])
    with pytest.raises(ValueError, match="density"):
        measure(male, male.mean_shape(), density=-1)


def test_inverse_recovers_stature_and_mass(male):
    rng = np.random.default_rng(5)
    s = male.sample_shapes(1, rng)[0]
    truth = measure(male, s)
    keys = ("stature", "chest_circumference", "waist_circumference", "mass")
    est = shape_from_measurements(male, {k: truth[k] for k in keys}, refine=2)
    got = measure(male, est)
    assert abs(got["stature"] - truth["stature"]) < 0.01
    assert abs(got["mass"] - truth["mass"]) / truth["mass"] < 0.03
    # missing measurements: stature alone still gives a body of that stature
    est1 = shape_from_measurements(male, {"stature": 1.9}, refine=1)
    assert abs(measure(male, est1)["stature"] - 1.9) < 0.02


def test_inverse_rejects_bad_input(male):
    with pytest.raises(ValueError, match="measurements is empty"):
        shape_from_measurements(male, {})
    with pytest.raises(ValueError, match="unknown measurement"):
        shape_from_measurements(male, {"shoe_size": 42})
    with pytest.raises(ValueError, match="finite positive"):
        shape_from_measurements(male, {"stature": float("nan")})


def test_inverse_needs_matching_samples(male):
    shapes, values = male.measurement_samples
    with pytest.raises(ValueError, match="has 3 shape coefficients, the model has"):
        shape_from_measurements(male, {"stature": 1.8}, samples=(shapes[:, :3], values))
    from dataclasses import replace

    bare = replace(male, measurement_samples=None)
    with pytest.raises(ValueError, match="no measurement samples"):
        shape_from_measurements(bare, {"stature": 1.8})
