"""Per-camera HSV background model (thesis §5.5.1, eq. 5.4) and its classifier.

The model holds, per pixel, the HSV mean and standard deviation of the empty scene, with
circular statistics for hue (eq. 5.4). Fitting is robust to a few frames with motion (a
person walking through, a car passing): frames whose RGB value at a pixel lies further than
``outlier_scale`` robust standard deviations from the per-pixel RGB *median* of all frames are
left out of that pixel's statistics (a trimmed estimate). With a clean empty-scene set this
changes nothing; it also lets a model be learned from the early frames of a sequence that has
no empty-scene frames (CDnet), provided the background is visible at each pixel in most of them.

On disk a model is a folder: ``mean.exr`` and ``std.exr`` ((H, W, 3) float32 HSV, written
with :mod:`rigs.imageio`) and ``model.json`` (format, version, thresholds, morphology).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from studio.segment.adaptive import AdaptiveSettings, adaptive_step
from studio.segment.classify import Thresholds, classify_pixels
from studio.segment.errors import SegmentationError
from studio.segment.hsv import check_rgb, circular_mean, circular_std, rgb_to_hsv
from studio.segment.morphology import Morphology, clean_labels
from studio.segment.registration import estimate_shift, shift_hsv, shift_image
from studio.segment.shadow_geometry import shadow_geometry

__all__ = ["BackgroundModel", "MODEL_FORMAT", "MODEL_VERSION"]

log = logging.getLogger(__name__)

MODEL_FORMAT = "studio.background-model"
MODEL_VERSION = 1
SIGMA_FLOOR = (0.01, 0.01, 0.01)  # smallest σ per channel (H, S, V): noise-free frames, JPEG steps


def _robust_weights(rgb: np.ndarray, outlier_scale: float, min_spread: float) -> np.ndarray:
    """(N, h, w) float32 inlier weights: 1 where a frame is near the per-pixel RGB median."""
    rgb = rgb.astype(np.float32)
    med = np.median(rgb, axis=0)
    dist = np.sqrt(((rgb - med) ** 2).sum(axis=-1))  # (N, h, w)
    spread = 1.4826 * np.median(dist, axis=0)
    limit = np.maximum(outlier_scale * spread, min_spread)
    return (dist <= limit).astype(np.float32)


def _running_from_rgb(frame: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    scale = 1.0 if frame.dtype == np.uint8 else 1.0 / 257.0
    mean = frame.astype(np.float32) * np.float32(scale)
    return mean, np.zeros_like(mean), 1  # the first frame counts as seen


def _running_from_hsv(hsv_mean: np.ndarray, seen: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Running RGB state from a fitted HSV mean (already warmed up: the empty scene is known)."""
    hsv = hsv_mean.copy()
    hsv[..., 0] *= np.float32(360.0)
    rgb = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB) * np.float32(255.0)
    return rgb, np.zeros_like(rgb), seen


