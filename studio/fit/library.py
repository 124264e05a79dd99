"""A start that finds the limbs: a library of lab postures matched to the silhouettes (thesis §4.7.1).

The thesis starts its search from a discriminative pose estimate. Ours is a nearest-neighbour
search over a library of postures a lab records (:data:`FAMILIES`: A- and T-pose, arms
overhead, hands on hips, one arm forward, arms crossed, wide stance, half squat, lunge, torso
twist, walking and running strides, seated), each jittered and mirrored into
:func:`pose_library` — deterministic for its seed, a few kilobytes, rebuilt by calling it
(nothing is shipped that could go stale). The descriptor is the silhouettes themselves,
through the session's own cameras, so the library needs no retraining for a new rig:

1. every library posture is posed on the frame's starting shape (one batch of SCAPE meshes),
   stood on the floor at the visual hull's floor centroid, and turned through ``n_headings``;
2. a subsample of its vertices is projected into every view's silhouette pooled ``factor`` ×
   (:func:`library_scores`): the share of points outside the silhouette (precision) plus the
   share of silhouette cells no point reaches (recall), summed over the views — a few
   million projections, no rendering;
3. the best candidates are scored by the real silhouette cost (eq. 4.6) and handed to the
   annealed particle filter as its starts.

Posture angles are in the model's joint-angle pose (:mod:`studio.body.skeleton`): ball
joints as rotation vectors in world axes (x flexion, y abduction, z twist; a downward limb
moves forward for negative x, the torso bends forward for positive x), hinges as one angle
(positive flexes). They are written from anatomy, not fitted to any benchmark person.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from studio.body.skeleton import JOINT_KIND, PART_NAMES, POSE_SIZE, pose_slices
from studio.fit.quality import pool_any
from studio.threads import chunk_ranges, map_chunks

__all__ = ["FAMILIES", "SCALES", "family_pose", "library_match", "library_scores", "pose_library", "stand_on_floor"]

_L, _R = "_l", "_r"

#: Lab postures: part → angles (rad; 3 for ball joints, 1 for hinges), others at rest.
FAMILIES: dict[str, dict[str, tuple[float, ...]]] = {
    "a_pose": {},
    "arms_down": {"upperarm_l": (0.0, 0.65, 0.0), "upperarm_r": (0.0, -0.65, 0.0)},
    "t_pose": {"upperarm_l": (0.0, -0.8, 0.0), "upperarm_r": (0.0, 0.8, 0.0),
               "lowerarm_l": (-0.7,), "lowerarm_r": (-0.7,)},
    "arms_overhead": {"upperarm_l": (0.0, -2.25, 0.0), "upperarm_r": (0.0, 2.25, 0.0),
                      "lowerarm_l": (-0.4,), "lowerarm_r": (-0.4,)},
    "hands_on_hips": {"upperarm_l": (0.15, 0.1, 0.5), "upperarm_r": (0.15, -0.1, -0.5),
                      "lowerarm_l": (1.3,), "lowerarm_r": (1.3,)},
    "arm_forward": {"upperarm_l": (-1.45, 0.5, 0.0), "upperarm_r": (0.0, -0.6, 0.0), "lowerarm_l": (-0.5,)},
    # the upper arms forward, out and turned in, so the flexed forearms cross in front of the
    # chest: each hand ~55 mm past the midline (until this release (-0.35, ±0.7, ±0.4), elbows 1.5:
    # turned out, the hands out beside the shoulders, 0.55 m apart, not crossed; kept as an extra
    # "forearms up" family it took the crossed frames' starts, dev median 6.00 → 6.43 mm)
    "arms_crossed": {"upperarm_l": (-0.3, 0.3, -0.9), "upperarm_r": (-0.3, -0.3, 0.9),
                     "lowerarm_l": (1.1,), "lowerarm_r": (1.1,)},
    "wide_stance": {"upperleg_l": (0.0, -0.35, 0.0), "upperleg_r": (0.0, 0.35, 0.0),
                    "upperarm_l": (0.0, 0.4, 0.0), "upperarm_r": (0.0, -0.4, 0.0)},
    "half_squat": {"upperleg_l": (-1.1, -0.15, 0.0), "upperleg_r": (-1.1, 0.15, 0.0),
                   "lowerleg_l": (1.6,), "lowerleg_r": (1.6,), "foot_l": (-0.3,), "foot_r": (-0.3,),
                   "torso": (0.45, 0.0, 0.0), "upperarm_l": (-1.2, 0.5, 0.0), "upperarm_r": (-1.2, -0.5, 0.0)},
    "lunge": {"upperleg_l": (-1.1, 0.0, 0.0), "lowerleg_l": (1.2,), "upperleg_r": (0.45, 0.0, 0.0),
              "lowerleg_r": (1.1,), "upperarm_l": (0.0, 0.55, 0.0), "upperarm_r": (0.0, -0.55, 0.0)},
    "torso_twist": {"torso": (0.0, 0.0, 0.6), "upperarm_l": (0.0, 0.3, 0.0), "upperarm_r": (0.0, -0.3, 0.0)},
    "walk": {"upperleg_l": (-0.38, 0.0, 0.0), "upperleg_r": (0.3, 0.0, 0.0), "lowerleg_r": (0.35,),
             "upperarm_l": (0.3, 0.6, 0.0), "upperarm_r": (-0.3, -0.6, 0.0), "lowerarm_l": (-0.3,),
             "lowerarm_r": (0.1,)},
    "run": {"upperleg_l": (-0.8, 0.0, 0.0), "lowerleg_l": (0.6,), "upperleg_r": (0.45, 0.0, 0.0),
            "lowerleg_r": (1.5,), "upperarm_l": (0.6, 0.6, 0.0), "upperarm_r": (-0.7, -0.6, 0.0),
            "lowerarm_l": (0.9,), "lowerarm_r": (0.9,), "torso": (0.2, 0.0, 0.0)},
    "seated": {"upperleg_l": (-1.5, -0.1, 0.0), "upperleg_r": (-1.5, 0.1, 0.0), "lowerleg_l": (1.5,),
               "lowerleg_r": (1.5,), "upperarm_l": (-0.3, 0.6, 0.0), "upperarm_r": (-0.3, -0.6, 0.0),
               "lowerarm_l": (0.9,), "lowerarm_r": (0.9,)},
}

_SLICES = pose_slices()
_PART = {n: i for i, n in enumerate(PART_NAMES)}


def family_pose(model, family: str) -> np.ndarray:
    """(POSE_SIZE,) pose of ``family`` (root at the origin, heading 0), clipped to the limits."""
    try:
        angles = FAMILIES[family]
    except KeyError:
        raise ValueError(f"unknown posture family {family!r}; known: {', '.join(FAMILIES)}") from None
    pose = model.default_pose()
    for part, a in angles.items():
        pose[_SLICES[_PART[part]]] = a
    return model.clip_pose(pose)


def _mirror(pose: np.ndarray) -> np.ndarray:
    """The left-right mirror image of a pose (x → -x): swap the sides; ball joints keep their x
    component and negate y and z; hinges and the root translation's y are kept."""
    out = pose.copy()
    for p, name in enumerate(PART_NAMES):
        src = name[:-2] + (_R if name.endswith(_L) else _L) if name.endswith((_L, _R)) else name
        a = pose[_SLICES[_PART[src]]].copy()
        if JOINT_KIND[p] in ("ball", "root"):
            a[1:] = -a[1:]
        out[_SLICES[p]] = a
    out[0] = -pose[0]
    return out


