"""A GenTL-level fake camera behind :class:`rigs.backends._genapi.Transport`, for what the
simulated producers do not offer: software and line triggers, Bayer and packed formats,
chunk timestamps, PTP lock, buffer underruns.

The device model: a frame is exposed on every trigger (``TriggerMode=On``: ``TriggerSoftware``
or :meth:`FakeTransport.pulse` on the trigger line) or every ``1/AcquisitionFrameRate`` s
(free-run thread). Each exposure increments the device's 16-bit block id (1..65535, starting
at ``first_id``) whether or not a buffer is free; with no free buffer the frame is lost and
counted in ``n_underruns``. The image is :func:`scene` of the block id, packed in the current
``PixelFormat`` (Bayer formats: the mosaic of the flat colour). The buffer timestamp is the
exposure time on the shared clock plus ``clock_offset_ns`` (0 once PTP is locked) plus 1 ms of
transfer; the chunk ``ChunkTimestamp`` is the exposure time itself.
"""

from __future__ import annotations

import collections
import threading
import time

import numpy as np

from rigs.backends import register_backend
from rigs.backends._genapi import GenICamCamera, RawBuffer, Transport, camera_arguments, common_options
from rigs.pixelformats import SENSOR_FORMATS, mosaic

FORMATS = ["Mono8", "Mono12", "Mono12p", "Mono12Packed", "Mono16", "RGB8", "BGR8",
           *[f"Bayer{p}{b}" for p in ("RG", "GB", "GR", "BG") for b in ("8", "12", "12p", "12Packed")]]  # fmt: skip
FLAT_RGB12 = (1000, 2000, 3000)  # the flat colour of colour formats, 12-bit


def scene_mono12(width: int, height: int, block_id: int) -> np.ndarray:
    """The mono scene, 12-bit: ``(7x + 13y + id) mod 4096``."""
    y, x = np.mgrid[0:height, 0:width]
    return ((7 * x + 13 * y + block_id) % 4096).astype(np.uint16)


def pack(values12: np.ndarray, pixel_format: str) -> bytes:
    """12-bit values as the buffer of ``pixel_format`` (the inverse of :func:`rigs.pixelformats.unpack`)."""
    f = SENSOR_FORMATS[pixel_format]
    v = values12.astype(np.uint16)
    if f.bits == 8:
        return (v >> 4).astype(np.uint8).tobytes()
    if f.bits == 16:
        return (v << 4).astype("<u2").tobytes()
    if f.packing is None:
        return v.astype("<u2").tobytes()
    a, b = v.reshape(-1, 2)[:, 0], v.reshape(-1, 2)[:, 1]
    if f.packing == "lsb":
        out = np.stack([a & 0xFF, (a >> 8) | ((b & 0x0F) << 4), b >> 4], axis=1)
    else:
        out = np.stack([a >> 4, (a & 0x0F) | ((b & 0x0F) << 4), b >> 4], axis=1)
    return out.astype(np.uint8).tobytes()


def frame_bytes(width: int, height: int, pixel_format: str, block_id: int) -> bytes:
    f = SENSOR_FORMATS[pixel_format]
    if f.channels == 1 and f.pattern is None:
        return pack(scene_mono12(width, height, block_id), pixel_format)
    rgb = np.empty((height, width, 3), np.uint16)
    rgb[:] = FLAT_RGB12
    if f.pattern is not None:
        return pack(mosaic(rgb, f.pattern), pixel_format)
    if f.order == "BGR":
        rgb = rgb[:, :, ::-1]
    return pack(rgb, pixel_format)


