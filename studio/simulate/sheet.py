"""Contact sheets: one multi-frame of a session (all cameras) above its truth masks."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

__all__ = ["contact_sheet", "LABEL_COLOURS"]

#: RGB of label 0 (background), 1 (person), 2 (shadow) and of visible skin in the sheet.
LABEL_COLOURS = {0: (20, 20, 24), 1: (235, 235, 235), 2: (80, 90, 200), "skin": (240, 150, 100)}


def contact_sheet(session: str | Path, index: int = 0, scale: float = 0.5) -> np.ndarray:
    """RGB (H, W, 3) uint8: row 1 the frames of every camera, row 2 their truth labels
    (person, shadow, skin coloured as :data:`LABEL_COLOURS`), camera names written in.
    """
    from rigs.imageio import read_image
    from rigs.session import Session
    from studio.workspace import Layout

    s = Session.open(session)
    if s.truth_dir is None:
        raise ValueError(f"{session}: no truth/ folder (not a simulated session)")
    cams = s.info["cameras"]
    top, bottom = [], []
    for cam in cams:
        img = s.image(cam, index)
        lab = read_image(Layout(s.path).truth_labels(cam, index))
        skin = read_image(Layout(s.path).truth_skin(cam, index)) > 0
        m = np.zeros_like(img)
        for k in (0, 1, 2):
            m[lab == k] = LABEL_COLOURS[k]
        m[skin] = LABEL_COLOURS["skin"]
        size = (int(img.shape[1] * scale), int(img.shape[0] * scale))
        img = cv2.resize(img, size, interpolation=cv2.INTER_AREA)
        m = cv2.resize(m, size, interpolation=cv2.INTER_NEAREST)
        cv2.putText(img, cam, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
        cv2.putText(m, f"{cam} truth", (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1,
                    cv2.LINE_AA)
        top.append(img)
        bottom.append(m)
    sep = lambda a: np.full((a.shape[0], 2, 3), 255, np.uint8)  # noqa: E731
    row = lambda ims: np.hstack([x for im in ims for x in (im, sep(im))][:-1])  # noqa: E731
    r1, r2 = row(top), row(bottom)
    return np.vstack([r1, np.full((2, r1.shape[1], 3), 255, np.uint8), r2])
