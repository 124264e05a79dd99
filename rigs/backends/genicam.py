"""``backend: genicam`` — GenICam cameras through harvesters and any GenTL producer (``.cti``).

The camera is :class:`rigs.backends._genapi.GenICamCamera` over :class:`HarvesterTransport`
(one harvesters ``ImageAcquirer``). One ``Harvester`` per rig loads the producers (kept in the
backends' ``shared`` dict) and is reset when the rig's last camera closes.

Rig YAML (camera keys)::

    backend: genicam
    producer: /opt/vendor/lib/vendor.cti   # a .cti file or a list; default: every .cti in the
                                           # folders of $GENICAM_GENTL64_PATH
    device: {serial: "21345678"}           # serial | user_id | model | id | index

plus the shared options of :mod:`rigs.backends._genapi` (``buffers``, ``timeout``, ``debayer``,
``chunks``, ``nodes``, ...). Buffers come from harvesters raw (its own pixel conversion is
bypassed) and go through :func:`rigs.pixelformats.to_image`. The ``genicam`` wheel ships a
simulated producer, ``genicam/viky.cti`` (three devices, ``RGBa8``/``Mono8`` 400×400, no
device timestamps: frames are then stamped with the host clock, counted in ``host_timestamps``).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from rigs.backends._genapi import GenICamCamera, RawBuffer, Transport, camera_arguments, common_options
from rigs.device import RigError

__all__ = ["GenTLCamera", "HarvesterTransport", "open_camera", "open_harvester", "producer_files"]

log = logging.getLogger(__name__)

_OPTIONS = {"producer"}
# genicam.genapi.EInterfaceType values
_KINDS = {2: "int", 3: "bool", 4: "command", 5: "float", 6: "string", 9: "enum"}
_DEVICE_KEYS = {"serial": "serial_number", "user_id": "user_defined_name", "model": "model", "id": "id_"}


def import_harvesters():
    """``harvesters.core.Harvester``, or :class:`RigError` saying what to install."""
    try:
        from harvesters.core import Harvester
    except ImportError:
        raise RigError("genicam backend: harvesters is not installed (pip install '.[genicam]')") from None
    return Harvester


def producer_files(producer: Any = None) -> list[Path]:
    """The GenTL producers to load: ``producer`` (a path or a list), else every ``.cti`` in the
    folders of ``$GENICAM_GENTL64_PATH``; :class:`RigError` when there is none."""
    if producer is not None:
        paths = [Path(p) for p in ([producer] if isinstance(producer, (str, Path)) else producer)]
        missing = [str(p) for p in paths if not p.is_file()]
        if missing:
            raise RigError(f"genicam backend: GenTL producer {missing[0]} does not exist (option producer)")
        return paths
    env = os.environ.get("GENICAM_GENTL64_PATH", "")
    found = sorted(p for d in env.split(os.pathsep) if d and Path(d).is_dir() for p in Path(d).glob("*.cti"))
    if not found:
        raise RigError("genicam backend: no GenTL producer: set option producer (a .cti file) or "
                       "GENICAM_GENTL64_PATH (folders holding .cti files); the genicam wheel ships "
                       "a simulated one, genicam/viky.cti")  # fmt: skip
    return found


def open_harvester(shared: dict | None, producers: list[Path]):
    """The rig's Harvester for ``producers`` (``shared`` keeps it and counts its users)."""
    key = ("harvester", tuple(str(p) for p in producers))
    if shared is not None and key in shared:
        entry = shared[key]
        entry["users"] += 1
        return entry
    harvester = import_harvesters()()
    try:
        for p in producers:
            harvester.add_file(str(p), check_existence=True)
        harvester.update()
    except Exception as exc:
        harvester.reset()
        raise RigError(f"genicam backend: cannot load GenTL producer(s) {[str(p) for p in producers]}: {exc}") from exc
    entry = {"harvester": harvester, "users": 1}
    if shared is not None:
        shared[key] = entry
    return entry


