"""The frame objective with the shadow term (thesis eq. 5.7), re-derived term by term:

    E = Σ_k D(F^e_k, F^o_k) + w · (1/K) Σ_k D(S^e_k, S^o_k) + prior terms

with the model silhouettes from the reference rasteriser, the visible shadows from the exact
per-face shadow renderer less those silhouettes, and D from a freshly built target."""

import numpy as np
import pytest

import lightkit
from studio.body import BodyModel
from studio.cost import SilhouetteTarget, silhouette_cost
from studio.fit.objective import FrameObjective
from studio.fit.shadows import ShadowTerm
from studio.render import PointLight, silhouette
from studio.render.pyramid import level_camera
from studio.render.shadow import shadow_mask

LIGHTS = (PointLight([1.4, -1.1, 3.3]), PointLight([-1.2, -0.9, 2.9]))
WEIGHT = 2.5
LEVEL = 1


@pytest.fixture(scope="module")
def scene():
    model = BodyModel.load("female")
    cams = lightkit.cameras(size=(200, 150), focal=170.0, n=3)
    pose = model.default_pose()
    pose[:2] = [0.1, -0.1]
    V = model.vertices(model.mean_shape(), pose)
    labels = lightkit.labels(cams, (V, model.faces), list(LIGHTS))
    names = [c.name for c in cams]
    targets = {LEVEL: SilhouetteTarget.build([lab == 1 for lab in labels], level=LEVEL, names=names)}
    shadow = ShadowTerm.build(LIGHTS, cams, [lab == 2 for lab in labels], [LEVEL], weight=WEIGHT)
    obj = FrameObjective(model, cams, targets, model.mean_shape(), 0, shadow=shadow)
    moved = pose.copy()
    moved[:3] += [0.12, -0.08, 0.0]  # off the truth: every term is well above zero
    moved[5] += 0.3
    return model, cams, labels, obj, moved


def _expected(model, cams, labels, pose):
    """(silhouette, shadow per view) of ``pose`` computed without the objective. The shadow
    views are compared in each camera's ideal image (the cameras have lens distortion): the
    observed shadows and the body's silhouette undistorted, the shadow rendered by the ideal
    camera."""
    V = model.vertices(model.mean_shape(), pose)
    lcams = [level_camera(c, LEVEL) for c in cams]
    body = [silhouette(c, V, model.faces) for c in lcams]
    shadows = []
    for c, b in zip(lcams, body, strict=True):
        ideal = c.replace(dist=np.zeros(5))
        s = np.zeros_like(b)
        for light in LIGHTS:
            s |= shadow_mask(ideal, V, model.faces, light)
        shadows.append(s & ~c.undistort_image(b))
    names = [c.name for c in cams]
    sil = silhouette_cost(SilhouetteTarget.build([lab == 1 for lab in labels], level=LEVEL, names=names), body)
    observed = [c.undistort_image(lab == 2) for c, lab in zip(cams, labels, strict=True)]
    sha = silhouette_cost(SilhouetteTarget.build(observed, level=LEVEL, names=names), shadows)
    return sil.total, sha.per_view


def test_cost_is_silhouettes_plus_weighted_mean_of_shadow_views(scene):
    model, cams, labels, obj, moved = scene
    x = obj.pack(model.mean_shape(), moved)
    sil, shadow_views = _expected(model, cams, labels, moved)
    sp, lp = obj.priors(x[None])
    expected = sil + WEIGHT * shadow_views.mean() + sp[0] + lp[0]
    assert shadow_views.min() > 1.0 and sil > 1.0
    np.testing.assert_allclose(obj(x[None], LEVEL)[0], expected, rtol=1e-6)
    t = obj.terms(x, LEVEL)
    np.testing.assert_allclose(t["shadow"], WEIGHT * shadow_views.mean(), rtol=1e-6)
    assert list(t["shadow_per_view"]) == [c.name for c in cams]
    np.testing.assert_allclose(list(t["shadow_per_view"].values()), shadow_views, rtol=1e-6)
    assert t["shadow_weight"] == WEIGHT
    np.testing.assert_allclose(t["total"], expected, rtol=1e-6)
    np.testing.assert_allclose(t["total"], t["silhouette"] + t["shape_prior"] + t["pose_limits"] + t["shadow"],
                               rtol=1e-12)


def test_without_shadow_term_nothing_is_added(scene):
    model, cams, labels, obj, moved = scene
    plain = FrameObjective(model, cams, obj.targets, model.mean_shape(), 0)
    x = obj.pack(model.mean_shape(), moved)
    t = plain.terms(x, LEVEL)
    assert "shadow" not in t and "shadow_per_view" not in t
    sil, shadow_views = _expected(model, cams, labels, moved)
    np.testing.assert_allclose(plain(x[None], LEVEL)[0], sil + t["shape_prior"] + t["pose_limits"], rtol=1e-6)
    np.testing.assert_allclose(obj(x[None], LEVEL)[0] - plain(x[None], LEVEL)[0], WEIGHT * shadow_views.mean(),
                               rtol=1e-6)
