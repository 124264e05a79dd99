"""Garments of the simulated person over the true body (for the clothing fit, thesis ch. 6).

The true (undressed) body stays the truth; garments only change what the cameras see:

- ``top.kind``: ``shirt`` (the torso above the waist, sleeves per ``top.sleeves``), ``long_shirt``
  (down to mid-thigh), ``jacket`` (down to the hips, long sleeves, twice as loose);
- ``bottom.kind``: ``trousers``, ``wide_trousers`` (looser toward the hem, up to 4× at the
  ankle), ``skirt`` (a separate flared tube from the waist to above the knees around both legs,
  bare legs below: :func:`skirt_mesh`).

Clothed vertices move out along their normals by the per-vertex amount of
:func:`garment_offsets` (``person.looseness`` metres scaled per garment) times the posture's
:func:`drape` factor in [0, 1]; the skirt is an extra mesh rendered with the body (person label,
never skin).

**Drape** (gravity, per posture): loose cloth rests on the body where the body holds it up and
hangs away below. A clothed vertex whose posed surface faces up (outward normal ``n`` with
``n · down ≤ -0.8``, within 37° of straight up: shoulders, the top of the upper chest, the top of
a raised arm's sleeve) carries the cloth (gap 0); one facing sideways or down (``n · down ≥ 0``)
gets the full looseness, smoothly between (:func:`gravity_gap`). The cut holds the garment at
its openings whatever the posture: a top's collar (zero gap above 0.85 of stature in the rest
pose, growing to full 0.2 of stature below it — the cloth hanging from the shoulders; by rest
height, so a sleeve is held at its shoulder seam too) and the trousers' waistband, hips and seat
(zero at the waist, about half over the hips, full at the crotch) (:func:`cut_gap`). Under a
long shirt or a jacket the hips are the top's and hang.
The factor is smoothed over each garment (a few one-ring averages) so it has no creases.
It is geometry, not cloth simulation: no folds, no swing, no self-collision, no friction; the cloth
never falls *inside* the body and a skirt stays the flared tube of :func:`skirt_mesh`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["HEMS", "adjust_labels", "cut_gap", "drape", "garment_offsets", "gravity_gap", "skirt_mesh"]

#: Rest height (fraction of stature) of the hem of each long garment.
HEMS = {"long_shirt": 0.42, "jacket": 0.47, "skirt": 0.33}
#: Looseness factor per garment (× ``person.looseness``).
FACTORS = {"shirt": 1.0, "long_shirt": 1.2, "jacket": 1.8, "trousers": 1.0, "wide_trousers": 1.0, "skirt": 0.0}
WAIST = 0.575
#: ``n · down`` at and below which a surface carries its cloth (0 gap) / from which the cloth
#: hangs at full looseness (sideways and downward-facing surfaces).
CARRY, HANG = -0.8, 0.0
#: Rest heights (fraction of stature): a top's collar (no gap above) and the drop below it over
#: which its gap grows to full; the trousers' waistband (no gap above) and crotch (full gap).
COLLAR, COLLAR_DROP = 0.85, 0.2
WAISTBAND, CROTCH = 0.555, 0.47
#: One-ring averaging passes over the drape factor.
SMOOTH_PASSES = 3


def adjust_labels(labels: np.ndarray, parts: np.ndarray, part_index: dict, rest_height: np.ndarray, person: dict,
                  skin: int, top: int, bottom: int) -> np.ndarray:
    """Material labels (V,) with the garment kinds applied (see the module doc)."""
    lab = labels.copy()
    legs = np.isin(parts, [part_index[n] for n in ("pelvis", "upperleg_l", "upperleg_r")])
    kind = person["top"]["kind"]
    if kind in ("long_shirt", "jacket"):
        lab[legs & (rest_height > HEMS[kind])] = top
    if kind == "jacket":
        arms = np.isin(parts, [part_index[n] for n in ("upperarm_l", "upperarm_r", "lowerarm_l", "lowerarm_r")])
        lab[arms] = top
    if person["bottom"]["kind"] == "skirt":
        lower = np.isin(parts, [part_index[n] for n in ("lowerleg_l", "lowerleg_r")])
        lab[lower] = skin  # bare legs under the skirt
        lab[legs & (rest_height < HEMS["skirt"])] = skin
    return lab


def garment_offsets(labels: np.ndarray, rest_height: np.ndarray, person: dict, top: int, bottom: int) -> np.ndarray:
    """How far (m, (V,)) each vertex's garment stands off the body."""
    loose = float(person["looseness"])
    out = np.zeros(len(labels))
    out[labels == top] = loose * FACTORS[person["top"]["kind"]]
    kind = person["bottom"]["kind"]
    b = labels == bottom
    if kind == "wide_trousers":
        flare = 1.0 + 3.0 * np.clip((0.5 - rest_height.astype(np.float64)) / 0.45, 0.0, 1.0)
        out[b] = loose * flare[b]
    else:
        out[b] = loose * FACTORS[kind]
    return out


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def gravity_gap(normals: np.ndarray) -> np.ndarray:
    """Share (V,) in [0, 1] of the looseness a garment keeps over a posed surface of outward unit
    ``normals`` (V, 3) (world z up): 0 where the surface faces up and carries the cloth
    (``n · down ≤ CARRY``), 1 where it faces sideways or down (``≥ HANG``), smoothstep between."""
    down = -np.asarray(normals, dtype=np.float64)[:, 2]
    return _smoothstep((down - CARRY) / (HANG - CARRY))


