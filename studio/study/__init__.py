"""Studies: many participants' sessions segmented, fitted and reported in one go (``studio study``).

- :func:`load_study` / :func:`study_from_sessions`: the study description (``STUDY.yaml``);
- :func:`run_study`: every session in turn, resumable, a failed session recorded while the rest
  go on; writes ``study.csv`` (:mod:`studio.study.table`) and the study report
  (:mod:`studio.study.report`).
"""

from studio.study.run import StudyLayout, run_study
from studio.study.spec import FitSettings, StudyError, StudySession, StudySpec, load_study, study_from_sessions

__all__ = ["FitSettings", "StudyError", "StudyLayout", "StudySession", "StudySpec", "load_study", "run_study",
           "study_from_sessions"]
