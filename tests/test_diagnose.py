"""`geoback diagnose` on the shipped concealed-physics cases (cases/concealed/generate.py): readings
from a model containing the effect, on a mesh twice as fine, with instrument noise; the case files
describe only the baseline model."""
import json
import subprocess
import sys

import numpy as np
import pytest

from conftest import CASES
from geoback.case.loading import load_case
from geoback.diagnosis import diagnose

CONCEALED = CASES / "concealed"

# case -> (hypothesis kind that must be named, its parameter, the concealed true value)
EXPECTED = {
    "stiffness-gradient": ("stiffness-gradient", "Egrad[clay]", 400.0),
    "layer-boundary": ("layer-boundary", "E[clay_below]", 25000.0),
    "anisotropy": ("anisotropy", "n[clay]", 1.6),
    "K0-gradient": ("K0-gradient", "K0grad", -0.06),
    "toe-moved": ("integration-constant", "B[I1]", 0.004),
    "stress-release": ("stress-release", "beta", 0.7),
    "bias-shift": ("bias-shift", "bias[I2]", 4e-4),
    "depth-offset": ("depth-offset", "zoff[I1]", 0.5),
}
INSTRUMENT = {"toe-moved", "bias-shift", "depth-offset"}  # concealed instrument errors, not ground physics


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_concealed_effect_is_named_estimated_and_fixes_the_fit(name):
    kind, param, truth = EXPECTED[name]
    d = diagnose(load_case(CONCEALED / f"{name}.yaml"))
    assert not d.adequate_before
    assert [s.hypothesis.kind for s in d.accepted] == [kind]
    rel = d.final_reliability
    lo, hi = rel.interval95()
    i = rel.names.index(param)
    assert lo[i] <= truth <= hi[i], (param, d.final_fit.p[i], rel.std[i])
    assert d.adequate_after
    assert rel.reduced_chi2 < d.baseline_reliability.reduced_chi2
    if name == "layer-boundary":  # the depth by profile likelihood over a continuous depth, with its interval
        prof = d.depth_profile(d.accepted[0])
        assert prof.has_interval and prof.low <= 16.0 <= prof.high and prof.high - prof.low < 1.0
        assert not prof.low_open and not prof.high_open
        # check 8: the inclinometer readings below the boundary improve with it themselves
        seen = d.accepted[0].checks["boundary-seen"]
        assert seen.passed and seen.detail["testable"] and seen.detail["z"] > seen.detail["needed"]
        assert seen.detail["below_gain"] > 0
        # the figure draws the accepted boundary at its depth, with its interval, on the panels that reach it
        from geoback.inference.explore import explore
        from geoback.reports.plots.diagnosis import before_after_figure
        from geoback.reports.plots.instruments import BOUNDARY

        fig = before_after_figure(d, explore(d.final_misfit, d.final, ("profiles",)))
        drawn = [ln for ax in fig.axes for ln in ax.lines if ln.get_color() == BOUNDARY]
        assert len(drawn) >= 2 and all(np.allclose(ln.get_ydata(), prof.z_hat) for ln in drawn)
        assert all(ax.axison for ax in fig.axes)  # four instruments in 2 x 2: no empty panel
        fig.clear()
    cause = "instrument" if name in INSTRUMENT else "ground"
    assert [s.hypothesis.cause for s in d.accepted] == [cause]
    # issue 24: the cause passes its claim checks (cross-validation, residual structure, no rival of another
    # family within 10 AIC, determined): named, not only a better fit. The depth offset has a K0 gradient
    # 9 AIC behind it (the confusion the issue reports): explained but not singled out, the rival listed.
    failed = {c.name: c.text for c in d.accepted[0].checks.values() if not c.passed}
    if name == "depth-offset":
        assert d.grade == "explained" and set(failed) == {"rivals"}
        assert [r.hypothesis.kind for r in d.accepted[0].rivals] == ["K0-gradient"]
    else:
        assert d.grade == "named", failed
        assert rel.p_value >= d.alpha  # a named cause's final model passes the chi^2 test the verdict states
    assert d.causes[cause] and not d.causes["ground" if cause == "instrument" else "instrument"]


