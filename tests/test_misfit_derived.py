"""Every derived misfit whitens with its own covariance: the constructors that copy a `Misfit`
(`with_fixed_scales`, `with_measured`, `with_scale_dof`, `holding`, `with_weighting`, `extended`)
checked against the whitening written out from C_x itself, never against the class's own factor.

The first test failed on the copy idiom the class had before it became a frozen value: a misfit with
the error scales held fixed kept the stated covariance's cached factor and whitened with it (residuals
off by up to 53 on the error-scales example), so `diagnose` scored spurious hypotheses."""
from __future__ import annotations

from dataclasses import FrozenInstanceError

import numpy as np
import pytest
import scipy.linalg as sla

from geoback.case.loading import load_case
from geoback.diagnosis.hypotheses import candidate_hypotheses
from geoback.diagnosis.procedure import _best_of_groups, score_hypotheses
from geoback.inference.identification import identify, prepare

pytestmark = pytest.mark.quick


@pytest.fixture(scope="module")
def scaled():
    """The error-scales example fitted: (misfit anchored at the estimate, estimate)."""
    analysis = prepare(load_case("cases/tunnel-paper-error-scales.yaml"))
    result = identify(analysis)
    return analysis.misfit.anchored(result.fit.p), result.fit.p


def _whitened(C: np.ndarray, r: np.ndarray) -> np.ndarray:
    """L^-1 r with L the lower Cholesky factor of C (numpy's, not geoback's)."""
    return sla.solve_triangular(np.linalg.cholesky(C), r, lower=True)


