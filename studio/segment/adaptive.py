"""Adaptive per-pixel background statistics: classify a frame and update the model in one pass.

The fixed model of :mod:`studio.segment.background` (eq. 5.4, learned once from empty-scene
frames) is what the thesis describes; real cameras drift (auto exposure, daylight, flicker) and
shake by a pixel. This module keeps, per pixel and per RGB channel, a running mean ``μ`` and a
running mean absolute deviation ``δ`` (selective running average: background pixels adapt with
``rate``, pixels labelled foreground with ``foreground_rate``, so a parked object is absorbed
after a fraction of ``1/foreground_rate`` frames — its deviation grows as its mean moves — and a
swaying tree widens its own noise band), and labels each pixel with the rule of eq. 5.5 written on RGB
ratios:

* background if ``Σ_c max(|I_c − μ_c| − k · max(δ_c, δ_min), 0) < t`` (the normalised distance of
  eq. 5.6, as an excess over a per-pixel noise band),
* else shadow if the pixel is uniformly darker — brightness ratio ``r = ΣI / Σμ`` in
  ``value_ratio`` and every channel ratio ``I_c / μ_c`` within ``chroma`` of ``r · tint_c``
  (eq. 5.5's "saturation unchanged", with ``tint`` the per-camera colour of the shadowing light,
  learned from data by :func:`learn_tint`),
* else person;
* with ``penumbra`` = n > 0, a shadow's rim: a person pixel up to n 8-connected steps from the
  gated shadow becomes shadow when it passes a loose gate (``r`` in ``value_ratio[0]`` –
  ``penumbra_ratio``, channel ratios within ``penumbra_chroma · r`` of ``r · tint_c``). A cast
  shadow's edge (penumbra, and the lit road mixed into it by blur and JPEG) is lighter than its
  core and misses the core's ratio band; a dark car misses it too, but only its pixels touching
  the shadow are at risk (hysteresis, as Canny's two thresholds). The running update depends on
  background / foreground only, so the rim never changes the model.

The per-pixel work is one compiled loop (numba, ``cache=True``): the labels, the value ratio for
voting and the update of ``μ`` and ``δ`` in a single read of the frame (~2.3 ms of CPU for 656×490 on
one core). The first ``warmup`` frames adapt with rate ``1/n`` (a running mean of everything
seen), so a model can start from any frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from studio.segment.errors import SegmentationError

__all__ = ["AdaptiveSettings", "adaptive_step", "learn_tint", "penumbra_rim"]


@dataclass(frozen=True)
class AdaptiveSettings:
    """Parameters of the adaptive model (8-bit levels; rates per frame).

    The detection defaults (``noise_scale``, ``distance``) are the best of the CDnet 2014 *highway*
    tuning split (GT frames 470–699, ``benchmarks/segmentation.py``); the shadow gate defaults are
    the studio's (:class:`studio.segment.Thresholds`: indoor shadows keep 40–95 % of the floor's
    value). ``load``/``save`` of a background model carry them in ``model.json``.
    """

    rate: float = 0.02  # adaptation of background pixels (illumination drift)
    foreground_rate: float = 0.001  # adaptation under foreground (absorbs static objects)
    noise_scale: float = 2.0  # k: noise band half-width in mean absolute deviations
    noise_floor: float = 4.0  # δ_min: smallest deviation (levels), JPEG steps and sensor noise
    distance: float = 12.0  # t: summed excess over the band (levels) at which a pixel is foreground
    value_ratio: tuple[float, float] = (0.4, 0.95)  # shadow brightness ratio range
    chroma: float = 0.08  # shadow: largest channel-ratio deviation from r · tint (relative)
    tint: tuple[float, float, float] = (1.0, 1.0, 1.0)  # per-channel ratio of the shadowing light (RGB)
    warmup: int = 30  # frames averaged with rate 1/n before the selective update takes over
    # cast-shadow geometry (studio.segment.shadow_geometry): None = off; else the image direction
    # from an object to its shadow, and the share of the chord a shadow pixel may have ahead of it
    shadow_direction: tuple[float, float] | None = None
    shadow_fraction: float = 0.2
    # shadow rim (hysteresis): steps of growth from the gated shadow into loosely gated person pixels
    penumbra: int = 0
    penumbra_ratio: float = 0.6  # loose gate: largest brightness ratio
    penumbra_chroma: float = 0.4  # loose gate: channel-ratio band, relative

    def __post_init__(self):
        for name in ("rate", "foreground_rate"):
            v = getattr(self, name)
            if not (0.0 <= v <= 1.0):
                raise SegmentationError(f"AdaptiveSettings.{name}: expected a rate in [0, 1], got {v!r}")
        for name in ("noise_scale", "noise_floor", "distance", "chroma", "penumbra_chroma"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise SegmentationError(f"AdaptiveSettings.{name}: expected a positive number, got {v!r}")
        lo, hi = self.value_ratio
        if not (0 <= lo < hi):
            raise SegmentationError(f"AdaptiveSettings.value_ratio: expected 0 <= lower < upper, got {self.value_ratio!r}")
        if len(self.tint) != 3 or min(self.tint) <= 0:
            raise SegmentationError(f"AdaptiveSettings.tint: expected 3 positive ratios, got {self.tint!r}")
        if self.shadow_direction is not None and (
            len(self.shadow_direction) != 2 or not all(math.isfinite(v) for v in self.shadow_direction)
            or not any(self.shadow_direction)
        ):
            raise SegmentationError(
                f"AdaptiveSettings.shadow_direction: expected None or a non-zero (dx, dy), got {self.shadow_direction!r}"
            )
        if not (0.0 < self.shadow_fraction <= 1.0):
            raise SegmentationError(f"AdaptiveSettings.shadow_fraction: expected (0, 1], got {self.shadow_fraction!r}")
        if not (isinstance(self.penumbra, int) and self.penumbra >= 0):
            raise SegmentationError(f"AdaptiveSettings.penumbra: expected an int >= 0, got {self.penumbra!r}")
        if not self.penumbra_ratio > lo:
            raise SegmentationError(
                f"AdaptiveSettings.penumbra_ratio: expected above value_ratio's lower {lo}, got {self.penumbra_ratio!r}"
            )
        if self.warmup < 0:
            raise SegmentationError(f"AdaptiveSettings.warmup: expected >= 0, got {self.warmup!r}")

    def to_dict(self) -> dict:
        return {"rate": self.rate, "foreground_rate": self.foreground_rate, "noise_scale": self.noise_scale,
                "noise_floor": self.noise_floor, "distance": self.distance, "value_ratio": list(self.value_ratio),
                "chroma": self.chroma, "tint": list(self.tint), "warmup": self.warmup,
                "shadow_direction": None if self.shadow_direction is None else list(self.shadow_direction),
                "shadow_fraction": self.shadow_fraction, "penumbra": self.penumbra,
                "penumbra_ratio": self.penumbra_ratio, "penumbra_chroma": self.penumbra_chroma}  # fmt: skip

    @classmethod
    def from_dict(cls, data: dict) -> "AdaptiveSettings":
        d = dict(data)
        d["value_ratio"] = tuple(float(v) for v in d["value_ratio"])
        d["tint"] = tuple(float(v) for v in d["tint"])
        if d.get("shadow_direction") is not None:
            d["shadow_direction"] = tuple(float(v) for v in d["shadow_direction"])
        if "penumbra" in d:
            d["penumbra"] = int(d["penumbra"])
        return cls(**d)


@njit(cache=True, nogil=True, fastmath=True, inline="always")
def _tinted(v0, v1, v2, m0, m1, m2, r, t0, t1, t2, band):
    """Every channel's ratio to the background within ``band`` of the brightness ratio ``r``
    times the shadow's tint (eq. 5.5–5.6 with a learned tint)."""
    return (abs((v0 + 1.0) / (m0 + 1.0) - r * t0) <= band and abs((v1 + 1.0) / (m1 + 1.0) - r * t1) <= band
            and abs((v2 + 1.0) / (m2 + 1.0) - r * t2) <= band)


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _step(frame, mean, dev, labels, ratio8, rate, fg_rate, k, floor, dist, lo, hi, chroma, tint, scale,
          loose_hi, loose_chroma):
    h, w = labels.shape
    t0, t1, t2 = tint[0], tint[1], tint[2]
    for y in range(h):
        for x in range(w):
            v0 = frame[y, x, 0] * scale
            v1 = frame[y, x, 1] * scale
            v2 = frame[y, x, 2] * scale
            m0 = mean[y, x, 0]
            m1 = mean[y, x, 1]
            m2 = mean[y, x, 2]
            d0 = v0 - m0
            d1 = v1 - m1
            d2 = v2 - m2
            a0 = abs(d0)
            a1 = abs(d1)
            a2 = abs(d2)
            e0 = a0 - k * max(dev[y, x, 0], floor)
            e1 = a1 - k * max(dev[y, x, 1], floor)
            e2 = a2 - k * max(dev[y, x, 2], floor)
            excess = max(e0, 0.0) + max(e1, 0.0) + max(e2, 0.0)
            r = (v0 + v1 + v2 + 1.0) / (m0 + m1 + m2 + 1.0)
            q = 200.0 * r + 0.5
            ratio8[y, x] = 255 if q >= 255.0 else np.uint8(q)
            label = 0
            if excess >= dist:
                label = 1
                if lo <= r <= hi and _tinted(v0, v1, v2, m0, m1, m2, r, t0, t1, t2, chroma * r):
                    label = 2
                elif (loose_hi > 0.0 and lo <= r <= loose_hi
                      and _tinted(v0, v1, v2, m0, m1, m2, r, t0, t1, t2, loose_chroma * r)):
                    label = 3  # loosely gated person: the rim may take it (_grow)
            labels[y, x] = label
            a = rate if label == 0 else fg_rate
            mean[y, x, 0] = m0 + a * d0
            mean[y, x, 1] = m1 + a * d1
            mean[y, x, 2] = m2 + a * d2
            dev[y, x, 0] += a * (a0 - dev[y, x, 0])
            dev[y, x, 1] += a * (a1 - dev[y, x, 1])
            dev[y, x, 2] += a * (a2 - dev[y, x, 2])