def test_bias_shift_is_named_as_instrument_error_in_words_and_json(tmp_path):
    from geoback.reports.diagnosis_report import write_diagnosis
    from geoback.reports.diagnosis_report import verdict

    d = diagnose(load_case(CONCEALED / "bias-shift.yaml"))
    text = verdict(d)
    assert text.startswith("The mismatch is instrument error, not ground physics.")
    assert "bias shift" in text
    write_diagnosis(d, tmp_path, plots=False)
    data = json.loads((tmp_path / "diagnosis.json").read_text())
    assert data["cause"] == "instrument error"
    assert data["instrument_error"] == ["bias-shift[I2]"] and data["ground_physics"] == []
    assert data["missing"][0]["cause"] == "instrument error"
    est = data["missing"][0]["estimates"]["bias[I2]"]
    assert est["from"] == "final joint fit" and est["ci95"][0] <= 4e-4 <= est["ci95"][1]


@pytest.mark.parametrize("name", ["null-1", "null-2", "null-3"])
def test_null_case_is_adequate(name):
    d = diagnose(load_case(CONCEALED / f"{name}.yaml"))
    assert d.adequate_before and not d.accepted


def test_unlined_stress_release_without_prior_is_reported_as_not_separable():
    d = diagnose(load_case(CONCEALED / "stiffness-gradient.yaml"))
    beta = next(s for s in d.rounds[0].ranking if s.hypothesis.kind == "stress-release")
    assert beta.collinear_with is not None and "E[clay]" in beta.collinear_with


def test_cli_writes_diagnosis_files(tmp_path):
    out = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "diagnose", str(CONCEALED / "null-1.yaml"),
                          "--out", str(tmp_path), "-q"], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "No effect the library can detect is missing" in out.stdout  # not "nothing is missing"
    assert "would have caught, with 80 % probability" in out.stdout  # and what size it would have caught
    data = json.loads((tmp_path / "diagnosis.json").read_text())
    assert data["adequate_before"] is True and data["missing"] == []
    assert (tmp_path / "diagnosis.md").read_text().startswith("# geoback diagnosis")
    assert (tmp_path / "diagnosis.png").stat().st_size > 0


def test_null_case_with_a_moving_model_toe_is_adequate():
    """Inclinometer readings are relative to the toe (as integrated in the field) and the model is
    compared as u(z) - u(toe): where the model's own toe moves by more than 5 mm, a null case is
    still adequate and no 'toe moved' is invented."""
    from geoback.inference.identification import prepare

    analysis = prepare(load_case(CONCEALED / "null-1.yaml"))
    sim = analysis.simulation
    toes = [b for b in sim.survey.blocks if b.kind == "inclinometer"]
    assert all(b.relative for b in toes)
    moves = [abs(sim.displacements_at(analysis.values, b.points[-1:])[0, 0]) for b in toes]
    assert min(moves) >= 0.005, moves
    d = diagnose(analysis)
    assert d.adequate_before and not d.accepted


