"""The SCAPE body model: a thin holder of the learned arrays (thesis §3.5).

``BodyModel.load("male" | "female" | "neutral")`` reads the shipped model
(``studio/body/data/scape_models.npz``, numpy/scipy only). Mesh generation follows eq. 3.23:
per-triangle ``A = R·D·Q`` (eq. 3.11) — R the part rotation from the pose, D from the
shape coefficients (eq. 3.22), Q regressed on the adjacent joint rotations (eq. 3.16) —
and the least-squares vertex positions from a system factored once at load.

Frame: world Z up, metres. With a zero pose the body stands on z = 0, its pelvis centred
over the origin, facing **-y** (its left side towards +x); the pose's root translation
moves it, the root rotation turns it about its pelvis centroid.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from studio.body import kinematics, posed, scape, skeleton
from studio.body.skeleton import PART_NAMES, PART_PARENTS, POSE_SIZE
from studio.body.storage import dequantize_blocks

log = logging.getLogger(__name__)

__all__ = ["BodyModel", "BodyModelError", "GENDERS", "DATA_FILE", "anny_correspondence"]

GENDERS = ("male", "female", "neutral")
DATA_FILE = Path(__file__).resolve().parent / "data" / "scape_models.npz"
_PELVIS = PART_NAMES.index("pelvis")
#: regressors per joint pair of a pose deformation on rotation entries (18 features, eq. 3.16)
#: in the fast kernel (:func:`studio.body.posed.low_rank_q`): the model's error at the lab
#: postures 6.48 mm with all 18, 6.61 at 8 (6: 7.29); the kernel costs about as much as the
#: rotation vectors' 6 (see :func:`studio.body.posed.posed_edges_planar`)
Q_RANK = 8


class BodyModelError(ValueError):
    """Invalid model file or invalid shape/pose input."""


_CACHE: dict[tuple[str, str], "BodyModel"] = {}


@dataclass(eq=False)
class BodyModel:
    """SCAPE model of one population; get the shipped ones with :meth:`load`.

    Attributes: ``template`` (V, 3) rest mesh, ``faces`` (F, 3) int, ``parts`` (V,) part
    index of every vertex, ``face_parts`` (F,), ``part_names`` (15), ``n_shape``,
    ``eigenvalues`` (n_shape,) shape prior variances (eq. 6.8), ``pose_size`` (30),
    ``pose_limits`` (30, 2).
    """

    gender: str
    template: np.ndarray
    faces: np.ndarray
    parts: np.ndarray
    face_parts: np.ndarray
    D_mean: np.ndarray  # (F*9,)
    D_basis: np.ndarray  # (K, F*9)
    eigenvalues: np.ndarray  # (K,)
    hinge_axes: np.ndarray  # (15, 3)
    pose_limits: np.ndarray  # (POSE_SIZE, 2)
    joint_regressor: np.ndarray  # (15, V)
    joint_pairs: np.ndarray  # (F, 2)
    Q_coef: np.ndarray | None  # (F, 7 or 19, 9) (eq. 3.16 on K = 3 or 9 joint features) or None: rigid (Q = I)
    measurement_samples: tuple[np.ndarray, np.ndarray] | None = None  # for the inverse map
    D_weights: np.ndarray | None = None  # (F,) metric of the shape PCA (triangle areas)
    part_names: tuple[str, ...] = PART_NAMES
    part_parents: tuple[int, ...] = PART_PARENTS
    Q_search: np.ndarray | None = None  # (F, 7, 9): the fit's search body's pose deformation (search_model)
    _solver: scape.PoissonSolver = field(init=False, repr=False)

    def __post_init__(self):
        self.faces = np.asarray(self.faces, dtype=np.int64)
        self.template = np.asarray(self.template, dtype=np.float64)
        V = len(self.template)
        if self.faces.ndim != 2 or self.faces.shape[1] != 3 or self.faces.min() < 0 or self.faces.max() >= V:
            raise BodyModelError(f"faces must be (F, 3) indices into {V} vertices")
        F = len(self.faces)
        self.parts = np.asarray(self.parts, dtype=np.int64)
        self.face_parts = np.asarray(self.face_parts, dtype=np.int64)
        if self.parts.shape != (V,) or self.face_parts.shape != (F,):
            raise BodyModelError(f"parts must be ({V},) and face_parts ({F},)")
        if np.any(np.diff(self.face_parts) < 0):
            raise BodyModelError("faces must be grouped by part (face_parts non-decreasing)")
        self.D_mean = np.asarray(self.D_mean, dtype=np.float32)
        self.D_basis = np.asarray(self.D_basis, dtype=np.float32)
        if self.D_mean.shape != (F * 9,) or self.D_basis.ndim != 2 or self.D_basis.shape[1] != F * 9:
            raise BodyModelError(f"shape basis must have F*9 = {F * 9} columns")
        self.eigenvalues = np.asarray(self.eigenvalues, dtype=np.float64)
        self.pose_limits = np.asarray(self.pose_limits, dtype=np.float64)
        if self.pose_limits.shape != (POSE_SIZE, 2) or np.any(self.pose_limits[:, 0] > self.pose_limits[:, 1]):
            raise BodyModelError(f"pose_limits must be ({POSE_SIZE}, 2) with low <= high")
        self._edges = scape.triangle_edges(self.template, self.faces).astype(np.float32)  # (F, 3, 2)
        # planar ("structure of arrays") copies for fast evaluation: component-major, faces last
        K = self.D_basis.shape[0]
        self._Dm = np.ascontiguousarray(self.D_mean.reshape(F, 9).T).reshape(9 * F)
        self._Db = np.ascontiguousarray(self.D_basis.reshape(K, F, 9).transpose(0, 2, 1)).reshape(K, 9 * F)
        # Q·v per triangle: linear in its two adjacent joints' features and a 1 (eq. 3.16): their
        # rotation vectors (K = 3, (F, 7, 9) coefficients) or rotation entries minus I (K = 9,
        # (F, 19, 9)); a rigid model (or use_q=False) keeps only the constant term, the template's edges
        n_reg = 7 if self.Q_coef is None else self.Q_coef.shape[1]
        if self.Q_coef is not None and (self.Q_coef.shape[0] != F or n_reg not in (7, 19)):
            raise BodyModelError(f"Q_coef must be ({F}, 7 or 19, 9), got {self.Q_coef.shape}")
        self._feature_size = (n_reg - 1) // 2
        rigid = np.zeros((F, n_reg, 3, 2), np.float32)
        rigid[:, -1] = self._edges
        self._Q_rigid = rigid
        self._Qc = rigid if self.Q_coef is None else posed.compact_q(self.Q_coef, self._edges)
        self._Qp_rigid = posed.planar_q(rigid[:, -1:])  # faces last, for the kernel: no regressor
        self._slots, self._slot = posed.pair_slots(self.joint_pairs)
        self._Qp, self._Q_reduce = posed.planar_q(self._Qc), None
        if self.Q_coef is not None and 2 * self._feature_size > Q_RANK:
            # the faces of a joint pair deform in few directions: Q_RANK regressors per pair
            # keep all but a few per cent of it at half the kernel's cost (posed.low_rank_q)
            sample = skeleton.part_rotations(np.concatenate([
                skeleton.sample_poses(300, self.pose_limits, np.random.default_rng(0)),
                skeleton.sample_wide_poses(300, self.pose_limits, np.random.default_rng(1))]), self.hinge_axes)[0]
            self._Qp, self._Q_reduce = posed.low_rank_q(self._Qc, self._slots, self._slot,
                                                        skeleton.joint_features(sample), Q_RANK)
        self._part_start = np.searchsorted(self.face_parts, np.arange(len(PART_NAMES) + 1)).astype(np.int64)
        if self.face_parts.min() < 0 or self._part_start[-1] != F:
            raise BodyModelError(f"face_parts must lie in 0..{len(PART_NAMES) - 1}")
        self._D_cache: tuple[bytes, np.ndarray] | None = None
        self._D_base: tuple[tuple, np.ndarray] | None = None
        self._solver = scape.PoissonSolver(self.faces, V)
        self._pelvis_idx = np.nonzero(self.parts == _PELVIS)[0]
        # rest-pose meshes are linear in the shape coefficients: precompute the basis
        Dall = np.concatenate([self._Dm[None], self._Db]).astype(np.float64).reshape(K + 1, 3, 3, F)
        w0 = np.moveaxis(self._Qc[:, -1], 0, -1).astype(np.float64)  # (3, 2, F): Q·v at the rest pose
        E = np.einsum("bijf,jkf->bikf", Dall, w0)
        sol = self._solver.solve_planar_reference(E)  # once per model: the previous releases' basis, bit for bit
        self._rest_mean = sol[0] - sol[0][self._pelvis_idx].mean(axis=0)
        self._rest_basis = (sol[1:] - sol[1:, self._pelvis_idx].mean(axis=1, keepdims=True)).reshape(K, -1)
        # lowest vertices of the rest pose (candidates for the floor contact)
        self._low_idx = np.argsort(self._rest_mean[:, 2])[:300]
        self._low_basis = self._rest_basis.reshape(K, V, 3)[:, self._low_idx, 2]
        self._search = None

    # ------------------------------------------------------------------ loading
    @classmethod
    def load(cls, gender: str = "neutral", path: str | Path | None = None) -> "BodyModel":
        """The shipped model of ``gender`` ('male', 'female' or 'neutral'); cached."""
        if gender not in GENDERS:
            raise BodyModelError(f"unknown gender {gender!r}: expected one of {', '.join(GENDERS)}")
        path = Path(path) if path is not None else DATA_FILE
        key = (str(path), gender)
        if key not in _CACHE:
            if not path.is_file():
                raise BodyModelError(f"{path}: body model file not found (run `studio model build`)")
            with np.load(path) as z:
                if f"{gender}/D_mean" not in z.files:
                    raise BodyModelError(f"{path}: no model for gender {gender!r}")
                _CACHE[key] = cls(
                    gender=gender,
                    template=z["template"],
                    faces=z["faces"],
                    parts=z["vertex_parts"].astype(np.int64),
                    face_parts=z["face_parts"].astype(np.int64),
                    D_mean=z[f"{gender}/D_mean"],
                    D_basis=(dequantize_blocks(z[f"{gender}/D_basis_q"], z[f"{gender}/D_basis_scale"])
                             if f"{gender}/D_basis_q" in z.files else z[f"{gender}/D_basis"]),
                    eigenvalues=z[f"{gender}/eigenvalues"],
                    hinge_axes=z["hinge_axes"],
                    pose_limits=z["pose_limits"],
                    joint_regressor=z["joint_regressor"].astype(np.float64),
                    joint_pairs=z["joint_pairs"].astype(np.int64),
                    Q_coef=z["Q_coef"].astype(np.float64),
                    Q_search=z["Q_coef_search"].astype(np.float64) if "Q_coef_search" in z.files else None,
                    D_weights=z["D_weights"] if "D_weights" in z.files else None,
                    measurement_samples=(
                        (z[f"{gender}/meas_shapes"], z[f"{gender}/meas_values"])
                        if f"{gender}/meas_shapes" in z.files
                        else None
                    ),
                )
        return _CACHE[key]

    def search_model(self) -> "BodyModel":
        """The body the fit's search scores (:func:`studio.fit.fit_frame`): this model with the
        pose deformation of ``Q_search`` (eq. 3.16 on the joints' rotation vectors, learned near
        rest), or this model itself when it has none. The model's own deformation (rotation
        entries, learned also from wide poses) is closer to the true body in deep postures, but a
        search scored with it lost its way on 4 of 120 held-out frames (15–32 mm off, where the search
        with ``Q_search`` had ended 6–8 mm off); the searched answer is refined with it."""
        if self.Q_search is None:
            return self
        if self._search is None:
            self._search = replace(self, Q_coef=self.Q_search, Q_search=None)
        return self._search

    # ------------------------------------------------------------------ sizes
    @property
    def n_shape(self) -> int:
        return int(self.D_basis.shape[0])

    @property
    def n_vertices(self) -> int:
        return int(len(self.template))

    @property
    def pose_size(self) -> int:
        return POSE_SIZE

    def default_pose(self) -> np.ndarray:
        """Zero pose (POSE_SIZE,): standing in the template's rest posture at the origin."""
        return np.zeros(POSE_SIZE)

    def mean_shape(self) -> np.ndarray:
        return np.zeros(self.n_shape)

    # ------------------------------------------------------------------ validation
    def check_shape(self, shape, batch: bool = False) -> np.ndarray:
        """Shape coefficients as float array (n_shape,) or (B, n_shape); clear errors."""
        s = np.asarray(shape, dtype=np.float64)
        want = 2 if batch else 1
        if s.ndim != want or s.shape[-1] != self.n_shape:
            exp = f"(B, {self.n_shape})" if batch else f"({self.n_shape},)"
            raise BodyModelError(f"shape must have shape {exp} for the {self.gender} model, got {s.shape}")
        if not np.all(np.isfinite(s)):
            raise BodyModelError("shape contains NaN or infinite values")
        return s

    def check_pose(self, pose, batch: bool = False, clip: bool = False) -> np.ndarray:
        """Pose vector(s) (POSE_SIZE,) or (B, POSE_SIZE) inside ``pose_limits``.

        Out-of-range angles raise, unless ``clip`` is set (then they are clamped).
        """
        p = np.asarray(pose, dtype=np.float64)
        want = 2 if batch else 1
        if p.ndim != want or p.shape[-1] != POSE_SIZE:
            exp = f"(B, {POSE_SIZE})" if batch else f"({POSE_SIZE},)"
            raise BodyModelError(f"pose must have shape {exp}, got {p.shape}")
        if not np.all(np.isfinite(p)):
            raise BodyModelError("pose contains NaN or infinite values")
        lo, hi = self.pose_limits[:, 0], self.pose_limits[:, 1]
        bad = (p < lo - 1e-9) | (p > hi + 1e-9)
        if np.any(bad):
            if clip:
                return np.clip(p, lo, hi)
            i = int(np.nonzero(bad.reshape(-1, POSE_SIZE).any(axis=0))[0][0])
            raise BodyModelError(
                f"pose entry {i} ({pose_entry_name(i)}) outside its limits "
                f"[{lo[i]:.3f}, {hi[i]:.3f}]"
            )
        return p

    def clip_pose(self, pose) -> np.ndarray:
        """Pose clamped to the anatomical limits."""
        return np.clip(np.asarray(pose, dtype=np.float64), self.pose_limits[:, 0], self.pose_limits[:, 1])

    # ------------------------------------------------------------------ algebra
    def part_rotations(self, poses: np.ndarray) -> np.ndarray:
        """Global rotation of each part (B, 15, 3, 3) for poses (B, POSE_SIZE)."""
        G, _ = skeleton.part_rotations(poses, self.hinge_axes)
        return G

    def rest_vertices_batch(self, shapes: np.ndarray) -> np.ndarray:
        """Rest-pose meshes (B, V, 3), pelvis centroid at the origin (linear in the shape)."""
        return (self._rest_mean.reshape(-1) + shapes @ self._rest_basis).reshape(len(shapes), -1, 3)

    def _anchor(self, shapes: np.ndarray) -> np.ndarray:
        """Height of the pelvis centroid above the floor in the rest pose, (B,)."""
        low = self._rest_mean[self._low_idx, 2] + shapes @ self._low_basis
        return -low.min(axis=1)

    def _shape_gradients(self, shapes: np.ndarray, free: int | None = None) -> np.ndarray:
        """Planar D (B, 3, 3, F) float32 (eq. 3.22), reusing the last result when the shapes
        repeat (pose-only optimisation) and computing a batch of equal shapes once.

        ``free``: only the first ``free`` coefficients vary from call to call (a fit's free
        ones): the rest, when every body shares them, are folded once into a cached base
        ``D_mean + β[free:]·basis[free:]`` (D is linear in β), so a new shape reads ``free``
        rows of the (n_shape, 9F) basis instead of all of them (10 of 30: 0.55 → 0.2 ms).
        Equal to the full product to float32 rounding (the sums are grouped differently)."""
        B = len(shapes)
        F = len(self.faces)
        key = shapes.tobytes() + bytes([0 if free is None else 1 + int(free)])
        cached = self._D_cache
        if cached is not None and cached[0] == key:
            return cached[1]
        if B > 1 and np.all(shapes == shapes[:1]):
            D = np.broadcast_to(self._shape_gradients(shapes[:1], free), (B, 3, 3, F))
        elif free is not None and 0 < free < self.n_shape and np.all(shapes[:, free:] == shapes[:1, free:]):
            D = (self._fixed_shape_base(shapes[0, free:], free)
                 + shapes[:, :free].astype(np.float32) @ self._Db[:free]).reshape(B, 3, 3, F)
        else:
            D = (self._Dm + shapes.astype(np.float32) @ self._Db).reshape(B, 3, 3, F)
        self._D_cache = (key, D)
        return D

    def _fixed_shape_base(self, tail: np.ndarray, free: int) -> np.ndarray:
        """``D_mean + tail·basis[free:]`` (9F,) float32, cached for the last ``(free, tail)``."""
        key = (int(free), tail.tobytes())
        cached = self._D_base
        if cached is None or cached[0] != key:
            cached = self._D_base = (key, self._Dm + tail.astype(np.float32) @ self._Db[free:])
        return cached[1]

    def _joint_features(self, G: np.ndarray, rotvecs: np.ndarray | None = None) -> np.ndarray:
        """The pose deformation's regressors per joint (B, 15, K) float32 (eq. 3.16) from the
        part rotations ``G``: rotation entries minus I (K = 9), or the rotation vectors (K = 3,
        ``rotvecs`` when already known)."""
        if self._feature_size == 9:
            f = skeleton.joint_features(G)
        else:
            f = skeleton.joint_rotvecs(G) if rotvecs is None else rotvecs
        return f.astype(np.float32)

    def _posed_edges(self, shapes: np.ndarray, poses: np.ndarray, use_q: bool = True,
                     free: int | None = None, reference: bool = False) -> np.ndarray:
        """Target edges R·D·Q·v (eq. 3.11), planar (B, 3, 2, F) float32 (:mod:`studio.body.posed`);
        the rotations by the compiled chain (:mod:`studio.body.kinematics`), or with
        ``reference`` by SciPy (:func:`studio.body.skeleton.part_rotations`)."""
        if reference:
            G, rv = self.part_rotations(poses), None  # (B, 15, 3, 3)
        else:
            G, rv = kinematics.chain_rotations(poses, self.hinge_axes)  # (B, 15, 3, 3), (B, 15, 3)
        D = self._shape_gradients(shapes, free)
        if use_q:
            x, Cp = posed.slot_regressors(self._joint_features(G, rv), self._slots, self._Q_reduce), self._Qp
        else:
            x, Cp = np.zeros((len(G), 1, 0), np.float32), self._Qp_rigid
        return posed.posed_edges_planar(x, Cp, self._slot, D, G.astype(np.float32), self._part_start)

    def _generate(self, shapes: np.ndarray, poses: np.ndarray, use_q: bool = True,
                  free: int | None = None, reference: bool = False) -> np.ndarray:
        """Meshes (B, V, 3) (eq. 3.23): the compiled rotations and solve, or with ``reference``
        SciPy's (the path of the releases before: the same meshes to the last bit)."""
        e = self._posed_edges(shapes, poses, use_q=use_q, free=free, reference=reference)
        Y = self._solver.solve_planar_reference(e) if reference else self._solver.solve_planar(e)
        c = Y[:, self._pelvis_idx].mean(axis=1)  # (B, 3)
        target = poses[:, :3].copy()
        target[:, 2] += self._anchor(shapes)
        return Y + (target - c)[:, None, :]

    # ------------------------------------------------------------------ public evaluation
    def vertices(self, shape, pose=None, *, use_q: bool = True) -> np.ndarray:
        """Mesh (V, 3) of one body (eq. 3.23). ``pose`` defaults to :meth:`default_pose`.

        One body, off the fitter's hot path: SciPy's rotations and SuperLU's solve, so the
        meshes that size the search cones, measure and report a body are the previous
        releases' to the last bit (the compiled path of :meth:`vertices_batch` agrees to
        1e-12 m, but a cone's radius depended on the rounding of its tip vertex: 0.2 mm)."""
        s = self.check_shape(shape)
        p = self.check_pose(self.default_pose() if pose is None else pose)
        return self._generate(s[None], p[None], use_q=use_q, reference=True)[0]

    def vertices_batch(self, shapes, poses, *, use_q: bool = True, free_shape: int | None = None) -> np.ndarray:
        """Meshes (B, V, 3) of B bodies, one factored system, 3B right-hand sides.

        ``free_shape``: a hint that only the first ``free_shape`` shape coefficients vary
        between calls (an optimiser's free ones); the others' share of the shape deformation
        is then computed once (see :meth:`_shape_gradients`)."""
        s = self.check_shape(shapes, batch=True)
        p = self.check_pose(poses, batch=True)
        if len(s) != len(p):
            raise BodyModelError(f"shapes ({len(s)}) and poses ({len(p)}) must have the same batch size")
        return self._generate(s, p, use_q=use_q, free=free_shape)

    def rest_joints(self, shape) -> np.ndarray:
        """Joint centres (15, 3) of ``shape`` in the default pose (placed like the mesh)."""
        return self.joints(shape, self.default_pose())

    def joints(self, shape, pose=None) -> np.ndarray:
        """Joint centres (15, 3): the joint of each part with its parent (pelvis: its root).

        Forward kinematics of the rest joints (regressed from the rest mesh) with the part
        rotations of ``pose``, placed like :meth:`vertices`.
        """
        s = self.check_shape(shape)
        p = self.check_pose(self.default_pose() if pose is None else pose)
        return self.joints_batch(s[None], p[None])[0]

    def joints_batch(self, shapes, poses) -> np.ndarray:
        """Joint centres (B, 15, 3) of B bodies."""
        s = np.asarray(shapes, dtype=np.float64)
        p = np.asarray(poses, dtype=np.float64)
        rest = self.rest_vertices_batch(s)  # pelvis centroid at 0
        J0 = np.einsum("jv,bvc->bjc", self.joint_regressor, rest)
        root = p[:, :3].copy()
        root[:, 2] += self._anchor(s)
        return scape.forward_kinematics(J0, self.part_rotations(p), root, PART_PARENTS)

    def shape_from_vertices(self, vertices) -> np.ndarray:
        """Shape coefficients (…, n_shape) best explaining rest-pose meshes (…, V, 3).

        The meshes must be in vertex correspondence with ``template`` and in its rest
        posture and orientation (translation is free). Least squares on the deformation
        gradients in the PCA's metric (eq. 3.22 inverted).
        """
        Y = np.asarray(vertices, dtype=np.float64)
        if Y.shape[-2:] != self.template.shape or not np.all(np.isfinite(Y)):
            raise BodyModelError(f"vertices must be finite (..., {self.n_vertices}, 3) in template correspondence")
        lead = Y.shape[:-2]
        D = scape.deformation_gradients(self.template, Y, self.faces).reshape(-1, self.D_mean.size)
        w = np.ones(len(self.faces)) if self.D_weights is None else np.asarray(self.D_weights, dtype=np.float64)
        w9 = np.repeat(w, 9)
        U = self.D_basis.astype(np.float64)
        A = (U * w9) @ U.T
        beta = np.linalg.solve(A, (U * w9) @ (D - self.D_mean).T).T
        return beta.reshape(lead + (self.n_shape,))

    def sample_shapes(self, n: int, rng: np.random.Generator | int | None = None, scale: float = 1.0) -> np.ndarray:
        """Shapes (n, n_shape) drawn from the Gaussian prior N(0, diag(eigenvalues))."""
        rng = np.random.default_rng(rng)
        return rng.standard_normal((n, self.n_shape)) * np.sqrt(self.eigenvalues) * scale

    def save_mesh(self, path: str | Path, vertices: np.ndarray) -> Path:
        """Write a mesh of this model as PLY or OBJ (by suffix), atomically."""
        from studio.body.meshio import write_mesh

        return write_mesh(path, vertices, self.faces)