@njit(cache=True, nogil=True)
def _grow(labels, steps):  # labels (H, W) uint8, 3 = loosely gated person
    """Rim growth in place: ``steps`` times, every loosely gated person pixel (3) with an
    8-neighbour shadow (2) becomes shadow; the rest of 3 is person (1) at the end."""
    h, w = labels.shape
    for _ in range(steps):
        changed = 0
        for y in range(h):
            for x in range(w):
                if labels[y, x] != 3:
                    continue
                hit = False
                for yy in range(max(y - 1, 0), min(y + 2, h)):
                    for xx in range(max(x - 1, 0), min(x + 2, w)):
                        if labels[yy, xx] == 2:
                            hit = True
                if hit:
                    labels[y, x] = 4  # shadow from this step on (not seen as 2 within the step)
                    changed += 1
        for y in range(h):
            for x in range(w):
                if labels[y, x] == 4:
                    labels[y, x] = 2
        if changed == 0:
            break
    for y in range(h):
        for x in range(w):
            if labels[y, x] == 3:
                labels[y, x] = 1


def penumbra_rim(labels: np.ndarray, steps: int) -> np.ndarray:
    """Grow the shadow rim in place on raw labels from ``adaptive_step(..., rim=False)``
    ((H, W) uint8 with 3 marking loosely gated person pixels): ``steps`` rounds of 8-connected
    growth from shadow (2) into 3; what is left of 3 becomes person (1). Returns ``labels``."""
    if labels.ndim != 2 or labels.dtype != np.uint8:
        raise SegmentationError(f"penumbra_rim: labels must be (H, W) uint8, got {labels.shape} {labels.dtype}")
    _grow(labels, int(steps))
    return labels


