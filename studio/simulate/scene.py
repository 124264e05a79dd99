"""The simulated studio: camera ring, floor and backdrop, lights, the person's appearance.

Everything here is numpy/OpenCV (no torch/anny). Radiance is linear RGB in [0, ~1]; the
sensor model (:mod:`studio.simulate.sensor`) turns it into 8-bit frames.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from calibration import Camera, GroundPlane, RigCalibration
from studio.render import PointLight, light_from_dict, rasterize, shade_raster, shadow_mask, vertex_normals
from studio.simulate.garments import adjust_labels, drape, garment_offsets, skirt_mesh
from studio.simulate.props import stool_mesh
from studio.simulate.spec import SimSpec, SpecError

__all__ = [
    "Body",
    "Scene",
    "FrameRender",
    "load_body",
    "ring_cameras",
    "skin_tone_rgb",
    "srgb_to_linear",
]

log = logging.getLogger(__name__)

#: Skin tones (sRGB 0-255) from very light to very dark, interpolated by ``skin_tone``.
SKIN_TONES = np.array(
    [[246, 214, 190], [234, 189, 157], [214, 160, 120], [184, 126, 88], [141, 90, 62], [94, 60, 44]],
    dtype=np.float64,
)


def srgb_to_linear(rgb) -> np.ndarray:
    """sRGB 0-255 (…, 3) → linear reflectance in [0, 1]."""
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def skin_tone_rgb(tone: float) -> np.ndarray:
    """sRGB (3,) of a skin tone in [0, 1] (0 very light … 1 very dark)."""
    x = float(np.clip(tone, 0.0, 1.0)) * (len(SKIN_TONES) - 1)
    i = min(int(x), len(SKIN_TONES) - 2)
    f = x - i
    return (1 - f) * SKIN_TONES[i] + f * SKIN_TONES[i + 1]


# --------------------------------------------------------------------------- cameras
def ring_cameras(cfg: dict, rng: np.random.Generator | None = None) -> list[Camera]:
    """Cameras on a ring around the capture volume (spec ``cameras`` section).

    ``count`` cameras at ``radius`` and ``height`` spread over ``span_deg`` from
    ``start_deg``, looking at ``look_at``; ``jitter_deg`` perturbs the azimuths and the
    principal points a little (seeded) so the rig is not perfectly symmetric.
    """
    n = cfg["count"]
    names = cfg["names"] or [f"cam{i}" for i in range(n)]
    rng = rng or np.random.default_rng(0)
    span = float(cfg["span_deg"])
    step = span / n if abs(span - 360.0) < 1e-9 else (span / max(n - 1, 1))
    cams = []
    for i in range(n):
        az = math.radians(cfg["start_deg"] + i * step + rng.uniform(-1, 1) * cfg["jitter_deg"])
        r = cfg["radius"] * (1.0 + 0.03 * rng.uniform(-1, 1))
        C = [r * math.cos(az), r * math.sin(az), cfg["height"] + 0.05 * rng.uniform(-1, 1)]
        target = np.asarray(cfg["look_at"], dtype=np.float64) + rng.uniform(-0.05, 0.05, 3)
        f = cfg["focal_px"] * (1.0 + 0.01 * rng.uniform(-1, 1))
        cams.append(Camera.look_at(names[i], C, target, f, cfg["size"], cfg["dist"]))
    return cams


# --------------------------------------------------------------------------- body
@dataclass(frozen=True)
class Body:
    """A true body sequence: vertices (T, V, 3) float32 world metres, faces, per-vertex data."""

    vertices: np.ndarray
    faces: np.ndarray
    parts: np.ndarray
    part_names: tuple[str, ...]
    rest_height: np.ndarray
    extra: dict

    @property
    def frame_count(self) -> int:
        return len(self.vertices)


def load_body(path: str | Path) -> Body:
    """Read a ``body.npz`` written by ``studio simulate build-truth``."""
    path = Path(path)
    if not path.is_file():
        raise SpecError(
            f"{path}: body file missing (build it with `studio simulate build-truth`)"
        )
    with np.load(path, allow_pickle=False) as z:
        missing = {"vertices_q", "scale", "faces", "parts", "part_names"} - set(z.files)
        if missing:
            raise SpecError(f"{path}: not a body file, missing {sorted(missing)}")
        V = (z["vertices_q"].astype(np.float32) * np.float32(z["scale"]))
        extra = {k: z[k] for k in z.files if k not in ("vertices_q", "faces", "parts", "part_names")}
        rest_h = z["rest_height"].astype(np.float32) if "rest_height" in z.files else None
        F = z["faces"].astype(np.int32)
        parts = z["parts"].astype(np.uint8)
        names = tuple(str(s) for s in z["part_names"])
    if rest_h is None:
        rest_h = np.zeros(V.shape[1], np.float32)
    return Body(V, F, parts, names, rest_h, extra)


# --------------------------------------------------------------------------- appearance
#: Linear albedo of the stool (a mid-grey lacquered wood).
STOOL_ALBEDO = np.array([0.30, 0.22, 0.15])

LABEL_SKIN, LABEL_TOP, LABEL_BOTTOM, LABEL_SHOES, LABEL_HAIR = range(5)


def clothing_labels(body: Body, person: dict, V0: np.ndarray) -> np.ndarray:
    """Per-vertex material (V,) uint8: skin, top, bottom, shoes, hair (``LABEL_*``)."""
    P = {n: i for i, n in enumerate(body.part_names)}
    parts = body.parts
    h = body.rest_height
    lab = np.full(len(parts), LABEL_SKIN, np.uint8)

    def isin(*names):
        return np.isin(parts, [P[n] for n in names])

    arms_up = isin("upperarm_l", "upperarm_r")
    arms_lo = isin("lowerarm_l", "lowerarm_r")
    trunk = isin("torso", "pelvis") | isin("upperleg_l", "upperleg_r")
    waist = 0.575
    top = isin("torso") & (h > waist)
    sleeves = person["top"]["sleeves"]
    if sleeves in ("short", "long"):
        top |= arms_up & ((h > 0.70) if sleeves == "short" else True)
    if sleeves == "long":
        top |= arms_lo
    bottom = (trunk & (h <= waist)) | isin("upperleg_l", "upperleg_r")
    if person["bottom"]["length"] == "long":
        bottom |= isin("lowerleg_l", "lowerleg_r")
    else:
        bottom |= isin("lowerleg_l", "lowerleg_r") & (h > 0.24)
    lab[top] = LABEL_TOP
    lab[bottom] = LABEL_BOTTOM
    lab = adjust_labels(lab, parts, P, h, person, LABEL_SKIN, LABEL_TOP, LABEL_BOTTOM)
    lab[isin("foot_l", "foot_r")] = LABEL_SHOES
    # hair: a cap, the head vertices within 7.5 cm of the top of the head in the first frame
    head = isin("head")
    if head.any():
        hv = V0[head]
        top_z = hv[:, 2].max()
        lab[head & (V0[:, 2] > top_z - 0.075)] = LABEL_HAIR
    return lab


def person_albedo(labels: np.ndarray, person: dict, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """Per-vertex linear albedo (V, 3) and the skin tone used (drawn when unset)."""
    tone = person["skin_tone"]
    if tone is None:
        tone = float(rng.beta(2.0, 2.5))
    colours = {
        LABEL_SKIN: skin_tone_rgb(tone),
        LABEL_TOP: np.asarray(person["top"]["color"], np.float64),
        LABEL_BOTTOM: np.asarray(person["bottom"]["color"], np.float64),
        LABEL_SHOES: np.asarray(person["shoes"], np.float64),
        LABEL_HAIR: np.asarray(person["hair"], np.float64),
    }
    srgb = np.zeros((len(labels), 3))
    for k, c in colours.items():
        srgb[labels == k] = c
    # fabric/skin texture: small per-vertex variation in brightness
    srgb *= 1.0 + 0.06 * rng.standard_normal((len(labels), 1))
    return srgb_to_linear(np.clip(srgb, 0, 255)), float(tone)


def dress(V: np.ndarray, F: np.ndarray, labels: np.ndarray, looseness, normals=None) -> np.ndarray:
    """Loose garments: move clothed vertices out along their normals by ``looseness`` metres
    (one value for every clothed vertex, or per vertex (V,) as :func:`garment_offsets` gives);
    ``normals``: the posed vertex normals when the caller has them already."""
    amount = np.asarray(looseness, dtype=np.float64)
    if amount.ndim == 0:
        amount = np.where(np.isin(labels, [LABEL_TOP, LABEL_BOTTOM]), float(amount), 0.0)
    if not np.any(amount > 0):
        return V
    N = vertex_normals(V, F) if normals is None else normals
    return (V + N * amount[:, None]).astype(V.dtype)


# --------------------------------------------------------------------------- studio
def _floor_texture(xy: np.ndarray, studio: dict) -> np.ndarray:
    """Linear albedo (N, 3) of the floor at world points (N, 2): tiles, grout, mottling."""
    t = studio["tile_size"]
    base = np.asarray(studio["floor_albedo"], np.float64)
    u = xy / t
    frac = u - np.floor(u)
    grout = np.any((frac < 0.02) | (frac > 0.98), axis=1)
    tile_id = np.floor(u).astype(np.int64)
    hsh = ((tile_id[:, 0] * 73856093) ^ (tile_id[:, 1] * 19349663)) % 1000 / 1000.0
    mott = 0.06 * np.sin(7.3 * xy[:, 0] + 2.1 * np.sin(5.1 * xy[:, 1])) * np.cos(6.1 * xy[:, 1])
    a = base[None, :] * (0.92 + 0.12 * hsh[:, None] + mott[:, None])
    a[grout] *= 0.55
    return np.clip(a, 0.0, 1.0)


def _wall_texture(pts: np.ndarray, studio: dict) -> np.ndarray:
    """Backdrop cloth albedo (N, 3): vertical folds and a little noise."""
    base = np.asarray(studio["backdrop_albedo"], np.float64)
    s = pts[:, 0] + pts[:, 1]
    folds = 0.07 * np.sin(9.0 * s) + 0.03 * np.sin(23.0 * s + 1.3)
    return np.clip(base[None, :] * (1.0 + folds[:, None]), 0.0, 1.0)


@dataclass(frozen=True)
class Backdrop:
    """Per-camera linear radiance of the empty studio, split by light for shadows.

    ``ambient`` (H, W, 3), ``direct`` list per light of (H, W, 3), ``floor`` (H, W) bool.
    """

    ambient: np.ndarray
    direct: list
    floor: np.ndarray

    def radiance(self, lit: list[np.ndarray] | None = None) -> np.ndarray:
        """Radiance (H, W, 3) with each light's direct term scaled by ``lit[l]`` (H, W) in [0, 1]."""
        out = self.ambient.copy()
        for k, d in enumerate(self.direct):
            out += d if lit is None else d * lit[k][..., None]
        return out


