"""``frames.csv`` and ``session.json``: the index of complete frames and the session header, read tolerantly."""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rigs.session.checks import _check_cameras
from rigs.session.layout import FRAMES_CSV, SESSION_FORMAT, SESSION_JSON, SESSION_VERSION, SessionError


def csv_header(cameras: list[str]) -> list[str]:
    """Column names of ``frames.csv`` for ``cameras`` (see the module docstring)."""
    cols = ["index"]
    for cam in cameras:
        cols += [f"{cam}.timestamp_ns", f"{cam}.frame_id", f"{cam}.flag"]
    return cols


@dataclass(frozen=True)
class _Row:
    line: int
    timestamps_ns: dict
    frame_ids: dict
    flags: dict


def _parse_major(version: Any, path: Path) -> int:
    if isinstance(version, int) and not isinstance(version, bool):
        return version
    if isinstance(version, str) and re.match(r"^\d+(\.\d+)*$", version):
        return int(version.split(".")[0])
    raise SessionError(f"{path}: field 'version' is {version!r}, expected an integer such as {SESSION_VERSION}")


def _read_info(path: Path) -> dict:
    file = path / SESSION_JSON
    try:
        text = file.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SessionError(
            f"{path}: not a capture session ({SESSION_JSON} missing; expected a folder written "
            "by rigs.SessionWriter)"
        ) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SessionError(f"{file}: cannot read ({exc})") from exc
    try:
        info = json.loads(text)
    except ValueError as exc:
        raise SessionError(f"{file}: not valid JSON ({exc})") from exc
    if not isinstance(info, dict):
        raise SessionError(f"{file}: expected a JSON object, got {type(info).__name__}")
    if info.get("format") != SESSION_FORMAT:
        raise SessionError(f"{file}: field 'format' is {info.get('format')!r}, expected {SESSION_FORMAT!r}")
    major = _parse_major(info.get("version"), file)
    if major != SESSION_VERSION:
        raise SessionError(
            f"{file}: field 'version' is {info.get('version')!r}; this reader understands major "
            f"version {SESSION_VERSION} only (a newer toolkit wrote it?)"
        )
    try:
        _check_cameras(info.get("cameras"))
    except SessionError as exc:
        raise SessionError(f"{file}: field {exc}") from None
    fps = info.get("fps")
    if fps is not None and (isinstance(fps, bool) or not isinstance(fps, (int, float)) or fps <= 0):
        raise SessionError(f"{file}: field 'fps' is {fps!r}, expected a positive number or null")
    images = info.get("images", {})
    if not isinstance(images, dict):
        raise SessionError(f"{file}: field 'images' is {images!r}, expected an object")
    for cam, spec in images.items():
        keys = {"width", "height", "channels", "dtype"}
        if not isinstance(spec, dict) or not keys <= set(spec):
            raise SessionError(f"{file}: field 'images.{cam}' is {spec!r}, expected keys {sorted(keys)}")
    return info


def _parse_optional_int(text: str) -> int | None:
    return None if text == "" else int(text)


def _read_frames_csv(file: Path, cameras: list[str]) -> tuple[dict[int, _Row], list[str]]:
    try:
        data = file.read_bytes()
    except FileNotFoundError:
        raise SessionError(f"{file}: missing (every session has a {FRAMES_CSV} with a header line)") from None
    header = csv_header(cameras)
    lines = data.split(b"\n")
    got_header = lines[0].decode("utf-8", "replace").rstrip("\r").split(",")
    if len(lines) < 2 or got_header != header:
        raise SessionError(
            f"{file}: header is {got_header}, expected {header} (columns for cameras {cameras} of {SESSION_JSON})"
        )
    rows: dict[int, _Row] = {}
    issues: list[str] = []
    tail = lines[-1]
    body = lines[1:-1]
    if tail:
        shown = tail[:60].decode("utf-8", "replace")
        issues.append(
            f"{FRAMES_CSV} line {len(lines)}: last line has no newline (torn write, ignored): {shown!r}"
        )
    for number, raw in enumerate(body, start=2):
        try:
            text = raw.decode("utf-8").rstrip("\r")
        except UnicodeDecodeError:
            issues.append(f"{FRAMES_CSV} line {number}: not UTF-8 text (ignored)")
            continue
        fields = text.split(",")
        if len(fields) != len(header):
            issues.append(
                f"{FRAMES_CSV} line {number}: {len(fields)} fields, expected {len(header)} (ignored)"
            )
            continue
        try:
            index = int(fields[0])
            if index < 0:
                raise ValueError
        except ValueError:
            issues.append(
                f"{FRAMES_CSV} line {number}: field 'index' is {fields[0][:20]!r}, expected a "
                "non-negative integer (ignored)"
            )
            continue
        ts, ids, flags = {}, {}, {}
        bad = None
        for k, cam in enumerate(cameras):
            t, fid, flag = fields[1 + 3 * k : 4 + 3 * k]
            for col, value, target in ((f"{cam}.timestamp_ns", t, ts), (f"{cam}.frame_id", fid, ids)):
                try:
                    target[cam] = _parse_optional_int(value)
                except ValueError:
                    bad = f"field '{col}' is {value[:20]!r}, expected an integer or empty"
            flags[cam] = flag
        if bad:
            issues.append(f"{FRAMES_CSV} line {number}: {bad} (ignored)")
            continue
        if index in rows:
            issues.append(
                f"{FRAMES_CSV} line {number}: duplicate row for frame {index} "
                f"(line {rows[index].line} kept)"
            )
            continue
        rows[index] = _Row(number, ts, ids, flags)
    return rows, issues
