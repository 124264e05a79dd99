"""The fitting objective of one frame: silhouettes in every view plus priors (eq. 4.6, 6.7–6.9).

Parameter vector ``x`` (D,) = ``pose`` (POSE_SIZE, see :mod:`studio.body.skeleton`) followed by
the first ``n_shape_free`` shape coefficients (the rest stay at ``base_shape``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from studio.body.skeleton import POSE_SIZE
from studio.cost import SilhouetteTarget, pose_limit_penalty, shape_prior, silhouette_cost
from studio.render.spans import ContourRenderer
from studio.render.pyramid import level_camera
from studio.threads import chunk_ranges, map_chunks

__all__ = ["CylinderObjective", "FrameObjective", "parameter_box", "pose_bounds"]

#: Evaluate the SCAPE meshes of at most this many particles in one batch.
BATCH = 16


def pose_bounds(model, root_xy: np.ndarray | None = None, xy_margin: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Bounds (lo, hi) of the pose vector: joint limits, translation within ``xy_margin`` of
    ``root_xy`` and between -0.6 and 0.3 m in height (the body stands on the floor; a seated or
    squatting body drops its pelvis up to 0.6 m)."""
    lo = model.pose_limits[:, 0].astype(np.float64).copy()
    hi = model.pose_limits[:, 1].astype(np.float64).copy()
    if root_xy is not None:
        lo[:2] = np.asarray(root_xy, dtype=np.float64) - xy_margin
        hi[:2] = np.asarray(root_xy, dtype=np.float64) + xy_margin
    lo[2], hi[2] = -0.6, 0.3
    return lo, hi


def parameter_box(model, lo: np.ndarray, hi: np.ndarray, n_free: int) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """((lower, upper) bounds, typical steps) of a pose + ``n_free`` shape vector: the pose
    bounds ``lo`` / ``hi`` and ±3 σ of the shape; steps 0.08 rad, 3 cm at the root, σ / 2."""
    sig = np.sqrt(model.eigenvalues[:n_free])
    step = np.concatenate([np.full(POSE_SIZE, 0.08), 0.5 * sig])
    step[:3] = 0.03
    return (np.concatenate([lo, -3 * sig]), np.concatenate([hi, 3 * sig])), step


