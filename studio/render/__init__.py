"""Rendering: silhouettes, shadow meshes and synthetic colour frames of meshes in cameras.

The silhouette path (:func:`silhouette`, :func:`shadow_mask`) is numpy-only and exact;
the fitter, which calls it thousands of times, uses :func:`silhouettes_contour` (fills the
projected occluding contour row by row, compiled with numba: same masks, ~0.5 ms per view); the colour path (:func:`rasterize` +
:func:`shade_raster`) adds a z-buffer, barycentric interpolation and Lambertian shading.
"""

from studio.render.lights import DirectionalLight, PointLight, light_from_dict
from studio.render.raster import (
    MAX_SMALL_BBOX,
    Raster,
    front_facing,
    project_vertices,
    rasterize,
    silhouette,
    silhouettes,
)
from studio.render.shade import lambert, shade_raster, vertex_normals
from studio.render.shadow import shadow_mask, shadow_outline, shadow_silhouettes, shadow_vertices
from studio.render.solids import cylinder_mesh
from studio.render.spans import silhouettes_contour, silhouettes_fast

__all__ = [
    "DirectionalLight",
    "cylinder_mesh",
    "MAX_SMALL_BBOX",
    "PointLight",
    "Raster",
    "front_facing",
    "lambert",
    "light_from_dict",
    "project_vertices",
    "rasterize",
    "shade_raster",
    "shadow_mask",
    "shadow_outline",
    "shadow_silhouettes",
    "shadow_vertices",
    "silhouette",
    "silhouettes",
    "silhouettes_contour",
    "silhouettes_fast",
    "vertex_normals",
]
