"""The simulated studio: scene specs, rendering of capture sessions with ground truth.

Runtime code is numpy/OpenCV only; the true bodies are built once from Anny by
:mod:`studio.simulate.truth_build` (``studio simulate build-truth``, needs the
``model-build`` extra) and stored compactly next to each ``spec.yaml``.
"""

from studio.simulate.scene import Body, FrameRender, Scene, load_body, ring_cameras, skin_tone_rgb
from studio.simulate.sensor import apply_sensor, bayer_mosaic, demosaic
from studio.simulate.samples import SAMPLES, cache_root
from studio.simulate.session import default_cache_dir, ensure_rendered, simulate
from studio.simulate.spec import SimSpec, SpecError, load_spec

__all__ = [
    "Body",
    "FrameRender",
    "Scene",
    "SimSpec",
    "SpecError",
    "apply_sensor",
    "bayer_mosaic",
    "SAMPLES",
    "cache_root",
    "default_cache_dir",
    "demosaic",
    "ensure_rendered",
    "load_body",
    "load_spec",
    "ring_cameras",
    "simulate",
    "skin_tone_rgb",
]
