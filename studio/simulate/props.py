"""Props the simulated person uses: a pedestal stool to sit on.

A lab records seated postures on a stool that is not in the empty-scene frames, so the
segmentation sees it as foreground: the stool is part of the observed silhouette while the
truth labels keep it apart (label 3, "object"). The stool is placed where the seated body
rests (:func:`studio.fit.props.seat_of` with the stool's radius) and drawn as three closed, outward-wound cylinders: a seat, a
column and a base (:func:`stool_mesh`).
"""

from __future__ import annotations

import numpy as np

from studio.render.solids import cylinder_mesh

__all__ = ["STOOL_RADIUS", "stool_mesh"]

#: Radius of the stool's seat (m).
STOOL_RADIUS = 0.17


def stool_mesh(x: float, y: float, top: float, radius: float = STOOL_RADIUS,
               sides: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A pedestal stool on the floor (z = 0) centred on (x, y), its seat's top at ``top`` (m):
    a 4 cm seat of ``radius``, a 3.5 cm column and a 2 cm base of 0.7 × ``radius``."""
    if not top > 0.1:
        raise ValueError(f"stool: the seat's top must be above 0.1 m, got {top}")
    parts = [cylinder_mesh(x, y, top - 0.04, top, radius, sides), cylinder_mesh(x, y, 0.02, top - 0.04, 0.035, sides),
             cylinder_mesh(x, y, 0.0, 0.02, 0.7 * radius, sides)]
    V = np.concatenate([p[0] for p in parts])
    offsets = np.cumsum([0] + [len(p[0]) for p in parts[:-1]])
    F = np.concatenate([p[1] + o for p, o in zip(parts, offsets, strict=True)])
    return V, F.astype(np.int32)

