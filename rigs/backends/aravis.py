"""``backend: aravis`` — GenICam cameras (GigE Vision, USB3 Vision) through Aravis 0.8 and PyGObject.

Aravis itself, its GObject introspection data and the in-process ``Fake`` camera come from
the operating system (Debian 12: ``gir1.2-aravis-0.8``); PyGObject from the ``[aravis]``
extra. The camera is :class:`rigs.backends._genapi.GenICamCamera` over :class:`AravisTransport`.

Rig YAML (camera keys)::

    backend: aravis
    device: {id: Fake_1}          # id (Aravis device id) | address (GigE camera's IPv4) | serial | model
    interfaces: [Fake]            # Aravis interfaces to enable (others disabled); default: Aravis' own
    packet_size: 8164             # GigE only: bytes, or "auto" (negotiated); default: camera's
    packet_delay: 0               # GigE only: inter-packet delay, ns
    packet_resend: true           # GigE only: ask the camera to resend lost packets (default true)

plus the shared options of :mod:`rigs.backends._genapi` (``buffers``, ``timeout``, ``debayer``,
``chunks``, ``nodes``, ...). The stream's own counters (``n_completed_buffers``,
``n_failures``, ``n_underruns``, and for GigE ``n_resent_packets``, ``n_missing_packets``, ...)
are :meth:`~rigs.CameraDevice.device_stats`, which ``studio capture`` copies into the session.

Opening by ``serial`` or ``model`` enumerates the enabled interfaces (a GigE Vision
discovery broadcasts on the local networks); opening by ``id`` does not enumerate.
"""

from __future__ import annotations

import ipaddress
import logging
from typing import Any

from rigs.backends._genapi import GenICamCamera, RawBuffer, Transport, camera_arguments, common_options
from rigs.device import RigError

__all__ = ["AravisCamera", "AravisTransport", "import_aravis", "list_devices", "open_camera"]

log = logging.getLogger(__name__)

_OPTIONS = {"interfaces", "packet_size", "packet_delay", "packet_resend"}
_KINDS = (("GcEnumeration", "enum"), ("GcCommand", "command"), ("GcBoolean", "bool"), ("GcFloat", "float"),
          ("GcInteger", "int"), ("GcString", "string"))  # fmt: skip


def import_aravis():
    """``(Aravis, GLib)`` from PyGObject, or :class:`RigError` saying what to install."""
    try:
        import gi
    except ImportError:
        raise RigError("aravis backend: PyGObject is not installed (pip install '.[aravis]'; it builds "
                       "against libgirepository1.0-dev and libcairo2-dev)") from None  # fmt: skip
    try:
        gi.require_version("Aravis", "0.8")
        from gi.repository import Aravis, GLib
    except (ValueError, ImportError) as exc:
        raise RigError(f"aravis backend: the Aravis 0.8 introspection data is missing ({exc}); "
                       "install gir1.2-aravis-0.8 (Debian/Ubuntu)") from None  # fmt: skip
    return Aravis, GLib


def select_interfaces(arv, wanted) -> None:
    """Enable exactly the Aravis interfaces in ``wanted`` (None: leave Aravis' defaults)."""
    if wanted is None:
        return
    known = [arv.get_interface_id(i) for i in range(arv.get_n_interfaces())]
    if isinstance(wanted, str) or not all(w in known for w in wanted):
        raise RigError(f"aravis backend: option interfaces {wanted!r}: expected a list of {known}")
    for name in known:
        (arv.enable_interface if name in wanted else arv.disable_interface)(name)


def list_devices(arv) -> list[dict[str, str]]:
    """The devices of the enabled interfaces (enumerates: a GigE discovery broadcasts)."""
    arv.update_device_list()
    return [{"id": arv.get_device_id(i), "vendor": arv.get_device_vendor(i), "model": arv.get_device_model(i),
             "serial": arv.get_device_serial_nbr(i), "interface": arv.get_device_protocol(i),
             "address": arv.get_device_address(i)} for i in range(arv.get_n_devices())]  # fmt: skip


