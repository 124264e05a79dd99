"""The adaptive model's grids on CDnet *highway* (``segmentation_cdnet.py``), scored once per frame.

The running model of :meth:`studio.segment.BackgroundModel.apply` updates a pixel with the
background rate when its excess over the noise band is below the distance ``t`` and with the
foreground rate otherwise — whatever the shadow gate, the morphology or the cast-shadow geometry
then make of it. So for fixed detection settings (``noise_scale``, ``distance``) the running
state is the same for every gate, and one pass over frames 1–1200 (:class:`DetectionRun`)
keeps what any gate needs: for each ground-truth frame, the pixels over the distance (their
frame values, running mean and deviation just before the step). A gate setting is then replayed
on those pixels by the same compiled step (:func:`studio.segment.adaptive.adaptive_step`), its
shadow rim grown on the frame's image (:func:`studio.segment.adaptive.penumbra_rim`: the rim only
reaches loosely gated pixels, all of them over the distance, so all kept), followed by the same
morphology and geometry as ``apply`` — identical labels (checked in the
benchmark against full ``apply`` runs) at ~0.5 ms a frame instead of a 1200-frame run per setting.

Every setting is scored on every ground-truth frame (:func:`studio.segment.tuning.cdnet_counts`),
so the picks of any tuning set are sums over its frames.
"""

from __future__ import annotations

import itertools

import numpy as np

from studio.segment import PERSON, AdaptiveSettings, clean_labels, learn_shadow_direction, learn_tint, shadow_geometry
from studio.segment.adaptive import adaptive_step, penumbra_rim
from studio.segment.self_shadow import StreamFrame, learn_stream_shadows, stream_frame
from studio.segment.tuning import cdnet_counts, pick_operating_point, scores_from_counts

# grids, fixed before any evaluation figure of this protocol was computed
DETECTION_GRID = tuple(itertools.product((1.5, 2.0, 2.5), (8.0, 12.0, 16.0)))  # noise_scale, distance
VALUE_RATIOS = ((0.05, 0.2), (0.05, 0.3), (0.08, 0.4), (0.05, 0.5))
CHROMAS = (0.05, 0.1, 0.2, 0.3)
FRACTIONS = (0.1, 0.15, 0.2, 0.25, 0.3)  # geometry: chord share of the shadow strip
# shadow rim (AdaptiveSettings.penumbra), added by issue 18 and chosen on 470–699 only: rim 1 for every
# gate; the grids (0,), (1,), (2,), (0, 1), (0, 1, 2) compared by the pick rule inside 470–699
# (leave one block of 23 frames out, gap 10): label-free FPR-S 0.252 / 0.122 / 0.234 / 0.241 / 0.272, F 0.987–0.988
PENUMBRAS = (1,)
FPRS_LIMIT = 0.30  # the target's own limit, used as the pick rule's limit


def detection_settings(noise_scale: float, distance: float) -> AdaptiveSettings:
    """Detection only: every pixel over the distance is foreground (no shadow label)."""
    return AdaptiveSettings(noise_scale=noise_scale, distance=distance, value_ratio=(0.0, 1e-3))


class DetectionRun:
    """One pass of the adaptive model (``start`` on frame 1, then every frame 1..last, as the
    benchmark's ``apply`` runs) with detection settings ``det``; keeps, for each frame in ``keep``,
    the pixels over the distance or in ``extra[i]`` (CDnet's shadow truth, for :func:`learn_tint`)
    with their frame values and the running mean / deviation before the step; and for each frame in
    ``stream`` its foreground pixels (:func:`studio.segment.stream_frame`, no truth: the label-free
    tint and direction of :func:`studio.segment.learn_stream_shadows`)."""

    def __init__(self, frames, det: AdaptiveSettings, keep, extra: dict | None = None, store: bool = True,
                 stream=()):  # fmt: skip
        self.det, self.shape = det, frames[0].shape[:2]
        self.raw: dict[int, np.ndarray] = {}  # frame -> (H, W) bool, over the distance
        self.pixels: dict[int, tuple] = {}  # frame -> (flat index, frame values, mean, dev)
        self.stream: dict[int, StreamFrame] = {}
        keep, stream = set(keep), set(stream)
        mean = frames[0].astype(np.float32)  # BackgroundModel.start: the first frame, seen once
        dev = np.zeros_like(mean)
        for i in range(1, max(keep | stream) + 1):
            frame = frames[i - 1]
            snap = (mean.copy(), dev.copy()) if (store and i in keep) or i in stream else None
            labels, _ = adaptive_step(frame, mean, dev, det, i)
            if i in stream:
                self.stream[i] = stream_frame(frame, snap[0], labels > 0)
            if i not in keep:
                continue
            over = labels > 0
            self.raw[i] = over
            if store:
                sel = over | extra[i] if extra is not None and i in extra else over
                idx = np.flatnonzero(sel)
                self.pixels[i] = (idx, frame.reshape(-1, 3)[idx][None], snap[0].reshape(-1, 3)[idx][None],
                                  snap[1].reshape(-1, 3)[idx][None])  # fmt: skip

    def detection_labels(self, i: int) -> np.ndarray:
        """``apply``'s labels of frame ``i`` with detection only (morphology, all foreground person)."""
        return clean_labels(self.raw[i].view(np.uint8) * np.uint8(PERSON))

    def gated_labels(self, i: int, gate: AdaptiveSettings) -> np.ndarray:
        """``apply``'s labels of frame ``i`` (before geometry) with ``gate``'s shadow gate."""
        idx, values, mean, dev = self.pixels[i]
        sub, _ = adaptive_step(values, mean.copy(), dev.copy(), gate, 10**9, rim=False)
        raw = np.zeros(self.shape, np.uint8)
        raw.reshape(-1)[idx] = sub[0]
        return clean_labels(penumbra_rim(raw, gate.penumbra))

    def tint(self, frames_: list[int], shadow_masks: dict) -> tuple[float, float, float]:
        """:func:`learn_tint` over ``frames_`` from their known shadow pixels (``shadow_masks[i]``)."""
        vals, means, masks = [], [], []
        for i in frames_:
            idx, values, mean, _ = self.pixels[i]
            vals.append(values)
            means.append(mean)
            masks.append(shadow_masks[i].reshape(-1)[idx][None])
        return learn_tint(vals, means, masks)


