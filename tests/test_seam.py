"""The seam (geoback.inference.misfit): its objective and Jacobian equal the paper's J written out directly
(eqns 6, 9 and 53 as corrected), priors enter as observations, and nothing downstream re-runs the model."""
import numpy as np
import pytest
import yaml

from conftest import CASES
from geoback.case.loading import LoadedCase, case_from_data, load_case
from geoback.inference.explore import explore
from geoback.inference.identification import identify, prepare
from geoback.reports.report import write_run

pytestmark = pytest.mark.quick  # the edit-test loop tier (`pytest -m quick`)


@pytest.fixture(scope="module")
def paper():
    return prepare(load_case(CASES / "tunnel-paper.yaml"))


def test_objective_is_the_whitened_sum_of_squares(paper):
    """J = (x* - x)^t C_x^-1 (x* - x) with C_x the full instrument covariance (eqns 6, 9)."""
    mis = paper.misfit
    C = mis.data.covariance
    for p in ([5000.0, 0.5], [10000.0, 1.0], [14000.0, 1.7]):
        p = np.array(p)
        r = mis.data.measured - paper.predict(p).x
        direct = float(r @ np.linalg.solve(C, r))
        assert mis.J(p) == pytest.approx(direct, rel=1e-12)


def test_jacobian_is_the_whitened_sensitivity_and_matches_differences(paper):
    """B = L^-1 A with C_x = L L^t, and A against central differences of x(p)."""
    mis = paper.misfit
    p = np.array([8000.0, 0.8])
    ev = mis.evaluate(p, jacobian=True)
    L = np.linalg.cholesky(mis.data.covariance)
    np.testing.assert_allclose(L @ ev.B, ev.A, rtol=1e-10, atol=1e-14 * np.abs(ev.A).max())
    for j, h in enumerate((1e-5 * p[0], 1e-4)):  # x ~ 1/E: truncation (h/E)^2 ~ 1e-10
        up, down = p.copy(), p.copy()
        up[j] += h
        down[j] -= h
        fd = (mis.evaluate(up).x - mis.evaluate(down).x) / (2 * h)
        assert np.linalg.norm(fd - ev.A[:, j]) <= 1e-7 * np.linalg.norm(ev.A[:, j])
    # r = L^-1 (x* - x): B is minus the derivative of r
    r_up = mis.evaluate(p + [1e-5 * p[0], 0]).r
    r_dn = mis.evaluate(p - [1e-5 * p[0], 0]).r
    np.testing.assert_allclose(-(r_up - r_dn) / (2e-5 * p[0]), ev.B[:, 0], rtol=1e-7)


def test_prior_rows_are_observations():
    data = yaml.safe_load((CASES / "tunnel-paper.yaml").read_text())
    data["parameters"][1]["prior"] = {"mean": 0.9, "std": 0.05}
    a = prepare(LoadedCase(case_from_data(data), CASES / "tunnel-paper.yaml", {}))
    p = np.array([9000.0, 1.1])
    ev = a.misfit.evaluate(p, jacobian=True)
    assert len(ev.r) == a.misfit.m + 1
    assert ev.r[-1] == pytest.approx((0.9 - 1.1) / 0.05)
    np.testing.assert_array_equal(ev.B[-1], [0.0, 1 / 0.05])
    assert ev.J == pytest.approx(ev.J_data + ((0.9 - 1.1) / 0.05) ** 2)


def test_weightings(paper):
    mis = paper.misfit
    p = np.array([9000.0, 0.9])
    r = mis.data.measured - paper.predict(p).x
    d = np.diag(mis.data.covariance)
    assert mis.with_weighting("diagonal").J(p) == pytest.approx(float(np.sum(r * r / d)), rel=1e-12)
    assert mis.with_weighting("identity").J(p) == pytest.approx(float(r @ r), rel=1e-12)


