"""The one adapter between Anny (build time: torch + anny) and this toolkit's body model.

Everything that reads Anny for the model build (:mod:`studio.body.build`) and for the
simulator's truth bodies (:mod:`studio.simulate.truth_build`) goes through here: which Anny
bone belongs to which of the thesis' 15 parts (:func:`bone_part`, the model's definition),
which bone's head is a part's joint centre (``PART_FIRST_BONE``), Anny's rest/skinning access
(``_Anny``), and posed Anny bodies in the model's frame (:func:`anny_truth_meshes`). The
toolkit at run time never imports this module.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from studio.body import skeleton
from studio.body.skeleton import PART_NAMES, PART_PARENTS

__all__ = ["PART_FIRST_BONE", "anny_bone_transforms", "anny_joint_positions", "anny_truth_meshes", "bone_part"]

log = logging.getLogger(__name__)


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


def anny_joint_positions(rest_joints: np.ndarray, G: np.ndarray) -> np.ndarray:
    """Posed joint centres (15, 3) of Anny's posing (pivots at rest joints, root fixed)."""
    posed = np.zeros_like(rest_joints)
    for p, parent in enumerate(PART_PARENTS):
        posed[p] = rest_joints[p] if parent < 0 else posed[parent] + G[parent] @ (rest_joints[p] - rest_joints[parent])
    return posed


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
