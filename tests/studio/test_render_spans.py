"""The fast silhouette paths (studio.render.spans) against the reference renderer and a brute force."""

import numpy as np
import pytest

from meshkit import brute_force_silhouette
from calibration import Camera
from studio.render import silhouette
from studio.render.pyramid import level_camera
from studio.render.spans import _topology, silhouettes_contour, silhouettes_fast


def _camera(w=160, h=120, name="c", R=None, t=(0.0, 0.0, 3.0), dist=None, f=150.0):
    K = np.array([[f, 0, (w - 1) / 2 + 0.3], [0, f, (h - 1) / 2 - 0.2], [0, 0, 1]])
    return Camera(name=name, K=K, dist=np.zeros(5) if dist is None else np.asarray(dist, float),
                  R=np.eye(3) if R is None else np.asarray(R, float), t=np.asarray(t, float), size=(w, h))


def _rig():
    """Four cameras around the origin looking at it (one with lens distortion)."""
    cams = []
    for k, ang in enumerate(np.radians([0.0, 80.0, 170.0, 260.0])):
        c, s = np.cos(ang), np.sin(ang)
        # camera looks along -radial direction, y down = -Z world
        R = np.array([[-s, c, 0.0], [0.0, 0.0, -1.0], [-c, -s, 0.0]])
        dist = [-0.12, 0.05, 0.001, -0.001, 0.0] if k == 2 else None
        cams.append(_camera(name=f"cam{k}", R=R, t=(0.0, 0.0, 3.2), dist=dist, f=120.0 + 20 * k))
    return cams


def _box(lo, hi):
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    V = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], float)
    F = np.array([[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7], [0, 1, 5], [0, 5, 4],
                  [1, 2, 6], [1, 6, 5], [2, 3, 7], [2, 7, 6], [3, 0, 4], [3, 4, 7]])
    return V, F


@pytest.fixture(scope="module")
def body():
    from studio.body import BodyModel

    model = BodyModel.load("female")
    rng = np.random.default_rng(4)
    poses = []
    for _ in range(2):
        p = model.default_pose().astype(float)
        p[6:] += rng.normal(0, 0.3, p[6:].shape)
        poses.append(model.clip_pose(p))
    meshes = [model.vertices(model.mean_shape(), p) - [0, 0, 0.85] for p in poses]
    return model, meshes


@pytest.mark.parametrize("level", [0, 1, 2])
def test_contour_and_spans_equal_reference_on_body(body, level):
    model, meshes = body
    cams = [level_camera(c, level) for c in _rig()]
    for V in meshes:
        ref = [silhouette(c, V, model.faces) for c in cams]
        fast = silhouettes_fast(cams, V, model.faces)
        cont = silhouettes_contour(cams, V, model.faces)
        for r, a, b in zip(ref, fast, cont, strict=True):
            assert r.sum() > 300 >> (2 * level)  # the body is in view (25 px at level 2)
            assert np.count_nonzero(r != a) == 0
            # the winding fill differs only for pixel centres exactly on the contour
            assert np.count_nonzero(r != b) <= 2


def test_contour_matches_brute_force_on_body(body):
    model, meshes = body
    cam = _rig()[1].replace(size=(48, 64), K=np.array([[90.0, 0, 23.5], [0, 90.0, 31.5], [0, 0, 1]]))
    ref = brute_force_silhouette(cam, meshes[0], model.faces)
    ours = silhouettes_contour([cam], meshes[0], model.faces)[0]
    assert ref.sum() > 100
    assert np.count_nonzero(ours != ref) <= 2


def test_large_triangles_box_and_clipping():
    V, F = _box((-0.4, -0.3, -0.5), (0.5, 0.35, 0.6))
    assert _topology(F, len(V)) is not None
    cams = _rig() + [_camera(name="close", t=(0.0, 0.0, 0.9))]  # the box overflows this image
    ref = [silhouette(c, V, F) for c in cams]
    for r, a, b in zip(ref, silhouettes_fast(cams, V, F), silhouettes_contour(cams, V, F), strict=True):
        assert r.sum() > 1000
        assert np.count_nonzero(r != a) == 0
        assert np.count_nonzero(r != b) <= 2
    assert ref[-1].all()  # the close camera sees only the box


def test_open_mesh_and_near_plane_fall_back():
    rng = np.random.default_rng(3)
    V = rng.uniform(-1.0, 1.0, (90, 3)) * [1.2, 0.9, 0.3]
    F = rng.integers(0, len(V), (30, 3))
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    cam = _camera(64, 48, f=60.0)
    assert _topology(F, len(V)) is None  # not closed: the contour path defers to the span path
    ref = brute_force_silhouette(cam, V, F)
    assert ref.sum() > 300
    assert np.count_nonzero(silhouettes_fast([cam], V, F, closed=False)[0] != ref) == 0
    # a closed box straddling the camera plane: faces behind `near` are skipped like the reference
    Vb, Fb = _box((-0.5, -0.5, -3.5), (0.5, 0.5, 1.0))
    r = silhouette(cam, Vb, Fb)
    assert np.count_nonzero(silhouettes_contour([cam], Vb, Fb)[0] != r) == 0