class AravisTransport(Transport):
    """One ``Arv.Camera`` and its stream."""

    def __init__(self, arv, glib, camera_id: str, owner: str):
        self.arv, self.glib, self.owner = arv, glib, owner
        try:
            self.camera = arv.Camera.new(camera_id)
        except glib.Error as exc:
            raise RigError(f"camera {owner!r}: Aravis cannot open device {camera_id!r}: {exc.message}") from None
        self.device = self.camera.get_device()
        self.stream = None
        self.chunk_parser = None
        self._format = "Mono8"
        self.resend: bool | None = None  # GigE packet resend policy, applied to each new stream
        self._last_stats: dict[str, int] = {}

    # -- nodes ---------------------------------------------------------------------
    def kind(self, node: str) -> str | None:
        feature = self.device.get_feature(node)
        if feature is None:
            return None
        for cls, kind in _KINDS:
            if isinstance(feature, getattr(self.arv, cls)):
                return kind
        return None

    def read(self, node: str) -> Any:
        d, kind = self.device, self.kind(node)
        getter = {"enum": d.get_string_feature_value, "string": d.get_string_feature_value,
                  "int": d.get_integer_feature_value, "float": d.get_float_feature_value,
                  "bool": d.get_boolean_feature_value}[kind]  # fmt: skip
        return getter(node)

    def write(self, node: str, value: Any) -> None:
        d, kind = self.device, self.kind(node)
        setter = {"enum": d.set_string_feature_value, "string": d.set_string_feature_value,
                  "int": d.set_integer_feature_value, "float": d.set_float_feature_value,
                  "bool": d.set_boolean_feature_value}[kind]  # fmt: skip
        try:
            setter(node, value)
        except self.glib.Error as exc:
            raise RigError(exc.message) from None

    def entries(self, node: str) -> list[str]:
        return list(self.device.dup_available_enumeration_feature_values_as_strings(node))

    def bounds(self, node: str) -> tuple[float, float]:
        b = (self.device.get_float_feature_bounds if self.kind(node) == "float"
             else self.device.get_integer_feature_bounds)(node)  # fmt: skip
        return b[0], b[1]

    def execute(self, node: str) -> None:
        try:
            self.device.execute_command(node)
        except self.glib.Error as exc:
            raise RigError(exc.message) from None

    # -- GigE ----------------------------------------------------------------------
    def configure_gige(self, packet_size, packet_delay) -> None:
        if packet_size == "auto":
            self.camera.gv_auto_packet_size()
        elif packet_size is not None:
            self.camera.gv_set_packet_size(int(packet_size))
        if packet_delay is not None:
            self.camera.gv_set_packet_delay(int(packet_delay))

    # -- stream --------------------------------------------------------------------
    def start(self, buffers: int) -> None:
        self._format = self.camera.get_pixel_format_as_string()
        self.stream = self.camera.create_stream(None, None)
        if self.resend is not None and self.camera.is_gv_device():
            policy = self.arv.GvStreamPacketResend.ALWAYS if self.resend else self.arv.GvStreamPacketResend.NEVER
            self.stream.set_property("packet-resend", policy)
        payload = self.camera.get_payload()
        for _ in range(int(buffers)):
            self.stream.push_buffer(self.arv.Buffer.new_allocate(payload))
        self.camera.set_acquisition_mode(self.arv.AcquisitionMode.CONTINUOUS)
        self.camera.start_acquisition()

    def stop(self) -> None:
        if self.stream is None:
            return
        try:
            self.camera.stop_acquisition()
        finally:
            self._last_stats = self._read_stats()
            self.stream = None  # the last reference: Aravis joins the stream thread and frees the buffers

    def pop(self, timeout: float) -> RawBuffer | None:
        buf = (self.stream.timeout_pop_buffer(int(timeout * 1e6)) if timeout > 0
               else self.stream.try_pop_buffer())  # fmt: skip
        if buf is None:
            return None
        ok = buf.get_status() == self.arv.BufferStatus.SUCCESS
        chunks = None
        if ok and self.chunk_parser is not None and buf.has_chunks():
            chunks = {}
            for name in ("ChunkTimestamp", "ChunkFrameID"):
                try:
                    chunks[name] = int(self.chunk_parser.get_integer_value(buf, name))
                except self.glib.Error:
                    pass
        return RawBuffer(buf.get_data() if ok else b"", buf.get_image_width() if ok else 0,
                         buf.get_image_height() if ok else 0, self._format, int(buf.get_timestamp()),
                         int(buf.get_frame_id()), ok, chunks, buf)  # fmt: skip

    def requeue(self, buffer: RawBuffer) -> None:
        if self.stream is not None:
            self.stream.push_buffer(buffer.token)

    def _read_stats(self) -> dict[str, int]:
        s = self.stream
        out = {}
        for i in range(s.get_n_infos()):
            if s.get_info_type(i).name == "guint64":
                out[s.get_info_name(i)] = int(s.get_info_uint64(i))
        return out

    def statistics(self) -> dict[str, int]:
        return self._read_stats() if self.stream is not None else dict(self._last_stats)

    def enable_chunk_parser(self) -> None:
        self.chunk_parser = self.camera.create_chunk_parser()

    def action_issuer(self) -> str | None:
        return "Aravis 0.8 has no API to issue GigE Vision action commands"

    def close(self) -> None:
        self.stop()
        self.chunk_parser = None
        self.device = None
        self.camera = None  # unref: Aravis closes the device


