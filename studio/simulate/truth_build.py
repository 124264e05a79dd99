"""Build the true bodies of the sample sequences from Anny (build time only).

This is the one module of :mod:`studio.simulate` that imports ``torch`` and ``anny`` (the
``model-build`` extra), and it does so inside :func:`build_truth`. The result is a compact
``body.npz`` per sequence that the numpy-only simulator replays:

``vertices_q`` (T, V, 3) int16
    world vertices in units of ``scale`` metres (0.1 mm), floor at z = 0, person facing the
    direction given by ``yaw`` (radians about +Z, 0 = facing +X).
``scale`` () float64, ``faces`` (F, 3) int32, ``parts`` (V,) uint8 index into
``part_names`` (coarse body part of the dominant skinning bone), ``bone_rotvecs`` (T, B, 3)
float32 world-aligned axis-angle deltas of the bones named in ``pose_bones`` (Anny's
``local-ref`` parameterisation), ``root_translation`` (T, 3), ``yaw`` (T,), ``phenotype_names``
/ ``phenotype_values``, ``pose_names`` (T,), ``rest_height`` (V,) float16 height of each vertex in the rest pose
as a fraction of stature (for clothing regions) and ``measurements`` (a JSON string).

``rest_q`` / ``tpose_q`` (V, 3) int16 (units of ``scale``)
    the person in Anny's own frame (Z up, facing -Y, left = +X, not placed on the floor) in
    the canonical postures the toolkit measures in: Anny's rest pose (the posture the body
    model's template and default pose were built from) and a T-pose by the toolkit's
    definition (:func:`straight_t_pose`: upper arms horizontal, elbows straight, hands rigid
    with the forearms). :mod:`studio.simulate.session` maps them into the model's topology
    and measures them with :func:`studio.body.measure_anny_body` (same-definition truth).

The people's phenotypes are drawn from Anny's population model (``anny.shape_distribution``,
adult ages, seeded). The truth is independent of the SCAPE model we fit (``studio.body`` is
never imported here): measurements come from Anny's ``anthropometry`` (rest pose) and from
convex-hull slices of the T-pose mesh (chest, hips). Anny's ``STATIC_POSES["t_pose"]`` keeps
the elbows bent about 43° (forearms forward); the measurement T-pose ``tpose_q`` straightens
them, which for the walk's woman lengthens the fingertip span by about 18 cm.
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np

from calibration.rotation import matrix_to_rotvec, rotvec_to_matrix
from rigs.atomic import atomic_open
from studio.body.anny_adapter import bone_part
from studio.body.skeleton import PART_NAMES
from studio.fit.props import seat_of
from studio.simulate.props import STOOL_RADIUS

__all__ = ["LAB_POSES", "SEQUENCES", "build_truth", "lab_pose", "straight_t_pose", "PART_NAMES", "QUANT_SCALE"]

log = logging.getLogger(__name__)

QUANT_SCALE = 1e-4  # metres per int16 step (covers ±3.27 m)



# --------------------------------------------------------------------------- poses
def _rot(axis: str, deg: float) -> np.ndarray:
    v = {"x": (1.0, 0, 0), "y": (0, 1.0, 0), "z": (0, 0, 1.0)}[axis]
    return np.asarray(v) * math.radians(deg)


def _compose(*rotvecs: np.ndarray) -> np.ndarray:
    """Axis-angle of ``R(r_0) @ R(r_1) @ ...``."""
    R = np.eye(3)
    for r in rotvecs:
        R = R @ rotvec_to_matrix(r)
    return matrix_to_rotvec(R)


# Anny rest pose: Z up, facing -Y, left = +X, arms ~47° below horizontal ("A-pose").
# Hip/arm flexion forward = negative rotation about X; knee flexion = positive about X;
# arm adduction of the left arm = +Y, of the right arm = -Y.
def _arms_down(deg: float) -> dict[str, np.ndarray]:
    return {"upperarm01.L": _rot("y", deg), "upperarm01.R": _rot("y", -deg)}


def walk_pose(phase: float) -> tuple[dict[str, np.ndarray], float]:
    """Bone deltas of a walking cycle at ``phase`` ∈ [0, 1) and the vertical bob (m)."""
    p = 2 * math.pi * phase
    hip_l = 22.0 * math.sin(p)
    hip_r = -hip_l
    knee_l = 8.0 + 45.0 * max(0.0, math.sin(p - 1.9)) ** 1.5
    knee_r = 8.0 + 45.0 * max(0.0, math.sin(p + math.pi - 1.9)) ** 1.5
    swing = 16.0 * math.sin(p)
    pose = {
        "upperleg01.L": _rot("x", -hip_l),
        "upperleg01.R": _rot("x", -hip_r),
        "lowerleg01.L": _rot("x", knee_l),
        "lowerleg01.R": _rot("x", knee_r),
        "upperarm01.L": _compose(_rot("x", swing), _rot("y", 32.0)),
        "upperarm01.R": _compose(_rot("x", -swing), _rot("y", -32.0)),
        "lowerarm01.L": _rot("x", -12.0),
        "lowerarm01.R": _rot("x", -12.0),
        "spine03": _rot("z", 4.0 * math.sin(p)),
    }
    bob = 0.02 * math.cos(2 * p)
    return pose, bob


STATIC_POSES: dict[str, dict[str, np.ndarray]] = {
    "a_pose": {},
    "t_pose": {"upperarm01.L": _rot("y", -47.0), "upperarm01.R": _rot("y", 47.0),
               "lowerarm01.L": _rot("y", -10.0), "lowerarm01.R": _rot("y", 10.0)},
    "arms_forward": {"upperarm01.L": _compose(_rot("x", -80.0), _rot("y", 40.0)),
                     "upperarm01.R": _compose(_rot("x", -80.0), _rot("y", -40.0))},
    "wave": {"upperarm01.L": _rot("y", -100.0), "lowerarm01.L": _rot("y", -30.0),
             **{k: v for k, v in _arms_down(30.0).items() if k.endswith(".R")}},
    "stride": {"upperleg01.L": _rot("x", -20.0), "upperleg01.R": _rot("x", 15.0),
               "lowerleg01.R": _rot("x", 20.0), **_arms_down(25.0)},
    "hands_on_hips": {"upperarm01.L": _rot("y", 5.0), "upperarm01.R": _rot("y", -5.0),
                      "lowerarm01.L": _compose(_rot("z", 70.0), _rot("y", 60.0)),
                      "lowerarm01.R": _compose(_rot("z", -70.0), _rot("y", -60.0))},
}

def _arm(side: str, *rotvecs) -> dict[str, np.ndarray]:
    return {f"upperarm01.{side}": _compose(*rotvecs)}


#: Postures a lab records, in Anny's bones (degrees; written from anatomy and checked by eye,
#: independently of the fitter's posture library ``studio.fit.library.FAMILIES``). ``seated``
#: sits on a stool (:mod:`studio.simulate.props`) that the renderer draws under the body.
LAB_POSES: dict[str, dict[str, np.ndarray]] = {
    "a_pose": {},
    "t_pose": STATIC_POSES["t_pose"],
    "arms_overhead": {"upperarm01.L": _rot("y", -120.0), "upperarm01.R": _rot("y", 120.0),
                      "lowerarm01.L": _rot("y", -10.0), "lowerarm01.R": _rot("y", 10.0)},
    "hands_on_hips": STATIC_POSES["hands_on_hips"],
    "arm_forward": {**_arms_down(30.0), **_arm("L", _rot("x", -80.0), _rot("y", 40.0))},
    "arms_crossed": {**_arm("L", _rot("x", -35.0), _rot("y", 35.0)), **_arm("R", _rot("x", -35.0), _rot("y", -35.0)),
                     "lowerarm01.L": _compose(_rot("z", -75.0), _rot("x", -20.0)),
                     "lowerarm01.R": _compose(_rot("z", 75.0), _rot("x", -20.0))},
    "wide_stance": {"upperleg01.L": _rot("y", -17.0), "upperleg01.R": _rot("y", 17.0), **_arms_down(22.0)},
    "half_squat": {"upperleg01.L": _rot("x", -65.0), "upperleg01.R": _rot("x", -65.0),
                   "lowerleg01.L": _rot("x", 95.0), "lowerleg01.R": _rot("x", 95.0), "spine03": _rot("x", 20.0),
                   **_arm("L", _rot("x", -70.0), _rot("y", 40.0)), **_arm("R", _rot("x", -70.0), _rot("y", -40.0))},
    "lunge": {"upperleg01.L": _rot("x", -60.0), "lowerleg01.L": _rot("x", 70.0), "upperleg01.R": _rot("x", 25.0),
              "lowerleg01.R": _rot("x", 55.0), **_arms_down(30.0)},
    "torso_twist": {"spine03": _rot("z", 28.0), "spine02": _rot("z", 10.0), **_arms_down(20.0)},
    "walk": walk_pose(0.25)[0],
    "run": {"upperleg01.L": _rot("x", -45.0), "lowerleg01.L": _rot("x", 30.0), "upperleg01.R": _rot("x", 28.0),
            "lowerleg01.R": _rot("x", 85.0), **_arm("L", _rot("x", 35.0), _rot("y", 35.0)),
            **_arm("R", _rot("x", -40.0), _rot("y", -35.0)),
            "lowerarm01.L": _rot("x", -70.0), "lowerarm01.R": _rot("x", -70.0)},
    "seated": {"upperleg01.L": _compose(_rot("x", -88.0), _rot("y", -6.0)),
               "upperleg01.R": _compose(_rot("x", -88.0), _rot("y", 6.0)),
               "lowerleg01.L": _rot("x", 85.0), "lowerleg01.R": _rot("x", 85.0),
               **_arm("L", _rot("x", -30.0), _rot("y", 30.0)), **_arm("R", _rot("x", -30.0), _rot("y", -30.0)),
               "lowerarm01.L": _rot("x", -50.0), "lowerarm01.R": _rot("x", -50.0)},
}

#: Families whose frames get a stool under the body.
SEATED_FAMILIES = ("seated",)


def lab_pose(family: str, rng, jitter_deg: float = 7.0) -> dict[str, np.ndarray]:
    """A jittered copy of ``LAB_POSES[family]`` (Gaussian ``jitter_deg`` on every bone's axis-angle)."""
    return {b: np.asarray(v) + rng.normal(0.0, math.radians(jitter_deg), 3) for b, v in LAB_POSES[family].items()}


#: Sequences built by :func:`build_truth`: name → recipe.
SEQUENCES = {
    "walk": {"kind": "walk", "frames": 24, "fps": 24.0, "speed": 1.2, "seed": 11,
             "gender": 1.0, "age_years": (25.0, 40.0)},
    "clothing_poses": {"kind": "static", "poses": list(STATIC_POSES), "seed": 12,
                       "gender": 0.0, "age_years": (25.0, 45.0)},
    # one woman striking 11 lab postures (the thesis' batches are 11 poses): the clothing batch
    "clothing_11": {"kind": "lab", "poses": ["a_pose", "t_pose", "arms_overhead", "hands_on_hips", "arm_forward",
                                             "wide_stance", "lunge", "torso_twist", "walk", "run", "arms_crossed"],
                    "seed": 13, "gender": 1.0, "age_years": (25.0, 45.0)},
}


# --------------------------------------------------------------------------- build
def _sample_phenotype(model, seed: int, gender: float, age_years: tuple[float, float]) -> dict:
    """Draw an adult's phenotype from Anny's population model (``anny.shape_distribution``:
    height/weight/muscle/proportions conditioned on age, calibrated to WHO data).

    ``gender`` is Anny's (0 male, 1 female); the morphological age is uniform in
    ``age_years``. Seeded through ``torch.manual_seed``.
    """
    import torch
    from anny.shape_distribution import SimpleShapeDistribution

    torch.manual_seed(seed)
    t = lambda v: torch.tensor(float(v), dtype=model.dtype)  # noqa: E731
    dist = SimpleShapeDistribution(
        model,
        morphological_age_distribution=torch.distributions.Uniform(t(age_years[0]), t(age_years[1])),
        gender_distribution=torch.distributions.Uniform(t(gender), t(gender + 1e-9)),
    )
    years, kwargs = dist.sample(1)
    phen = {k: float(v[0]) for k, v in kwargs.items() if k in model.phenotype_labels}
    phen["gender"] = float(gender)
    phen["morphological_age_years"] = float(years[0])
    return phen


def _posed(model, poses: list[dict[str, np.ndarray]], phenotype: dict) -> tuple[np.ndarray, np.ndarray]:
    import roma
    import torch

    n = len(poses)
    names = sorted({k for p in poses for k in p})
    params = {}
    for name in names:
        rv = np.stack([p.get(name, np.zeros(3)) for p in poses])
        T = torch.eye(4, dtype=model.dtype)[None].repeat(n, 1, 1)
        T[:, :3, :3] = roma.rotvec_to_rotmat(torch.as_tensor(rv, dtype=model.dtype))
        params[name] = T
    with torch.no_grad():
        out = model(pose_parameters=params or None,
                    phenotype_kwargs={k: torch.full((n,), float(v), dtype=model.dtype)
                                      for k, v in phenotype.items()})
    V = out["vertices"].cpu().numpy().astype(np.float64)
    rest = out["rest_vertices"][:1].cpu().numpy().astype(np.float64)[0]
    if V.shape[0] != n:
        V = np.broadcast_to(V, (n,) + V.shape[1:]).copy()
    return V, rest


def _shortest_arc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(3, 3) rotation turning direction ``a`` onto direction ``b`` about ``a × b``."""
    import cv2

    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    axis = np.cross(a, b)
    s = np.linalg.norm(axis)
    if s < 1e-12:
        return np.eye(3)
    return cv2.Rodrigues(axis / s * math.atan2(s, float(a @ b)))[0]


def _subtree(parents: list[int], root: int) -> list[int]:
    """Indices of bone ``root`` and all its descendants."""
    out = [root]
    for b, p in enumerate(parents):  # parents precede children in Anny's bone order
        if p in out and b not in out:
            out.append(b)
    return out


def straight_t_pose(model, phenotype: dict) -> tuple[np.ndarray, np.ndarray]:
    """Rest vertices (V, 3) and the toolkit's measurement T-pose (V, 3), Anny's frame.

    The T-pose is the definition of ``studio.body.measure.t_pose``: each upper arm turned by
    the shortest rotation that makes the shoulder → elbow direction horizontal (±X), each
    forearm turned so that elbow → wrist continues it (elbow straight), hands and fingers
    rigid with the forearm. Joints are Anny's rest bone heads (``upperarm01``,
    ``lowerarm01``, ``wrist``: the centres the body model's joint regressor was trained on)
    and the rest vertices are skinned with Anny's own linear blend skinning, as in the body
    model's pose training (``studio.body.build.anny_bone_transforms``).
    """
    import torch

    pk = {k: torch.full((1,), float(v), dtype=model.dtype) for k, v in phenotype.items()}
    with torch.no_grad():
        out = model(pose_parameters=None, phenotype_kwargs=pk)
    rest = out["rest_vertices"][0].cpu().numpy().astype(np.float64)
    heads = out["rest_bone_heads"][0].cpu().numpy().astype(np.float64)
    labels = list(model.bone_labels)
    parents = [int(p) for p in model.bone_parents]
    T = np.broadcast_to(np.eye(4), (len(labels), 4, 4)).copy()
    for side, sign in (("L", 1.0), ("R", -1.0)):
        iu, il, iw = (labels.index(f"{b}.{side}") for b in ("upperarm01", "lowerarm01", "wrist"))
        s, e, w = heads[iu], heads[il], heads[iw]
        Ru = _shortest_arc(e - s, np.array([sign, 0.0, 0.0]))
        Rl = Ru @ _shortest_arc(w - e, e - s)
        e_posed = s + Ru @ (e - s)
        lower = set(_subtree(parents, il))
        for b in _subtree(parents, iu):
            R, pivot, moved = (Rl, e, e_posed) if b in lower else (Ru, s, s)
            T[b, :3, :3] = R
            T[b, :3, 3] = moved - R @ pivot
    with torch.no_grad():
        V = model.get_skinned_vertices(torch.as_tensor(rest[None], dtype=model.dtype),
                                       torch.as_tensor(T[None], dtype=model.dtype))
    return rest, V[0].cpu().numpy().astype(np.float64)


def _slice_perimeter(V: np.ndarray, F: np.ndarray, z: float, keep) -> float:
    """Tape-measure perimeter at height z: the fit's own slice and hull (:mod:`studio.body.measure`),
    restricted to the points ``keep`` selects."""
    from studio.body.measure import convex_perimeter, slice_points

    P = slice_points(V, F, z)
    P = P[keep(P)]
    return convex_perimeter(P) if len(P) >= 3 else float("nan")


def _measurements(model, rest: np.ndarray, tpose: np.ndarray, F: np.ndarray) -> dict:
    import torch
    from anny import Anthropometry

    anth = Anthropometry(model)
    rv = torch.as_tensor(rest[None], dtype=model.dtype)
    m = {k: float(v[0]) for k, v in anth(rv).items()}
    V = tpose - [0.0, 0.0, tpose[:, 2].min()]
    stature = float(V[:, 2].max())
    # chest: widest torso girth between 70 % and 73 % of stature (below the armpits, which
    # sit near 76 %); hip: widest between 47 % and 54 %. Arms are out sideways in T-pose.
    torso = lambda P: np.abs(P[:, 0]) < 0.22  # noqa: E731
    chest = max(_slice_perimeter(V, F, f * stature, torso) for f in np.linspace(0.70, 0.73, 4))
    hips = max(_slice_perimeter(V, F, f * stature, torso) for f in np.linspace(0.47, 0.54, 8))
    return {
        "units": {"length": "m", "mass": "kg", "volume": "m^3"},
        "stature": stature,
        "mass": m["mass"],
        "volume": m["volume"],
        "bmi": m["bmi"],
        "waist_circumference": m["waist_circumference"],
        "chest_circumference": chest,
        "hip_circumference": hips,
        "source": "anny.Anthropometry (rest pose; density 980 kg/m^3) + convex-hull slices of the T-pose mesh",
    }


def _to_world(V: np.ndarray, yaw: float, offset: np.ndarray) -> np.ndarray:
    """Anny frame (facing -Y) → world: facing direction ``yaw`` about +Z (0 = +X)."""
    a = yaw + math.pi / 2  # Anny's front (-Y) maps to +X at yaw 0
    c, s = math.cos(a), math.sin(a)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return V @ Rz.T + offset


def build_truth(out_dir: str | Path, names: list[str] | None = None, progress=None,
                sequences: dict | None = None) -> list[Path]:
    """Build ``<out_dir>/<name>/body.npz`` for the named sequences (default all) of
    ``sequences`` (default :data:`SEQUENCES`).

    Needs the ``model-build`` extra (torch + anny); the first model construction takes
    about a minute. ``ANNY_CACHE_DIR`` is honoured by anny.
    """
    recipes = SEQUENCES if sequences is None else sequences
    names = list(recipes) if names is None else list(names)
    unknown = set(names) - set(recipes)
    if unknown:
        raise ValueError(f"unknown sequence(s) {sorted(unknown)}; known: {sorted(recipes)}")
    try:
        import anny  # noqa: F401
        import torch  # noqa: F401
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise RuntimeError(
            f"build-truth needs the model-build extra (torch + anny): {exc}"
        ) from None
    model = anny.Anny(topology="anny-noeyes-notongue")
    F = model.faces.cpu().numpy().astype(np.int32)
    labels = list(model.bone_labels)
    vb_idx = model.vertex_bone_indices.cpu().numpy()
    vb_w = model.vertex_bone_weights.cpu().numpy()
    dominant = vb_idx[np.arange(len(vb_idx)), np.argmax(vb_w, axis=1)]
    part_of_bone = np.array([PART_NAMES.index(bone_part(b)) for b in labels], dtype=np.uint8)
    parts = part_of_bone[dominant]
    written = []
    for name in names:
        recipe = recipes[name]
        rng = np.random.default_rng(recipe["seed"])
        phen = _sample_phenotype(model, recipe["seed"], recipe["gender"], recipe["age_years"])
        if recipe["kind"] == "walk":
            T = recipe["frames"]
            poses, bobs = zip(*(walk_pose(i / T) for i in range(T)))
            pose_names = [f"walk_{i / T:.3f}" for i in range(T)]
        elif recipe["kind"] == "lab":
            poses = [lab_pose(f, rng) for f in recipe["poses"]]
            bobs = [0.0] * len(poses)
            pose_names = list(recipe["poses"])
        else:
            poses = [STATIC_POSES[p] for p in recipe["poses"]]
            bobs = [0.0] * len(poses)
            pose_names = list(recipe["poses"])
        anny_phen = {k: v for k, v in phen.items() if k in model.phenotype_labels}
        V, rest = _posed(model, list(poses), anny_phen)
        tpose, _ = _posed(model, [STATIC_POSES["t_pose"]], anny_phen)
        meas = _measurements(model, rest, tpose[0], F)
        rest_m, tpose_m = straight_t_pose(model, anny_phen)
        meas["sex"] = "female" if phen["gender"] > 0.5 else "male"
        meas["age_years"] = phen["morphological_age_years"]
        n = len(poses)
        world = np.empty_like(V)
        props = np.full((n, 4), np.nan, dtype=np.float32)  # stool x, y, top, radius (NaN: none)
        yaw = np.zeros(n)
        root = np.zeros((n, 3))
        for i in range(n):
            Vi = V[i]
            if recipe["kind"] == "walk":
                yaw[i] = 0.0
                x = recipe["speed"] * (i - (n - 1) / 2) / recipe["fps"]
                root[i] = [x, 0.0, 0.0]
            else:
                yaw[i] = rng.uniform(-math.pi, math.pi)
                root[i] = [rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15), 0.0]
            Wi = _to_world(Vi, yaw[i], np.zeros(3))
            Wi = Wi + [root[i, 0], root[i, 1], -Wi[:, 2].min()]
            root[i, 2] = -V[i][:, 2].min()
            world[i] = Wi
            if pose_names[i] in SEATED_FAMILIES:
                props[i] = (*seat_of(Wi, parts, STOOL_RADIUS), STOOL_RADIUS)
        pose_bones = sorted({k for p in poses for k in p})
        rotvecs = np.array([[p.get(b, np.zeros(3)) for b in pose_bones] for p in poses],
                           dtype=np.float32).reshape(n, len(pose_bones), 3)
        q = np.round(world / QUANT_SCALE)
        canon = np.round(np.stack([rest_m, tpose_m]) / QUANT_SCALE)
        if max(np.abs(q).max(), np.abs(canon).max()) > 32767:
            raise RuntimeError(f"{name}: vertices exceed the int16 range of ±3.27 m")
        folder = Path(out_dir) / name
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / "body.npz"
        with atomic_open(path, "wb") as tmp:
            np.savez_compressed(
                tmp, vertices_q=q.astype(np.int16), scale=np.float64(QUANT_SCALE), faces=F,
                parts=parts, part_names=np.array(PART_NAMES), pose_bones=np.array(pose_bones),
                bone_rotvecs=rotvecs, root_translation=root.astype(np.float32),
                yaw=yaw.astype(np.float32), pose_names=np.array(pose_names),
                phenotype_names=np.array(list(phen)),
                phenotype_values=np.array(list(phen.values()), dtype=np.float64),
                bob=np.asarray(bobs, dtype=np.float32), props=props,
                measurements=np.array(json.dumps(meas)),
                rest_height=((rest[:, 2] - rest[:, 2].min()) / meas["stature"]).astype(np.float16),
                rest_q=canon[0].astype(np.int16), tpose_q=canon[1].astype(np.int16),
                source=np.array(f"anny {anny.__version__} topology anny-noeyes-notongue, pose "
                                "parameterisation local-ref (world-aligned deltas)"),
                )
        log.info("wrote %s (%d frames, %.1f kB)", path, n, path.stat().st_size / 1e3)
        written.append(path)
        if progress is not None:
            progress(name)
    return written
