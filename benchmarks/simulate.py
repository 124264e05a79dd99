"""Rendering speed of the simulated studio at the thesis rig size (4 × 656×490).

Anchor (thesis §4.8/§5.8): the capture rig ran at 60 Hz per camera; the silhouette-only
path (what the fitter calls thousands of times) should render faster than that per camera.
Also times the shadow mask and the full colour frame (shadows, shading, sensor effects).

    .venv/bin/python benchmarks/simulate.py [--frames N]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ANCHOR_HZ = 60.0


def main() -> None:
    from rigs.atomic import atomic_write_text

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=8, help="walk frames to time")
    args = ap.parse_args()

    from rich.console import Console
    from rich.table import Table

    from studio.render import rasterize, shadow_mask, silhouette
    from studio.simulate import Scene, apply_sensor, load_spec

    spec = load_spec(ROOT / "studio" / "samples" / "walk" / "spec.yaml")
    scene = Scene(spec, seed=0)
    cams = scene.cameras
    F = scene.body.faces
    frames = list(scene.frame_range)[: args.frames]
    verts = [scene.dressed(i) for i in frames]
    for cam in cams:  # warm-up: backdrop ray casting is cached once per camera
        scene.backdrop(cam)
        silhouette(cam, verts[0], F)

    def timed(fn) -> float:
        """Median seconds per camera image (robust to other processes on a shared machine)."""
        times = []
        for V in verts:
            for cam in cams:
                t0 = time.perf_counter()
                fn(cam, V)
                times.append(time.perf_counter() - t0)
        return float(np.median(times))

    import cv2

    from studio.render import front_facing

    def fill_loop(cam, V):  # per-triangle cv2.fillConvexPoly over the front faces
        img = np.zeros((cam.size[1], cam.size[0]), np.uint8)
        uv = cam.project(V)
        for tri in np.round(uv[F[front_facing(cam, V, F)]] * 256).astype(np.int32):
            cv2.fillConvexPoly(img, tri, 1, cv2.LINE_8, 8)
        return img

    def fill_poly(cam, V):  # one cv2.fillPoly call over all front faces
        img = np.zeros((cam.size[1], cam.size[0]), np.uint8)
        uv = cam.project(V)
        cv2.fillPoly(img, list(np.round(uv[F[front_facing(cam, V, F)]] * 256).astype(np.int32)),
                     1, cv2.LINE_8, 8)
        return img

    # how far the OpenCV alternatives are from the exact pixel-centre silhouette
    errors = {}
    for name, fn in (("cv2.fillConvexPoly loop", fill_loop), ("cv2.fillPoly one call", fill_poly)):
        ref = silhouette(cams[0], verts[0], F)
        got = fn(cams[0], verts[0]).astype(bool)
        errors[name] = int((ref != got).sum()), int(ref.sum())

    light = scene.lights[0]
    rng = np.random.default_rng(0)
    rows = {
        "silhouette (closed-mesh culling)": timed(lambda c, V: silhouette(c, V, F)),
        "silhouette (all faces)": timed(lambda c, V: silhouette(c, V, F, closed=False)),
        "shadow mask (point light)": timed(lambda c, V: shadow_mask(c, V, F, light)),
        "z-buffer raster (face ids, depth)": timed(lambda c, V: rasterize(c, V, F)),
        "alt: cv2.fillConvexPoly loop": timed(fill_loop),
        "alt: cv2.fillPoly one call": timed(fill_poly),
        "full colour frame + truth masks + sensor": timed(
            lambda c, V: apply_sensor(scene.render(0, c, V).radiance, spec["sensor"], rng)),
    }
    results = {
        "anchor": f"thesis capture rate {ANCHOR_HZ:.0f} Hz per camera",
        "image_size": list(cams[0].size), "cameras": len(cams), "faces": int(len(F)),
        "frames_timed": len(verts), "rows": {},
    }
    table = Table(title=f"studio.render at {len(cams)}×{cams[0].size[0]}×{cams[0].size[1]}, "
                  f"{len(F)} faces (anchor {ANCHOR_HZ:.0f} Hz per camera)")
    for col in ("path", "median ms / camera image", "images / s", "multi-frames / s", "vs 60 Hz"):
        table.add_column(col)
    for name, sec in rows.items():
        fps = 1.0 / sec
        results["rows"][name] = {"ms_per_image": sec * 1e3, "images_per_s": fps,
                                 "multiframes_per_s": fps / len(cams),
                                 "faster_than_anchor": fps > ANCHOR_HZ}
        table.add_row(name, f"{sec * 1e3:.1f}", f"{fps:.1f}", f"{fps / len(cams):.1f}",
                      f"{fps / ANCHOR_HZ:.2f}×")
    Console().print(table)
    for name, (wrong, total) in errors.items():
        print(f"{name}: {wrong} of {total} silhouette pixels differ from the exact sampler")
    results["alternatives_pixel_errors"] = {k: {"wrong": w, "silhouette": t} for k, (w, t) in errors.items()}
    out = ROOT / "benchmarks" / "results" / "simulate.json"
    atomic_write_text(out, json.dumps(results, indent=2), mkdir=True)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
