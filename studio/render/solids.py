"""Simple closed solids for props drawn or reasoned about beside the body (a stool, the region a
seated person rests on)."""

from __future__ import annotations

import numpy as np

__all__ = ["cylinder_mesh"]


def cylinder_mesh(x: float, y: float, z0: float, z1: float, radius: float,
                  sides: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """An upright closed cylinder on the circle of ``radius`` about (x, y), from ``z0`` to ``z1``:
    vertices (2 sides + 2, 3) and faces (4 sides, 3) int32, wound counter-clockwise seen from
    outside (outward normals)."""
    a = np.linspace(0.0, 2 * np.pi, sides, endpoint=False)
    ring = np.stack([x + radius * np.cos(a), y + radius * np.sin(a)], axis=1)
    V = np.concatenate([np.column_stack([ring, np.full(sides, z0)]), np.column_stack([ring, np.full(sides, z1)]),
                        [[x, y, z0], [x, y, z1]]])
    i = np.arange(sides)
    j = (i + 1) % sides
    bottom, top = 2 * sides, 2 * sides + 1
    F = np.concatenate([
        np.stack([i, j, sides + j], axis=1), np.stack([i, sides + j, sides + i], axis=1),  # side
        np.stack([np.full(sides, top), sides + i, sides + j], axis=1),  # top, normal +z
        np.stack([np.full(sides, bottom), j, i], axis=1),  # bottom, normal -z
    ])
    return V, F.astype(np.int32)
