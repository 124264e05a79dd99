"""Errors raised by the fitting code."""

from __future__ import annotations

__all__ = ["FitError"]


class FitError(ValueError):
    """A session or an input cannot be fitted; the message names what is missing."""