def test_fixed_scales_whiten_with_the_fixed_covariance(scaled):
    misfit, p = scaled
    u = misfit.scales_at(p)
    assert u is not None and np.ptp(u) > 1.0  # the example's scales differ (k_X1 = 3.5)
    fixed = misfit.with_fixed_scales(u)
    ev = fixed.evaluate(p, jacobian=True)
    D = np.diag(np.exp(u / 2))
    C_fixed = D @ misfit.data.covariance @ D
    r = misfit.data.measured - ev.x
    np.testing.assert_allclose(ev.r[:misfit.m], _whitened(C_fixed, r), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(ev.B[:misfit.m], _whitened(C_fixed, ev.A), rtol=1e-10, atol=1e-12)
    # J is the quadratic form of C_fixed^-1 whatever the factor, and ln|C| its own log-determinant
    assert ev.J == pytest.approx(float(r @ np.linalg.solve(C_fixed, r)) + float(ev.r[misfit.m:] @ ev.r[misfit.m:]),
                                 rel=1e-10)
    assert fixed.logdet == pytest.approx(np.linalg.slogdet(C_fixed)[1], rel=1e-12)
    assert not fixed.free and all(g.kind == "known" for g in fixed.scales)
    # the original is untouched
    assert misfit.free and misfit.row_u is None


def test_fixed_scales_leave_no_spurious_hypothesis(scaled):
    """The diagnosis scores the error-scales example with the scales at their null estimates: no
    hypothesis is significant at diagnose's Bonferroni level (with the stale factor a layer
    boundary scored p = 4.9e-5 and a K0 gradient p = 0.0036 and were refitted)."""
    misfit, p = scaled
    hyps = candidate_hypotheses(misfit, p)
    ranking = _best_of_groups(score_hypotheses(misfit, p, hyps))
    testable = [s for s in ranking if s.collinear_with is None]
    threshold = 0.05 / len(testable)
    assert all(s.p_score >= threshold for s in testable), [(s.hypothesis.key, s.p_score) for s in testable]
    k0 = next(s for s in testable if s.hypothesis.key == "K0-gradient")
    assert k0.p_score == pytest.approx(0.0511, abs=0.002)


def test_with_measured_whitens_the_new_readings_with_the_same_covariance(scaled):
    misfit, p = scaled
    other = misfit.data.measured * 1.1 + 1e-4
    new = misfit.with_measured(other)
    ev = new.evaluate(p)
    np.testing.assert_allclose(ev.whitened_residual * np.exp(ev.scales.row_u / 2),
                               _whitened(misfit.data.covariance, other - ev.x), rtol=1e-10, atol=1e-12)
    assert new.L is misfit.L  # one factorisation of an unchanged covariance, shared
    np.testing.assert_array_equal(misfit.data.measured, misfit.data.measured)  # untouched
    assert not np.array_equal(new.data.measured, misfit.data.measured)
    with pytest.raises(ValueError, match="expected"):
        misfit.with_measured(other[:-1])


def test_with_scale_dof_equals_a_misfit_built_with_those_dof(scaled):
    misfit, p = scaled
    c = misfit.scale_dof * 0.9
    derived = misfit.with_scale_dof(c)
    from geoback.inference.misfit import Misfit

    fresh = Misfit(misfit.simulation, misfit.data, misfit.parameters, misfit.base_values, misfit.weighting,
                   misfit.scales, scale_dof=c)
    a, b = derived.evaluate(p, jacobian=True), fresh.evaluate(p, jacobian=True)
    np.testing.assert_allclose(a.r, b.r, rtol=1e-13)
    np.testing.assert_allclose(a.B, b.B, rtol=1e-13)
    assert a.J == pytest.approx(b.J, rel=1e-13)
    np.testing.assert_allclose(misfit.scale_dof * 0.9, c)  # the original keeps its own


def test_holding_a_parameter_is_the_full_misfit_at_that_value():
    analysis = prepare(load_case("cases/tunnel-paper.yaml"))
    misfit = analysis.misfit
    p = misfit.parameters.initial * np.array([1.7, 1.6])
    held = misfit.holding(1, p[1])
    assert held.parameters.names == [misfit.parameters.names[0]]
    assert held.J(p[:1]) == pytest.approx(misfit.J(p), rel=1e-12)
    # and it keeps fixed scales: held at a fixed covariance, it whitens with that covariance
    u = np.linspace(-1.0, 1.0, misfit.m)
    fixed = misfit.with_fixed_scales(u)
    assert fixed.holding(1, p[1]).J(p[:1]) == pytest.approx(fixed.J(p), rel=1e-12)
    assert fixed.J(p) != pytest.approx(misfit.J(p), rel=1e-3)


def test_with_weighting_diagonal_whitens_by_each_reading_sigma():
    analysis = prepare(load_case("cases/tunnel-paper.yaml"))
    misfit = analysis.misfit
    p = misfit.parameters.initial
    diag = misfit.with_weighting("diagonal")
    ev = diag.evaluate(p)
    sd = np.sqrt(np.diag(misfit.data.covariance))
    np.testing.assert_allclose(ev.whitened_residual, (misfit.data.measured - ev.x) / sd, rtol=1e-12)
    ident = misfit.with_weighting("identity")
    np.testing.assert_allclose(ident.evaluate(p).whitened_residual, misfit.data.measured - ev.x, rtol=1e-12)


def test_extended_keeps_the_fixed_covariance(scaled):
    misfit, p = scaled
    u = misfit.scales_at(p)
    fixed = misfit.with_fixed_scales(u)
    h = next(h for h in candidate_hypotheses(misfit, p) if h.key == "K0-gradient")
    ext = fixed.extended(h.parameters, h.extra_values, start=p)
    p0 = np.concatenate([p, [q.initial for q in h.parameters]])
    ev = ext.evaluate(p0)
    D = np.diag(np.exp(u / 2))
    np.testing.assert_allclose(ev.whitened_residual,
                               _whitened(D @ misfit.data.covariance @ D, misfit.data.measured - ev.x),
                               rtol=1e-10, atol=1e-12)


def test_a_misfit_cannot_be_changed_in_place(scaled):
    misfit, _ = scaled
    with pytest.raises(FrozenInstanceError):
        misfit.data = None
    with pytest.raises(ValueError):
        misfit.L[0, 0] = 1.0  # the factor is read-only
