"""Eqn 55 in one place (geoback.inference.linear_analysis.LinearAnalysis):

- the posterior covariance C_p = (A'^t A' + C_p0^-1)^-1 against a dense inverse on a well-conditioned
  problem whose parameters span decades, from rows and from an information matrix; the conditional
  posterior (a candidate's whitened rows added) against stacking the rows and against a dense
  inverse; the prediction variance g^t C_p g;
- rank deficiency: infinite std for the parameters and predictions an undetermined combination
  reaches (as the reliability measures always reported it), finite for the rest;
- Monte Carlo: the sample covariance of least-squares estimates of a linear model approaches C_p;
- the four call paths that once computed eqn 55 each their own way (the reliability measures,
  Monte Carlo replicates, the prior -> posterior table, the design's posterior with a candidate)
  agree with each other and with a dense inverse on the shipped staged case.
"""
from __future__ import annotations

import numpy as np
import pytest

from conftest import CASES
from geoback.case.loading import load_case
from geoback.inference.identification import identify, identify_replicates, prepare
from geoback.inference.linear_analysis import LinearAnalysis

pytestmark = pytest.mark.quick


def _problem(seed: int = 0, m: int = 40):
    """Whitened rows A' of 4 parameters spanning eight decades (a modulus beside ratios), a prior on one."""
    rng = np.random.default_rng(seed)
    units = np.array([1e4, 1.0, 0.3, 1e-3])  # typical parameter magnitudes
    A = rng.standard_normal((m, 4)) / units
    prec = np.array([0.0, 0.0, 1 / 0.2 ** 2, 0.0])
    return A, prec, units


def _dense(M):
    """A direct inverse, equilibrated only to keep the dense reference itself accurate."""
    d = 1 / np.sqrt(np.diag(M))
    return np.linalg.inv(M * np.outer(d, d)) * np.outer(d, d)


def test_posterior_is_the_inverse_information():
    A, prec, units = _problem()
    info = A.T @ A + np.diag(prec)
    direct = _dense(info)
    rows = LinearAnalysis.from_rows(A, prec, units)
    default = LinearAnalysis.from_rows(A, prec)  # the rows' own column scaling
    eig = LinearAnalysis.from_information(info)
    for la in (rows, default, eig):
        np.testing.assert_allclose(la.covariance, direct, rtol=1e-12, atol=0)
        np.testing.assert_allclose(la.std, np.sqrt(np.diag(direct)), rtol=1e-12)
        assert not la.undetermined.any()
    # predictions q = G p: C_q = G C_p G^t, var q_i = g_i^t C_p g_i
    G = np.random.default_rng(1).standard_normal((5, 4)) * units
    np.testing.assert_allclose(rows.prediction_covariance(G), G @ direct @ G.T, rtol=1e-11)
    np.testing.assert_allclose(rows.prediction_variance(G), np.diag(G @ direct @ G.T), rtol=1e-11)
    np.testing.assert_allclose(eig.prediction_std(G), np.sqrt(np.diag(G @ direct @ G.T)), rtol=1e-11)
    # the analysis is a frozen value: read-only arrays
    with pytest.raises(ValueError):
        rows.covariance[0, 0] = 0.0
    with pytest.raises(AttributeError):
        rows.scale = units


def test_conditional_posterior_adds_the_candidate_rows():
    """Data worth: C_p,c = (A'^t A' + C_p0^-1 + A_c'^t A_c')^-1, the same from rows or information."""
    A, prec, units = _problem()
    Ac = np.random.default_rng(2).standard_normal((6, 4)) / units * 3
    direct = _dense(A.T @ A + np.diag(prec) + Ac.T @ Ac)
    rows = LinearAnalysis.from_rows(A, prec, units)
    eig = LinearAnalysis.from_information(A.T @ A + np.diag(prec))
    stacked = LinearAnalysis.from_rows(np.vstack([A, Ac]), prec, units)
    for la in (rows.conditional(Ac), eig.conditional(Ac)):
        np.testing.assert_allclose(la.covariance, direct, rtol=1e-12)
        assert np.all(la.std < rows.std)
    np.testing.assert_allclose(rows.conditional(Ac).covariance, stacked.covariance, rtol=1e-13)
    np.testing.assert_array_equal(rows.conditional(Ac).scale, rows.scale)  # equilibrated once