def frontal_twin(model, shape: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """The pose of the body ``model(shape, pose)`` reflected through its own frontal plane (the
    vertical plane through its pelvis across its facing direction): facing the other way with
    the sides swapped (:func:`_mirror`), so each limb fills nearly the same place seen from the
    front or back — the front/back ambiguity of silhouettes that a search can settle on the
    wrong side of. The pelvis stays where it was."""
    from calibration.rotation import matrix_to_rotvec, rotvec_to_matrix

    pose = np.asarray(pose, dtype=np.float64)
    R = rotvec_to_matrix(pose[3:6])
    f = R @ [0.0, -1.0, 0.0]  # the facing direction, the plane's normal
    a = 2.0 * np.arctan2(f[1], f[0])
    M = np.diag([-1.0, 1.0, 1.0])
    # the reflection through the vertical plane of normal f: Rz(2θ)·M, θ the angle of f
    S = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]]) @ M
    twin = _mirror(pose)
    twin[:3] = pose[:3]
    twin[3:6] = matrix_to_rotvec(S @ R @ M)
    twin[:2] += (model.joints(shape, pose)[0] - model.joints(shape, twin)[0])[:2]
    return twin


def pose_library(model, *, variants: int = 6, jitter: float = 0.15, seed: int = 0) -> tuple[np.ndarray, list[str]]:
    """Library poses (N, POSE_SIZE) and their family names (N,): every family, its mirror
    image, and ``variants`` - 1 jittered copies of each (Gaussian ``jitter`` rad on every joint
    angle), clipped to the joint limits. Deterministic for ``seed``. A symmetric posture (an
    unjittered A-pose, squat, …) equals its mirror image: its twin is the same body with the same
    score and fills a second place of the shortlist. Kept: without the twins (dev people, 32
    frames) the shortlist held 6.6 distinct (family, stature) candidates instead of 4.9, the true
    family was first as often (24) and among the descriptor's first 4 once more (28 against 27),
    but the fits changed chaotically (a dev T-pose 8.2 → 21.4 mm, cost 0.63 → 3.15)."""
    rng = np.random.default_rng(seed)
    poses, names = [], []
    joints = np.arange(6, POSE_SIZE)
    for family in FAMILIES:
        base = family_pose(model, family)
        for k in range(variants):
            p = base.copy()
            if k:
                p[joints] += rng.normal(0.0, jitter, len(joints))
            for q in (p, _mirror(p)):
                poses.append(model.clip_pose(q))
                names.append(family)
    return np.asarray(poses), names


