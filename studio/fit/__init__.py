"""Fitting the body model to multi-view silhouettes (thesis ch. 4).

- :func:`fit_frame` / :func:`fit_frame_gender`: one frame (particle filter, then staged
  Nelder–Mead, coarse-to-fine pyramid levels), gender given or chosen by the lower cost;
- :func:`fit_session`: a sequence, frames as units on local processes or a Dask cluster
  (:mod:`studio.fit.units`, :mod:`studio.execution`), chains of tracked frames;
- :mod:`studio.fit.quality`: the quality gates every fitted frame carries (status ok /
  suspect / failed with reasons);
- :mod:`studio.fit.evaluate`: accuracy against a simulated session's truth;
- :mod:`studio.fit.batch` / :mod:`studio.fit.batch_session`: the clothing-robust multi-pose batch
  (one shape, one pose per frame, gender by batch; thesis ch. 6) and ``studio fit --batch``.
"""

from studio.fit.batch import BatchFrame, BatchOptions, BatchResult, batch_fit
from studio.fit.batch_session import fit_batch_session, load_batch
from studio.fit.errors import FitError, UnusableFrame
from studio.fit.frame import FitOptions, fit_frame, fit_frame_gender
from studio.fit.init import hull_centroid, initial_poses
from studio.fit.objective import FrameObjective, pose_bounds
from studio.fit.output import OVERLAY_COLORS, overlay_image, write_frame_fit
from studio.fit.quality import fit_quality, screen_masks
from studio.fit.result import FrameFit
from studio.fit.session import fit_session, load_fits, load_quality, open_workspace

__all__ = [
    "BatchFrame",
    "BatchOptions",
    "BatchResult",
    "batch_fit",
    "fit_batch_session",
    "load_batch",
    "FitError",
    "FitOptions",
    "FrameFit",
    "FrameObjective",
    "UnusableFrame",
    "OVERLAY_COLORS",
    "fit_frame",
    "fit_frame_gender",
    "fit_quality",
    "fit_session",
    "hull_centroid",
    "initial_poses",
    "load_fits",
    "load_quality",
    "open_workspace",
    "overlay_image",
    "pose_bounds",
    "screen_masks",
    "write_frame_fit",
]
