"""The light's objective: predicted against observed shadow silhouettes over frames (eq. 5.9).

For fixed bodies ``s^t`` (fitted, or the truth in tests) the cost of a light hypothesis ℓ is

    E(ℓ) = Σ_t Σ_k D(S^e_{k,t}(s^t, ℓ, g), S^o_{k,t})                                (5.9)

with ``D`` the symmetric truncated chamfer distance of eq. 4.5 (:func:`studio.cost.silhouette_cost`)
and ``S^e`` the *visible* predicted shadow: the shadow of the body through ℓ onto the ground g
(:func:`studio.render.shadow_outline`, eq. 5.2) rendered in camera k (eq. 5.3), less the body's
own silhouette in that camera (thesis §5.6: shadows first, then the body). Everything that does
not depend on ℓ — the observed shadows' distance maps, the body silhouettes, the face normals and
edge topology of each mesh — is computed once per frame in :class:`ShadowFrame`; one evaluation
is then a light-facing test, the contour edges and a winding fill per view.

The comparison is made in each camera's *ideal* (undistorted, same K) image at the pyramid
level: the observed masks are undistorted once (:meth:`calibration.Camera.undistort_image`) and
the body silhouettes rendered with the ideal camera, so that the shadow outline on the ground
reaches every view by one 3×4 projection (eq. 5.3 without the lens), for all views at once.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from studio.cost import SilhouetteTarget, silhouette_cost
from studio.render.pyramid import level_camera
from studio.render.shadow import join_outlines, shadow_outline, shadow_silhouettes
from studio.render.spans import _topology, face_normals, silhouettes_contour

__all__ = ["ShadowFrame", "ShadowObjective", "ideal_camera", "observed_arrays", "predicted_shadows", "projection_matrices",
           "shadow_distances"]


@dataclass(frozen=True, eq=False)
class ShadowFrame:
    """The ℓ-independent part of one frame: the body mesh (``vertices`` (V, 3), ``faces``), its
    face ``normals`` and edge ``topology``, the observed shadows as a :class:`SilhouetteTarget`
    and the body's silhouette in every view (``occluders``, at the target's level)."""

    frame: int
    vertices: np.ndarray
    faces: np.ndarray
    normals: tuple
    topology: object
    target: SilhouetteTarget
    occluders: tuple

    @classmethod
    def build(cls, frame: int, vertices: np.ndarray, faces: np.ndarray, cameras: Sequence,
              shadow_masks: Sequence[np.ndarray], *, level: int = 2, tau: float = 20.0,
              xi: float = 1.0) -> ShadowFrame:
        """``cameras`` full-resolution, ``shadow_masks`` (H, W) bool observed shadows (label 2)
        in the same order."""
        V = np.asarray(vertices, dtype=np.float64)
        F = np.asarray(faces, dtype=np.int64)
        cams = [level_camera(ideal_camera(c), level) for c in cameras]
        masks = [c.undistort_image(np.asarray(m, bool)) for c, m in zip(cameras, shadow_masks, strict=True)]
        target = SilhouetteTarget.build(masks, tau=tau, xi=xi, level=level, names=[c.name for c in cameras])
        occ = tuple(silhouettes_contour(cams, V, F))
        return cls(int(frame), V, F, face_normals(V, F), _topology(F, len(V)), target, occ)


def ideal_camera(camera):
    """``camera`` without its lens distortion (an ideal pinhole with the same K, R, t)."""
    return camera.replace(dist=np.zeros(5), model="pinhole")


def projection_matrices(cameras: Sequence) -> np.ndarray:
    """(C, 3, 4) ``K [R | t]`` of ideal pinhole ``cameras``."""
    return np.stack([np.asarray(c.K, float) @ np.hstack([np.asarray(c.R, float), np.asarray(c.t, float).reshape(3, 1)])
                     for c in cameras])


def predicted_shadows(frame: ShadowFrame, cameras: Sequence, lights, ground=None,
                      matrices: np.ndarray | None = None) -> list[np.ndarray]:
    """Visible predicted shadows S^e (H_l, W_l) bool of ``frame`` in the ideal level ``cameras``:
    the union of the shadows of every light, less the body's own silhouette (thesis §5.6).
    ``matrices``: their :func:`projection_matrices` (computed when None)."""
    from studio.render.winding import winding_fill

    M = projection_matrices(cameras) if matrices is None else matrices
    outlines = [shadow_outline(frame.vertices, frame.faces, light, ground, normals=frame.normals,
                               topology=frame.topology) for light in lights]
    fast = all(o is not None for o in outlines)
    if fast:
        P, a, b = join_outlines(outlines)
        uvw = P @ M[:, :, :3].transpose(0, 2, 1) + M[:, None, :, 3]
    out = []
    for k, (cam, occ) in enumerate(zip(cameras, frame.occluders, strict=True)):
        m = None
        if fast and len(a) == 0:
            m = np.zeros(occ.shape, bool)
        elif fast and uvw[k, :, 2].min() > 1e-3:
            uv = uvw[k, :, :2] / uvw[k, :, 2:]
            m = winding_fill(uv[a], uv[b], cam.size[0], cam.size[1])
        out.append(m & ~occ if m is not None else
                   shadow_silhouettes([cam], frame.vertices, frame.faces, lights, ground, occluders=[occ])[0])
    return out


def _pack_lights(hypotheses) -> np.ndarray | None:
    """(N, J, 4) lights of hypotheses of J lights each (:func:`studio.light._kernels.shadow_chamfer`'s
    layout); None when they are not all of the same size."""
    from studio.render.lights import DirectionalLight, PointLight

    if len({len(h) for h in hypotheses}) != 1:
        return None
    out = np.empty((len(hypotheses), len(hypotheses[0]), 4))
    for i, hyp in enumerate(hypotheses):
        for j, light in enumerate(hyp):
            if isinstance(light, PointLight):
                out[i, j, :3], out[i, j, 3] = light.position, 1.0
            elif isinstance(light, DirectionalLight):
                out[i, j, :3], out[i, j, 3] = light.direction, 0.0
            else:
                raise TypeError(f"light: expected PointLight or DirectionalLight, got {type(light).__name__}")
    return out


def observed_arrays(target: SilhouetteTarget) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``target``'s distance maps (C, H, W), observed masks (C, H, W) bool and their pixel counts
    (C,) in :func:`studio.light._kernels.shadow_chamfer`'s layout."""
    return (np.stack(target.distance_maps), np.stack([np.ascontiguousarray(m, dtype=bool) for m in target.masks]),
            np.asarray(target.counts, dtype=np.int64))


