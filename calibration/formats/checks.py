"""Checks every calibration load goes through: units and the world's up axis, stated, never assumed silently.

A reader returns the file's numbers as they are (:class:`calibration.formats.RigParts`) with
what its format says about them: the units of the translations (``units``; ``units_fixed``
when the format defines them, e.g. Vicon's millimetres, rather than inheriting them from the
board's size, as anipose does) and whether the world frame is the toolkit's own
(``own_frame``: files this toolkit wrote, carrying their ground plane). :func:`settle` then

1. **units**: detects millimetres vs metres from the spread of the camera centres
   (:func:`detect_units`: ≥ ``MM_ABOVE`` → mm, ≤ ``M_BELOW`` → m, in between the unit the
   reader expects, with a warning); a ``units`` argument overrides; translations (and the ground offset) are scaled to
   metres. Where the format fixes the units and the magnitudes disagree, a warning says so.
2. **up axis**: the cameras must stand above the floor (``n·C > d`` for the ground plane
   ``n·X = d``, default z = 0). When every camera is below it the world's Z points down:
   foreign files are **fixed** by default — the world is turned half a turn about its X
   axis (``X' = diag(1, -1, -1) X``: ``R' = R·diag(1, -1, -1)``, ``t`` unchanged, so every
   pixel projects as before) — or refused with ``z_down="refuse"``, or kept with
   ``z_down="keep"``. The toolkit's own files are never changed (the check only reports).
   When some cameras sit on the floor plane or on both sides of it (a world anchored on a
   camera, as Kalibr, anipose and Caliscope write), the up axis is reported as not verified.
   Cameras above the floor with a ground normal pointing down get the normal reversed
   (foreign files) or a warning (own files).
3. **facing**: with three cameras or more, at least half must look towards the others
   (:func:`facing_count`); fewer is reported as a warning about the rotation convention.

Every step appends a sentence to ``notes`` (warnings start with ``"warning:"``), so a load
says which units it read, which way is up and what it assumed.
"""

from __future__ import annotations

import numpy as np

from calibration.errors import CalibrationError
from calibration.ground import GroundPlane

__all__ = ["MM_ABOVE", "M_BELOW", "UNIT_SCALE", "Z_DOWN_CHOICES", "camera_spread", "detect_units",
           "facing_count", "flip_world", "settle", "up_status"]

#: Metres per unit of the unit names accepted by ``units=``.
UNIT_SCALE = {"m": 1.0, "cm": 0.01, "mm": 0.001}
#: Camera centres spread over more than this many file units: millimetres (a 250 m rig is implausible).
MM_ABOVE = 250.0
#: Camera centres spread over less than this many file units: metres (a 25 mm multi-camera rig is rare).
M_BELOW = 25.0
#: Cameras within this distance (metres) of the floor plane count as on it (a camera-anchored world).
ON_FLOOR_M = 1e-3
#: What to do with a world whose Z points down.
Z_DOWN_CHOICES = ("flip", "refuse", "keep")
#: Half a turn about the world X axis: the fix for a Z-down world (keeps the frame right-handed).
FLIP = np.diag([1.0, -1.0, -1.0])


def camera_spread(cameras) -> float:
    """Size of the rig in file units: the largest distance between two camera centres, or, for
    a single camera, its distance from the origin (0 for an intrinsics-only camera)."""
    C = np.array([c.center for c in cameras.values()])
    if len(C) == 1:
        return float(np.linalg.norm(C[0]))
    return float(np.max(np.linalg.norm(C[:, None, :] - C[None, :, :], axis=2)))


def detect_units(spread: float) -> str | None:
    """``"mm"``, ``"m"`` or ``None`` (undecided) from the rig's size in file units.

    >>> detect_units(5836.0), detect_units(3.2), detect_units(60.0)
    ('mm', 'm', None)
    """
    if spread >= MM_ABOVE:
        return "mm"
    if 0 < spread <= M_BELOW:
        return "m"
    return None