def pose_entry_name(i: int) -> str:
    """Human-readable name of pose vector entry ``i``."""
    if i < 3:
        return f"root translation {'xyz'[i]}"
    for p, s in enumerate(skeleton.pose_slices()):
        if s.start <= i < s.stop:
            kind = skeleton.JOINT_KIND[p]
            if kind == "hinge":
                return f"{PART_NAMES[p]} hinge angle"
            return f"{PART_NAMES[p]} rotation {'xyz'[i - s.start]}"
    return f"entry {i}"


def anny_correspondence(path: str | Path | None = None):
    """Sparse (V, 13348) barycentric map from Anny's ``anny-noeyes-notongue`` mesh to ours.

    ``map @ anny_vertices`` (13348, 3) gives a mesh in this model's topology, in Anny's
    frame (Z up, facing -y, origin near the pelvis): the exact correspondence the model
    was learned with.
    """
    import scipy.sparse as sp

    path = Path(path) if path is not None else DATA_FILE
    if not path.is_file():
        raise BodyModelError(f"{path}: body model file not found")
    with np.load(path) as z:
        n = len(z["template"])
        return sp.csr_matrix(
            (z["anny_map_weights"].astype(np.float64), z["anny_map_indices"], z["anny_map_indptr"]),
            shape=(n, int(z["anny_n_vertices"]) if "anny_n_vertices" in z.files else 13348),
        )
