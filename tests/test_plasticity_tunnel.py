"""The incremental elastoplastic solution (geoback.physics.plasticity.incremental) on real gmsh meshes.

* deep circular tunnel under hydrostatic stress against the closed form (Salencon 1969;
  Carranza-Torres & Fairhurst 2000): plastic radius and wall displacement within 2 %, associated
  and non-associated flow, at full and partial release;
* a huge cohesion reproduces the linear-elastic FE model (fem.matrix + solver.Factorisation);
* every converged increment meets the residual tolerance; results do not depend on the increments;
* failures are reported with the increment, lambda and the residual; bad inputs are refused.
"""
from __future__ import annotations

import numpy as np
import pytest

from geoback.physics.ground import plane_strain_isotropic
from geoback.physics.plasticity import DeepTunnelMC, Material, NonConvergence, Options, solve
from geoback.physics.plasticity.deep_tunnel import deep_tunnel_model, hydrostatic_load, measure
from geoback.physics.plasticity.operators import PointOperators
from geoback.physics.solver import Factorisation

P0, E, NU, C, PHI = 1000.0, 1.0e5, 0.4, 110.0, 30.0  # R_p = 1.768 R at full release


@pytest.fixture(scope="module")
def deep():
    """L = 50 R, wall elements R/10 growing by 0.2 per unit distance (5.7 k DOFs)."""
    fe = deep_tunnel_model(L=50.0, size_tunnel=0.1, growth=0.2)
    return fe, PointOperators(fe)


@pytest.fixture(scope="module")
def small():
    """L = 20 R, wall elements R/4 (1.9 k DOFs)."""
    fe = deep_tunnel_model(L=20.0, size_tunnel=0.25, size_far=4.0)
    return fe, PointOperators(fe)


@pytest.mark.parametrize("psi", [0.0, 10.0, 30.0])
def test_deep_tunnel_against_the_closed_form(deep, psi):
    fe, ops = deep
    sigma0, f = hydrostatic_load(fe, P0)
    stages = (0.9, 1.0)
    res = solve(fe, Material.from_degrees(E, NU, C, PHI, psi), sigma0, f, stages, operators=ops)
    assert np.all(res.converged_residuals() <= res.tol)
    xy = ops.point_coordinates()
    for k, lam in enumerate(stages):
        cf = DeepTunnelMC.released(P0, fe.radius, E, NU, C, np.radians(PHI), np.radians(psi), lam)
        assert cf.plastic and cf.out_of_plane_is_intermediate()
        m = measure(fe, xy, res.sigma[k].reshape(-1, 4), res.plastic[k], res.u[k], cf.critical_pressure)
        assert m.plastic_radius == pytest.approx(cf.plastic_radius, rel=0.02)
        assert m.wall_displacement == pytest.approx(cf.wall_displacement, rel=0.02)
        assert abs(m.outermost_yielded - cf.plastic_radius) <= 0.15 * cf.plastic_radius  # ~ element size there
        # nothing yields far outside the closed-form plastic zone
        r = np.hypot(xy[:, 0], xy[:, 1] - fe.centre[1])
        assert not res.yielded[k].reshape(-1)[r > 1.2 * cf.plastic_radius].any()


def test_huge_cohesion_is_the_linear_elastic_model(small):
    fe, ops = small
    sigma0, f = hydrostatic_load(fe, P0)
    stages = (0.5, 1.0)
    res = solve(fe, Material.from_degrees(E, NU, 1e12, PHI, 0.0), sigma0, f, stages, operators=ops)
    assert not res.yielded.any()
    K = fe.matrix(np.tile(plane_strain_isotropic(E, NU), (fe.ne, 1)))
    u_el = Factorisation(K).solve(f)
    for k, lam in enumerate(stages):
        assert np.linalg.norm(res.u[k] - lam * u_el) <= 1e-10 * np.linalg.norm(lam * u_el)
    # one factorisation served every elastic increment
    assert res.counters.factorisations == 1


def _uniform(n):
    return (tuple(np.linspace(0.0, 1.0, n + 1)[1:]),)


