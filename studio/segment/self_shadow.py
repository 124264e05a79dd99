"""A camera's shadow tint and cast-shadow direction learned from its own stream, without labels.

:func:`studio.segment.learn_tint` and :func:`studio.segment.learn_shadow_direction` need pixels
known to be shadow (multi-view voting agreement in a studio, a labelled split on CDnet). One
camera watching a scene under a fixed light (the sun, a lamp) shows its shadows every frame,
though, and they can be picked out by the model's own rule, loosely, and averaged over many
frames:

1. **Candidates** — foreground pixels of the adaptive model (:meth:`BackgroundModel.apply`'s
   running mean ``μ`` before the step) that pass eq. 5.5's colour gate with a loose, untinted
   band: brightness ratio ``r = ΣI / Σμ`` in ``value_ratio`` and every channel ratio
   ``I_c / μ_c`` within ``chroma · r`` of ``r · tint_c`` (``tint`` = 1 on the first round).
2. **Direction** — in every foreground region (8-connected) holding at least ``min_pixels``
   candidates and ``min_pixels`` other pixels, the candidates' centroid minus the others'
   centroid; the regions' unit offsets averaged with their candidate counts as weights, then
   again over the regions within ``trim_degrees`` of that mean (a dark car, all candidate, gives
   a short offset in any direction: trimmed out).
3. **Tint** — the candidates that also pass the cast-shadow geometry along that direction
   (:func:`studio.segment.shadow_geometry`, chord share ``fraction``: the strip a region casts
   beyond itself, not a dark car body), eroded ``interior`` times (3×3: the strip's rim mixes the
   shadow with the lit road — blur, penumbra, JPEG — and with the car it borders; a car's dark
   paint passes as thin slivers and speckles, a cast shadow as a solid strip), give the tint by
   :func:`learn_tint` (median of ``(I_c / μ_c) / r``, normalised to mean 1).
4. ``rounds`` − 1 more times: candidates re-gated with the learned tint, then 2 and 3 again.

Nothing here runs per frame in ``apply``: :func:`stream_frame` keeps a frame's foreground pixels
(the caller's model pass), :func:`learn_stream_shadows` is an offline fit over them (~1 s of CPU
for 320 frames of 320×240).

The defaults were chosen on CDnet *highway*'s tuning split only (stream frames 60–699 every 2nd,
scored on GT 470–699 with the benchmark's gate grid, ``benchmarks/cdnet_adaptive.py``): the
morphology before the regions lifts the best tuning F at FPR-S ≤ 0.15 from 0.9837 to 0.9856;
``fraction`` 0.15 keeps half true shadow among the tint's pixels (0.3: 17 %) and gives tuning
F 0.9867 at FPR-S 0.17 (0.3: 0.9883 at 0.28, on the limit); chroma 0.3–0.5, value ratio up to
0.6–0.8, 1–3 rounds, trimming 45–60°, the first frame 30–100 and every 1st–4th frame move the
direction by ≤ 1.5° and the tuning figures by ≤ 0.001. Learned there: tint (0.977, 0.975,
1.048), direction (−0.45, 0.89), 6° from the one learned from the split's labels (−0.54, 0.84).

``interior`` (issue 18, also chosen on 470–699 only): of the tint's pixels in the stream frames
with truth (470–698), those labelled shadow or car (CDnet 50 / 255; most of the rest is the 170
"unknown" band at object edges) were 3,744 shadow / 3,267 car — purity 0.534 — with the whole
strip (``interior`` 0; 109,487 pixels in all, 11,381 unknown), 3,075 / 1,156 — purity 0.727 —
eroded once (56,049 pixels, 2,821 unknown; twice: 0.768 from 29,064). The tint moves from
(0.977, 0.975, 1.048) to (0.937, 0.954, 1.109), bluer than the one learned from the split's
labelled shadows (B 1.072: CDnet's shadow label includes the mixed rim). At the same gate (value
ratio 0.05–0.3, chroma 0.3, fraction 0.15) the tuning FPR-S falls from 0.168 to 0.146; by the
pick rule inside 470–699 (leave one block of 23 frames out, gap 10) FPR-S 0.267 → 0.252 at
F 0.987; with the shadow rim of ``AdaptiveSettings.penumbra`` = 1, 0.165 → 0.122.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import cv2
import numpy as np

from studio.segment.adaptive import learn_tint
from studio.segment.classify import PERSON, SHADOW
from studio.segment.errors import SegmentationError
from studio.segment.morphology import Morphology, clean_labels
from studio.segment.shadow_geometry import shadow_geometry

__all__ = ["StreamFrame", "StreamShadows", "learn_stream_shadows", "stream_frame"]


@dataclass(frozen=True)
class StreamFrame:
    """One frame's foreground pixels as the adaptive model saw them.

    ``shape`` (H, W); ``index`` (n,) int64 flat pixel indices; ``values`` (n, 3) frame RGB in the
    frame's dtype (uint8 or uint16); ``mean`` (n, 3) float32 running mean before the step, in
    8-bit levels.
    """

    shape: tuple[int, int]
    index: np.ndarray
    values: np.ndarray
    mean: np.ndarray


@dataclass(frozen=True)
class StreamShadows:
    """What :func:`learn_stream_shadows` learned: ``tint`` (RGB, mean 1), unit ``direction``
    (dx, dy) from objects to their shadows, and what it rests on: ``pixels`` (candidates behind
    the tint), ``regions`` (regions behind the direction, after trimming), ``frames`` used;
    ``kept``: per stream frame, (n,) bool over its :class:`StreamFrame` pixels, the last round's
    pixels behind the tint (to measure their purity against labels)."""

    tint: tuple[float, float, float]
    direction: tuple[float, float]
    pixels: int
    regions: int
    frames: int
    kept: tuple = field(default=(), repr=False, compare=False)


def stream_frame(frame: np.ndarray, mean: np.ndarray, foreground: np.ndarray) -> StreamFrame:
    """Keep the pixels of ``foreground`` ((H, W) bool) with their ``frame`` values ((H, W, 3)
    uint8 / uint16 RGB) and the model's running ``mean`` ((H, W, 3), 8-bit levels, before the step)."""
    fg = np.asarray(foreground, bool)
    if fg.ndim != 2 or frame.shape[:2] != fg.shape or mean.shape[:2] != fg.shape:
        raise SegmentationError(
            f"stream_frame: frame {frame.shape}, mean {mean.shape} and foreground {fg.shape} must share (H, W)"
        )
    idx = np.flatnonzero(fg)
    return StreamFrame(fg.shape, idx, frame.reshape(-1, 3)[idx], np.asarray(mean, np.float32).reshape(-1, 3)[idx])


