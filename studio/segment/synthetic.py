"""A tiny synthetic multi-view scene with known labels (test kit for segmentation).

Cameras on a ring look at a textured floor (z = 0); a box-shaped "person" (legs, torso,
head) stands on it and a point light casts its shadow onto the floor. Rendering is exact
ray casting (rays / floor and rays / boxes), so every pixel's true label is known:
0 background, 1 person, 2 shadow; skin is the head box.

>>> scene = SyntheticScene.build(n_cameras=3, size=(160, 120), seed=0)
>>> frame, truth, skin = scene.render(seed=1)
>>> sorted(frame), frame["cam0"].shape, truth["cam0"].dtype.name
(['cam0', 'cam1', 'cam2'], (120, 160, 3), 'uint8')
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["SyntheticScene", "Box", "ring_calibration", "write_session"]


@dataclass(frozen=True)
class Box:
    """Axis-aligned box ``lo`` … ``hi`` (metres) with an RGB colour (0–255)."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    color: tuple[int, int, int]
    skin: bool = False


def ring_calibration(n_cameras: int, size: tuple[int, int], radius: float = 3.2, height: float = 2.0):
    """``RigCalibration`` of ``n_cameras`` on a ring, looking at (-0.3, -0.2, 0.6), floor z = 0."""
    from calibration.ground import GroundPlane
    from calibration.rig import RigCalibration
    from calibration.synthetic import camera_ring

    cams = camera_ring(n_cameras, radius=radius, height=height, target=(-0.3, -0.2, 0.6), size=size,
                       focal=1.1 * size[0], dist=np.zeros(5), start=0.3,
                       names=[f"cam{i}" for i in range(n_cameras)], principal_offset=(0.0, 0.0))
    return RigCalibration(cams, GroundPlane.floor())


def _ray_box(o: np.ndarray, d: np.ndarray, box: Box) -> np.ndarray:
    """Ray parameter of the first hit of rays o + s d with ``box`` (inf where missed)."""
    lo, hi = np.asarray(box.lo), np.asarray(box.hi)
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - o) / d
        t2 = (hi - o) / d
    tmin = np.nanmax(np.minimum(t1, t2), axis=1)
    tmax = np.nanmin(np.maximum(t1, t2), axis=1)
    hit = (tmax >= np.maximum(tmin, 0)) & (tmax > 0)
    return np.where(hit, np.maximum(tmin, 0), np.inf)


def _floor_color(xy: np.ndarray) -> np.ndarray:
    """Smoothly varying saturated floor colour (N, 3) float in 0–255."""
    x, y = xy[:, 0], xy[:, 1]
    base = np.array([150.0, 135.0, 95.0])
    var = 18 * np.sin(3.1 * x)[:, None] * np.array([1.0, 0.6, 0.2]) + 14 * np.cos(2.3 * y)[
        :, None
    ] * np.array([0.3, 1.0, 0.5])
    tiles = ((np.floor(x / 0.5) + np.floor(y / 0.5)) % 2)[:, None] * np.array([-20.0, -15.0, 10.0])
    return base + var + tiles


