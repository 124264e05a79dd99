"""What the two GenICam backends (``genicam``, ``aravis``) share: a camera driven through
GenApi node names over a small driver :class:`Transport`.

A transport (harvesters' ``ImageAcquirer``, Aravis' ``Arv.Camera``, or a test's GenTL-level
fake) reads and writes nodes and hands out raw buffers; :class:`GenICamCamera` does the rest,
the same for every driver:

- **features → nodes.** ``Width``/``Height``/``Offset*``, ``PixelFormat``, ``ExposureTime``
  (or ``ExposureTimeAbs``), ``Gain``, ``AcquisitionFrameRate`` (free-run only, with
  ``AcquisitionFrameRateEnable``), ``TriggerSelector``/``TriggerMode``/``TriggerSource``/
  ``TriggerActivation``, ``GevIEEE1588`` (or ``PtpEnable``), then the rig YAML's ``nodes:``
  mapping in order (``LineSelector``, ``LineMode``, ...). Every value is checked against the
  node before it is written — enumeration entries, integer/float bounds — so a refused setting
  names the camera, the node, the value and what the node allows.
- **PTP.** With ``sync: {ptp: true}`` the camera's IEEE 1588 client is enabled and the camera
  waits (``ptp_timeout``, default 10 s) until ``GevIEEE1588Status``/``PtpStatus`` is
  ``Master`` or ``Slave``.
- **frames.** A buffer becomes an RGB/mono image (:func:`rigs.pixelformats.to_image`;
  ``debayer: false`` keeps Bayer mosaics raw) and goes straight back to the driver, so a frame
  owns its memory. ``timestamp_ns`` is the device clock (``ChunkTimestamp`` when ``chunks:
  true`` and the device sends it), else the host clock, noted in :meth:`device_stats`;
  ``frame_id`` is the device's block id (``ChunkFrameID`` with chunks), unwrapped across the
  16-bit GigE Vision wrap and counted from the run's first frame, so cameras armed before the
  first trigger agree.
- **triggers.** ``TriggerSource=Software``: the rig's :class:`~rigs.backends._trigger.SoftwareTrigger`
  fires ``TriggerSoftware`` on all cameras together. ``trigger: {mode: action}``: every camera
  gets ``ActionDeviceKey``, ``ActionSelector=1``, ``ActionGroupKey``, ``ActionGroupMask`` and
  ``TriggerSource=Action1``; the same timer has the rig's first camera's transport issue one
  action command per tick (a GigE Vision broadcast from its GenTL interface), which every
  camera whose keys match answers with an exposure.

Options (rig YAML camera keys): ``buffers`` (driver buffers, default 8), ``timeout``
(default fetch timeout in s, default 1), ``debayer`` (default true), ``chunks`` (default
false), ``ptp_timeout``, ``trigger_activation`` (``RisingEdge``...), ``nodes`` (mapping).
"""

from __future__ import annotations

import abc
import atexit
import logging
import time
import weakref
from dataclasses import dataclass
from typing import Any

from rigs.backends._trigger import SoftwareTrigger, shared_trigger
from rigs.device import FEATURES, CameraDevice, Frame, FrameTimeout, RigError
from rigs.pixelformats import SENSOR_FORMATS, bayer_pattern, to_image

__all__ = ["GENICAM_FEATURES", "GenICamCamera", "RawBuffer", "Transport", "camera_arguments", "common_options",
           "unwrap_frame_id"]

log = logging.getLogger(__name__)

#: the feature rules of a GenICam camera: any PFNC format :mod:`rigs.pixelformats` reads
GENICAM_FEATURES = {**FEATURES, "PixelFormat": (str, tuple(SENSOR_FORMATS))}

#: feature -> GenApi node names tried in order (SFNC name first, then older names)
NODE_NAMES = {
    "ExposureTime": ("ExposureTime", "ExposureTimeAbs"),
    "Gain": ("Gain", "GainAbs"),
    "AcquisitionFrameRate": ("AcquisitionFrameRate", "AcquisitionFrameRateAbs"),
    "GevIEEE1588": ("GevIEEE1588", "PtpEnable"),
}
#: features written in this order (trigger selector before the mode it selects, size before offset)
ORDER = ("TriggerSelector", "TriggerMode", "TriggerSource", "PixelFormat", "Width", "Height",
         "OffsetX", "OffsetY", "ExposureTime", "Gain", "AcquisitionFrameRate", "GevIEEE1588")  # fmt: skip