class HarvesterTransport(Transport):
    """One harvesters ``ImageAcquirer``."""

    def __init__(self, entry: dict, search: dict | int, owner: str):
        self.entry, self.owner = entry, owner
        try:
            self.acquirer = entry["harvester"].create(search)
        except Exception as exc:
            devices = [(d.serial_number, d.model, d.id_) for d in entry["harvester"].device_info_list]
            raise RigError(f"camera {owner!r}: GenTL device {search!r} cannot be opened ({exc or type(exc).__name__}); "
                           f"devices (serial, model, id): {devices}") from None  # fmt: skip
        self.nodes = self.acquirer.remote_device.node_map
        self._counts = {"num_images": 0}

    def _node(self, name: str):
        return getattr(self.nodes, name)

    def kind(self, node: str) -> str | None:
        if not self.nodes.has_node(node):
            return None
        return _KINDS.get(int(self._node(node).node.principal_interface_type))

    def read(self, node: str) -> Any:
        return self._node(node).value

    def write(self, node: str, value: Any) -> None:
        self._node(node).value = value

    def entries(self, node: str) -> list[str]:
        return [str(s) for s in self._node(node).symbolics]

    def bounds(self, node: str) -> tuple[float, float]:
        n = self._node(node)
        return n.min, n.max

    def execute(self, node: str) -> None:
        self._node(node).execute()

    def start(self, buffers: int) -> None:
        self.acquirer.num_buffers = int(buffers)
        self.acquirer.start()

    def stop(self) -> None:
        if self.acquirer is not None and self.acquirer.is_acquiring():
            self.acquirer.stop()

    def pop(self, timeout: float) -> RawBuffer | None:
        buf = self.acquirer.try_fetch(timeout=max(float(timeout), 1e-4))
        if buf is None:
            return None
        comp = buf.payload.components[0]
        data = np.frombuffer(buf.module.raw_buffer, np.uint8)[comp.data_offset:]
        try:
            ts = int(buf.timestamp_ns)
        except Exception:  # GenTL: the producer keeps no timestamps (NotAvailableException)
            ts = 0
        chunks = {}
        for name in ("ChunkTimestamp", "ChunkFrameID"):
            if self.nodes.has_node(name):
                try:
                    chunks[name] = int(self._node(name).value)
                except Exception:  # the chunk is not in this buffer
                    pass
        self._counts["num_images"] += 1
        return RawBuffer(data, int(comp.width), int(comp.height), str(comp.data_format), ts, int(buf.frame_id),
                         True, chunks, buf)  # fmt: skip

    def requeue(self, buffer: RawBuffer) -> None:
        buffer.token.queue()

    def statistics(self) -> dict[str, int]:
        return dict(self._counts)

    def _action_nodes(self):
        """The node map of the GenTL interface (or system) module that sends action commands."""
        interface = self.acquirer.device.parent
        for module in (interface, interface.parent):
            nodes = module.node_map
            if nodes is not None and nodes.has_node("ActionCommand"):
                return nodes
        return None

    def action_issuer(self) -> str | None:
        if self._action_nodes() is None:
            return "the GenTL producer has no ActionCommand node on its interface or system module"
        return None

    def issue_action(self, device_key: int, group_key: int, group_mask: int) -> None:
        nodes = self._action_nodes()
        nodes.ActionDeviceKey.value = int(device_key)
        nodes.ActionGroupKey.value = int(group_key)
        nodes.ActionGroupMask.value = int(group_mask)
        nodes.ActionCommand.execute()

    def close(self) -> None:
        if self.acquirer is None:
            return
        try:
            self.stop()
            self.acquirer.destroy()
        finally:
            self.acquirer = None
            self.entry["users"] -= 1
            if self.entry["users"] <= 0:
                self.entry["harvester"].reset()


class GenTLCamera(GenICamCamera):
    """A GenICam camera opened through harvesters and a GenTL producer."""

    backend = "genicam"


def _search_key(owner: str, device: dict) -> dict | int:
    if "index" in device:
        return int(device["index"])
    keys = {_DEVICE_KEYS[k]: str(v) for k, v in device.items() if k in _DEVICE_KEYS}
    if not keys or len(keys) != len(device):
        raise RigError(f"camera {owner!r}: genicam device needs any of {sorted(_DEVICE_KEYS)} or 'index', "
                       f"got {device!r}")  # fmt: skip
    return keys


def open_camera(config, description, *, epoch_ns: int, shared: dict | None = None) -> GenTLCamera:
    """Backend factory: a :class:`GenTLCamera` for ``config``."""
    name = config.name
    raw = dict(config.options)
    options = common_options(name, "genicam", raw, _OPTIONS)
    search = _search_key(name, dict(config.device))
    entry = open_harvester(shared, producer_files(raw.get("producer")))
    try:
        transport = HarvesterTransport(entry, search, name)
    except BaseException:
        entry["users"] -= 1
        if entry["users"] <= 0:
            entry["harvester"].reset()
        raise
    features, sync = camera_arguments(config, description, shared)
    info = {}
    for key, node in (("vendor", "DeviceVendorName"), ("model", "DeviceModelName"), ("serial", "DeviceSerialNumber")):
        if transport.kind(node) is not None:
            info[key] = str(transport.read(node))
    return GenTLCamera(name, features, transport, options, info=info, **sync)