@dataclass
class SyntheticScene:
    """Calibrated ring of cameras, floor texture, box person and a point light."""

    calibration: object
    boxes: list[Box]
    light: np.ndarray
    shadow_factor: float = 0.55
    noise: float = 2.0
    _rays: dict = field(default_factory=dict, repr=False)

    @classmethod
    def build(
        cls,
        n_cameras: int = 4,
        size: tuple[int, int] = (160, 120),
        *,
        torso_color: tuple[int, int, int] = (40, 90, 170),
        light: tuple[float, float, float] = (2.5, 1.0, 3.0),
        position: tuple[float, float] = (0.0, 0.0),
        seed: int = 0,
    ) -> "SyntheticScene":
        """A scene; ``torso_color`` dark and grey mimics the torso-as-shadow case of fig. 5.3."""
        px, py = position
        boxes = [
            Box((px - 0.15, py - 0.1, 0.0), (px + 0.15, py + 0.1, 0.85), (150, 30, 40)),
            Box((px - 0.2, py - 0.12, 0.85), (px + 0.2, py + 0.12, 1.5), tuple(torso_color)),
            Box((px - 0.09, py - 0.09, 1.5), (px + 0.09, py + 0.09, 1.75), (200, 150, 120), True),
        ]
        return cls(ring_calibration(n_cameras, size), boxes, np.asarray(light, float))

    def _camera_rays(self, name: str):
        if name not in self._rays:
            cam = self.calibration[name]
            w, h = cam.size
            u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
            o, d = cam.pixel_rays(np.stack([u.ravel(), v.ravel()], axis=1))
            self._rays[name] = (o, d)
        return self._rays[name]

    def _in_shadow(self, X: np.ndarray) -> np.ndarray:
        """(N,) bool: floor points whose segment to the light hits a box."""
        d = self.light - X
        out = np.zeros(len(X), bool)
        for box in self.boxes:
            s = _ray_box(X, d, box)
            out |= s < 1.0
        return out

    def render(self, seed: int = 0, person: bool = True):
        """One multi-frame: ``({cam: RGB uint8}, {cam: labels uint8}, {cam: skin bool})``."""
        rng = np.random.default_rng(seed)
        frames, labels, skins = {}, {}, {}
        for name in self.calibration.camera_names:
            cam = self.calibration[name]
            w, h = cam.size
            o, d = self._camera_rays(name)
            s_floor = np.where(d[:, 2] < 0, -o[:, 2] / np.where(d[:, 2] < 0, d[:, 2], -1), np.inf)
            X = o + np.where(np.isfinite(s_floor), s_floor, 0)[:, None] * d
            color = _floor_color(X[:, :2])
            color[~np.isfinite(s_floor)] = (90, 110, 130)  # far wall
            lab = np.zeros(len(d), np.uint8)
            skin = np.zeros(len(d), bool)
            if person:
                shadow = np.isfinite(s_floor) & self._in_shadow(X)
                color[shadow] *= self.shadow_factor
                lab[shadow] = 2
                best = np.full(len(d), np.inf)
                for box in self.boxes:
                    s = _ray_box(o, d, box)
                    hit = (s < best) & (s < s_floor)
                    best[hit] = s[hit]
                    color[hit] = box.color
                    lab[hit] = 1
                    skin[hit] = box.skin
            color = color + rng.normal(0, self.noise, color.shape)
            frames[name] = np.clip(np.round(color), 0, 255).astype(np.uint8).reshape(h, w, 3)
            labels[name] = lab.reshape(h, w)
            skins[name] = skin.reshape(h, w)
        return frames, labels, skins

    def backgrounds(self, n: int = 8, seed: int = 100) -> dict[str, list[np.ndarray]]:
        """``n`` noisy empty-scene frames per camera."""
        out: dict[str, list[np.ndarray]] = {c: [] for c in self.calibration.camera_names}
        for i in range(n):
            frames, _, _ = self.render(seed=seed + i, person=False)
            for c, f in frames.items():
                out[c].append(f)
        return out


def write_session(
    path,
    *,
    n_cameras: int = 3,
    size: tuple[int, int] = (96, 72),
    frames: int = 3,
    backgrounds: int = 4,
    torso_color: tuple[int, int, int] = (60, 58, 52),
    seed: int = 0,
):
    """Write a capture session of the box scene (person walking along x) with truth.

    Truth follows the simulator's layout: ``truth/labels/<cam>/NNNNNN.png`` (0/1/2) and
    ``truth/skin/<cam>/NNNNNN.png`` (0/255). Returns the session path.
    """
    from pathlib import Path

    from rigs.imageio import write_image
    from rigs.session import SessionWriter
    from studio.workspace import Layout

    path = Path(path)
    lay = Layout(path)
    scene = SyntheticScene.build(n_cameras, size, torso_color=torso_color, seed=seed)
    calib = scene.calibration
    calib_file = path.parent / f".{path.name}-calibration.json"
    calib.save(calib_file)
    writer = SessionWriter.create(path, list(calib.camera_names), rig="box-scene", calibration=calib_file)
    calib_file.unlink()
    with writer:
        for i, (cam, images) in enumerate(sorted(scene.backgrounds(backgrounds, seed=seed + 1000).items())):
            for k, image in enumerate(images):
                writer.write_background(cam, k, image)
        for index in range(frames):
            moved = SyntheticScene.build(
                n_cameras, size, torso_color=torso_color, position=(0.15 * index - 0.15, 0.0)
            )
            moved._rays = scene._rays
            images, labels, skins = moved.render(seed=seed + index)
            writer.write_frame(index, images)
            for cam in images:
                for target, array in ((lay.truth_labels(cam, index), labels[cam]), (lay.truth_skin(cam, index), skins[cam])):
                    target.parent.mkdir(parents=True, exist_ok=True)
                    write_image(target, array)
    return path
