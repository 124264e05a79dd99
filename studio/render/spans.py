"""Fast multi-view silhouettes by scanline spans (the fitter's hot path).

:func:`silhouettes_fast` gives the same masks as :func:`studio.render.silhouette` (same
pixel-centre sampling, same inclusive edge test) for one mesh in several cameras, but

* the face normals and the enclosed-volume sign of the front-face test are computed once
  for all cameras (only ``n · (c − a)`` changes per camera);
* each triangle is cut into one span of pixel centres per image row it covers — the
  span ends come from the three edge half-planes solved for ``x`` and are then nudged by
  one pixel where the exact edge test (the same expression as the reference sampler)
  disagrees with the division round-off — so the work is O(rows) per triangle instead of
  O(bounding box²);
* the spans are filled with a difference image (+1 at the span start, −1 after its end)
  and a cumulative sum along rows over the mesh's bounding box only.

The masks are identical to :func:`studio.render.silhouette` except for pixel centres lying
within round-off of an edge (see ``tests/studio/test_render_spans.py``).
"""

from __future__ import annotations

import threading

import numpy as np
from numba import njit

from .raster import _check_mesh

__all__ = ["ContourRenderer", "silhouettes_fast", "silhouettes_contour", "face_normals"]

#: Tolerance of the edge test, in pixels² (as :mod:`studio.render.raster`).
_EDGE_EPS = 1e-9


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Unnormalised face normals (F, 3), ``n · a`` (F,) of each face's first vertex, and the
    sign (+1/−1) of the enclosed volume (the winding of a closed mesh). Compiled
    (:func:`_face_normals`): one pass over the faces, a quarter of NumPy's time for a body mesh."""
    n, na = _face_normals(np.ascontiguousarray(vertices, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int64))
    return n, na, (1.0 if float(na.sum()) >= 0 else -1.0)


@njit(cache=True, nogil=True)
def _face_normals(V, F):  # pragma: no cover - compiled
    """``(u × v, (u × v) · a)`` per face ``(a, b, c)``, ``u = b − a``, ``v = c − a``."""
    n = np.empty((F.shape[0], 3))
    na = np.empty(F.shape[0])
    for f in range(F.shape[0]):
        i, j, k = F[f, 0], F[f, 1], F[f, 2]
        ax, ay, az = V[i, 0], V[i, 1], V[i, 2]
        ux, uy, uz = V[j, 0] - ax, V[j, 1] - ay, V[j, 2] - az
        vx, vy, vz = V[k, 0] - ax, V[k, 1] - ay, V[k, 2] - az
        nx, ny, nz = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        n[f, 0], n[f, 1], n[f, 2] = nx, ny, nz
        na[f] = nx * ax + ny * ay + nz * az
    return n, na


