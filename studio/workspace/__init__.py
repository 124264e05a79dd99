"""The workspace: one owner of a session folder and of every output derived from it."""

from studio.workspace.layout import SEGMENTATION_RESERVED, Layout

__all__ = ["Layout", "SEGMENTATION_RESERVED"]
