"""Small versions of the studies (studies/*.py) and the checks of C_p and A against scipy / FD.

Each study is run with --small into a temporary folder; the tests assert the direction of
each effect (paper Figs. 7, 9-10, and the calibration of the 95 % ellipse of C_p).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
STUDIES = ROOT / "studies"
if str(STUDIES) not in sys.path:
    sys.path.insert(0, str(STUDIES))


@pytest.fixture(scope="module", autouse=True)
def _cache(tmp_path_factory):
    """Meshes of this module go to a temporary cache (GEOBACK_CACHE), never the user's home."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("GEOBACK_CACHE", str(tmp_path_factory.mktemp("geoback-cache")))
        yield


@pytest.fixture(scope="module")
def out(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("studies-out")


def _outputs_exist(out: Path, name: str) -> None:
    assert (out / f"{name}.csv").stat().st_size > 0
    assert (out / f"{name}.png").stat().st_size > 0


# ----------------------------------------------------------------------------- (a) Fig. 7
def test_measurement_count_std_decreases_and_is_proportional_to_sigma(out, capsys):
    import measurement_count as study

    rows = study.main(["--small", "--out", str(out)])
    _outputs_exist(out, study.NAME)
    assert "readings" in capsys.readouterr().out
    s1, s2 = study.SIGMAS
    by = {(r["sigma_m"], r["readings"]): r for r in rows}
    counts = [2, 12, 24, 55]
    for sigma in (s1, s2):
        for key in ("std_E_kPa", "std_K0"):
            stds = [by[sigma, m][key] for m in counts]
            assert all(np.isfinite(stds))
            assert all(a > b for a, b in zip(stds, stds[1:])), (sigma, key, stds)
        for m in counts:  # every layout identifies the truth from noise-free fine-mesh readings
            assert by[sigma, m]["status"] == "converged"
            assert abs(by[sigma, m]["E_hat_kPa"] / 10000 - 1) < 0.01
            assert abs(by[sigma, m]["K0_hat"] - 1) < 0.01
    for m in counts:  # exactly proportional to sigma (C_p scales with sigma^2)
        for key in ("std_E_kPa", "std_K0"):
            assert by[s2, m][key] / by[s1, m][key] == pytest.approx(s2 / s1, rel=1e-9)


# ----------------------------------------------------------------------------- (b) Figs. 9-10
def test_covariance_structure_full_cx_beats_identity(out):
    import covariance_structure as study

    rows = study.main(["--small", "--out", str(out)])
    _outputs_exist(out, study.NAME)
    full = next(r for r in rows if r["weighting"] == "full")
    ident = next(r for r in rows if r["weighting"] == "identity")
    assert full["realisations"] >= 40
    assert full["rmse_E_kPa"] < ident["rmse_E_kPa"]
    assert full["rmse_K0"] < ident["rmse_K0"]
    # the discretisation bias is negligible against the noise (sigma_alpha = 0.005 rad)
    assert abs(full["bias_E_kPa"]) < 0.05 * full["rmse_E_kPa"]
    assert abs(full["bias_K0"]) < 0.05 * full["rmse_K0"]


# ----------------------------------------------------------------------------- (c) calibration
def test_calibration_fraction_inside_95_ellipse(out):
    import calibration as study

    row = study.main(["--small", "--out", str(out)])
    _outputs_exist(out, study.NAME)
    assert row["realisations"] == 100
    assert 0.85 <= row["fraction_inside_95"] <= 1.0, row
    # the fitting mesh's bias is small against the std, so the test measures C_p, not the mesh
    assert abs(row["bias_E_in_std"]) < study.BIAS_LIMIT
    assert abs(row["bias_K0_in_std"]) < study.BIAS_LIMIT
    # the scatter of the estimates agrees with C_p (100 samples: sd within ~ +-14 % at 2 se)
    assert row["sample_sd_E_kPa"] == pytest.approx(row["Cp_std_E_kPa"], rel=0.2)
    assert row["sample_sd_K0"] == pytest.approx(row["Cp_std_K0"], rel=0.2)


# ----------------------------------------------------------------------------- forecast coverage, Mohr-Coulomb
def test_forecast_coverage_plastic_machinery(out):
    """The plastic variant of studies/forecast_coverage.py on a handful of replicates: every fit is
    counted, and a replicate's band is the one geoback's own forecast (draws=0) gives on that
    replicate's readings. The machinery only; the coverage needs >= 500 replicates (see the study)."""
    import forecast_coverage as study
    from geoback.worth.forecast import forecast
    from geoback.inference.identification import identify, prepare

    r = study.main(["--small", "--case", "plastic", "--out", str(out)])
    _outputs_exist(out, f"{study.NAME}_plastic")
    assert (out / f"{study.NAME}_plastic.npz").stat().st_size > 0
    n = r["replicates"]
    assert n == 6 and r["converged"] + r["failed"] == n and r["converged"] >= n - 1
    assert r["inside"].shape == (n, 27) and r["x"][-1].startswith("crown")
    assert r["x"][r["largest"]].startswith("crown")  # the crown settles more than the surface
    assert np.abs(r["bias_std"]).max() < 0.5  # the fitting mesh's bias is small against the forecast std
    np.testing.assert_allclose(r["p0"], [40000.0, 0.9, 50.0, 30.0], rtol=0.03)  # noise-free fit near the truth
    # replicate 0 again, through geoback's identify and forecast
    problem = prepare(study.plastic_case(), with_readings=False).with_readings(r["noisy"][0])
    res = identify(problem, p0=r["p0"], require_dof=False, profile="none")
    np.testing.assert_allclose(res.fit.p, r["p"][0], rtol=1e-4)
    fc = forecast(problem, res, draws=0)
    np.testing.assert_allclose(fc.value, r["q"][0], rtol=1e-4, atol=1e-7)
    np.testing.assert_allclose(fc.std, r["s"][0], rtol=1e-3)
    truth = r["q_true"]
    np.testing.assert_array_equal((fc.low <= truth) & (truth <= fc.high), r["inside"][0])


# ----------------------------------------------------------------------------- C_p vs scipy
def test_cp_equals_scipy_least_squares_covariance():
    """C_p (eqn 55) equals inv(J^t J) of scipy.optimize.least_squares on the whitened residuals."""
    from scipy.optimize import least_squares

    import common as C
    from geoback.inference.identification import identify, prepare
    from geoback.inference.synthetic import synthetic_readings

    data = C.case_dict(weighting="full")
    loaded = C.loaded_case(data)
    noisy = synthetic_readings(loaded, refine=2.0, noise_seed=7)
    loaded = C.loaded_case(C.with_readings(data, noisy))
    problem = prepare(loaded)
    res = identify(problem, weighting="full")
    assert res.fit.status == "converged"
    Cp = res.reliability.covariance

    misfit = problem.misfit  # C_x = L L^t, full instrument covariance
    measured = misfit.data.measured
    scale = np.abs(problem.parameters.initial)

    def whitened_residual(z):
        return misfit.whiten(measured - problem.predict(z * scale).x)

    ls = least_squares(whitened_residual, problem.parameters.initial / scale, jac="3-point", method="lm",
                       xtol=1e-12, ftol=1e-12, gtol=1e-12)
    assert ls.success
    J = ls.jac / scale  # d r' / d p in physical units
    cov = np.linalg.inv(J.T @ J)
    np.testing.assert_allclose(ls.x * scale, res.fit.p, rtol=1e-4)
    rel_frob = np.linalg.norm(cov - Cp) / np.linalg.norm(Cp)
    d = np.sqrt(np.diag(Cp))  # also in standardised units, where K0's entries count as much as E's
    rel_frob_std = np.linalg.norm((cov - Cp) / np.outer(d, d)) / np.linalg.norm(Cp / np.outer(d, d))
    print(f"C_p vs least_squares: relative Frobenius {rel_frob:.2e} (standardised {rel_frob_std:.2e})")
    assert rel_frob < 0.02, rel_frob
    assert rel_frob_std < 0.02, rel_frob_std


# ----------------------------------------------------------------------------- A vs central FD
def _two_layer_case():
    import common as C

    data = C.case_dict(mesh_scale=0.5, name="two-layers")
    data["ground"]["K0"] = 1.0
    data["ground"]["layers"] = [
        {"name": "clay", "top": 0.0, "E": "8 MPa", "nu": 0.3},
        {"name": "marl", "top": 9.0, "E": "25 MPa", "nu": 0.45, "K0": 0.8},
    ]
    data["parameters"] = [
        {"name": "E[clay]", "initial": "8 MPa"},
        {"name": "E[marl]", "initial": "25 MPa"},
        {"name": "nu[clay]", "initial": 0.3},
        {"name": "K0", "initial": 1.0},
        {"name": "K0[marl]", "initial": 0.8},
        {"name": "B[I1]", "initial": 0.002},
    ]
    for ins in data["instruments"]:
        if ins["name"] == "I1":
            ins["var_b"] = 1e-6
    return C.loaded_case(data)


def test_sensitivities_match_central_differences():
    from conftest import central_difference_error
    from geoback.inference.identification import prepare

    problem = prepare(_two_layer_case())
    names = problem.parameters.names
    assert names == ["E[clay]", "E[marl]", "nu[clay]", "K0", "K0[marl]", "B[I1]"]
    p = problem.parameters.initial.copy()
    A = problem.predict(p, sensitivities=True).A
    steps = {"E[clay]": 1e-4 * p[0], "E[marl]": 1e-4 * p[1], "nu[clay]": 1e-5, "K0": 1e-4, "K0[marl]": 1e-4,
             "B[I1]": 1e-4}
    for j, name in enumerate(names):
        err = central_difference_error(problem, p, A, j, steps[name])
        assert err < 1e-6, (name, err)
    # B[I1] shifts every inclinometer reading by -1 (x = P u - G c) and nothing else
    rows_i1 = [i for i, lab in enumerate(problem.simulation.survey.labels) if lab.instrument == "I1"]
    col = A[:, names.index("B[I1]")]
    np.testing.assert_array_equal(col[rows_i1], -1.0)
    assert np.count_nonzero(col) == len(rows_i1)


# ----------------------------------------------------------------------------- pooled instrument tests
def test_the_exact_level_of_the_largest_of_correlated_statistics():
    """studies/instrument_pooling.py: P(max |Z_i| > c) for Z ~ N(0, R) is Sidak's for independent
    members, a single test's for identical ones, and in between otherwise."""
    from scipy import stats

    import instrument_pooling as study

    level = 0.05 / 9
    single = stats.norm.isf(level / 2)
    sidak = stats.norm.isf((1 - (1 - level) ** (1 / 3)) / 2)
    assert study.pooled_critical(level, np.eye(1)) == pytest.approx(single, abs=1e-5)
    assert study.pooled_critical(level, np.eye(3)) == pytest.approx(sidak, abs=1e-4)
    same = np.full((3, 3), 1.0)
    assert study.pooled_critical(level, same) == pytest.approx(single, abs=1e-3)
    R = np.array([[1.0, 0.0, -0.8], [0.0, 1.0, 0.0], [-0.8, 0.0, 1.0]])
    assert single < study.pooled_critical(level, R) < sidak
    assert study.power(single, 0.0) == pytest.approx(level)


def test_pooling_an_inclinometers_errors_would_cost_them_power_on_the_shipped_layout(out, capsys):
    """The shipped concealed cases (one layout, two inclinometers and an extensometer): an inclinometer's
    three error hypotheses are nearly independent (|correlation| <= 0.3), so one pooled test of them would
    accept each at a stricter level than the single tests do, and find an instrument error less often."""
    import instrument_pooling as study

    rows = study.main(["--random", "0", "--out", str(out)])
    assert rows and {r["members"] for r in rows} == {3}
    for r in rows:
        assert r["largest_correlation"] < 0.3
        assert r["family_pooled"] == r["family"] - 4  # two inclinometers, three errors each
        assert r["c_pooled"] > r["c"]
        assert r["power_instrument_pooled"] < r["power_instrument"] < r["power_ground_pooled"]
    assert (out / "instrument_pooling.csv").stat().st_size > 0


# ----------------------------------------------------------------------------- the reading a tie asks for
def _tie_csv(path):
    import csv

    cols = ["seed", "case", "kind", "effect_size", "correct", "grade", "failed_checks"]
    rows = [("2033", "bench-016-depth-offset", "depth-offset", "5.1", "True", "explained", "rivals(K0-gradient)"),
            ("2033", "bench-008-stress-release", "stress-release", "8.5", "True", "explained", "adequacy"),
            ("2033", "bench-002-bias-shift", "bias-shift", "2.9", "True", "explained", "rivals(anisotropy[clay])"),
            ("2034", "bench-003-K0-gradient", "K0-gradient", "7.5", "False", "explained", "rivals(depth-offset[I1])")]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(cols)
        w.writerows(rows)


def test_the_tied_cases_and_the_reading_added(tmp_path):
    """studies/separating_reading.py: a tie is a right first cause explained only by its rival check, effect > 3;
    the reading added is one point reading the component named, with the case's extensometer's sigma."""
    import separating_reading as study

    _tie_csv(tmp_path / "full.csv")
    assert [r["case"] for r in study.tied_rows(tmp_path / "full.csv")] == ["bench-016-depth-offset"]
    spec = {"data": {"instruments": [{"name": "X1", "kind": "extensometer", "sigma": 0.00021}]}}
    added = study.with_reading(spec, {"x": 2.8234, "depth": 11.1049, "component": "ux", "difference": 0.0044})
    assert spec["data"]["instruments"] == [{"name": "X1", "kind": "extensometer", "sigma": 0.00021}]  # not changed
    assert added["data"]["instruments"][-1] == {"name": "N1", "kind": "points", "points": [[2.823, -11.105]],
                                                "components": ["ux"], "sigma": 0.00021}
    # --sigma asked: the sigma the verdict asks for where smaller, never below 0.05 mm
    for needed, sigma in ((0.0009, 0.00021), (0.00012, 0.00012), (0.00001, study.MIN_SIGMA)):
        point = {"x": 2.8234, "depth": 11.1049, "component": "ux", "difference": 0.0044, "sigma_needed": needed}
        assert study.with_reading(spec, point, asked=True)["data"]["instruments"][-1]["sigma"] == sigma


@pytest.mark.slow  # 15 s: one benchmark case diagnosed twice
def test_the_reading_a_tie_asks_for_singles_the_cause_out(tmp_path):
    """Seed 2033 bench-016 of the accuracy benchmark: a depth offset of I1 tied with a K0 gradient (within 10
    AIC); one reading of u_x where the two refits differ most (4.4 mm) names the depth offset."""
    import separating_reading as study

    _tie_csv(tmp_path / "full.csv")
    out = study.main(["--csv", str(tmp_path / "full.csv"), "--out", str(tmp_path)])
    assert len(out) == 1 and out[0]["rival"] == "K0-gradient" and out[0]["outcome"] == "named right", out
    assert (tmp_path / "separating_reading.csv").stat().st_size > 0
