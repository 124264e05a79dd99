"""Measurement reports of fitted sessions: ``report/index.html``, ``measurements.json/.csv``."""

from studio.report.data import Participant
from studio.report.html import write_report
from studio.report.measurements import REPORTED, measurement_table, write_measurements
from studio.report.views import body_views

__all__ = ["Participant", "REPORTED", "body_views", "measurement_table", "write_measurements", "write_report"]
