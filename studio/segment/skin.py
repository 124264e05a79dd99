"""Hue–Saturation histogram skin classifier (thesis §6.3.4, eq. 6.10).

A normalised joint histogram ``P(H, S | skin)`` is built from skin pixels; a pixel is skin
when its bin holds at least ``threshold`` (eq. 6.10, ``rule="density"``). When labelled
non-skin pixels are available too, the same histogram divided by the histogram of all pixels,
``P(skin | H, S)`` (Jones & Rehg 2002, which the thesis cites), ranks the bins better; that is
``rule="posterior"``, the default of :meth:`SkinClassifier.train` (the benchmark reports both). The Value channel is ignored (it carries
the lighting), except that nearly black pixels (``V < min_value``), whose hue and saturation
are noise, are never skin — a documented guard the thesis did not need with its lighting.

Two ways to learn it:

* :meth:`SkinClassifier.train` — from images with skin masks; the threshold is chosen to
  maximise the pixel F1 on the training pixels.
* :meth:`SkinClassifier.self_train` — the thesis' procedure without labels: the foreground
  pixels of a minimal-clothing capture are histogrammed inside the box where skin is
  expected (hue in [0, 0.15], saturation in [0.15, 0.5], fig. 6.3b); hair, dark clothing and
  colour spill fall outside it or in sparse bins. The threshold keeps the densest bins that
  hold ``coverage`` of that mass.

Post-processing (§6.3.4): median filter, removal of small components, and a final dilation
by a few pixels *inside the person silhouette* when one is given.

Saved as ``.npz`` (histogram + JSON settings, format ``studio.skin-model`` version 1).
"""

from __future__ import annotations

import io
import json
import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from studio.segment.errors import SegmentationError
from studio.segment.hsv import check_rgb
from studio.segment.morphology import disk, remove_small_components

__all__ = ["SkinClassifier", "SKIN_FORMAT", "SKIN_VERSION", "ycrcb_skin"]

log = logging.getLogger(__name__)

SKIN_FORMAT = "studio.skin-model"
SKIN_VERSION = 1
THESIS_BOX = ((0.0, 0.15), (0.15, 0.5))  # (hue range, saturation range) of fig. 6.3b