def test_empty_and_bad_inputs():
    V, F = _box((-0.1, -0.1, 5.0), (0.1, 0.1, 5.2))
    cam = _camera()
    behind = silhouettes_contour([cam], V - [0, 0, 10.0], F)[0]
    assert behind.shape == (120, 160) and not behind.any()
    with pytest.raises(ValueError, match="vertices"):
        silhouettes_contour([cam], V[:, :2], F)
    with pytest.raises(ValueError, match="faces"):
        silhouettes_fast([cam], V, F + 100)


@pytest.mark.parametrize("dist", [np.zeros(5), [-0.12, 0.05, 0.001, -0.001, 0.02],
                                  [-0.3, 0.1, 0.002, -0.003, 0.01, 0.05, -0.02, 0.01, 0.001, -0.002, 0.003, 0.0005]])
def test_compiled_projection_equals_camera_model(dist):
    """The contour renderer's compiled pinhole projection against Camera.project_points (the
    model cv2.projectPoints is tested against), every coefficient of the 12-term model in use;
    points behind the camera get NaN pixels and their depth."""
    from studio.render.spans import _pinhole_lens
    from studio.render.winding import project_pinhole

    cam = _rig()[1].replace(dist=np.asarray(dist, float))
    rng = np.random.default_rng(3)
    V = rng.uniform(-0.6, 0.6, (400, 3))
    V[:5] = cam.center + 0.5 * (cam.R.T @ np.array([0.0, 0.0, -1.0]))  # behind the camera
    idx = np.arange(0, 400, 3)
    idx = np.concatenate([[0, 2], idx])
    uv, depth = project_pinhole(V, idx, *_pinhole_lens(cam))
    ref_uv, ref_depth, front = cam.project_points(V[idx])
    np.testing.assert_allclose(depth, ref_depth, rtol=0, atol=1e-12)
    assert np.array_equal(np.isnan(uv[:, 0]), ~front) and np.array_equal(~front, idx < 5)
    np.testing.assert_allclose(uv[front], ref_uv[front], rtol=0, atol=1e-9)


def test_compiled_projection_not_used_for_fisheye_or_tilt():
    from studio.render.spans import _pinhole_lens

    cam = _rig()[0]
    assert _pinhole_lens(cam) is not None
    assert _pinhole_lens(cam.replace(dist=np.r_[np.zeros(12), 0.01, 0.0])) is None
    fish = Camera(name="f", K=cam.K, dist=np.array([0.01, 0.0, 0.0, 0.0]), R=cam.R, t=cam.t, size=cam.size,
                  model="fisheye")
    assert _pinhole_lens(fish) is None


def _composed(cameras, V, F):
    """The contour path as separate kernels (contour edges → projection → winding fill)."""
    from studio.render.spans import _pinhole_lens
    from studio.render.winding import contour_edges, front_faces, project_pinhole, winding_fill

    topo = _topology(F, len(V))
    facing = front_faces(V, F, np.stack([c.center for c in cameras], axis=1))
    out = []
    for k, cam in enumerate(cameras):
        u, v, used = contour_edges(facing[:, k], topo.u, topo.v, topo.f_uv, topo.f_vu, len(V))
        uv_used, _ = project_pinhole(V, used, *_pinhole_lens(cam))
        uv = np.empty((len(V), 2))
        uv[used] = uv_used
        out.append(winding_fill(uv[u], uv[v], *cam.size))
    return out


@pytest.mark.parametrize("level", [0, 1])
def test_renderer_one_pass_per_view_equals_the_composed_kernels(body, level):
    """ContourRenderer (one compiled call per view, the difference image cleared on the
    contour's box only) gives the masks of the separate kernels bit for bit, body after body,
    and on two threads at once."""
    from studio.render.spans import ContourRenderer

    model, meshes = body
    cams = [level_camera(c, level) for c in _rig()]
    renderer = ContourRenderer(cams, model.faces, model.n_vertices)
    for V in meshes + [m + [0.9, -0.4, 0.0] for m in meshes]:  # moved: one view cut by its border
        got, want = renderer(V), _composed(cams, V, model.faces)
        assert sum(int(w.sum()) for w in want) > 1000 >> (2 * level)
        for g, w in zip(got, want, strict=True):
            np.testing.assert_array_equal(g, w)
        assert not any(d.any() for d in renderer._local.diffs)  # the difference images are left clean
    # another thread renders with its own difference images, side by side with this one
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(2) as pool:
        got = list(pool.map(renderer, meshes * 4))
    for V, masks in zip(meshes * 4, got, strict=True):
        for g, w in zip(masks, _composed(cams, V, model.faces), strict=True):
            np.testing.assert_array_equal(g, w)
    with pytest.raises(ValueError, match="vertices"):
        renderer(meshes[0][:-1])


def test_topology_is_cached_by_the_faces_array_and_by_content():
    """The fitter passes the same faces array every evaluation: its topology comes back without
    hashing the faces again; an equal copy finds the same topology by content, another vertex
    count does not share it."""
    from studio.body import BodyModel
    from studio.render.spans import _TOPOLOGY_BY_ARRAY, _topology

    model = BodyModel.load("female")
    F = np.asarray(model.faces, dtype=np.int64)
    n = int(F.max()) + 1
    topo = _topology(F, n)
    assert topo is not None and _TOPOLOGY_BY_ARRAY[id(F)][0] is F
    assert _topology(F, n) is topo and _topology(F.copy(), n) is topo
    np.testing.assert_array_equal(_topology(F, n + 1).u, topo.u)
    assert _topology(F, n + 1) is not topo