#: values a device without the node already has (skipped, not refused)
IMPLIED = {"GevIEEE1588": False, "TriggerMode": "Off", "TriggerSelector": "FrameStart", "Gain": 0.0,
           "OffsetX": 0, "OffsetY": 0}  # fmt: skip
PTP_STATUS = ("GevIEEE1588Status", "PtpStatus")
COMMON_OPTIONS = {"buffers", "timeout", "debayer", "chunks", "ptp_timeout", "trigger_activation", "nodes"}


@dataclass
class RawBuffer:
    """One filled driver buffer: bytes (or a uint8 array), geometry, PFNC format, the
    device's ``timestamp_ns`` (0 when the device sends none) and block ``frame_id``;
    ``complete`` is False for a buffer the driver flagged (missing packets, ...);
    ``chunks`` holds chunk values the driver parsed (``ChunkTimestamp``, ``ChunkFrameID``)."""

    data: Any
    width: int
    height: int
    pixel_format: str
    timestamp_ns: int
    frame_id: int
    complete: bool = True
    chunks: dict | None = None
    token: Any = None


class Transport(abc.ABC):
    """A driver binding. Node kinds are ``"int"``, ``"float"``, ``"enum"``, ``"bool"``,
    ``"command"``, ``"string"`` (None: no such node). Driver errors may be raised as anything;
    :class:`GenICamCamera` wraps them into :class:`RigError` naming the node."""

    @abc.abstractmethod
    def kind(self, node: str) -> str | None: ...
    @abc.abstractmethod
    def read(self, node: str) -> Any: ...
    @abc.abstractmethod
    def write(self, node: str, value: Any) -> None: ...
    @abc.abstractmethod
    def entries(self, node: str) -> list[str]:
        """Available entries of an enumeration node."""
    @abc.abstractmethod
    def bounds(self, node: str) -> tuple[float, float]:
        """(min, max) of an integer or float node."""
    @abc.abstractmethod
    def execute(self, node: str) -> None: ...
    @abc.abstractmethod
    def start(self, buffers: int) -> None:
        """Allocate ``buffers`` driver buffers and start acquisition."""
    @abc.abstractmethod
    def stop(self) -> None:
        """Stop acquisition and release the buffers (idempotent)."""
    @abc.abstractmethod
    def pop(self, timeout: float) -> RawBuffer | None:
        """The next filled buffer, or None after ``timeout`` s (0 polls)."""
    @abc.abstractmethod
    def requeue(self, buffer: RawBuffer) -> None: ...
    def statistics(self) -> dict[str, int]:
        return {}
    def action_issuer(self) -> str | None:
        """None when :meth:`issue_action` works, else why not (one line)."""
        return f"{type(self).__name__} cannot issue action commands"
    def issue_action(self, device_key: int, group_key: int, group_mask: int) -> None:
        raise RigError(self.action_issuer() or "action commands are not supported")
    @abc.abstractmethod
    def close(self) -> None:
        """Release the device (idempotent)."""


#: transports not closed yet; closed at interpreter exit (an interrupted script leaks no device)
_OPEN: weakref.WeakSet = weakref.WeakSet()


#: backends that play stored frames and take no triggers from the rig's timer
PLAYBACK_BACKENDS = ("simulated", "replay")


def camera_arguments(config, description, shared: dict | None) -> tuple[dict[str, Any], dict[str, Any]]:
    """The features of a rig camera and the synchronisation arguments of :class:`GenICamCamera`:
    the rig's software-trigger timer (waiting for every live camera of the rig), the action
    keys, and whether this camera issues the action commands (the rig's first live camera)."""
    features = config.features(description.frame_rate, description.trigger, description.sync.ptp)
    live = [n for n, c in description.cameras.items() if c.backend not in PLAYBACK_BACKENDS]
    trigger = description.trigger
    return features, {
        "trigger": shared_trigger(shared, description.frame_rate, len(live)),
        "action": trigger.action if trigger.mode == "action" else None,
        "issuer": config.name == live[0],
    }


def _nothing() -> None:
    """The timer callback of a camera that an action command issued by another one triggers."""


