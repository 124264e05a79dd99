"""Refining the ground plane from the shadows (the shadow camera's second half, thesis §5.4).

The shadow camera is the light *and* the ground: eq. 5.2 projects a body point through the light
onto the plane ``n·X = d``, so a floor the calibration has slightly wrong (a tilt of a degree, a
centimetre of height) moves every predicted shadow and biases the light. With the light held,
eq. 5.9 is minimised over the plane by the same 7×7×7 grid refinement as the light
(:func:`studio.light.search.refine_grid`), in three parameters about the calibration's plane:

    n ∝ n₀ + tan(α) e₁ + tan(β) e₂,    the plane through c₀ + h n₀

(``e₁, e₂, n₀`` the calibration plane's frame, ``c₀`` the subject's centre on it): α and β tilt
the normal towards e₁ and e₂, h raises the plane under the subject. The shadows of several
frames at different places on the floor fix the tilt; their sizes (with the light) the height.

>>> import numpy as np
>>> from calibration import GroundPlane
>>> p = plane_of([0.0, 0.0, 0.02], GroundPlane.floor(), np.zeros(3))
>>> np.round(p.normal, 6).tolist(), round(p.offset, 6)
([0.0, 0.0, 1.0], 0.02)
"""

from __future__ import annotations

import numpy as np

from studio.light.search import refine_grid

__all__ = ["FLOOR_BOUNDS", "FLOOR_STEP", "describe_floor", "plane_of", "refine_floor"]

#: First grid spacing: tilts (rad) towards e1 and e2, height (m).
FLOOR_STEP = np.array([np.radians(1.0), np.radians(1.0), 0.02])
#: The search box about the calibration's plane.
FLOOR_BOUNDS = np.array([np.radians(6.0), np.radians(6.0), 0.15])
#: Stop once the spacing is below these (0.05°, 1 mm).
FLOOR_STOP = np.array([np.radians(0.05), np.radians(0.05), 0.001])


def plane_of(x, base, centre: np.ndarray):
    """The plane of parameters ``x`` = (α, β, h) about ``base`` (a :class:`calibration.GroundPlane`)
    at the subject's ``centre`` (3,)."""
    from calibration import GroundPlane

    _, e1, e2 = base.basis()
    n0 = np.asarray(base.normal, float)
    n = n0 + np.tan(float(x[0])) * e1 + np.tan(float(x[1])) * e2
    foot = base.project_onto(np.asarray(centre, float)[None])[0]
    return GroundPlane.from_point_normal(foot + float(x[2]) * n0, n)


def describe_floor(plane, base, centre: np.ndarray) -> dict:
    """The refined ``plane`` against the calibration's ``base``: its tilt (deg) and the height (m)
    of the refined plane above the calibration's at the subject's ``centre``."""
    n, n0 = np.asarray(plane.normal, float), np.asarray(base.normal, float)
    foot = base.project_onto(np.asarray(centre, float)[None])[0]
    height = (plane.offset - n @ foot) / (n @ n0)  # along n0 from the calibration's plane to the refined one
    return {"normal": np.round(n, 9).tolist(), "offset": float(plane.offset),
            "calibration": {"normal": np.round(n0, 9).tolist(), "offset": float(base.offset)},
            "tilt_deg": float(np.degrees(np.arccos(np.clip(n @ n0, -1.0, 1.0)))),
            "height_at_centre_m": float(height)}


def refine_floor(evaluate, lights: list, base, centre: np.ndarray, x0=None, *,
                 step=None) -> tuple[np.ndarray, float, list, int]:
    """The plane parameters (α, β, h) minimising eq. 5.9 with ``lights`` held; ``evaluate`` has
    ``planes(lights, grounds)`` → (N,) costs (:func:`studio.light.pool.evaluators`). Starts at
    ``x0`` (default the calibration's plane) with grids of spacing ``step`` / 3 (default
    ``FLOOR_STEP``), down to ``FLOOR_STOP``. Returns (x, cost, rounds, evaluations)."""
    x0 = np.zeros(3) if x0 is None else np.asarray(x0, float)
    step = FLOOR_STEP * 3.0 if step is None else np.asarray(step, float)

    def cost(X):
        return np.asarray(evaluate.planes(lights, [plane_of(x, base, centre) for x in X]), float)

    c0 = float(cost(x0[None])[0])
    x, c, rounds, evals = refine_grid(cost, x0, c0, step, -FLOOR_BOUNDS, FLOOR_BOUNDS,
                                      done=lambda x, s: bool(np.all(s < FLOOR_STOP)))
    return x, c, rounds, evals + 1