def _hsv8(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 HSV with hue over the full 0–255 range (OpenCV ``HSV_FULL``)."""
    image = check_rgb(image)
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    return cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2HSV_FULL)


def _check_mask(mask, shape, name: str) -> np.ndarray:
    mask = np.asarray(mask)
    if mask.shape != shape[:2]:
        raise SegmentationError(f"{name}: mask is {mask.shape}, the image is {shape[:2]}")
    return mask.astype(bool) if mask.dtype == bool else mask > 0


@dataclass(eq=False)
class SkinClassifier:
    """``P(H, S | skin) ≥ threshold`` (eq. 6.10) plus post-processing settings.

    Attributes
    ----------
    histogram : (hue_bins, sat_bins) float64, sums to 1 (``P(H, S | skin)``).
    score : (hue_bins, sat_bins) float64 table that is thresholded: the histogram itself
        (``rule="density"``, eq. 6.10) or ``P(skin | H, S)`` (``rule="posterior"``).
    threshold : threshold on ``score``.
    min_value : pixels darker than this (V in [0, 1]) are never skin.
    median : odd median-filter size of the post-processing (0/1: none).
    min_area : components smaller than this fraction of the image are dropped.
    edge_dilation : final dilation (pixels) inside the person mask.
    """

    histogram: np.ndarray = field(default_factory=lambda: np.zeros((64, 64)))
    threshold: float = np.inf
    score: np.ndarray | None = None
    rule: str = "density"
    min_value: float = 0.12
    median: int = 5
    min_area: float = 1e-4
    edge_dilation: int = 2

    def __post_init__(self):
        self.histogram = np.asarray(self.histogram, dtype=np.float64)
        if self.histogram.ndim != 2 or min(self.histogram.shape) < 2:
            raise SegmentationError(
                f"SkinClassifier: histogram must be (hue_bins, sat_bins), got {self.histogram.shape}"
            )
        if self.rule not in ("density", "posterior"):
            raise SegmentationError(
                f"SkinClassifier.rule: expected 'density' or 'posterior', got {self.rule!r}"
            )
        self.score = self.histogram if self.score is None else np.asarray(self.score, np.float64)
        if self.score.shape != self.histogram.shape:
            raise SegmentationError(
                f"SkinClassifier: score table {self.score.shape} does not match the histogram "
                f"{self.histogram.shape}"
            )
        self._table = None

    @property
    def trained(self) -> bool:
        return bool(np.isfinite(self.threshold) and self.histogram.sum() > 0)

    # ------------------------------------------------------------------ histograms
    def _bins(self, hsv8: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        hb, sb = self.histogram.shape
        h = (hsv8[..., 0].astype(np.int32) * hb) >> 8
        s = (hsv8[..., 1].astype(np.int32) * sb) >> 8
        return h, s

    def _histogram(self, pairs: Iterable[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
        """Counts (hue_bins, sat_bins) of the selected pixels of each (image, mask)."""
        hb, sb = self.histogram.shape
        counts = np.zeros(hb * sb, np.float64)
        for image, mask in pairs:
            hsv = _hsv8(image)
            keep = mask & (hsv[..., 2] >= self.min_value * 255)
            h, s = self._bins(hsv[keep])
            counts += np.bincount(h * sb + s, minlength=hb * sb)
        return counts.reshape(hb, sb)

    @staticmethod
    def _smooth(counts: np.ndarray) -> np.ndarray:
        padded = np.concatenate([counts[-2:], counts, counts[:2]], axis=0)  # hue wraps
        blurred = cv2.GaussianBlur(padded, (5, 5), 1.0, borderType=cv2.BORDER_REPLICATE)
        return blurred[2:-2]

    # ------------------------------------------------------------------ training
    def train(
        self,
        images: Sequence[np.ndarray],
        masks: Sequence[np.ndarray],
        *,
        rule: str = "posterior",
        smooth: bool = False,
    ) -> "SkinClassifier":
        """Learn ``P(H, S | skin)`` from labelled images and pick the threshold (max pixel F1).

        Parameters
        ----------
        images : (H, W, 3) uint8 RGB images.
        masks : (H, W) skin masks (bool, or uint8 where > 0 is skin — threshold 8-bit
            anti-aliased masks before passing them, e.g. ``mask >= 128``).
        rule : ``"posterior"`` (rank bins by ``P(skin | H, S)``) or ``"density"`` (eq. 6.10).
        smooth : blur the histograms by one bin (circular in hue) before use.

        Returns ``self`` (trained in place).
        """
        if rule not in ("density", "posterior"):
            raise SegmentationError(f"SkinClassifier.train: rule must be 'density' or 'posterior', got {rule!r}")
        if len(images) == 0 or len(images) != len(masks):
            raise SegmentationError(
                f"SkinClassifier.train: need as many masks as images (got {len(images)} images, "
                f"{len(masks)} masks, at least one)"
            )
        checked = []
        for i, (im, m) in enumerate(zip(images, masks)):
            im = check_rgb(im, f"training image {i}")
            checked.append((im, _check_mask(m, im.shape, f"training mask {i}")))
        skin = self._histogram(checked)
        other = self._histogram((im, ~m) for im, m in checked)
        if skin.sum() == 0:
            raise SegmentationError("SkinClassifier.train: the masks contain no skin pixels")
        if smooth:
            skin, other = self._smooth(skin), self._smooth(other)
        density = skin / skin.sum()
        # F1 of every candidate threshold, from the histograms (bins sorted by the ranking)
        if rule == "posterior":
            score = skin / np.maximum(skin + other, 1e-12)
        else:
            score = density
        order = np.argsort(score.ravel(), kind="stable")[::-1]
        tp = np.cumsum(skin.ravel()[order])
        fp = np.cumsum(other.ravel()[order])
        f1 = 2 * tp / (tp + fp + skin.sum())
        best = int(np.argmax(f1))
        self.histogram, self.score, self.rule = density, score, rule
        self.threshold = float(score.ravel()[order[best]])
        self._table = None
        log.debug("skin model: threshold %.3g, training F1 %.3f", self.threshold, f1[best])
        return self

    def self_train(
        self,
        images: Sequence[np.ndarray],
        person_masks: Sequence[np.ndarray],
        *,
        box: tuple[tuple[float, float], tuple[float, float]] = THESIS_BOX,
        coverage: float = 0.9,
    ) -> "SkinClassifier":
        """Learn from foreground pixels of a minimal-clothing capture, no labels (§6.3.4).

        Parameters
        ----------
        images : (H, W, 3) uint8 RGB frames (one camera: the thesis trains one model per view).
        person_masks : (H, W) person masks of those frames (segmentation label 1).
        box : ``((h_lo, h_hi), (s_lo, s_hi))`` where skin is expected (fig. 6.3b); a hue range
            with ``h_lo > h_hi`` wraps through 0.
        coverage : fraction of the in-box foreground mass kept by the threshold.
        """
        if len(images) == 0 or len(images) != len(person_masks):
            raise SegmentationError(
                f"SkinClassifier.self_train: need one person mask per image (got {len(images)} "
                f"images, {len(person_masks)} masks, at least one)"
            )
        if not 0 < coverage <= 1:
            raise SegmentationError(f"SkinClassifier.self_train: coverage must be in (0, 1], got {coverage}")
        checked = []
        for i, (im, m) in enumerate(zip(images, person_masks)):
            im = check_rgb(im, f"self-training image {i}")
            checked.append((im, _check_mask(m, im.shape, f"person mask {i}")))
        counts = self._histogram(checked)
        hb, sb = counts.shape
        hc = (np.arange(hb) + 0.5) / hb
        sc = (np.arange(sb) + 0.5) / sb
        (h0, h1), (s0, s1) = box
        in_h = (hc >= h0) & (hc <= h1) if h0 <= h1 else (hc >= h0) | (hc <= h1)
        in_s = (sc >= s0) & (sc <= s1)
        counts = counts * (in_h[:, None] & in_s[None, :])
        if counts.sum() == 0:
            raise SegmentationError(
                "SkinClassifier.self_train: no foreground pixel falls in the skin box "
                f"{box} (is the person mask empty, or the capture not minimal-clothing?)"
            )
        density = counts / counts.sum()
        values = np.sort(density.ravel())[::-1]
        k = int(np.searchsorted(np.cumsum(values), coverage))
        self.histogram, self.score, self.rule = density, density, "density"
        self.threshold = float(values[min(k, len(values) - 1)])
        self._table = None
        return self

    # ------------------------------------------------------------------ prediction
    def predict(
        self,
        image: np.ndarray,
        person_mask: np.ndarray | None = None,
        *,
        postprocess: bool = True,
    ) -> np.ndarray:
        """(H, W) bool skin mask of an RGB image (inside ``person_mask`` when given)."""
        if not self.trained:
            raise SegmentationError("SkinClassifier.predict: the model is not trained (train or load it)")
        image = check_rgb(image)
        if self._table is None:
            self._table = (self.score >= self.threshold) & (self.histogram > 0)
        hsv = _hsv8(image)
        h, s = self._bins(hsv)
        raw = self._table[h, s] & (hsv[..., 2] >= self.min_value * 255)
        person = None
        if person_mask is not None:
            person = _check_mask(person_mask, image.shape, "person_mask")
            raw &= person
        if not postprocess:
            return raw
        mask = raw.astype(np.uint8)
        if self.median > 1:
            mask = cv2.medianBlur(mask, self.median)
        mask = remove_small_components(mask, int(round(self.min_area * mask.size)), 0) & mask
        if person is not None:
            if self.edge_dilation > 0:
                mask = cv2.dilate(mask, disk(self.edge_dilation))
            mask &= person.astype(np.uint8)
        return mask.astype(bool)

    # ------------------------------------------------------------------ files
    def settings(self) -> dict:
        return {
            "format": SKIN_FORMAT,
            "version": SKIN_VERSION,
            "rule": self.rule,
            "threshold": self.threshold,
            "min_value": self.min_value,
            "median": self.median,
            "min_area": self.min_area,
            "edge_dilation": self.edge_dilation,
        }

    def save(self, path: str | Path) -> Path:
        """Write the model to an ``.npz`` file (atomically)."""
        from rigs.imageio import atomic_write_bytes

        if not self.trained:
            raise SegmentationError(f"cannot save {path}: the skin model is not trained")
        buf = io.BytesIO()
        np.savez(buf, histogram=self.histogram, score=self.score, settings=np.array(json.dumps(self.settings())))
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        return atomic_write_bytes(path, buf.getvalue(), fsync=False)

    @classmethod
    def load(cls, path: str | Path) -> "SkinClassifier":
        """Read a model written by :meth:`save`."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                histogram = data["histogram"]
                score = data["score"]
                settings = json.loads(str(data["settings"]))
        except FileNotFoundError:
            raise SegmentationError(f"{path}: skin model file not found") from None
        except (KeyError, ValueError, OSError) as exc:
            raise SegmentationError(f"{path}: not a skin model file ({exc})") from None
        if settings.get("format") != SKIN_FORMAT or settings.get("version") != SKIN_VERSION:
            raise SegmentationError(
                f"{path}: format {settings.get('format')!r} version {settings.get('version')!r}, "
                f"expected {SKIN_FORMAT!r} version {SKIN_VERSION}"
            )
        return cls(
            histogram,
            threshold=float(settings["threshold"]),
            score=score,
            rule=str(settings["rule"]),
            min_value=float(settings["min_value"]),
            median=int(settings["median"]),
            min_area=float(settings["min_area"]),
            edge_dilation=int(settings["edge_dilation"]),
        )


def ycrcb_skin(image: np.ndarray, cr=(133, 173), cb=(77, 127)) -> np.ndarray:
    """Fixed-threshold YCrCb skin detector (Chai & Ngan 1999), the benchmark baseline.

    Returns (H, W) bool: ``Cr ∈ cr`` and ``Cb ∈ cb`` (8-bit units).
    """
    image = check_rgb(image)
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    ycc = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2YCrCb)
    return (
        (ycc[..., 1] >= cr[0]) & (ycc[..., 1] <= cr[1]) & (ycc[..., 2] >= cb[0]) & (ycc[..., 2] <= cb[1])
    )