def close_leftovers() -> int:
    """Stop and close every transport still open (``atexit``); returns how many."""
    n = 0
    for transport in list(_OPEN):
        try:
            transport.stop()
            transport.close()
            n += 1
        except Exception as exc:  # keep closing the rest
            log.error("closing a leftover camera failed: %s", exc)
    return n


atexit.register(close_leftovers)


def unwrap_frame_id(raw: int, last_raw: int | None, last: int | None) -> int:
    """Continue a frame counter across the GigE Vision 16-bit wrap (ids 1..65535, 0 skipped).

    >>> unwrap_frame_id(1, 65535, 100)
    101
    >>> unwrap_frame_id(7, 5, 100)
    102
    """
    if last_raw is None or last is None:
        return int(raw)
    step = int(raw) - int(last_raw)
    if step < 0 and last_raw <= 0xFFFF and last_raw - raw > 0x8000:
        step = (int(raw) - int(last_raw)) % 0xFFFF
    return int(last) + step


def common_options(camera: str, backend: str, options: dict, known: set[str]) -> dict:
    """Validated shared options (module docstring) with defaults."""
    unknown = sorted(set(options) - known - COMMON_OPTIONS)
    if unknown:
        raise RigError(f"camera {camera!r}: unknown {backend} option {unknown[0]!r}; expected any of "
                       f"{sorted(known | COMMON_OPTIONS)}")  # fmt: skip
    out = {"buffers": options.get("buffers", 8), "timeout": options.get("timeout", 1.0),
           "debayer": options.get("debayer", True), "chunks": options.get("chunks", False),
           "ptp_timeout": options.get("ptp_timeout", 10.0), "nodes": options.get("nodes") or {},
           "trigger_activation": options.get("trigger_activation")}  # fmt: skip
    b = out["buffers"]
    if isinstance(b, bool) or not isinstance(b, int) or not 1 <= b <= 4096:
        raise RigError(f"camera {camera!r}: option buffers must be an integer in 1..4096, got {b!r}")
    for key in ("timeout", "ptp_timeout"):
        v = out[key]
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
            raise RigError(f"camera {camera!r}: option {key} must be a positive number of seconds, got {v!r}")
    for key in ("debayer", "chunks"):
        if not isinstance(out[key], bool):
            raise RigError(f"camera {camera!r}: option {key} must be true or false, got {out[key]!r}")
    if not isinstance(out["nodes"], dict):
        raise RigError(f"camera {camera!r}: option nodes must be a mapping of GenApi node -> value, "
                       f"got {out['nodes']!r}")  # fmt: skip
    return out


