"""A seat in the silhouettes: the stool or chair a seated person rests on.

A prop the person sits on is not in the empty-scene frames, so segmentation labels it
foreground and it becomes part of the observed silhouettes; fitted as if it were body, it
drags the legs and the pelvis towards it (own-model seated body on a stool: surface distance
5.4 mm without the stool in the masks, 15.6 mm with it). The body tells where a seat must be:
a fitted body sitting (both thighs well away from vertical) with its seat above the floor rests
on something.
:func:`find_support` takes the upright cylinder under the seat (``SUPPORT_RADIUS``, from the
floor to the seat), projects it into every view, and where the observed silhouette fills what
the body leaves of that projection (the median share over the views at least ``EVIDENCE``)
there is a prop. The observed pixels of that cylinder, raised ``SEAT_MARGIN`` above the seat,
less what the body's other parts than its seat (``SEAT_PARTS``: pelvis, thighs) cover, become a
don't-care region of the cost (:meth:`studio.cost.SilhouetteTarget.build` ``ignore``) and of the
quality gates' agreement: the body need not explain them, and may cover them (a stool can hide
a calf; a calf in front of the stool is still the calf's to explain). Until this release the
region was what the whole body left uncovered: a body fitted low covered the stool's seat,
which then stayed in the cost as body and held the hips down on it (dev seated fits: seats 32–120
mm below the true one; median surface 11.2 → 8.7 mm with the seat parts' pixels left to the prop).
A squat with nothing under it finds no evidence and keeps the ordinary cost.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from studio.body.skeleton import PART_NAMES

__all__ = ["EVIDENCE", "MIN_SEAT_HEIGHT", "MIN_THIGH_ANGLE", "SEAT_MARGIN", "SEAT_PARTS", "SUPPORT_RADIUS", "Support",
           "find_support", "seat_of", "thigh_angles"]

#: Radius (m) of the region under the seat searched for a support (a stool's or chair's seat).
SUPPORT_RADIUS = 0.30
#: Radius (m) around the pelvis within which the body's lowest point is its seat.
SEAT_RADIUS = 0.15
#: A seat lower than this (m) is the floor itself (kneeling, sitting on the floor): no prop.
MIN_SEAT_HEIGHT = 0.2
#: Both thighs at least this far from vertical (rad) make a sitting posture (a lunge has one).
MIN_THIGH_ANGLE = np.radians(55.0)
#: Median share, over the views, of the support region left by the body that the observed
#: silhouette fills, above which the region holds a prop.
EVIDENCE = 0.1
#: The parts a body rests on a seat with: where they cover the support region, the pixels may be
#: the prop's (a body sunk onto the seat covers its rim), so they stay in the don't-care region.
SEAT_PARTS = ("pelvis", "upperleg_l", "upperleg_r")
#: The don't-care region reaches this far (m) above the body's seat: a seat fitted low lies
#: below the prop's top.
SEAT_MARGIN = 0.05


@dataclass(frozen=True)
class Support:
    """A prop found under a seated body: centre ``x``, ``y`` and ``seat`` height (m), the
    ``ignore`` masks (full resolution, one per view) and the ``evidence`` share per view."""

    x: float
    y: float
    seat: float
    ignore: list
    evidence: list

    def to_json(self, names) -> dict:
        return {"centre_m": [round(self.x, 4), round(self.y, 4)], "seat_height_m": round(self.seat, 4),
                "views": {n: {"ignored_pixels": int(m.sum()), "evidence": round(float(e), 3)}
                          for n, m, e in zip(names, self.ignore, self.evidence, strict=True)}}


def seat_of(vertices: np.ndarray, parts: np.ndarray, radius: float = SEAT_RADIUS) -> tuple[float, float, float]:
    """(x, y, height) of the seat of a body (``parts``: part index per vertex): under the pelvis
    part's centroid, at the lowest vertex within ``radius`` of it. The simulator puts its stool's
    top there too (:mod:`studio.simulate.props`)."""
    V = np.asarray(vertices, dtype=np.float64)
    x, y = V[parts == PART_NAMES.index("pelvis"), :2].mean(axis=0)
    near = np.hypot(V[:, 0] - x, V[:, 1] - y) <= radius
    return float(x), float(y), float(V[near, 2].min())


def thigh_angles(model, shape, pose) -> tuple[float, float]:
    """Angles (rad) of the left and right thighs (hip → knee) from the downward vertical."""
    J = model.joints(shape, pose)
    out = []
    for side in ("l", "r"):
        d = J[PART_NAMES.index(f"lowerleg_{side}")] - J[PART_NAMES.index(f"upperleg_{side}")]
        out.append(float(np.arccos(np.clip(-d[2] / np.linalg.norm(d), -1.0, 1.0))))
    return out[0], out[1]


def find_support(model, cameras, masks, shape, pose) -> Support | None:
    """The prop under a seated body fitted as ``shape``, ``pose`` to the observed ``masks``, or
    None (not seated, or nothing observed under the seat). See the module doc."""
    import cv2

    from studio.render import cylinder_mesh, silhouette

    if min(thigh_angles(model, shape, pose)) < MIN_THIGH_ANGLE:
        return None
    V = model.vertices(shape, pose)
    x, y, seat = seat_of(V, model.parts)
    if seat < MIN_SEAT_HEIGHT:
        return None
    Vs, Fs = cylinder_mesh(x, y, 0.0, seat, SUPPORT_RADIUS)
    Vm, Fm = cylinder_mesh(x, y, 0.0, seat + SEAT_MARGIN, SUPPORT_RADIUS)
    rest = model.faces[~np.isin(model.face_parts, [PART_NAMES.index(p) for p in SEAT_PARTS])]
    kernel = np.ones((5, 5), np.uint8)
    ignore, evidence = [], []
    for cam, obs in zip(cameras, masks, strict=True):
        body = cv2.dilate(silhouette(cam, V, model.faces).view(np.uint8), kernel).astype(bool)
        free = silhouette(cam, Vs, Fs) & ~body
        evidence.append((obs & free).sum() / max(int(free.sum()), 1))
        limbs = cv2.dilate(silhouette(cam, V, rest).view(np.uint8), kernel).astype(bool)
        ignore.append(obs & silhouette(cam, Vm, Fm) & ~limbs)
    if np.median(evidence) < EVIDENCE:
        return None
    return Support(x, y, seat, ignore, evidence)
