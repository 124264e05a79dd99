"""Light parameters as the thesis searches them (§5.7): ℓ = [γ, φ, r] around the subject.

γ is the azimuth in the ground plane and φ the elevation above it, seen from ``centre`` (the
subject's mean position on the floor); the thesis' third parameter is the light's height z, we
use its distance r = z / sin φ from the centre instead: the shadows fix the direction (γ, φ) much
better than the distance, and with r a step in either changes only one of the two (with z, a step
in φ at fixed height also moves the light along the ray, a ridge the grid refinement crawls
along). A point light is at ``centre + r u``; a directional light (at infinity) has only (γ, φ) and shines along the opposite of the
unit vector ``cos φ (cos γ e1 + sin γ e2) + sin φ n`` (which points from the scene towards it).
``(e1, e2, n)`` is the ground plane's frame (:meth:`calibration.GroundPlane.basis`).

>>> import numpy as np
>>> frame = Frame(np.zeros(3), None)
>>> light = to_light("point", np.radians([90.0, 45.0]).tolist() + [np.sqrt(18.0)], frame)
>>> np.round(light.position, 6).tolist()
[0.0, 3.0, 3.0]
>>> np.allclose(from_light(light, frame), [np.pi / 2, np.pi / 4, np.sqrt(18.0)])
True
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from studio.render.lights import DirectionalLight, PointLight

__all__ = ["Frame", "KINDS", "N_PARAMS", "above_bodies", "coarse_grid", "coarse_steps", "direction_of", "from_light",
           "param_bounds", "to_light"]

KINDS = ("point", "directional")
#: Parameters per light kind.
N_PARAMS = {"point": 3, "directional": 2}
#: Lowest and highest point-light height searched (m above the ground), lowest elevation (deg).
HEIGHT_RANGE = (2.0, 6.0)
#: Point-light distances from the subject searched (m).
DISTANCE_RANGE = (2.0, 12.0)
ELEVATION_RANGE_DEG = (10.0, 89.0)


@dataclass(frozen=True)
class Frame:
    """The subject's ``centre`` (3,) on the ground and the ground plane (None: floor z = 0)."""

    centre: np.ndarray
    ground: object = None

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.ground is None:
            return np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([0, 0, 1.0])
        _, e1, e2 = self.ground.basis()
        return e1, e2, np.asarray(self.ground.normal, dtype=np.float64)


def _unit(theta, frame: Frame) -> np.ndarray:
    e1, e2, n = frame.basis()
    g, p = float(theta[0]), float(theta[1])
    return np.cos(p) * (np.cos(g) * e1 + np.sin(g) * e2) + np.sin(p) * n


def to_light(kind: str, theta, frame: Frame) -> PointLight | DirectionalLight:
    """The light of parameters ``theta`` ([γ, φ, r] point, [γ, φ] directional; radians, m)."""
    u = _unit(theta, frame)
    if kind == "point":
        return PointLight(np.asarray(frame.centre, float) + u * float(theta[2]))
    if kind == "directional":
        return DirectionalLight(-u)
    raise ValueError(f"kind: expected one of {KINDS}, got {kind!r}")


def direction_of(light, frame: Frame) -> np.ndarray:
    """Unit vector (3,) from the subject's centre towards the light."""
    if isinstance(light, PointLight):
        d = light.position - np.asarray(frame.centre, float)
        return d / np.linalg.norm(d)
    return -np.asarray(light.direction, float)


def from_light(light, frame: Frame) -> np.ndarray:
    """Inverse of :func:`to_light`: ([γ, φ, r] or [γ, φ]) of a light."""
    e1, e2, n = frame.basis()
    u = direction_of(light, frame)
    g = float(np.arctan2(u @ e2, u @ e1))
    p = float(np.arcsin(np.clip(u @ n, -1, 1)))
    if isinstance(light, PointLight):
        return np.array([g, p, float(np.linalg.norm(light.position - np.asarray(frame.centre, float)))])
    return np.array([g, p])


def param_bounds(kind: str, body_top: float) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) of the parameters: any azimuth (unwrapped, ±2π), elevations in
    ``ELEVATION_RANGE_DEG``, point-light distances ``DISTANCE_RANGE`` (the height above the
    bodies' top is :func:`above_bodies`' business)."""
    lo = [-2 * np.pi, np.radians(ELEVATION_RANGE_DEG[0])]
    hi = [4 * np.pi, np.radians(ELEVATION_RANGE_DEG[1])]
    if kind == "point":
        lo.append(DISTANCE_RANGE[0])
        hi.append(DISTANCE_RANGE[1])
    return np.array(lo), np.array(hi)


def above_bodies(kind: str, theta, body_top: float) -> bool:
    """A point light at least 0.3 m above the bodies' top (and within ``HEIGHT_RANGE``); always
    true for a directional light."""
    if kind != "point":
        return True
    z = float(theta[2]) * np.sin(float(theta[1]))
    return max(HEIGHT_RANGE[0], body_top + 0.3) <= z <= HEIGHT_RANGE[1]


def coarse_grid(kind: str, body_top: float) -> np.ndarray:
    """The thesis' coarse search (§5.8.1): 288 hypotheses spread over the space above the person
    — point: 12 azimuths × 4 elevations × 6 distances (2.5 to 7.5 m); directional: 24 azimuths ×
    12 elevations. Point hypotheses not above the bodies (:func:`above_bodies`) are left out."""
    if kind == "point":
        g = np.radians(np.arange(12) * 30.0)
        p = np.radians([30.0, 45.0, 60.0, 75.0])
        r = np.linspace(2.5, 7.5, 6)
        G, P, R = np.meshgrid(g, p, r, indexing="ij")
        grid = np.stack([G.ravel(), P.ravel(), R.ravel()], axis=1)
        return grid[[above_bodies(kind, t, body_top) for t in grid]]
    if kind == "directional":
        g = np.radians(np.arange(24) * 15.0)
        p = np.radians(np.linspace(15.0, 81.0, 12))
        G, P = np.meshgrid(g, p, indexing="ij")
        return np.stack([G.ravel(), P.ravel()], axis=1)
    raise ValueError(f"kind: expected one of {KINDS}, got {kind!r}")


def coarse_steps(kind: str, body_top: float) -> np.ndarray:
    """Spacing of :func:`coarse_grid` per parameter."""
    grid = coarse_grid(kind, body_top)
    steps = [np.radians(30.0 if kind == "point" else 15.0), np.radians(15.0 if kind == "point" else 6.0)]
    if kind == "point":
        r = np.unique(grid[:, 2])
        steps.append(float(r[1] - r[0]))
    return np.array(steps)
