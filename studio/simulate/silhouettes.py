"""A capture session of a body of the model seen as exact silhouettes (no rendering, no noise).

For tests and benchmarks that need a session with a known body: frame images are the
silhouettes in two grey levels, the segmentation labels are the silhouettes themselves.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["write_silhouette_session"]


def write_silhouette_session(path: str | Path, model, shape, poses, cameras, calibration: str | Path) -> list:
    """Write session ``path`` (frame ``i`` for ``poses[i]``) of ``model``'s body ``shape`` seen
    by ``cameras`` (their calibration saved at ``calibration``), with the exact silhouettes as
    segmentation labels. Returns the masks of every frame ([frame][camera] (H, W) bool)."""
    from rigs.imageio import write_image
    from rigs.session import SessionWriter
    from studio.render import silhouette
    from studio.workspace import Layout

    writer = SessionWriter.create(path, [c.name for c in cameras], rig="silhouettes", calibration=calibration)
    lay = Layout(path)
    out = []
    for i, pose in enumerate(poses):
        V = model.vertices(shape, pose)
        masks = [silhouette(c, V, model.faces) for c in cameras]
        writer.write_frame(i, {c.name: np.where(m[..., None], 180, 60).astype(np.uint8).repeat(3, 2)
                               for c, m in zip(cameras, masks, strict=True)})
        for c, m in zip(cameras, masks, strict=True):
            p = lay.labels(c.name, i)
            p.parent.mkdir(parents=True, exist_ok=True)
            write_image(p, m.astype(np.uint8))
        out.append(masks)
    writer.close()
    return out
