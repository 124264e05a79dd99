"""Acquisition: cameras, synchronized multi-frames and capture sessions on disk.

- :class:`Rig` — ``Rig.open("rigs/simulated.yaml", source=DIR)`` opens the cameras of a rig
  description (:class:`RigDescription`); ``rig.multiframes(n)`` yields synchronized
  :class:`MultiFrame` s.
- :class:`CameraDevice` — the camera interface (GenICam feature names, leased frames);
  backends ``simulated`` and ``replay`` (:mod:`rigs.backends`).
- :class:`SyncGroup` — per-camera streams → multi-frames of one trigger instant, with
  dropped / late / duplicate counts (:class:`SyncStats`).
- :class:`Recorder` — multi-frames → capture session through a bounded queue and a writer
  thread (:class:`RecorderStats`).
- :class:`Session` / :class:`SessionWriter` — the capture-session folder format.
"""

from rigs.backends import available_backends, register_backend
from rigs.description import CameraConfig, RigDescription, SyncConfig, TriggerConfig
from rigs.device import (
    FEATURES,
    PIXEL_FORMATS,
    CameraDevice,
    CameraStats,
    EndOfStream,
    Frame,
    FrameQueue,
    FrameTimeout,
    RigError,
)
from rigs.imageio import (
    ImageIOError,
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_text,
    read_image,
    write_image,
)
from rigs.recorder import Recorder, RecorderStats
from rigs.rig import Rig, RigStats
from rigs.session import Session, SessionError, SessionWriter, ValidationReport
from rigs.sync import MultiFrame, SyncGroup, SyncStats

__all__ = [
    "FEATURES",
    "PIXEL_FORMATS",
    "CameraConfig",
    "CameraDevice",
    "CameraStats",
    "EndOfStream",
    "Frame",
    "FrameQueue",
    "FrameTimeout",
    "ImageIOError",
    "MultiFrame",
    "Recorder",
    "RecorderStats",
    "Rig",
    "RigDescription",
    "RigError",
    "RigStats",
    "Session",
    "SessionError",
    "SessionWriter",
    "SyncConfig",
    "SyncGroup",
    "SyncStats",
    "TriggerConfig",
    "ValidationReport",
    "atomic_write_bytes",
    "atomic_write_json",
    "atomic_write_text",
    "available_backends",
    "default_rig_path",
    "read_image",
    "register_backend",
    "write_image",
]


def default_rig_path():
    """Path of the shipped default rig description ``rigs/simulated.yaml``."""
    from importlib import resources

    return resources.files("rigs").joinpath("simulated.yaml")
