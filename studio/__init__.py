"""Silhouette & Shadow Studio: analysis layer (segmentation, body model, fitting, reports)."""

__version__ = "0.1.0"
