"""The Anny truth recipes (the build itself needs torch + anny and runs at build time only)."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from studio.simulate import load_body, load_spec
from studio.body.anny_adapter import bone_part
from studio.simulate.truth_build import PART_NAMES, SEQUENCES, STATIC_POSES, build_truth, walk_pose

ROOT = Path(__file__).resolve().parents[2] / "studio" / "samples"


def test_bone_parts_cover_the_15_parts():
    bones = ["root", "pelvis.L", "spine03", "clavicle.R", "neck02", "head", "upperarm02.L",
             "lowerarm01.R", "wrist.L", "finger3-2.R", "upperleg01.R", "lowerleg02.L", "toe1-1.R",
             "foot.L", "upperarm01.R", "lowerarm02.L", "metacarpal1.R", "upperleg02.L",
             "lowerleg01.R", "foot.R"]
    assert {bone_part(b) for b in bones} == set(PART_NAMES)
    # the one map (the model's): the spine's lowest bone is pelvis, the lowest neck bone torso
    assert bone_part("spine05") == "pelvis" and bone_part("neck01") == "torso" and bone_part("neck02") == "head"


def test_walk_cycle_is_periodic_and_antisymmetric():
    p0, bob0 = walk_pose(0.0)
    p1, bob1 = walk_pose(1.0)
    for k in p0:
        np.testing.assert_allclose(p0[k], p1[k], atol=1e-9)
    q, _ = walk_pose(0.25)
    # at a quarter cycle the left hip flexes forward (negative about X) and the right extends
    assert q["upperleg01.L"][0] == pytest.approx(-math.radians(22.0))
    assert q["upperleg01.R"][0] == pytest.approx(math.radians(22.0))
    assert bob0 == pytest.approx(0.02)
    assert set(SEQUENCES["clothing_poses"]["poses"]) == set(STATIC_POSES)


def test_unknown_sequence_is_rejected(tmp_path):
    with pytest.raises(ValueError, match=r"unknown sequence\(s\) \['jog'\]"):
        build_truth(tmp_path, ["jog"])


@pytest.mark.parametrize("name", ["walk", "clothing_poses", "clothing_11", "mono_shadow"])
def test_sample_sequences_are_compact_and_plausible(name):
    spec = load_spec(ROOT / name / "spec.yaml")
    body = load_body(spec.body_path)
    assert body.vertices.shape[1:] == (13348, 3) and body.faces.shape == (26692, 3)
    meas = json.loads(str(body.extra["measurements"]))
    assert 1.5 < meas["stature"] < 2.0 and 45 < meas["mass"] < 110
    assert meas["waist_circumference"] < meas["hip_circumference"] < 1.3
    # feet on the floor in every frame, the person inside the capture volume
    np.testing.assert_allclose(body.vertices[..., 2].min(axis=1), 0.0, atol=2e-4)
    assert np.abs(body.vertices[..., :2]).max() < 1.5
    # per-frame heights close to stature (walking bends knees a little, clothing_11's lunge ~17 cm)
    tops = body.vertices[..., 2].max(axis=1)
    low = 0.2 if name == "clothing_11" else 0.15
    assert np.all(tops < meas["stature"] + 0.45) and np.all(tops > meas["stature"] - low)
    assert spec.body_path.stat().st_size < 3e6
