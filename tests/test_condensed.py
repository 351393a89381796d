"""Factorise only what yields (plasticity/condensed.py): the elastic part condensed onto the region that
may yield gives the same solutions and sensitivities as whole factorisations, to rounding.

Deep tunnel (1.9 k DOFs: condensation is forced, it is automatic from condensed.CONDENSE_FROM unknowns
up), K0 = 0.9, phi = 30 deg, psi = 10 deg (unsymmetric tangent), two stages with a growing plastic
zone, seven parameters differentiated. Measured: solutions and sensitivities agree with whole
factorisations to 3e-13 (50 k DOFs, benchmarks/plastic_identification.py) and 1e-13 here.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

from geoback.physics.plasticity import Options, solve
from geoback.physics.solver import available_backends
from test_plasticity_sensitivities import BASE, T, deep_tunnel_problem

pytestmark = pytest.mark.skipif("pardiso" not in available_backends(), reason="condensation needs PARDISO")

WHOLE = Options(tol=1e-12, backend="pardiso", condense=False)
CONDENSED = replace(WHOLE, condense=True)


@pytest.fixture(scope="module")
def tunnel():
    return deep_tunnel_problem()


def _close(a, b, tol):
    return np.max(np.abs(a - b)) <= tol * np.max(np.abs(b))


def test_schur_complement_against_dense():
    from geoback.physics.plasticity.condensed import schur_complement

    rng = np.random.default_rng(4)
    n = 300
    M = sp.random(n, n, density=0.02, random_state=5)
    A = (M @ M.T + sp.eye(n) * 5.0).tocsr()
    last = np.zeros(n, bool)
    last[rng.choice(n, 25, replace=False)] = True
    S = schur_complement(sp.triu(A, format="csr"), last)
    D = A.toarray()
    i, g = ~last, last
    ref = D[np.ix_(g, g)] - D[np.ix_(g, i)] @ np.linalg.solve(D[np.ix_(i, i)], D[np.ix_(i, g)])
    assert S.shape == (25, 25)
    assert _close(S, ref, 1e-12)


def test_condensed_run_equals_whole_factorisations(tunnel):
    fe, ops, inputs, derivs = tunnel
    whole = solve(fe, *inputs(BASE), derivatives=derivs, options=WHOLE, operators=ops)
    cond = solve(fe, *inputs(BASE), derivatives=derivs, options=CONDENSED, operators=ops)
    assert whole.plastic[1].sum() > whole.plastic[0].sum() > 50
    assert _close(cond.u, whole.u, 1e-11)
    for j, name in enumerate(whole.names):
        assert _close(cond.du_dp[..., j], whole.du_dp[..., j], 1e-10), name
    c, w = cond.counters, whole.counters
    assert c.newton_iterations == w.newton_iterations and c.increments == w.increments
    assert c.condensations >= 1 and w.condensations == 0
    # each Newton step factorises the region that may yield, not the whole mesh
    assert c.factorised_unknowns / c.factorisations < 0.6 * w.factorised_unknowns / w.factorisations
    assert np.all(cond.converged_residuals() <= 1e-12)


def test_condensed_sensitivities_equal_central_differences(tunnel):
    fe, ops, inputs, derivs = tunnel
    base = solve(fe, *inputs(BASE), derivatives=derivs, options=CONDENSED, operators=ops)
    replay = replace(CONDENSED, tol=1e-13, schedule=base.schedule)
    for name in ("E", "phi", "K0", "beta"):
        j = base.names.index(name)
        h = 1e-5 * abs(BASE[name])
        up, down = dict(BASE), dict(BASE)
        up[name] += h
        down[name] -= h
        fd = (solve(fe, *inputs(up), options=replay, operators=ops).u
              - solve(fe, *inputs(down), options=replay, operators=ops).u) / (2 * h)
        for k in range(len(T)):
            exact = base.du_dp[k, :, j]
            assert np.linalg.norm(fd[k] - exact) <= 1e-6 * np.linalg.norm(exact), (name, k)


def test_region_kept_from_run_to_run_when_only_the_modulus_changes(tunnel):
    from geoback.physics.plasticity.condensed import Region

    fe, ops, inputs, derivs = tunnel
    region = Region(ops.element_dofs(), ops.nfree)
    first = solve(fe, *inputs(BASE), options=CONDENSED, operators=ops, region=region)
    assert first.counters.condensations >= 2  # it grew with the plastic zone
    yielded = first.yielded[-1].any(axis=1)
    assert region.mask[yielded].all() and region.mask.sum() < 0.8 * ops.ne
    stiffer = dict(BASE, E=1.07 * BASE["E"])
    again = solve(fe, *inputs(stiffer), options=CONDENSED, operators=ops, region=region, warm=first.warm)
    assert again.counters.condensations_reused == 1 and again.counters.condensations == 0
    whole = solve(fe, *inputs(stiffer), options=WHOLE, operators=ops)
    assert _close(again.u, whole.u, 1e-9)  # two Newton paths, each converged to 1e-12
    # Poisson's ratio changes K_e other than by a factor: condensed anew, on the region already known
    other = solve(fe, *inputs(dict(BASE, nu=0.35)), options=CONDENSED, operators=ops, region=region)
    assert other.counters.condensations_reused == 0 and other.counters.condensations == 1
    assert _close(other.u, solve(fe, *inputs(dict(BASE, nu=0.35)), options=WHOLE, operators=ops).u, 1e-9)
    region.release()


def test_condensation_needs_pardiso(tunnel):
    fe, ops, inputs, derivs = tunnel
    with pytest.raises(ValueError, match="PARDISO"):
        solve(fe, *inputs(BASE), options=replace(CONDENSED, backend="scipy"), operators=ops)


def test_factorisations_kept_from_run_to_run_analyse_a_pattern_once(tunnel):
    """A caller's region keeps the run's two factorisations: the tangents of every run share one pattern,
    so a later run analyses nothing (PARDISO; the condensed region's R, 0.7 k unknowns here, goes to SuperLU,
    which has no separate analysis), and gives what a run with factorisations of its own gives, to rounding."""
    from geoback.physics.plasticity.condensed import Region

    fe, ops, inputs, derivs = tunnel
    stiffer = dict(BASE, E=1.07 * BASE["E"])
    for options in (WHOLE, CONDENSED):
        region = Region(ops.element_dofs(), ops.nfree)
        first = solve(fe, *inputs(BASE), derivatives=derivs, options=options, operators=ops, region=region)
        again = solve(fe, *inputs(stiffer), derivatives=derivs, options=options, operators=ops, region=region)
        own = solve(fe, *inputs(stiffer), derivatives=derivs, options=options, operators=ops)
        if options is WHOLE:
            assert first.counters.analyses == own.counters.analyses == 2  # the two factorisations of a run
            assert again.counters.analyses == 0 and again.counters.factorisations > 10
        assert _close(again.u, own.u, 1e-12)
        assert _close(again.du_dp, own.du_dp, 1e-10)
        region.release()
        assert region._factors == ()  # freed


def test_a_factorisation_dropped_without_release_frees_pardiso_memory():
    """PARDISO's memory is MKL's: a factorisation kept from run to run and then dropped frees it."""
    import gc

    from geoback.physics.plasticity.linear import LU, Counters

    n = 50
    A = (sp.diags([4.0] * n) + sp.diags([-1.0] * (n - 1), 1) + sp.diags([-1.0] * (n - 1), -1)).tocsr()
    lu = LU(Counters(), "pardiso").factorise(A)
    assert np.allclose(A @ lu.solve(np.ones(n)), 1.0)
    freed, free = [], lu._solver.free_memory
    lu._solver.free_memory = lambda everything=False: (freed.append(everything), free(everything))
    del lu
    gc.collect()
    assert freed == [True]