def cut_gap(labels: np.ndarray, rest_height: np.ndarray, top: int, bottom: int) -> np.ndarray:
    """Share (V,) in [0, 1] of the looseness the garment's cut allows, any posture: a top hangs
    from its collar (0 above ``COLLAR``, full ``COLLAR_DROP`` below), trousers are held at the
    waistband, hips and seat (0 above ``WAISTBAND``, full at ``CROTCH``); 1 elsewhere."""
    h = np.asarray(rest_height, dtype=np.float64)
    out = np.ones(len(labels))
    t, b = labels == top, labels == bottom
    out[t] = _smoothstep((COLLAR - h[t]) / COLLAR_DROP)
    out[b] = _smoothstep((WAISTBAND - h[b]) / (WAISTBAND - CROTCH))
    return out


def _smooth(values: np.ndarray, faces: np.ndarray, keep: np.ndarray, groups: np.ndarray, passes: int) -> np.ndarray:
    """``passes`` one-ring averages of ``values`` (V,) over the mesh, among the ``keep`` vertices,
    each vertex with its neighbours of the same ``groups`` value (one garment)."""
    F = np.asarray(faces)
    a = np.concatenate([F[:, 0], F[:, 1], F[:, 2], F[:, 1], F[:, 2], F[:, 0]])
    b = np.concatenate([F[:, 1], F[:, 2], F[:, 0], F[:, 0], F[:, 1], F[:, 2]])
    ok = keep[a] & keep[b] & (groups[a] == groups[b])
    a, b = a[ok], b[ok]
    n = len(values)
    deg = np.bincount(a, minlength=n) + 1.0
    v = np.asarray(values, dtype=np.float64).copy()
    for _ in range(passes):
        v = np.where(keep, (np.bincount(a, weights=v[b], minlength=n) + v) / deg, v)
    return v


def drape(normals: np.ndarray, faces: np.ndarray, labels: np.ndarray, rest_height: np.ndarray, top: int,
          bottom: int) -> np.ndarray:
    """The posture's drape factor (V,) in [0, 1] (module doc): :func:`gravity_gap` of the posed
    body's ``normals`` times :func:`cut_gap`, smoothed over each garment (1 elsewhere: a shirt's
    hem hangs over the trousers' waistband)."""
    clothed = np.isin(labels, [top, bottom])
    share = gravity_gap(normals) * cut_gap(labels, rest_height, top, bottom)
    return np.where(clothed, _smooth(share, faces, clothed, np.asarray(labels), SMOOTH_PASSES), 1.0)


def skirt_mesh(V: np.ndarray, parts: np.ndarray, part_index: dict, rest_height: np.ndarray, looseness: float,
               n_theta: int = 36, n_rings: int = 10) -> tuple[np.ndarray, np.ndarray]:
    """A flared tube (vertices (n_rings · n_theta, 3), faces) around the hips and both thighs of
    the posed body ``V``, from the waist to the skirt's hem, standing ``looseness`` off at the
    waist and twice that at the hem; outward-facing triangles."""
    h = rest_height.astype(np.float64)
    band = np.isin(parts, [part_index[n] for n in ("pelvis", "upperleg_l", "upperleg_r")])
    top_v = band & (np.abs(h - 0.56) < 0.015)
    hem_v = band & (np.abs(h - HEMS["skirt"]) < 0.015)
    z_top, z_hem = float(V[top_v, 2].mean()), float(V[hem_v, 2].mean())
    inside = band & (h >= HEMS["skirt"] - 0.02) & (h <= 0.58)
    P = V[inside]
    zs = np.linspace(z_top, z_hem, n_rings)
    dz = max(abs(z_top - z_hem) / (n_rings - 1), 0.01)
    theta = np.linspace(0.0, 2 * np.pi, n_theta, endpoint=False)
    U = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    rings = []
    for j, z in enumerate(zs):
        near = P[np.abs(P[:, 2] - z) < dz]
        if len(near) < 3:
            near = P[np.argsort(np.abs(P[:, 2] - z))[:50]]
        xy = near[:, :2]
        c = xy.mean(axis=0)
        support = ((xy - c) @ U.T).max(axis=0)  # (n_theta,) extent of the body along each direction
        t = j / max(n_rings - 1, 1)
        r = support + looseness * (1.0 + t)
        rings.append(np.column_stack([c + U * r[:, None], np.full(n_theta, z)]))
    Vs = np.concatenate(rings)
    faces = []
    for j in range(n_rings - 1):
        for i in range(n_theta):
            a, b = j * n_theta + i, j * n_theta + (i + 1) % n_theta
            c_, d = a + n_theta, b + n_theta
            faces += [(a, c_, b), (b, c_, d)]
    Fs = np.asarray(faces, dtype=np.int32)
    # outward: the face normals point away from the ring centres
    tri = Vs[Fs]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    centre = np.concatenate([np.repeat(r[:, :2].mean(axis=0)[None], n_theta, axis=0) for r in rings])
    radial = tri.mean(axis=1)[:, :2] - centre[Fs[:, 0]]
    if np.mean(np.einsum("ij,ij->i", n[:, :2], radial)) < 0:
        Fs = Fs[:, [0, 2, 1]]
    return Vs.astype(np.float64), Fs