def _scaled(cameras, ground, factor: float):
    if factor == 1.0:
        return cameras, ground
    cams = {n: c.replace(t=c.t * factor) for n, c in cameras.items()}
    return cams, GroundPlane(ground.normal, ground.offset * factor)


def _settle_units(parts, units: str | None) -> tuple[dict, GroundPlane, list[str]]:
    cameras, ground = parts.cameras, parts.ground
    spread = camera_spread(cameras)
    notes = []
    if parts.units == "arbitrary" and units is None:
        return cameras, ground, [
            "units: arbitrary (the format has no scale); taken as metres — set the scale with a floor or "
            "board calibration before measuring"]
    if spread == 0.0:
        unit = units or (parts.units if parts.units in UNIT_SCALE else "m")
        return (*_scaled(cameras, ground, UNIT_SCALE[unit]), ["units: not applicable (no camera pose in the file)"])
    detected = detect_units(spread)
    shown = f"camera centres spread over {spread:.4g} file units"
    if units is not None:
        if units not in UNIT_SCALE:
            raise CalibrationError(f"expected one of {', '.join(UNIT_SCALE)}, got {units!r}", field="units")
        unit = units
        notes.append(f"units: {unit} (given; {shown})")
        if detected is not None and detected != unit:
            notes.append(f"warning: the given units {unit} disagree with the magnitudes ({shown} suggests {detected})")
    elif parts.units_fixed and parts.units in UNIT_SCALE:
        unit = parts.units
        notes.append(f"units: {unit} (as the format defines; {shown})")
        if detected is not None and detected != unit:
            notes.append(f"warning: {shown}, which suggests {detected}, but the format defines {unit}: "
                         f"kept {unit}; pass units={detected!r} (--units {detected}) if the file is not as documented")
    elif detected is not None:
        unit = detected
        word = f"; expected {parts.units}" if parts.units in UNIT_SCALE else ""
        notes.append(f"units: {unit} (detected: {shown}{word})")
    else:
        unit = parts.units if parts.units in UNIT_SCALE else "m"
        notes.append(f"warning: units: {unit} assumed — {shown}, too few to tell mm from m "
                     f"(≤ {M_BELOW:g} means m, ≥ {MM_ABOVE:g} mm); pass units= (--units) to be sure")
    if unit != "m":
        notes.append(f"translations converted from {unit} to metres")
    return (*_scaled(cameras, ground, UNIT_SCALE[unit]), notes)


def up_status(cameras, ground: GroundPlane) -> tuple[str, np.ndarray]:
    """Where the cameras stand relative to the floor: ``"up"`` (all above it on the side of
    its normal), ``"below"`` (all below it), ``"unknown"`` (some on it or on both sides), or
    ``"none"`` (intrinsics only); and the heights ``n·C - d`` (metres), camera order."""
    C = np.array([c.center for c in cameras.values()])
    h = C @ ground.normal - ground.offset
    if np.all(C == 0.0) or camera_spread(cameras) == 0.0:
        return "none", h
    if np.all(h > ON_FLOOR_M):
        return "up", h
    if np.all(h < -ON_FLOOR_M):
        return "below", h
    return "unknown", h


def flip_world(cameras, ground: GroundPlane, toward_cameras: bool):
    """The rig in the world turned half a turn about X (``X' = diag(1, -1, -1) X``).

    Every camera sees the same pixels (``R' = R F``, ``t' = t``). The ground plane follows
    the turn; with ``toward_cameras`` its normal is first reversed (the same plane, the
    normal pointing at the cameras), as needed when the cameras stood below it.
    """
    n, d = (-ground.normal, -ground.offset) if toward_cameras else (ground.normal, ground.offset)
    cams = {name: c.replace(R=c.R @ FLIP) for name, c in cameras.items()}
    return cams, GroundPlane(FLIP @ n, d + 0.0)


def _range(h: np.ndarray) -> str:
    lo, hi = f"{h.min():.2f}", f"{h.max():.2f}"
    return f"{lo} m" if lo == hi else f"{lo} to {hi} m"


