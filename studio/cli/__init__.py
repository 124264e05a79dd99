"""The ``studio`` command.

Every sub-command lives in its own module under :mod:`studio.cli.commands` and exposes
``register(subparsers)``, which adds its parser and sets ``func`` (called with the parsed
arguments; its return value is the exit code, ``None`` meaning 0). Modules are discovered,
so adding a command is adding a file.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import sys

from studio import __version__
from studio.cli import commands

__all__ = ["main", "build_parser", "CommandError", "name_path_pairs", "open_workspace"]


class CommandError(RuntimeError):
    """A user-facing failure: printed as one line, exit code ``code``."""

    def __init__(self, message: str, code: int = 1):
        super().__init__(message)
        self.code = code


def name_path_pairs(specs, what: str) -> dict:
    """``NAME=PATH`` command-line items → ``{camera name: Path}`` in the given order; an item
    without both parts or a camera named twice is a :class:`CommandError` (``what`` says which
    items were expected)."""
    from pathlib import Path

    out = {}
    for spec in specs:
        name, sep, path = spec.partition("=")
        if not sep or not name or not path:
            raise CommandError(f"{spec}: expected NAME=FILE {what}")
        if name in out:
            raise CommandError(f"{spec}: camera {name!r} is given twice")
        out[name] = Path(path)
    return out


def open_workspace(path, *, out=None):
    """Open a session for a command (:class:`studio.workspace.Workspace`); its problems exit as one line."""
    from studio.workspace import Workspace, WorkspaceError

    try:
        return Workspace.open(path, out=out)
    except WorkspaceError as exc:
        raise CommandError(str(exc)) from None


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="studio",
        description="Silhouette & Shadow Studio: capture, calibrate, segment, fit and measure "
        "people from a synchronized multi-camera rig.",
    )
    parser.add_argument("--version", action="version", version=f"studio {__version__}")
    parser.add_argument("--debug", action="store_true", help="show full tracebacks on errors")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", title="commands")
    for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{commands.__name__}.{info.name}")
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.WARNING - 10 * min(args.verbose, 2),
        format="%(levelname)s %(name)s: %(message)s",
    )
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    from studio.workers import terminate_on_sigterm

    try:
        with terminate_on_sigterm():
            code = args.func(args)
    except KeyboardInterrupt:
        print("studio: interrupted", file=sys.stderr)
        return 130
    except CommandError as exc:
        if args.debug:
            raise
        print(f"studio: error: {exc}", file=sys.stderr)
        return exc.code
    except Exception as exc:  # one clear line for any failure; --debug shows the traceback
        if args.debug:
            raise
        message = str(exc) or type(exc).__name__
        print(f"studio: error: {message}", file=sys.stderr)
        return 1
    return 0 if code is None else int(code)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
