"""Build the shipped SCAPE models from the open Anny population (build time only).

Needs the ``model-build`` extra (torch, anny, fast-simplification); the toolkit at run
time never imports this module. Steps (thesis ch. 3):

1. template: Anny's neutral adult, segmented into the 15 parts from its skinning weights,
   decimated half-body (head and hands decimated harder) and mirrored, so the template is
   exactly left/right symmetric; a barycentric map gives exact correspondence to Anny;
2. shape: deformation gradients D of adults sampled from Anny's calibrated population plus
   its local sliders, and their PCA per population (eq. 3.18–3.22);
3. pose: the reference (template) body and 5 adults of the populations, each in 75
   training poses (+ 25 held out) skinned by Anny; Q = D⁻¹·Rᵀ·A per example with the
   known part rotations R (the thesis estimates R by Procrustes, App. C, because its scan
   poses are unknown; ours are known, and using them makes training match evaluation),
   regressed on the adjacent joint rotations with Q = I at rest (eq. 3.14–3.17);
4. joint regressors and held-out sets for the benchmark.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from studio.body import scape, skeleton
from studio.body.skeleton import JOINT_KIND, PART_NAMES, PART_PARENTS
from studio.body.storage import save_model_file

log = logging.getLogger(__name__)

__all__ = ["build_models", "add_measurement_samples", "anny_truth_meshes", "bone_part", "POPULATIONS"]

#: gender value ranges of Anny (0 = male, 1 = female) per population
POPULATIONS = {"male": (0.0, 0.12), "female": (0.88, 1.0), "neutral": (0.0, 1.0)}

#: first Anny bone of each part (its head is the joint centre / rotation pivot)
PART_FIRST_BONE = {
    "pelvis": "root",
    "torso": "spine04",
    "head": "neck02",
    "upperarm_l": "upperarm01.L",
    "lowerarm_l": "lowerarm01.L",
    "hand_l": "wrist.L",
    "upperarm_r": "upperarm01.R",
    "lowerarm_r": "lowerarm01.R",
    "hand_r": "wrist.R",
    "upperleg_l": "upperleg01.L",
    "lowerleg_l": "lowerleg01.L",
    "foot_l": "foot.L",
    "upperleg_r": "upperleg01.R",
    "lowerleg_r": "lowerleg01.R",
    "foot_r": "foot.R",
}


def bone_part(bone: str) -> str:
    """The part an Anny bone belongs to (from its name)."""
    side = "_l" if bone.endswith(".L") else "_r"
    b = bone.split(".")[0]
    if b in ("root", "pelvis", "spine05"):
        return "pelvis"
    if b in ("spine04", "spine03", "spine02", "spine01", "clavicle", "shoulder01", "breast", "neck01"):
        return "torso"
    if b.startswith(("neck", "head", "eye", "jaw", "tongue")) or b in ("special04",):
        return "head"
    if b.startswith("upperarm"):
        return "upperarm" + side
    if b.startswith("lowerarm"):
        return "lowerarm" + side
    if b.startswith(("wrist", "finger", "metacarpal")):
        return "hand" + side
    if b.startswith("upperleg"):
        return "upperleg" + side
    if b.startswith("lowerleg"):
        return "lowerleg" + side
    if b.startswith(("foot", "toe")):
        return "foot" + side
    return "head"


# ----------------------------------------------------------------------------- anny access
class _Anny:
    """Thin access to Anny (torch), float64, no gradients."""

    def __init__(self):
        import anny
        import torch

        torch.set_grad_enabled(False)
        self.torch = torch
        self.m = anny.Anny(topology="anny-noeyes-notongue", local_changes="all").to(torch.float64)
        self.labels = list(self.m.bone_labels)
        self.parents = [int(p) for p in self.m.bone_parents]
        self.faces = self.m.faces.numpy().astype(np.int64)
        self.local_labels = list(self.m.local_change_labels)
        w = self.m.vertex_bone_weights.numpy()
        idx = self.m.vertex_bone_indices.numpy()
        self.n_vertices = w.shape[0]
        self.weights = sp.csr_matrix(
            (w.ravel(), (np.repeat(np.arange(w.shape[0]), w.shape[1]), idx.ravel())),
            shape=(w.shape[0], len(self.labels)),
        )
        from anny.anthropometry import Anthropometry

        self.anthro = Anthropometry(self.m)

    def rest(self, phen: np.ndarray, local: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
        """Rest vertices (B, V, 3), bone heads (B, 104, 3), anthropometry dict of arrays."""
        torch = self.torch
        labels = self.m.phenotype_labels
        pk = {k: torch.as_tensor(phen[:, i]) for i, k in enumerate(labels)}
        lk = torch.as_tensor(local)
        out = self.m(phenotype_kwargs=pk, local_changes_kwargs=lk)
        rv = out["rest_vertices"]
        anth = {k: v.numpy() for k, v in self.anthro(rv).items()}
        return rv.numpy(), out["rest_bone_heads"].numpy(), anth

    def skin(self, rest_vertices: np.ndarray, transforms: np.ndarray) -> np.ndarray:
        """Anny's skinning of rest vertices (B, V, 3) with bone transforms (B, 104, 4, 4)."""
        torch = self.torch
        v = self.m.get_skinned_vertices(torch.as_tensor(rest_vertices), torch.as_tensor(transforms))
        return v.numpy()