def test_undetermined_combination_has_infinite_std_and_reaches_predictions():
    """Two parameters seen only through their sum (K = E k with E and a load factor, say)."""
    rng = np.random.default_rng(3)
    a = rng.standard_normal((30, 1))
    A = np.hstack([a, a, rng.standard_normal((30, 1))])
    p = np.array([1.0, 1.0, 1.0])
    for la in (LinearAnalysis.from_rows(A, np.zeros(3), p), LinearAnalysis.from_information(A.T @ A)):
        assert la.undetermined.sum() == 1
        np.testing.assert_allclose(np.abs(la.undetermined_directions[0]), [2 ** -0.5, 2 ** -0.5, 0], atol=1e-8)
        assert np.isinf(la.std[:2]).all() and np.isfinite(la.std[2])
        G = np.array([[1.0, 1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 0.0, 2.0]])  # sum, difference, third
        v = la.prediction_variance(G)
        assert np.isfinite(v[0]) and np.isinf(v[1]) and np.isfinite(v[2])
        reduced = np.linalg.inv(A[:, 1:].T @ A[:, 1:])  # the sum p1 + p2 as one parameter, and p3
        assert v[0] == pytest.approx(reduced[0, 0], rel=1e-9) and v[2] == pytest.approx(4 * reduced[1, 1], rel=1e-9)
        # a prior on one of the two determines both
        fixed = la.conditional(np.array([[0.0, 10.0, 0.0]]))
        assert not fixed.undetermined.any() and np.isfinite(fixed.std).all()


def test_monte_carlo_covariance_of_least_squares_estimates():
    """x = A p + e, e ~ N(0, I) (whitened): the estimates' sample covariance approaches C_p (eqn 55)."""
    A, _, units = _problem(seed=4, m=25)
    rng = np.random.default_rng(5)
    N = 4000
    E = rng.standard_normal((N, A.shape[0]))
    P = np.linalg.lstsq(A, E.T, rcond=None)[0].T  # estimates of p = 0 from each noisy data set
    C = LinearAnalysis.from_rows(A, None, units).covariance
    S = np.cov(P.T)
    d = np.sqrt(np.diag(C))
    # the sample variance's relative std is sqrt(2 / N) ~ 2.2 %; correlations within ~ 3 / sqrt(N)
    np.testing.assert_allclose(np.sqrt(np.diag(S)) / d, 1.0, atol=0.04)
    np.testing.assert_allclose(S / np.outer(d, d), C / np.outer(d, d), atol=0.05)


def _same_covariance(C, reference, tol):
    """C = reference to `tol` in units of the std: |C_ij - R_ij| <= tol sqrt(R_ii R_jj) (a covariance
    that is zero in exact arithmetic has no relative precision)."""
    d = np.sqrt(np.diag(reference))
    np.testing.assert_allclose(C / np.outer(d, d), reference / np.outer(d, d), rtol=0, atol=tol)


@pytest.fixture(scope="module")
def staged():
    analysis = prepare(load_case(CASES / "staged-forecast.yaml"))
    return analysis, identify(analysis, profile="none")


def test_the_four_call_paths_agree(staged):
    """Reliability (assess), replicates, the prior -> posterior table and the design's posterior all
    solve eqn 55 through LinearAnalysis: they agree with each other and with a dense inverse."""
    from geoback.inference.identifiability import prior_posterior, prior_std
    from geoback.inference.parameters import parameter_limits
    from geoback.inference.misfit import whiten_block
    from geoback.physics.simulation import is_constant
    from geoback.worth.design import case_candidates, design

    analysis, res = staged
    rel, params, p = res.reliability, res.parameters, res.fit.p
    info = rel.information + np.diag(params.prior_precision())
    direct = _dense(info)
    # 1. the reliability measures
    _same_covariance(rel.covariance, direct, 1e-10)
    # 2. replicates: the case's own readings refitted reach the same estimate and the same C_p
    reps = identify_replicates(analysis, analysis.misfit.data.measured[None, :])
    np.testing.assert_allclose(reps.p[0], p, rtol=1e-12)
    _same_covariance(reps.covariance[0], rel.covariance, 1e-10)
    np.testing.assert_allclose(reps.std[0], rel.std, rtol=1e-10)
    # 3. the prior -> posterior table: eqn 55 with a prior on every parameter
    sim = analysis.simulation
    limits = [parameter_limits(sim, n, analysis.values_at(p)) for n in params.names]
    s0, _ = prior_std(params, p, limits)
    pp = prior_posterior(rel.information, params, p, limits)
    np.testing.assert_allclose(pp.posterior_std, np.sqrt(np.diag(_dense(rel.information + np.diag(1 / s0 ** 2)))),
                               rtol=1e-10)
    # 4. the design: C_p now is the reliability's; with a candidate, the dense inverse with its information
    d = design(analysis, res)
    np.testing.assert_array_equal(d.std_before, rel.std)
    names = list(params.names)
    cols = [j for j, n in enumerate(names) if not is_constant(n)]
    values = {k: v for k, v in analysis.values_at(p).items() if not is_constant(k)}
    for k, (_, _, block) in enumerate(case_candidates(analysis)[:3]):
        with sim.surveying([block]) as view:
            A = np.zeros((block.m, len(names)))
            A[:, cols] = view.predict(values, [names[j] for j in cols], sensitivities=True).A
        with_c = _dense(info + A.T @ np.linalg.solve(block.covariance, A))
        np.testing.assert_allclose(d.std_after[k], np.sqrt(np.diag(with_c)), rtol=1e-10)
        _same_covariance(rel.linear.conditional(whiten_block(block, A)).covariance, with_c, 1e-10)
