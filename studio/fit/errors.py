"""Errors raised by the fitting code."""

from __future__ import annotations

__all__ = ["FitError", "UnusableFrame"]


class FitError(ValueError):
    """A session or an input cannot be fitted; the message names what is missing."""


class UnusableFrame(FitError):
    """A frame's silhouettes fail the segmentation checks (:func:`studio.fit.quality.screen_masks`):
    no body is fitted. ``frame`` and ``quality`` (the ``quality`` object, status ``failed``)."""

    def __init__(self, frame: int, quality: dict):
        self.frame = int(frame)
        self.quality = quality
        ordered = sorted(quality["reasons"], key=lambda r: r["severity"] != "failed")
        reasons = "; ".join((f"{r['view']}: " if r.get("view") else "") + r["message"] for r in ordered)
        super().__init__(f"frame {frame}: not fitted — {reasons}")
