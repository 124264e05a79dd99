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

from studio.body import scape, skeleton
from studio.body.skeleton import PART_NAMES, PART_PARENTS, sample_poses, sample_wide_poses
from studio.body.anny_adapter import (
    PART_FIRST_BONE,
    _Anny,
    anny_bone_transforms,
    anny_joint_positions,
    anny_truth_meshes,
    bone_part,
)
from studio.body.storage import save_model_file
from studio.body.template_build import _barycentric_map, _check_watertight, _decimate_template, _segment

log = logging.getLogger(__name__)

__all__ = ["build_models", "add_measurement_samples", "anny_truth_meshes", "bone_part", "POPULATIONS"]

#: gender value ranges of Anny (0 = male, 1 = female) per population
POPULATIONS = {"male": (0.0, 0.12), "female": (0.88, 1.0), "neutral": (0.0, 1.0)}


# ----------------------------------------------------------------------------- anny access


# ----------------------------------------------------------------------------- template


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


# ----------------------------------------------------------------------------- main build
def build_models(
    out_dir: Path,
    seed: int = 0,
    n_train: int = 600,
    n_test: int = 100,
    n_poses: int = 100,
    n_wide_poses: int = 100,
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
    say(f"posing the template body and {n_pose_bodies - 1} adults in {n_poses} + {n_wide_poses} wide poses each")
    # near rest, and across each joint's whole range (its own stream: the rest of the build
    # draws the same numbers whatever n_wide_poses is)
    poses = np.concatenate([sample_poses(n_poses, limits, rng),
                            sample_wide_poses(n_wide_poses, limits, np.random.default_rng([seed, 1]))])
    G, _ = skeleton.part_rotations(poses, hinge_axes)
    pairs = _joint_pairs(fpart, X[Ft].mean(axis=1), joints_t)
    n_fit = max(1, n_poses - max(n_poses // 4, 10))
    n_wide_fit = n_wide_poses - n_wide_poses // 4
    fit = np.r_[:n_fit, n_poses : n_poses + n_wide_fit]
    held = {"": np.r_[n_fit:n_poses], "wide_": np.r_[n_poses + n_wide_fit : len(poses)]}
    # pose bodies: the template itself (D = I, the thesis' single subject) and adults of the
    # three training populations; for each, Q = D⁻¹·Rᵀ·A (eq. 3.11 solved for Q), so that
    # the regressed Q transfers across shapes
    bodies = [(ref_phen[0], np.zeros(L))]
    for i in range(n_pose_bodies - 1):
        ph, lo = pop_samples[("male", "female", "neutral")[i % 3]]
        bodies.append((ph[i // 3], lo[i // 3]))
    Q_all, feats_all = [], []
    for b, (ph, lo) in enumerate(bodies):
        Vb, hb, _ = anny.rest(ph[None], lo[None])
        Vb, hb = Vb[0], hb[0]
        Yb = M @ Vb
        Db_inv = np.linalg.inv(scape.triangle_frames(Yb, Ft) @ frames_inv)  # (F, 3, 3)
        T = anny_bone_transforms(anny, np.broadcast_to(hb, (len(poses),) + hb.shape), G, part_joint_bone)
        Vp = anny.skin(np.broadcast_to(Vb, (len(poses),) + Vb.shape).copy(), T)
        Yp = np.stack([M @ v for v in Vp])
        # the part rotations are known here (we posed Anny with them): use them rather than
        # Procrustes estimates (App. C), so that training matches evaluation, where R comes
        # from the pose vector
        Rp = G[fit]
        A = np.einsum("bfij,fjk->bfik", scape.triangle_frames(Yp[fit], Ft), frames_inv)
        RtA = np.einsum("bfji,bfjk->bfik", Rp[:, fpart], A)
        Q_all.append(np.einsum("fij,bfjk->bfik", Db_inv, RtA).astype(np.float32))
        feats_all.append(skeleton.joint_features(Rp))
        if b == 0:
            Yp_ref = Yp
    Q_all = np.concatenate(Q_all).astype(np.float64)
    coef = scape.fit_pose_deformation(Q_all, np.concatenate(feats_all), pairs)
    # the fit's search body (BodyModel.search_model): eq. 3.16 on the rotation vectors, learned
    # from the near-rest poses alone (the previous releases' model, bit for bit)
    near = (np.arange(len(bodies))[:, None] * len(fit) + np.arange(n_fit)).ravel()  # each body's first n_fit
    rotvecs = np.tile(skeleton.joint_rotvecs(G[:n_fit]), (len(bodies), 1, 1))
    coef_search = scape.fit_pose_deformation(Q_all[near], rotvecs, pairs)
    del Q_all
    Yp = Yp_ref
    if scratch is not None:
        sets = {}
        for key, idx in held.items():
            sets.update({f"{key}poses": poses[idx], f"{key}vertices": Yp[idx].astype(np.float32),
                         f"{key}joints": np.stack([anny_joint_positions(heads0[part_joint_bone], G[i]) for i in idx])})
        np.savez_compressed(scratch / "heldout_poses.npz", rest=X.astype(np.float32), **sets)
    summary["poses_train"] = int(n_fit)
    summary["wide_poses_train"] = int(n_wide_fit)
    summary["pose_bodies"] = int(n_pose_bodies)
    summary["poses_heldout"] = int(n_poses - n_fit)
    summary["wide_poses_heldout"] = int(n_wide_poses - n_wide_fit)

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
        Q_coef_search=coef_search.astype(np.float32),
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


