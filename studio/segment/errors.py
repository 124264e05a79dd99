"""Errors raised by :mod:`studio.segment`."""

from __future__ import annotations

__all__ = ["SegmentationError"]


class SegmentationError(ValueError):
    """Bad input to segmentation: names the file / camera / field and what was expected."""
