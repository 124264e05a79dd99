"""Static changes: objects the person brings or moves (a chair, a box), told apart from the person.

A background model of the empty scene (fixed, eq. 5.4–5.5, or adaptive) labels anything new as
foreground: a box put down stays "person" for ever (the fixed model) or fades into the
background after ~``1/foreground_rate`` frames whether it is a box or a person who stopped (the
adaptive one). This module adds the persistence rule of GSOC / SuBSENSE with a guard for a
person who stands still:

* **Stationary pixels.** Per pixel, the colour of a foreground pixel is compared with its
  reference (the running mean of its current stationary run) by the same excess-over-a-noise-band
  distance as :mod:`studio.segment.adaptive` (eq. 5.6 written as ``Σ_c max(|I_c − r_c| − b, 0)``);
  within ``distance`` the pixel's age grows, beyond it the run restarts and the pixel counts as
  *moving* this frame.
* **Static components.** A connected foreground component (person and shadow labels together: a
  box's own shadow goes with it) at least ``min_share`` of whose pixels have been stationary for
  ``frames`` frames is a static change **only if other foreground moved meanwhile**: in at least
  ``witness`` of those frames, ``min_motion`` of the image was moving outside the component's
  box (grown by ``margin``). A box left while the person walks on qualifies; a person who stops —
  nothing else moving — never does, however long they stand (``witness=0`` drops this guard:
  plain persistence, as GSOC / SuBSENSE absorb whatever stops). A seated person
  makes one component with the chair: both stay person unless something else moves meanwhile
  while the sitter is as still as the chair (on the UU capture 97 % of the sitter's own pixels
  are unchanged over 50 frames: it is the guard that keeps them; a second person walking about
  would have them absorbed, a limit of any persistence rule).
* **A static layer.** Pixels of a static component join a per-pixel layer holding the object's
  colour: a pixel that matches it is labelled background (the output keeps the 0/1/2 label
  format); a pixel that does not is labelled as the model said (the person in front of the
  object); a pixel back to the empty scene (labelled background by the model) leaves the layer
  (the object was taken away: no ghost). The empty-scene model itself is never changed.

The per-pixel work is one compiled pass (numba) over the frame (~0.6 ms of CPU for 644×486); the
components and the witness test run every ``frames // 10`` frames when enough foreground is old
(OpenCV connected components, ~2 ms), so a static change is found within ``1.1 · frames`` frames.

A user's *ignore* regions (per camera: a mask image or polygons, :func:`ignore_masks`) are the
simple, reliable fallback for an object the person uses throughout (the UU capture's chair).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from numba import njit

from studio.segment.classify import BACKGROUND
from studio.segment.errors import SegmentationError

__all__ = ["StaticChanges", "StaticDetector", "StaticSettings", "absolute_spec", "ignore_masks", "polygon_mask"]

CELL = 8  # pixels per side of the motion-history cells


@dataclass(frozen=True)
class StaticSettings:
    """Parameters of :class:`StaticDetector` (8-bit levels; counts in frames fed to it)."""

    frames: int = 50  # N: frames a component must stay unchanged (1 s at 50 fps)
    noise: float = 8.0  # b: per-channel noise band (levels) around a pixel's reference colour
    distance: float = 12.0  # summed excess over the band (levels) at which a pixel has changed
    min_share: float = 0.95  # share of a component's pixels stationary for ``frames``
    witness: float = 0.5  # share of those frames in which foreground moved elsewhere (0: no guard)
    min_motion: float = 5e-4  # fraction of the image that must move elsewhere in a witness frame
    margin: int = 8  # pixels around a component's bounding box that do not count as elsewhere
    min_area: float = 2e-4  # smallest static component (fraction of the image)
    rate: float = 0.05  # adaptation of the static layer's colour

    def __post_init__(self):
        if int(self.frames) != self.frames or self.frames < 2:
            raise SegmentationError(f"StaticSettings.frames: expected an integer >= 2, got {self.frames!r}")
        for name in ("noise", "distance", "min_motion", "min_area"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise SegmentationError(f"StaticSettings.{name}: expected a positive number, got {v!r}")
        for name in ("min_share", "witness", "rate"):
            v = getattr(self, name)
            if not (0.0 < v <= 1.0 or (name == "witness" and v == 0.0)):
                raise SegmentationError(f"StaticSettings.{name}: expected a value in (0, 1], got {v!r}")
        if self.margin < 0:
            raise SegmentationError(f"StaticSettings.margin: expected >= 0, got {self.margin!r}")


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _track(frame, labels, ref, age, layer, colour, in_layer, cells, scale, band, dist, rate, old_age):
    """One frame of the per-pixel state: ``cells`` gets the moving foreground pixels per CELL×CELL
    cell; returns the number of foreground pixels outside the layer at least ``old_age`` old."""
    h, w = labels.shape
    cells[:] = 0
    old = 0
    for y in range(h):
        for x in range(w):
            v0 = frame[y, x, 0] * scale
            v1 = frame[y, x, 1] * scale
            v2 = frame[y, x, 2] * scale
            fg = labels[y, x] != 0
            in_layer[y, x] = 0
            if layer[y, x]:
                e = (max(abs(v0 - colour[y, x, 0]) - band, 0.0) + max(abs(v1 - colour[y, x, 1]) - band, 0.0)
                     + max(abs(v2 - colour[y, x, 2]) - band, 0.0))
                if e < dist:
                    in_layer[y, x] = 1
                    colour[y, x, 0] += rate * (v0 - colour[y, x, 0])
                    colour[y, x, 1] += rate * (v1 - colour[y, x, 1])
                    colour[y, x, 2] += rate * (v2 - colour[y, x, 2])
                    continue
                if not fg:
                    layer[y, x] = 0  # the empty scene is back: the object was taken away
            if not fg:
                age[y, x] = 0
                ref[y, x, 0] = v0
                ref[y, x, 1] = v1
                ref[y, x, 2] = v2
                continue
            e = (max(abs(v0 - ref[y, x, 0]) - band, 0.0) + max(abs(v1 - ref[y, x, 1]) - band, 0.0)
                 + max(abs(v2 - ref[y, x, 2]) - band, 0.0))
            if e < dist:
                a = age[y, x] + 1
                age[y, x] = a
                g = 1.0 / min(a + 1, 16)  # running mean of the run, then a slow follow
                ref[y, x, 0] += g * (v0 - ref[y, x, 0])
                ref[y, x, 1] += g * (v1 - ref[y, x, 1])
                ref[y, x, 2] += g * (v2 - ref[y, x, 2])
                if a >= old_age:
                    old += 1
            else:
                age[y, x] = 0
                ref[y, x, 0] = v0
                ref[y, x, 1] = v1
                ref[y, x, 2] = v2
                cells[y // CELL, x // CELL] += 1
    return old


class StaticDetector:
    """Per-camera persistence state; feed it the frames in order with their labels.

    >>> det = StaticDetector((4, 4))
    >>> labels, static = det.update(np.zeros((4, 4, 3), np.uint8), np.zeros((4, 4), np.uint8))
    >>> int(static.sum())
    0
    """

    def __init__(self, shape: tuple[int, int], settings: StaticSettings = StaticSettings()):
        self.settings = settings
        self.shape = tuple(int(v) for v in shape)
        h, w = self.shape
        self._ref = np.zeros((h, w, 3), np.float32)
        self._colour = np.zeros((h, w, 3), np.float32)
        self._age = np.zeros((h, w), np.int32)
        self._layer = np.zeros((h, w), np.uint8)
        self._in_layer = np.zeros((h, w), np.uint8)
        # moving pixels per cell over the last N frames (a ring) and per frame in total
        self._history = np.zeros((settings.frames, -(-h // CELL), -(-w // CELL)), np.int32)
        self._totals = np.zeros(settings.frames, np.int64)
        self.frames_seen = 0

    @property
    def layer(self) -> np.ndarray:
        """(H, W) bool: pixels holding a static object (whether visible or covered now)."""
        return self._layer.astype(bool)

    @property
    def stationary(self) -> np.ndarray:
        """(H, W) bool: foreground pixels unchanged for at least ``settings.frames`` frames."""
        return self._age >= self.settings.frames

    def update(self, frame: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Labels of ``frame`` with its static changes turned to background.

        Parameters
        ----------
        frame : (H, W, 3) uint8 or uint16 RGB, the next frame of the sequence.
        labels : (H, W) uint8 labels 0/1/2 of ``frame`` from a background model (not changed).

        Returns ``(labels, static)``: new labels and the (H, W) bool mask of pixels labelled static.
        """
        if frame.shape[:2] != self.shape or labels.shape != self.shape:
            raise SegmentationError(f"StaticDetector: frame {frame.shape[:2]} / labels {labels.shape}, "
                                    f"expected {self.shape}")  # fmt: skip
        s = self.settings
        scale = 1.0 if frame.dtype == np.uint8 else 1.0 / 257.0
        slot = self.frames_seen % s.frames
        old = _track(frame, labels, self._ref, self._age, self._layer, self._colour, self._in_layer,
                     self._history[slot], np.float32(scale), np.float32(s.noise), np.float32(s.distance),
                     np.float32(s.rate), s.frames)  # fmt: skip
        self._totals[slot] = self._history[slot].sum()
        self.frames_seen += 1
        static = self._in_layer.view(bool)
        h, w = self.shape
        due = self.frames_seen % max(1, s.frames // 10) == 0  # components every N/10 frames: ~2 ms each
        if due and self.frames_seen >= s.frames and old >= max(1, round(s.min_area * h * w)):
            static = static | self._new_static(labels)
        if not static.any():
            return labels.copy(), static.copy()
        return np.where(static, np.uint8(BACKGROUND), labels), static.copy()

    def _new_static(self, labels: np.ndarray) -> np.ndarray:
        """Components that became static this frame (moved into the layer)."""
        s = self.settings
        h, w = self.shape
        candidate = (labels != 0) & (self._in_layer == 0)
        old = candidate & (self._age >= s.frames)
        min_area = max(1, int(round(s.min_area * h * w)))
        n, cc, stats, _ = cv2.connectedComponentsWithStats(candidate.view(np.uint8), connectivity=8)
        area = stats[:, cv2.CC_STAT_AREA]
        share = np.bincount(cc[old], minlength=n) / np.maximum(area, 1)
        chosen = [k for k in range(1, n) if area[k] >= min_area and share[k] >= s.min_share]
        if not chosen:
            return np.zeros(self.shape, bool)
        need = s.min_motion * h * w
        static = np.zeros(n, bool)
        for k in chosen:
            x, y, bw, bh = stats[k, :4]
            x0, y0 = max(x - s.margin, 0) // CELL, max(y - s.margin, 0) // CELL
            x1, y1 = -(-(x + bw + s.margin) // CELL), -(-(y + bh + s.margin) // CELL)
            elsewhere = self._totals - self._history[:, y0:y1, x0:x1].sum(axis=(1, 2))
            static[k] = np.count_nonzero(elsewhere >= need) >= s.witness * s.frames
        if not static.any():
            return np.zeros(self.shape, bool)
        mask = static[cc] & candidate
        if mask.any():
            self._layer[mask] = 1
            self._colour[mask] = self._ref[mask]
        return mask


# ---------------------------------------------------------------------- user-given regions
def polygon_mask(polygons, shape: tuple[int, int]) -> np.ndarray:
    """(H, W) bool mask of ``polygons`` (each a list of ``[x, y]`` pixel vertices, pixel centres
    at integer coordinates), filled with 1/16 px precision."""
    mask = np.zeros(shape, np.uint8)
    for poly in polygons:
        pts = np.asarray(poly, np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3:
            raise SegmentationError(f"polygon: expected at least 3 [x, y] vertices, got {poly!r}")
        cv2.fillPoly(mask, [np.round(pts * 16).astype(np.int32)], 1, lineType=cv2.LINE_8, shift=4)
    return mask.astype(bool)


def ignore_masks(specs, shapes: dict[str, tuple[int, int]]) -> dict[str, np.ndarray]:
    """Per-camera ignore masks from ``specs``: ``"CAM=MASK.png"`` (non-zero pixels ignored) or a
    JSON file ``{"cameras": {cam: [[[x, y], ...], ...]}}`` of polygons per camera (the format of
    ``benchmarks/uu_chair_polygons.json``). Masks of one camera are united; sizes are checked."""
    from rigs.imageio import read_image

    out: dict[str, np.ndarray] = {}
    for spec in specs:
        spec = str(spec)
        if "=" in spec and not spec.lower().endswith(".json"):
            cam, path = spec.split("=", 1)
            if cam not in shapes:
                raise SegmentationError(f"ignore mask {spec!r}: no camera {cam!r} (cameras: {sorted(shapes)})")
            try:
                image = read_image(Path(path))
            except (OSError, ValueError) as exc:
                raise SegmentationError(f"ignore mask {path}: cannot read it ({exc})") from None
            mask = (image.reshape(image.shape[0], image.shape[1], -1) != 0).any(axis=2)
            if mask.shape != tuple(shapes[cam]):
                raise SegmentationError(f"ignore mask {path}: {mask.shape[1]}x{mask.shape[0]}, camera {cam!r} is "
                                        f"{shapes[cam][1]}x{shapes[cam][0]}")  # fmt: skip
            masks = {cam: mask}
        else:
            try:
                data = json.loads(Path(spec).read_text())
                cameras = data["cameras"]
            except (OSError, ValueError, KeyError, TypeError) as exc:
                raise SegmentationError(f"ignore polygons {spec}: expected JSON with 'cameras' ({exc})") from None
            unknown = sorted(set(cameras) - set(shapes))
            if unknown:
                raise SegmentationError(f"ignore polygons {spec}: unknown camera(s) {unknown}")
            masks = {cam: polygon_mask(polys, shapes[cam]) for cam, polys in cameras.items()}
        for cam, mask in masks.items():
            out[cam] = mask | out[cam] if cam in out else mask
    return out


def absolute_spec(spec: str) -> str:
    """An ignore spec (``CAM=MASK.png`` or ``POLYGONS.json``) with its file made absolute."""
    spec = str(spec)
    if "=" in spec and not spec.lower().endswith(".json"):
        cam, path = spec.split("=", 1)
        return f"{cam}={Path(path).resolve()}"
    return str(Path(spec).resolve())


class StaticChanges:
    """The session's stage after single-view classification: the user's ignore regions, then
    the static changes (:class:`StaticDetector` per camera, ``frames`` > 0), both relabelled
    background. Called with the frames in order; an index not after the last one starts the
    persistence again."""

    def __init__(self, ignore: dict[str, np.ndarray], frames: int = 0):
        self.ignore, self.frames = ignore, int(frames)
        self._detectors: dict[str, StaticDetector] = {}
        self._last: int | None = None

    def __call__(self, index: int, frame: dict, labels: dict) -> dict:
        """Relabel ``labels`` (``{camera: (H, W) uint8}``) in place; returns per camera
        ``{"ignored": px, "static": px}``, the foreground pixels relabelled background."""
        if not self.ignore and self.frames <= 0:
            return {}
        if self._last is not None and index <= self._last:
            self._detectors = {}
        self._last = index
        out = {}
        for cam in labels:
            figures = {}
            if cam in self.ignore:
                hit = self.ignore[cam] & (labels[cam] != BACKGROUND)
                figures["ignored"] = int(np.count_nonzero(hit))
                labels[cam] = np.where(hit, np.uint8(BACKGROUND), labels[cam])
            if self.frames > 0:
                det = self._detectors.get(cam)
                if det is None:
                    det = self._detectors[cam] = StaticDetector(labels[cam].shape, StaticSettings(frames=self.frames))
                labels[cam], static = det.update(frame[cam], labels[cam])
                figures["static"] = int(np.count_nonzero(static))
            out[cam] = figures
        return out
