"""Running a study: segment → fit → report for every session, one after the other, each session's
frames fanned out over the runner (:mod:`studio.execution`).

The study folder::

    study.json                   what happened to each participant (status, reason, settings, time)
    study.csv                    one row per participant (:mod:`studio.study.table`)
    report/index.html            the study report (:mod:`studio.study.report`)
    sessions/<participant>/      that session's segmentation/, fit/ and report/ (the capture
                                 itself is only read, so sessions may be read-only)

Resumable: a participant done before with the same settings is skipped; a session interrupted
half-way continues where it stopped (``segment`` and ``fit`` keep their finished frames). A
session that fails is recorded with its reason and the study goes on with the next.
"""

from __future__ import annotations

import json
import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from studio.study.spec import StudyError, StudySession, StudySpec

__all__ = ["StudyLayout", "run_study"]

log = logging.getLogger(__name__)

STATE_FORMAT = "studio.study-state"


@dataclass(frozen=True)
class StudyLayout:
    """Where a study's files live (pure: nothing is read or created)."""

    root: Path

    @property
    def state(self) -> Path:
        return self.root / "study.json"

    @property
    def csv(self) -> Path:
        return self.root / "study.csv"

    @property
    def report_html(self) -> Path:
        return self.root / "report" / "index.html"

    def session_dir(self, participant: str) -> Path:
        return self.root / "sessions" / participant


def load_state(layout: StudyLayout) -> dict:
    """``study.json`` by participant ({} for a new study)."""
    try:
        obj = json.loads(layout.state.read_text())
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as exc:
        raise StudyError(f"{layout.state}: unreadable study state ({exc}); remove it to start the study afresh") from None
    if obj.get("format") != STATE_FORMAT:
        raise StudyError(f"{layout.state}: field 'format': expected {STATE_FORMAT!r}, got {obj.get('format')!r}")
    return obj.get("participants", {})


def _run_session(s: StudySession, folder: Path, *, workers: int, scheduler, options, progress) -> None:
    from studio.cli.commands.fit import QUICK
    from studio.fit import FitOptions, fit_session
    from studio.report import write_report
    from studio.segment import SegmentOptions, segment_session
    from studio.workspace import Workspace
    from studio.workspace.frames import select_frames

    ws = Workspace.open(s.path, out=folder)
    frames = select_frames(s.fit.frames, ws.frame_indices)

    def stage(name):
        return None if progress is None else (lambda d, n: progress(s.participant, name, d, n))

    segment_session(ws, SegmentOptions(), frames=frames, workers=workers, scheduler=scheduler,
                    progress=stage("segment"))
    if options is None:
        options = FitOptions(**QUICK) if s.fit.quick else FitOptions()
    fit_session(ws, frames=frames, gender=s.fit.gender, workers=workers, scheduler=scheduler, options=options,
                seed=s.fit.seed, progress=stage("fit"))
    if progress:
        progress(s.participant, "report", 0, 1)
    write_report(ws)


def run_study(spec: StudySpec, *, output=None, workers: int = 1, scheduler: str | None = None, options=None,
              force: bool = False, progress: Callable[[str, str, int, int], None] | None = None) -> dict:
    """Run every session of ``spec``; write ``study.json``, ``study.csv`` and the study report
    into ``output`` (default ``spec.output``). Returns ``study.json``'s participants mapping.

    ``workers`` / ``scheduler`` as for :func:`studio.fit.fit_session` (``local:N`` starts one
    cluster for the whole study); ``options`` a :class:`~studio.fit.FitOptions` for every session
    (default: by each session's ``quick``); ``force`` runs sessions done before again (their
    finished frames are still kept: ``segment``/``fit`` redo only what changed). ``progress(participant,
    stage, done, total)`` with stage ``segment``, ``fit``, ``report`` or ``done`` / ``failed`` / ``kept``.
    """
    from rigs.atomic import atomic_write_json
    from studio.execution import shared_scheduler
    from studio.study.report import write_study_report
    from studio.study.table import write_study_csv

    root = output if output is not None else spec.output
    if root is None:
        raise StudyError("no study folder: give -o STUDY (or `output:` in the study description)")
    layout = StudyLayout(Path(root).resolve())
    try:
        layout.root.mkdir(parents=True, exist_ok=True)
        (layout.root / "sessions").mkdir(exist_ok=True)
    except OSError as exc:
        raise StudyError(f"{layout.root}: cannot write the study there ({exc.strerror or exc})") from None
    state = load_state(layout)

    def save():
        atomic_write_json(layout.state, {"format": STATE_FORMAT, "version": 1,
                                         "source": None if spec.source is None else str(spec.source),
                                         "participants": state})

    with shared_scheduler(scheduler) as address:
        for s in spec.sessions:
            settings = {"session": str(s.path), **s.fit.to_dict()}
            folder = layout.session_dir(s.participant)
            before = state.get(s.participant) or {}
            if (not force and before.get("status") == "done" and before.get("settings") == settings
                    and (folder / "report" / "measurements.json").is_file()):
                log.info("%s: done before with the same settings: kept", s.participant)
                if progress:
                    progress(s.participant, "kept", 1, 1)
                continue
            t0 = time.perf_counter()
            try:
                _run_session(s, folder, workers=workers, scheduler=address, options=options, progress=progress)
            except Exception as exc:  # noqa: BLE001 - one session's failure is recorded; the study goes on
                reason = str(exc) or type(exc).__name__
                log.warning("%s: failed: %s", s.participant, reason)
                state[s.participant] = {"status": "failed", "reason": reason, "settings": settings,
                                        "seconds": round(time.perf_counter() - t0, 3)}
                if progress:
                    progress(s.participant, "failed", 1, 1)
            else:
                state[s.participant] = {"status": "done", "reason": None, "settings": settings,
                                        "seconds": round(time.perf_counter() - t0, 3)}
                if progress:
                    progress(s.participant, "done", 1, 1)
            save()
    save()
    rows = write_study_csv(layout, spec, state)
    write_study_report(layout, spec, rows)
    return state