class FakeTransport(Transport):
    def __init__(self, first_id: int = 65530, clock_offset_ns: int = 0, ptp_lock_s: float = 0.05):
        self.values = {"Width": 32, "Height": 24, "OffsetX": 0, "OffsetY": 0, "PixelFormat": "Mono8",
                       "ExposureTime": 10000.0, "Gain": 0.0, "AcquisitionFrameRate": 30.0,
                       "TriggerSelector": "FrameStart", "TriggerMode": "Off", "TriggerSource": "Software",
                       "TriggerActivation": "RisingEdge", "LineSelector": "Line0", "LineMode": "Input",
                       "GevIEEE1588": False, "GevIEEE1588Status": "Disabled", "ChunkModeActive": False,
                       "ChunkSelector": "Timestamp", "ChunkEnable": False, "DeviceModelName": "FakeGenTL",
                       "ActionDeviceKey": 0, "ActionSelector": 1, "ActionGroupKey": 0, "ActionGroupMask": 0}
        self.kinds = {"Width": "int", "Height": "int", "OffsetX": "int", "OffsetY": "int", "PixelFormat": "enum",
                      "ExposureTime": "float", "Gain": "float", "AcquisitionFrameRate": "float",
                      "TriggerSelector": "enum", "TriggerMode": "enum", "TriggerSource": "enum",
                      "TriggerActivation": "enum", "TriggerSoftware": "command", "LineSelector": "enum",
                      "LineMode": "enum", "GevIEEE1588": "bool", "GevIEEE1588Status": "enum",
                      "ChunkModeActive": "bool", "ChunkSelector": "enum", "ChunkEnable": "bool",
                      "DeviceModelName": "string", "ActionDeviceKey": "int", "ActionSelector": "int",
                      "ActionGroupKey": "int", "ActionGroupMask": "int"}
        self.enums = {"PixelFormat": FORMATS, "TriggerSelector": ["FrameStart"], "TriggerMode": ["Off", "On"],
                      "TriggerSource": ["Software", "Line0", "Line1", "Action1"], "TriggerActivation": ["RisingEdge", "FallingEdge"],
                      "LineSelector": ["Line0", "Line1"], "LineMode": ["Input", "Output"],
                      "GevIEEE1588Status": ["Disabled", "Listening", "Slave", "Master"],
                      "ChunkSelector": ["Timestamp", "FrameID"]}
        self.ranges = {"Width": (8, 256), "Height": (8, 256), "OffsetX": (0, 248), "OffsetY": (0, 248),
                       "ExposureTime": (10.0, 1e6), "Gain": (0.0, 24.0), "AcquisitionFrameRate": (1.0, 500.0),
                       "ActionDeviceKey": (0, 0xFFFFFFFF), "ActionSelector": (0, 7), "ActionGroupKey": (0, 0xFFFFFFFF),
                       "ActionGroupMask": (0, 0xFFFFFFFF)}  # fmt: skip
        self.block_id = first_id - 1
        self.clock_offset_ns = int(clock_offset_ns)
        self.ptp_lock_s = ptp_lock_s
        self._ptp_since: float | None = None
        self.stats = collections.Counter(n_completed_buffers=0, n_underruns=0)
        self.exposures = 0
        self.actions_issued = 0
        self.streaming = False
        self.closed = False
        self._free = 0
        self._out: collections.deque = collections.deque()
        self._cv = threading.Condition()
        self._thread: threading.Thread | None = None

    # -- nodes
    def kind(self, node):
        return self.kinds.get(node)

    def read(self, node):
        if node == "GevIEEE1588Status" and self.values["GevIEEE1588"]:
            locked = time.monotonic() - self._ptp_since >= self.ptp_lock_s
            return "Slave" if locked else "Listening"
        return self.values[node]

    def write(self, node, value):
        if self.streaming and node in ("Width", "Height", "PixelFormat"):
            raise RuntimeError(f"{node} is locked while streaming (TLParamsLocked)")
        if node == "GevIEEE1588Status":
            raise RuntimeError("GevIEEE1588Status is read-only")
        self.values[node] = value
        if node == "GevIEEE1588":
            self._ptp_since = time.monotonic() if value else None

    def entries(self, node):
        return list(self.enums[node])

    def bounds(self, node):
        return self.ranges[node]

    def execute(self, node):
        if node != "TriggerSoftware":
            raise RuntimeError(f"unknown command {node}")
        if self.values["TriggerMode"] == "On" and self.values["TriggerSource"] == "Software":
            self._expose()

    def action_issuer(self):
        return None

    def issue_action(self, device_key, group_key, group_mask):
        """A GigE Vision action command on the fake network: every streaming fake whose keys
        match (device key equal, group key equal, group masks overlapping) exposes."""
        self.actions_issued += 1
        for t in CREATED:
            v = t.values
            if (v["TriggerMode"] == "On" and v["TriggerSource"] == f"Action{v['ActionSelector']}"
                    and v["ActionDeviceKey"] == device_key and v["ActionGroupKey"] == group_key
                    and v["ActionGroupMask"] & group_mask):  # fmt: skip
                t._expose()

    def pulse(self, line: str = "Line0") -> None:
        """An edge on input ``line`` (a hardware trigger)."""
        if self.values["TriggerMode"] == "On" and self.values["TriggerSource"] == line:
            self._expose()

    # -- stream
    def _expose(self) -> None:
        with self._cv:
            if not self.streaming:
                return
            self.exposures += 1
            self.block_id = self.block_id % 0xFFFF + 1
            t = time.time_ns() + (0 if self.read("GevIEEE1588Status") == "Slave" else self.clock_offset_ns)
            if self._free == 0:
                self.stats["n_underruns"] += 1
                return
            self._free -= 1
            w, h, fmt = self.values["Width"], self.values["Height"], self.values["PixelFormat"]
            chunks = ({"ChunkTimestamp": t, "ChunkFrameID": self.block_id}
                      if self.values["ChunkModeActive"] else None)  # fmt: skip
            self._out.append(RawBuffer(frame_bytes(w, h, fmt, self.block_id), w, h, fmt, t + 1_000_000,
                                       self.block_id, True, chunks))  # fmt: skip
            self.stats["n_completed_buffers"] += 1
            self._cv.notify_all()

    def _free_run(self) -> None:
        period = 1.0 / self.values["AcquisitionFrameRate"]
        t0, k = time.monotonic(), 0
        while self.streaming:
            self._expose()
            k += 1
            time.sleep(max(0.0, t0 + k * period - time.monotonic()))

    def start(self, buffers):
        with self._cv:
            self._free, self._out = int(buffers), collections.deque()
            self.streaming = True
        if self.values["TriggerMode"] == "Off":
            self._thread = threading.Thread(target=self._free_run, daemon=True)
            self._thread.start()

    def stop(self):
        with self._cv:
            self.streaming = False
            self._out.clear()
            self._cv.notify_all()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def pop(self, timeout):
        with self._cv:
            if not self._out and timeout > 0:
                self._cv.wait(timeout)
            return self._out.popleft() if self._out else None

    def requeue(self, buffer):
        with self._cv:
            if self.streaming:
                self._free += 1

    def statistics(self):
        return dict(self.stats)

    def close(self):
        self.stop()
        self.closed = True


class FakeGenTLCamera(GenICamCamera):
    backend = "fake-gentl"


#: device id -> FakeTransport keyword arguments, set by the tests
DEVICES: dict[str, dict] = {}
#: every transport opened, in order (the tests check they were all closed)
CREATED: list[FakeTransport] = []


def open_camera(config, description, *, epoch_ns, shared=None):
    options = common_options(config.name, "fake-gentl", dict(config.options), set())
    transport = FakeTransport(**DEVICES.get(str(config.device.get("id")), {}))
    CREATED.append(transport)
    features, sync = camera_arguments(config, description, shared)
    return FakeGenTLCamera(config.name, features, transport, options, **sync)


register_backend("fake-gentl", open_camera)
