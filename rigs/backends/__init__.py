"""Camera backends, looked up by the ``backend`` name of a rig description.

A backend is a factory ``open_camera(config, description, *, epoch_ns, shared) -> CameraDevice``
(``config`` a :class:`rigs.description.CameraConfig`; ``epoch_ns`` the rig's common clock
origin; ``shared`` a dict the cameras of one :meth:`rigs.Rig.open` call share, e.g. to open a
GenTL producer or a session folder once). Built-in: ``simulated`` and ``replay``. The GenICam
backends (``genicam`` through harvesters and any GenTL producer, ``aravis`` through PyGObject)
plug in here with :func:`register_backend` — or by adding their ``"module:function"`` entry.

How a GenICam backend maps onto :class:`~rigs.CameraDevice` (harvesters 1.4 names):
``device: {serial: ...}`` → ``Harvester.create({"serial_number": ...})`` (one ``Harvester``
per rig, kept in ``shared``); ``_apply`` writes the SFNC features (``Width``, ``Height``,
``PixelFormat``, ``ExposureTime``, ``Gain``, ``AcquisitionFrameRate``, ``TriggerSelector`` /
``TriggerMode`` / ``TriggerSource``, ``GevIEEE1588``) to ``remote_device.node_map``;
``_start``/``_stop`` → ``start()``/``stop()`` acquisition; ``_next(timeout)`` → ``fetch(timeout=...)``
with ``timestamp_ns`` from the buffer (PTP time when ``GevIEEE1588`` is on) and ``frame_id``
from the GenTL block id; ``_release`` → ``buffer.queue()``; ``buffers_reused = True`` so the
rig copies images it keeps; ``_close`` → ``destroy()``. No signal handlers are installed.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from rigs.device import CameraDevice, RigError

__all__ = ["available_backends", "create_camera", "register_backend"]

_BACKENDS: dict[str, str | Callable[..., CameraDevice]] = {
    "simulated": "rigs.backends.simulated:open_camera",
    "replay": "rigs.backends.replay:open_camera",
}

_PLANNED = {
    "genicam": "GenICam cameras through harvesters and a GenTL producer",
    "aravis": "GenICam cameras through Aravis (PyGObject)",
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
        if name in _PLANNED:
            raise RigError(f"camera backend {name!r} ({_PLANNED[name]}) is not implemented yet; "
                           f"available: {available_backends()}")  # fmt: skip
        raise RigError(f"unknown camera backend {name!r}; available: {available_backends()}")
    if isinstance(entry, str):
        module, _, attr = entry.partition(":")
        entry = getattr(importlib.import_module(module), attr)
        _BACKENDS[name] = entry
    return entry


def create_camera(config, description, *, epoch_ns: int, shared: dict | None = None) -> CameraDevice:
    """Open the camera ``config`` describes with its backend."""
    return _factory(config.backend)(config, description, epoch_ns=epoch_ns, shared=shared)
