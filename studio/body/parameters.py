"""Model parameters of a fitted person as JSON (``export/model_parameters.json``), reloadable.

Format ``studio.body-parameters`` version 1: ``gender``, ``shape`` (the person's shape
coefficients, the mean over the frames measured), ``frames`` {frame: {"shape", "pose"}}
(POSE_SIZE pose vectors, see :mod:`studio.body.skeleton`), units metres / radians, world Z up.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["BodyParameters", "load_parameters"]

FORMAT, VERSION = "studio.body-parameters", 1


@dataclass(frozen=True)
class BodyParameters:
    """``gender``, ``shape`` (n_shape,), ``frames`` {frame: (shape, pose)}."""

    gender: str
    shape: np.ndarray
    frames: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        return {"format": FORMAT, "version": VERSION, "gender": self.gender, "units": {"length": "m", "angle": "rad"},
                "shape": [float(v) for v in self.shape],
                "frames": {str(f): {"shape": [float(v) for v in s], "pose": [float(v) for v in p]}
                           for f, (s, p) in sorted(self.frames.items())}}

    def save(self, path: str | Path) -> Path:
        from rigs.atomic import atomic_write_json

        return atomic_write_json(path, self.to_json(), mkdir=True)

    def vertices(self, frame: int | None = None) -> np.ndarray:
        """(V, 3) the body in the default pose (``frame`` None) or as fitted in ``frame``."""
        from studio.body.model import BodyModel

        model = BodyModel.load(self.gender)
        if frame is None:
            return model.vertices(self.shape)
        s, p = self.frames[frame]
        return model.vertices(s, p)


def load_parameters(path: str | Path) -> BodyParameters:
    """Read a ``studio.body-parameters`` file; a wrong format, version or field is named."""
    from studio.body.model import GENDERS, BodyModel
    from studio.body.skeleton import POSE_SIZE

    path = Path(path)
    try:
        obj = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: not a readable JSON file ({exc})") from None
    if not isinstance(obj, dict) or obj.get("format") != FORMAT or obj.get("version") != VERSION:
        raise ValueError(f"{path}: expected format {FORMAT!r} version {VERSION}")
    if obj.get("gender") not in GENDERS:
        raise ValueError(f"{path}: field 'gender': expected one of {', '.join(GENDERS)}, got {obj.get('gender')!r}")
    n = BodyModel.load(obj["gender"]).n_shape

    def vec(value, size, where):
        try:
            a = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if a.shape != (size,) or not np.all(np.isfinite(a)):
            raise ValueError(f"{path}: field {where!r}: expected {size} finite numbers")
        return a

    frames = {}
    for f, entry in (obj.get("frames") or {}).items():
        if not isinstance(entry, dict):
            raise ValueError(f"{path}: field 'frames.{f}': expected an object with 'shape' and 'pose'")
        frames[int(f)] = (vec(entry.get("shape"), n, f"frames.{f}.shape"), vec(entry.get("pose"), POSE_SIZE,
                                                                                  f"frames.{f}.pose"))
    return BodyParameters(obj["gender"], vec(obj.get("shape"), n, "shape"), frames)
