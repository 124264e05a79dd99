"""Initial pose from the silhouettes alone (thesis §4.7.1–4.7.2).

The floor position of the body is the centroid of a coarse visual hull: points of a
vertical grid of columns that project inside the silhouette in every view that sees them
(at least two). The heading is then chosen by a coarse search over yaw in the default
posture, scored with the silhouette cost at a coarse pyramid level; the best few headings
(the front/back ambiguity of silhouettes makes the opposite heading a likely rival) are
handed to the particle filter as a mixture of starts.
"""

from __future__ import annotations

import numpy as np

from studio.fit.errors import FitError

__all__ = ["STATURE_STEPS", "costs_at_statures", "feet_on_floor", "hull_centroid", "hull_height", "initial_poses", "standing_pose",
           "stature_search", "stature_shape", "stride_poses"]

#: Relative stature changes searched around the library's stature with its best posture
#: (:func:`stature_search`): the library's scale grid steps 6 %.
STATURE_STEPS = (-0.06, -0.045, -0.03, -0.015, 0.0, 0.015, 0.03, 0.045, 0.06)


def image_pixels(cam, shape: tuple[int, int], pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(ok, u, v)``: which points (N, 3) ``cam`` sees inside an image of ``shape`` (H, W), in front
    of it, and their nearest pixel (column, row; valid where ``ok``).

    Points whose ideal (undistorted) projection leaves the image are rejected too, so the
    fold-back of the lens model far outside the field of view cannot produce false hits.
    """
    h, w = shape
    uv, _, front = cam.project_points(pts)
    ideal, _, _ = cam.project_points(pts, distort=False)
    ok = front & np.isfinite(uv).all(axis=1) & np.isfinite(ideal).all(axis=1)
    m = 0.25 * max(w, h)
    ok &= (ideal[:, 0] > -m) & (ideal[:, 0] < w + m) & (ideal[:, 1] > -m) & (ideal[:, 1] < h + m)
    uv = np.where(ok[:, None], uv, -1.0)
    u = np.rint(uv[:, 0]).astype(np.int64)
    v = np.rint(uv[:, 1]).astype(np.int64)
    ok &= (u >= 0) & (u < w) & (v >= 0) & (v < h)
    return ok, u, v


def _in_mask(cam, mask: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(N,) bool: points :func:`image_pixels` sees that project onto ``mask``."""
    ok, u, v = image_pixels(cam, mask.shape, pts)
    hit = np.zeros(len(pts), dtype=bool)
    hit[ok] = mask[v[ok], u[ok]]
    return hit


def hull_centroid(cameras, masks, *, extent: float = 3.5, step: float = 0.04,
                  heights=(0.15, 0.5, 0.9, 1.2, 1.5)) -> np.ndarray:
    """Floor (x, y) of the visual-hull centroid (2,) from full-resolution ``masks`` (list, camera order).

    Only points seen inside the image of every camera count (the person must be in every view).
    Raises :class:`FitError` when no grid point falls inside all silhouettes. One camera has no
    hull: the floor point under the silhouette's lowest pixels (:func:`feet_on_floor`).
    """
    if len(cameras) == 1:
        return feet_on_floor(cameras[0], masks[0])
    g = np.arange(-extent, extent + 1e-9, step)
    X, Y = np.meshgrid(g, g, indexing="ij")
    pts = np.stack([np.repeat(X.ravel()[:, None], len(heights), 1).ravel(),
                    np.repeat(Y.ravel()[:, None], len(heights), 1).ravel(),
                    np.tile(np.asarray(heights, dtype=float), X.size)], axis=1)
    inside = np.ones(len(pts), dtype=bool)
    for cam, mask in zip(cameras, masks, strict=True):
        inside &= _in_mask(cam, mask, pts)
    if not inside.any():
        raise FitError("no point of the floor grid lies inside every silhouette: is the person in view of all cameras?")
    return pts[inside, :2].mean(axis=0)


def feet_on_floor(camera, mask: np.ndarray, *, share: float = 0.03, sole: float = 0.04) -> np.ndarray:
    """Floor (x, y) (2,) under the feet seen by one camera: the pixel at the mean row of the
    silhouette's lowest rows (``share`` of its height) and its mean column (the body's centre:
    the lowest pixels of a stride are one foot's, ~0.3 m from the pelvis) back-projected onto the
    plane ``z = sole`` (a foot's centre height). The monocular start: a camera looking down sees
    the feet lowest in the image."""
    ys, xs = np.nonzero(np.asarray(mask, bool))
    if len(ys) == 0:
        raise FitError(f"camera {camera.name}: empty silhouette, no feet to put on the floor")
    low = ys >= ys.max() - max(1.0, share * (ys.max() - ys.min()))
    origin, d = camera.pixel_rays(np.array([[xs.mean(), ys[low].mean()]]))
    if d[0, 2] >= -1e-6:
        raise FitError(f"camera {camera.name}: the feet's ray does not meet the floor (camera looking up?)")
    return (origin[0] + d[0] * (sole - origin[0, 2]) / d[0, 2])[:2]


def standing_pose(model) -> np.ndarray:
    """The default pose with the arms lowered along the body (a typical standing/walking start)."""
    from studio.body.skeleton import pose_slices

    sl = pose_slices()
    pose = model.default_pose()
    pose[sl[3]] = [0.0, 0.65, 0.0]  # left upper arm down
    pose[sl[6]] = [0.0, -0.65, 0.0]  # right upper arm down
    return model.clip_pose(pose)


def stride_poses(model) -> np.ndarray:
    """Starting postures (3, POSE_SIZE): standing (:func:`standing_pose`) and a walking stride
    with either leg forward (hips ∓0.35 rad, the back knee bent 0.3 rad)."""
    from studio.body.skeleton import PART_NAMES, pose_slices

    sl = pose_slices()
    idx = {n: sl[i] for i, n in enumerate(PART_NAMES)}
    base = standing_pose(model)
    out = [base]
    for front, back in (("l", "r"), ("r", "l")):
        p = base.copy()
        p[idx[f"upperleg_{front}"].start] = -0.35  # flexion (forward) is negative about x
        p[idx[f"upperleg_{back}"].start] = 0.3
        p[idx[f"lowerleg_{back}"]] = 0.3
        out.append(model.clip_pose(p))
    return np.stack(out)


def initial_poses(objective, cameras, masks, level: int, *, n_headings: int = 12, keep: int | None = 4,
                  shape=None, xy=None) -> tuple[np.ndarray, np.ndarray]:
    """Starts (keep, D) for the particle filter and their costs (keep,), best first.

    Every heading of ``n_headings`` is scored in each posture of :func:`stride_poses` (a
    person in mid-stride seen in the standing posture looks best side-on, so the standing
    posture alone picks the wrong heading); the best posture per heading is kept and the
    ``keep`` best headings are returned (``None``: every heading). ``xy``: the floor position
    (default: :func:`hull_centroid` of the masks).
    """
    xy = hull_centroid(cameras, masks) if xy is None else xy
    postures = stride_poses(objective.model)
    postures[:, :2] = xy
    yaws = np.linspace(-np.pi, np.pi, n_headings, endpoint=False)
    base = objective.base_shape if shape is None else shape
    X = np.stack([objective.pack(base, p) for p in postures])  # (P, D)
    X = np.repeat(X[None], n_headings, axis=0)  # (H, P, D)
    X[:, :, 5] = yaws[:, None]
    X = X.reshape(-1, X.shape[-1])
    costs = objective(X, level).reshape(n_headings, len(postures))
    best = np.argmin(costs, axis=1)
    Xh = X.reshape(n_headings, len(postures), -1)[np.arange(n_headings), best]
    ch = costs[np.arange(n_headings), best]
    order = np.argsort(ch)[:keep]
    return Xh[order], ch[order]


def hull_height(cameras, masks, xy, *, radius: float = 0.35, step: float = 0.02, dz: float = 0.01) -> float:
    """Height (m) of the top of the visual hull within ``radius`` of the floor point ``xy``.

    A first guess of the stature for the shape initialisation (the hull of a few views is
    slightly larger than the body; the posture of a walk makes the body slightly shorter).
    """
    g = np.arange(-radius, radius + 1e-9, step)
    zs = np.arange(0.5, 2.4, dz)
    X, Y, Z = np.meshgrid(xy[0] + g, xy[1] + g, zs, indexing="ij")
    pts = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    inside = np.ones(len(pts), dtype=bool)
    for cam, mask in zip(cameras, masks, strict=True):
        inside &= _in_mask(cam, mask, pts)
    if not inside.any():
        raise FitError("the visual hull above the body's floor position is empty: cannot estimate the height")
    return float(pts[inside, 2].max())



def stature_shape(model, stature: float) -> np.ndarray:
    """Shape (n_shape,) of ``stature`` (m): the conditional mean given the stature
    (:func:`studio.body.shape_from_measurements`, §4.7.2-style), clipped to ±2.5 σ."""
    from studio.body.inverse import shape_from_measurements

    sig = np.sqrt(model.eigenvalues)
    return np.clip(shape_from_measurements(model, {"stature": float(stature)}, refine=0), -2.5 * sig, 2.5 * sig)


def stature_search(model, objective_of, pose: np.ndarray, stature: float, level: int,
                   steps=STATURE_STEPS) -> tuple[float, np.ndarray]:
    """The stature (m) and its shape (:func:`stature_shape`) that best explain the silhouettes
    with ``pose`` (stood on the floor for each stature) at pyramid ``level``, searched over
    ``stature × (1 + steps)``. The library's stature comes in 6 % steps, and a wrong one pulls
    the posture after it: a seated dev body started 7 cm short sat with its knees too straight
    and its shape stayed short (−10 cm), while the fit's own cost, with the true posture, is
    lowest at the true stature (±5 cm: 1.5–2.5× the cost; dev people only).
    ``objective_of(shape)``: the pose objective (eq. 4.6, no free shape coefficient) of a shape."""
    statures = stature * (1.0 + np.asarray(steps, dtype=np.float64))
    cost, _ = costs_at_statures(model, objective_of, np.repeat(np.asarray(pose)[None], len(statures), axis=0),
                                statures, level)
    best = float(statures[int(np.argmin(cost))])
    return best, stature_shape(model, best)


def costs_at_statures(model, objective_of, poses: np.ndarray, statures: np.ndarray, level: int) -> tuple[np.ndarray, int]:
    """(cost (N,) of each pose at pyramid ``level`` on the shape of its own stature
    (:func:`stature_shape`), stood on the floor; the evaluations spent). ``objective_of(shape)``:
    the pose objective of a shape, built once per distinct stature."""
    from studio.fit.library import stand_on_floor

    statures = np.asarray(statures, dtype=np.float64)
    cost, n = np.empty(len(poses)), 0
    for h in np.unique(statures):
        sel = statures == h
        shape = stature_shape(model, h)
        obj = objective_of(shape)
        cost[sel] = obj(np.stack([obj.pack(shape, p) for p in stand_on_floor(model, shape, poses[sel])]), level)
        n += obj.n_evaluations
    return cost, n
