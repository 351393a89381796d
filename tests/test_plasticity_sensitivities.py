"""Direct differentiation of the incremental elastoplastic problem against central differences.

Deep tunnel (small mesh, 1.9 k DOFs), initial stress (K0 sv, sv, K0 sv, 0) with sv = -1000 kPa
and K0 = 0.9 (not axisymmetric), phi = 30 deg, psi = 10 deg (non-associated: unsymmetric tangent),
released to lambda_i = beta t_i with t = (0.85, 1), beta = 0.95: a real plastic zone at both stages,
so the second stage carries the history of the first.

Parameters: E, nu, c, phi, psi (material), K0 (initial stress and load), beta (release schedule).
Finite differences: central, step 1e-5 relative to the parameter, Newton tolerance 1e-13, replaying
the base run's schedule (the derivative is that of the discrete solution for a given schedule).
Measured differences at 1e-5: 1e-11 to 1e-9 for every parameter and stage. Steps of 1e-3 are too
large: quadrature points then change between elastic and plastic inside the interval and the
differences pick up O(h) kinks (measured: 2e-2 for phi, 1e-2 for beta, 4e-3 for K0 at stage 1).
"""
from __future__ import annotations

import numpy as np
import pytest

from geoback.physics.plasticity import Material, Options, ParameterDerivative, solve
from geoback.physics.plasticity.deep_tunnel import deep_tunnel_model
from geoback.physics.plasticity.operators import PointOperators

P0 = 1000.0
BASE = dict(E=1.0e5, nu=0.4, c=110.0, phi=np.radians(30.0), psi=np.radians(10.0), K0=0.9, beta=0.95)
T = np.array([0.85, 1.0])
STEP = 1e-5


def deep_tunnel_problem():
    """The mesh, its operators, inputs(p) -> (material, sigma0, f, stages) and the seven parameter derivatives."""
    fe = deep_tunnel_model(L=20.0, size_tunnel=0.25, size_far=4.0)
    ops = PointOperators(fe)
    sv = np.full(len(fe.wall_points), -P0)

    def inputs(p):
        mat = Material(p["E"], p["nu"], p["c"], p["phi"], p["psi"])
        sigma0 = np.array([-p["K0"] * P0, -P0, -p["K0"] * P0, 0.0])
        return mat, sigma0, fe.load(sv, p["K0"] * sv), p["beta"] * T

    derivs = [ParameterDerivative("E", E=1.0), ParameterDerivative("nu", nu=1.0), ParameterDerivative("c", c=1.0),
              ParameterDerivative("phi", phi=1.0), ParameterDerivative("psi", psi=1.0),
              ParameterDerivative("K0", sigma0=np.array([-P0, 0.0, -P0, 0.0]), f=fe.load(0 * sv, sv)),
              ParameterDerivative("beta", stages=T)]
    return fe, ops, inputs, derivs


@pytest.fixture(scope="module")
def problem():
    fe, ops, inputs, derivs = deep_tunnel_problem()
    base = solve(fe, *inputs(BASE), derivatives=derivs, options=Options(tol=1e-12), operators=ops)
    return fe, ops, inputs, base


def test_base_run_has_plastic_zones_and_counts(problem):
    fe, ops, inputs, base = problem
    assert base.du_dp.shape == (2, fe.nfree, 7) and base.names == ["E", "nu", "c", "phi", "psi", "K0", "beta"]
    assert base.plastic[0].sum() > 50 and base.plastic[1].sum() > base.plastic[0].sum()
    assert np.all(base.converged_residuals() <= 1e-12)
    # sensitivities are back-substitutions only: 7 columns per converged increment
    c = base.counters
    assert c.backsubstitutions == c.newton_iterations + 7 * c.increments
    assert c.factorisations <= c.newton_iterations + 1


@pytest.mark.parametrize("name", list(BASE))
def test_ddm_equals_central_differences(problem, name):
    fe, ops, inputs, base = problem
    j = base.names.index(name)
    h = STEP * abs(BASE[name])
    opts = Options(tol=1e-13, schedule=base.schedule)
    up, down = dict(BASE), dict(BASE)
    up[name] += h
    down[name] -= h
    r_up = solve(fe, *inputs(up), options=opts, operators=ops)
    r_down = solve(fe, *inputs(down), options=opts, operators=ops)
    fd = (r_up.u - r_down.u) / (2 * h)
    for k in range(len(T)):
        exact = base.du_dp[k, :, j]
        assert np.linalg.norm(exact) > 0
        assert np.linalg.norm(fd[k] - exact) <= 1e-5 * np.linalg.norm(exact), (name, k)
