"""Lights of a scene: point lights (finite distance) and directional (distant) lights."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PointLight", "DirectionalLight", "light_from_dict"]


def _vec3(value, what: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{what}: expected 3 finite numbers, got {value!r}")
    return arr


@dataclass(frozen=True)
class PointLight:
    """A point light at ``position`` (3,) world metres.

    ``intensity`` scales the diffuse term; with ``falloff`` the irradiance falls as
    ``(reference_distance / r)²``; ``radius`` > 0 (metres) gives a soft penumbra when
    rendering colour frames (the truth masks use the point itself).
    """

    position: np.ndarray
    intensity: float = 1.0
    falloff: bool = False
    reference_distance: float = 3.0
    radius: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", _vec3(self.position, "point light position"))
        if not self.intensity >= 0:
            raise ValueError(f"point light intensity: expected >= 0, got {self.intensity}")

    def directions_to(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unit vectors (N, 3) from points X (N, 3) towards the light, and irradiance scale (N,)."""
        d = self.position - np.asarray(X, dtype=np.float64)
        r = np.linalg.norm(d, axis=-1)
        scale = np.full(r.shape, float(self.intensity))
        if self.falloff:
            scale = scale * (self.reference_distance / np.maximum(r, 1e-6)) ** 2
        return d / np.maximum(r, 1e-12)[..., None], scale

    def to_dict(self) -> dict:
        return {"type": "point", "position": self.position.tolist(), "intensity": self.intensity,
                "falloff": self.falloff, "reference_distance": self.reference_distance,
                "radius": self.radius}


@dataclass(frozen=True)
class DirectionalLight:
    """A distant light shining along ``direction`` (3,) (from the light into the scene)."""

    direction: np.ndarray
    intensity: float = 1.0
    radius: float = 0.0  # angular softness (radians) for penumbra in colour frames

    def __post_init__(self) -> None:
        d = _vec3(self.direction, "directional light direction")
        n = float(np.linalg.norm(d))
        if n < 1e-12:
            raise ValueError("directional light direction: must be non-zero")
        object.__setattr__(self, "direction", d / n)
        if not self.intensity >= 0:
            raise ValueError(f"directional light intensity: expected >= 0, got {self.intensity}")

    def directions_to(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        X = np.asarray(X, dtype=np.float64)
        shape = X.shape[:-1]
        return (np.broadcast_to(-self.direction, X.shape).copy(),
                np.full(shape, float(self.intensity)))

    def to_dict(self) -> dict:
        return {"type": "directional", "direction": self.direction.tolist(),
                "intensity": self.intensity, "radius": self.radius}


def light_from_dict(data: dict, where: str = "light") -> PointLight | DirectionalLight:
    """Build a light from a spec mapping (``type: point|directional``)."""
    if not isinstance(data, dict):
        raise ValueError(f"{where}: expected a mapping, got {type(data).__name__}")
    kind = data.get("type", "point")
    known = {"point": {"type", "position", "intensity", "falloff", "reference_distance", "radius"},
             "directional": {"type", "direction", "intensity", "radius"}}
    if kind not in known:
        raise ValueError(f"{where}.type: expected 'point' or 'directional', got {kind!r}")
    extra = set(data) - known[kind]
    if extra:
        raise ValueError(f"{where}: unknown field(s) {sorted(extra)} for a {kind} light")
    args = {k: v for k, v in data.items() if k != "type"}
    if kind == "point":
        if "position" not in args:
            raise ValueError(f"{where}.position: required for a point light")
        return PointLight(**args)
    if "direction" not in args:
        raise ValueError(f"{where}.direction: required for a directional light")
    return DirectionalLight(**args)
