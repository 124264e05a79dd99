"""Camera backends, looked up by the ``backend`` name of a rig description.

A backend is a factory ``open_camera(config, description, *, epoch_ns, shared) -> CameraDevice``
(``config`` a :class:`rigs.description.CameraConfig`; ``epoch_ns`` the rig's common clock
origin; ``shared`` a dict the cameras of one :meth:`rigs.Rig.open` call share, e.g. to open a
GenTL producer or a session folder once). Built-in: ``simulated`` and ``replay`` (playback
of stored frames), ``genicam`` (harvesters and any GenTL producer, :mod:`rigs.backends.genicam`)
and ``aravis`` (Aravis 0.8 through PyGObject, :mod:`rigs.backends.aravis`); both GenICam
backends share :mod:`rigs.backends._genapi` (GenApi node writes with checked values,
buffers, timestamps, frame ids, software-trigger fan-out). Others plug in with
:func:`register_backend` or a ``"module:function"`` entry. No backend installs signal handlers.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from rigs.device import CameraDevice, RigError

__all__ = ["available_backends", "create_camera", "register_backend"]

_BACKENDS: dict[str, str | Callable[..., CameraDevice]] = {
    "simulated": "rigs.backends.simulated:open_camera",
    "replay": "rigs.backends.replay:open_camera",
    "genicam": "rigs.backends.genicam:open_camera",
    "aravis": "rigs.backends.aravis:open_camera",
}


def register_backend(name: str, factory: str | Callable[..., CameraDevice]) -> None:
    """Make ``backend: name`` available; ``factory`` is a callable or ``"module:function"``."""
    if not isinstance(name, str) or not name:
        raise ValueError(f"backend name must be a non-empty string, got {name!r}")
    _BACKENDS[name] = factory


def available_backends() -> list[str]:
    return sorted(_BACKENDS)


def _factory(name: str) -> Callable[..., CameraDevice]:
    entry = _BACKENDS.get(name)
    if entry is None:
        raise RigError(f"unknown camera backend {name!r}; available: {available_backends()}")
    if isinstance(entry, str):
        module, _, attr = entry.partition(":")
        entry = getattr(importlib.import_module(module), attr)
        _BACKENDS[name] = entry
    return entry


def create_camera(config, description, *, epoch_ns: int, shared: dict | None = None) -> CameraDevice:
    """Open the camera ``config`` describes with its backend."""
    return _factory(config.backend)(config, description, epoch_ns=epoch_ns, shared=shared)