def _gate(f: StreamFrame, value_ratio, chroma: float, tint: np.ndarray) -> np.ndarray:
    """(n,) bool: eq. 5.5's colour gate of :func:`studio.segment.adaptive_step` on the kept pixels."""
    v = f.values.astype(np.float32) * np.float32(1.0 if f.values.dtype == np.uint8 else 1.0 / 257.0)
    i, m = v + 1.0, f.mean + 1.0
    r = (v.sum(1) + 1.0) / (f.mean.sum(1) + 1.0)
    ok = (value_ratio[0] <= r) & (r <= value_ratio[1])
    return ok & (np.abs(i / m - r[:, None] * tint) <= chroma * r[:, None]).all(1)


def _region_offsets(labels: np.ndarray, min_pixels: int):
    """Per foreground region of ``labels`` ((H, W) 0/1/2) with at least ``min_pixels`` shadow and
    person pixels: (k, 2) centroid offsets (shadow − person, as (dx, dy)) and (k,) shadow counts."""
    n, cc = cv2.connectedComponents((labels > 0).view(np.uint8), connectivity=8)
    comp = cc.reshape(-1)
    ys, xs = np.divmod(np.arange(comp.size), labels.shape[1])
    stats = []
    for value in (SHADOW, PERSON):
        sel = labels.reshape(-1) == value
        c = np.bincount(comp[sel], minlength=n).astype(np.float64)
        stats.append((c, np.bincount(comp[sel], weights=xs[sel], minlength=n),
                      np.bincount(comp[sel], weights=ys[sel], minlength=n)))  # fmt: skip
    (nc, cx, cy), (no, ox, oy) = stats
    ok = (nc >= min_pixels) & (no >= min_pixels)
    ok[0] = False  # background
    d = np.stack([cx[ok] / nc[ok] - ox[ok] / no[ok], cy[ok] / nc[ok] - oy[ok] / no[ok]], axis=1)
    return d, nc[ok]


