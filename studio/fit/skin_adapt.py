"""Skin / clothing split adapted to the session from visible skin (thesis §6.3.4, eq. 6.10).

The segmentation's skin model is learned without labels inside the thesis' fixed Hue–Saturation
box (fig. 6.3b), which misses dark or very light skin and takes in skin-coloured clothes. Once
single-frame bodies are fitted, the session labels itself: pixels where the fitted body shows
the **hands and the face** (head faces below the head's middle, above is hair) are skin seeds,
pixels where it shows the **trunk and thighs** are clothing seeds (both inside the observed
person mask, away from its border). A Hue–Saturation histogram classifier is trained on these
seeds (``P(skin | H, S)`` ranked, threshold at the best F1 on the seeds, :class:`SkinClassifier`)
and predicts the skin masks ``F^s`` of the batch frames.
"""

from __future__ import annotations

import logging

import cv2
import numpy as np

from studio.render import rasterize
from studio.segment.skin import SkinClassifier

__all__ = ["MIN_SEED_PIXELS", "SKIN_PARTS", "CLOTH_PARTS", "adapt_skin", "seed_masks"]

log = logging.getLogger(__name__)

#: Parts whose visible pixels are skin seeds (hands; the head below its middle is added).
SKIN_PARTS = ("hand_l", "hand_r")
#: Parts whose visible pixels are clothing seeds.
CLOTH_PARTS = ("pelvis", "torso", "upperleg_l", "upperleg_r")
#: Fewer skin (or clothing) seed pixels than this over the session: no adaptation.
MIN_SEED_PIXELS = 150


def seed_masks(model, camera, shape, pose, person: np.ndarray, erode: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """(skin seeds, clothing seeds), (H, W) bool each, of one fitted body in one view."""
    V = model.vertices(shape, pose)
    ras = rasterize(camera, V, model.faces)
    names = list(model.part_names)
    fp = np.full(ras.face.shape, -1, np.int64)
    hit = ras.face >= 0
    fp[hit] = model.face_parts[ras.face[hit]]
    head = names.index("head")
    head_v = model.parts == head
    mid = 0.5 * (V[head_v, 2].min() + V[head_v, 2].max())
    face_low = np.zeros(len(model.faces), bool)
    face_low[model.face_parts == head] = V[model.faces[model.face_parts == head]].mean(axis=1)[:, 2] < mid
    skin = np.isin(fp, [names.index(n) for n in SKIN_PARTS])
    skin[hit] |= face_low[ras.face[hit]]
    cloth = np.isin(fp, [names.index(n) for n in CLOTH_PARTS])
    inner = person.astype(np.uint8)
    if erode > 0:
        inner = cv2.erode(inner, np.ones((2 * erode + 1, 2 * erode + 1), np.uint8))
    inner = inner.astype(bool)
    return skin & inner, cloth & inner


def adapt_skin(samples, *, min_seed: int = MIN_SEED_PIXELS) -> tuple[SkinClassifier | None, dict]:
    """Train a skin classifier on the seeds of fitted frames.

    ``samples``: iterable of ``(image (H, W, 3) uint8 RGB, person mask, model, camera, shape,
    pose)``. Returns the classifier (None when there are fewer than ``min_seed`` skin or clothing
    seed pixels) and a summary (seed counts, training F1 threshold).
    """
    pix, lab = [], []
    for image, person, model, camera, shape, pose in samples:
        skin, cloth = seed_masks(model, camera, shape, pose, person)
        pix += [image[skin], image[cloth]]
        lab += [np.ones(int(skin.sum()), bool), np.zeros(int(cloth.sum()), bool)]
    labels = np.concatenate(lab) if lab else np.zeros(0, bool)
    info = {"skin_seed_pixels": int(labels.sum()), "clothing_seed_pixels": int((~labels).sum())}
    if info["skin_seed_pixels"] < min_seed or info["clothing_seed_pixels"] < min_seed:
        log.info("skin adaptation: too few seeds (%s)", info)
        return None, info | {"adapted": False}
    strip = np.concatenate(pix)[None].astype(np.uint8)  # one row of seed pixels
    model = SkinClassifier().train([strip], [labels[None]], rule="posterior")
    return model, info | {"adapted": True, "threshold": model.threshold}
