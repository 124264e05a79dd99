"""Props the simulated person uses: a pedestal stool to sit on.

A lab records seated postures on a stool that is not in the empty-scene frames, so the
segmentation sees it as foreground: the stool is part of the observed silhouette while the
truth labels keep it apart (label 3, "object"). The stool is placed where the seated body
rests (:func:`stool_under`) and drawn as three closed, outward-wound cylinders: a seat, a
column and a base (:func:`stool_mesh`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["STOOL_RADIUS", "stool_mesh", "stool_under"]

#: Radius of the stool's seat (m).
STOOL_RADIUS = 0.17


def _cylinder(cx: float, cy: float, z0: float, z1: float, r: float, sides: int) -> tuple[np.ndarray, np.ndarray]:
    """A closed cylinder (vertices (2 sides + 2, 3), faces wound counter-clockwise seen from outside)."""
    a = np.linspace(0.0, 2 * np.pi, sides, endpoint=False)
    ring = np.stack([cx + r * np.cos(a), cy + r * np.sin(a)], axis=1)
    V = np.concatenate([np.column_stack([ring, np.full(sides, z0)]), np.column_stack([ring, np.full(sides, z1)]),
                        [[cx, cy, z0], [cx, cy, z1]]])
    i = np.arange(sides)
    j = (i + 1) % sides
    bottom, top = 2 * sides, 2 * sides + 1
    F = np.concatenate([
        np.stack([i, j, sides + j], axis=1), np.stack([i, sides + j, sides + i], axis=1),  # side
        np.stack([np.full(sides, top), sides + i, sides + j], axis=1),  # top, normal +z
        np.stack([np.full(sides, bottom), j, i], axis=1),  # bottom, normal -z
    ])
    return V, F


def stool_mesh(x: float, y: float, top: float, radius: float = STOOL_RADIUS,
               sides: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A pedestal stool on the floor (z = 0) centred on (x, y), its seat's top at ``top`` (m):
    a 4 cm seat of ``radius``, a 3.5 cm column and a 2 cm base of 0.7 × ``radius``."""
    if not top > 0.1:
        raise ValueError(f"stool: the seat's top must be above 0.1 m, got {top}")
    parts = [_cylinder(x, y, top - 0.04, top, radius, sides), _cylinder(x, y, 0.02, top - 0.04, 0.035, sides),
             _cylinder(x, y, 0.0, 0.02, 0.7 * radius, sides)]
    V = np.concatenate([p[0] for p in parts])
    offsets = np.cumsum([0] + [len(p[0]) for p in parts[:-1]])
    F = np.concatenate([p[1] + o for p, o in zip(parts, offsets, strict=True)])
    return V, F.astype(np.int32)


def stool_under(vertices: np.ndarray, parts: np.ndarray, pelvis: int,
                radius: float = STOOL_RADIUS) -> tuple[float, float, float]:
    """(x, y, top) of a stool the body of ``vertices`` (V, 3) sits on: centred under the pelvis
    part's vertices, its top touching the lowest point of the body within the seat's radius."""
    V = np.asarray(vertices, dtype=np.float64)
    x, y = V[parts == pelvis, :2].mean(axis=0)
    near = np.hypot(V[:, 0] - x, V[:, 1] - y) <= radius
    return float(x), float(y), float(V[near, 2].min())