def render_backdrop(camera: Camera, studio: dict, lights, ambient: float) -> Backdrop:
    """Ray-cast the floor (z = 0) and the backdrop walls of a square room for every pixel."""
    w, h = camera.size
    ys, xs = np.mgrid[0:h, 0:w]
    uv = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float64)
    o, d = camera.pixel_rays(uv)
    half = float(studio["room_half"])
    big = 1e9
    # floor hit
    tf = np.where(d[:, 2] < -1e-9, -o[:, 2] / np.where(d[:, 2] < -1e-9, d[:, 2], 1.0), big)
    # walls x = ±half, y = ±half (inside the room)
    tw = np.full(len(d), big)
    wall_n = np.zeros((len(d), 3))
    for axis in (0, 1):
        for sgn in (-1.0, 1.0):
            den = d[:, axis]
            ok = sgn * den > 1e-9
            t = np.where(ok, (sgn * half - o[:, axis]) / np.where(ok, den, 1.0), big)
            better = ok & (t > 0) & (t < tw)
            tw = np.where(better, t, tw)
            n = np.zeros(3)
            n[axis] = -sgn
            wall_n[better] = n
    on_floor = tf < tw
    t = np.where(on_floor, tf, tw)
    P = o + t[:, None] * d
    N = np.where(on_floor[:, None], [0.0, 0.0, 1.0], wall_n)
    albedo = np.where(on_floor[:, None], _floor_texture(P[:, :2], studio), _wall_texture(P, studio))
    ceiling = (~on_floor) & (P[:, 2] > studio["wall_height"])
    albedo[ceiling] = 0.05
    amb = (albedo * ambient).reshape(h, w, 3).astype(np.float32)
    direct = []
    for light in lights:
        ldir, scale = light.directions_to(P)
        e = np.maximum(np.einsum("ij,ij->i", N, ldir), 0.0) * scale
        direct.append((albedo * e[:, None]).reshape(h, w, 3).astype(np.float32))
    return Backdrop(amb, direct, on_floor.reshape(h, w))


