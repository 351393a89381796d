"""Quadrature-point operators (geoback.physics.plasticity.operators) and the unsymmetric factorisation
(geoback.physics.plasticity.linear) against the elastic FE model they adapt."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from geoback.physics.ground import plane_strain_isotropic
from geoback.physics.plasticity import mohr_coulomb as mc
from geoback.physics.plasticity.deep_tunnel import deep_tunnel_model
from geoback.physics.plasticity.linear import LU, Counters, SingularMatrix
from geoback.physics.plasticity.operators import PointOperators
from geoback.physics.solver import available_backends


@pytest.fixture(scope="module")
def model():
    fe = deep_tunnel_model(L=20.0, size_tunnel=0.25, size_far=4.0)
    return fe, PointOperators(fe)


def full(upper):
    return (upper + sp.triu(upper, k=1).T).tocsr()


def test_elastic_tangent_is_the_fe_stiffness(model):
    fe, ops = model
    E, nu = 3.0e4, 0.35
    K = ops.tangent(mc.elastic_matrix(mc.Material(E, nu, 1.0, 0.5, 0.0).at(ops.npts)))
    K_fe = full(fe.matrix(np.tile(plane_strain_isotropic(E, nu), (fe.ne, 1))))
    assert K.shape == K_fe.shape == (fe.nfree, fe.nfree)
    assert abs(K - K_fe).max() <= 1e-13 * abs(K_fe).max()
    # internal force of the elastic stress of a displacement is K u
    u = np.random.default_rng(0).normal(size=fe.nfree)
    D = mc.elastic_matrix(mc.Material(E, nu, 1.0, 0.5, 0.0).at(ops.npts))
    sigma = np.einsum("nij,nj->ni", D, ops.strain(u))
    assert np.linalg.norm(ops.internal_force(sigma) - K_fe @ u) <= 1e-12 * np.linalg.norm(K_fe @ u)


def test_strain_of_a_linear_field_and_point_coordinates(model):
    fe, ops = model
    a, b, c, d = 1e-3, -2e-3, 0.5e-3, 3e-3
    x, y = fe.nodes[:, 0], fe.nodes[:, 1]
    u = np.column_stack([a * x + b * y, c * x + d * y]).ravel()
    # fixed dofs are zero in the reduced vector: compare only points of elements without fixed dofs
    eps = ops.strain(u[fe.free]).reshape(fe.ne, ops.nq, 3)
    clean = ~fe.fixed[fe.edofs].any(axis=1)
    assert clean.sum() > 0.8 * fe.ne
    assert np.allclose(eps[clean], [a, d, b + c], rtol=0, atol=1e-14)
    xy = ops.point_coordinates()
    assert xy.shape == (ops.npts, 2)
    assert np.all(np.hypot(xy[:, 0], xy[:, 1] - fe.centre[1]) > fe.radius)
    # the weights integrate the area (the wall is a chain of quadratic arcs: not exactly the circle)
    assert ops.w.sum() == pytest.approx(fe.width * fe.depth - np.pi * fe.radius ** 2 / 2, rel=1e-7)


def test_per_point_shapes(model):
    fe, ops = model
    assert ops.per_point(2.0).shape == (ops.npts,)
    per_elem = np.arange(fe.ne, dtype=float)
    assert np.array_equal(ops.per_point(per_elem).reshape(fe.ne, ops.nq)[:, 0], per_elem)
    with pytest.raises(ValueError, match="per element"):
        ops.per_point(np.zeros(fe.ne + 1), "E")


@pytest.mark.parametrize("backend", available_backends())
def test_unsymmetric_solve_and_counters(model, backend):
    fe, ops = model
    mat = mc.Material(3.0e4, 0.35, 1.0, np.radians(30), 0.0)
    rng = np.random.default_rng(1)
    # an unsymmetric tangent: plastic returns at random states
    sigma_n = rng.normal(0, 30, (ops.npts, 4)) - 20
    deps = rng.normal(0, 1e-3, (ops.npts, 3))
    C = mc.consistent_tangent(sigma_n, deps, mat)
    C = 0.2 * C + 0.8 * mc.elastic_matrix(mat.at(ops.npts))  # keep it well conditioned
    K = ops.tangent(C)
    assert abs(K - K.T).max() > 1e-3 * abs(K).max()
    counters = Counters()
    lu = LU(counters, backend)
    b = rng.normal(size=(fe.nfree, 3))
    for scale in (1.0, 2.0):  # the second factorisation reuses PARDISO's analysis
        x = lu.factorise(K * scale).solve(b)
        assert np.linalg.norm(scale * (K @ x) - b) <= 1e-10 * np.linalg.norm(b)
    assert counters.factorisations == 2 and counters.backsubstitutions == 6
    lu.release()


def test_singular_matrix_is_reported():
    A = sp.csr_matrix(np.array([[1.0, 2.0], [2.0, 4.0]]))
    with pytest.raises(SingularMatrix):
        LU(Counters(), "scipy").factorise(A)
