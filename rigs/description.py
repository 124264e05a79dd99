"""Rig description files (``rigs/*.yaml``): which cameras, how they are triggered and synced.

Format (version 1)::

    format: studio.rig
    version: 1
    name: simulated
    frame_rate: 60.0                  # Hz, the trigger rate
    trigger:
      mode: software                  # software | hardware | free-run | action
      line: Line0                     # hardware trigger input (mode: hardware)
      selector: FrameStart
      action: {device_key: 1, group_key: 1, group_mask: 1}   # mode: action (GigE Vision)
    sync:
      ptp: true                       # cameras' clocks are IEEE 1588 synchronised
      tolerance_ms: 2.0               # max timestamp spread of one instant (SyncGroup)
      key: frame_id                   # frame_id | timestamp
      max_pending: 16
    calibration: calibration.json     # relative to this file; optional
    defaults:                         # merged under every camera (optional)
      backend: simulated
      pixel_format: RGB8
    cameras:
      cam0:
        backend: simulated            # simulated | replay | genicam | aravis
        device: {id: sim0}            # id / serial / address, whichever the backend uses
        pixel_format: RGB8            # RGB8 | Mono8 | RGB16 | Mono16; GenICam backends: any
                                      # format of rigs.pixelformats (BayerRG8, Mono12p, ...)
        width: 656
        height: 490
        exposure: 10000               # µs (GenICam ExposureTime)
        gain: 0.0                     # dB (GenICam Gain)
        # any other key is a backend option (simulated: source, jitter_ms, drop_probability,
        # drop_frames, duplicate_frames, realtime, loop, seed; replay: session, realtime, loop;
        # genicam/aravis: buffers, timeout, debayer, chunks, nodes, ... — rigs/backends/_genapi.py)

Relative paths (``calibration``, and the backend options ``source`` and ``session``) are
resolved against the folder of the YAML file. Errors name the file and the field.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import yaml

from rigs.device import PIXEL_FORMATS, RigError
from rigs.pixelformats import SENSOR_FORMATS

__all__ = ["CameraConfig", "RigDescription", "SyncConfig", "TriggerConfig"]

FORMAT = "studio.rig"
VERSION = 1
TRIGGER_MODES = ("software", "hardware", "free-run", "action")
#: the action-command keys of ``trigger: {mode: action}`` (GigE Vision: 32-bit each)
ACTION_KEYS = ("device_key", "group_key", "group_mask")
PATH_OPTIONS = ("source", "session")
_TOP_KEYS = {
    "format", "version", "name", "frame_rate", "trigger", "sync", "calibration", "cameras",
    "defaults", "description",
}
_CAMERA_KEYS = {"backend", "device", "pixel_format", "width", "height", "exposure", "gain"}


@dataclass(frozen=True)
class TriggerConfig:
    """How exposures are started: ``software`` (host timer), ``hardware`` (input ``line``),
    ``free-run`` (each camera's own clock) or ``action`` (GigE Vision action commands, one
    per tick for the whole rig, matched by the ``action`` keys)."""

    mode: str = "software"
    line: str | None = None
    selector: str = "FrameStart"
    action: dict[str, int] | None = None

    @property
    def genicam(self) -> dict[str, str]:
        """The GenICam trigger features this mode maps to."""
        if self.mode == "free-run":
            return {"TriggerMode": "Off"}
        source = {"software": "Software", "action": "Action1"}.get(self.mode, self.line)
        return {"TriggerMode": "On", "TriggerSelector": self.selector, "TriggerSource": source}


@dataclass(frozen=True)
class SyncConfig:
    """How frames of one instant are recognised (see :class:`rigs.SyncGroup`)."""

    ptp: bool = False
    tolerance_ns: int | None = 2_000_000
    key: str = "frame_id"
    max_pending: int = 16


@dataclass(frozen=True)
class CameraConfig:
    """One camera of a rig; ``options`` holds the backend-specific keys."""

    name: str
    backend: str
    device: dict[str, Any] = field(default_factory=dict)
    pixel_format: str = "RGB8"
    width: int | None = None
    height: int | None = None
    exposure: float | None = None
    gain: float | None = None
    options: dict[str, Any] = field(default_factory=dict)

    def features(self, frame_rate: float, trigger: TriggerConfig, ptp: bool) -> dict[str, Any]:
        """GenICam feature values this configuration asks for (unset ones omitted)."""
        f: dict[str, Any] = {"PixelFormat": self.pixel_format, "AcquisitionFrameRate": frame_rate}
        if self.width is not None:
            f["Width"] = self.width
        if self.height is not None:
            f["Height"] = self.height
        if self.exposure is not None:
            f["ExposureTime"] = self.exposure
        if self.gain is not None:
            f["Gain"] = self.gain
        f.update(trigger.genicam)
        f["GevIEEE1588"] = bool(ptp)
        return f


def _err(where: str, field_name: str, msg: str) -> RigError:
    return RigError(f"{where}: field {field_name!r}: {msg}")


def _number(where: str, name: str, value: Any, *, positive: bool = True, allow_none=False,
            low: float | None = None, high: float | None = None, integer: bool = False):
    """``value`` as a finite number (an integer when ``integer``) within [low, high]."""
    if value is None and allow_none:
        return None
    kind = "an integer" if integer else "a number"
    if isinstance(value, bool) or not isinstance(value, int if integer else (int, float)):
        raise _err(where, name, f"expected {kind}, got {value!r}")
    if not math.isfinite(value):
        raise _err(where, name, f"expected a finite number, got {value!r}")
    if positive and value <= 0:
        raise _err(where, name, f"expected a positive number, got {value!r}")
    if (low is not None and value < low) or (high is not None and value > high):
        span = f">= {low}" if high is None else f"<= {high}" if low is None else f"between {low} and {high}"
        raise _err(where, name, f"expected {kind} {span}, got {value!r}")
    return value


#: Backend options with a numeric or boolean meaning: (integer, low, high) or bool.
_OPTION_RULES: dict[str, tuple | type] = {
    "queue_size": (True, 1, 100_000),
    "max_frames": (True, 0, None),
    "jitter_ms": (False, 0.0, 1000.0),
    "clock_offset_ms": (False, -1e9, 1e9),
    "drop_probability": (False, 0.0, 1.0),
    "duplicate_probability": (False, 0.0, 1.0),
    "realtime": bool,
    "loop": bool,
}
#: Ranges of the camera fields (GenICam units: exposure in µs, gain in dB).
EXPOSURE_US = (1.0, 60e6)
GAIN_DB = (-20.0, 60.0)
FRAME_RATE_HZ = (1e-3, 100_000.0)


def _check_option(where: str, at: str, key: str, value: Any) -> None:
    rule = _OPTION_RULES.get(key)
    if rule is None or value is None:
        return
    if rule is bool:
        if not isinstance(value, bool):
            raise _err(where, f"{at}.{key}", f"expected true or false, got {value!r}")
        return
    integer, low, high = rule
    _number(where, f"{at}.{key}", value, positive=False, low=low, high=high, integer=integer)


class _UniqueKeyLoader(yaml.SafeLoader):
    """PyYAML keeps the last of two equal keys silently (two cameras named alike become one):
    this loader refuses the second, naming both lines."""

    def construct_mapping(self, node, deep=False):
        seen = {}
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                hash(key)
            except TypeError:
                continue  # the base class reports unhashable keys
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"key {key!r} appears twice (lines {seen[key] + 1} and {key_node.start_mark.line + 1}): "
                    "expected unique keys (two cameras or settings of the same name)", key_node.start_mark)
            seen[key] = key_node.start_mark.line
        return super().construct_mapping(node, deep)


@dataclass(frozen=True)
class RigDescription:
    """A validated rig description; build with :meth:`load` or :meth:`from_dict`."""

    name: str
    frame_rate: float
    cameras: dict[str, CameraConfig]
    trigger: TriggerConfig = TriggerConfig()
    sync: SyncConfig = SyncConfig()
    calibration: Path | None = None
    path: Path | None = None

    @property
    def camera_names(self) -> list[str]:
        return list(self.cameras)

    # -- construction ------------------------------------------------------------------
    @classmethod
    def load(cls, path: str | Path) -> RigDescription:
        """Read and validate a rig YAML file; errors name the file and the field."""
        path = Path(path)
        try:
            text = path.read_text(encoding="utf-8")
        except OSError as exc:
            raise RigError(f"rig description {path}: cannot read ({exc.strerror or exc})") from exc
        except UnicodeDecodeError as exc:
            raise RigError(f"rig description {path}: not UTF-8 text (byte {exc.start}): expected a UTF-8 YAML "
                           "file") from None
        try:
            data = yaml.load(text, Loader=_UniqueKeyLoader)  # noqa: S506 - a SafeLoader subclass
        except yaml.YAMLError as exc:
            raise RigError(f"rig description {path}: not valid YAML ({exc})") from exc
        except RecursionError:
            raise RigError(f"rig description {path}: nested too deeply to be a rig description") from None
        return cls.from_dict(data, path=path)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], *, path: str | Path | None = None) -> RigDescription:
        """Validate a description mapping; relative paths resolve against ``path``'s folder
        (the current folder when ``path`` is None)."""
        where = f"rig description {path}" if path is not None else "rig description"
        base = Path(path).resolve().parent if path is not None else Path.cwd()
        if not isinstance(d, Mapping):
            raise RigError(f"{where}: expected a mapping at the top level, got {type(d).__name__}")
        fmt = d.get("format")
        if fmt != FORMAT:
            raise _err(where, "format", f"expected {FORMAT!r}, got {fmt!r}")
        version = d.get("version")
        if not isinstance(version, int) or isinstance(version, bool):
            raise _err(where, "version", f"expected an integer, got {version!r}")
        if version != VERSION:
            raise _err(where, "version", f"unsupported major version {version} (this reader: {VERSION})")
        unknown = set(d) - _TOP_KEYS
        if unknown:
            raise _err(where, sorted(unknown)[0], f"unknown key; expected any of {sorted(_TOP_KEYS)}")
        name = d.get("name", Path(path).stem if path is not None else "rig")
        if not isinstance(name, str) or not name:
            raise _err(where, "name", f"expected a non-empty string, got {name!r}")
        frame_rate = float(_number(where, "frame_rate", d.get("frame_rate"), low=FRAME_RATE_HZ[0],
                                   high=FRAME_RATE_HZ[1]))
        trigger = cls._trigger(where, d.get("trigger") or {})
        sync = cls._sync(where, d.get("sync") or {})
        calibration = d.get("calibration")
        if calibration is not None:
            if not isinstance(calibration, (str, Path)):
                raise _err(where, "calibration", f"expected a path, got {calibration!r}")
            calibration = (base / calibration).resolve()
        defaults = d.get("defaults") or {}
        if not isinstance(defaults, Mapping):
            raise _err(where, "defaults", f"expected a mapping, got {defaults!r}")
        cams = d.get("cameras")
        if not isinstance(cams, Mapping) or not cams:
            raise _err(where, "cameras", "expected a non-empty mapping of camera name -> settings")
        cameras = {}
        for cname, cd in cams.items():
            if not isinstance(cname, str) or not cname or "/" in cname:
                raise _err(where, "cameras", f"camera names must be non-empty strings without '/', got {cname!r}")
            if cd is None:
                cd = {}
            if not isinstance(cd, Mapping):
                raise _err(where, f"cameras.{cname}", f"expected a mapping, got {cd!r}")
            merged = {**copy.deepcopy(dict(defaults)), **cd}
            cameras[cname] = cls._camera(where, cname, merged, base)
        return cls(name, frame_rate, cameras, trigger, sync, calibration,
                   Path(path).resolve() if path is not None else None)

    @staticmethod
    def _trigger(where: str, t: Any) -> TriggerConfig:
        if not isinstance(t, Mapping):
            raise _err(where, "trigger", f"expected a mapping, got {t!r}")
        mode = t.get("mode", "software")
        if mode not in TRIGGER_MODES:
            raise _err(where, "trigger.mode", f"expected one of {TRIGGER_MODES}, got {mode!r}")
        line = t.get("line")
        if mode == "hardware":
            if not (isinstance(line, str) and line.startswith("Line")):
                raise _err(where, "trigger.line", f"hardware trigger needs an input line like 'Line0', got {line!r}")
        selector = t.get("selector", "FrameStart")
        if selector != "FrameStart":
            raise _err(where, "trigger.selector", f"only 'FrameStart' is supported, got {selector!r}")
        action = None
        if mode == "action":
            a = t.get("action") or {}
            if not isinstance(a, Mapping) or set(a) - set(ACTION_KEYS):
                raise _err(where, "trigger.action", f"expected a mapping of {list(ACTION_KEYS)}, got {a!r}")
            action = {k: int(_number(where, f"trigger.action.{k}", a.get(k, 1), positive=False, low=0,
                                     high=0xFFFFFFFF, integer=True)) for k in ACTION_KEYS}  # fmt: skip
        return TriggerConfig(mode, line, selector, action)

    @staticmethod
    def _sync(where: str, s: Any) -> SyncConfig:
        if not isinstance(s, Mapping):
            raise _err(where, "sync", f"expected a mapping, got {s!r}")
        ptp = s.get("ptp", False)
        if not isinstance(ptp, bool):
            raise _err(where, "sync.ptp", f"expected true/false, got {ptp!r}")
        tol = s.get("tolerance_ms", 2.0)
        if tol is not None:
            tol = _number(where, "sync.tolerance_ms", tol, positive=False, low=0.0, high=60_000.0)
            tol = int(round(tol * 1e6))
        key = s.get("key", "frame_id")
        if key not in ("frame_id", "timestamp"):
            raise _err(where, "sync.key", f"expected 'frame_id' or 'timestamp', got {key!r}")
        mp = s.get("max_pending", 16)
        if not isinstance(mp, int) or isinstance(mp, bool) or mp < 1:
            raise _err(where, "sync.max_pending", f"expected a positive integer, got {mp!r}")
        return SyncConfig(ptp, tol, key, mp)

    @staticmethod
    def _camera(where: str, name: str, c: Mapping[str, Any], base: Path) -> CameraConfig:
        at = f"cameras.{name}"
        backend = c.get("backend")
        if not isinstance(backend, str) or not backend:
            raise _err(where, f"{at}.backend", f"expected a backend name, got {backend!r}")
        device = c.get("device") or {}
        if not isinstance(device, Mapping):
            raise _err(where, f"{at}.device", f"expected a mapping (id/serial/address), got {device!r}")
        pf = c.get("pixel_format", "RGB8")
        if pf not in PIXEL_FORMATS and pf not in SENSOR_FORMATS:
            raise _err(where, f"{at}.pixel_format", f"expected one of {list(dict.fromkeys([*PIXEL_FORMATS, *SENSOR_FORMATS]))}, got {pf!r}")
        size = {}
        for key in ("width", "height"):
            v = c.get(key)
            if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v <= 0):
                raise _err(where, f"{at}.{key}", f"expected a positive integer, got {v!r}")
            size[key] = v
        exposure = _number(where, f"{at}.exposure", c.get("exposure"), allow_none=True, low=EXPOSURE_US[0],
                           high=EXPOSURE_US[1])
        gain = _number(where, f"{at}.gain", c.get("gain"), positive=False, allow_none=True, low=GAIN_DB[0],
                       high=GAIN_DB[1])
        options = {k: v for k, v in c.items() if k not in _CAMERA_KEYS}
        for key, value in options.items():
            _check_option(where, at, key, value)
        for key in PATH_OPTIONS:
            if key in options and options[key] is not None:
                if not isinstance(options[key], (str, Path)):
                    raise _err(where, f"{at}.{key}", f"expected a path, got {options[key]!r}")
                options[key] = (base / options[key]).resolve()
        return CameraConfig(
            name, backend, dict(device), pf, size["width"], size["height"],
            None if exposure is None else float(exposure),
            None if gain is None else float(gain), options,
        )

    # -- derived -----------------------------------------------------------------------
    def with_overrides(self, **overrides: Any) -> RigDescription:
        """A copy with top-level fields (``name``, ``frame_rate``, ``calibration``) replaced
        and any other key set as a backend option of every camera (``source=DIR``,
        ``realtime=False``, ``jitter_ms=0.1``, ...). Camera fields (``exposure``, ``gain``,
        ``width``, ``height``, ``pixel_format``) are replaced on every camera."""
        top = {}
        cams = {n: c for n, c in self.cameras.items()}
        for key, value in overrides.items():
            if key in ("name", "frame_rate", "calibration"):
                if key == "frame_rate":
                    value = float(_number("override", key, value))
                if key == "calibration" and value is not None:
                    value = Path(value).resolve()
                top[key] = value
            elif key in ("exposure", "gain", "width", "height", "pixel_format"):
                cams = {n: replace(c, **{key: value}) for n, c in cams.items()}
                # re-validated like a file would be
                self.from_dict({"format": FORMAT, "version": VERSION, "frame_rate": self.frame_rate,
                                "cameras": {"override": {"backend": "x", key: value}}})
            elif key in ("trigger", "sync"):
                if not isinstance(value, (TriggerConfig, SyncConfig)):
                    raise _err("override", key, f"expected a {key.title()}Config, got {value!r}")
                top[key] = value
            else:
                _check_option("override", "cameras.*", key, value)
                if key in PATH_OPTIONS and value is not None:
                    value = Path(value).resolve()
                cams = {n: replace(c, options={**c.options, key: value}) for n, c in cams.items()}
        return replace(self, cameras=cams, **top)