def test_two_effects_are_reported_from_the_final_joint_fit(tmp_path):
    """I1's toe moved and I2 has a bias shift: both accepted, in two rounds; the verdict, diagnosis.md
    and diagnosis.json give each parameter from the final joint fit, not from its round."""
    import numpy as np

    from geoback.reports.diagnosis_report import write_diagnosis
    from geoback.reports.diagnosis_report import verdict
    from geoback.inference.identification import prepare
    from geoback.inference.synthetic import synthetic_readings

    loaded = load_case(CONCEALED / "toe-moved.yaml")
    readings = synthetic_readings(loaded, refine=2.0, values={"B[I1]": 0.004, "bias[I2]": 4e-4}, noise_seed=3)
    analysis = prepare(loaded)
    analysis = analysis.with_readings(np.concatenate([readings[b.name] for b in analysis.simulation.survey.blocks]))
    d = diagnose(analysis)
    assert sorted(s.hypothesis.kind for s in d.accepted) == ["bias-shift", "integration-constant"]
    assert d.causes["instrument"] and not d.causes["ground"]
    final = dict(zip(d.final.parameters.names, d.final_fit.p))
    first = d.accepted[0]
    name = first.hypothesis.names[0]
    i = first.reliability.names.index(name)
    assert first.refit.p[i] != final[name]  # the round's number differs from the joint fit's
    text = verdict(d)
    assert "final joint fit" in text
    write_diagnosis(d, tmp_path, plots=False)
    data = json.loads((tmp_path / "diagnosis.json").read_text())
    md = (tmp_path / "diagnosis.md").read_text()
    from geoback.units import value_text as shown

    units = dict(zip(d.final.parameters.names, d.final.parameters.units))
    for s, item in zip(d.accepted, data["missing"]):
        for n in s.hypothesis.names:
            assert item["estimates"][n]["estimate"] == final[n]
            # (issue 18.4: shown in engineering units, B in mm and bias in mrad, no longer in m and rad)
            number = f"{n} = {shown(n, units[n], final[n]).split(' ')[0]}"
            assert number in text and number in md
    # the amended case (issue 18.4) holds the readings diagnosed (given in memory here) and both
    # instrument errors as parameters: `run` on it gives the final joint fit again
    import geoback

    amended = tmp_path / "amended.yaml"
    assert "given in memory" in amended.read_text()
    res = geoback.run_case(geoback.load_case(amended), tmp_path / "run")
    assert {"B[I1]", "bias[I2]"} <= set(res.keys())
    for e in res:
        assert e.value == pytest.approx(final[e.name], rel=1e-6), e.name
    truth = {"B[I1]": 0.004, "bias[I2]": 4e-4}  # (one draw: within 3 sigma, not necessarily inside the 95 %)
    for n, t in truth.items():
        j = d.final.parameters.names.index(n)
        assert abs(final[n] - t) < 3 * d.final.reliability.std[j]


def test_deep_rigid_stratum_is_a_tentative_answer():
    """A rigid stratum below 30 m: the boundary is found, but its modulus is not determined by the
    readings, so the answer is tentative (said so), with an open profile-likelihood interval."""
    import numpy as np
    import yaml

    from geoback.case.loading import LoadedCase, case_from_data
    from geoback.reports.diagnosis_report import verdict
    from geoback.inference.identification import prepare
    from geoback.inference.synthetic import synthetic_readings

    loaded = load_case(CONCEALED / "null-1.yaml")
    data = yaml.safe_load((CONCEALED / "null-1.yaml").read_text())
    data["ground"]["layers"].append({"name": "rock", "top": 30.0, "E": 2.0e6, "nu": 0.3})
    for ins in data["instruments"]:
        ins.pop("readings_file", None)
    truth = LoadedCase(case_from_data(data), loaded.path, {})
    readings = synthetic_readings(truth, refine=2.0, noise_seed=7)
    analysis = prepare(loaded)
    analysis = analysis.with_readings(np.concatenate([readings[b.name] for b in analysis.simulation.survey.blocks]))
    d = diagnose(analysis)
    s = d.accepted[0]
    assert s.hypothesis.kind == "layer-boundary" and not s.determined and d.rounds[0].tentative
    prof = d.depth_profile(s)
    assert prof.low <= 30.0 <= prof.high
    assert d.open_ends("E[clay_below]") == (False, True)  # bounded below only
    assert "TENTATIVE" in verdict(d)


