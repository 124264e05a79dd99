"""Digests of the code a cached result was computed by, so that a cache is never reused across a
code change it depends on (a stored fit, a render's same-definition truth).

A module counts by its syntax tree without docstrings (:func:`source_key`): an edit to a comment, a
docstring or the layout leaves the digest alone, so hours of benchmark results (``benchmarks/ledger``)
survive it; any change to what the code does, a message string included, does not. The tree's text
is Python's ``ast.dump``, which may change between Python versions (the toolkit runs on 3.11).

>>> code_digest("studio.provenance") == code_digest("studio.provenance")
True
"""

from __future__ import annotations

import ast
import functools
import hashlib
import importlib
from pathlib import Path

__all__ = ["code_digest", "source_key"]


def source_key(source: bytes) -> bytes:
    """What of a module's ``source`` a digest counts: its syntax tree with every module, class and
    function docstring left out (comments and layout are not in the tree), or the bytes themselves
    when they do not parse."""
    try:
        tree = ast.parse(source)
    except (SyntaxError, ValueError):
        return source
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and body
                and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return ast.dump(tree, include_attributes=False).encode()


@functools.lru_cache(maxsize=16)
def code_digest(*modules: str, files: tuple[str | Path, ...] = (), exclude: tuple[str, ...] = ()) -> str:
    """16-hex digest of the source (:func:`source_key`) of ``modules`` (a package: every ``.py``
    file under it, in path order) and of ``files`` (a missing file counts as empty), leaving out the
    modules named in ``exclude`` (dotted names, e.g. ``"studio.fit.batch"``). Cached per process."""
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
            h.update(source_key(src.read_bytes()))
    for f in files:
        f = Path(f)
        h.update(f.read_bytes() if f.is_file() else b"")
    return h.hexdigest()[:16]
