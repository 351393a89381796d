"""Forecasts, the prior -> posterior table and `geoback design`.

- the forecasts' sensitivities F = dq/dp (exact for displacements and instrument readings, central
  differences for the lining's forces) against central differences of the forward model;
- reading other instruments (`Simulation.surveying`) leaves the simulation as it was;
- the 95 % band's coverage over 1000 noisy replicates on data from a finer mesh (93-97 %);
- the design's predicted posterior equals the one of a fit that has the candidate's readings
  (exact readings at the estimate: the estimate does not move, so C_p must agree to rounding);
- the prior -> posterior table: equal to the fit's std where every parameter has a case prior,
  identifiability near 0 for what the readings cannot see;
- the command line: files, figures, warnings.
"""
from __future__ import annotations

import copy
import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from geoback.case.loading import LoadedCase, case_from_data, load_case
from geoback.worth.forecast import forecast, forecast_model
from geoback.inference.identification import identify, prepare
from geoback.physics.simulation import is_constant

ROOT = Path(__file__).resolve().parents[1]
STAGED = ROOT / "cases" / "staged-forecast.yaml"
sys.path.insert(0, str(ROOT / "studies"))


@pytest.fixture(scope="module")
def staged():
    analysis = prepare(load_case(STAGED))
    return analysis, identify(analysis, profile="none")


def test_forecast_sensitivities_match_central_differences(staged):
    analysis, res = staged
    model = forecast_model(analysis)
    names = res.parameters.names
    p = res.fit.p
    with model.reading():
        q, F = model(analysis.values_at(p), names, True)
        for j, name in enumerate(names):
            h = 1e-5 * abs(p[j])
            up, down = p.copy(), p.copy()
            up[j] += h
            down[j] -= h
            fd = (model(analysis.values_at(up))[0] - model(analysis.values_at(down))[0]) / (2 * h)
            scale = np.abs(fd).max()
            assert np.abs(F[:, j] - fd).max() <= 1e-5 * scale, name


def test_reading_other_instruments_leaves_the_simulation_as_it_was(staged):
    analysis, res = staged
    sim = analysis.simulation
    before = analysis.predict(res.fit.p, sensitivities=True)
    m = sim.survey.m
    fc = forecast(analysis, res, draws=30)
    assert sim.survey.m == m
    after = analysis.predict(res.fit.p, sensitivities=True)
    np.testing.assert_array_equal(before.x, after.x)
    np.testing.assert_array_equal(before.A, after.A)
    assert fc.counts["factorisations"] == 0  # the forecasts reuse the fit's factorisations
    sections = len(sim.lining_forces(analysis.values_at(res.fit.p)).angle)
    assert fc.draws == 30 and len(fc.value) == 31 + 5 + 2 * sections


def test_band_is_the_first_order_one_and_alert_probability(staged):
    analysis, res = staged
    fc = forecast(analysis, res, draws=0)
    C = res.reliability.covariance
    np.testing.assert_allclose(fc.std, np.sqrt(np.einsum("ij,jk,ik->i", fc.sensitivity, C, fc.sensitivity)))
    np.testing.assert_allclose(fc.high - fc.value, 1.959963984540054 * fc.std)
    i = fc.rows("trough")[0]
    from scipy import stats

    a, mu, s = fc.alert[i], fc.value[i], fc.std[i]
    assert fc.p_exceed[i] == pytest.approx(stats.norm.sf(a, mu, s) + stats.norm.cdf(-a, mu, s), rel=1e-9)
    assert np.isnan(fc.p_exceed[fc.rows("X1-lined")]).all()


def test_forecast_band_covers_the_truth_95_percent():
    """1000 noisy replicates, truth from a mesh twice as fine (studies/forecast_coverage.py)."""
    import forecast_coverage as study

    r = study.run(1000, "paper", seed=1)
    assert r["converged"] == 1000
    assert np.abs(r["bias_std"]).max() < 0.2  # the forecasts' own mesh bias is small against their std
    assert 0.93 <= r["coverage"][r["largest"]] <= 0.97
    assert 0.92 <= r["coverage"].min() and r["coverage"].max() <= 0.975


@pytest.mark.slow
def test_forecast_band_covers_the_truth_95_percent_on_yielding_ground():
    """500 noisy replicates of the Mohr-Coulomb case (E, K0, c', phi'), truth from a mesh twice as
    fine (studies/forecast_coverage.py --case plastic); about 15 min on two cores."""
    import forecast_coverage as study

    r = study.run(500, "plastic", seed=20240601, workers=2)
    assert r["failed"] == 0
    assert np.abs(r["bias_std"]).max() < 0.3
    assert 0.93 <= r["coverage"][r["largest"]] <= 0.97
    assert 0.92 <= r["coverage"].min() and r["coverage"].max() <= 0.975