class GenICamCamera(CameraDevice):
    """A GenICam camera over a :class:`Transport`; see the module docstring."""

    backend = "genicam"
    feature_rules = GENICAM_FEATURES

    def __init__(self, name: str, features: dict[str, Any], transport: Transport, options: dict, *,
                 trigger: SoftwareTrigger | None = None, info: dict | None = None,
                 action: dict[str, int] | None = None, issuer: bool = False):  # fmt: skip
        self.transport = transport
        self.action = action
        self.issuer = bool(issuer)
        _OPEN.add(transport)
        self.options = options
        self.info = dict(info or {})
        self._trigger = trigger
        self._written: dict[str, Any] = {}
        self._requested = set(features)
        self._counters = {"incomplete_buffers": 0, "host_timestamps": 0, "chunk_timestamps": 0, "triggers": 0}
        self._ids: tuple[int | None, int | None] = (None, None)
        self._first_id: int | None = None
        try:
            super().__init__(name, features)
            self._apply(self._features)
            for node, value in options["nodes"].items():
                self.set_node(str(node), value)
            if options["trigger_activation"] is not None and self._features["TriggerMode"] == "On":
                self.set_node("TriggerActivation", options["trigger_activation"])
            if options["chunks"]:
                self._enable_chunks()
            if action is not None:
                self._arm_action_keys()
        except BaseException:
            self._close()
            raise

    # -- nodes -------------------------------------------------------------------------
    def node(self, name: str) -> Any:
        """Current value of any GenApi node."""
        self._check_open()
        if self.transport.kind(name) is None:
            raise RigError(f"camera {self.name!r}: the device has no GenApi node {name!r}")
        try:
            return self.transport.read(name)
        except Exception as exc:
            raise RigError(f"camera {self.name!r}: reading node {name} failed: {exc}") from exc

    def allowed(self, name: str) -> str:
        """What node ``name`` accepts, in words (its entries or its range)."""
        kind = self.transport.kind(name)
        if kind == "enum":
            return "one of " + ", ".join(self.transport.entries(name))
        if kind in ("int", "float"):
            lo, hi = self.transport.bounds(name)
            return f"{kind} in [{lo:g}, {hi:g}]"
        return {"bool": "true or false", "command": "a command (value true executes it)"}.get(kind, str(kind))

    def set_node(self, name: str, value: Any) -> None:
        """Write GenApi node ``name`` after checking ``value`` against it; errors name the
        camera, the node, the value and what the node allows."""
        self._check_open()
        kind = self.transport.kind(name)
        where = f"camera {self.name!r}: node {name}={value!r}"
        if kind is None:
            raise RigError(f"{where}: the device has no GenApi node {name!r}")
        if kind == "enum":
            entries = self.transport.entries(name)
            if str(value) not in entries:
                raise RigError(f"{where} refused: allowed values are {', '.join(entries)}")
            value = str(value)
        elif kind in ("int", "float"):
            if isinstance(value, bool) or not isinstance(value, (int, float)) or (kind == "int" and int(value) != value):
                raise RigError(f"{where} refused: expected {'an integer' if kind == 'int' else 'a number'}, "
                               f"{self.allowed(name)}")  # fmt: skip
            lo, hi = self.transport.bounds(name)
            if not lo <= value <= hi:
                raise RigError(f"{where} refused: out of range, allowed {self.allowed(name)}")
            value = int(value) if kind == "int" else float(value)
        elif kind == "bool":
            if not isinstance(value, bool):
                raise RigError(f"{where} refused: expected true or false")
        elif kind == "command":
            if value is not True:
                raise RigError(f"{where} refused: a command node takes true (execute)")
            try:
                self.transport.execute(name)
            except Exception as exc:
                raise RigError(f"{where}: the device refused the command: {exc}") from exc
            return
        try:
            self.transport.write(name, value)
        except Exception as exc:
            raise RigError(f"{where} refused by the device ({exc}); allowed {self.allowed(name)}") from exc

    def _node_for(self, feature: str) -> str | None:
        for name in NODE_NAMES.get(feature, (feature,)):
            if self.transport.kind(name) is not None:
                return name
        return None

    # -- CameraDevice hooks ------------------------------------------------------------
    def fetch(self, timeout: float | None = None):
        """Lease the next frame (see :meth:`rigs.CameraDevice.fetch`); ``timeout`` defaults to
        the camera's ``timeout`` option."""
        return super().fetch(float(self.options["timeout"]) if timeout is None else timeout)

    def configure(self, **features: Any) -> None:
        self._requested |= set(features)
        super().configure(**features)

    def _apply(self, features: dict[str, Any]) -> None:
        free_run = features.get("TriggerMode") == "Off"
        for feature in ORDER:
            value = features.get(feature)
            if feature not in self._requested or self._written.get(feature) == value:
                continue
            if feature == "AcquisitionFrameRate" and not free_run:
                continue  # a triggered camera exposes at the trigger rate
            if feature in ("TriggerSource", "TriggerSelector") and free_run:
                continue
            node = self._node_for(feature)
            if node is None:
                if IMPLIED.get(feature) == value:
                    continue
                names = " or ".join(NODE_NAMES.get(feature, (feature,)))
                raise RigError(f"camera {self.name!r}: {feature}={value!r} cannot be set: the device has no "
                               f"GenApi node {names}")  # fmt: skip
            if feature == "AcquisitionFrameRate" and self.transport.kind("AcquisitionFrameRateEnable") == "bool":
                self.set_node("AcquisitionFrameRateEnable", True)
            self.set_node(node, value)
            if feature == "GevIEEE1588" and value:
                self._wait_ptp_lock()
            self._written[feature] = value

    def _wait_ptp_lock(self) -> None:
        status_node = next((n for n in PTP_STATUS if self.transport.kind(n) is not None), None)
        if status_node is None:
            raise RigError(f"camera {self.name!r}: PTP enabled but the device has no {' or '.join(PTP_STATUS)} "
                           "node to report its lock")  # fmt: skip
        deadline = time.monotonic() + float(self.options["ptp_timeout"])
        status = None
        while time.monotonic() < deadline:
            status = str(self.transport.read(status_node))
            if status in ("Master", "Slave"):
                self.info["ptp_status"] = status
                return
            time.sleep(0.1)
        raise RigError(f"camera {self.name!r}: PTP did not lock within {self.options['ptp_timeout']:g} s "
                       f"({status_node}={status!r}, expected Master or Slave)")  # fmt: skip

    def _enable_chunks(self) -> None:
        if self.transport.kind("ChunkModeActive") is None:
            raise RigError(f"camera {self.name!r}: option chunks: the device has no GenApi node "
                           "'ChunkModeActive' (it sends no chunk data); set chunks: false")  # fmt: skip
        self.set_node("ChunkModeActive", True)
        for chunk in ("Timestamp", "FrameID"):
            if chunk in (self.transport.entries("ChunkSelector") if self.transport.kind("ChunkSelector") == "enum" else []):
                self.set_node("ChunkSelector", chunk)
                self.set_node("ChunkEnable", True)

    def _arm_action_keys(self) -> None:
        """Device side of action commands; the issuer's transport must be able to send them."""
        self.set_node("ActionDeviceKey", self.action["device_key"])
        if self.transport.kind("ActionSelector") is not None:
            self.set_node("ActionSelector", 1)
        self.set_node("ActionGroupKey", self.action["group_key"])
        self.set_node("ActionGroupMask", self.action["group_mask"])
        why = self.transport.action_issuer() if self.issuer else None
        if why is not None:
            raise RigError(f"camera {self.name!r}: trigger mode action: {why}; use mode software or hardware")

    def _start(self) -> None:
        self._ids = (None, None)
        self._first_id = None
        self.transport.start(int(self.options["buffers"]))
        source = self._features.get("TriggerSource")
        if self._trigger is not None and self._features.get("TriggerMode") == "On":
            if source == "Software":
                self._trigger.arm(self.name, self._fire)
            elif self.action is not None and str(source).startswith("Action"):
                self._trigger.arm(self.name, self._fire_action if self.issuer else _nothing)

    def _fire(self) -> None:
        self.transport.execute("TriggerSoftware")
        self._counters["triggers"] += 1

    def _fire_action(self) -> None:
        a = self.action
        self.transport.issue_action(a["device_key"], a["group_key"], a["group_mask"])
        self._counters["actions"] = self._counters.get("actions", 0) + 1

    def _stop(self) -> None:
        try:
            if self._trigger is not None:
                self._trigger.disarm(self.name)
        finally:
            self.transport.stop()

    def _next(self, timeout: float) -> Frame:
        deadline = time.monotonic() + max(0.0, float(timeout))
        while True:
            raw = self.transport.pop(max(0.0, deadline - time.monotonic()))
            if raw is None:
                raise FrameTimeout(f"camera {self.name!r}: no frame within {timeout:g} s")
            try:
                if not raw.complete:
                    self._counters["incomplete_buffers"] += 1
                    continue
                image = to_image(raw.data, raw.width, raw.height, raw.pixel_format,
                                 debayer=bool(self.options["debayer"]))  # fmt: skip
            finally:
                self.transport.requeue(raw)
            chunks = raw.chunks or {}
            ts = chunks.get("ChunkTimestamp") or raw.timestamp_ns
            if chunks.get("ChunkTimestamp"):
                self._counters["chunk_timestamps"] += 1
            if not ts:
                ts = time.time_ns()
                self._counters["host_timestamps"] += 1
            raw_id = int(chunks.get("ChunkFrameID", raw.frame_id))
            last_raw, last = self._ids
            fid = unwrap_frame_id(raw_id, last_raw, last)
            self._ids = (raw_id, fid)
            if self._first_id is None:
                self._first_id = fid
            return Frame(self.name, image, int(ts), fid - self._first_id)

    def device_stats(self) -> dict[str, Any]:
        out = {k: int(v) for k, v in self.transport.statistics().items()}
        out.update(self._counters)
        pattern = bayer_pattern(self._features["PixelFormat"])
        if pattern is not None:
            out["bayer_pattern"] = pattern
            out["debayered"] = bool(self.options["debayer"])
        return out

    def _close(self) -> None:
        try:
            self.transport.stop()
        finally:
            self.transport.close()
            _OPEN.discard(self.transport)