def _settle_up(cameras, ground, own_frame: bool, z_down: str | None, source: str):
    if z_down is not None and z_down not in Z_DOWN_CHOICES:
        raise CalibrationError(f"expected one of {', '.join(Z_DOWN_CHOICES)}, got {z_down!r}", field="z_down")
    choice = z_down or ("keep" if own_frame else "flip")
    status, h = up_status(cameras, ground)
    names = list(cameras)
    if status == "none":
        return cameras, ground, ["up axis: not applicable (no camera pose)"]
    if status == "unknown":
        near = [n for n, v in zip(names, h) if abs(v) <= ON_FLOOR_M]
        why = (f"camera(s) {', '.join(near)} on the floor plane: the world is anchored on a camera"
               if near else "cameras on both sides of the floor plane")
        return cameras, ground, [
            f"warning: up axis not verified — {why} (heights {_range(h)}); calibrate the floor "
            "(`studio calibrate floor`) before segmenting or fitting"]
    up = ground.normal if status == "up" else -ground.normal
    heights = _range(np.abs(h))
    if up[2] > 0 and status == "up":
        return cameras, ground, [f"up axis: Z up (cameras {heights} above the floor)"]
    n = np.round(ground.normal, 3).tolist()
    if choice == "keep":
        if up[2] <= 0:
            return cameras, ground, [f"warning: the world's Z axis points down (the cameras stand {heights} from "
                                     f"the floor on the side of {np.round(up, 3).tolist()}); kept as it is — "
                                     "z_down='flip' (--z-down flip) turns it"]
        return cameras, ground, [f"warning: the ground normal {n} points away from the cameras ({heights} from the "
                                 "floor on its other side); kept as it is"]
    if up[2] > 0:  # cameras above the floor along +Z, but the ground normal points down: reverse it
        return cameras, GroundPlane(-ground.normal, -ground.offset), [
            f"up axis: Z up (cameras {heights} above the floor); the ground normal was reversed to point at them"]
    if choice == "refuse":
        raise CalibrationError(
            f"the world's Z axis points down (all cameras {heights} below the floor z = 0 along +Z): "
            "expected world Z up; pass z_down='flip' (--z-down flip) to turn the world half a turn about X",
            file=source, field="up axis")
    cameras, ground = flip_world(cameras, ground, toward_cameras=status == "below")
    return cameras, ground, [
        f"up axis: the file's world had Z pointing down (cameras {heights} below the floor along +Z): "
        "turned half a turn about X (x, y, z) → (x, -y, -z); cameras project exactly as before"]


def facing_count(cameras) -> tuple[int, int]:
    """How many cameras' optical axes point towards the centroid of the other cameras' centres,
    and how many were checked (0 below three posed cameras: the test means nothing there)."""
    C = np.array([c.center for c in cameras.values()])
    if len(C) < 3 or camera_spread(cameras) == 0.0:
        return 0, 0
    axes = np.array([c.R[2] for c in cameras.values()])  # optical axis in world coordinates
    others = (C.sum(axis=0)[None, :] - C) / (len(C) - 1)
    return int(np.sum(np.einsum("ij,ij->i", axes, others - C) > 0)), len(C)


def _facing_note(cameras) -> list[str]:
    facing, n = facing_count(cameras)
    if n == 0 or 2 * facing >= n:
        return []
    return [f"warning: only {facing} of {n} cameras look towards the others: the file's rotation convention may "
            "differ from OpenCV's (world → camera, camera looking along +z), e.g. an extra half turn about the "
            "camera x axis as older Pose2Sim versions wrote"]


def settle(parts, *, units: str | None = None, z_down: str | None = None, source: str = "calibration"):
    """``parts`` with translations in metres and world Z up, and ``notes`` saying what was
    read and assumed (the reader's own notes first). See the module docstring."""
    cameras, ground, unit_notes = _settle_units(parts, units)
    cameras, ground, up_notes = _settle_up(cameras, ground, parts.own_frame, z_down, source)
    return parts._replace(cameras=cameras, ground=ground, units="m", units_fixed=True,
                          notes=tuple(parts.notes) + tuple(unit_notes) + tuple(up_notes) + tuple(_facing_note(cameras)))