def _hsv_statistics(hsv: np.ndarray, w: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """Mean and σ of a stack (N, h, w, 3) of HSV frames, weighted (eq. 5.4 for hue)."""
    mean = np.empty(hsv.shape[1:], np.float32)
    std = np.empty(hsv.shape[1:], np.float32)
    mean[..., 0] = circular_mean(hsv[..., 0], axis=0, weights=w)
    std[..., 0] = circular_std(hsv[..., 0], mean[..., 0], axis=0, weights=w)
    sv = hsv[..., 1:]
    if w is None:
        mean[..., 1:] = sv.mean(axis=0)
        std[..., 1:] = sv.std(axis=0)
    else:
        ww = w[..., None]
        total = np.maximum(ww.sum(axis=0), np.float32(1e-12))
        m = (sv * ww).sum(axis=0) / total
        mean[..., 1:] = m
        std[..., 1:] = np.sqrt(((sv - m) ** 2 * ww).sum(axis=0) / total)
    return mean, std


@dataclass(eq=False)
class BackgroundModel:
    """HSV mean / σ of the empty scene of one camera, plus the decision settings.

    Attributes
    ----------
    mean : (H, W, 3) float32 HSV mean (hue: circular mean, eq. 5.4).
    std : (H, W, 3) float32 HSV standard deviation (hue: wrapped RMS distance, eq. 5.4),
        floored at ``SIGMA_FLOOR``.
    thresholds : eq. 5.5 thresholds.
    morphology : clean-up sizes (§5.5.1).
    frames_used : number of empty-scene frames the model was fitted on.
    adaptive : settings of :meth:`apply` (the running model, :mod:`studio.segment.adaptive`).
    """

    mean: np.ndarray
    std: np.ndarray
    thresholds: Thresholds = field(default_factory=Thresholds)
    morphology: Morphology = field(default_factory=Morphology)
    frames_used: int = 0
    adaptive: AdaptiveSettings = field(default_factory=AdaptiveSettings)

    def __post_init__(self):
        mean = np.asarray(self.mean, dtype=np.float32)
        std = np.asarray(self.std, dtype=np.float32)
        if mean.ndim != 3 or mean.shape[2] != 3 or std.shape != mean.shape:
            raise SegmentationError(
                f"BackgroundModel: mean and std must both be (H, W, 3), got {mean.shape} and {std.shape}"
            )
        std = np.maximum(std, np.asarray(SIGMA_FLOOR, np.float32))
        self.mean, self.std = mean, std
        self._inv_std = (1.0 / std).astype(np.float32)
        # value ratio I^V / μ^V encoded as uint8 200·ratio (voting.encode_ratio), by one multiply
        self._ratio_scale = (200.0 / np.maximum(mean[..., 2], 1e-3)).astype(np.float32)
        self._running = None  # (mean, deviation, frames seen) of apply(), started on first use

    # ------------------------------------------------------------------ fitting
    @classmethod
    def fit(
        cls,
        frames: Iterable[np.ndarray],
        *,
        thresholds: Thresholds | None = None,
        morphology: Morphology | None = None,
        robust: bool = True,
        outlier_scale: float = 3.0,
        min_spread: float = 12.0,
        rows_per_chunk: int = 64,
    ) -> "BackgroundModel":
        """Fit the model to empty-scene frames.

        Parameters
        ----------
        frames : iterable of (H, W, 3) uint8 (or uint16) RGB images of the empty scene.
        robust : drop, per pixel, frames further than ``outlier_scale`` robust σ (but at
            least ``min_spread`` 8-bit levels) from the per-pixel RGB median before eq. 5.4.
        rows_per_chunk : image rows processed at once (bounds memory).
        """
        frames = [check_rgb(f, f"background frame {i}") for i, f in enumerate(frames)]
        if len(frames) < 2:
            raise SegmentationError(
                f"BackgroundModel.fit: need at least 2 empty-scene frames, got {len(frames)}"
            )
        shape, dtype = frames[0].shape, frames[0].dtype
        for i, f in enumerate(frames):
            if f.shape != shape or f.dtype != dtype:
                raise SegmentationError(
                    f"BackgroundModel.fit: background frame {i} is {f.shape} {f.dtype}, "
                    f"frame 0 is {shape} {dtype}"
                )
        level = 1.0 if dtype == np.uint8 else 257.0
        mean = np.empty(shape, np.float32)
        std = np.empty(shape, np.float32)
        for r0 in range(0, shape[0], rows_per_chunk):
            r1 = min(shape[0], r0 + rows_per_chunk)
            rgb = np.stack([f[r0:r1] for f in frames])  # (N, h, W, 3)
            hsv = np.stack([rgb_to_hsv(f) for f in rgb])
            w = _robust_weights(rgb, outlier_scale, min_spread * level) if robust else None
            mean[r0:r1], std[r0:r1] = _hsv_statistics(hsv, w)
        log.debug("background model fitted on %d frames of %s", len(frames), shape)
        return cls(
            mean,
            std,
            thresholds=thresholds or Thresholds(),
            morphology=morphology or Morphology(),
            frames_used=len(frames),
        )

    @classmethod
    def start(cls, frame: np.ndarray, *, adaptive: AdaptiveSettings | None = None, **settings) -> "BackgroundModel":
        """A model to be learned while it runs (:meth:`apply`), from a first frame that may contain
        foreground (no empty-scene frames, as on CDnet): the first ``adaptive.warmup`` frames are
        averaged, then the selective update takes over."""
        frame = check_rgb(frame, "first frame")
        model = cls(rgb_to_hsv(frame), np.zeros(frame.shape, np.float32), adaptive=adaptive or AdaptiveSettings(),
                    **settings)  # fmt: skip
        model._running = _running_from_rgb(frame)
        return model

    # ------------------------------------------------------------------ adaptive
    def apply(self, frame: np.ndarray, clean: bool = True, name: str = "frame") -> np.ndarray:
        """Classify ``frame`` with the running model and update it (as OpenCV's subtractors do).

        The running per-pixel RGB mean and deviation start from the fitted empty-scene mean (or
        from :meth:`start`'s first frame) and follow illumination drift; pixels labelled
        foreground adapt ``adaptive.foreground_rate`` times as fast, so an object left in the
        scene becomes background after ~``1/foreground_rate`` frames. With
        ``adaptive.shadow_direction`` set, shadow pixels not at the light-opposite end of their
        region become person (:func:`studio.segment.shadow_geometry.shadow_geometry`). :meth:`classify` stays
        the fixed model of eq. 5.4–5.5. Returns (H, W) uint8 labels 0/1/2 (after morphology
        unless ``clean`` is False).
        """
        return self.apply_analyse(frame, clean, name)[0]

    def apply_analyse(self, frame: np.ndarray, clean: bool = True, name: str = "frame") -> tuple[np.ndarray, np.ndarray]:
        """:meth:`apply` returning ``(labels, ratio8)`` as :meth:`analyse` does (for voting)."""
        frame = self._check_frame(frame, name)
        if self._running is None:
            self._running = _running_from_hsv(self.mean, self.adaptive.warmup)
        mean, dev, seen = self._running
        labels, ratio8 = adaptive_step(frame, mean, dev, self.adaptive, seen)
        self._running = (mean, dev, seen + 1)
        if clean:
            labels = clean_labels(labels, self.morphology)
        if self.adaptive.shadow_direction is not None:
            labels = shadow_geometry(labels, self.adaptive.shadow_direction, self.adaptive.shadow_fraction)
        return labels, ratio8

    @property
    def running_mean(self) -> np.ndarray | None:
        """(H, W, 3) float32 RGB running mean of :meth:`apply` in 8-bit levels (None before the first call)."""
        return None if self._running is None else self._running[0]

    # ------------------------------------------------------------------ registration
    def estimate_shift(self, frames: Iterable[np.ndarray], min_response: float = 0.1) -> tuple[float, float]:
        """Median ``(dx, dy)`` by which ``frames`` are moved against the empty scene (phase
        correlation of the value channel; frames whose peak is below ``min_response`` are
        ignored, (0, 0) when none is left)."""
        shifts = []
        for i, frame in enumerate(frames):
            v = rgb_to_hsv(self._check_frame(frame, f"registration frame {i}"))[..., 2]
            dx, dy, response = estimate_shift(self.mean[..., 2], v)
            if response >= min_response:
                shifts.append((dx, dy))
        if not shifts:
            return 0.0, 0.0
        dx, dy = np.median(np.asarray(shifts), axis=0)
        return float(dx), float(dy)

    def shifted(self, dx: float, dy: float) -> "BackgroundModel":
        """The model moved by (dx, dy) pixels onto frames taken after the camera was nudged."""
        return BackgroundModel(shift_hsv(self.mean, dx, dy), shift_image(self.std, dx, dy),
                               thresholds=self.thresholds, morphology=self.morphology,
                               frames_used=self.frames_used, adaptive=self.adaptive)  # fmt: skip

    # ------------------------------------------------------------------ classification
    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the images the model applies to."""
        return self.mean.shape[:2]

    def with_settings(
        self,
        thresholds: Thresholds | None = None,
        morphology: Morphology | None = None,
        adaptive: AdaptiveSettings | None = None,
    ) -> "BackgroundModel":
        """A model with the same statistics and changed settings (the running state of
        :meth:`apply` starts afresh)."""
        return BackgroundModel(
            self.mean,
            self.std,
            thresholds=thresholds or self.thresholds,
            morphology=morphology or self.morphology,
            frames_used=self.frames_used,
            adaptive=adaptive or self.adaptive,
        )

    def _check_frame(self, frame: np.ndarray, name: str) -> np.ndarray:
        frame = check_rgb(frame, name)
        if frame.shape[:2] != self.shape:
            raise SegmentationError(
                f"{name}: image is {frame.shape[1]}x{frame.shape[0]}, the background model is "
                f"{self.shape[1]}x{self.shape[0]}"
            )
        return frame

    def classify_raw(self, frame: np.ndarray, name: str = "frame") -> np.ndarray:
        """Per-pixel labels of eq. 5.5 before morphology: (H, W) uint8 0 / 1 / 2."""
        return self._raw(frame, name)[0]

    def analyse(self, frame: np.ndarray, name: str = "frame") -> tuple[np.ndarray, np.ndarray]:
        """Labels after morphology and the encoded value ratio ``I^V / μ^V`` (for voting).

        Returns ``(labels, ratio)``: (H, W) uint8 labels 0/1/2 and (H, W) uint8
        ``round(200 · I^V / μ^V)`` (:func:`studio.segment.voting.encode_ratio`).
        """
        labels, ratio8 = self._raw(frame, name)
        return clean_labels(labels, self.morphology), ratio8

    def _raw(self, frame: np.ndarray, name: str) -> tuple[np.ndarray, np.ndarray]:
        frame = self._check_frame(frame, name)
        hsv = rgb_to_hsv(frame)
        ratio8 = cv2.multiply(cv2.extractChannel(hsv, 2), self._ratio_scale, dtype=cv2.CV_8U)
        return classify_pixels(hsv, self.mean, self._inv_std, self.thresholds, ratio8), ratio8

    def classify(self, frame: np.ndarray, clean: bool = True, name: str = "frame") -> np.ndarray:
        """Labels 0 background / 1 person / 2 shadow of an (H, W, 3) RGB frame, after morphology.

        Returns (H, W) uint8.
        """
        labels = self.classify_raw(frame, name)
        return clean_labels(labels, self.morphology) if clean else labels

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> Path:
        """Write the model to the folder ``path`` (``mean.exr``, ``std.exr``, ``model.json``)."""
        from rigs.imageio import atomic_write_json, write_image

        path = Path(path)
        path.mkdir(parents=True, exist_ok=True)
        write_image(path / "mean.exr", self.mean)
        write_image(path / "std.exr", self.std)
        m = self.morphology
        atomic_write_json(
            path / "model.json",
            {
                "format": MODEL_FORMAT,
                "version": MODEL_VERSION,
                "size": [int(self.shape[1]), int(self.shape[0])],
                "frames_used": int(self.frames_used),
                "thresholds": self.thresholds.to_dict(),
                "adaptive": self.adaptive.to_dict(),
                "morphology": {
                    "median": m.median,
                    "open_radius": m.open_radius,
                    "close_radius": m.close_radius,
                    "min_area": m.min_area,
                    "max_person_hole": m.max_person_hole,
                    "max_hole": m.max_hole,
                },
            },
        )
        return path

    @classmethod
    def load(cls, path: str | Path) -> "BackgroundModel":
        """Read a model folder written by :meth:`save`."""
        from rigs.imageio import read_image

        path = Path(path)
        meta_path = path / "model.json"
        if not meta_path.is_file():
            raise SegmentationError(f"{meta_path}: no background model here (model.json missing)")
        try:
            meta = json.loads(meta_path.read_text())
        except json.JSONDecodeError as exc:
            raise SegmentationError(f"{meta_path}: not valid JSON ({exc})") from None
        if meta.get("format") != MODEL_FORMAT:
            raise SegmentationError(
                f"{meta_path}: format is {meta.get('format')!r}, expected {MODEL_FORMAT!r}"
            )
        if int(meta.get("version", -1)) != MODEL_VERSION:
            raise SegmentationError(
                f"{meta_path}: version {meta.get('version')!r} is not supported (expected {MODEL_VERSION})"
            )
        mean = read_image(path / "mean.exr")
        std = read_image(path / "std.exr")
        size = tuple(meta["size"])
        if mean.shape[:2] != (size[1], size[0]):
            raise SegmentationError(
                f"{path / 'mean.exr'}: image is {mean.shape[1]}x{mean.shape[0]}, model.json says "
                f"{size[0]}x{size[1]}"
            )
        return cls(
            mean,
            std,
            thresholds=Thresholds.from_dict(meta["thresholds"]),
            morphology=Morphology(**meta["morphology"]),
            frames_used=int(meta.get("frames_used", 0)),
            adaptive=AdaptiveSettings.from_dict(meta["adaptive"]) if "adaptive" in meta else AdaptiveSettings(),
        )
