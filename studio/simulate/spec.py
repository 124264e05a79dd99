"""Scene specifications of the simulated studio (``spec.yaml``, format ``studio.sim-spec`` v1).

A spec names the true body sequence (a ``body.npz`` built by ``studio simulate
build-truth``), the camera ring, the studio (floor, backdrop), the lights, the person's
appearance and the sensor. Every field has a default; unknown fields are errors, so a typo
never silently falls back to a default. Example::

    format: studio.sim-spec
    version: 1
    name: walk
    body: body.npz              # relative to the spec file
    frames: null                # all frames, or [start, stop]
    fps: 24
    cameras: {count: 4, size: [656, 490], radius: 3.6, height: 2.3, focal_px: 560}
    lights:  [{type: point, position: [1.5, -2.0, 3.2], intensity: 0.9}]
    ambient: 0.45
    person:  {skin_tone: null, top: {color: [40, 70, 150], sleeves: short}, looseness: 0.0}
             # top.kind shirt | long_shirt | jacket; bottom.kind trousers | wide_trousers | skirt
    sensor:  {noise: 1.5, gamma: 2.2, bayer: false, flicker: 0.01, drop: 0.0, jitter_ns: 0}
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

__all__ = ["SimSpec", "SpecError", "load_spec", "DEFAULTS", "SPEC_FORMAT", "SPEC_VERSION"]

SPEC_FORMAT = "studio.sim-spec"
SPEC_VERSION = 1


#: Garments (``person.top.kind``, ``person.bottom.kind``), see :mod:`studio.simulate.garments`.
TOP_KINDS = ("shirt", "long_shirt", "jacket")
BOTTOM_KINDS = ("trousers", "wide_trousers", "skirt")
#: Version of the loose garment model (part of a loosely dressed spec's cache key): "drape 1" = the
#: posture-dependent drape of :func:`studio.simulate.garments.drape`.
GARMENT_MODEL = "drape 1"


class SpecError(ValueError):
    """A scene spec is malformed; the message names the file and the field."""


DEFAULTS: dict[str, Any] = {
    "format": SPEC_FORMAT,
    "version": SPEC_VERSION,
    "name": None,
    "body": "body.npz",
    "frames": None,
    "fps": 24.0,
    "seed": 0,
    "background_frames": 5,
    "cameras": {
        "count": 4,
        "size": [656, 490],
        "radius": 3.6,
        "height": 2.3,
        "look_at": [0.0, 0.0, 0.9],
        "start_deg": 45.0,
        "span_deg": 360.0,
        "focal_px": 560.0,
        "dist": [-0.04, 0.008, 0.0, 0.0, 0.0],
        "jitter_deg": 2.0,
        "names": None,
    },
    "studio": {
        "room_half": 4.5,
        "wall_height": 3.2,
        "floor_albedo": [0.55, 0.52, 0.47],
        "tile_size": 0.6,
        "backdrop_albedo": [0.32, 0.42, 0.36],
    },
    "lights": [{"type": "point", "position": [1.1, -1.5, 3.6], "intensity": 0.85}],
    "ambient": 0.45,
    "person": {
        "skin_tone": None,
        "top": {"color": [45, 75, 150], "sleeves": "short", "kind": "shirt"},
        "bottom": {"color": [60, 55, 50], "length": "long", "kind": "trousers"},
        "shoes": [30, 30, 32],
        "hair": [50, 35, 25],
        "looseness": 0.0,
    },
    "sensor": {
        "noise": 1.5,
        "shot_noise": 0.02,
        "gamma": 2.2,
        "bayer": False,
        "flicker": 0.01,
        "exposure": 1.0,
        "penumbra_px": 0.0,
        "drop": 0.0,
        "jitter_ns": 0,
    },
}


@dataclass(frozen=True)
class SimSpec:
    """A validated scene spec: ``data`` (defaults merged), ``path`` of the file (or None)."""

    data: dict
    path: Path | None

    def __getitem__(self, key: str) -> Any:
        return self.data[key]

    @property
    def name(self) -> str:
        return self.data["name"]

    @property
    def folder(self) -> Path:
        return self.path.parent if self.path is not None else Path.cwd()

    @property
    def body_path(self) -> Path:
        p = Path(self.data["body"])
        return p if p.is_absolute() else self.folder / p

    def digest(self) -> str:
        """Hash of the spec content and of the body file (cache key); a loosely dressed person's
        also of the garment model's version (:data:`GARMENT_MODEL`: loose renders made before the
        drape are not reused)."""
        h = hashlib.sha256(json.dumps(self.data, sort_keys=True).encode())
        if float(self.data["person"]["looseness"]) > 0:
            h.update(GARMENT_MODEL.encode())
        body = self.body_path
        if body.is_file():
            h.update(body.read_bytes())
        return h.hexdigest()[:16]


def _merge(defaults: dict, given: dict, where: str, src: str) -> dict:
    out = copy.deepcopy(defaults)
    for key, value in given.items():
        if key not in defaults:
            raise SpecError(f"{src}: unknown field {where}{key!r}; known: {sorted(defaults)}")
        if isinstance(defaults[key], dict) and value is not None:
            if not isinstance(value, dict):
                raise SpecError(f"{src}: {where}{key} must be a mapping, got {value!r}")
            out[key] = _merge(defaults[key], value, f"{where}{key}.", src)
        else:
            out[key] = value
    return out


def _number(value, src: str, field: str, lo: float | None = None, hi: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SpecError(f"{src}: {field} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise SpecError(f"{src}: {field} must be a finite number, got {value!r}")
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise SpecError(f"{src}: {field} must lie in [{lo}, {hi}], got {value!r}")
    return float(value)


def validate(data: dict, src: str) -> dict:
    """Merge defaults into a raw spec mapping and check every field (raises :class:`SpecError`)."""
    if not isinstance(data, dict):
        raise SpecError(f"{src}: expected a YAML mapping at the top level")
    fmt = data.get("format", SPEC_FORMAT)
    if fmt != SPEC_FORMAT:
        raise SpecError(f"{src}: format must be {SPEC_FORMAT!r}, got {fmt!r}")
    version = data.get("version", SPEC_VERSION)
    if not isinstance(version, int) or version != SPEC_VERSION:
        raise SpecError(f"{src}: unsupported version {version!r} (this reader knows {SPEC_VERSION})")
    d = _merge(DEFAULTS, data, "", src)
    cams = d["cameras"]
    count = cams["count"]
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise SpecError(f"{src}: cameras.count must be a positive integer, got {count!r}")
    size = cams["size"]
    if (not isinstance(size, (list, tuple)) or len(size) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in size)):
        raise SpecError(f"{src}: cameras.size must be [width, height] positive integers, got {size!r}")
    for key in ("radius", "height", "focal_px"):
        _number(cams[key], src, f"cameras.{key}", 1e-6)
    if cams["names"] is not None and (not isinstance(cams["names"], list) or len(cams["names"]) != count):
        raise SpecError(f"{src}: cameras.names must list {count} names, got {cams['names']!r}")
    _number(d["fps"], src, "fps", 1e-6)
    _number(d["ambient"], src, "ambient", 0.0)
    if not isinstance(d["lights"], list) or not d["lights"]:
        raise SpecError(f"{src}: lights must be a non-empty list")
    from studio.render.lights import light_from_dict

    for i, light in enumerate(d["lights"]):
        try:
            light_from_dict(light, f"lights[{i}]")
        except (ValueError, TypeError) as exc:
            raise SpecError(f"{src}: {exc}") from None
    frames = d["frames"]
    if frames is not None and (not isinstance(frames, list) or len(frames) != 2
                               or not all(isinstance(v, int) for v in frames)):
        raise SpecError(f"{src}: frames must be null or [start, stop], got {frames!r}")
    person = d["person"]
    if person["skin_tone"] is not None:
        _number(person["skin_tone"], src, "person.skin_tone", 0.0, 1.0)
    if person["top"]["sleeves"] not in ("none", "short", "long"):
        raise SpecError(f"{src}: person.top.sleeves must be none/short/long, got {person['top']['sleeves']!r}")
    if person["bottom"]["length"] not in ("short", "long"):
        raise SpecError(f"{src}: person.bottom.length must be short/long, got {person['bottom']['length']!r}")
    _number(person["looseness"], src, "person.looseness", 0.0, 0.2)
    if person["top"]["kind"] not in TOP_KINDS:
        raise SpecError(f"{src}: person.top.kind must be one of {'/'.join(TOP_KINDS)}, got {person['top']['kind']!r}")
    if person["bottom"]["kind"] not in BOTTOM_KINDS:
        raise SpecError(f"{src}: person.bottom.kind must be one of {'/'.join(BOTTOM_KINDS)}, "
                        f"got {person['bottom']['kind']!r}")
    s = d["sensor"]
    _number(s["noise"], src, "sensor.noise", 0.0)
    _number(s["gamma"], src, "sensor.gamma", 0.1)
    _number(s["drop"], src, "sensor.drop", 0.0, 1.0)
    _number(s["flicker"], src, "sensor.flicker", 0.0, 0.5)
    bg = d["background_frames"]
    if isinstance(bg, bool) or not isinstance(bg, int) or bg < 0:
        raise SpecError(f"{src}: background_frames must be a non-negative integer, got {bg!r}")
    seed = d["seed"]
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise SpecError(f"{src}: seed must be a non-negative integer, got {seed!r}")
    return d


def load_spec(path: str | Path | dict) -> SimSpec:
    """Read and validate a ``spec.yaml`` (or a mapping: path-relative fields use the CWD)."""
    if isinstance(path, dict):
        d = validate(path, "<spec>")
        if d["name"] is None:
            d["name"] = "scene"
        return SimSpec(d, None)
    p = Path(path)
    if p.is_dir():
        p = p / "spec.yaml"
    if not p.is_file():
        raise SpecError(f"{p}: no such spec file")
    try:
        raw = yaml.safe_load(p.read_text())
    except yaml.YAMLError as exc:
        raise SpecError(f"{p}: not valid YAML ({exc})") from None
    d = validate(raw, str(p))
    if d["name"] is None:
        d["name"] = p.parent.name
    return SimSpec(d, p.resolve())