def test_measured_readings_cannot_be_changed_in_place(paper):
    with pytest.raises(ValueError):
        paper.misfit.data.measured[0] = 0.0
    other = paper.misfit.with_measured(paper.misfit.data.measured * 1.01)
    assert other.simulation is paper.misfit.simulation  # factorisations shared
    assert not np.array_equal(other.data.measured, paper.misfit.data.measured)


def test_reports_and_figures_run_no_model(tmp_path):
    """Only the exploration step solves; writing every output (figures included) reads results."""
    from geoback.reports import plots

    paper = prepare(load_case(CASES / "tunnel-paper.yaml"))  # a fresh simulation: counts from zero
    res = identify(paper)
    exploration = explore(paper.misfit, res, plots.exploration_for(), paper.settings)
    counters = paper.simulation.counters
    before = counters.snapshot()
    write_run(res, tmp_path, exploration, plots=True)
    assert counters.snapshot() == before
    assert (tmp_path / "field.vtu").exists() and (tmp_path / "objective_contours.png").exists()
    # the summary reports the identification's own work and, apart, the exploration's
    import json

    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["factorisations"] == 1
    assert summary["exploration"]["factorisations"] == 0  # K = E k: the fit's factorisation served it


def test_one_instrument_is_whitened_as_the_survey_whitens_it(paper):
    """whiten_block (a candidate instrument's rows, or one block of the data) is L_i^-1 v with the
    block's own Cholesky factor: the rows Misfit.whiten gives that block, for readings and sensitivities."""
    from dataclasses import replace

    from geoback.case.covariance import NotPositiveDefinite
    from geoback.inference.misfit import block_factor, whiten_block

    mis = paper.misfit
    assert mis.weighting == "full"
    ev = mis.evaluate(np.array([8000.0, 0.8]), jacobian=True)
    for block, rows in mis.data.block_rows():
        C = mis.data.covariance[rows, rows]
        np.testing.assert_array_equal(block_factor(block, C), np.linalg.cholesky(C))
        r = mis.data.measured[rows] - ev.x[rows]
        np.testing.assert_allclose(whiten_block(block, r, C), ev.r[rows], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(whiten_block(block, ev.A[rows], C), ev.B[rows], rtol=1e-13,
                                   atol=1e-13 * np.abs(ev.B[rows]).max())
        np.testing.assert_allclose(np.linalg.cholesky(C) @ whiten_block(block, ev.A[rows], C), ev.A[rows],
                                   rtol=1e-12, atol=1e-14 * np.abs(ev.A[rows]).max())
    bad = replace(mis.data.blocks[0], covariance=-np.eye(mis.data.blocks[0].m))
    with pytest.raises(NotPositiveDefinite, match=bad.name):
        whiten_block(bad, np.ones(bad.m))


@pytest.mark.parametrize("case", ["tunnel-paper.yaml", "staged-tunnel.yaml", "concealed/null-1.yaml"])
def test_noise_is_drawn_in_one_place_on_the_seeded_stream(case):
    """block_noise draws L_i z per instrument in survey order, z = rng.standard_normal(m_i), with the
    factor np.linalg.cholesky gives (bitwise): the stream the shipped readings were generated with
    (synthetic_readings) and the one Data.noise draws."""
    from geoback.inference.misfit import Data, block_factor, block_noise

    sim = prepare(load_case(CASES / case), with_readings=False).simulation
    blocks = sim.survey.blocks
    for b in blocks:
        np.testing.assert_array_equal(block_factor(b), np.linalg.cholesky(b.covariance))
    old_rng, new_rng = np.random.default_rng(7), np.random.default_rng(7)
    old = np.concatenate([np.linalg.cholesky(b.covariance) @ old_rng.standard_normal(b.m) for b in blocks])
    new = np.concatenate([block_noise(b, new_rng) for b in blocks])
    np.testing.assert_array_equal(new, old)
    data = Data.build(blocks, np.zeros(len(old)))
    np.testing.assert_array_equal(data.noise(np.random.default_rng(7)), old)
    np.testing.assert_array_equal(data.noise(np.random.default_rng(7), scale=2.0), 2.0 * old)
