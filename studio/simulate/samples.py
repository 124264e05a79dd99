"""Where the shipped sample sequences live and where their renders are cached.

The specs and true bodies are package data (``studio/samples/<name>/``), found through the
installed package, so ``studio demo`` works from any folder after ``pip install``. Renders are
never written beside them (site-packages may be read-only and is shared): they go to a user
cache, ``$STUDIO_CACHE`` or ``$XDG_CACHE_HOME/studio`` (default ``~/.cache/studio``).
"""

from __future__ import annotations

import os
from importlib.resources import files
from pathlib import Path

__all__ = ["SAMPLES", "cache_root"]

#: The folder of the shipped sample sequences (``walk``, ``clothing_poses``, ``mono_shadow``).
SAMPLES = Path(str(files("studio").joinpath("samples")))


def cache_root() -> Path:
    """``$STUDIO_CACHE``, else ``$XDG_CACHE_HOME/studio``, else ``~/.cache/studio``."""
    env = os.environ.get("STUDIO_CACHE")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "studio"
