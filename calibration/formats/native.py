"""The native ``calibration.json``: ``{"format": "studio.rig-calibration", "version": 1, ...}``.

Per camera ``{model, K, dist, R, t, size}``. ``model`` (``"pinhole"`` or ``"fisheye"``) was
added within version 1 as an optional field: files without it are pinhole and still load.
"""

from __future__ import annotations

import json
import math
from os import PathLike
from pathlib import Path

from calibration.camera import Camera
from calibration.errors import CalibrationError
from calibration.formats import RigParts
from calibration.formats.text import read_document
from rigs.atomic import atomic_write_text
from calibration.ground import GroundPlane

FORMAT = "studio.rig-calibration"
VERSION = 1


def _major(version, path) -> int:
    try:
        if isinstance(version, bool):
            raise ValueError
        if isinstance(version, float) and not math.isfinite(version):
            raise ValueError
        return int(str(version).split(".")[0])
    except (TypeError, ValueError):
        raise CalibrationError(
            f"expected an integer version, got {version!r}", file=path, field="version"
        ) from None


def rig_to_dict(rig) -> dict:
    """The JSON document of a rig (plain lists and numbers)."""
    return {
        "format": FORMAT,
        "version": VERSION,
        "units": "m",
        "cameras": {name: cam.to_dict() for name, cam in rig.cameras.items()},
        "ground": rig.ground.to_dict(),
        "metadata": rig.metadata,
    }


def rig_from_dict(doc: dict, path: str | PathLike = "<dict>"):
    """Parse the JSON document; errors name ``path``, the camera and the field."""
    if not isinstance(doc, dict):
        raise CalibrationError("expected a JSON object at the top level", file=path)
    if doc.get("format") != FORMAT:
        raise CalibrationError(
            f"expected {FORMAT!r}, got {doc.get('format')!r}", file=path, field="format"
        )
    if "version" not in doc:
        raise CalibrationError("missing", file=path, field="version")
    major = _major(doc["version"], path)
    if major != VERSION:
        raise CalibrationError(
            f"unknown major version {doc['version']!r} (this reader knows {VERSION})",
            file=path,
            field="version",
        )
    units = doc.get("units", "m")
    if units != "m":
        raise CalibrationError(f"expected 'm', got {units!r}", file=path, field="units")
    cams = doc.get("cameras")
    if not isinstance(cams, dict) or not cams:
        raise CalibrationError("missing or empty camera table", file=path, field="cameras")
    try:
        cameras = {str(name): Camera.from_dict(str(name), data) for name, data in cams.items()}
        g = doc.get("ground")
        if g is None:
            ground = GroundPlane.floor()
        else:
            if not isinstance(g, dict) or "normal" not in g or "offset" not in g:
                raise CalibrationError("expected {normal, offset}", field="ground")
            ground = GroundPlane(g["normal"], g["offset"])
        return RigParts(cameras, ground, doc.get("metadata") or {}, units="m", units_fixed=True, own_frame=True)
    except CalibrationError as exc:
        raise exc.in_file(path) from None


def read_native(path: str | PathLike):
    path = Path(path)
    return rig_from_dict(read_document(path, json.loads, "JSON", (json.JSONDecodeError,)), path)


def write_native(rig, path: str | PathLike) -> Path:
    try:
        text = json.dumps(rig_to_dict(rig), indent=2, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise CalibrationError(
            f"metadata cannot be written as JSON ({exc})", file=path, field="metadata"
        ) from None
    return atomic_write_text(path, text + "\n", mkdir=True)