def test_design_predicts_the_posterior_of_a_fit_with_the_candidate(staged):
    """Readings of the best candidate equal to the model at the estimate: the estimate stays put, so
    the fit's forecast std must be the design's prediction (to rounding)."""
    from geoback.case.checks import expand_candidates
    from geoback.worth.design import design
    from geoback.observation.readings import survey_blocks

    analysis, res = staged
    d = design(analysis, res)
    assert d.best == "I2-x4.5" and d.reduction[d.ranking[0]] > 0.15
    loaded = analysis.loaded
    k = d.ranking[0]
    cand = {c.name: c for _, c in expand_candidates(loaded.case.design)}[d.names[k]]
    data = loaded.case.model_dump(exclude_none=True, mode="json")
    blocks, measured = survey_blocks(loaded, ["advance", "lined"])
    start = 0
    for b in blocks:
        entry = next(i for i in data["instruments"] if i["name"] == b.name)
        entry.pop("readings_file", None)
        entry.setdefault("readings", {})[b.stage] = list(map(float, measured[start:start + b.m]))
        start += b.m
    ins = cand.model_dump(exclude_none=True, mode="json", exclude={"vary", "read_at"})
    sim = analysis.simulation
    from geoback.worth.design import candidate_blocks

    block = next(b for _, c, b in candidate_blocks(loaded, "advance") if c.name == cand.name)
    with sim.surveying([block]) as view:
        exact = view.predict({k: v for k, v in analysis.values_at(res.fit.p).items() if not is_constant(k)}).x
    ins["readings"] = {"advance": list(map(float, exact))}
    data["instruments"].append(ins)
    data.pop("design")
    with_it = prepare(LoadedCase(case_from_data(data), STAGED, {}))
    res2 = identify(with_it, p0=res.fit.p, profile="none")
    np.testing.assert_allclose(res2.fit.p, res.fit.p, rtol=1e-6)
    np.testing.assert_allclose(res2.reliability.std, d.std_after[k], rtol=1e-6)
    fc = forecast(with_it, res2, draws=0)
    rows = fc.rows("trough")
    assert np.sqrt(np.mean(fc.std[rows] ** 2)) == pytest.approx(d.after[k], rel=1e-6)


def test_prior_posterior_table(staged):
    analysis, res = staged
    pp = res.prior_posterior
    i = pp.names.index("beta[advance]")
    assert pp.prior_source[i] == "case prior" and pp.prior_std[i] == 0.15
    assert pp.identifiability[i] < 0.05  # one stage's readings cannot tell beta from E
    j = pp.names.index("K0")
    assert pp.prior_source[j] == "usual range" and pp.identifiability[j] > 0.9
    # with a case prior on every parameter, the posterior is the fit's C_p itself (eqn 55)
    data = copy.deepcopy(analysis.loaded.case.model_dump(exclude_none=True, mode="json"))
    for ins in data["instruments"]:
        ins["readings_file"] = str(ROOT / "cases" / "staged-forecast-readings.csv")
    data["parameters"][0]["prior"] = {"mean": 40000.0, "std": 20000.0}
    data["parameters"][1]["prior"] = {"mean": 0.7, "std": 0.3}
    loaded = LoadedCase(case_from_data(data), STAGED, {})
    res2 = identify(prepare(loaded), profile="none")
    np.testing.assert_allclose(res2.prior_posterior.posterior_std, res2.reliability.std, rtol=1e-8)


def test_run_and_design_commands(tmp_path):
    env = {"GEOBACK_CACHE": str(tmp_path / "cache"), "PATH": "/usr/bin:/bin"}
    run = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "run", str(STAGED), "--out", str(tmp_path / "r"),
                          "--plots", "-q"], capture_output=True, text=True, env=env, timeout=600)
    assert run.returncode == 0, run.stderr
    out = tmp_path / "r"
    with open(out / "forecast.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert {r["forecast"] for r in rows} == {"trough", "X1-lined", "shotcrete"}
    trough = [r for r in rows if r["forecast"] == "trough"]
    assert len(trough) == 31 and all(float(r["low95"]) <= float(r["value"]) <= float(r["high95"]) for r in trough)
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["forecasts"]["forecasts"]) == {"trough", "X1-lined", "shotcrete"}
    assert "identifiability" in summary["parameters"]["K0"]
    assert any(w["code"] == "forecast-nonlinear" for w in summary["warnings"])
    report = (out / "report.md").read_text()
    assert "## Forecasts" in report and "identifiability" in report
    for name in ("trough", "X1-lined", "shotcrete"):
        assert (out / f"forecast_{name}.png").stat().st_size > 10_000
    design = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "design", str(STAGED), "--out",
                             str(tmp_path / "d")], capture_output=True, text=True, env=env, timeout=600)
    assert design.returncode == 0, design.stderr
    assert "best: I2-x4.5" in design.stdout
    assert (tmp_path / "d" / "design.csv").exists() and (tmp_path / "d" / "design.png").exists()
    no_design = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "design", str(ROOT / "cases" / "tunnel-paper.yaml"),
                                "--out", str(tmp_path / "n")], capture_output=True, text=True, env=env, timeout=600)
    assert no_design.returncode == 2 and "design" in no_design.stderr and "Traceback" not in no_design.stderr
