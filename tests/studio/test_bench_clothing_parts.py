"""benchmarks/clothing_parts.py: the per-region surface distance the clothing benchmark is split by."""

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

from clothing_parts import REGIONS, region_distances, region_faces  # noqa: E402

from studio.body import BodyModel  # noqa: E402
from studio.fit.evaluate import surface_distance  # noqa: E402


@pytest.fixture(scope="module")
def body():
    model = BodyModel.load("female")
    return model, model.vertices(model.mean_shape(), np.zeros(model.pose_size))


def test_regions_cover_every_face_once(body):
    model, _ = body
    sel = np.array(list(region_faces(model).values()))
    assert sel.shape == (len(REGIONS), len(model.faces))
    assert np.all(sel.sum(axis=0) == 1)


def test_moved_legs_show_in_the_legs_only(body):
    """The legs' vertices moved 5 cm forward: the legs' distance is centimetres, the head's and
    arms' stay at the sampling floor (the distance of a mesh to itself: 2.6 mm at 60,000 samples),
    and the whole figure is surface_distance's."""
    model, V = body
    legs = np.zeros(len(V), bool)
    legs[model.faces[region_faces(model)["legs"]].ravel()] = True
    moved = V.copy()
    moved[legs & (V[:, 2] < 0.6)] += [0.0, 0.05, 0.0]  # below the crotch (the seam stays put)
    floor = region_distances(V, V, model.faces, region_faces(model))
    assert all(0.001 < v < 0.004 for v in floor.values())
    d = region_distances(moved, V, model.faces, region_faces(model))
    assert abs(d["head"] - floor["head"]) < 0.0005 and abs(d["arms"] - floor["arms"]) < 0.0005
    assert 0.01 < d["legs"] < 0.05
    assert d["trunk"] < d["legs"] / 3
    whole = surface_distance(moved, model.faces, V, model.faces)
    assert d["whole"] == pytest.approx(whole, rel=0.15)