class AravisCamera(GenICamCamera):
    """A GenICam camera opened through Aravis."""

    backend = "aravis"


def _camera_id(arv, owner: str, device: dict) -> str:
    if "address" in device:
        try:  # an IP literal: Aravis then talks to that address only (a name it cannot resolve
            return str(ipaddress.IPv4Address(str(device["address"])))  # would start a discovery broadcast)
        except ValueError:
            raise RigError(f"camera {owner!r}: device address {device['address']!r} is not an IPv4 address") from None
    if "id" in device:
        return str(device["id"])
    for key in ("serial", "model", "user_id"):
        if key in device:
            found = [d for d in list_devices(arv) if str(d.get(key if key != "user_id" else "id")) == str(device[key])]
            if len(found) != 1:
                raise RigError(f"camera {owner!r}: device {key}={device[key]!r} matches {len(found)} Aravis "
                               f"device(s); found {[d['id'] for d in list_devices(arv)]}")  # fmt: skip
            return found[0]["id"]
    raise RigError(f"camera {owner!r}: aravis device needs 'id', 'address', 'serial' or 'model', got {device!r}")


def open_camera(config, description, *, epoch_ns: int, shared: dict | None = None) -> AravisCamera:
    """Backend factory: a :class:`GenICamCamera` over Aravis for ``config``."""
    arv, glib = import_aravis()
    name = config.name
    raw = dict(config.options)
    options = common_options(name, "aravis", raw, _OPTIONS)
    select_interfaces(arv, raw.get("interfaces"))
    transport = AravisTransport(arv, glib, _camera_id(arv, name, dict(config.device)), name)
    try:
        gige = {k: raw[k] for k in ("packet_size", "packet_delay", "packet_resend") if raw.get(k) is not None}
        if gige and not transport.camera.is_gv_device():
            raise RigError(f"camera {name!r}: options {sorted(gige)} apply to GigE Vision cameras only; "
                           f"{transport.camera.get_model_name()!r} is not one")  # fmt: skip
        if gige:
            transport.configure_gige(gige.get("packet_size"), gige.get("packet_delay"))
        transport.resend = gige.get("packet_resend", True) if transport.camera.is_gv_device() else None
        if options["chunks"]:
            transport.enable_chunk_parser()
        features, sync = camera_arguments(config, description, shared)
        info = {"vendor": transport.camera.get_vendor_name(), "model": transport.camera.get_model_name(),
                "serial": transport.camera.get_device_serial_number()}  # fmt: skip
    except BaseException:
        transport.close()
        raise
    return AravisCamera(name, features, transport, options, info=info, **sync)