def adaptive_step(
    frame: np.ndarray, mean: np.ndarray, dev: np.ndarray, settings: AdaptiveSettings, seen: int, rim: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Label one frame and update ``mean`` / ``dev`` in place.

    Parameters
    ----------
    frame : (H, W, 3) uint8 or uint16 RGB.
    mean, dev : (H, W, 3) float32 running mean and mean absolute deviation, in 8-bit levels.
    seen : frames the model has adapted to so far (warm-up: rate ``1/(seen+1)``).
    rim : grow the shadow rim (``settings.penumbra``) here; False leaves the loosely gated person
        pixels as 3 for :func:`penumbra_rim` (a caller holding only some of the frame's pixels).

    Returns
    -------
    ``(labels, ratio8)``: (H, W) uint8 raw labels 0/1/2 and the value ratio ``round(200 · ΣI/Σμ)``.
    """
    s = settings
    rate, fg_rate = s.rate, s.foreground_rate
    if seen < s.warmup:
        rate = fg_rate = max(rate, 1.0 / (seen + 1))
    labels = np.empty(frame.shape[:2], np.uint8)
    ratio8 = np.empty(frame.shape[:2], np.uint8)
    scale = 1.0 if frame.dtype == np.uint8 else 1.0 / 257.0
    _step(frame, mean, dev, labels, ratio8, np.float32(rate), np.float32(fg_rate), np.float32(s.noise_scale),
          np.float32(s.noise_floor), np.float32(s.distance), np.float32(s.value_ratio[0]),
          np.float32(min(s.value_ratio[1], 1e30)), np.float32(s.chroma), np.asarray(s.tint, np.float32),
          np.float32(scale), np.float32(s.penumbra_ratio if s.penumbra else 0.0),
          np.float32(s.penumbra_chroma))  # fmt: skip
    if s.penumbra and rim:
        _grow(labels, s.penumbra)
    return labels, ratio8


def learn_tint(frames, means, shadow_masks, min_pixels: int = 200) -> tuple[float, float, float]:
    """Per-camera colour of the shadowing light: the median, over pixels known to be shadow, of
    ``(I_c / μ_c) / r`` (``r`` the brightness ratio), normalised to mean 1.

    ``shadow_masks`` come from wherever the camera's shadows are known: multi-view voting
    agreement (§5.5.2) in a studio, a labelled tuning split on CDnet. Outdoor shadows are lit by
    the sky only and come out bluish (``tint`` B > 1 > R).
    """
    ratios = []
    for frame, mean, mask in zip(frames, means, shadow_masks):
        if not mask.any():
            continue
        scale = 1.0 if frame.dtype == np.uint8 else 1.0 / 257.0
        i = frame[mask].astype(np.float32) * scale + 1.0
        m = np.asarray(mean, np.float32)[mask] + 1.0
        rc = i / m
        ratios.append(rc / (i.sum(1) / m.sum(1))[:, None])
    if not ratios or sum(len(r) for r in ratios) < min_pixels:
        raise SegmentationError(
            f"learn_tint: need at least {min_pixels} shadow pixels, got {sum(len(r) for r in ratios)}"
        )
    t = np.median(np.concatenate(ratios), axis=0)
    t = t / t.mean()
    return tuple(float(v) for v in t)
