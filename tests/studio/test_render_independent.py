"""The silhouette renderer against an independent brute-force point-in-triangle rasteriser."""

import numpy as np
import pytest

from meshkit import brute_force_silhouette
from calibration import Camera
from studio.render import silhouette
from studio.render.pyramid import level_camera


def _camera(w=64, h=48, dist=None):
    K = np.array([[60.0, 0, (w - 1) / 2], [0, 60.0, (h - 1) / 2], [0, 0, 1]])
    return Camera(name="c", K=K, dist=np.zeros(5) if dist is None else np.asarray(dist), R=np.eye(3),
                  t=np.array([0.0, 0.0, 3.0]), size=(w, h))


def test_random_triangles_match_brute_force():
    rng = np.random.default_rng(3)
    V = rng.uniform(-1.0, 1.0, (90, 3)) * [1.2, 0.9, 0.3]
    F = rng.integers(0, len(V), (30, 3))
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    cam = _camera()
    ours = silhouette(cam, V, F, closed=False)
    ref = brute_force_silhouette(cam, V, F)
    assert ref.sum() > 300  # the test image is not trivially empty
    assert np.count_nonzero(ours != ref) == 0


def test_closed_body_mesh_matches_brute_force():
    from studio.body import BodyModel

    model = BodyModel.load("female")
    V = model.vertices(model.mean_shape()) - [0, 0, 0.9]
    cam = _camera(48, 64)
    cam = cam.replace(K=np.array([[90.0, 0, 23.5], [0, 90.0, 31.5], [0, 0, 1]]),
                      R=np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]), t=np.array([0.0, 0.0, 3.0]))
    ours = silhouette(cam, V, model.faces)  # front faces only
    ref = brute_force_silhouette(cam, V, model.faces)  # every face
    assert ref.sum() > 200
    # front-face culling of a closed mesh must not change the mask (allow ties on shared edges)
    assert np.count_nonzero(ours != ref) <= 2


def test_level_camera_matches_downsampled_rendering():
    from studio.cost import downsample_mask

    rng = np.random.default_rng(0)
    V = rng.uniform(-1, 1, (60, 3)) * [1.0, 0.8, 0.2]
    F = rng.integers(0, len(V), (25, 3))
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    cam = _camera(128, 96)
    full = silhouette(cam, V, F, closed=False)
    small = silhouette(level_camera(cam, 2), V, F, closed=False)
    assert small.shape == (24, 32)
    assert np.mean(small != downsample_mask(full, 2)) < 0.04
    assert level_camera(cam, 0) is cam
    with pytest.raises(ValueError, match="pyramid level"):
        level_camera(cam, -1)
