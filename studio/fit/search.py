"""The search's pieces of a single-frame fit (thesis §4.7): the pose's index groups (torso
outward, §4.7.4; limb by limb for Deutscher's partitioned annealed particle filter), the
partitioned search itself, the particle spread and the heading of a pose."""

from __future__ import annotations

import numpy as np

from studio.body.skeleton import JOINT_KIND, POSE_SIZE, pose_slices
from studio.optimize import annealed_particle_filter

__all__ = ["_arm_states", "_heading", "_part_groups", "_partitioned_search", "_partitions", "_pose_sigma"]


def _part_groups() -> list[list[int]]:
    """Pose indices grouped from the torso outward (thesis §4.7.4)."""
    sl = pose_slices()
    idx = {p: list(range(sl[p].start, sl[p].stop)) for p in range(1, 15)}
    names = ("pelvis", "torso", "head", "upperarm_l", "lowerarm_l", "hand_l", "upperarm_r", "lowerarm_r",
             "hand_r", "upperleg_l", "lowerleg_l", "foot_l", "upperleg_r", "lowerleg_r", "foot_r")
    n = {name: i for i, name in enumerate(names)}
    return [
        idx[n["torso"]] + idx[n["upperarm_l"]] + idx[n["upperarm_r"]] + idx[n["upperleg_l"]] + idx[n["upperleg_r"]],
        idx[n["lowerarm_l"]] + idx[n["lowerarm_r"]] + idx[n["lowerleg_l"]] + idx[n["lowerleg_r"]],
        idx[n["hand_l"]] + idx[n["hand_r"]] + idx[n["foot_l"]] + idx[n["foot_r"]] + idx[n["head"]],
    ]


def _partitions() -> list[list[int]]:
    """Pose index groups of the partitioned particle filter: root + spine + head, then each
    arm and each leg (one limb at a time: 5 angles, so 40 particles cover it)."""
    sl = pose_slices()

    def idx(*parts):
        return [i for p in parts for i in range(sl[p].start, sl[p].stop)]

    return [list(range(3)) + idx(0, 1, 2), idx(3, 4, 5), idx(6, 7, 8), idx(9, 10, 11), idx(12, 13, 14)]


def _partitioned_search(cost, x, sigma, lo, hi, groups, *, n_particles, n_layers, rng,
                        extra=None) -> tuple[np.ndarray, float]:
    """Deutscher's partitioned annealed particle filter: re-search each index group of ``x``
    in turn with the others held; a group's answer is kept only if it lowers ``cost``
    ((N, D) → (N,)). ``extra``: group number → (K, len(group)) other states of that group, searched
    from (the mixture of eq. 4.12 over them) after the search around ``x``'s own values, the
    lower cost kept: a small particle budget still refines ``x`` as before. Returns the
    parameters and their cost."""
    x = np.asarray(x, dtype=np.float64).copy()
    current = float(cost(x[None])[0])
    for g, idx in enumerate(groups):
        idx = np.asarray(idx)

        def sub(Z, idx=idx, base=x.copy()):
            X = np.repeat(base[None], len(Z), axis=0)
            X[:, idx] = Z
            return cost(X)

        for start in (x[idx], *((extra[g],) if extra and g in extra else ())):
            r = annealed_particle_filter(sub, start, sigma[idx], bounds=(lo[idx], hi[idx]), n_particles=n_particles,
                                         n_layers=n_layers, vectorized=True, seed=rng)
            if r.cost < current:
                x[idx], current = r.x, float(r.cost)
    return x, current


def _arm_states(model, groups) -> dict[int, np.ndarray]:
    """Group number → the distinct states (K, len(group)) of the arm groups among ``groups``
    in the posture library's families and their mirror images (:data:`studio.fit.library.FAMILIES`):
    starts of the per-limb search, so an arm the whole-body search left hanging can be lifted
    forward or crossed (the library's arm configurations, not just jitter around the answer)."""
    from studio.fit.library import FAMILIES, _mirror, family_pose

    sl = pose_slices()
    arms = {tuple(range(sl[a].start, sl[c].stop)) for a, c in ((3, 5), (6, 8))}
    poses = [q for f in FAMILIES for q in (family_pose(model, f), _mirror(family_pose(model, f)))]
    out = {}
    for g, idx in enumerate(groups):
        if tuple(idx) in arms:
            out[g] = np.unique(np.round(np.stack([q[idx] for q in poses]), 6), axis=0)
    return out


def _heading(pose: np.ndarray) -> float:
    """Root yaw (rad) of ``pose``: the angle about z that turns the template's facing
    direction (-y) into the body's (the root rotation's tilt ignored)."""
    from calibration.rotation import rotvec_to_matrix

    f = rotvec_to_matrix(np.asarray(pose[3:6], dtype=np.float64)) @ [0.0, -1.0, 0.0]
    return float(np.arctan2(f[1], f[0]) + np.pi / 2)


def _pose_sigma(scale: float) -> np.ndarray:
    """Initial particle spread per pose entry (translation m, angles rad) times ``scale``."""
    s = np.empty(POSE_SIZE)
    s[:2], s[2] = 0.06, 0.02
    s[3:5], s[5] = 0.06, 0.25
    for p, kind in enumerate(JOINT_KIND):
        if kind != "root":
            s[pose_slices()[p]] = 0.25
    return s * scale
