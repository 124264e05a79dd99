"""Measurement accuracy and honest uncertainty on simulated people (ISO 7250-1 definitions).

People: the walk sample (an Anny woman: the model never saw her, so model mismatch counts)
at a few frames, and people drawn from the model's own shape prior (both sexes, rendered as
exact silhouettes by a 4-camera ring like the walk's: the fitter's error alone). Every fit is
cached (``<cache>/bench/measurements``), a rerun fits only what is missing.

Per measurement (:data:`studio.body.iso7250.DEFINITIONS`): mean error (fit − truth, the
truth being the true body measured by the SAME definitions), its spread, the share of people
whose truth falls in the report's 95 % interval (:mod:`studio.report.uncertainty`), and
whether the mean |error| meets the ISO 20685-1:2018 maximum allowable error. Anchors:
SMPL-Anthropometry's published ~3.5 cm mean error over its measurements, and the thesis'
7 mm stature error (§4.8.6).

Usage::

    .venv/bin/python benchmarks/measurements.py fit [--people 4] [--workers 2]
    .venv/bin/python benchmarks/measurements.py table
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

WALK_FRAMES = (0, 8, 16)
FIRST_SEED = 7000  # model-prior people: these seeds are only ever measured
ANCHORS = {"smpl_anthropometry_mean_error_mm": 35.0, "thesis_stature_error_mm": 7.0}


def bench_root() -> Path:
    from studio.simulate.samples import cache_root

    return cache_root() / "bench" / "measurements"


def _prior_person(root: Path, index: int) -> dict:
    """A session of one model-prior person: 2 frames (standing, mid-stride), exact silhouettes
    as segmentation, the walk's 4-camera ring (656×490, f = 560 px)."""
    from calibration import RigCalibration
    from calibration.synthetic import camera_ring
    from rigs.imageio import write_image
    from rigs.session import SessionWriter
    from studio.body import BodyModel
    from studio.fit.init import stride_poses
    from studio.render import silhouette

    rng = np.random.default_rng(FIRST_SEED + index)
    sex = ("female", "male")[index % 2]
    model = BodyModel.load(sex)
    shape = model.sample_shapes(1, rng)[0]
    path = root / f"prior_{index:02d}"
    info = {"name": path.name, "sex": sex, "shape": shape.tolist(), "frames": [0, 1], "kind": "model prior"}
    if (path / "person.json").is_file():
        return json.loads((path / "person.json").read_text())
    cams = list(camera_ring(4, radius=3.6, height=2.3, target=(0.0, 0.0, 0.9), size=(656, 490), focal=560.0,
                            dist=(0, 0, 0, 0, 0), start=np.pi / 4, principal_offset=(0.0, 0.0)).values())
    calib = root / f"{path.name}-calibration.json"
    RigCalibration(cameras={c.name: c for c in cams}).save(calib)
    writer = SessionWriter.create(path, [c.name for c in cams], rig="bench", calibration=calib)
    poses = [model.default_pose(), stride_poses(model)[1]]
    for i, pose in enumerate(poses):
        pose = pose.copy()
        pose[:2] = rng.uniform(-0.2, 0.2, 2)
        pose[5] = rng.uniform(-np.pi, np.pi)
        V = model.vertices(shape, pose)
        masks = [silhouette(c, V, model.faces) for c in cams]
        writer.write_frame(i, {c.name: np.where(m[..., None], 180, 60).astype(np.uint8).repeat(3, 2)
                               for c, m in zip(cams, masks, strict=True)})
        for c, m in zip(cams, masks, strict=True):
            p = path / "segmentation" / c.name / f"{i:06d}.png"
            p.parent.mkdir(parents=True, exist_ok=True)
            write_image(p, m.astype(np.uint8))
    writer.close()
    from rigs.atomic import atomic_write_json

    atomic_write_json(path / "person.json", info)
    return info


def cmd_fit(args) -> int:
    from studio.fit import FitOptions, fit_session
    from studio.segment import segment_session
    from studio.simulate import ensure_rendered
    from studio.workspace import Workspace

    root = bench_root()
    root.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    walk = ensure_rendered(ROOT / "studio" / "samples" / "walk" / "spec.yaml", seed=0)
    ws = Workspace.open(walk, out=root / "walk")
    segment_session(ws, frames=list(WALK_FRAMES), workers=args.workers)
    fit_session(ws, frames=list(WALK_FRAMES), gender="female", workers=args.workers, options=FitOptions())
    print(f"walk fitted ({time.perf_counter() - t0:.0f} s)", flush=True)
    for i in range(args.people):
        p = _prior_person(root, i)
        fit_session(root / p["name"], frames=p["frames"], gender=p["sex"], workers=args.workers,
                    options=FitOptions())
        print(f"{p['name']} ({p['sex']}) fitted ({time.perf_counter() - t0:.0f} s)", flush=True)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fit", help="fit (or reuse) the benchmark people")
    f.add_argument("--people", type=int, default=4)
    f.add_argument("--workers", type=int, default=2)
    t = sub.add_parser("table", help="measure the cached fits against the truth")
    t.add_argument("--people", type=int, default=4)
    args = ap.parse_args(argv)
    return cmd_fit(args) if args.cmd == "fit" else cmd_table(args)


if __name__ == "__main__":
    raise SystemExit(main())