# --------------------------------------------------------------------------- the scene
@dataclass(frozen=True)
class FrameRender:
    """One camera's render of one frame: linear radiance and truth masks.

    ``radiance`` (H, W, 3) float32 linear; ``labels`` (H, W) uint8 (0 background, 1 person,
    2 shadow); ``skin`` (H, W) bool visible skin.
    """

    radiance: np.ndarray
    labels: np.ndarray
    skin: np.ndarray


class Scene:
    """Cameras, lights, studio and the dressed person of a spec, ready to render frames."""

    def __init__(self, spec: SimSpec, seed: int | None = None):
        self.spec = spec
        self.seed = int(spec["seed"] if seed is None else seed)
        rng = np.random.default_rng([self.seed, 1])
        self.cameras = ring_cameras(spec["cameras"], rng)
        self.ground = GroundPlane.floor()
        self.lights = [light_from_dict(d, f"lights[{i}]") for i, d in enumerate(spec["lights"])]
        self.ambient = float(spec["ambient"])
        self.body = load_body(spec.body_path)
        frames = spec["frames"]
        T = self.body.frame_count
        start, stop = (0, T) if frames is None else frames
        if not 0 <= start < stop <= T:
            raise SpecError(f"{spec.path}: frames {frames} outside the body's 0..{T}")
        self.frame_range = range(start, stop)
        person = spec["person"]
        self.labels = clothing_labels(self.body, person, self.body.vertices[start])
        self.albedo, self.skin_tone = person_albedo(self.labels, person, rng)
        self.is_skin = self.labels == LABEL_SKIN
        self._backdrops: dict[str, Backdrop] = {}

    @property
    def calibration(self) -> RigCalibration:
        return RigCalibration({c.name: c for c in self.cameras}, self.ground,
                              {"source": "studio simulate", "spec": self.spec.name, "seed": self.seed})

    def backdrop(self, camera: Camera) -> Backdrop:
        if camera.name not in self._backdrops:
            self._backdrops[camera.name] = render_backdrop(
                camera, self.spec["studio"], self.lights, self.ambient)
        return self._backdrops[camera.name]

    def true_vertices(self, frame: int) -> np.ndarray:
        """(V, 3) float32 true (undressed) vertices of body frame ``frame``."""
        return self.body.vertices[frame]

    def dressed(self, frame: int) -> np.ndarray:
        """(V, 3) vertices of body frame ``frame`` with the garments on: each clothed vertex out
        along its normal by its garment's looseness times the posture's drape
        (:func:`studio.simulate.garments.drape`: cloth rests where the body carries it)."""
        person = self.spec["person"]
        offsets = garment_offsets(self.labels, self.body.rest_height, person, LABEL_TOP, LABEL_BOTTOM)
        V = self.body.vertices[frame].astype(np.float64)
        if not np.any(offsets > 0):
            return V
        normals = vertex_normals(V, self.body.faces)
        offsets = offsets * drape(normals, self.body.faces, self.labels, self.body.rest_height, LABEL_TOP, LABEL_BOTTOM)
        return dress(V, self.body.faces, self.labels, offsets, normals=normals)

    def skirt(self, frame: int) -> tuple[np.ndarray, np.ndarray] | None:
        """(vertices, faces) of the skirt of body frame ``frame``, or None (no skirt)."""
        person = self.spec["person"]
        if person["bottom"]["kind"] != "skirt":
            return None
        index = {n: i for i, n in enumerate(self.body.part_names)}
        return skirt_mesh(self.body.vertices[frame].astype(np.float64), self.body.parts, index,
                          self.body.rest_height, max(float(person["looseness"]), 0.01))

    @staticmethod
    def _light_penumbra_px(light, camera: Camera, V: np.ndarray) -> float:
        """Blur (pixels, Gaussian σ) of the shadow edge of an extended light.

        A light of radius ρ at height H casts, from an occluder at height h (half the
        body's height), a penumbra of width ρ h / (H − h) on the floor (a directional light
        of angular radius ρ: h tan ρ); it is converted to pixels at the body's distance.
        """
        if light.radius <= 0:
            return 0.0
        h = 0.5 * float(V[:, 2].max())
        if isinstance(light, PointLight):
            width = light.radius * h / max(float(light.position[2]) - h, 0.1)
        else:
            width = h * math.tan(light.radius)
        foot = np.array([*V[:, :2].mean(axis=0), 0.0])
        dist = float(np.linalg.norm(camera.center - foot))
        return float(camera.K[0, 0]) * width / dist / 2.0

    def render(self, frame: int, camera: Camera, dressed: np.ndarray | None = None,
               normals: np.ndarray | None = None) -> FrameRender:
        """Render body frame ``frame`` in ``camera``: radiance and truth masks.

        ``dressed`` (V, 3) and ``normals`` (V, 3) may be passed when rendering the same frame
        in several cameras (computed once per frame).
        """
        import cv2

        V = self.dressed(frame) if dressed is None else dressed
        F = self.body.faces
        albedo, is_skin = self.albedo, self.is_skin.astype(np.float32)
        if normals is None:
            normals = vertex_normals(V, F)
        skirt = self.skirt(frame)
        if skirt is not None:  # part of the person (label 1), never skin
            Vk, Fk = skirt
            F = np.concatenate([F, Fk + len(V)])
            normals = np.concatenate([normals, vertex_normals(Vk, Fk)])
            V = np.concatenate([V, Vk])
            colour = srgb_to_linear(np.asarray(self.spec["person"]["bottom"]["color"], np.float64))
            albedo = np.concatenate([albedo, np.broadcast_to(colour, (len(Vk), 3))])
            is_skin = np.concatenate([is_skin, np.zeros(len(Vk), np.float32)])
        n_person = len(F)
        stool = self.stool(frame)
        if stool is not None:  # the person and the stool are one scene: z-buffer and shadows
            Vs, Fs = stool
            F = np.concatenate([F, Fs + len(V)])
            normals = np.concatenate([normals, vertex_normals(Vs, Fs)])
            V = np.concatenate([V, Vs])
            albedo = np.concatenate([albedo, np.broadcast_to(STOOL_ALBEDO, (len(Vs), 3))])
            is_skin = np.concatenate([is_skin, np.zeros(len(Vs), np.float32)])
        bd = self.backdrop(camera)
        penumbra = float(self.spec["sensor"]["penumbra_px"])
        lit, shadow_any = [], np.zeros(bd.floor.shape, bool)
        for light in self.lights:
            sm = shadow_mask(camera, V, F, light, self.ground) & bd.floor
            shadow_any |= sm
            vis = 1.0 - sm.astype(np.float32)
            sigma = penumbra + self._light_penumbra_px(light, camera, V)
            if sigma > 0:
                vis = cv2.GaussianBlur(vis, (0, 0), sigma)
            lit.append(vis)
        img = bd.radiance(lit)
        ras = rasterize(camera, V, F)
        pix, rad = shade_raster(ras, V, F, normals, albedo, self.lights, self.ambient)
        flat = img.reshape(-1, 3)
        flat[pix] = rad
        covered = ras.mask
        labels = np.zeros(covered.shape, np.uint8)
        labels[shadow_any] = 2
        labels[covered] = 1
        if stool is not None:
            labels[covered & (ras.face >= n_person)] = 3
        face = ras.face.ravel()[pix]
        bary = ras.bary.reshape(-1, 3)[pix]
        skin_val = np.einsum("nk,nk->n", bary, is_skin[F[face]])
        skin = np.zeros(covered.size, bool)
        skin[pix] = skin_val > 0.5
        return FrameRender(img, labels, skin.reshape(covered.shape))

    def stool(self, frame: int) -> tuple[np.ndarray, np.ndarray] | None:
        """(vertices, faces) of the stool under body frame ``frame``, or None (no stool)."""
        props = self.body.extra.get("props")
        if props is None or not np.all(np.isfinite(props[frame])):
            return None
        x, y, top, radius = (float(v) for v in props[frame])
        return stool_mesh(x, y, top, radius)
