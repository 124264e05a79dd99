"""Rasteriser geometry: pixels agree with ``Camera.project``, z-buffer, silhouette paths."""

from functools import partial

import numpy as np
import pytest

from calibration import Camera
from meshkit import uv_sphere
from studio.render import front_facing, rasterize, silhouette

SIZE = (160, 120)
sphere = partial(uv_sphere, n=24)  # small triangles: the vectorised path


def camera(dist=(-0.05, 0.01, 0.0, 0.0, 0.0), name="c"):
    return Camera.look_at(name, [2.0, -1.5, 1.4], [0.0, 0.0, 0.8], 140.0, SIZE, dist)


def box(center, half):
    """Closed box mesh: 8 vertices, 12 outward triangles."""
    c = np.asarray(center, float)
    h = np.asarray(half, float) * np.ones(3)
    s = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    V = c + s * h
    F = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                  [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    return V, F


def test_tiny_mesh_lands_on_projected_pixel():
    """A 2.5 cm sphere around X (about 1.4 px radius) covers the pixel nearest
    ``camera.project(X)`` and nothing farther than its radius (with lens distortion)."""
    cam = camera()
    rng = np.random.default_rng(0)
    for X in rng.uniform([-0.5, -0.5, 0.2], [0.5, 0.5, 1.6], (5, 3)):
        V, F = sphere(X, 0.025, n=8)
        mask = silhouette(cam, V, F, closed=False)
        uv = cam.project(X)[0]
        ys, xs = np.nonzero(mask)
        assert len(xs) >= 1
        rad = 140.0 * 0.025 / np.linalg.norm(cam.center - X)
        assert np.max(np.hypot(xs - uv[0], ys - uv[1])) < rad + 0.1
        r = rasterize(cam, V, F)
        assert r.mask[int(round(uv[1])), int(round(uv[0]))]


def test_sphere_silhouette_centroid_matches_projection():
    cam = camera()
    X = np.array([0.1, 0.2, 1.0])
    V, F = sphere(X, 0.12)
    mask = silhouette(cam, V, F)
    ys, xs = np.nonzero(mask)
    uv = cam.project(X)[0]
    assert abs(xs.mean() - uv[0]) < 0.3 and abs(ys.mean() - uv[1]) < 0.3
    # area of the disc of radius f r / d (up to perspective and lens distortion: 3 %)
    d = np.linalg.norm(cam.center - X)
    expected = np.pi * (140.0 * 0.12 / np.sqrt(d**2 - 0.12**2)) ** 2
    assert mask.sum() == pytest.approx(expected, rel=0.03)


def test_culled_silhouette_equals_full_and_raster_mask():
    cam = camera()
    V, F = sphere([0.0, 0.0, 0.9], 0.3)
    closed = silhouette(cam, V, F)
    full = silhouette(cam, V, F, closed=False)
    assert np.array_equal(closed, full)
    assert np.array_equal(rasterize(cam, V, F).mask, full)
    assert front_facing(cam, V, F).sum() < len(F) * 0.6
    # inverted winding gives the same silhouette
    assert np.array_equal(silhouette(cam, V, F[:, ::-1]), closed)


def test_large_triangles_box_area_and_depth():
    """A big box goes through the fillConvexPoly path; depth equals the camera Z of its surface."""
    cam = camera(dist=())
    V, F = box([0.0, 0.0, 0.9], [0.3, 0.3, 0.3])
    r = rasterize(cam, V, F)
    assert np.array_equal(r.mask, silhouette(cam, V, F))
    hull_uv = cam.project(V)
    import cv2

    hull = cv2.convexHull(hull_uv.astype(np.float32))
    area = cv2.contourArea(hull)
    assert r.mask.sum() == pytest.approx(area, rel=0.03)
    # depth at a covered pixel equals the ray's distance to the box face (within 1 cm)
    ys, xs = np.nonzero(r.mask)
    k = len(xs) // 2
    o, d = cam.pixel_rays(np.array([[xs[k], ys[k]]], float))
    z = r.depth[ys[k], xs[k]]
    X = o[0] + d[0] * (z / (cam.R @ d[0])[2])
    assert np.max(np.abs(X - [0, 0, 0.9])) == pytest.approx(0.3, abs=0.01)


def test_zbuffer_nearest_wins_in_any_order():
    cam = camera()
    near_V, F = sphere([0.4, -0.3, 1.0], 0.1)  # closer to the camera at (2, -1.5, 1.4)
    far_V, _ = sphere([-0.2, 0.15, 0.85], 0.25)
    for order in (0, 1):
        parts = [(near_V, F), (far_V, F)] if order == 0 else [(far_V, F), (near_V, F)]
        V = np.vstack([parts[0][0], parts[1][0]])
        FF = np.vstack([parts[0][1], parts[1][1] + len(parts[0][0])])
        r = rasterize(cam, V, FF)
        near_alone = silhouette(cam, near_V, F)
        near_faces = range(0, len(F)) if order == 0 else range(len(F), 2 * len(F))
        hit = np.isin(r.face, list(near_faces))
        assert np.array_equal(hit, near_alone)


def test_empty_and_behind_camera():
    cam = camera()
    V, F = sphere(cam.center - [0.5, -0.4, 0.0] * np.array([-1, 1, 1]) * 3, 0.05)
    assert not silhouette(cam, V[:0].reshape(0, 3), F[:0]).any()
    behind = cam.center + (cam.center - np.array([0, 0, 0.8]))
    Vb, Fb = sphere(behind, 0.2)
    assert not silhouette(cam, Vb, Fb).any()
    assert not rasterize(cam, Vb, Fb).mask.any()


def test_bad_inputs_are_named():
    cam = camera()
    V, F = box([0, 0, 1], 0.1)
    with pytest.raises(ValueError, match=r"vertices: expected shape \(V, 3\)"):
        silhouette(cam, V[:, :2], F)
    with pytest.raises(ValueError, match=r"faces: expected integer shape"):
        silhouette(cam, V, F.astype(float))
    with pytest.raises(ValueError, match=r"faces: indices must lie in \[0, 7\]"):
        rasterize(cam, V, F + 1)


def test_silhouettes_of_a_rig():
    from calibration import Camera, RigCalibration
    from studio.render import silhouettes

    cams = [camera(name="a"), Camera.look_at("b", [-2.0, 1.0, 1.2], [0, 0, 0.8], 120.0, SIZE, ())]
    V, F = sphere([0.0, 0.0, 0.9], 0.2)
    got = silhouettes(RigCalibration({c.name: c for c in cams}), V, F)
    assert list(got) == ["a", "b"]
    assert np.array_equal(got["b"], silhouette(cams[1], V, F))
    assert list(silhouettes({c.name: c for c in cams}, V, F)) == ["a", "b"]
