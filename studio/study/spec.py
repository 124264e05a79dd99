"""A study description: the sessions of many participants and how to fit them (``STUDY.yaml``).

::

    format: studio.study
    version: 1
    output: results            # the study folder (relative to this file; `-o` overrides)
    fit:                       # for every session unless a session says otherwise
      gender: auto             # auto | female | male | neutral
      frames: "0:24:6"         # START:STOP[:STEP] or a comma list (default: every frame)
      seed: 0
      quick: false             # fewer particles and evaluations
    sessions:                  # capture-session folders, relative to this file
      - sessions/p01
      - {path: sessions/p02, participant: P02, gender: male, frames: "0:12"}

A participant's name (default: the session folder's name) names its folder in the study and its
row of ``study.csv``; names are unique.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["FORMAT", "FitSettings", "StudyError", "StudySession", "StudySpec", "load_study", "study_from_sessions"]

FORMAT = "studio.study"
VERSION = 1
GENDERS = ("auto", "female", "male", "neutral")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")


class StudyError(ValueError):
    """A study description or study folder that cannot be used; the message names the file and field."""


@dataclass(frozen=True)
class FitSettings:
    """How a session is fitted (the ``fit`` mapping; a session may override any field)."""

    gender: str = "auto"
    frames: str | None = None
    seed: int = 0
    quick: bool = False

    def to_dict(self) -> dict:
        return {"gender": self.gender, "frames": self.frames, "seed": self.seed, "quick": self.quick}


@dataclass(frozen=True)
class StudySession:
    participant: str
    path: Path
    fit: FitSettings


@dataclass(frozen=True)
class StudySpec:
    sessions: list[StudySession]
    output: Path | None = None
    source: Path | None = None  # the STUDY.yaml it came from
    fit: FitSettings = field(default_factory=FitSettings)


def _settings(raw, where: str, base: FitSettings) -> FitSettings:
    if raw is None:
        return base
    if not isinstance(raw, dict):
        raise StudyError(f"{where}: expected a mapping, got {type(raw).__name__}")
    unknown = sorted(set(raw) - {"gender", "frames", "seed", "quick", "path", "participant"})
    if unknown:
        raise StudyError(f"{where}: unknown field(s) {unknown} (expected gender, frames, seed, quick)")
    gender = raw.get("gender", base.gender)
    if gender not in GENDERS:
        raise StudyError(f"{where}: field 'gender': expected one of {', '.join(GENDERS)}, got {gender!r}")
    frames = raw.get("frames", base.frames)
    if frames is not None and not isinstance(frames, (str, int)):
        raise StudyError(f"{where}: field 'frames': expected START:STOP[:STEP] or a comma list, got {frames!r}")
    seed = raw.get("seed", base.seed)
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise StudyError(f"{where}: field 'seed': expected an integer, got {seed!r}")
    quick = raw.get("quick", base.quick)
    if not isinstance(quick, bool):
        raise StudyError(f"{where}: field 'quick': expected true or false, got {quick!r}")
    return FitSettings(gender, None if frames is None else str(frames), seed, quick)


def _participants(sessions: list[StudySession], where: str) -> list[StudySession]:
    seen: dict[str, Path] = {}
    for s in sessions:
        if not _NAME.match(s.participant):
            raise StudyError(f"{where}: participant {s.participant!r}: expected letters, digits, '.', '_' or '-' "
                             "(it names a folder and a row of study.csv)")
        if s.participant in seen:
            raise StudyError(f"{where}: participant {s.participant!r} named twice ({seen[s.participant]} and "
                             f"{s.path}); give one of them another `participant:`")
        seen[s.participant] = s.path
    if not sessions:
        raise StudyError(f"{where}: field 'sessions': expected at least one session")
    return sessions


def load_study(path: str | os.PathLike) -> StudySpec:
    """Read and check ``STUDY.yaml``; relative paths are taken from its folder."""
    import yaml

    path = Path(path)
    try:
        raw = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise StudyError(f"{path}: cannot read the study description ({exc.strerror or exc})") from None
    except yaml.YAMLError as exc:
        raise StudyError(f"{path}: not valid YAML ({exc})") from None
    if not isinstance(raw, dict):
        raise StudyError(f"{path}: expected a mapping with format: {FORMAT}")
    if raw.get("format") != FORMAT:
        raise StudyError(f"{path}: field 'format': expected {FORMAT!r}, got {raw.get('format')!r}")
    if raw.get("version") != VERSION:
        raise StudyError(f"{path}: field 'version': this toolkit reads version {VERSION}, got {raw.get('version')!r}")
    base = _settings(raw.get("fit"), f"{path}: field 'fit'", FitSettings())
    items = raw.get("sessions")
    if not isinstance(items, list):
        raise StudyError(f"{path}: field 'sessions': expected a list of session folders")
    sessions = []
    for k, item in enumerate(items):
        where = f"{path}: sessions[{k}]"
        entry = {"path": item} if isinstance(item, str) else item
        if not isinstance(entry, dict) or not isinstance(entry.get("path"), str):
            raise StudyError(f"{where}: expected a folder or a mapping with 'path', got {item!r}")
        folder = (path.parent / entry["path"]).resolve()
        name = str(entry.get("participant", folder.name))
        sessions.append(StudySession(name, folder, _settings(entry, where, base)))
    output = raw.get("output")
    if output is not None and not isinstance(output, str):
        raise StudyError(f"{path}: field 'output': expected a folder, got {output!r}")
    return StudySpec(_participants(sessions, str(path)), None if output is None else (path.parent / output).resolve(),
                     path.resolve(), base)


def study_from_sessions(folders, output, fit: FitSettings = FitSettings()) -> StudySpec:
    """A study of session ``folders`` (``studio study SESSION... -o STUDY``)."""
    sessions = [StudySession(Path(f).resolve().name, Path(f).resolve(), fit) for f in folders]
    return StudySpec(_participants(sessions, "studio study"), Path(output).resolve(), None, fit)
