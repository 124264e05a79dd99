"""A gradient polish of a fitted frame: trust-region least squares on a smooth stand-in of the
silhouette cost (eq. 4.4–4.6), with the true cost deciding whether its answer is kept.

The silhouette cost is piecewise constant in the parameters (masks are counted in whole
pixels), so the fit searches it with Nelder–Mead, which in the ~40 dimensions of pose + shape
stalls short of the cost's own minimum. :func:`contour_residuals` gives a residual vector whose
squared sum stands in for the two truncated chamfer directions of eq. 4.5 per view but is
smooth in the parameters: every (second) model vertex projected into a view reads the observed
silhouette's truncated distance map ``C^τ(F^o)`` bilinearly (model → observed; with ``outline``,
its distance beyond the outline of the observed pixels, :func:`outline_distance`), and every
observed pixel near the observed outline that the model's silhouette does not cover reads its
distance to the nearest projected vertex, truncated at τ (observed → model; the model's point
cloud stands in for its outline, a covered pixel counts 0 as in eq. 4.4). A distance ``d``
enters as ``d / sqrt(d + 1 px)`` divided by the square root of the direction's sample count, so
the squared sum is, far from 0, the sum over views of the two mean distances, eq. 4.5. The
Jacobian is a forward difference of the projections of one batch of bodies, chained with the
distance map's gradient, and with the nearest vertex and the coverage held (the derivative of
a minimum). :func:`lsq_polish` runs :func:`scipy.optimize.least_squares` (``trf``, the joint
limits and ±3 σ shape as bounds) and keeps the iterate the fit's own cost
(:class:`~studio.fit.objective.FrameObjective`, eq. 4.6 with its priors) likes best, the start
if none is lower: the stand-in's minimum is near the cost's, not on it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from studio.blas import one_blas_thread
from studio.body.skeleton import POSE_SIZE
from studio.threads import map_chunks

__all__ = ["band_samples", "contour_residuals", "lsq_polish", "polish_frame", "shape_residuals"]

#: Observed pixels within this many pixels of the observed outline (inside) enter the
#: observed → model direction, every ``OBSERVED_STRIDE``-th row and column.
OBSERVED_BAND = 10.0
OBSERVED_STRIDE = 2
#: Every ``VERTEX_STRIDE``-th model vertex is projected (the mesh's ~1 cm spacing is ~1.5 px).
VERTEX_STRIDE = 2
#: Forward-difference step of the Jacobian, a share of the parameters' typical step (``scale``).
FD_STEP = 0.05
#: The distance map counts from the observed pixels' centres; the outline of their region lies half a
#: pixel beyond them (:func:`outline_distance`).
HALF_PIXEL = 0.5


def outline_distance(distance_map: np.ndarray) -> np.ndarray:
    """A truncated distance map ``C^τ`` (0 on the observed pixels) made a signed distance to the
    outline of the observed pixels' region: ``d − ½`` outside, ``−½`` on the observed pixels.
    Read bilinearly at a projected vertex and clipped at 0 it is 0 up to that outline (the true
    cost is flat while the model's outline moves between the last observed pixel centre and the
    next: both silhouettes hold the same pixels) and grows past it; read from ``C^τ`` itself a
    vertex on the outline counts ½ px, which holds the model's outline at the last observed
    centres, on the edge of uncovering them. Used with ``FitOptions.polish_outline`` (off by
    default: on the benchmark's Anny people it lowered the fit's own cost and balanced precision
    and recall, but did not bring the bodies closer; see the option)."""
    d = np.asarray(distance_map, dtype=np.float64)
    return np.where(d > 0, d - HALF_PIXEL, -HALF_PIXEL)


def _bilinear(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """``img`` (H, W) read at pixel positions ``uv`` (..., 2) (x, y), clamped to the image."""
    h, w = img.shape
    x = np.clip(uv[..., 0], 0.0, w - 1.000001)
    y = np.clip(uv[..., 1], 0.0, h - 1.000001)
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = x - x0, y - y0
    a, b = img[y0, x0], img[y0, x0 + 1]
    c, d = img[y0 + 1, x0], img[y0 + 1, x0 + 1]
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


def _root(d: np.ndarray, smooth: float | None) -> tuple[np.ndarray, np.ndarray]:
    """Residual of a distance ``d`` (px) and its slope: ``d / sqrt(d + smooth)`` (its square is
    ``d`` far from 0, as eq. 4.4 sums distances, and smooth at 0), or ``d`` itself when
    ``smooth`` is None (squared distances)."""
    if smooth is None:
        return d, np.ones_like(d)
    s = np.sqrt(d + smooth)
    return d / s, (d + 2 * smooth) / (2 * s**3)


def shape_residuals(obj, weight: float, threshold: float):
    """(residuals, jacobian) of the shape prior's stand-in in the polish: per free shape coefficient
    ``√weight · max(0, |β|/σ − threshold)`` (eq. 6.8 with its threshold lowered: the least squares
    otherwise drive coefficients to the ±3 σ bounds to make up for pose errors)."""
    sigma = obj._sigma[: obj.n_shape_free]
    root = np.sqrt(weight)

    def residuals(x):
        return root * np.maximum(0.0, np.abs(np.asarray(x, float)[-len(sigma):]) / sigma - threshold)

    def jacobian(x):
        beta = np.asarray(x, float)[-len(sigma):]
        J = np.zeros((len(sigma), len(x)))
        J[:, -len(sigma):] = np.diag(root * np.sign(beta) / sigma * (np.abs(beta) / sigma > threshold))
        return J

    return residuals, jacobian


def band_samples(mask: np.ndarray) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
    """The observed → model samples of one view's observed mask (H, W): every ``OBSERVED_STRIDE``-th
    row and column of its pixels within ``OBSERVED_BAND`` of its outline, as pixels (n, 2) (x, y)
    and (rows, cols)."""
    import cv2

    from studio.cost.chamfer import _distance_to

    inner = _distance_to(~mask, OBSERVED_BAND + 1, cv2.DIST_MASK_PRECISE)  # same in every process
    keep = mask & (inner <= OBSERVED_BAND)
    grid = np.zeros_like(keep)
    grid[::OBSERVED_STRIDE, ::OBSERVED_STRIDE] = True
    r, c = np.nonzero(keep & grid)
    return np.stack([c, r], axis=1).astype(np.float64), (r, c)


def contour_residuals(obj, level: int = 0, balance: float = 1.0, l1: float | None = 1.0, *, distance_maps=None,
                      samples=None, outline: bool = False):
    """(residuals, jacobian) of ``obj`` (a :class:`~studio.fit.objective.FrameObjective`) at
    ``level``: ``residuals(x) -> (M,)``, ``jacobian(x, h) -> (M, D)`` (forward differences of
    step ``h`` (D,)). See the module docstring for the residuals; ``balance`` weights the observed →
    model direction against the other, ``l1`` is the smoothing of :func:`_root`; ``outline``: the
    vertices read their distance beyond the observed outline (:func:`outline_distance`).

    ``distance_maps`` (per view, level pixels; default the target's) and ``samples`` (per view
    ``(pixels (n, 2), (rows, cols), τ, weight, norm)``, τ / weight / norm scalars or (n,): each
    sample's residual is ``weight · root(min(d, τ)) / norm``; default :func:`band_samples` of the
    target's masks with τ of the target, ``balance`` and the square root of the view's count) let
    other costs of the same form use it (the clothing cost's regions,
    :func:`studio.fit.batch_terms.clothing_residuals`)."""
    from scipy.spatial import cKDTree

    target = obj.targets[level]
    cams = obj._level_cams[level]
    if distance_maps is None:
        distance_maps = target.distance_maps
    if samples is None:
        tau = float(target.tau_level)
        samples = [(pts, rc, tau, balance, np.sqrt(len(pts))) for pts, rc in map(band_samples, target.masks)]
    dts = [outline_distance(d) if outline else np.asarray(d, dtype=np.float64) for d in distance_maps]
    grads = [np.stack(np.gradient(d)[::-1], axis=-1) for d in dts]  # (H, W, 2): d/dx, d/dy
    sample = np.arange(0, obj.model.n_vertices, VERTEX_STRIDE)
    n_v = len(sample)

    def project(V):
        """(N, V, 3) → per view (N, n_v, 2) pixels of the sampled vertices (views on threads)."""
        flat = np.ascontiguousarray(V[:, sample]).reshape(-1, 3)
        return map_chunks(lambda cam: cam.project(flat).reshape(len(V), n_v, 2), cams)

    def parts(V, uv):
        """Residuals of one body (mesh ``V``, projections ``uv``); also the nearest vertex and the
        distance of every observed sample (0 where the model's silhouette covers it)."""
        out, nearest = [], []
        masks = obj.masks(V, level)
        for k, p in enumerate(uv):
            pts, rc, tau, weight, norm = samples[k]
            fwd = _root(np.maximum(_bilinear(dts[k], p), 0.0), l1)[0] / np.sqrt(n_v)
            if len(pts):
                d, j = cKDTree(p).query(pts)
                d = np.where(masks[k][rc], 0.0, np.minimum(d, tau))
                bwd = weight * _root(d, l1)[0] / norm
            else:
                d, j, bwd = np.zeros(0), np.zeros(0, np.int64), np.zeros(0)
            out += [fwd, bwd]
            nearest.append((j, d))
        return np.concatenate(out), nearest

    def residuals(x):
        V = obj.meshes(np.asarray(x, float)[None])
        return parts(V[0], [u[0] for u in project(V)])[0]

    def jacobian(x, h):
        x = np.asarray(x, float)
        X = np.repeat(x[None], len(x) + 1, axis=0)
        X[1:] += np.diag(h)
        V = obj.meshes(X)
        uv = project(V)
        _, nearest = parts(V[0], [u[0] for u in uv])

        def view_rows(k):
            """The Jacobian's rows of view ``k``: its model → observed residuals, then the others."""
            u = uv[k]
            du = (u[1:] - u[0]) / h[:, None, None]  # (D, V, 2) pixels per unit
            g = _bilinear(grads[k][..., 0], u[0]), _bilinear(grads[k][..., 1], u[0])
            beyond = _bilinear(dts[k], u[0])
            # clipped at 0, the signed reading has no slope inside (the map's own reading keeps the
            # slope it had there: the default fits unchanged to the last digit)
            slope = _root(np.maximum(beyond, 0.0), l1)[1] * (beyond > 0) if outline else _root(beyond, l1)[1]
            rows = [((du[..., 0] * g[0] + du[..., 1] * g[1]) * slope / np.sqrt(n_v)).T]
            j, d = nearest[k]
            if len(j):
                pts, _, tau, weight, norm = samples[k]
                diff = u[0][j] - pts  # nearest vertex − observed sample (n, 2)
                unit = diff / np.maximum(d, 1e-9)[:, None]
                slope = _root(d, l1)[1] * ((d > 0) & (d < tau))
                rows.append((weight * (du[:, j] * unit).sum(axis=-1) * slope / norm).T)
            return rows

        return np.vstack([r for rows in map_chunks(view_rows, range(len(uv))) for r in rows])

    return residuals, jacobian


@one_blas_thread  # the trust region's SVD of a ~18000 × 40 Jacobian: 0.06 s on one thread, 0.2–0.5 s on two
def lsq_polish(obj, x0, bounds, scale, *, level: int = 0, max_nfev: int = 12, balance: float = 1.0,
               l1: float | None = 1.0, shape_prior: tuple[float, float] | None = None,
               residuals=None, outline: bool = False) -> tuple[np.ndarray, float, dict]:
    """Trust-region least squares (``trf``, at most ``max_nfev`` iterations) on
    :func:`contour_residuals` from ``x0`` within ``bounds`` = (lo, hi), ``x_scale=scale`` (D,)
    (the parameters' typical steps; the Jacobian's step is ``FD_STEP`` of them). Returns the
    iterate with the lowest cost by ``obj`` (eq. 4.6 with its priors; ``x0`` when none is lower),
    that cost, and a record: ``cost_before``, ``costs`` (every iterate's), ``nfev``, ``njev``.
    ``l1``: the smoothing of :func:`_root` (None: squared distances); ``balance``: the weight of
    the observed → model direction; ``shape_prior``: (weight, threshold σ) of
    :func:`shape_residuals` appended to the residuals (None: none); ``residuals``: another
    (residuals, jacobian) pair of the form of :func:`contour_residuals` in its place (the batch's
    clothing stand-in, :func:`studio.fit.batch.pose_polish`); ``outline``: as :func:`contour_residuals`."""
    from scipy.optimize import least_squares

    lo, hi = (np.asarray(b, float) for b in bounds)
    x0 = np.clip(np.asarray(x0, float), lo, hi)
    res, jac = contour_residuals(obj, level, balance, l1, outline=outline) if residuals is None else residuals
    h = FD_STEP * np.asarray(scale, float)
    if shape_prior is not None and shape_prior[0] > 0 and obj.n_shape_free:
        sres, sjac = shape_residuals(obj, *shape_prior)
    else:
        sres = sjac = None

    def R(x):
        return res(x) if sres is None else np.concatenate([res(x), sres(x)])

    def J(x):
        j = jac(x, np.where(x + h > hi, -h, h))  # a forward step that stays inside the bounds
        return j if sjac is None else np.vstack([j, sjac(x)])

    best = {"x": x0, "cost": float(obj(x0[None], level)[0])}
    start_cost, costs = best["cost"], []

    def keep_best(intermediate_result):  # the stand-in's minimum is not the cost's: keep the best iterate
        c = float(obj(intermediate_result.x[None], level)[0])
        costs.append(c)
        if c < best["cost"]:
            best.update(x=intermediate_result.x.copy(), cost=c)

    r = least_squares(R, x0, jac=J, bounds=(lo, hi), x_scale=np.asarray(scale, float), max_nfev=max_nfev,
                      method="trf", xtol=1e-6, ftol=1e-6, callback=keep_best)
    return best["x"], best["cost"], {"cost_before": start_cost, "costs": costs, "nfev": int(r.nfev),
                                     "njev": int(r.njev or 0)}


def polish_frame(obj, x, box, step, *, level: int, iterations: int, shape_prior=None, twin=None,
                 outline: bool = False):
    """The fit's polish step: :func:`lsq_polish` of ``x`` (parameters of ``obj``, a
    :class:`~studio.fit.objective.FrameObjective`) within ``box`` = (lo, hi) with typical steps
    ``step``, whose length may free more shape coefficients than ``obj`` does (a copy of ``obj``
    then frees them, ``FitOptions.polish_shape_free``); with ``twin`` (``f(shape, pose) -> pose``)
    the polished answer's twin is polished too and the lower cost kept (``outline``: as
    :func:`contour_residuals`). Returns ``(objective, x,
    record, twin_costs, n_copy)``: the objective of the later stages (``obj``, or ``obj`` with the
    extra coefficients held as polished in its base shape) and ``x`` in its parameters, the
    polish's record, [cost, twin's cost] (None without ``twin``) and the evaluations the copy made."""
    n_shape = len(box[0]) - POSE_SIZE
    pobj = obj if n_shape == obj.n_shape_free else replace(obj, n_shape_free=n_shape, n_evaluations=0)
    shapes, poses = obj.split(np.asarray(x, float)[None])
    xp, cost, record = lsq_polish(pobj, pobj.pack(shapes[0], poses[0]), box, step, level=level, max_nfev=iterations,
                                  shape_prior=shape_prior, outline=outline)
    twin_costs = None
    if twin is not None:
        shapes, poses = pobj.split(xp[None])
        xt, cost_t, _ = lsq_polish(pobj, pobj.pack(shapes[0], twin(shapes[0], poses[0])), box, step, level=level,
                                   max_nfev=iterations, shape_prior=shape_prior, outline=outline)
        twin_costs = [cost, cost_t]
        if cost_t < cost:
            xp = xt
    if pobj is obj:
        return obj, xp, record, twin_costs, 0
    shapes, poses = pobj.split(xp[None])
    out = replace(obj, base_shape=shapes[0])  # the final stage frees the search's coefficients again
    return out, out.pack(shapes[0], poses[0]), record, twin_costs, pobj.n_evaluations
