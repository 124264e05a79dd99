"""Anthropometric measurements by ISO 7250-1 definitions, on any mesh of the model's topology.

One definition per measurement (:data:`DEFINITIONS`), each with the clause it follows, its
kind (which sets the ISO 20685-1:2018 maximum allowable error, :data:`ISO20685_MAE`) and the
ANSUR II column that measures the same thing (or None). The fit, the simulator's truth
(:func:`studio.body.measure.measure_anny_body`) and the benchmarks all measure through
:func:`measure_iso`.

Clause numbers are those of ISO 7250-1:2008 §4 (the 2017 revision kept the measurements
and their order); hip and upper-arm girths are not in ISO 7250-1 and follow ISO 8559-1:2017;
arm span follows ANSUR II's ``span`` (no ISO 7250-1 clause).

**Landmarks** are vertex indices of the template (:func:`template_landmarks`), chosen once by
the geometric rules below on the neutral model's mean body in its default standing pose,
and then carried by the mesh for every shape — so a landmark is the same point of the body
for every person, fitted or true:

- ``vertex``: highest point of the head;
- ``exocanthion_l/_r``: outer eye corner, the anterior head surface 45 mm lateral of the
  midline, 35 mm above the nose tip (pronasale, the head's most anterior point);
- ``acromion_l/_r``: highest point of the shoulder within 25 mm (front/back) of the shoulder
  joint and lateral of it;
- ``olecranon_l/_r``: back of the elbow, the arm vertex farthest along the upper arm's axis
  within 60 mm of the elbow joint;
- ``stylion_l/_r``: wrist, the forearm vertex farthest along the forearm's axis;
- ``thelion_l/_r``: most anterior point of the chest 50–130 mm lateral of the midline;
- ``tibiale_l/_r``: medial point of the knee at the knee joint's height;
- ``crotch``: lowest point of the pelvis and thighs within 15 mm of the sagittal plane,
  between the knees and the shoulders.

Girths are perimeters of the convex hull of a plane section (a tape bridges concavities,
thesis §6.4.4) of the named body parts only.

All functions take metres, return metres (kg for mass, kg/m² for BMI).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from studio.body.skeleton import PART_NAMES

__all__ = [
    "DEFINITIONS",
    "ISO20685_MAE",
    "ISO_NAMES",
    "Definition",
    "IsoMeasurement",
    "measure_iso",
    "plane_section",
    "template_landmarks",
]

_P = {n: i for i, n in enumerate(PART_NAMES)}


@dataclass(frozen=True)
class Definition:
    """One measurement: ``name``, ``title``, ``clause`` it follows, ``kind`` (``height``,
    ``breadth``, ``depth``, ``small_girth``, ``large_girth``, ``length``, ``mass``, ``index``),
    ``unit`` (SI), ``ansur`` (ANSUR II column or None) and ``text`` (the definition)."""

    name: str
    title: str
    clause: str
    kind: str
    unit: str
    ansur: str | None
    text: str

    @property
    def max_error(self) -> float | None:
        """ISO 20685-1:2018 maximum allowable error (metres) for this kind, or None."""
        return ISO20685_MAE.get(self.kind)


#: ISO 20685-1:2018 maximum allowable error (metres) of a scan-derived measurement by kind
ISO20685_MAE = {"height": 0.004, "breadth": 0.004, "depth": 0.004, "small_girth": 0.004,
                "length": 0.005, "large_girth": 0.009}

_D = Definition
DEFINITIONS: tuple[Definition, ...] = (
    _D("stature", "Stature", "ISO 7250-1 4.1.2", "height", "m", "stature",
       "vertical distance from the floor to the highest point of the head (vertex)"),
    _D("eye_height", "Eye height", "ISO 7250-1 4.1.3", "height", "m", None,
       "vertical distance from the floor to the outer corner of the eye (exocanthion), mean of both sides"),
    _D("shoulder_height", "Shoulder height", "ISO 7250-1 4.1.4", "height", "m", "acromialheight",
       "vertical distance from the floor to the acromion, mean of both sides"),
    _D("elbow_height", "Elbow height", "ISO 7250-1 4.1.5", "height", "m", None,
       "vertical distance from the floor to the bottom of the elbow with the upper arm hanging: "
       "shoulder height minus shoulder-elbow length"),
    _D("crotch_height", "Crotch height", "ISO 7250-1 4.1.7", "height", "m", "crotchheight",
       "vertical distance from the floor to the crotch landmark (lowest trunk point in the sagittal plane)"),
    _D("knee_height", "Knee (tibial) height", "ISO 7250-1 4.1.8", "height", "m", "tibialheight",
       "vertical distance from the floor to the tibiale (medial knee at the knee joint), mean of both sides"),
    _D("chest_depth", "Chest depth", "ISO 7250-1 4.1.9", "depth", "m", "chestdepth",
       "horizontal front-to-back depth of the trunk at the level of the nipples (thelion)"),
    _D("hip_breadth", "Hip breadth", "ISO 7250-1 4.1.12", "breadth", "m", "hipbreadth",
       "maximum horizontal breadth across the hips, between the crotch and 5 cm above the hip joints"),
    _D("shoulder_elbow_length", "Shoulder–elbow length", "ISO 7250-1 4.2.8", "length", "m",
       "shoulderelbowlength", "from the acromion to the back of the elbow (olecranon) along the upper "
       "arm's axis, mean of both sides"),
    _D("elbow_wrist_length", "Elbow–wrist length", "ISO 7250-1 4.2.9", "length", "m", "radialestylionlength",
       "from the back of the elbow (olecranon) to the wrist (stylion), mean of both sides"),
    _D("biacromial_breadth", "Shoulder (biacromial) breadth", "ISO 7250-1 4.2.10", "breadth", "m",
       "biacromialbreadth", "distance between the left and right acromion"),
    _D("neck_circumference", "Neck circumference", "ISO 7250-1 4.4.6", "small_girth", "m", "neckcircumference",
       "narrowest horizontal girth of the neck between 3 cm above the acromion and 15 cm below the vertex"),
    _D("chest_circumference", "Chest circumference", "ISO 7250-1 4.4.7", "large_girth", "m", "chestcircumference",
       "horizontal girth of the trunk (arms excluded) at the level of the nipples (thelion)"),
    _D("waist_circumference", "Waist circumference", "ISO 7250-1 4.4.8", "large_girth", "m", "waistcircumference",
       "narrowest horizontal girth of the trunk between 6 cm above the hip joints and 5 cm below the chest level"),
    _D("hip_circumference", "Hip circumference", "ISO 8559-1 (hip girth)", "large_girth", "m",
       "buttockcircumference", "largest horizontal girth of the hips and buttocks, 15 cm below to 5 cm above "
       "the hip joints"),
    _D("thigh_circumference", "Thigh circumference", "ISO 7250-1 4.4.10", "small_girth", "m", "thighcircumference",
       "horizontal girth of the thigh 2 cm below the crotch (below the gluteal furrow), mean of both sides"),
    _D("upper_arm_circumference", "Upper-arm circumference", "ISO 8559-1 (upper arm girth)", "small_girth", "m",
       None, "girth of the upper arm perpendicular to its axis, midway between acromion and olecranon, mean of "
       "both sides (ANSUR measures it flexed: not comparable)"),
    _D("arm_span", "Arm span", "ANSUR II span (no ISO 7250-1 clause)", "length", "m", "span",
       "fingertip to fingertip, arms horizontal and elbows straight"),
    _D("mass", "Body mass", "ISO 7250-1 4.1.1", "mass", "kg", "weightkg",
       "enclosed volume of the mesh × 980 kg/m³"),
    _D("bmi", "Body mass index", "mass / stature² (from 4.1.1 and 4.1.2)", "index", "kg/m²", "bmi",
       "body mass divided by the square of stature"),
)
del _D

ISO_NAMES: tuple[str, ...] = tuple(d.name for d in DEFINITIONS)


@dataclass(frozen=True)
class IsoMeasurement:
    """What :func:`measure_iso` found: ``values`` {name: SI value}, ``points`` {landmark: (3,)}
    and ``lines`` {name: (N, 3) polyline} (girth rings, lengths, breadths) to draw."""

    values: dict
    points: dict
    lines: dict


# ----------------------------------------------------------------------------- geometry
def _frame(normal: np.ndarray) -> np.ndarray:
    """(3, 3) rows: two unit vectors spanning the plane ⟂ ``normal``, then the normal."""
    n = normal / np.linalg.norm(normal)
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(n, a)
    u /= np.linalg.norm(u)
    return np.stack([u, np.cross(n, u), n])


def plane_section(vertices: np.ndarray, faces: np.ndarray, origin, normal) -> tuple[float, np.ndarray]:
    """Convex-hull perimeter (metres) of the section of the mesh ``faces`` by the plane through
    ``origin`` with ``normal``, and the hull ring (N, 3) in world coordinates (empty when the
    plane misses the mesh). A tape measure around the section (thesis §6.4.4)."""
    from scipy.spatial import ConvexHull

    from studio.body.measure import slice_points

    R = _frame(np.asarray(normal, dtype=np.float64))
    o = np.asarray(origin, dtype=np.float64)
    local = (np.asarray(vertices, dtype=np.float64) - o) @ R.T
    pts = slice_points(local, faces, 0.0)
    if len(pts) < 3:
        return 0.0, np.zeros((0, 3))
    ring = pts[ConvexHull(pts).vertices]
    per = float(np.linalg.norm(ring - np.roll(ring, 1, axis=0), axis=1).sum())
    return per, np.column_stack([ring, np.zeros(len(ring))]) @ R + o


def _horizontal_scan(v, faces, z0, z1, pick, step=0.005):
    """The horizontal section between ``z0`` and ``z1`` (every ``step``) whose girth is the
    ``pick`` (np.argmax / np.argmin) of all non-empty ones: (girth, ring, z). Bounds that cross
    (``z0 > z1``: an extreme body, e.g. the neck's, shoulder height + 3 cm above the head top
    − 15 cm) give the one plane halfway between them."""
    from studio.body.measure import _edges, convex_perimeter, slice_points

    zs = np.arange(z0, z1 + 1e-9, step)
    if not len(zs):
        z0 = z1 = 0.5 * (z0 + z1)
        zs = np.array([z0])
    e = _edges(faces)
    lo = np.minimum(v[e[:, 0], 2], v[e[:, 1], 2])
    hi = np.maximum(v[e[:, 0], 2], v[e[:, 1], 2])
    e = e[(hi >= z0) & (lo <= z1)]
    c = np.array([convex_perimeter(slice_points(v, faces, z, e)) for z in zs])
    if not np.any(c > 0):
        return 0.0, np.zeros((0, 3)), float(zs[0])
    c_pick = np.where(c > 0, c, np.inf if pick is np.argmin else -np.inf)
    z = float(zs[pick(c_pick)])
    per, ring = plane_section(v, faces, [0.0, 0.0, z], [0.0, 0.0, 1.0])
    return per, ring, z


# ----------------------------------------------------------------------------- landmarks
def _landmark_rules(v: np.ndarray, parts: np.ndarray, J: np.ndarray) -> dict[str, int]:
    """Vertex index of every landmark (module doc) on a default-pose mesh ``v`` (V, 3)."""
    idx = np.arange(len(v))
    out = {}
    head = idx[parts == _P["head"]]
    out["vertex"] = int(head[np.argmax(v[head, 2])])
    sh_z = float(0.5 * (J[_P["upperarm_l"], 2] + J[_P["upperarm_r"], 2]))
    knee_z = float(0.5 * (J[_P["lowerleg_l"], 2] + J[_P["lowerleg_r"], 2]))
    mid = idx[(np.abs(v[:, 0]) < 0.015) & (v[:, 2] > knee_z) & (v[:, 2] < sh_z)
              & np.isin(parts, [_P["pelvis"], _P["upperleg_l"], _P["upperleg_r"]])]
    out["crotch"] = int(mid[np.argmin(v[mid, 2])])
    nose = head[np.argmin(v[head, 1])]
    front = head[v[head, 1] < v[head, 1].min() + 0.06]
    for side, sign in (("l", 1.0), ("r", -1.0)):
        target = np.array([sign * 0.045, v[nose, 1], v[nose, 2] + 0.035])
        d = v[front] - target
        d[:, 1] *= 0.2  # depth matters less than position on the face
        out[f"exocanthion_{side}"] = int(front[np.argmin(np.linalg.norm(d, axis=1))])
        S, E, W = J[_P[f"upperarm_{side}"]], J[_P[f"lowerarm_{side}"]], J[_P[f"hand_{side}"]]
        cand = idx[np.isin(parts, [_P["torso"], _P[f"upperarm_{side}"]]) & (np.abs(v[:, 1] - S[1]) < 0.025)
                   & (sign * (v[:, 0] - S[0]) > 0.0)]
        out[f"acromion_{side}"] = int(cand[np.argmax(v[cand, 2])])
        du = (E - S) / np.linalg.norm(E - S)
        cand = idx[np.isin(parts, [_P[f"upperarm_{side}"], _P[f"lowerarm_{side}"]])
                   & (np.linalg.norm(v - E, axis=1) < 0.06)]
        out[f"olecranon_{side}"] = int(cand[np.argmax((v[cand] - E) @ du)])
        df = (W - E) / np.linalg.norm(W - E)
        cand = idx[parts == _P[f"lowerarm_{side}"]]
        out[f"stylion_{side}"] = int(cand[np.argmax((v[cand] - E) @ df)])
        sh = J[_P[f"upperarm_{side}"], 2]
        cand = idx[(parts == _P["torso"]) & (sign * v[:, 0] > 0.05) & (sign * v[:, 0] < 0.13)
                   & (v[:, 2] > sh - 0.28) & (v[:, 2] < sh - 0.08)]
        out[f"thelion_{side}"] = int(cand[np.argmin(v[cand, 1])])
        K = J[_P[f"lowerleg_{side}"]]
        cand = idx[np.isin(parts, [_P[f"upperleg_{side}"], _P[f"lowerleg_{side}"]]) & (np.abs(v[:, 2] - K[2]) < 0.015)]
        out[f"tibiale_{side}"] = int(cand[np.argmin(sign * v[cand, 0])])
    return out


@lru_cache(maxsize=1)
def template_landmarks() -> dict[str, int]:
    """{landmark: vertex index} on the model topology (module doc), chosen on the neutral
    model's mean body in the default pose (all genders share the topology)."""
    from studio.body.model import BodyModel

    m = BodyModel.load("neutral")
    v = m.vertices(m.mean_shape())
    return _landmark_rules(v, np.asarray(m.parts), m.joints(m.mean_shape()))


