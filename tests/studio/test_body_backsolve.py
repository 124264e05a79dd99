"""The compiled back-substitution (studio.body.backsolve) against SciPy's SuperLU path."""

import numpy as np
import pytest

from studio.body import BodyModel, scape
from studio.body.backsolve import TriangularFactors


@pytest.fixture(scope="module")
def model():
    return BodyModel.load("female")


@pytest.mark.parametrize("n_bodies", [1, 3, 16])
def test_model_meshes_equal_the_superlu_path(model, n_bodies):
    """Posed float32 edges of random bodies: the same vertices as Gᵀ·E + SuperLU to 1e-12 m."""
    rng = np.random.default_rng(n_bodies)
    shapes = rng.normal(size=(n_bodies, model.n_shape)) * np.sqrt(model.eigenvalues)
    poses = model.clip_pose(rng.normal(size=(n_bodies, model.pose_size)) * 0.4)
    edges = model._posed_edges(shapes, poses)
    assert edges.dtype == np.float32
    ref = model._solver.solve_planar_reference(edges)
    new = model._solver.solve_planar(edges)
    assert new.shape == (n_bodies, model.n_vertices, 3)
    assert np.all(new[:, 0] == 0.0)
    assert np.abs(ref).max() > 0.5  # a body, metres from vertex 0
    np.testing.assert_allclose(new, ref, rtol=0, atol=1e-12)


def test_float64_edges_and_a_body_of_known_shape(model):
    """The rest mesh's own edges (float64) give the template back, vertex 0 at the origin."""
    T = model.template
    edges = np.transpose(scape.triangle_edges(T, model.faces), (1, 2, 0))[None]  # (1, 3, 2, F)
    y = model._solver.solve_planar(np.ascontiguousarray(edges))
    np.testing.assert_allclose(y[0], T - T[0], atol=1e-9)
    with pytest.raises(ValueError, match="planar"):
        model._solver.solve_planar(np.ascontiguousarray(np.transpose(edges, (0, 2, 1, 3))))


def test_factors_solve_any_number_of_columns(model):
    """K = 3 (the unrolled path) and K = 5 (the general one) equal SuperLU's solve."""
    lu = model._solver._lu
    f = TriangularFactors.from_superlu(lu)
    rng = np.random.default_rng(0)
    for k in (3, 5):
        rhs = rng.normal(size=(lu.shape[0], k))
        ref = lu.solve(rhs)
        assert np.abs(ref).max() > 10.0
        np.testing.assert_allclose(f.solve(rhs), ref, rtol=0, atol=1e-10)


def test_factors_refuse_a_non_unit_lower_factor():
    class Fake:
        import scipy.sparse as _sp

        L = _sp.csc_matrix(np.array([[2.0, 0.0], [1.0, 1.0]]))
        U = _sp.csc_matrix(np.eye(2))
        perm_r = perm_c = np.arange(2)

    with pytest.raises(ValueError, match="unit diagonal"):
        TriangularFactors.from_superlu(Fake())