def count_table(frames_: list[int], labels_of, truths: dict, roi) -> np.ndarray:
    """(N, 8) counts of ``labels_of(i)`` for every frame ``i`` in ``frames_``."""
    return np.stack([cdnet_counts(labels_of(i), truths[i], roi) for i in frames_])


def detection_grid(frames, gt_frames: list[int], truths: dict, roi) -> dict:
    """Counts of every detection setting on every ground-truth frame: ``{(k, t): (N, 8)}``."""
    table = {}
    for k, t in DETECTION_GRID:
        run = DetectionRun(frames, detection_settings(k, t), gt_frames, store=False)
        table[(k, t)] = count_table(gt_frames, run.detection_labels, truths, roi)
    return table


def labelled_shadows(run: DetectionRun, tune: list[int], truths: dict, shadow_masks: dict):
    """Tint and direction from the truth of ``tune``'s frames (:func:`learn_tint`, :func:`learn_shadow_direction`)."""
    tint = run.tint(tune, shadow_masks)
    return tint, learn_shadow_direction([truths[i] == 255 for i in tune], [shadow_masks[i] for i in tune])


def label_free_shadows(run: DetectionRun, frames_: list[int]):
    """Tint and direction from the model's own foreground over ``frames_`` (no truth;
    :func:`learn_stream_shadows` with its defaults). Returns the :class:`StreamShadows`."""
    return learn_stream_shadows([run.stream[i] for i in frames_])


def tint_purity(run: DetectionRun, learned, frames_: list[int], truths: dict) -> dict:
    """The label-free tint's pixels (``learned.kept`` over ``frames_``, the frames it was learned
    from) on the frames with truth: counts labelled shadow (50), car (255) and unknown (170), and
    the purity shadow / (shadow + car). Truth is only counted here, never used to learn."""
    n = {"shadow": 0, "car": 0, "unknown": 0}
    for i, kept in zip(frames_, learned.kept):
        if i not in truths:
            continue
        t = truths[i].reshape(-1)[run.stream[i].index[kept]]
        n["shadow"] += int((t == 50).sum())
        n["car"] += int((t == 255).sum())
        n["unknown"] += int((t == 170).sum())
    return {**n, "purity": n["shadow"] / max(n["shadow"] + n["car"], 1)}


def gate_grid(run: DetectionRun, gt_frames: list[int], truths: dict, roi, tint, direction,
              penumbras=PENUMBRAS) -> dict:  # fmt: skip
    """Every colour gate with ``tint`` (and each shadow rim of ``penumbras``), alone and with each
    geometry fraction along ``direction``, scored on every ground-truth frame: ``{settings: (N, 8)}``."""
    base = run.det.to_dict()
    settings = []
    for vr, chroma, rim in itertools.product(VALUE_RATIOS, CHROMAS, penumbras):
        gate = AdaptiveSettings.from_dict({**base, "value_ratio": vr, "chroma": chroma, "tint": tint, "penumbra": rim})
        settings.append((gate, [AdaptiveSettings.from_dict({**gate.to_dict(), "shadow_direction": direction,
                                                            "shadow_fraction": f}) for f in FRACTIONS]))  # fmt: skip
    table = {}
    for gate, shaped in settings:
        rows = {s: [] for s in [gate, *shaped]}
        for i in gt_frames:
            lab = run.gated_labels(i, gate)
            rows[gate].append(cdnet_counts(lab, truths[i], roi))
            for s in shaped:
                rows[s].append(cdnet_counts(shadow_geometry(lab, direction, s.shadow_fraction), truths[i], roi))
        table.update({s: np.stack(r) for s, r in rows.items()})
    return table


def tuning_points(table: dict, rows: np.ndarray) -> list[tuple[object, float, float]]:
    """``(key, tuning F, tuning FPR-S)`` of every setting of ``table`` over the frame rows ``rows``."""
    out = []
    for key, counts in table.items():
        sc = scores_from_counts(counts[rows])
        out.append((key, sc["f_measure"], sc["fpr_shadow"]))
    return out


def picks(det_points, gate_points) -> dict:
    """The operating points of one tuning set, by the pick rule (best tuning F within a limit):

    * ``best F``: detection only or a colour gate, no limit;
    * ``colour, FPR-S≤0.3``: colour gates (no geometry) with tuning FPR-S ≤ 0.30;
    * ``target``: every point (detection only, colour gates, colour gates + geometry) with tuning
      FPR-S ≤ 0.30 — the point the issue's target is checked at.
    """
    colour = [p for p in gate_points if p[0].shadow_direction is None]
    return {"best F": pick_operating_point(det_points[:1] + colour),
            "colour, FPR-S≤0.3": pick_operating_point(colour, FPRS_LIMIT),
            "target": pick_operating_point(det_points[:1] + gate_points, FPRS_LIMIT)}  # fmt: skip
