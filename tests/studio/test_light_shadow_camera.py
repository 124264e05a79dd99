"""The shadow camera (thesis §5.4, eqs. 5.1-5.3): projection of a body onto the ground through a
point or a directional light, checked against an independent ray-plane intersection, and the
fast outline renderer against the per-face rasteriser."""

import numpy as np
import pytest

from calibration import Camera, GroundPlane
from meshkit import uv_sphere
from studio.body import BodyModel
from studio.render import DirectionalLight, PointLight, shadow_mask, shadow_outline, shadow_silhouettes, shadow_vertices


def _ray_plane(origin, direction, plane) -> np.ndarray:
    """Independent ray-plane intersection: solve ``origin + t·direction = p0 + a·e1 + b·e2`` for
    (t, a, b) as a 3×3 linear system, with (e1, e2) spanning the plane and p0 a point on it
    (no use of the closed form of eq. 5.2)."""
    n = plane.normal
    p0 = n * plane.offset
    e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    t, a, b = np.linalg.solve(np.stack([direction, -e1, -e2], axis=1), p0 - origin)
    return p0 + a * e1 + b * e2


@pytest.mark.parametrize("plane", [GroundPlane.floor(),
                                   GroundPlane.from_point_normal([0.2, -0.1, 0.03], [0.05, -0.08, 1.0])])
def test_projection_matches_independent_ray_plane_intersection(plane):
    rng = np.random.default_rng(3)
    P = rng.uniform([-0.8, -0.8, 0.1], [0.8, 0.8, 1.9], (40, 3))
    for L in ([1.3, -0.7, 3.4], [-2.5, 1.0, 2.6], [0.1, 0.2, 5.0]):
        S, valid = shadow_vertices(P, PointLight(L), plane)
        assert valid.all()
        ref = np.stack([_ray_plane(np.asarray(L, float), p - np.asarray(L, float), plane) for p in P])
        np.testing.assert_allclose(S, ref, atol=1e-9)
    for w in ([0.4, -0.3, -1.0], [-1.0, 0.2, -0.35]):
        light = DirectionalLight(w)
        S, valid = shadow_vertices(P, light, plane)
        assert valid.all()
        ref = np.stack([_ray_plane(p, light.direction, plane) for p in P])
        np.testing.assert_allclose(S, ref, atol=1e-9)


@pytest.fixture(scope="module")
def body():
    model = BodyModel.load("female")
    pose = model.default_pose()
    pose[:3] = [0.3, -0.2, 0.0]
    V = model.vertices(model.mean_shape(), pose)
    V[:, 2] -= V[:, 2].min()
    return V, model.faces


CAMS = [Camera.look_at("a", [3.2, -2.0, 2.3], [0.0, 0.0, 0.5], 170.0, (200, 150), [-0.04, 0.008, 0, 0]),
        Camera.look_at("b", [-2.5, -2.8, 2.0], [0.3, 0.0, 0.4], 160.0, (180, 140), [0.0, 0.0, 0, 0])]


def test_outline_fast_path_equals_rasterised_shadow(body):
    """The outline + winding fill gives the very masks of the per-face rasteriser, for point,
    directional and two lights (union), on the floor and on a tilted plane."""
    V, F = body
    tilted = GroundPlane.from_point_normal([0, 0, -0.02], [0.03, 0.02, 1.0])
    cases = [([PointLight([1.5, -1.0, 3.2])], None), ([DirectionalLight([-0.5, 0.4, -1.0])], None),
             ([PointLight([-1.2, -1.6, 2.8]), PointLight([1.8, 0.9, 3.5])], None),
             ([PointLight([0.9, 1.4, 3.0])], tilted)]
    for lights, plane in cases:
        fast = shadow_silhouettes(CAMS, V, F, lights, plane)
        for cam, m in zip(CAMS, fast):
            ref = np.zeros_like(m)
            for light in lights:
                ref |= shadow_mask(cam, V, F, light, plane)
            assert ref.sum() > 200
            assert (m ^ ref).sum() <= 2, f"{cam.name}: {(m ^ ref).sum()} pixels differ of {ref.sum()}"
        assert shadow_outline(V, F, lights[0], plane) is not None


def test_outline_falls_back_when_light_is_below_the_body(body):
    """A point light at shoulder height: some contour vertices are above it, the outline does not
    apply and the exact per-face path is used."""
    V, F = body
    light = PointLight([1.6, 0.0, 1.2])
    assert shadow_outline(V, F, light) is None
    fast = shadow_silhouettes(CAMS, V, F, light)
    for cam, m in zip(CAMS, fast):
        assert np.array_equal(m, shadow_mask(cam, V, F, light))


def test_open_mesh_uses_exact_path():
    V, F = uv_sphere([0.0, 0.0, 0.8], 0.2)
    half = F[V[F].mean(axis=1)[:, 2] > 0.8]
    light = PointLight([0.5, 0.4, 3.0])
    assert shadow_outline(V, half, light) is None
    m = shadow_silhouettes(CAMS[:1], V, half, [light])[0]
    assert np.array_equal(m, shadow_mask(CAMS[0], V, half, light))