def _mean_direction(offsets: np.ndarray, weights: np.ndarray, trim_degrees: float):
    """Weighted mean of unit offsets, then again over those within ``trim_degrees`` of it."""
    length = np.hypot(offsets[:, 0], offsets[:, 1])
    keep = length > 0
    u, w = offsets[keep] / length[keep, None], weights[keep]
    if not len(u):
        return None, 0
    d = (w[:, None] * u).sum(0)
    if not np.hypot(*d):
        return None, 0
    near = u @ (d / np.hypot(*d)) >= math.cos(math.radians(trim_degrees))
    d = (w[near, None] * u[near]).sum(0)
    norm = float(np.hypot(*d))
    return (None, 0) if norm == 0 else ((float(d[0] / norm), float(d[1] / norm)), int(near.sum()))


def _labels(f: StreamFrame, cand: np.ndarray, morphology: Morphology | None) -> np.ndarray:
    """The frame's labels as ``apply`` makes them: candidates shadow, other foreground person,
    then the morphology of §5.5.1 (None: raw)."""
    lab = np.zeros(f.shape[0] * f.shape[1], np.uint8)
    lab[f.index] = np.where(cand, SHADOW, PERSON)
    lab = lab.reshape(f.shape)
    return lab if morphology is None else clean_labels(lab, morphology)


def _interior(f: StreamFrame, keep: np.ndarray, steps: int) -> np.ndarray:
    """(n,) bool: the pixels of ``keep`` whose 3×3 neighbourhood lies in ``keep``, ``steps`` times
    over (an erosion of the kept strip: its rim mixes shadow with road or car)."""
    if steps <= 0:
        return keep
    mask = np.zeros(f.shape[0] * f.shape[1], np.uint8)
    mask[f.index[keep]] = 1
    inner = cv2.erode(mask.reshape(f.shape), np.ones((3, 3), np.uint8), iterations=steps)
    return keep & (inner.reshape(-1)[f.index] > 0)


def learn_stream_shadows(
    stream: Sequence[StreamFrame],
    value_ratio: tuple[float, float] = (0.05, 0.6),
    chroma: float = 0.4,
    fraction: float = 0.15,
    interior: int = 1,
    rounds: int = 2,
    min_pixels: int = 20,
    trim_degrees: float = 45.0,
    min_regions: int = 5,
    morphology: Morphology | None = Morphology(),
) -> StreamShadows:
    """Tint and object-to-shadow direction of one camera from its foreground pixels alone
    (the module's steps 1–4; eq. 5.5's gate, thesis §5.5's fixed light).

    Parameters
    ----------
    stream : :class:`StreamFrame` of many frames (a few hundred of a busy scene).
    value_ratio, chroma : the loose candidate gate (brightness ratio range; channel-ratio band
        relative to ``r``).
    fraction : chord share of the cast-shadow geometry that keeps a candidate for the tint.
    interior : erosions (3×3) of the kept strip before the tint: only its core, away from the
        road and the car it borders, is averaged (0: the whole strip).
    rounds : learn passes (1: untinted gate only; 2: learn, re-gate with the tint, learn).
    min_pixels, trim_degrees, min_regions : a region's least candidates and others; the
        trimming angle; fewest regions behind a direction (else :class:`SegmentationError`).
    morphology : cleaning of the candidate labels before the regions and the geometry, as in
        ``apply`` (None: raw foreground).
    """
    if rounds < 1:
        raise SegmentationError(f"learn_stream_shadows: rounds must be >= 1, got {rounds!r}")
    tint = np.ones(3, np.float32)
    direction, pixels, regions = None, 0, 0
    for _ in range(rounds):
        cands = [_gate(f, value_ratio, chroma, tint) for f in stream]
        labels = [_labels(f, c, morphology) for f, c in zip(stream, cands)]
        parts = [_region_offsets(lab, min_pixels) for lab in labels]
        offsets = np.concatenate([p[0] for p in parts]) if parts else np.zeros((0, 2))
        weights = np.concatenate([p[1] for p in parts]) if parts else np.zeros(0)
        direction, regions = _mean_direction(offsets, weights, trim_degrees)
        if direction is None or regions < min_regions:
            raise SegmentationError(
                f"learn_stream_shadows: {regions} regions with {min_pixels} candidate and other pixels "
                f"over {len(stream)} frames, need {min_regions}"
            )
        kept = [_interior(f, c & (shadow_geometry(lab, direction, fraction).reshape(-1)[f.index] == SHADOW), interior)
                for f, c, lab in zip(stream, cands, labels)]  # fmt: skip
        pixels = int(sum(k.sum() for k in kept))
        tint = np.asarray(learn_tint([f.values[None] for f in stream], [f.mean[None] for f in stream],
                                     [k[None] for k in kept]), np.float32)  # fmt: skip
    return StreamShadows(tuple(float(v) for v in tint), direction, pixels, regions, len(stream), tuple(kept))