def _spans(t: np.ndarray, size) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Row spans (y, x_first, x_last) of pixel centres inside triangles ``t`` (T, 3, 2)."""
    w, h = size
    a, b, c = t[:, 0], t[:, 1], t[:, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    ok = np.abs(area) > 1e-12
    if not ok.all():
        t, a, b, c, area = t[ok], a[ok], b[ok], c[ok], area[ok]
    sgn = np.where(area >= 0, 1.0, -1.0)
    ys = t[:, :, 1]
    y0 = np.maximum(np.ceil(ys.min(axis=1) - 1e-9), 0.0).astype(np.int64)
    y1 = np.minimum(np.floor(ys.max(axis=1) + 1e-9), h - 1).astype(np.int64)
    nrows = np.maximum(y1 - y0 + 1, 0)
    total = int(nrows.sum())
    if total == 0:
        z = np.zeros(0, np.int64)
        return z, z, z
    tri = np.repeat(np.arange(len(t)), nrows)
    starts = np.cumsum(nrows) - nrows
    y = (y0[tri] + (np.arange(total) - starts[tri])).astype(np.float64)
    edges = []
    xl = np.full(total, -np.inf)
    xr = np.full(total, np.inf)
    for p, q in ((b, c), (c, a), (a, b)):
        A = ((q[:, 0] - p[:, 0]) * sgn)[tri]
        B = ((q[:, 1] - p[:, 1]) * sgn)[tri]
        px = p[tri, 0]
        py = p[tri, 1]
        edges.append((A, B, px, py))
        r = A * (y - py) + _EDGE_EPS
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = px + r / B
        pos = B > 0
        neg = B < 0
        flat = ~(pos | neg)
        xr = np.where(pos, np.minimum(xr, bound), xr)
        xl = np.where(neg, np.maximum(xl, bound), xl)
        dead = flat & (r < 0)
        if dead.any():
            xr[dead] = -np.inf

    def inside(x):
        m = np.ones(total, bool)
        for A, B, px, py in edges:
            m &= A * (y - py) - B * (x - px) >= -_EDGE_EPS
        return m

    live = xl <= xr + 1.0
    xl = np.where(live, xl, 0.0)
    xr = np.where(live, xr, -1.0)
    # exact ends: the division may round a centre lying on an edge to the wrong side
    xl = np.ceil(xl)
    xr = np.floor(xr)
    xl = np.where(inside(xl - 1.0) & live, xl - 1.0, xl)
    xl = np.where(~inside(xl) & live, xl + 1.0, xl)
    xr = np.where(inside(xr + 1.0) & live, xr + 1.0, xr)
    xr = np.where(~inside(xr) & live, xr - 1.0, xr)
    xl = np.maximum(xl, 0.0)
    xr = np.minimum(xr, w - 1.0)
    keep = live & (xl <= xr)
    return y[keep].astype(np.int64), xl[keep].astype(np.int64), xr[keep].astype(np.int64)


def _fill(y, x0, x1, size) -> np.ndarray:
    """(H, W) bool union of row spans."""
    w, h = size
    out = np.zeros((h, w), dtype=bool)
    if len(y) == 0:
        return out
    ya, yb = int(y.min()), int(y.max()) + 1
    xa, xb = int(x0.min()), int(x1.max()) + 1
    ww = xb - xa + 1
    n = (yb - ya) * ww
    rows = (y - ya) * ww
    diff = np.bincount(rows + (x0 - xa), minlength=n) - np.bincount(rows + (x1 + 1 - xa), minlength=n)
    cov = np.cumsum(diff.reshape(yb - ya, ww), axis=1)[:, :-1] > 0
    out[ya:yb, xa:xb] = cov
    return out


def silhouettes_fast(cameras, vertices: np.ndarray, faces: np.ndarray, *, closed: bool = True,
                     near: float = 1e-3) -> list[np.ndarray]:
    """Silhouettes (H_k, W_k) bool of one mesh in each camera of ``cameras`` (a sequence).

    Same arguments and masks as :func:`studio.render.silhouette` called per camera.
    """
    V, F = _check_mesh(vertices, faces)
    if closed:
        n, na, sign = face_normals(V, F)
        centres = np.stack([np.asarray(c.center, dtype=np.float64) for c in cameras], axis=1)  # (3, C)
        facing = (n @ centres - na[:, None]) * sign > 0  # (F, C)
    out = []
    for k, cam in enumerate(cameras):
        w, h = cam.size
        Fk = F[facing[:, k]] if closed else F
        uv, depth, _ = cam.project_points(V)
        d = depth[Fk]
        t = uv[Fk]
        lo = t.min(axis=1)
        hi = t.max(axis=1)
        ok = (d[:, 0] > near) & (d[:, 1] > near) & (d[:, 2] > near)
        ok &= (hi[:, 0] >= -0.5) & (hi[:, 1] >= -0.5) & (lo[:, 0] <= w - 0.5) & (lo[:, 1] <= h - 0.5)
        ok &= np.isfinite(lo[:, 0] + lo[:, 1] + hi[:, 0] + hi[:, 1])
        out.append(_fill(*_spans(t[ok], (w, h)), (w, h)))
    return out


class _Topology:
    """Edge–face incidence of a consistently oriented closed triangle mesh.

    ``u``, ``v`` (E,) the vertices of each undirected edge as directed in face ``f_uv``
    (E,); ``f_vu`` (E,) the face that holds it as ``v → u``.
    """

    __slots__ = ("u", "v", "f_uv", "f_vu")

    def __init__(self, u, v, f_uv, f_vu):
        self.u, self.v, self.f_uv, self.f_vu = u, v, f_uv, f_vu


_TOPOLOGY_CACHE: dict = {}
#: the same by the faces array itself (``id`` and ``is``): hashing a body's faces costs ~0.1 ms,
#: a tenth of a shadow-term evaluation, and the fitter passes the same array every time
_TOPOLOGY_BY_ARRAY: dict = {}


def _topology(F: np.ndarray, n_vertices: int) -> _Topology | None:
    """Cached :class:`_Topology` of ``F``, or None if some edge is not shared by exactly one
    ``u → v`` face and one ``v → u`` face (open, non-manifold or inconsistently wound)."""
    held = _TOPOLOGY_BY_ARRAY.get(id(F))
    if held is not None and held[0] is F and held[1] == n_vertices:
        return held[2]
    key = (F.shape, n_vertices, hash(F.tobytes()))
    held = _TOPOLOGY_CACHE.get(key, _TOPOLOGY_CACHE)  # one read: another thread may clear the cache
    if held is not _TOPOLOGY_CACHE:
        _TOPOLOGY_BY_ARRAY[id(F)] = (F, n_vertices, held)
        return held
    a = F.reshape(-1).astype(np.int64)
    b = F[:, [1, 2, 0]].reshape(-1).astype(np.int64)
    face = np.repeat(np.arange(len(F)), 3)
    fwd = a * n_vertices + b
    rev = b * n_vertices + a
    order = np.argsort(fwd)
    sorted_fwd = fwd[order]
    topo = None
    if len(np.unique(sorted_fwd)) == len(fwd):
        pos = np.searchsorted(sorted_fwd, rev)
        pos = np.minimum(pos, len(fwd) - 1)
        match = sorted_fwd[pos] == rev
        if match.all():
            first = a < b  # keep each undirected edge once, directed as in its face
            topo = _Topology(a[first], b[first], face[first], face[order[pos[first]]])
    if len(_TOPOLOGY_CACHE) > 8:
        _TOPOLOGY_CACHE.clear()
        _TOPOLOGY_BY_ARRAY.clear()
    _TOPOLOGY_CACHE[key] = topo
    _TOPOLOGY_BY_ARRAY[id(F)] = (F, n_vertices, topo)
    return topo


def _pinhole_lens(camera) -> tuple | None:
    """(R, t, K, 12 distortion coefficients) of a pinhole ``camera`` without sensor tilt, for
    :func:`studio.render.winding.project_pinhole`; None for a fisheye or a tilted sensor."""
    from calibration.distortion import _padded

    d = _padded(np.asarray(camera.dist, dtype=np.float64).ravel())
    if camera.model != "pinhole" or d[12] != 0.0 or d[13] != 0.0:
        return None
    return (np.asarray(camera.R, dtype=np.float64), np.asarray(camera.t, dtype=np.float64),
            np.asarray(camera.K, dtype=np.float64), d[:12].copy())


class ContourRenderer:
    """:func:`silhouettes_contour` for one set of ``cameras`` and ``faces``, with what does not
    change between meshes prepared once: the mesh's edge–face topology (hashing the faces
    cost 70 µs per call), each camera's centre and lens. ``renderer(vertices)`` returns the
    same masks as ``silhouettes_contour(cameras, vertices, faces)``; each view is one
    compiled call (:func:`studio.render.winding.contour_silhouette`) with a difference image
    per view kept between calls (4 views of the walk body, CPU per mesh, same run: 1.07 → 0.49 ms
    at full resolution, 0.76 → 0.38 ms at level 1; the same masks bit for bit)."""

    def __init__(self, cameras, faces: np.ndarray, n_vertices: int):
        self.cameras = list(cameras)
        self.n_vertices = int(n_vertices)
        _, F = _check_mesh(np.zeros((self.n_vertices, 3)), faces)
        self.faces = np.ascontiguousarray(F, dtype=np.int64)
        self.topology = _topology(self.faces, self.n_vertices)
        self.centres = np.stack([np.asarray(c.center, dtype=np.float64) for c in self.cameras], axis=1)
        self.lenses = [_pinhole_lens(c) for c in self.cameras]
        # difference images of the scanline fill, one set per thread, kept all zeros between calls
        self._local = threading.local()

    def __call__(self, vertices: np.ndarray, *, near: float = 1e-3) -> list[np.ndarray]:
        """Silhouettes (H_k, W_k) bool of the mesh ``vertices`` (n_vertices, 3) in each camera."""
        from .winding import front_faces

        V = np.asarray(vertices, dtype=np.float64)
        if V.shape != (self.n_vertices, 3):
            raise ValueError(f"vertices: expected ({self.n_vertices}, 3), got {V.shape}")
        topo = self.topology
        if topo is None:
            return silhouettes_fast(self.cameras, V, self.faces, near=near)
        V = np.ascontiguousarray(V)
        facing = front_faces(V, self.faces, self.centres)  # (F, C)
        diffs = getattr(self._local, "diffs", None)
        if diffs is None:
            diffs = self._local.diffs = [np.zeros((int(c.size[1]), int(c.size[0]) + 1), np.int32)
                                         for c in self.cameras]
        return self._views(V, facing, diffs, near)

    def _views(self, V, facing, diffs, near) -> list[np.ndarray]:
        from .winding import contour_edges, contour_silhouette, winding_fill

        topo = self.topology
        out = []
        for k, (cam, lens) in enumerate(zip(self.cameras, self.lenses, strict=True)):
            if lens is not None:
                mask, ok = contour_silhouette(facing[:, k], topo.u, topo.v, topo.f_uv, topo.f_vu, V, *lens,
                                              int(cam.size[0]), int(cam.size[1]), float(near), diffs[k])
                out.append(mask if ok else silhouettes_fast([cam], V, self.faces, near=near)[0])
                continue
            u, v, used = contour_edges(facing[:, k], topo.u, topo.v, topo.f_uv, topo.f_vu, len(V))
            uv_used, depth, _ = cam.project_points(V[used])
            if len(used) and depth.min() <= near:
                out.append(silhouettes_fast([cam], V, self.faces, near=near)[0])
                continue
            uv = np.empty((len(V), 2))
            uv[used] = uv_used
            out.append(winding_fill(uv[u], uv[v], *cam.size))
        return out


def silhouettes_contour(cameras, vertices: np.ndarray, faces: np.ndarray, *,
                        near: float = 1e-3) -> list[np.ndarray]:
    """Silhouettes (H_k, W_k) bool of a CLOSED, consistently wound mesh in each camera.

    The front faces of a closed mesh all project with the same orientation, so the number
    of front faces covering a pixel is the winding number, around it, of the sum of their
    boundaries — in which every edge shared by two front faces cancels. What is left is the
    occluding contour (edges between a front and a back face, a few hundred on a body), filled
    by one scanline pass. The masks equal :func:`silhouettes_fast` / :func:`silhouette` up to
    pixel centres lying exactly on the contour. Meshes that are not closed and consistently
    wound, and cameras with a vertex closer than ``near``, fall back to :func:`silhouettes_fast`.
    The per-view loops are compiled (:mod:`studio.render.winding`): 4 views of a 5,746-vertex
    body at 328×246 take 2.3 ms instead of 4.1 ms with NumPy. Many meshes in the same cameras:
    :class:`ContourRenderer`.
    """
    V, F = _check_mesh(vertices, faces)
    return ContourRenderer(cameras, F, len(V))(V, near=near)