def test_results_do_not_depend_on_the_increments(small):
    fe, ops = small
    sigma0, f = hydrostatic_load(fe, P0)
    mat = Material.from_degrees(E, NU, C, PHI, 10.0)
    runs = {name: solve(fe, mat, sigma0, f, [1.0], options=Options(schedule=sched), operators=ops)
            for name, sched in (("5", _uniform(5)), ("20", _uniform(20)), ("adaptive", None))}
    # the fixed schedules' ends are used, the elastic span before yielding in one increment (exact: linear)
    for n in (5, 20):
        used = runs[str(n)].schedule[0]
        assert set(used) <= set(_uniform(n)[0]) and used[-1] == 1.0
        assert runs[str(n)].counters.increments == len(used) < n
    assert runs["20"].counters.increments > 2 * runs["5"].counters.increments
    ref = runs["20"].u[0]
    for name, res in runs.items():
        assert np.all(res.converged_residuals() <= res.tol), name
        assert np.linalg.norm(res.u[0] - ref) <= 5e-3 * np.linalg.norm(ref), name
        assert res.yielded[0].sum() == pytest.approx(runs["20"].yielded[0].sum(), rel=0.05), name
    # replaying the adaptive schedule gives the same result to the Newton tolerance
    replay = solve(fe, mat, sigma0, f, [1.0], options=Options(schedule=runs["adaptive"].schedule), operators=ops)
    assert np.linalg.norm(replay.u[0] - runs["adaptive"].u[0]) <= 1e-9 * np.linalg.norm(ref)


def test_non_convergence_is_reported(small):
    fe, ops = small
    sigma0, f = hydrostatic_load(fe, P0)
    mat = Material.from_degrees(E, NU, C, PHI, 0.0)
    # one Newton iteration cannot converge a plastic increment: cut back to the minimum, then fail
    with pytest.raises(NonConvergence) as info:
        solve(fe, mat, sigma0, f, [1.0], options=Options(max_iterations=1, min_increment=0.01), operators=ops)
    err = info.value
    assert 0 < err.lam < 1 and err.residual > 1e-10 and err.increment >= 1
    text = str(err)
    assert f"increment {err.increment}" in text and "lambda" in text and "relative residual" in text
    # a fixed schedule is not cut back
    with pytest.raises(NonConvergence, match="fixed schedule"):
        solve(fe, mat, sigma0, f, [1.0], options=Options(max_iterations=2, schedule=_uniform(2)), operators=ops)
    # nor may the run exceed its budget of Newton attempts
    with pytest.raises(NonConvergence, match="budget"):
        solve(fe, mat, sigma0, f, [1.0], options=Options(max_increments=3), operators=ops)


def test_bad_inputs_are_refused(small):
    fe, ops = small
    sigma0, f = hydrostatic_load(fe, P0)
    mat = Material.from_degrees(E, NU, C, PHI, 0.0)
    with pytest.raises(ValueError, match="yield"):
        solve(fe, mat, np.array([-P0, 0.0, -P0, 0.0]), f, [1.0], operators=ops)  # far outside yield
    with pytest.raises(ValueError, match="increasing"):
        solve(fe, mat, sigma0, f, [1.0, 0.5], operators=ops)
    with pytest.raises(ValueError, match="f"):
        solve(fe, mat, sigma0, f[:-1], [1.0], operators=ops)
    with pytest.raises(ValueError, match="per element"):
        solve(fe, Material.from_degrees(np.ones(3), NU, C, PHI, 0.0), sigma0, f, [1.0], operators=ops)


def test_per_element_and_per_point_inputs(small):
    """Material per element or per quadrature point, and sigma0 per point, give the scalar run."""
    fe, ops = small
    sigma0, f = hydrostatic_load(fe, P0)
    mat = Material.from_degrees(E, NU, C, PHI, 10.0)
    opts = Options(schedule=((0.5, 0.8, 1.0),))
    ref = solve(fe, mat, sigma0, f, [1.0], options=opts, operators=ops)
    per_elem = Material(*(np.full(fe.ne, v) for v in mat.values()))
    per_point = Material(*(np.full((fe.ne, ops.nq), v) for v in mat.values()))
    for m, s0 in ((per_elem, sigma0), (per_point, np.tile(sigma0, (fe.ne, ops.nq, 1)))):
        res = solve(fe, m, s0, f, [1.0], options=opts, operators=ops)
        assert np.array_equal(res.u, ref.u) and np.array_equal(res.plastic, ref.plastic)
    assert ref.plastic.any()
