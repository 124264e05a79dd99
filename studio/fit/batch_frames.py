"""Frame choice of the batch fit (:func:`choose_frames`; split from :mod:`studio.fit.batch`)."""

from __future__ import annotations

import numpy as np

from studio.fit.errors import FitError

__all__ = ["CLOTHES_CHECKS", "choose_frames"]

#: Quality checks whose ``failed`` verdict a loosely clothed single-frame fit may earn from the
#: clothes alone (a body fattened to fill them: implausible mass or girths, silhouettes explained
#: poorly) — the batch is what corrects it, so such frames stay usable for a loose batch.
CLOTHES_CHECKS = frozenset({"population", "shape_prior", "agreement"})


def _failed_by_clothes(fit) -> bool:
    failed = {r.get("check") for r in fit.quality.get("reasons", []) if r.get("severity") == "failed"}
    return bool(failed) and failed <= CLOTHES_CHECKS


def choose_frames(fits: dict, n: int = 8, loose: bool = False) -> list[int]:
    """Up to ``n`` frames for a batch from single-frame fits {frame: FrameFit}: status ``ok`` first
    (``suspect`` only if fewer than two are ok; ``failed`` never, except — ``loose`` clothing,
    fewer than two otherwise — frames failed only by :data:`CLOTHES_CHECKS`), then the most diverse
    postures (farthest-point sampling on the joint angles, root heading and position left out),
    starting from the frame with the lowest cost."""
    usable = {f: fit for f, fit in fits.items() if fit.status in ("ok", "unchecked")}
    if len(usable) < 2:
        usable.update({f: fit for f, fit in fits.items() if fit.status == "suspect"})
    if len(usable) < 2 and loose:
        usable.update({f: fit for f, fit in fits.items() if fit.status == "failed" and _failed_by_clothes(fit)})
    if not usable:
        raise FitError("batch fit: no single-frame fit passed the quality gates")
    order = sorted(usable)
    X = np.array([usable[f].pose[6:] for f in order])
    costs = np.array([usable[f].costs.get("total", 0.0) for f in order])
    chosen = [int(np.argmin(costs))]
    dist = np.linalg.norm(X - X[chosen[0]], axis=1)
    while len(chosen) < min(n, len(order)):
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(X - X[k], axis=1))
    return sorted(order[k] for k in chosen)