def identity_index(n_views: int, size: tuple[int, int]) -> np.ndarray:
    """(C, H, W) flat pixel indices of (W, H) images: occluders rendered in the ideal image itself
    (:func:`shadow_distances`)."""
    w, h = size
    return np.ascontiguousarray(np.broadcast_to(np.arange(h * w, dtype=np.int64).reshape(h, w), (n_views, h, w)))


def lens_index(camera) -> np.ndarray:
    """(H, W) flat index of the pixel of ``camera``'s image nearest each pixel of its ideal image
    (−1: outside): ``camera.undistort_image`` of a mask, as a lookup (:func:`shadow_distances`)."""
    import cv2

    w, h = camera.size
    if not camera.has_distortion:
        return np.arange(h * w, dtype=np.int64).reshape(h, w)
    mx, my = camera.undistort_maps()
    flat = np.arange(h * w, dtype=np.float32).reshape(h, w)  # exact below 2^24 pixels
    out = cv2.remap(flat, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
    return out.astype(np.int64)


def shadow_distances(vertices: np.ndarray, faces: np.ndarray, normals: tuple, topology, hypotheses, plane: np.ndarray,
                     ground, cameras: Sequence, matrices: np.ndarray, occluders: tuple, target: SilhouetteTarget,
                     observed: tuple) -> np.ndarray:
    """(N, K) ``D(S^e_k, S^o_k)`` (eq. 4.5, full-resolution units) of one body under each of
    ``hypotheses`` (lists of lights; their union casts the shadow) in the ideal level ``cameras``
    (``matrices`` their :func:`projection_matrices`), the body's own silhouettes taken out (§5.6;
    ``occluders``: ``(masks (K, S) flat, index (K, H, W))``, the ideal image's pixels looked up in
    them, :func:`identity_index` or :func:`lens_index`), against ``target`` (``observed``: its
    :func:`observed_arrays`).

    Scored by the compiled :func:`studio.light._kernels.shadow_chamfer` (the same numbers as
    :func:`predicted_shadows` then :func:`studio.cost.silhouette_cost`); what it cannot score (an
    open mesh, a light below a contour vertex) is rendered exactly
    (:func:`studio.render.shadow_silhouettes`)."""
    from studio.cost.silhouette import _score_view
    from studio.light._kernels import shadow_chamfer

    hypotheses = [list(h) for h in hypotheses]
    lights = _pack_lights(hypotheses) if hypotheses else None
    n_views = len(target)
    if topology is not None and lights is not None:
        n, na, sign = normals
        raw, ok = shadow_chamfer(vertices, n, na, float(sign), topology.u, topology.v, topology.f_uv, topology.f_vu,
                                 lights, plane, matrices, *occluders, *observed, target.tau_level)
    else:
        raw, ok = np.zeros((len(hypotheses), n_views, 3)), np.zeros((len(hypotheses), n_views), bool)
    for i, k in zip(*np.nonzero(~ok), strict=True):  # the renderer's exact path
        flat, index = occluders
        body = np.where(index[k] >= 0, flat[k][np.maximum(index[k], 0)], False)
        mask = shadow_silhouettes([cameras[k]], vertices, faces, hypotheses[i], ground, normals=normals,
                                  topology=topology, occluders=[body])[0]
        raw[i, k] = _score_view(target, k, mask)
    xi, counts = target.xi, np.asarray(target.counts, float)
    with np.errstate(divide="ignore", invalid="ignore"):  # eq. 4.4's normalisation, 0 for an empty side
        fwd = np.where(raw[..., 2] > 0, raw[..., 0] / raw[..., 2] ** xi, 0.0)
        bwd = np.where(counts > 0, raw[..., 1] / counts ** xi, 0.0)
    return (fwd + bwd) * target.unit_factor


class ShadowObjective:
    """E(ℓ) of eq. 5.9 over ``frames`` (:class:`ShadowFrame`, all at one level) seen by
    ``cameras`` (full resolution, in the targets' order), shadows cast on ``ground`` (None: the
    floor z = 0). Call with a list of lights (their union casts the shadows).

    Hypotheses are scored by the compiled :func:`studio.light._kernels.shadow_chamfer` (the
    same numbers as :func:`predicted_shadows` then :func:`studio.cost.silhouette_cost`); what it
    cannot score (an open mesh, a light below a contour vertex) is rendered exactly
    (:func:`studio.render.shadow_silhouettes`)."""

    def __init__(self, frames: Sequence[ShadowFrame], cameras: Sequence, ground=None):
        from studio.render.shadow import _plane

        if not frames:
            raise ValueError("frames: at least one frame is needed")
        self.frames = list(frames)
        level = self.frames[0].target.level
        self.cameras = [level_camera(ideal_camera(c), level) for c in cameras]
        self.matrices = projection_matrices(self.cameras)
        self.ground = ground
        normal, offset = _plane(ground)
        self._plane = np.append(normal, offset)
        self._observed = [observed_arrays(f.target) for f in self.frames]
        index = identity_index(len(self.cameras), self.cameras[0].size)
        self._occluders = [(np.stack(f.occluders).reshape(len(self.cameras), -1), index) for f in self.frames]
        self.n_evaluations = 0

    @property
    def n_terms(self) -> int:
        """Number of (frame, view) terms of the sum."""
        return sum(len(f.target) for f in self.frames)

    def terms(self, hypotheses, ground=None) -> np.ndarray:
        """(N, T, K) ``D(S^e_{k,t}, S^o_{k,t})`` of each hypothesis (a list of lights), frame and
        view; the shadows cast on ``ground`` (default: the objective's)."""
        from studio.render.shadow import _plane

        ground = self.ground if ground is None else ground
        plane = self._plane if ground is self.ground else np.append(*_plane(ground))
        hypotheses = [list(h) for h in hypotheses]
        self.n_evaluations += len(hypotheses)
        out = np.empty((len(hypotheses), len(self.frames), len(self.frames[0].target)))
        for t, f in enumerate(self.frames):
            out[:, t] = shadow_distances(f.vertices, f.faces, f.normals, f.topology, hypotheses, plane, ground,
                                         self.cameras, self.matrices, self._occluders[t], f.target, self._observed[t])
        return out

    def per_view(self, lights) -> np.ndarray:
        """(T, K) ``D(S^e_{k,t}, S^o_{k,t})`` per frame and view."""
        return self.terms([lights])[0]

    def __call__(self, lights) -> float:
        return float(self.per_view(lights).sum())

    def many(self, hypotheses, ground=None) -> np.ndarray:
        """(N,) costs of a list of hypotheses (each a list of lights), cast on ``ground`` (default: the objective's)."""
        return self.terms(hypotheses, ground).sum(axis=(1, 2))

    def planes(self, lights, grounds) -> np.ndarray:
        """(N,) costs of ``lights`` casting their shadows on each of ``grounds`` (the floor's refinement)."""
        return np.array([self.many([lights], g)[0] for g in grounds])

    def empty_cost(self) -> float:
        """E with no predicted shadow at all: what a light casting nothing visible would score."""
        return float(sum(silhouette_cost(f.target, [np.zeros(f.target.image_size, bool)] * len(f.target)).total
                         for f in self.frames))