# ----------------------------------------------------------------------------- template
def _segment(anny: _Anny) -> np.ndarray:
    """Part index of every Anny vertex: argmax of skinning weights summed per part."""
    bp = np.array([PART_NAMES.index(bone_part(b)) for b in anny.labels])
    P = sp.csr_matrix((np.ones(len(bp)), (np.arange(len(bp)), bp)), shape=(len(bp), 15))
    return np.asarray((anny.weights @ P).argmax(axis=1)).ravel()


def _weld(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge vertices closer than 0.1 µm (the decimated pieces share their kept borders)."""
    q = np.round(vertices / 1e-7).astype(np.int64)
    _, first, inverse = np.unique(q, axis=0, return_index=True, return_inverse=True)
    return vertices[first], inverse.ravel()[faces]


def _decimate_template(
    V0: np.ndarray, F0: np.ndarray, vpart: np.ndarray, keep: dict[str, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric decimation: decimate the +x half region by region (borders kept), mirror."""
    import fast_simplification

    V0 = V0.copy()
    mid = np.abs(V0[:, 0]) < 1e-6
    V0[mid, 0] = 0.0
    cx = V0[F0].mean(axis=1)[:, 0]
    half = F0[cx > 0]
    fpart = vpart[half]
    fpart = np.array([np.bincount(r, minlength=15).argmax() for r in fpart])
    region = np.full(len(half), "body", dtype=object)
    region[fpart == PART_NAMES.index("head")] = "head"
    region[(fpart == PART_NAMES.index("hand_l")) | (fpart == PART_NAMES.index("hand_r"))] = "hand"
    region[(fpart == PART_NAMES.index("foot_l")) | (fpart == PART_NAMES.index("foot_r"))] = "foot"
    pieces_v, pieces_f = [], []
    offset = 0
    for name in ("body", "head", "hand", "foot"):
        f = half[region == name]
        used, inv = np.unique(f, return_inverse=True)
        v, fl = V0[used], inv.reshape(-1, 3)
        target = int(len(fl) * keep[name])
        v2, f2 = fast_simplification.simplify(
            v, fl.astype(np.int32), target_count=target, agg=7.0, preserve_border=True
        )
        pieces_v.append(v2)
        pieces_f.append(f2 + offset)
        offset += len(v2)
    v = np.concatenate(pieces_v)
    f = np.concatenate(pieces_f)
    v, f = _weld(v, f)
    # snap the seam on the symmetry plane, then mirror
    on_plane = np.abs(v[:, 0]) < 1e-6
    v[on_plane, 0] = 0.0
    n = len(v)
    vm = v * [-1.0, 1.0, 1.0]
    allv = np.concatenate([v, vm])
    allf = np.concatenate([f, f[:, ::-1] + n])
    allv, allf = _weld(allv, allf)
    # drop degenerate faces
    good = (allf[:, 0] != allf[:, 1]) & (allf[:, 1] != allf[:, 2]) & (allf[:, 0] != allf[:, 2])
    allf = allf[good]
    used, inv = np.unique(allf, return_inverse=True)
    return allv[used], inv.reshape(-1, 3)


def _closest_on_triangles(p: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest points of p (N, 3) on triangles (N, K, 3, 3): distances (N, K), bary (N, K, 3)."""
    a, b, c = tri[..., 0, :], tri[..., 1, :], tri[..., 2, :]
    q = p[:, None, :]
    e0, e1 = b - a, c - a
    n = np.cross(e0, e1)
    nn = np.maximum(np.einsum("...i,...i", n, n), 1e-30)
    # projection barycentrics
    w = q - a
    d00, d01, d11 = (np.einsum("...i,...i", x, y) for x, y in ((e0, e0), (e0, e1), (e1, e1)))
    d20, d21 = np.einsum("...i,...i", w, e0), np.einsum("...i,...i", w, e1)
    den = np.maximum(d00 * d11 - d01 * d01, 1e-30)
    v = (d11 * d20 - d01 * d21) / den
    u = (d00 * d21 - d01 * d20) / den
    bary = np.stack([1 - v - u, v, u], axis=-1)
    inside = np.all(bary >= 0, axis=-1)
    best_b = bary.copy()
    best_d = np.abs(np.einsum("...i,...i", w, n)) / np.sqrt(nn)
    best_d = np.where(inside, best_d, np.inf)
    verts = (a, b, c)
    for i, j in ((0, 1), (1, 2), (2, 0)):
        s0, s1 = verts[i], verts[j]
        seg = s1 - s0
        t = np.clip(np.einsum("...i,...i", q - s0, seg) / np.maximum(np.einsum("...i,...i", seg, seg), 1e-30), 0, 1)
        d = np.linalg.norm(q - (s0 + t[..., None] * seg), axis=-1)
        bb = np.zeros_like(bary)
        bb[..., i] = 1 - t
        bb[..., j] = t
        better = d < best_d
        best_d = np.where(better, d, best_d)
        best_b = np.where(better[..., None], bb, best_b)
    return best_d, best_b


def _barycentric_map(V0: np.ndarray, F0: np.ndarray, points: np.ndarray, k: int = 12) -> sp.csr_matrix:
    """Sparse (P, V0) map: each point as barycentric combination of its closest triangle."""
    from scipy.spatial import cKDTree

    vf = sp.csr_matrix(
        (np.ones(F0.size), (F0.ravel(), np.repeat(np.arange(len(F0)), 3))), shape=(len(V0), len(F0))
    )
    _, nn = cKDTree(V0).query(points, k=k)
    rows, cols, vals = [], [], []
    for i, pt in enumerate(points):
        cand = np.unique(vf[nn[i]].indices)
        d, b = _closest_on_triangles(pt[None], V0[F0[cand]][None])
        j = int(np.argmin(d[0]))
        rows += [i] * 3
        cols += list(F0[cand[j]])
        vals += list(b[0, j])
    M = sp.csr_matrix((vals, (rows, cols)), shape=(len(points), len(V0)))
    M.sum_duplicates()
    return M


def _check_watertight(faces: np.ndarray) -> int:
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return int(np.sum(counts != 2))


# ----------------------------------------------------------------------------- sampling
def _body_local_mask(labels: list[str]) -> np.ndarray:
    keys = (
        "measure-", "upperarm", "lowerarm", "upperleg", "lowerleg", "hip-", "torso-",
        "stomach-", "buttocks-", "neck-", "foot-scale", "hand-scale", "breast-volume",
        "leg-valgus", "upperlegs-", "lowerlegs-",
    )
    return np.array([any(k in lab for k in keys) and "nipple" not in lab for lab in labels])


def sample_population(
    anny: _Anny,
    population: str,
    n: int,
    rng: np.random.Generator,
    local_sigma: float = 0.04,
    latent_dims: int = 8,
    latent_sigma: float = 0.2,
) -> tuple[np.ndarray, np.ndarray]:
    """Phenotypes (n, 6) and local slider values (n, L) of realistic adults.

    Height, weight, muscle and proportions come from Anny's calibrated conditional
    distributions (``anny.shape_distribution``) at adult (morphological) ages 20-65; the
    body local sliders (tied left/right) add variation beyond the six phenotypes: a few
    correlated latent factors (``latent_dims``, each moving all sliders along a fixed random
    direction, like real covarying proportions) plus small independent noise.
    """
    import torch
    from anny.shape_distribution import SimpleShapeDistribution

    torch.manual_seed(int(rng.integers(2**31)))
    lo, hi = POPULATIONS[population]
    dist = SimpleShapeDistribution(
        anny.m,
        morphological_age_distribution=torch.distributions.Uniform(
            torch.tensor(20.0, dtype=torch.float64), torch.tensor(65.0, dtype=torch.float64)
        ),
        gender_distribution=torch.distributions.Uniform(
            torch.tensor(lo, dtype=torch.float64), torch.tensor(hi, dtype=torch.float64)
        ),
    )
    _, kw = dist.sample(n)
    labels = anny.m.phenotype_labels
    phen = np.stack([kw[k].numpy() for k in labels], axis=1)
    mask = _body_local_mask(anny.local_labels)
    m = int(mask.sum())
    directions = np.random.default_rng(12345).standard_normal((latent_dims, m)) / np.sqrt(latent_dims)
    local = np.zeros((n, len(anny.local_labels)))
    local[:, mask] = (
        rng.normal(0.0, latent_sigma, size=(n, latent_dims)) @ directions
        + rng.normal(0.0, local_sigma, size=(n, m))
    )
    # tie left/right sliders
    labs = anny.local_labels
    for i, lab in enumerate(labs):
        if lab.startswith("r-") and ("l-" + lab[2:]) in labs:
            local[:, i] = local[:, labs.index("l-" + lab[2:])]
    if population == "male":
        for i, lab in enumerate(labs):
            if lab.startswith("breast"):
                local[:, i] = 0.0
    return phen, np.clip(local, -1.0, 1.0)


# ----------------------------------------------------------------------------- pose
def _hinge_axes(joints: np.ndarray) -> tuple[np.ndarray, float]:
    """Hinge axes (15, 3) in the template frame and the rest elbow flexion (rad)."""
    ax = np.zeros((15, 3))
    ax[[PART_NAMES.index(n) for n in ("head", "lowerleg_l", "lowerleg_r", "foot_l", "foot_r")]] = [1, 0, 0]
    bends = []
    for side in ("l", "r"):
        s = joints[PART_NAMES.index(f"upperarm_{side}")]
        e = joints[PART_NAMES.index(f"lowerarm_{side}")]
        w = joints[PART_NAMES.index(f"hand_{side}")]
        d1, d2 = e - s, w - e
        a = np.cross(d1, d2)
        a /= np.linalg.norm(a)
        bends.append(np.arccos(np.clip(d1 @ d2 / np.linalg.norm(d1) / np.linalg.norm(d2), -1, 1)))
        ax[PART_NAMES.index(f"lowerarm_{side}")] = a
        ax[PART_NAMES.index(f"hand_{side}")] = a
    return ax, float(np.mean(bends))


def sample_poses(n: int, limits: np.ndarray, rng: np.random.Generator, spread: float = 0.6) -> np.ndarray:
    """Random joint angles (n, POSE_SIZE), root fixed: hinges uniform in the central
    ``spread`` of their range, ball joints within ±35 % of their half-range around rest."""
    mid = limits.mean(axis=1)
    half = 0.5 * (limits[:, 1] - limits[:, 0])
    poses = mid + rng.uniform(-1, 1, size=(n, len(mid))) * half * spread
    poses[:, :6] = 0.0
    for p, kind in enumerate(JOINT_KIND):
        s = skeleton.pose_slices()[p]
        if kind == "ball":  # the rest (0) lies inside every ball joint's box
            poses[:, s] = rng.uniform(-1, 1, (n, 3)) * half[s] * 0.35
    return np.clip(poses, limits[:, 0], limits[:, 1])


def anny_bone_transforms(
    anny: _Anny, bone_heads: np.ndarray, G: np.ndarray, part_joint_bone: list[int]
) -> np.ndarray:
    """Bone transforms (B, 104, 4, 4) applying the part rotations G about the joint pivots."""
    B = G.shape[0]
    bp = np.array([PART_NAMES.index(bone_part(b)) for b in anny.labels])
    piv = bone_heads[:, part_joint_bone]  # (B, 15, 3) rest joint centres
    posed = np.zeros_like(piv)
    for p, parent in enumerate(PART_PARENTS):
        if parent < 0:
            posed[:, p] = piv[:, p]
        else:
            posed[:, p] = posed[:, parent] + np.einsum("bij,bj->bi", G[:, parent], piv[:, p] - piv[:, parent])
    T = np.zeros((B, len(anny.labels), 4, 4))
    Rb = G[:, bp]
    T[..., :3, :3] = Rb
    T[..., :3, 3] = posed[:, bp] - np.einsum("bkij,bkj->bki", Rb, piv[:, bp])
    T[..., 3, 3] = 1.0
    return T


# ----------------------------------------------------------------------------- main build
def build_models(
    out_dir: Path,
    seed: int = 0,
    n_train: int = 600,
    n_test: int = 100,
    n_poses: int = 100,
    n_components: int = 30,
    n_pose_bodies: int = 6,
    scratch: Path | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict:
    """Build male/female/neutral models into ``out_dir``; returns a summary dict."""
    say = progress or (lambda msg: log.info(msg))
    rng = np.random.default_rng(seed)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    scratch = Path(scratch) if scratch else None

    say("loading Anny (first construction takes ~1 min)")
    anny = _Anny()
    L = len(anny.local_labels)
    phen_labels = list(anny.m.phenotype_labels)
    ref_phen = np.full((1, len(phen_labels)), 0.5)
    ref_phen[0, phen_labels.index("age")] = 0.8
    V0, heads0, _ = anny.rest(ref_phen, np.zeros((1, L)))
    V0, heads0 = V0[0], heads0[0]
    F0 = anny.faces
    vpart0 = _segment(anny)

    say("decimating the template")
    keep = {"body": 0.72, "head": 0.3, "hand": 0.24, "foot": 0.45}
    Vt, Ft = _decimate_template(V0, F0, vpart0, keep)
    holes = _check_watertight(Ft)
    M = _barycentric_map(V0, F0, Vt)
    X = M @ V0
    # symmetric correspondence: mirror of each template vertex
    from scipy.spatial import cKDTree

    mirror = cKDTree(X).query(X * [-1, 1, 1])[1]
    # vertex parts: part of the heaviest Anny vertex; triangle parts: majority
    vpart = vpart0[np.asarray(M.argmax(axis=1)).ravel()]
    fpart = np.array([np.bincount(r, minlength=15).argmax() for r in vpart[Ft]])
    order = np.argsort(fpart, kind="stable")  # faces grouped by part (fast per-part rotation)
    Ft, fpart = Ft[order], fpart[order]
    say(f"template: {len(X)} vertices, {len(Ft)} triangles, non-manifold edges {holes}")

    part_joint_bone = [anny.labels.index(PART_FIRST_BONE[n]) for n in PART_NAMES]

    # ------------------------------------------------------------- shape populations
    frames_inv = np.linalg.inv(scape.triangle_frames(X, Ft))
    tri_area = 0.5 * np.linalg.norm(np.cross(X[Ft[:, 1]] - X[Ft[:, 0]], X[Ft[:, 2]] - X[Ft[:, 0]]), axis=1)
    area_w = tri_area / tri_area.mean()
    arrays: dict[str, np.ndarray] = {}
    summary: dict = {"vertices": int(len(X)), "triangles": int(len(Ft)), "nonmanifold_edges": holes}
    joints_train = []
    pop_samples: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    meshes_train = []
    for pop in ("male", "female", "neutral"):
        say(f"sampling {pop} population ({n_train} + {n_test})")
        phen, local = sample_population(anny, pop, n_train + n_test, rng)
        Ys, Js, anth = [], [], {"height": [], "volume": [], "mass": []}
        for i in range(0, len(phen), 50):
            rv, bh, an = anny.rest(phen[i : i + 50], local[i : i + 50])
            Ys.append(np.stack([M @ r for r in rv]))
            Js.append(bh[:, part_joint_bone])
            for k in anth:
                anth[k].append(an[k])
        Y = np.concatenate(Ys)
        J = np.concatenate(Js)
        anth = {k: np.concatenate(v) for k, v in anth.items()}
        D = np.einsum("bfij,fjk->bfik", scape.triangle_frames(Y, Ft), frames_inv)
        Dtr = D[:n_train].reshape(n_train, -1)
        del D
        mean = Dtr.mean(axis=0)
        # area-weighted PCA: the D-space metric integrates over the surface, so that small
        # dense triangles (face, fingers) do not take the components (eq. 3.20-3.22)
        sw = np.repeat(np.sqrt(area_w), 9)
        _, s, Vt_ = np.linalg.svd(((Dtr - mean) * sw).astype(np.float32), full_matrices=False)
        s = s.astype(np.float64)
        del Dtr
        eig = s**2 / (n_train - 1)
        arrays[f"{pop}/D_mean"] = mean.astype(np.float32)
        arrays[f"{pop}/D_basis"] = (Vt_[:n_components] / sw).astype(np.float16)
        arrays[f"{pop}/eigenvalues"] = eig[:n_components].astype(np.float64)
        arrays[f"{pop}/explained"] = (np.cumsum(eig) / eig.sum())[:n_components]
        # held-out set for the benchmark (scratch, not shipped)
        if scratch is not None:
            scratch.mkdir(parents=True, exist_ok=True)
            np.savez_compressed(
                scratch / f"heldout_{pop}.npz",
                vertices=Y[n_train:].astype(np.float32),
                anny_vertices_height=anth["height"][n_train:],
                anny_volume=anth["volume"][n_train:],
                anny_mass=anth["mass"][n_train:],
                joints=J[n_train:],
                phenotypes=phen[n_train:],
                train_vertices=Y[:200].astype(np.float32),
            )
        joints_train.append(J[:n_train])
        pop_samples[pop] = (phen[:n_train], local[:n_train])
        meshes_train.append(Y[:n_train])
        summary[pop] = {
            "explained_20": float(arrays[f"{pop}/explained"][19]),
            "stature_mean": float(np.ptp(Y[:, :, 2], axis=1).mean()),
            "stature_std": float(np.ptp(Y[:, :, 2], axis=1).std()),
            "mass_mean": float(anth["mass"].mean()),
            "mass_std": float(anth["mass"].std()),
        }
        say(f"{pop}: stature {summary[pop]['stature_mean']:.3f}±{summary[pop]['stature_std']:.3f} m, "
            f"mass {summary[pop]['mass_mean']:.1f}±{summary[pop]['mass_std']:.1f} kg, "
            f"20 comps explain {summary[pop]['explained_20']:.4f}")

    # ------------------------------------------------------------- joint regressor
    say("joint regressors")
    Jtr = np.concatenate(joints_train)  # (N, 15, 3)
    Ytr = np.concatenate(meshes_train)  # (N, V, 3)
    Wj = _joint_regressor(X, Ft, fpart, vpart, Ytr, Jtr, heads0[part_joint_bone])
    Wj = symmetrize_joint_regressor(Wj, mirror)

    # ------------------------------------------------------------- pose deformations
    joints_t = Wj @ X
    hinge_axes, elbow_rest = _hinge_axes(heads0[part_joint_bone])
    limits = skeleton.default_limits(elbow_rest)
    say(f"posing the template body and {n_pose_bodies - 1} adults in {n_poses} poses each")
    poses = sample_poses(n_poses, limits, rng)
    G, _ = skeleton.part_rotations(poses, hinge_axes)
    pairs = _joint_pairs(fpart, X[Ft].mean(axis=1), joints_t)
    n_fit = max(1, n_poses - max(n_poses // 4, 10))
    # pose bodies: the template itself (D = I, the thesis' single subject) and adults of the
    # three training populations; for each, Q = D⁻¹·Rᵀ·A (eq. 3.11 solved for Q), so that
    # the regressed Q transfers across shapes
    bodies = [(ref_phen[0], np.zeros(L))]
    for i in range(n_pose_bodies - 1):
        ph, lo = pop_samples[("male", "female", "neutral")[i % 3]]
        bodies.append((ph[i // 3], lo[i // 3]))
    Q_all, rv_all = [], []
    for b, (ph, lo) in enumerate(bodies):
        Vb, hb, _ = anny.rest(ph[None], lo[None])
        Vb, hb = Vb[0], hb[0]
        Yb = M @ Vb
        Db_inv = np.linalg.inv(scape.triangle_frames(Yb, Ft) @ frames_inv)  # (F, 3, 3)
        T = anny_bone_transforms(anny, np.broadcast_to(hb, (n_poses,) + hb.shape), G, part_joint_bone)
        Vp = anny.skin(np.broadcast_to(Vb, (n_poses,) + Vb.shape).copy(), T)
        Yp = np.stack([M @ v for v in Vp])
        # the part rotations are known here (we posed Anny with them): use them rather than
        # Procrustes estimates (App. C), so that training matches evaluation, where R comes
        # from the pose vector
        Rp = G
        A = np.einsum("bfij,fjk->bfik", scape.triangle_frames(Yp[:n_fit], Ft), frames_inv)
        RtA = np.einsum("bfji,bfjk->bfik", Rp[:n_fit, fpart], A)
        Q_all.append(np.einsum("fij,bfjk->bfik", Db_inv, RtA).astype(np.float32))
        rv_all.append(skeleton.joint_rotvecs(Rp[:n_fit]))
        if b == 0:
            Yp_ref = Yp
    coef = scape.fit_pose_deformation(np.concatenate(Q_all).astype(np.float64), np.concatenate(rv_all), pairs)
    del Q_all
    Yp = Yp_ref
    if scratch is not None:
        np.savez_compressed(
            scratch / "heldout_poses.npz",
            poses=poses[n_fit:],
            vertices=Yp[n_fit:].astype(np.float32),
            joints=np.stack(
                [anny_joint_positions(heads0[part_joint_bone], G[i]) for i in range(n_fit, n_poses)]
            ),
            rest=X.astype(np.float32),
        )
    summary["poses_train"] = int(n_fit)
    summary["pose_bodies"] = int(n_pose_bodies)
    summary["poses_heldout"] = int(n_poses - n_fit)

    arrays.update(
        template=X.astype(np.float64),
        D_weights=area_w.astype(np.float32),
        faces=Ft.astype(np.int32),
        vertex_parts=vpart.astype(np.int8),
        face_parts=fpart.astype(np.int8),
        mirror=mirror.astype(np.int32),
        hinge_axes=hinge_axes,
        pose_limits=limits,
        joint_regressor=Wj.astype(np.float32),
        joint_pairs=pairs.astype(np.int8),
        Q_coef=coef.astype(np.float32),
        anny_map_indices=M.indices.astype(np.int32),
        anny_map_weights=M.data.astype(np.float32),
        anny_map_indptr=M.indptr.astype(np.int32),
        anny_n_vertices=np.array(M.shape[1]),
    )
    save_model_file(out_dir / "scape_models.npz", arrays)
    say("measuring bodies sampled from each shape prior (inverse map)")
    add_measurement_samples(out_dir / "scape_models.npz", n=120, seed=seed)
    summary["file_bytes"] = os.path.getsize(out_dir / "scape_models.npz")
    return summary


def anny_joint_positions(rest_joints: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Posed joint centres (15, 3) of Anny's posing (pivots at rest joints, root fixed)."""
    posed = np.zeros_like(rest_joints)
    for p, parent in enumerate(PART_PARENTS):
        posed[p] = rest_joints[p] if parent < 0 else posed[parent] + G[parent] @ (rest_joints[p] - rest_joints[parent])
    return posed


def _joint_pairs(fpart: np.ndarray, centroids: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """The two joints nearest each triangle among those adjacent to its part (eq. 3.16)."""
    adj: list[list[int]] = [[] for _ in range(15)]
    for p, parent in enumerate(PART_PARENTS):
        if parent >= 0:
            adj[p].append(p)  # the joint of part p with its parent is indexed by p
            adj[parent].append(p)
    pairs = np.zeros((len(fpart), 2), dtype=np.int64)
    for p in range(15):
        sel = np.nonzero(fpart == p)[0]
        cand = np.array(adj[p])
        d = np.linalg.norm(centroids[sel, None] - joints[cand][None], axis=-1)
        order = np.argsort(d, axis=1)
        first = cand[order[:, 0]]
        second = cand[order[:, 1]] if len(cand) > 1 else first
        pairs[sel, 0], pairs[sel, 1] = first, second
    return pairs


def _joint_regressor(X, Ft, fpart, vpart, Y, J, J0, radius: float = 0.09, ridge: float = 1e-4) -> np.ndarray:
    """Sparse (15, V) regressor, weights summing to 1, on vertices near each joint."""
    V = len(X)
    W = np.zeros((15, V))
    for p in range(15):
        near = np.nonzero(np.linalg.norm(X - J0[p], axis=1) < radius)[0]
        parent = PART_PARENTS[p]
        ok = np.isin(vpart[near], [p] + ([parent] if parent >= 0 else []))
        near = near[ok]
        if len(near) < 4:
            near = np.argsort(np.linalg.norm(X - J0[p], axis=1))[:20]
        # unknown w (k), sum 1: solve via lstsq with a heavy constraint row
        A = np.transpose(Y[:, near, :], (0, 2, 1)).reshape(-1, len(near))
        b = J[:, p, :].reshape(-1)
        w0 = np.full(len(near), 1.0 / len(near))
        big = 1e3
        A2 = np.vstack([A, np.sqrt(ridge) * np.eye(len(near)), big * np.ones((1, len(near)))])
        b2 = np.concatenate([b, np.sqrt(ridge) * w0, [big]])
        w = np.linalg.lstsq(A2, b2, rcond=None)[0]
        W[p, near] = w
    return W


def add_measurement_samples(path: Path, n: int = 120, seed: int = 0) -> None:
    """Measure n prior samples per population and store them in the model file."""
    from studio.body.inverse import measurement_samples
    from studio.body.model import _CACHE, GENDERS, BodyModel

    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    for g in GENDERS:
        _CACHE.pop((str(path), g), None)
        model = BodyModel.load(g, path)
        shapes, values = measurement_samples(model, n, np.random.default_rng([seed, GENDERS.index(g)]))
        arrays[f"{g}/meas_shapes"] = shapes.astype(np.float32)
        arrays[f"{g}/meas_values"] = values.astype(np.float32)
        _CACHE.pop((str(path), g), None)
    save_model_file(path, arrays)


def symmetrize_joint_regressor(W: np.ndarray, mirror: np.ndarray) -> np.ndarray:
    """Make left/right joint weights mirror images (and centre joints self-symmetric)."""
    W = np.asarray(W, dtype=np.float64).copy()
    out = W.copy()
    for p, name in enumerate(PART_NAMES):
        if name.endswith("_l"):
            q = PART_NAMES.index(name[:-2] + "_r")
            sym = 0.5 * (W[p] + W[q][mirror])
            out[p], out[q] = sym, sym[mirror]
        elif not name.endswith("_r"):
            out[p] = 0.5 * (W[p] + W[p][mirror])
    return out


_ANNY_SINGLETON: list[_Anny] = []


def anny_truth_meshes(
    phenotypes: dict[str, np.ndarray] | np.ndarray,
    poses: np.ndarray,
    local_changes: np.ndarray | None = None,
    model_path: Path | None = None,
) -> dict[str, np.ndarray]:
    """Posed Anny bodies placed in the frame of :class:`studio.body.BodyModel` (build extra).

    Independent "truth" bodies for simulation and evaluation: Anny's own shape and skinning,
    driven by this toolkit's pose vectors (part rotations about Anny's joint centres) and
    placed by the model's convention (standing on z = 0, pelvis centroid over the origin
    at zero translation, facing -y, root rotation about the pelvis centroid).

    ``phenotypes``: dict label → (B,) or array (B, 6) in Anny's phenotype order
    (gender 0 = male … 1 = female, age ≈ 0.77–0.83 for adults, muscle, weight, height,
    proportions, all in [0, 1]); ``poses`` (B, 30); ``local_changes`` (B, 256) or None.
    Returns ``vertices`` (B, V, 3) in the model topology, ``anny_vertices`` (B, 13348, 3)
    and ``anny_faces`` at full resolution, ``joints`` (B, 15, 3) (joint centres).
    """
    from studio.body.model import DATA_FILE, anny_correspondence

    path = Path(model_path) if model_path else DATA_FILE
    if not _ANNY_SINGLETON:
        _ANNY_SINGLETON.append(_Anny())
    anny = _ANNY_SINGLETON[0]
    poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
    B = len(poses)
    labels = list(anny.m.phenotype_labels)
    if isinstance(phenotypes, dict):
        phen = np.full((B, len(labels)), 0.5)
        phen[:, labels.index("age")] = 0.8
        for k, v in phenotypes.items():
            if k not in labels:
                raise ValueError(f"unknown Anny phenotype {k!r}: expected some of {labels}")
            phen[:, labels.index(k)] = v
    else:
        phen = np.broadcast_to(np.asarray(phenotypes, dtype=np.float64), (B, len(labels))).copy()
    local = np.zeros((B, len(anny.local_labels))) if local_changes is None else np.asarray(local_changes, float)
    with np.load(path) as z:
        hinge_axes = z["hinge_axes"]
        vparts = z["vertex_parts"]
    M = anny_correspondence(path)
    rest, heads, _ = anny.rest(phen, local)
    part_joint_bone = [anny.labels.index(PART_FIRST_BONE[n]) for n in PART_NAMES]
    G, _ = skeleton.part_rotations(poses, hinge_axes)
    T = anny_bone_transforms(anny, heads, G, part_joint_bone)
    full = anny.skin(rest, T)
    pel = vparts == PART_NAMES.index("pelvis")
    out_v, out_full, out_j = [], [], []
    for b in range(B):
        y_rest = M @ rest[b]
        y = M @ full[b]
        anchor = y_rest[pel].mean(axis=0)[2] - y_rest[:, 2].min()
        shift = -y[pel].mean(axis=0) + [0.0, 0.0, anchor] + poses[b, :3]
        out_v.append(y + shift)
        out_full.append(full[b] + shift)
        out_j.append(anny_joint_positions(heads[b, part_joint_bone], G[b]) + shift)
    return {
        "vertices": np.stack(out_v),
        "anny_vertices": np.stack(out_full),
        "anny_faces": anny.faces,
        "joints": np.stack(out_j),
    }
