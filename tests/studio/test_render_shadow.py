"""Shadow meshes through point and directional lights onto the ground (thesis eqs. 5.1-5.3)."""

import numpy as np
import pytest

from calibration import Camera, GroundPlane
from meshkit import uv_sphere as sphere
from studio.render import (
    DirectionalLight,
    PointLight,
    lambert,
    light_from_dict,
    shadow_mask,
    shadow_vertices,
    vertex_normals,
)


def test_point_light_projection_eq_5_2():
    light = PointLight([0.0, 0.0, 4.0])
    S, valid = shadow_vertices(np.array([[1.0, 0.0, 2.0], [0.5, 0.5, 3.0], [0.0, 0.0, 5.0]]), light)
    assert valid.tolist() == [True, True, False]
    np.testing.assert_allclose(S[0], [2.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(S[1], [2.0, 2.0, 0.0], atol=1e-12)
    # general plane: S is on the plane and on the line through L and P
    g = GroundPlane.from_point_normal([0, 0, 0.1], [0.1, 0.0, 1.0])
    P = np.random.default_rng(1).uniform([-1, -1, 0.5], [1, 1, 1.8], (50, 3))
    S, valid = shadow_vertices(P, light, g)
    assert valid.all()
    np.testing.assert_allclose(S @ g.normal, g.offset, atol=1e-12)
    cross = np.cross(S - light.position, P - light.position)
    np.testing.assert_allclose(cross, 0.0, atol=1e-12)


def test_directional_light_projection():
    light = DirectionalLight([1.0, 0.0, -1.0])
    S, valid = shadow_vertices(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -0.5]]), light)
    np.testing.assert_allclose(S[0], [1.0, 0.0, 0.0], atol=1e-12)
    assert valid.tolist() == [True, False]
    _, none = shadow_vertices(np.zeros((3, 3)) + 1, DirectionalLight([0, 0, 1.0]))
    assert not none.any()


def test_shadow_pixels_lie_where_light_ray_meets_floor():
    """The shadow of a ball in the image is centred on the projection of the floor point hit by
    the ray from the light through the ball's centre (eq. 5.2) and has the right size."""
    cam = Camera.look_at("c", [3.0, -2.0, 2.2], [0.0, 0.0, 0.3], 150.0, (160, 120), [-0.04, 0.0, 0, 0])
    C = np.array([0.1, -0.1, 0.8])
    V, F = sphere(C, 0.08)
    for light in (PointLight([-0.8, 0.9, 3.2]), DirectionalLight([0.5, -0.3, -1.0])):
        mask = shadow_mask(cam, V, F, light)
        if isinstance(light, PointLight):
            hit = light.position + (C - light.position) * light.position[2] / (light.position[2] - C[2])
        else:
            hit = C - light.direction * C[2] / light.direction[2]
        uv = cam.project(hit)[0]
        assert mask[int(round(uv[1])), int(round(uv[0]))]
        ys, xs = np.nonzero(mask)
        # the ellipse's centroid is near (not exactly at) the projected centre ray hit
        assert np.hypot(xs.mean() - uv[0], ys.mean() - uv[1]) < 1.5
        # every shadow pixel back-projects to a floor point whose ray from the light hits the ball
        o, d = cam.pixel_rays(np.stack([xs, ys], 1).astype(float))
        G = o + d * (-o[:, 2] / d[:, 2])[:, None]
        L = light.position if isinstance(light, PointLight) else G - 10 * light.direction
        u = (G - L) / np.linalg.norm(G - L, axis=1, keepdims=True)
        dist = np.linalg.norm(np.cross(C - L, u), axis=1)
        assert np.max(dist) < 0.08 + 0.02


def test_lambert_and_normals():
    V, F = sphere([0, 0, 0], 1.0)
    N = vertex_normals(V, F)
    np.testing.assert_allclose(np.einsum("ij,ij->i", N, V), 1.0, atol=0.02)
    np.testing.assert_allclose(vertex_normals(V, F[:, ::-1]), N, atol=1e-12)
    light = PointLight([0, 0, 10.0], intensity=0.5, falloff=True, reference_distance=9.0)
    E = lambert(np.array([[0, 0, 1.0], [0, 0, -1.0]]), np.array([[0, 0, 1.0], [0, 0, -1.0]]),
                [light], ambient=0.2)
    np.testing.assert_allclose(E, [0.2 + 0.5, 0.2], atol=1e-12)


def test_light_spec_errors():
    assert isinstance(light_from_dict({"type": "directional", "direction": [0, 0, -1]}), DirectionalLight)
    with pytest.raises(ValueError, match=r"lights\[0\].type: expected 'point' or 'directional'"):
        light_from_dict({"type": "spot"}, "lights[0]")
    with pytest.raises(ValueError, match=r"unknown field\(s\) \['colour'\]"):
        light_from_dict({"type": "point", "position": [0, 0, 3], "colour": 1})
    with pytest.raises(ValueError, match=r"position: required"):
        light_from_dict({"type": "point"})
    with pytest.raises(ValueError, match=r"direction: required"):
        light_from_dict({"type": "directional"})
    with pytest.raises(ValueError, match=r"expected a mapping"):
        light_from_dict([1, 2])
    with pytest.raises(ValueError, match=r"point light position: expected 3 finite numbers"):
        PointLight([0, 0])
    with pytest.raises(ValueError, match=r"intensity: expected >= 0"):
        PointLight([0, 0, 3], intensity=-1)
    with pytest.raises(ValueError, match=r"direction: must be non-zero"):
        DirectionalLight([0, 0, 0])
    with pytest.raises(ValueError, match=r"directional light intensity"):
        DirectionalLight([0, 0, -1], intensity=-1)
    with pytest.raises(ValueError, match=r"vertices: expected shape \(V, 3\)"):
        shadow_vertices(np.zeros((3, 2)), PointLight([0, 0, 3]))
    with pytest.raises(TypeError, match=r"light: expected PointLight or DirectionalLight"):
        shadow_vertices(np.zeros((3, 3)), object())


def test_shadow_of_closed_mesh_equals_all_faces():
    cam = Camera.look_at("c", [3.0, -2.0, 2.2], [0.0, 0.0, 0.3], 150.0, (160, 120), [-0.04, 0.0, 0, 0])
    V, F = sphere([0.2, 0.1, 0.7], 0.25)
    for light in (PointLight([-0.8, 0.9, 3.2]), DirectionalLight([0.5, -0.3, -1.0])):
        a = shadow_mask(cam, V, F, light)
        b = shadow_mask(cam, V, F, light, closed=False)
        assert a.sum() > 200 and np.array_equal(a, b)