# ----------------------------------------------------------------------------- measurements
def measure_iso(vertices, tpose_vertices, joints, faces, parts, face_parts, *, density: float = 980.0,
                landmarks: dict | None = None) -> IsoMeasurement:
    """Every measurement of :data:`DEFINITIONS` on one body (shapes and frames as in
    :func:`studio.body.measure.measure_mesh`, which validates them): ``vertices`` (V, 3) in the
    default standing pose on the floor, ``tpose_vertices`` (V, 3) the same body with arms
    horizontal (arm span), ``joints`` (15, 3), ``faces`` (F, 3), ``parts`` (V,), ``face_parts``
    (F,). ``landmarks`` defaults to :func:`template_landmarks`."""
    v, vt, J, f = vertices, tpose_vertices, joints, faces
    L = template_landmarks() if landmarks is None else landmarks
    pt = {k: v[i] for k, i in L.items()}
    floor = float(v[:, 2].min())
    vals: dict[str, float] = {}
    lines: dict[str, np.ndarray] = {}

    def mean_sides(fn):
        return float(np.mean([fn(s) for s in ("l", "r")]))

    top = int(np.argmax(v[:, 2]))
    pt["vertex"] = v[top]
    vals["stature"] = float(v[top, 2] - floor)
    vals["eye_height"] = mean_sides(lambda s: pt[f"exocanthion_{s}"][2]) - floor
    vals["shoulder_height"] = mean_sides(lambda s: pt[f"acromion_{s}"][2]) - floor

    def upper_axis(s):
        a, b = J[_P[f"upperarm_{s}"]], J[_P[f"lowerarm_{s}"]]
        return (b - a) / np.linalg.norm(b - a)

    vals["shoulder_elbow_length"] = mean_sides(lambda s: (pt[f"olecranon_{s}"] - pt[f"acromion_{s}"]) @ upper_axis(s))
    vals["elbow_height"] = vals["shoulder_height"] - vals["shoulder_elbow_length"]
    vals["elbow_wrist_length"] = mean_sides(lambda s: np.linalg.norm(pt[f"stylion_{s}"] - pt[f"olecranon_{s}"]))
    vals["knee_height"] = mean_sides(lambda s: pt[f"tibiale_{s}"][2]) - floor
    vals["biacromial_breadth"] = float(np.linalg.norm(pt["acromion_l"] - pt["acromion_r"]))
    for s in ("l", "r"):
        lines[f"shoulder_elbow_length_{s}"] = np.stack([pt[f"acromion_{s}"], pt[f"olecranon_{s}"]])
        lines[f"elbow_wrist_length_{s}"] = np.stack([pt[f"olecranon_{s}"], pt[f"stylion_{s}"]])
    lines["biacromial_breadth"] = np.stack([pt["acromion_l"], pt["acromion_r"]])

    hip_z = float(0.5 * (J[_P["upperleg_l"], 2] + J[_P["upperleg_r"], 2]))
    crotch_z = float(pt["crotch"][2])
    vals["crotch_height"] = crotch_z - floor

    hips = np.isin(parts, [_P["pelvis"], _P["upperleg_l"], _P["upperleg_r"]]) & (v[:, 2] < hip_z + 0.05)
    hips &= v[:, 2] > crotch_z
    if np.any(hips):
        il, ir = np.flatnonzero(hips)[[np.argmax(v[hips, 0]), np.argmin(v[hips, 0])]]
        vals["hip_breadth"] = float(v[il, 0] - v[ir, 0])
        zc = 0.5 * (v[il, 2] + v[ir, 2])
        lines["hip_breadth"] = np.array([[v[il, 0], v[il, 1], zc], [v[ir, 0], v[ir, 1], zc]])
    else:
        vals["hip_breadth"] = float("nan")

    torso_f = f[face_parts == _P["torso"]]
    trunk_f = f[np.isin(face_parts, [_P["torso"], _P["pelvis"]])]
    hips_f = f[np.isin(face_parts, [_P["pelvis"], _P["upperleg_l"], _P["upperleg_r"]])]
    chest_z = float(0.5 * (pt["thelion_l"][2] + pt["thelion_r"][2]))
    vals["chest_circumference"], ring = plane_section(v, torso_f, [0, 0, chest_z], [0, 0, 1])
    lines["chest_circumference"] = ring
    vals["chest_depth"] = float(np.ptp(ring[:, 1])) if len(ring) else float("nan")
    if len(ring):
        x = float(np.mean(ring[:, 0]))
        lines["chest_depth"] = np.array([[x, ring[:, 1].min(), chest_z], [x, ring[:, 1].max(), chest_z]])
    vals["waist_circumference"], lines["waist_circumference"], _ = _horizontal_scan(
        v, trunk_f, hip_z + 0.06, chest_z - 0.05, np.argmin)
    vals["hip_circumference"], lines["hip_circumference"], _ = _horizontal_scan(
        v, hips_f, hip_z - 0.15, hip_z + 0.05, np.argmax)
    neck_f = f[np.isin(face_parts, [_P["torso"], _P["head"]])]
    vals["neck_circumference"], lines["neck_circumference"], _ = _horizontal_scan(
        v, neck_f, vals["shoulder_height"] + floor + 0.03, float(v[top, 2]) - 0.15, np.argmin)

    def thigh(s):
        sign = 1.0 if s == "l" else -1.0
        side_f = hips_f[np.all(sign * v[hips_f][:, :, 0] > 0, axis=1)]
        per, ring = plane_section(v, side_f, [0, 0, crotch_z - 0.02], [0, 0, 1])
        lines[f"thigh_circumference_{s}"] = ring
        return per

    vals["thigh_circumference"] = mean_sides(thigh)

    def upper_arm(s):
        a, o = pt[f"acromion_{s}"], pt[f"olecranon_{s}"]
        per, ring = plane_section(v, f[face_parts == _P[f"upperarm_{s}"]], 0.5 * (a + o), upper_axis(s))
        lines[f"upper_arm_circumference_{s}"] = ring
        return per

    vals["upper_arm_circumference"] = mean_sides(upper_arm)
    il, ir = int(np.argmax(vt[:, 0])), int(np.argmin(vt[:, 0]))
    vals["arm_span"] = float(vt[il, 0] - vt[ir, 0])
    from studio.body.measure import mesh_volume

    vals["mass"] = float(mesh_volume(v, f)) * density
    vals["bmi"] = vals["mass"] / vals["stature"] ** 2
    lines["stature"] = np.array([[pt["vertex"][0], pt["vertex"][1], floor], pt["vertex"]])
    return IsoMeasurement({n: float(vals[n]) for n in ISO_NAMES}, {k: np.asarray(p) for k, p in pt.items()}, lines)