@dataclass
class FrameObjective:
    """Cost of parameter vectors against one frame's observed silhouettes.

    ``cameras`` full-resolution cameras in ``targets[level].names`` order; ``targets``
    {level: SilhouetteTarget}; ``base_shape`` (n_shape,) the shape whose first
    ``n_shape_free`` coefficients ``x`` replaces; ``prior_weight`` multiplies the shape
    prior (eq. 6.8) and the joint-limit penalty (eq. 6.9, first term); ``shadow`` (a
    :class:`studio.fit.shadows.ShadowTerm`, optional) adds the shadow term of eq. 5.7.
    """

    model: object
    cameras: Sequence
    targets: dict
    base_shape: np.ndarray
    n_shape_free: int = 0
    prior_weight: float = 1.0
    n_evaluations: int = 0
    shadow: object = None

    def __post_init__(self):
        self.base_shape = np.asarray(self.base_shape, dtype=np.float64)
        self._sigma = np.sqrt(np.asarray(self.model.eigenvalues, dtype=np.float64))
        self._level_cams = {lvl: [level_camera(c, lvl) for c in self.cameras] for lvl in self.targets}
        self._limits = self.model.pose_limits.astype(np.float64)
        self._limit_sigma = np.full(POSE_SIZE, 0.05)
        self._renderers = {}

    @property
    def size(self) -> int:
        return POSE_SIZE + int(self.n_shape_free)

    def split(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N, D) parameters → shapes (N, n_shape), poses (N, POSE_SIZE)."""
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        shapes = np.repeat(self.base_shape[None], len(X), axis=0)
        shapes[:, : self.n_shape_free] = X[:, POSE_SIZE:]
        return shapes, X[:, :POSE_SIZE]

    def pack(self, shape: np.ndarray, pose: np.ndarray) -> np.ndarray:
        """(D,) parameter vector of a full ``shape`` and ``pose``."""
        return np.concatenate([np.asarray(pose, dtype=np.float64), np.asarray(shape, dtype=np.float64)[: self.n_shape_free]])

    def meshes(self, X: np.ndarray) -> np.ndarray:
        """Meshes (N, V, 3) of parameter vectors (N, D), at most ``BATCH`` at a time, on several
        threads (:meth:`chunks`)."""
        shapes, poses = self.split(X)
        poses = self.model.clip_pose(poses)
        parts = map_chunks(lambda r: self.model.vertices_batch(shapes[r[0] : r[1]], poses[r[0] : r[1]],
                                                               free_shape=self.n_shape_free), self.chunks(X))
        if len(parts) == 1:
            return parts[0]
        return np.concatenate(parts) if parts else np.empty((0, self.model.n_vertices, 3))

    def chunks(self, X: np.ndarray) -> list[tuple[int, int]]:
        """Ranges of the rows of ``X`` (N, D) evaluated together (:func:`studio.threads.chunk_ranges`):
        balanced over the threads when every row has the same shape (a search over the pose), else
        ``BATCH`` rows each but the last, as they always were. A body's shape deformation is a matrix
        product over its batch, by BLAS gemm, or by gemv for a batch of one shape: 1e-9 m apart, and
        fits follow such differences into other answers (a single shape by gemm too, so that a body's
        mesh no longer depended on its batch, moved every dev fit: 59 of 64 by less than 0.3 mm, 5 by
        0.3–1.3). Either way the cut, so the results, do not depend on the thread count."""
        X = np.atleast_2d(X)
        shared = not self.n_shape_free or len(X) < 2 or bool(np.all(X[:, POSE_SIZE:] == X[:1, POSE_SIZE:]))
        return chunk_ranges(len(X), BATCH, balance=shared)

    def masks(self, vertices: np.ndarray, level: int) -> list[np.ndarray]:
        """Model silhouettes (H_l, W_l) bool of one mesh in every camera at ``level``
        (the contour scanline renderer, prepared once per level: same masks as
        :func:`studio.render.silhouette`)."""
        r = self._renderers.get(level)
        if r is None or r.n_vertices != len(vertices):
            r = self._renderers[level] = ContourRenderer(self._level_cams[level], self.faces, len(vertices))
        return r(vertices)

    @property
    def faces(self) -> np.ndarray:
        """(F, 3) faces of the meshes :meth:`meshes` returns."""
        return self.model.faces

    def priors(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        shapes, poses = self.split(X)
        sp = np.atleast_1d(shape_prior(shapes, self._sigma))
        lp = np.atleast_1d(pose_limit_penalty(poses, self._limits[:, 0], self._limits[:, 1], self._limit_sigma))
        return sp, lp

    def __call__(self, X: np.ndarray, level: int) -> np.ndarray:
        """Total cost (N,) of parameter vectors (N, D) at pyramid ``level`` (full-res units)."""
        X = np.atleast_2d(np.asarray(X, dtype=np.float64))
        target: SilhouetteTarget = self.targets[level]

        def chunk(r):
            """Silhouette (and shadow) costs of the bodies ``r[0] : r[1]``."""
            V = self.meshes(X[r[0] : r[1]])
            out = np.empty(len(V))
            for j, v in enumerate(V):
                masks = self.masks(v, level)
                out[j] = silhouette_cost(target, masks).total
                if self.shadow is not None:  # eq. 5.7
                    out[j] += self.shadow.cost(v, self.faces, masks, level)
            return out

        parts = map_chunks(chunk, self.chunks(X))
        sp, lp = self.priors(X)
        self.n_evaluations += len(X)
        return np.concatenate(parts + [np.empty(0)]) + self.prior_weight * (sp + lp)

    def scalar(self, level: int):
        """``f(x) -> float`` at ``level`` for Nelder–Mead."""
        return lambda x: float(self(x[None], level)[0])

    def terms(self, x: np.ndarray, level: int = 0) -> dict:
        """Term-by-term costs of one parameter vector (for the results file)."""
        x = np.asarray(x, dtype=np.float64)
        V = self.meshes(x[None])[0]
        masks = self.masks(V, level)
        sc = silhouette_cost(self.targets[level], masks)
        sp, lp = self.priors(x[None])
        out = {
            "silhouette": float(sc.total),
            "silhouette_per_view": {n: float(a + b) for n, a, b in zip(sc.names, sc.model_to_observed, sc.observed_to_model)},
            "shape_prior": float(sp[0]),
            "pose_limits": float(lp[0]),
            "total": float(sc.total + self.prior_weight * (sp[0] + lp[0])),
            "level": int(level),
        }
        if self.shadow is not None:  # eq. 5.7: the shadow views averaged, with their own weight
            per = self.shadow.per_view(V, self.faces, masks, level)
            out["shadow"] = float(self.shadow.weight * np.mean(per))
            out["shadow_per_view"] = {n: float(v) for n, v in zip(sc.names, per)}
            out["shadow_weight"] = self.shadow.weight
            out["total"] += out["shadow"]
        return out


@dataclass
class CylinderObjective(FrameObjective):
    """:class:`FrameObjective` of the coarse cylinder model (thesis §4.8.1, 15 truncated cones
    sized from ``base_shape``): the same pose vector, silhouette cost and priors, a ~20× smaller
    mesh. The shape is held (``n_shape_free`` must be 0)."""

    sides: int = 12

    def __post_init__(self):
        from studio.body import CylinderModel
        from studio.body.cylinder import cone_faces

        super().__post_init__()
        if self.n_shape_free:
            raise ValueError(f"CylinderObjective: the shape is held, got n_shape_free={self.n_shape_free}")
        self.cylinder = CylinderModel.from_shape(self.model, self.base_shape)
        self._faces = cone_faces(self.sides)
        # rest joints of the held shape, so each batch needs only the kinematic chain
        # (CylinderModel.segments_batch recomputes the whole rest mesh per call)
        shape = self.base_shape[None]
        self._rest_joints = np.einsum("jv,bvc->bjc", self.model.joint_regressor,
                                      self.model.rest_vertices_batch(shape))[0]
        pose0 = self.model.default_pose()[None]
        self._root_offset = np.zeros(3)
        self._root_offset = (self.model.joints_batch(shape, pose0) - self._posed_joints(pose0)[0])[0, 0]
        self._local = self.cylinder.ends - self.cylinder.joints[:, None, :]  # (15, 2, 3)

    def _posed_joints(self, poses: np.ndarray):
        """Posed joints (B, 15, 3) and part rotations (B, 15, 3, 3) (the chain of
        ``BodyModel.joints_batch`` with the rest joints precomputed)."""
        from studio.body.scape import forward_kinematics
        from studio.body.skeleton import PART_PARENTS

        G = self.model.part_rotations(poses)
        return forward_kinematics(self._rest_joints, G, poses[:, :3] + self._root_offset, PART_PARENTS), G

    @property
    def faces(self) -> np.ndarray:
        return self._faces

    def meshes(self, X: np.ndarray) -> np.ndarray:
        from studio.body.cylinder import cone_meshes

        _, poses = self.split(X)
        J, G = self._posed_joints(self.model.clip_pose(poses))
        ends = J[:, :, None, :] + np.einsum("bpij,pkj->bpki", G, self._local)
        return cone_meshes(ends, self.cylinder.radii, self.sides)
