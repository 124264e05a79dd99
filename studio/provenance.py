"""Digests of the code a cached result was computed by, so that a cache is never reused across a
code change it depends on (a stored fit, a render's same-definition truth).

>>> code_digest("studio.provenance") == code_digest("studio.provenance")
True
"""

from __future__ import annotations

import functools
import hashlib
import importlib
from pathlib import Path

__all__ = ["code_digest"]


@functools.lru_cache(maxsize=16)
def code_digest(*modules: str, files: tuple[str | Path, ...] = (), exclude: tuple[str, ...] = ()) -> str:
    """16-hex digest of the source of ``modules`` (a package: every ``.py`` file under it, in path
    order) and of ``files`` (a missing file counts as empty), leaving out the modules named in
    ``exclude`` (dotted names, e.g. ``"studio.fit.batch"``). Cached per process."""
    h = hashlib.sha256()
    for name in modules:
        mod = importlib.import_module(name)
        path = Path(mod.__file__)
        sources = sorted(path.parent.rglob("*.py")) if path.name == "__init__.py" else [path]
        for src in sources:
            dotted = ".".join((name, *src.relative_to(path.parent).with_suffix("").parts))
            if path.name == "__init__.py" and dotted in exclude:
                continue
            h.update(str(src.relative_to(path.parent)).encode())
            h.update(src.read_bytes())
    for f in files:
        f = Path(f)
        h.update(f.read_bytes() if f.is_file() else b"")
    return h.hexdigest()[:16]
