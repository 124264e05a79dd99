"""The SCAPE body model learned from the open Anny population (thesis ch. 3).

Public API::

    from studio.body import BodyModel, measure
    model = BodyModel.load("female")          # numpy/scipy only, ~0.2 s
    v = model.vertices(shape, pose)           # (V, 3), metres, Z up, facing -y
    m = measure(model, shape)                 # stature, circumferences, mass, ...

The model files are built by ``studio model build`` (needs the ``model-build`` extra).
"""

from studio.body.cylinder import CylinderModel
from studio.body.inverse import shape_from_measurements
from studio.body.measure import (
    MEASUREMENT_NAMES,
    measure,
    measure_anny_body,
    measure_mesh,
    mesh_volume,
    slice_circumference,
)
from studio.body.meshio import read_ply, write_mesh
from studio.body.model import GENDERS, BodyModel, BodyModelError, anny_correspondence
from studio.body.skeleton import PART_NAMES, PART_PARENTS, POSE_SIZE

__all__ = [
    "BodyModel",
    "anny_correspondence",
    "BodyModelError",
    "CylinderModel",
    "GENDERS",
    "MEASUREMENT_NAMES",
    "PART_NAMES",
    "PART_PARENTS",
    "POSE_SIZE",
    "measure",
    "measure_anny_body",
    "measure_mesh",
    "mesh_volume",
    "read_ply",
    "shape_from_measurements",
    "slice_circumference",
    "write_mesh",
]