def _pinhole(cam, factor: int):
    """(K', R, t, (w', h')) of ``cam`` pooled ``factor`` × (no distortion: a coarse descriptor)."""
    K = cam.K.astype(np.float64).copy()
    K[:2] /= factor
    w, h = cam.size
    return K, cam.R.astype(np.float64), cam.t.astype(np.float64).ravel(), (-(-w // factor), -(-h // factor))


def library_scores(points: np.ndarray, cameras, masks, yaws: np.ndarray, xy, *, factor: int = 8,
                   shadows: dict | None = None) -> np.ndarray:
    """Descriptor distance (P, H) of every library body × heading to the observed silhouettes.

    ``points`` (P, M, 3): vertex subsamples of the library bodies, standing on the floor,
    their centroid over the origin; ``yaws`` (H,) headings (rad, about +z through the origin)
    before the move to the floor point ``xy`` (the visual hull's centroid). Per view, with the
    mask pooled ``factor`` ×: the share of points landing outside the silhouette plus the
    share of silhouette cells no point lands in; summed over the views (0 = perfect,
    2 × views = nothing in common). The loops are compiled (:func:`_scores`): 10,080
    candidates × 1,200 points × 4 views take ~0.75 s CPU (400 points: ~0.3 s; ~6 s in NumPy).

    ``shadows`` (``{"lights", "masks", "ground", "weight"}``: known lights, the observed shadow
    per camera, the floor plane (None: z = 0), the shadow term's weight) adds the shadow camera
    of §5.5 as more views, one per camera and light: the points' shadows on the floor (eq. 5.2)
    seen by the camera (eq. 5.3), inside when they land on the shadow or on the person (who
    hides part of it, §5.6), the shadow's cells to reach; each weighs ``weight / cameras`` as
    in eq. 5.7 (the views of the one shadow camera averaged).
    """
    from studio.render.lights import DirectionalLight, PointLight
    from studio.render.shadow import _plane

    masks = [np.asarray(m, bool) for m in masks]
    # views: (camera, cells inside, cells to reach, light kind, light, weight)
    views = [(k, m, m, 0.0, np.zeros(3), 1.0) for k, m in enumerate(masks)]
    plane = np.zeros(4)
    if shadows:
        plane = np.append(*_plane(shadows.get("ground")))
        weight = float(shadows.get("weight", 1.0)) / len(masks)
        for light in shadows["lights"]:
            if isinstance(light, PointLight):
                row, kind = light.position, 1.0
            elif isinstance(light, DirectionalLight):
                row, kind = light.direction, 2.0
                if float(plane[:3] @ light.direction) >= -1e-12:
                    raise ValueError("shadows: a directional light shining upwards casts no floor shadow")
            else:
                raise TypeError(f"light: expected PointLight or DirectionalLight, got {type(light).__name__}")
            views += [(k, np.asarray(sm, bool) | m, np.asarray(sm, bool), kind, row, weight)
                      for k, (m, sm) in enumerate(zip(masks, shadows["masks"], strict=True))]
    pins = [_pinhole(cameras[k], factor) for k, *_ in views]
    inside = [pool_any(v[1], factor) for v in views]
    wanted = [pool_any(v[2], factor) for v in views]
    sizes = np.array([size for *_, size in pins], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(sizes[:, 0] * sizes[:, 1])])
    lights = np.stack([np.append(v[4], v[3]) for v in views])
    points = np.ascontiguousarray(points, dtype=np.float64)
    rest = (np.asarray(yaws, dtype=np.float64), np.asarray(xy, dtype=np.float64), np.stack([p[0] for p in pins]),
            np.stack([p[1] for p in pins]), np.stack([p[2] for p in pins]), sizes, offsets,
            np.concatenate([c.ravel() for c in inside]), np.concatenate([c.ravel() for c in wanted]),
            np.array([max(int(c.sum()), 1) for c in wanted], dtype=np.float64), lights, plane,
            np.array([v[5] for v in views], dtype=np.float64))
    # one range of bodies per thread (chunk_ranges balances a single chunk over them): each body's scores are its own
    parts = map_chunks(lambda r: _scores(points[r[0] : r[1]], *rest), chunk_ranges(len(points), len(points)))
    return np.concatenate(parts)


@njit(cache=True, nogil=True)
def _scores(points, yaws, xy, Ks, Rs, ts, sizes, offsets, inside, wanted, n_cells, lights, plane,
            weights):  # pragma: no cover - compiled
    """The loops of :func:`library_scores` over bodies × headings, points and views; a cell
    is counted once per candidate by stamping it with the candidate's number. View k sees the
    points themselves (``lights[k, 3]`` 0), or their shadows on ``plane`` [n, d] (n·X = d)
    through a point light at ``lights[k, :3]`` (1) or a directional light shining along it (2)."""
    P, M, _ = points.shape
    H = len(yaws)
    C = len(Ks)
    nx, ny, nz, d = plane[0], plane[1], plane[2], plane[3]
    score = np.zeros((P, H))
    stamp = np.full(len(inside), -1, dtype=np.int64)
    outside = np.zeros(C)
    reached = np.zeros(C)
    for p in range(P):
        for h in range(H):
            c, s = np.cos(yaws[h]), np.sin(yaws[h])
            cand = p * H + h
            outside[:] = 0.0
            reached[:] = 0.0
            for m in range(M):
                x0, y0, z0 = points[p, m, 0], points[p, m, 1], points[p, m, 2]
                px, py = c * x0 - s * y0 + xy[0], s * x0 + c * y0 + xy[1]
                for k in range(C):
                    wx, wy, wz = px, py, z0
                    kind = lights[k, 3]
                    if kind > 0.5:  # the point's shadow on the floor (eq. 5.2)
                        lx, ly, lz = lights[k, 0], lights[k, 1], lights[k, 2]
                        if kind < 1.5:
                            rx, ry, rz = wx - lx, wy - ly, wz - lz
                            den = rx * nx + ry * ny + rz * nz
                            hl = lx * nx + ly * ny + lz * nz - d
                            if not (den < -1e-12 and wx * nx + wy * ny + wz * nz - d < hl):
                                outside[k] += 1
                                continue
                            lam = -hl / den
                            wx, wy, wz = lx + lam * rx, ly + lam * ry, lz + lam * rz
                        else:
                            t = (wx * nx + wy * ny + wz * nz - d) / (lx * nx + ly * ny + lz * nz)
                            wx, wy, wz = wx - t * lx, wy - t * ly, wz - t * lz
                    R, t, K = Rs[k], ts[k], Ks[k]
                    cx = R[0, 0] * wx + R[0, 1] * wy + R[0, 2] * wz + t[0]
                    cy = R[1, 0] * wx + R[1, 1] * wy + R[1, 2] * wz + t[1]
                    cz = R[2, 0] * wx + R[2, 1] * wy + R[2, 2] * wz + t[2]
                    if cz <= 0:
                        outside[k] += 1
                        continue
                    u = np.floor((K[0, 0] * cx + K[0, 1] * cy) / cz + K[0, 2])
                    v = np.floor(K[1, 1] * cy / cz + K[1, 2])
                    if u < 0 or u >= sizes[k, 0] or v < 0 or v >= sizes[k, 1]:
                        outside[k] += 1
                        continue
                    cell = offsets[k] + int(v) * sizes[k, 0] + int(u)
                    if not inside[cell]:
                        outside[k] += 1
                    elif wanted[cell] and stamp[cell] != cand:
                        stamp[cell] = cand
                        reached[k] += 1
            for k in range(C):
                score[p, h] += weights[k] * (outside[k] / M + 1.0 - reached[k] / n_cells[k])
    return score


#: Statures searched with the library, as multiples of the model's mean stature (the hull's
#: top is no stature for a seated, squatting or arms-overhead person).
SCALES = (0.88, 0.94, 1.0, 1.06, 1.12)


#: Library bodies by (gender, shape, points): every frame fitted from its silhouettes with the
#: same starting shape poses the same 168 meshes (~1 s), so a worker poses them once.
_BODIES: dict = {}


def _library_bodies(model, shape, library, n_points: int):
    """(poses, names, points (P, M, 3) standing on the floor with their centroid over the
    origin, the pelvis seen from the centroid (P, 2), the a-pose stature) of a library."""
    poses, names = library
    V = model.vertices_batch(np.repeat(shape[None], len(poses), axis=0), poses)
    V[:, :, 2] -= V[:, :, 2].min(axis=1, keepdims=True)  # every posture on the floor
    stature = float(V[names.index("a_pose"), :, 2].max()) if "a_pose" in names else float(V[:, :, 2].max())
    pts = V[:, np.linspace(0, V.shape[1] - 1, n_points).astype(int)]
    pelvis = -pts[:, :, :2].mean(axis=1)  # the pelvis (origin) seen from the body's centroid
    pts[:, :, :2] += pelvis[:, None]  # centroid over the origin, like the hull's centroid over xy
    return poses, names, pts, pelvis, stature


def library_match(model, cameras, masks, xy, *, shape=None, scales=SCALES, n_headings: int = 12,
                  shortlist: int = 12, n_points: int = 1200, factor: int = 8,
                  library: tuple[np.ndarray, list[str]] | None = None, shadows: dict | None = None) -> dict:
    """The library postures best matching the silhouettes (:func:`library_scores`), searched
    over posture × stature scale × heading with the bodies of ``shape`` (default: the mean).

    ``xy`` the floor point (2,) the bodies' centroids stand over, or several (F, 2) searched too
    (one view leaves the depth along its rays open).

    Returns ``{"poses": (shortlist, POSE_SIZE) with the heading and the floor point set (root
    height 0: see :func:`stand_on_floor`), "families", "scales", "scores", "statures", "stature",
    "xy"}`` best first; ``statures`` (m) are each candidate's scale × the library body's stature,
    ``stature`` the best candidate's, ``xy`` its floor point.

    ``n_points`` vertices per body: with 400 the "silhouette cells no point reaches" share was
    mostly sampling noise. Measured on the *dev* people of ``benchmarks/pose_accuracy.py``
    (16 frames, 13 families; never the held-out ones): the true family first 50 % → 75 % of
    frames, among the 4 starts 62 → 81 %, in the shortlist 75 → 94 % (2,400 points: no better;
    ``factor`` 6 or 12: worse or no better). ``shadows``: the shadow camera's views
    (:func:`library_scores`), for a frame fitted with its shadow.

    The shortlist is the plain best ``shortlist``: a symmetric posture and its mirror image are
    the same body with the same score, so pairs fill it (on a dev ``arm_forward`` frame that
    family ranked 21st of the candidates, 5th of the families). A shortlist of at most 3 per
    family without the twins brought it in, but the silhouette cost ranked it last (19.3 against
    10.7-15.5: a forward arm a few cm off costs more than a missing one), no start changed, and
    the batch tests' small-budget fits got worse starts; the per-limb search's arm states
    (:func:`studio.fit.search._arm_states`) lift such an arm instead.
    """
    from calibration.rotation import matrix_to_rotvec, rotvec_to_matrix

    shape = model.mean_shape() if shape is None else np.asarray(shape, dtype=np.float64)
    if library is not None:
        poses, names, pts, pelvis, stature = _library_bodies(model, shape, library, n_points)
    else:
        # by the model object (a model and its search body share a gender), held in the entry so
        # that its id cannot be reused while cached
        key = (id(model), shape.tobytes(), n_points)
        if key not in _BODIES:
            if len(_BODIES) > 4:
                _BODIES.clear()
            _BODIES[key] = (model, _library_bodies(model, shape, pose_library(model), n_points))
        poses, names, pts, pelvis, stature = _BODIES[key][1]
    scales = np.asarray(scales, dtype=np.float64)
    pts = (pts[:, None] * scales[None, :, None, None]).reshape(-1, n_points, 3)  # (P*S, M, 3)
    yaws = np.linspace(-np.pi, np.pi, n_headings, endpoint=False)
    xys = np.atleast_2d(np.asarray(xy, dtype=np.float64))
    scores = np.stack([library_scores(pts, cameras, masks, yaws, q, factor=factor, shadows=shadows)
                       for q in xys])  # (floor points, P*S, H)
    order = np.argsort(scores, axis=None, kind="stable")[:shortlist]
    x_idx, ps_idx, h_idx = np.unravel_index(order, scores.shape)
    p_idx, s_idx = np.divmod(ps_idx, len(scales))
    out = []
    for q, p, s, h in zip(x_idx, p_idx, s_idx, h_idx, strict=True):
        pose = poses[p].copy()
        Rz = rotvec_to_matrix(np.array([0.0, 0.0, yaws[h]]))
        pose[3:6] = matrix_to_rotvec(Rz @ rotvec_to_matrix(pose[3:6]))  # turns about the pelvis
        pose[:2] = xys[q] + (Rz[:2, :2] @ pelvis[p]) * scales[s]
        out.append(pose)
    return {"poses": np.asarray(out), "families": [names[p] for p in p_idx], "scales": scales[s_idx].tolist(),
            "scores": scores[x_idx, ps_idx, h_idx].tolist(), "statures": (scales[s_idx] * stature).tolist(),
            "stature": float(scales[s_idx[0]] * stature),
            "xy": xys[x_idx[0]].copy()}


def stand_on_floor(model, shape, poses: np.ndarray) -> np.ndarray:
    """``poses`` (N, POSE_SIZE) with the root height set so that the body of ``shape`` touches z = 0."""
    poses = np.array(poses, dtype=np.float64)
    V = model.vertices_batch(np.repeat(np.asarray(shape, dtype=np.float64)[None], len(poses), axis=0), poses)
    poses[:, 2] -= V[:, :, 2].min(axis=1)
    return poses
