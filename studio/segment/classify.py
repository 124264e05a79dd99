"""Per-pixel background / person / shadow decision (thesis §5.5.1, eq. 5.5–5.6).

Labels: ``BACKGROUND = 0``, ``PERSON = 1``, ``SHADOW = 2``.

The thesis rule (eq. 5.5) is

* background if ``‖[N^H, N^S, N^V]‖ < t^HSV``,
* else person (foreground) if ``N^S ≥ t^S``,
* else shadow,

with ``N`` the per-channel absolute difference to the background mean normalised by the
background standard deviation (eq. 5.6; hue distance taken around the circle). One
extension, optional and on by default (it is what the shadow literature the thesis cites —
Prati et al. 2003 / Cucchiara et al. — adds to the same HSV test): a cast shadow only
*darkens* the background, so a non-background pixel is a shadow candidate only when its value
ratio ``I^V / μ^V`` lies in ``value_ratio`` (lower, upper); brighter or nearly black pixels with
unchanged saturation are person. Set ``value_ratio=(0, inf)`` for the plain eq. 5.5.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from studio.segment.errors import SegmentationError
from studio.segment.hsv import fold_hue

__all__ = ["BACKGROUND", "PERSON", "SHADOW", "Thresholds", "classify_pixels", "normalized_difference"]

BACKGROUND, PERSON, SHADOW = 0, 1, 2


@dataclass(frozen=True)
class Thresholds:
    """Decision thresholds of eq. 5.5 (in background standard deviations) and the value-ratio gate.

    The defaults come from grid searches (:func:`studio.segment.tune_thresholds`, objective:
    mean of person and shadow F1) on labelled data. On the simulated studio session (indoor
    lights, shadows keep ~65 % of the floor's value, dark trousers ~10–30 %) the value gate
    (0.4, 0.95) separates the two (person / shadow F1 0.993 / 0.988 on the walk session,
    ``benchmarks/segmentation.py``); t^HSV in 4–8 and t^S in 4–12 do about as well. Harsh outdoor shadows need a lower gate: the CDnet
    2014 *highway* tuning split prefers (8, 12, (0.08, 0.5)) — its hard shadows keep only ~15 %
    of the road's value. The defaults are for the studio; ``benchmarks/segmentation.py`` re-tunes
    on each data set and prints the result, and ``studio segment --t-hsv/--t-s`` overrides them.
    """

    hsv: float = 6.0  # t^HSV: norm of (N^H, N^S, N^V) below which a pixel is background
    saturation: float = 8.0  # t^S: saturation change at or above which a pixel is person
    value_ratio: tuple[float, float] = (0.4, 0.95)  # shadow: μ^V·lo ≤ I^V ≤ μ^V·hi

    def __post_init__(self):
        for field in ("hsv", "saturation"):
            value = getattr(self, field)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise SegmentationError(f"Thresholds.{field}: expected a positive number, got {value!r}")
        lo, hi = self.value_ratio
        if not (0 <= lo < hi):
            raise SegmentationError(
                f"Thresholds.value_ratio: expected 0 <= lower < upper, got {self.value_ratio!r}"
            )

    def to_dict(self) -> dict:
        return {"hsv": self.hsv, "saturation": self.saturation, "value_ratio": list(self.value_ratio)}

    @classmethod
    def from_dict(cls, data: dict) -> "Thresholds":
        return cls(
            hsv=float(data["hsv"]),
            saturation=float(data["saturation"]),
            value_ratio=tuple(float(v) for v in data["value_ratio"]),
        )


def normalized_difference(hsv: np.ndarray, mean: np.ndarray, inv_std: np.ndarray) -> np.ndarray:
    """``[N^H, N^S, N^V]`` of eq. 5.6.

    Parameters
    ----------
    hsv, mean : (H, W, 3) float32 HSV in [0, 1] (hue circular).
    inv_std : (H, W, 3) float32, ``1 / σ`` per channel.

    Returns
    -------
    (H, W, 3) float32 normalised absolute differences.
    """
    d = cv2.absdiff(hsv, mean)
    fold_hue(d[..., 0], out=d[..., 0])  # hue taken around the circle
    return cv2.multiply(d, inv_std)


def classify_pixels(
    hsv: np.ndarray,
    mean: np.ndarray,
    inv_std: np.ndarray,
    thresholds: Thresholds = Thresholds(),
    ratio8: np.ndarray | None = None,
) -> np.ndarray:
    """Raw per-pixel labels of eq. 5.5 (no morphology).

    Parameters
    ----------
    hsv : (H, W, 3) float32 observed HSV.
    mean, inv_std : (H, W, 3) float32 background mean and ``1/σ``.
    ratio8 : optional (H, W) uint8 value ratio ``round(200 · I^V / μ^V)`` (saturated at 255),
        when the caller has it already; used for the value gate.

    Returns
    -------
    (H, W) uint8 labels 0 background / 1 person / 2 shadow.
    """
    n = normalized_difference(hsv, mean, inv_std)
    norm2 = cv2.transform(cv2.multiply(n, n), np.ones((1, 3), np.float32))
    nonbg = cv2.compare(norm2, float(thresholds.hsv**2), cv2.CMP_GE)  # 0 / 255
    person = cv2.compare(cv2.extractChannel(n, 1), float(thresholds.saturation), cv2.CMP_GE)
    lo, hi = thresholds.value_ratio
    if lo > 0 or math.isfinite(hi):
        if ratio8 is not None:
            lo8 = float(np.ceil(lo * 200.0 - 1e-9))
            hi8 = float(np.floor(hi * 200.0 + 1e-9)) if math.isfinite(hi) else 1e9
            darker = cv2.inRange(ratio8, lo8, hi8)
        else:
            v, mv = hsv[..., 2], mean[..., 2]
            darker = ((v >= mv * np.float32(lo)) & (v <= mv * np.float32(hi))).view(np.uint8) * np.uint8(255)
        person = cv2.bitwise_or(person, cv2.bitwise_not(darker))
    # 0 background, 2 shadow (non-background), 1 person (non-background and person)
    labels = nonbg & np.uint8(SHADOW)
    labels -= nonbg & person & np.uint8(1)
    return labels
