"""Speed of the 4-view silhouette cost (eq. 4.4–4.6) at 656×490.

Anchor: the fitting issue's target of ≤ 10 ms per 4-view cost evaluation at full
resolution (the thesis's camera size, §7.2.3: 4 views of 656×490; its Matlab fit
took ~40 min). Synthetic silhouettes: a person-like union of ellipses per view
(torso, head, arms, legs), the model a perturbed copy. Measures the per-frame
precompute (`SilhouetteTarget.build`) and the per-evaluation time
(`silhouette_cost`) at pyramid levels 0–2 and both distance masks, and checks the
fast path against the whole-image reference (`symmetric_chamfer`).

Run: ``.venv/bin/python benchmarks/cost_speed.py``; writes
``benchmarks/results/cost_speed.json``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from studio.cost import SilhouetteTarget, downsample_mask, silhouette_cost, symmetric_chamfer

H, W = 490, 656
VIEWS = 4
TAU = 20.0
TARGET_MS = 10.0


def person_mask(cx: float, rng: np.random.Generator | None = None, jitter: float = 0.0) -> np.ndarray:
    """A standing person ~380 px tall centred at column ``cx``, optionally perturbed by ``jitter`` px."""
    yy, xx = np.mgrid[:H, :W]
    parts = [  # (cy, cx, semi-axis y, semi-axis x)
        (150, cx, 75, 45),  # torso
        (55, cx, 28, 22),  # head
        (150, cx - 75, 70, 14),  # left arm
        (150, cx + 75, 70, 14),  # right arm
        (320, cx - 25, 110, 20),  # left leg
        (320, cx + 25, 110, 20),  # right leg
    ]
    mask = np.zeros((H, W), dtype=bool)
    for cy, px, ay, ax in parts:
        d = rng.normal(0.0, jitter, 4) if rng is not None else np.zeros(4)
        mask |= ((yy - cy - 30 - d[0]) / (ay + d[2])) ** 2 + ((xx - px - d[1]) / (ax + d[3])) ** 2 < 1
    return mask


def timed(fn, repeats: int) -> tuple[float, float]:
    """Best and median wall time of ``fn()`` in milliseconds.

    The best time is the figure to compare with the target: the machine is shared,
    and the median also counts time the process spent waiting for a core.
    """
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.min(times)), 1e3 * float(np.median(times))


def main() -> None:
    from rigs.atomic import atomic_write_text

    rng = np.random.default_rng(0)
    centres = W / 2 + rng.uniform(-40, 40, VIEWS)
    observed = [person_mask(cx) for cx in centres]
    models = [person_mask(cx, rng, jitter=5.0) for cx in centres]  # a hypothesis a few pixels off
    rows = []
    for mask_size in ("precise", 5):
        for level in (0, 1, 2):
            precompute, _ = timed(
                lambda: SilhouetteTarget.build(observed, tau=TAU, level=level, mask_size=mask_size), 5)
            target = SilhouetteTarget.build(observed, tau=TAU, level=level, mask_size=mask_size)
            level_models = [downsample_mask(m, level) for m in models]
            per_eval, per_eval_median = timed(lambda: silhouette_cost(target, level_models), 100)
            cost = silhouette_cost(target, level_models).total
            reference = target.unit_factor * sum(
                symmetric_chamfer(m, o, target.tau_level, mask_size=mask_size)
                for m, o in zip(level_models, target.masks, strict=True)
            )
            reference_ms, _ = timed(
                lambda: [symmetric_chamfer(m, o, target.tau_level, mask_size=mask_size)
                         for m, o in zip(level_models, target.masks, strict=True)], 5)
            rows.append({
                "mask_size": str(mask_size),
                "level": level,
                "image": f"{target.image_size[1]}x{target.image_size[0]}",
                "precompute_ms": round(precompute, 3),
                "eval_ms": round(per_eval, 3),
                "eval_median_ms": round(per_eval_median, 3),
                "whole_image_eval_ms": round(reference_ms, 3),
                "cost_px": round(cost, 4),
                "abs_error_vs_whole_image": float(abs(cost - reference)),
                "meets_target": per_eval <= TARGET_MS,
            })
    header = (f"{'mask':>8} {'lvl':>3} {'image':>8} {'precomp ms':>10} {'eval ms':>8} {'median':>7} "
              f"{'naive ms':>9} {'cost px':>8} {'ok':>3}")
    print(f"4-view silhouette cost, {W}x{H}, tau={TAU} px; target <= {TARGET_MS} ms per evaluation "
          f"(best of 100; median beside it; 'naive' = whole-image distance transforms)")
    print(header)
    for r in rows:
        print(f"{r['mask_size']:>8} {r['level']:>3} {r['image']:>8} {r['precompute_ms']:>10.2f} "
              f"{r['eval_ms']:>8.2f} {r['eval_median_ms']:>7.2f} "
              f"{r['whole_image_eval_ms']:>9.2f} {r['cost_px']:>8.3f} {'yes' if r['meets_target'] else 'NO':>3}")
    out = Path(__file__).resolve().parent / "results" / "cost_speed.json"
    payload = {"benchmark": "cost_speed", "anchor": f"<= {TARGET_MS} ms per 4-view evaluation at {W}x{H}",
               "views": VIEWS, "tau_px": TAU, "rows": rows}
    atomic_write_text(out, json.dumps(payload, indent=2), mkdir=True)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
