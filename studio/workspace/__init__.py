"""The workspace: one owner of a session folder and of every output derived from it."""

from studio.workspace.layout import SEGMENTATION_RESERVED, Layout
from studio.workspace.workspace import Workspace, WorkspaceError, validate_calibration

__all__ = ["Layout", "SEGMENTATION_RESERVED", "Workspace", "WorkspaceError", "validate_calibration"]
