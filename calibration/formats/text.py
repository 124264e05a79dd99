"""Reading a calibration document (JSON, TOML, YAML, XML) with errors that name the file."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, Callable

import numpy as np

from calibration.errors import CalibrationError

__all__ = ["attr_float", "child", "parse_xml", "read_document"]


def read_document(path: Path, parse: Callable[[str], Any], kind: str, errors: tuple) -> Any:
    """``parse`` of the UTF-8 text of ``path``; unreadable files, other encodings, and the
    parser's ``errors`` (and too deep nesting) become one :class:`CalibrationError` naming the
    file and what was expected (``kind``: "JSON", "TOML", ...)."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as exc:
        raise CalibrationError(f"cannot read ({exc.strerror})", file=path) from None
    except UnicodeDecodeError as exc:
        raise CalibrationError(f"not UTF-8 text (byte {exc.start}): expected a UTF-8 {kind} file", file=path) from None
    try:
        return parse(text)
    except (*errors, RecursionError) as exc:
        reason = "nested too deeply" if isinstance(exc, RecursionError) else str(exc).replace("\n", " ")
        raise CalibrationError(f"not valid {kind} ({reason})", file=path) from None


def parse_xml(path: Path, kind: str = "XML"):
    """The root element of the XML file ``path``."""
    try:
        return ET.parse(path).getroot()
    except OSError as exc:
        raise CalibrationError(f"cannot read ({exc.strerror})", file=path) from None
    except ET.ParseError as exc:
        raise CalibrationError(f"not valid {kind} ({exc})", file=path) from None


def attr_float(elem, attr: str, cam: str, field: str) -> float:
    """The finite number of attribute ``attr`` of ``elem``; errors name the camera and ``field.attr``."""
    value = elem.get(attr)
    if value is None:
        raise CalibrationError("missing", camera=cam, field=f"{field}.{attr}")
    try:
        number = float(value)
    except ValueError:
        raise CalibrationError(f"not a number: {value!r}", camera=cam, field=f"{field}.{attr}") from None
    if not np.isfinite(number):
        raise CalibrationError(f"expected a finite number, got {value!r}", camera=cam, field=f"{field}.{attr}")
    return number


def child(elem, tag: str, cam: str):
    """The ``tag`` child of ``elem``, or an error naming the camera and the tag."""
    found = elem.find(tag)
    if found is None:
        raise CalibrationError("missing", camera=cam, field=tag)
    return found