def test_error_scales_example_names_the_instrument_and_refits_no_searched_boundary():
    """The error-scales example (X1 read 3.5x less accurately than stated) scored with the scales at
    their null estimates: the verdict is X1's stated sigma, no hypothesis is accepted and no layer
    boundary is searched in depth (with a misfit that whitened by the stated C_x it was, at
    p = 4.9e-5, and `diagnose` took 40x longer; tests/test_misfit_derived.py)."""
    d = diagnose(load_case(CASES / "tunnel-paper-error-scales.yaml"))
    assert d.accepted == []
    assert all(r.accepted is None for r in d.rounds)
    refitted = [s.hypothesis.key for r in d.rounds for s in r.ranking if s.refit is not None]
    assert not any(k.startswith("layer-boundary") for k in refitted), refitted
    assert d.rounds[0].threshold is not None
    first = d.rounds[0]
    scored = [s for s in first.ranking if s.collinear_with is None  # (no score test: yielding, a support)
              and not s.hypothesis.key.startswith(("yielding", "supported-release"))]
    assert scored and all(s.p_score >= first.threshold for s in scored)
    assert first.mismatches[0].instrument == "X1"


def _logged(name: str, depth: float):
    """A shipped concealed case whose boreholes log the strata to `depth` (ground: logged_to)."""
    loaded = load_case(CONCEALED / f"{name}.yaml")
    ground = loaded.case.ground.model_copy(update={"logged_to": depth})
    return loaded.with_case(loaded.case.model_copy(update={"ground": ground}))


def test_strata_logged_by_boreholes_keep_the_boundary_search_below_them():
    """ground.logged_to = 12 m (the stiffer sand begins at 16 m): no boundary is proposed above 12 m,
    the depth profile searches 12-40 m and still finds 16 m with its interval, and the report says
    what was not tested and why. Logged to the model's bottom: no boundary is proposed at all."""
    from geoback.diagnosis.hypotheses import candidate_hypotheses
    from geoback.inference.identification import prepare
    from geoback.reports.diagnosis_report import diagnosis_json, diagnosis_text

    d = diagnose(_logged("layer-boundary", 12.0))
    proposed = [z for r in d.rounds for s in r.ranking if s.hypothesis.kind == "layer-boundary"
                for key, z in s.hypothesis.extra_values.items() if key.startswith("zsplit")]
    assert proposed and min(proposed) > 12.0, proposed
    s = d.accepted[0]
    assert s.hypothesis.kind == "layer-boundary" and s.grade == "named"
    prof = d.depth_profile(s)
    assert prof.lo_limit == 12.0 and prof.low <= 16.0 <= prof.high and not prof.low_open
    assert all(z >= 12.0 for z, _, _ in prof.points)
    md = diagnosis_text(d)
    assert ("Not tested: layer-boundary (a layer boundary with a different modulus below it): not above 12 m, the "
            "depth the case's boreholes log the strata to (ground: logged_to); below it, tested.") in md
    assert diagnosis_json(d)["not_tested"][-1]["kind"] == "layer-boundary"

    a = prepare(_logged("layer-boundary", 40.0))
    kinds = {h.kind for h in candidate_hypotheses(a.misfit, a.parameters.initial)}
    assert "layer-boundary" not in kinds and "stiffness-gradient" in kinds, kinds


def test_a_profile_reaching_the_logged_depth_says_so():
    """An interval open at the shallow end of the search says which end it is: the layer's top, or the
    depth the strata are logged to."""
    from geoback.diagnosis.depth import profile_depth

    def refit_at(z, near):  # J falls towards the shallow end: the interval is open there
        return type("S", (), {"refit": type("F", (), {"J": 20 + 30 * max(0.0, z - 14.0), "p": np.array([z])})(),
                              "reliability": None})()

    prof = profile_depth("clay", refit_at, 12.0, 40.0, [13, 20, 30], tol=0.02,
                         lo_words="the depth the strata are logged to")
    assert prof.low_open and prof.interval_text().startswith("the depth the strata are logged to (12 m)")
