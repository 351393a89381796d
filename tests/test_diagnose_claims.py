"""Issue 24: a diagnosis that knows the edge of its library. Refits never worse than the model they
extend, no interval at a search bound, a cause tested as a claim (cross-validation across instruments,
residual structure, rivals of other families) and graded (named / explained but not singled out /
no effect the library can detect), and the rival family a one-step model lacks (a support before the
full release)."""
from __future__ import annotations

import copy
import importlib.util
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from conftest import CASES
from geoback.case.loading import LoadedCase, case_from_data, load_case
from geoback.diagnosis import diagnose
from geoback.diagnosis.claims import _runs_z, left_out_scores
from geoback.errors import GeobackError

CONCEALED = CASES / "concealed"
BENCH = Path(__file__).resolve().parents[1] / "benchmarks" / "diagnosis_accuracy.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("diagnosis_accuracy", BENCH)
    mod = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("diagnosis_accuracy", mod)
    spec.loader.exec_module(mod)
    return mod


def test_runs_statistic_counts_runs_of_one_sign():
    assert _runs_z(np.array([1.0, -1.0] * 10)) > 3  # alternating: many runs
    assert _runs_z(np.ones(16)) == pytest.approx(-4.0)  # one sign throughout
    assert _runs_z(np.array([1.0] * 8 + [-1.0] * 8)) < -3  # two runs only
    rng = np.random.default_rng(3)
    z = [_runs_z(rng.standard_normal(40)) for _ in range(400)]
    assert abs(np.mean(z)) < 0.15 and 0.85 < np.std(z) < 1.15  # N(0, 1) under the null


def _scored(J0, J_refit):
    from geoback.diagnosis.hypotheses import Hypothesis
    from geoback.diagnosis.results import Scored
    from geoback.case.loading import Parameter

    h = Hypothesis("k", "anisotropy", "t", "d", [Parameter(name="n[clay]", initial=1.0, bounds=(0.2, 5.0))])
    s = Scored(h, 1.0, 1, 0.5)
    s.misfit = SimpleNamespace(free=False)
    s.refit = SimpleNamespace(J=J_refit, status="converged", history=())
    s.reliability = SimpleNamespace(aic=J_refit + 2, bic=J_refit + 3, whitened_residual=np.zeros(10))
    return s


def test_a_refit_above_its_base_is_no_improvement():
    from geoback.diagnosis.refit import compare

    s = _scored(100.0, 119.2)  # the round-2 refit: 'converged', 19.2 above the model it extends
    compare(s, 100.0, 0)
    assert s.worse and not s.settled and s.p_lr == 1.0
    s = _scored(100.0, 90.0)
    compare(s, 100.0, 0, J_null=95.0)  # another mesh's null lower than the base's: its own gain is not an effect
    assert not s.worse and s.dJ == pytest.approx(5.0)


def test_a_split_layer_with_a_gradient_starts_as_the_model_it_extends(tmp_path, monkeypatch):
    """Round 2 after a gradient was accepted: the split's lower part inherits the gradient and starts at
    the layer's modulus at the split depth, so the split at its null value is the current model (its
    objective differs by the split mesh only); the refit ends no higher than that."""
    monkeypatch.setenv("GEOBACK_CACHE", str(tmp_path / "cache"))
    from geoback.case.loading import Parameter
    from geoback.diagnosis.boundary import _split_layer_misfit, null_modulus
    from geoback.diagnosis.refit import fit_and_assess, null_start
    from geoback.inference.estimate import fit
    from geoback.inference.identification import prepare

    a = prepare(load_case(CONCEALED / "stiffness-gradient.yaml"))
    base = fit(a.misfit, a.settings)
    cur = a.misfit.extended([Parameter(name="Egrad[clay]", initial=0.0, bounds=(-500.0, 5000.0))], start=base.p)
    cf = fit(cur, a.settings)
    assert cf.J < base.J - 50  # the gradient explains the readings
    loaded, case = cur.simulation.loaded, cur.simulation.loaded.case
    z = 14.0
    E_null = null_modulus(cur, cf.p, "clay", z, 0.0)
    split = _split_layer_misfit(cur, case, loaded, "clay", z, cf.p, E_null)
    J_null = split.evaluate(null_start(split)).J
    assert abs(J_null - cf.J) < 0.05 * cf.J + 2.0  # the split mesh alone
    # as before the fix: the lower part without the gradient, from the modulus at the layer's top
    E_top = cur.values(cf.p)["E[clay]"]
    old = _split_layer_misfit(cur, case, loaded, "clay", z, cf.p, E_top)
    old = old.extended([], values={"Egrad[clay_below]": 0.0})
    assert old.evaluate(null_start(old)).J - cf.J > 10 * abs(J_null - cf.J)
    res, _ = fit_and_assess(split, a.settings, "lm", 100, starts=[null_start(split), np.r_[cf.p, E_top]])
    assert res.J <= J_null + 1e-9


def test_left_out_scores_of_a_linear_model_are_the_deleted_residuals():
    """Each instrument's score is its residual at the refit without it against its band; for the fitted
    case model (nearly linear about its optimum) it follows chi^2 of its readings."""
    from geoback.inference.estimate import fit
    from geoback.inference.identification import prepare

    a = prepare(load_case(CONCEALED / "null-1.yaml"))
    f = fit(a.misfit, a.settings)
    scores = left_out_scores(a.misfit, f.p)
    names = {b.name for b in a.misfit.data.blocks}
    assert set(scores) == names
    total = sum(T for T, _ in scores.values())
    m = sum(n for _, n in scores.values())
    assert abs(total - m) < 4 * np.sqrt(2 * m)  # about chi^2(m): no mismatch left out of sample either
    assert total >= f.J - 1e-6  # predicting what was not fitted is never better than fitting it


def test_exclude_names_the_kinds_it_knows():
    with pytest.raises(GeobackError, match="no-such-kind"):
        diagnose(load_case(CONCEALED / "null-1.yaml"), exclude=["no-such-kind"])


def test_a_concealed_effect_left_out_of_the_library_is_not_named():
    """Leave one family out: the K0 gradient (5.3 sigma in the issue was called a depth offset with no
    rival) diagnosed without K0-gradient in the library: whatever improves the fit is not named."""
    d = diagnose(load_case(CONCEALED / "K0-gradient.yaml"), exclude=["K0-gradient"])
    assert not d.adequate_before
    assert d.grade != "named"
    assert all(s.hypothesis.kind != "K0-gradient" for s in d.accepted)
    for s in d.accepted:
        assert s.grade == "explained" and any(not c.passed for c in s.checks.values())


def test_a_supported_tunnel_modelled_in_one_step_is_not_named_a_stratum(bench, tmp_path, monkeypatch):
    """The issue's independent-code case in small: a tunnel lined after a release of 0.5, modelled by
    the engineer as a one-step excavation. A stratum improves the fit most, but the family the model
    lacks (a support before the full release) explains the readings within the evidence: the stratum
    is 'explained but not singled out', with no interval as if found, and the rival is listed."""
    monkeypatch.setenv("GEOBACK_CACHE", str(tmp_path / "cache"))
    from geoback.inference.identification import prepare
    from geoback.inference.synthetic import synthetic_readings
    from geoback.reports.diagnosis_report import diagnosis_json, verdict

    spec = bench.random_case(3, "null", 2024)
    data = copy.deepcopy(spec["data"])
    truth = copy.deepcopy(data)
    R = data["geometry"]["radius"]
    truth["construction"] = {"lining": {"name": "shotcrete", "thickness": round(0.1 * R, 3), "E": 8.0e6, "nu": 0.2},
                             "stages": [{"name": "advance", "release": 0.5},
                                        {"name": "excavation", "install": "shotcrete", "release": 1.0}]}
    path = tmp_path / f"{data['name']}.yaml"
    loaded = LoadedCase(case_from_data(data), path, {})
    clean = synthetic_readings(LoadedCase(case_from_data(truth), path, {}), refine=2.0)
    problem = prepare(loaded, with_readings=False)
    problem = problem.with_readings(bench._stack(bench._with_noise(clean, loaded, spec["noise_seed"]), problem))
    d = diagnose(problem)
    support = [s for s in d.rounds[0].ranking if s.hypothesis.kind == "supported-release"]
    assert support and support[0].settled and support[0].p_lr < d.rounds[0].threshold
    assert d.accepted and d.grade == "explained"
    acc = d.accepted[0]
    if acc.family != "release":  # named otherwise: the release family is the truth's
        assert any(r.hypothesis.kind == "supported-release" for r in acc.rivals)
        words = verdict(d)
        assert "EXPLAINED BUT NOT SINGLED OUT" in words and "supported before the full release" in words
        js = diagnosis_json(d)
        assert js["grade"] == "explained but not singled out"
        assert all(e["ci95"] is None for e in js["missing"][0]["estimates"].values())
        assert js["missing"][0]["rivals"][0]["kind"] == "supported-release"


def test_a_score_test_alone_never_makes_a_model_inadequate(bench, tmp_path, monkeypatch):
    """A null case of the accuracy benchmark (bench-063: noise only) whose chi^2 passes but whose K0-gradient
    score test is below the level: with no round left to refit it (max_rounds=0) the model is adequate,
    the score test a linear approximation no refit confirmed."""
    monkeypatch.setenv("GEOBACK_CACHE", str(tmp_path / "cache"))
    from geoback.inference.identification import prepare
    from geoback.inference.synthetic import synthetic_readings

    spec = bench.random_case(63, "null", 2024)
    loaded = LoadedCase(case_from_data(copy.deepcopy(spec["data"])), tmp_path / "null.yaml", {})
    problem = prepare(loaded, with_readings=False)
    clean = synthetic_readings(loaded, refine=2.0)
    problem = problem.with_readings(bench._stack(bench._with_noise(clean, loaded, spec["noise_seed"]), problem))
    d = diagnose(problem, max_rounds=0)
    r = d.rounds[0]
    assert r.p_value >= d.alpha
    assert min(s.p_score for s in r.ranking if s.collinear_with is None) < r.threshold  # a score test fires
    assert r.adequate and d.adequate_after and not d.accepted and d.grade == "none"


def _instrument_error_refit(name: str, key: str):
    """A concealed case's baseline fitted, then refitted with the instrument error `key` (real FE runs)."""
    from geoback.diagnosis.hypotheses import candidate_hypotheses
    from geoback.inference.estimate import fit
    from geoback.inference.identification import prepare

    a = prepare(load_case(CONCEALED / f"{name}.yaml"))
    f = fit(a.misfit, a.settings)
    h = next(h for h in candidate_hypotheses(a.misfit, f.p) if h.key == key)
    ext = a.misfit.extended(h.parameters, h.extra_values, start=f.p)
    fe = fit(ext, a.settings)
    assert fe.J < f.J
    return ext, fe, f


def test_an_error_of_one_instrument_must_explain_the_readings_alone():
    """Check 5: the bias shift of I2 that the concealed case hides explains the readings alone; the same
    hypothesis on the stiffness-gradient case (I2's readings improved by 17, the gradient showing at I1,
    X1 and S as well) does not: cross-validation cannot tell them apart (the bias is not informed with
    I2 left out), this check does."""
    from geoback.diagnosis.claims import _left_out, instrument_alone, single_instrument

    assert single_instrument(["bias[I2]"]) == "I2" and single_instrument(["B[I1]"]) == "I1"
    assert single_instrument(["Egrad[clay]"]) is None and single_instrument(["B[I1]", "B[I2]"]) is None
    ext, fe, _ = _instrument_error_refit("bias-shift", "bias-shift[I2]")
    scores = _left_out(ext, fe.p)
    assert scores["I2"][2] == scores["I2"][1] - 1  # I2 left out: its bias is not informed, one dof less
    assert all(dof == m for k, (_, m, dof, _) in scores.items() if k != "I2")
    c = instrument_alone(ext, fe.p, "I2")
    assert c.passed and c.name == "instrument-alone"
    rest = c.detail["tests"]["the other instruments fitted without I2"]
    m_rest = len(ext.data.measured) - scores["I2"][1]
    assert rest["dof"] == m_rest - 2  # E and K0 are informed by the others, bias[I2] is not
    assert rest["p_value"] > 0.05

    ext, fe, base = _instrument_error_refit("stiffness-gradient", "bias-shift[I2]")
    assert base.J - fe.J > 10  # the bias improves the fit a lot ...
    c = instrument_alone(ext, fe.p, "I2")
    assert not c.passed  # ... but the other instruments keep the gradient's signature
    assert c.detail["tests"]["the other instruments fitted without I2"]["p_value"] < c.detail["level"]
    assert "alone does not explain" in c.text


def test_a_stiffness_gradient_left_out_is_not_named_a_bias_shift(bench, tmp_path, monkeypatch):
    """The leave-one-family-out benchmark's bench-010 (seed 2024): a stiffness gradient (7.5 sigma) with the
    gradient family removed was named a bias shift of I2 (it improves J by 44, no rival within 10 AIC,
    and cross-validation passes: it cannot test a hypothesis on one instrument). Now 'explained but not
    singled out': an error of I2 alone leaves X1 predicted outside its band."""
    monkeypatch.setenv("GEOBACK_CACHE", str(tmp_path / "cache"))
    from geoback.inference.identification import prepare
    from geoback.inference.synthetic import synthetic_readings

    spec = bench.random_case(10, "stiffness-gradient", 2024, strong=True)
    loaded = LoadedCase(case_from_data(copy.deepcopy(spec["data"])), tmp_path / "case.yaml", {})
    clean = synthetic_readings(loaded, refine=2.0, values=spec["values"])
    problem = prepare(loaded, with_readings=False)
    problem = problem.with_readings(bench._stack(bench._with_noise(clean, loaded, spec["noise_seed"]), problem))
    d = diagnose(problem, exclude=sorted(bench.left_out("stiffness-gradient")))
    assert d.accepted and d.accepted[0].hypothesis.kind == "bias-shift"
    acc = d.accepted[0]
    assert acc.checks["cross-validation"].passed  # the old checks all pass ...
    assert not acc.checks["instrument-alone"].passed  # ... this one does not
    assert acc.grade == "explained" and d.grade == "explained"


def test_a_cause_that_leaves_the_model_inadequate_is_not_named():
    """Check 6, the issue's 'a yielding case called a layer boundary that stayed inadequate': the concealed
    yielding case diagnosed without yielding in the library. The stratum passes the other checks of its round
    (determined, cross-validation, no rival within 10 AIC) and leaves no structure (check 8, the readings below
    it, fails as well), but the final model still fails its chi^2 test: the library lacks something the stratum may stand in for, so it is
    explained but not singled out, in words and in diagnosis.json."""
    from geoback.reports.diagnosis_report import diagnosis_json

    d = diagnose(load_case(CONCEALED / "yielding.yaml"), exclude=["yielding"])
    assert d.accepted and d.accepted[0].hypothesis.kind == "layer-boundary"
    first = d.accepted[0]
    assert all(c.passed for k, c in first.checks.items() if k not in ("adequacy", "boundary-seen"))
    # check 8: the inclinometer readings below 20 m follow only part of the change the stratum makes there
    seen = first.checks["boundary-seen"]
    assert not seen.passed and seen.detail["testable"] and seen.detail["z"] < seen.detail["needed"]
    rel = d.final.reliability
    assert rel.p_value < 0.01 and not first.checks["adequacy"].passed
    # the causes after it are not singled out: it is judged by the model at the end of its own round
    assert first.checks["adequacy"].detail["chi2"] == pytest.approx(d.rounds[1].chi2)
    assert first.checks["adequacy"].detail["without"] == [s.hypothesis.title for s in d.accepted[1:]]
    assert all(s.grade == "explained" for s in d.accepted) and d.grade == "explained"
    deep = [s for s in d.accepted[1:] if s.hypothesis.kind == "layer-boundary"]  # a second stratum below 35 m
    assert deep
    for s in deep:  # (check 8: below the inclinometers' toes at 30 m, but its 95 % interval reaches up within them:
        seen = s.checks["boundary-seen"]  # nothing to test it with, said so with the depth to reach)
        assert seen.passed and seen.detail["readings_below"] == 0 and seen.detail["reached"]
        assert seen.detail["reach"] == pytest.approx(30.0) and seen.detail["depth"] > 30.0
        assert "the instruments reach 30 m, I1's reference end, and its 95 % interval reaches up to" in seen.text
        assert f"an instrument reading below {seen.detail['depth']:.3g} m would test it" in seen.text
    js = diagnosis_json(d)
    assert js["grade"] == "explained but not singled out"
    assert js["missing"][0]["checks"]["adequacy"]["passed"] is False
    assert all(e["ci95"] is None for e in js["missing"][0]["estimates"].values())


def test_adequacy_is_judged_at_the_level_the_verdict_calls_a_model_adequate():
    """Check 6 at the diagnosis' level (0.05), not at the other checks' 0.01: the leave-one-family-out
    benchmark named a yielding zone standing in for a stratum (seed 2027, bench-027) with a final model at
    chi^2 = 57.27 on 36 dof, p = 0.0135, while its verdict said "still not adequate"."""
    from scipy.stats import chi2

    from geoback.diagnosis import claims

    p = float(chi2.sf(57.27, 36))
    assert 0.01 < p < 0.05
    check = claims.adequacy(57.27, 36, p, 0.05)
    assert not check.passed and "still does not explain" in check.text and check.detail["level"] == 0.05
    assert claims.adequacy(40.0, 36, float(chi2.sf(40.0, 36)), 0.05).passed
    assert claims.adequacy(0.0, 0, float("nan"), 0.05).passed  # nothing left to test it with


def _refitted(name: str, key: str):
    """A concealed case's baseline fit and a Scored refit of hypothesis `key`, judged as diagnose judges it."""
    from geoback.diagnosis.hypotheses import candidate_hypotheses
    from geoback.diagnosis.refit import REFIT_ITERATIONS, compare, fit_and_assess, judge
    from geoback.diagnosis.results import Scored
    from geoback.inference.estimate import fit
    from geoback.inference.identification import prepare

    a = prepare(load_case(CONCEALED / f"{name}.yaml"))
    f = fit(a.misfit, a.settings)
    h = next(h for h in candidate_hypotheses(a.misfit, f.p) if h.key == key)
    s = Scored(h, 0.0, len(h.parameters), 1.0, misfit=a.misfit.extended(h.parameters, h.extra_values, start=f.p))
    s.refit, s.reliability = fit_and_assess(s.misfit, a.settings, "lm", REFIT_ITERATIONS)
    compare(s, f.J, 0)
    judge(s)
    return a, f, s


def test_a_rival_that_fails_its_own_claim_checks_does_not_block_a_verdict():
    """Check 3: a rival of another family blocks the verdict only when it passes the checks of its round
    itself. On the stiffness-gradient case a bias shift of I2 improves the fit, but an error of I2 alone
    does not explain the readings: dismissed, and said so. On the bias-shift case the same hypothesis
    (the truth) passes them: a rival that stands."""
    from geoback.diagnosis.claims import credible, rival_check

    a, f, s = _refitted("stiffness-gradient", "bias-shift[I2]")
    assert s.settled and s.dJ > 10
    assert not credible(s, a.misfit, f.p)
    assert s.checks["cross-validation"].passed and not s.checks["instrument-alone"].passed
    assert not s.checks["cross-validation"].detail["beyond_linear"]  # a bias is linear in its parameter
    acc = SimpleNamespace(aic=s.aic - 3.0, reliability=SimpleNamespace(reduced_chi2=1.0, p_value=0.5))
    c = rival_check(acc, [], [s])
    assert c.passed and c.detail["dismissed"] == ["bias-shift[I2]"]
    assert "fails its own claim checks (instrument-alone)" in c.text

    a, f, s = _refitted("bias-shift", "bias-shift[I2]")
    assert credible(s, a.misfit, f.p) and all(ch.passed for ch in s.checks.values())
    c = rival_check(acc, [s])
    assert not c.passed and c.detail["rivals"] == ["bias-shift[I2]"]


def _bench_problem(bench, tmp_path, index: int, kind: str):
    """Case `index` of the leave-one-family-out benchmark (seed 2024, upper-half effects): its baseline
    model with the truth's readings (a mesh twice as fine, instrument noise), as run_one builds them."""
    from geoback.inference.identification import prepare
    from geoback.inference.synthetic import synthetic_readings

    spec = bench.random_case(index, kind, 2024, strong=True)
    assert not spec["extra_layer"] and not spec.get("strength")  # the truth is the case with other values
    loaded = LoadedCase(case_from_data(copy.deepcopy(spec["data"])), tmp_path / "case.yaml", {})
    clean = synthetic_readings(loaded, refine=2.0, values=spec["values"])
    problem = prepare(loaded, with_readings=False)
    return problem.with_readings(bench._stack(bench._with_noise(clean, loaded, spec["noise_seed"]), problem))


def test_a_stratum_whose_depth_is_not_determined_is_not_named(bench, tmp_path, monkeypatch):
    """Check 4 for a layer boundary: the leave-one-family-out benchmark's bench-018 (32 cases, seed 2024), a
    release beta = 0.79 diagnosed without the release family, named 'a stratum below 0.36 m' whose
    depth interval ran to the layer's top [0, 3.95]: the readings say the layer differs, not where a
    stratum begins. Now explained but not singled out, said so in its determined check."""
    monkeypatch.setenv("GEOBACK_CACHE", str(tmp_path / "cache"))
    problem = _bench_problem(bench, tmp_path, 18, "stress-release")
    d = diagnose(problem, exclude=sorted(bench.left_out("stress-release")))
    acc = d.accepted[0]
    assert acc.hypothesis.kind == "layer-boundary" and acc.profile is not None
    assert acc.profile.low_open and acc.profile.low == pytest.approx(acc.profile.lo_limit)
    c = acc.checks["determined"]
    assert not c.passed and "reaches the layer's top" in c.text and c.detail["open"][0]
    assert acc.grade == "explained" and d.grade == "explained"


def test_a_parameter_whose_final_interval_is_open_is_not_determined():
    """Check 4 again in the final joint fit (claims.final_determined): an end of an accepted parameter's
    95 % interval at a limit the readings do not move it from fails the check, naming the end; closed
    intervals leave the round's check as it was."""
    from geoback.diagnosis.claims import final_determined

    s = SimpleNamespace(hypothesis=SimpleNamespace(names=["c[clay]", "phi[clay]"]))
    assert final_determined(s, lambda name: (False, False)) is None
    c = final_determined(s, lambda name: (name == "c[clay]", False))
    assert not c.passed and c.name == "determined"
    assert "c[clay] (its lower end)" in c.text and "phi[clay]" not in c.text
    assert c.detail["open"] == {"c[clay]": [True, False]}


def test_a_cause_after_it_that_is_not_named_does_not_take_its_determination():
    """regrade_final, last cause first: the last cause's open interval fails it; an earlier cause's open interval
    fails it only while every cause after it is named (seed 2025's bench-040: a true yielding zone whose c'
    interval opened only beside a K0 gradient accepted after it that fails cross-validation)."""
    from geoback.diagnosis.claims import Check, regrade_final

    def cause(name, passed=True):
        return SimpleNamespace(hypothesis=SimpleNamespace(names=[name]), grade="named" if passed else "explained",
                               checks={"determined": Check("determined", True, ""),
                                       "cross-validation": Check("cross-validation", passed, "")})

    everything_open = lambda name: (False, True)  # noqa: E731
    first, second = cause("c[clay]"), cause("K0grad", passed=False)  # the later cause is a surrogate
    regrade_final([first, second], everything_open)
    assert first.grade == "named" and first.checks["determined"].passed
    assert not second.checks["determined"].passed and second.grade == "explained"
    first, second = cause("c[clay]"), cause("K0grad")
    regrade_final([first, second], lambda name: (False, name == "c[clay]"))  # the later one named: it counts
    assert second.grade == "named" and first.grade == "explained" and not first.checks["determined"].passed


def _graded_cause(title: str, passed: bool, check: str, final: tuple):
    """An accepted cause as regrade_final sees it: determined, `check` passed or not (its grade follows), and
    the final model's adequacy (chi^2, dof, p) at the 5 % level."""
    from geoback.diagnosis.claims import Check, adequacy

    return SimpleNamespace(hypothesis=SimpleNamespace(names=[title], title=title, key=title, group=""),
                           grade="named" if passed else "explained",
                           checks={"determined": Check("determined", True, ""), check: Check(check, passed, ""),
                                   "adequacy": adequacy(*final, 0.05)})


def test_a_cause_that_explains_the_readings_only_with_a_cause_not_singled_out_is_not_named():
    """Check 6 again once every cause is graded (regrade_final with the rounds): a cause accepted before a cause
    that is not singled out is judged by the model at the end of its own round, not by the final one; a cause
    followed only by named causes keeps the final model's verdict."""
    from geoback.diagnosis.claims import regrade_final

    def cause(title, passed=True):
        return _graded_cause(title, passed, "cross-validation", (50.0, 36, 0.06))

    closed = lambda name: (False, False)  # noqa: E731
    rounds = [SimpleNamespace(chi2=115.1, dof=38, p_value=1e-9, ranking=[]),
              SimpleNamespace(chi2=62.8, dof=37, p_value=0.005, ranking=[]),
              SimpleNamespace(chi2=50.0, dof=36, p_value=0.06, ranking=[])]
    first, second = cause("a stratum"), cause("a bias shift", passed=False)
    regrade_final([first, second], closed, rounds, 0.05)
    a = first.checks["adequacy"]
    assert not a.passed and first.grade == "explained" and second.grade == "explained"
    assert a.detail["without"] == ["a bias shift"] and a.detail["chi2"] == 62.8 and a.detail["dof"] == 37
    assert "only with a bias shift added" in a.text and "p = 0.005 < 0.05" in a.text
    b = second.checks["adequacy"]  # and the bias, accepted after the stratum, is judged without it (not refitted)
    assert not b.passed and b.detail["without"] == ["a stratum"] and not b.detail["refitted"]
    rounds[1].p_value = 0.2  # its own round's model explains the readings: the later surrogate takes nothing away
    first, second = cause("a stratum"), cause("a bias shift", passed=False)
    regrade_final([first, second], closed, rounds, 0.05)
    assert first.grade == "named" and "without a bias shift" in first.checks["adequacy"].text
    rounds[1].p_value = 0.005  # the later cause named: the final model's verdict holds for both
    first, second = cause("a stratum"), cause("a bias shift")
    regrade_final([first, second], closed, rounds, 0.05)
    assert first.grade == second.grade == "named" and "without" not in first.checks["adequacy"].detail


def test_a_cause_accepted_after_a_cause_not_singled_out_is_judged_without_it():
    """Check 6, first cause first: a cause accepted after a cause that is not singled out is judged by its own
    refit in the round where that cause was accepted (the model with it and without the helper): the leave-out
    benchmark's 2031 bench-026, a stratum explained by X1's anchor (not singled out) and then a bias shift of
    I1 (chi^2 154 on 23 dof on its own in round 1). A cause not refitted in that round fails; one whose own
    refit there explains the readings keeps its name."""
    from geoback.diagnosis.claims import regrade_final

    def cause(title, passed=True):
        return _graded_cause(title, passed, "installation-record", (20.8, 22, 0.54))

    def refit(title, chi2, dof, p_value):
        return SimpleNamespace(hypothesis=SimpleNamespace(key=title, group=""), settled=True,
                               reliability=SimpleNamespace(chi2=chi2, dof=dof, p_value=p_value))

    closed = lambda name: (False, False)  # noqa: E731
    rounds = [SimpleNamespace(chi2=163.0, dof=24, p_value=1e-22, ranking=[refit("an anchor", 33.8, 23, 0.067),
                                                                          refit("a bias shift", 153.6, 23, 2.7e-21)]),
              SimpleNamespace(chi2=33.8, dof=23, p_value=0.067, ranking=[]),
              SimpleNamespace(chi2=20.8, dof=22, p_value=0.54, ranking=[])]
    first, second = cause("an anchor", passed=False), cause("a bias shift")
    regrade_final([first, second], closed, rounds, 0.05)
    a = second.checks["adequacy"]
    assert not a.passed and second.grade == "explained" and first.grade == "explained"
    assert a.detail["without"] == ["an anchor"] and a.detail["chi2"] == 153.6 and a.detail["refitted"]
    assert "does not explain the readings without an anchor, which is not singled out" in a.text
    rounds[0].ranking[1] = refit("a bias shift", 30.2, 23, 0.14)  # on its own it explains them: named
    first, second = cause("an anchor", passed=False), cause("a bias shift")
    regrade_final([first, second], closed, rounds, 0.05)
    assert second.grade == "named" and "explains the readings without an anchor" in second.checks["adequacy"].text
    del rounds[0].ranking[1]  # not refitted without the helper: the readings call for it only beside it
    first, second = cause("an anchor", passed=False), cause("a bias shift")
    regrade_final([first, second], closed, rounds, 0.05)
    assert second.grade == "explained" and not second.checks["adequacy"].detail["refitted"]
    first, second = cause("an anchor"), cause("a bias shift")  # every cause named: the final model judges both
    regrade_final([first, second], closed, rounds, 0.05)
    assert first.grade == second.grade == "named" and "without" not in second.checks["adequacy"].detail


def test_a_reference_end_moved_beyond_what_the_case_states_contradicts_it():
    """Check 10: X1 states its anchor to 0.1 mm (var_a = 1e-8 m^2). On the concealed stratum case a moved anchor
    explains much of the misfit (J falls by 239) with A = -5.7 mm, 57 times what the case states: it contradicts
    the installation record. On a null case the anchor's refit stays within the record and passes. For a lone
    constant the statistic is the likelihood ratio's (the baseline's C_x already lets A vary by var_a); an
    inclinometer whose record states nothing (var_b = 0) is not tested."""
    from geoback.diagnosis.claims import Check, credible, rival_check, stated_record

    _, f, s = _refitted("layer-boundary", "integration-constant[X1]")
    c = stated_record(s)
    assert not c.passed and c.name == "installation-record" and c.detail["p_value"] < c.detail["level"] == 0.01
    assert c.detail["stated_std"] == {"A[X1]": pytest.approx(1e-4)}
    assert -7e-3 < c.detail["estimate"]["A[X1]"] < -4e-3
    assert c.detail["chi2"] == pytest.approx(s.dJ, rel=1e-2)
    assert "A[X1] = -5.7" in c.text and "the ±0.1 mm the case states (var_a)" in c.text
    assert "contradicts what the case states" in c.text
    # as a rival it is not dismissed (a stated precision does not rule out a gross error of the record): it
    # keeps the accepted cause from being singled out, and says what it needs
    s.checks = {"determined": Check("determined", True, ""), "installation-record": c}
    assert credible(s, None, None)
    acc = SimpleNamespace(aic=s.aic - 5.0, reliability=SimpleNamespace(reduced_chi2=0.9, p_value=0.6))
    r = rival_check(acc, [s])
    assert not r.passed and "extensometer X1: anchor moved (ΔAIC +5, if the case's record of its reference end is " \
                            "wrong)" in r.text
    _, f, s = _refitted("null-1", "integration-constant[X1]")
    c = stated_record(s)
    assert c.passed and c.detail["chi2"] == pytest.approx(s.dJ, rel=1e-2) and c.detail["p_value"] > 0.5
    _, f, s = _refitted("null-1", "integration-constant[I1]")
    assert stated_record(s) is None


@pytest.mark.slow
def test_a_stratum_named_a_moved_anchor_against_the_record_is_not_named(bench, tmp_path, monkeypatch):
    """The leave-one-family-out benchmark's bench-012 (seed 2035): a stratum 3.6 times stiffer below 18.2 m
    (36 sigma) diagnosed without strata and modulus gradients was named "X1's anchor moved 12 mm" (every check
    of its round passed, the final model adequate). The case states that anchor to 0.1 mm: explained, not
    named, in words that point at the record (about 30 s)."""
    d = _leave_out_diagnosis(bench, tmp_path, monkeypatch, 2035, 12, "layer-boundary")
    acc = d.accepted[0]
    assert acc.hypothesis.key == "integration-constant[X1]" and d.adequate_after
    c = acc.checks["installation-record"]
    assert not c.passed and c.detail["estimate"]["A[X1]"] < -0.01 and c.detail["stated_std"]["A[X1]"] == 1e-4
    assert all(ch.passed for k, ch in acc.checks.items() if k != "installation-record")  # the only check it fails
    assert acc.grade == "explained" and d.grade == "explained"


def _leave_out_problem(bench, tmp_path, seed: int, index: int, kind: str):
    """Case `index` of the leave-one-family-out benchmark (32 concealed cases, upper-half effects), its truth
    on a mesh twice as fine with instrument noise, as run_one builds it (a stratum's truth included)."""
    spec = bench.random_case(index, kind, seed, strong=True)
    return bench.truth_readings(spec, str(tmp_path))[2]


def _leave_out_diagnosis(bench, tmp_path, monkeypatch, seed: int, index: int, kind: str):
    """That case diagnosed with its truth's family left out of the library, as the benchmark does."""
    monkeypatch.setenv("GEOBACK_CACHE", str(tmp_path / "cache"))
    problem = _leave_out_problem(bench, tmp_path, seed, index, kind)
    return diagnose(problem, exclude=sorted(bench.left_out(kind)))


@pytest.mark.slow
def test_a_yielding_zone_standing_in_for_a_stratum_is_not_named(bench, tmp_path, monkeypatch):
    """The leave-one-family-out benchmark's bench-027 (seed 2024): a stiffer stratum 2.1 m below the invert
    (E2/E = 2.9, 15 sigma) diagnosed without the stratum family was named yielding (c' = 26.1 +- 1.7 kPa,
    every check of its round passed, the final model adequate), the refit making the ground 2.3x stiffer
    away from a wide plastic zone. Its strength's 95 % profile interval in the final joint fit runs down to
    the search bound: the readings do not bound it, so it is not determined and not named (about 30 s)."""
    d = _leave_out_diagnosis(bench, tmp_path, monkeypatch, 2024, 27, "layer-boundary")
    acc = d.accepted[0]
    assert acc.hypothesis.kind == "yielding" and d.adequate_after
    assert d.open_ends("c[clay]")[0]
    c = acc.checks["determined"]
    assert not c.passed and "c[clay] (its lower end)" in c.text and c.detail["open"]["c[clay]"] == [True, False]
    assert all(ch.passed for k, ch in acc.checks.items() if k != "determined")  # the only check it fails
    assert acc.grade == "explained" and d.grade == "explained"


@pytest.mark.slow
def test_a_stratum_that_needs_a_helper_not_singled_out_is_not_named(bench, tmp_path, monkeypatch):
    """The leave-one-family-out benchmark's bench-016 (seed 2030): an anisotropic ground (n = 1.28, 7.4 sigma)
    diagnosed without anisotropy in the library. A stratum 10 % stiffer below 12 m (the tunnel's invert) was
    accepted and passed every check it could take in its round; the readings still needed more (chi^2 62.8
    on 37 dof, p = 0.005), and a bias shift of I1 accepted next, not singled out from a modulus gradient,
    made the final model adequate. The stratum explains the readings only with that helper: not named
    (about 35 s)."""
    d = _leave_out_diagnosis(bench, tmp_path, monkeypatch, 2030, 16, "anisotropy")
    first, second = d.accepted
    assert first.hypothesis.kind == "layer-boundary" and second.hypothesis.kind == "bias-shift"
    assert second.grade == "explained" and d.adequate_after
    a = first.checks["adequacy"]
    assert not a.passed and a.detail["without"] == [second.hypothesis.title]
    assert a.detail["p_value"] < 0.05 and a.detail["dof"] == d.rounds[1].dof
    assert all(c.passed for k, c in first.checks.items() if k != "adequacy")  # the only check it fails
    assert first.grade == "explained" and d.grade == "explained"


def test_a_true_yielding_zone_passes_the_checks_a_surrogate_fails(bench, tmp_path, monkeypatch):
    """The benchmark's yielding case bench-039 (seed 2024: phi' = 26 deg, a plastic zone to 1.36 R), full
    library: yielding named, its strength's interval in the final joint fit closed on both sides (check 4
    again) and the readings nearest the opening carrying a significant part of the gain (check 7)."""
    monkeypatch.setenv("GEOBACK_CACHE", str(tmp_path / "cache"))
    spec = bench.random_yielding_case(39, 2024)
    problem = bench.truth_readings(spec, str(tmp_path))[2]
    d = diagnose(problem)
    acc = d.accepted[0]
    assert acc.hypothesis.kind == "yielding"
    names = [n for n in acc.hypothesis.names if n.startswith("c[")]
    assert names and not any(any(d.open_ends(n)) for n in acc.hypothesis.names)
    assert acc.checks["determined"].passed
    zone = acc.checks["plastic-zone"]
    assert zone.passed and zone.detail["near_gain"] > 50 * zone.detail["needed"]  # 482: the crown anchors
    assert 1.2 < zone.detail["equivalent_radius_over_R"] < 1.6
    assert acc.grade == "named"
    # the strength with phi' and psi not assumed (yielding.strength_profile) holds the truth's c' and s_c
    sp = d.strength[acc.hypothesis.key]
    truth = spec["truth"]
    assert sp.c_low <= truth["c[clay]"] <= sp.c_high and sp.ucs_low <= truth["ucs[clay]"] <= sp.ucs_high


def test_a_release_before_the_lining_is_predicted_stage_by_stage(bench, tmp_path, monkeypatch):
    """Cross-validation across stages (check 1 by stage): the full library's bench-035 of seed 2024, a
    two-stage lined tunnel whose truth releases 0.75 before the lining (23 sigma). The release named
    predicts the readings of each stage, left out, from the other's better than the model without it."""
    monkeypatch.setenv("GEOBACK_CACHE", str(tmp_path / "cache"))
    from geoback.diagnosis.claims import _stage_rows, stages_of

    spec = bench.random_staged_case(35, "release-before-lining", 2024)
    problem = bench.truth_readings(spec, str(tmp_path))[2]
    rows = _stage_rows(problem.misfit.data)
    assert set(rows) == {st["name"] for st in spec["data"]["construction"]["stages"]}
    assert sorted(np.concatenate(list(rows.values())).tolist()) == list(range(problem.misfit.data.m))
    assert stages_of(problem.misfit) == 2
    d = diagnose(problem)
    acc = d.accepted[0]
    assert acc.hypothesis.kind == "release-before-lining" and acc.grade == "named"
    stage = acc.checks["stage-cross-validation"]
    assert stage.passed and set(stage.detail["stages"]) == set(rows)
    assert stage.detail["with"] < stage.detail["without"]


def test_a_yielding_zone_the_near_readings_do_not_see_is_not_named(bench, tmp_path, monkeypatch):
    """Check 7 on the leave-one-family-out benchmark's bench-008 of seed 2025: a stiffness gradient (15 sigma)
    diagnosed without the gradient family was named yielding, the final model adequate (chi^2/dof 0.89).
    Its gain (197) came from the surface settlements 3-6 R from the axis; the four readings within 2 R_eq of
    the opening improve by 1.8: no plastic zone the readings saw. Explained but not singled out."""
    from geoback.diagnosis.claims import NEAR_ZONE

    d = _leave_out_diagnosis(bench, tmp_path, monkeypatch, 2025, 8, "stiffness-gradient")
    acc = d.accepted[0]
    assert acc.hypothesis.kind == "yielding" and d.adequate_after
    zone = acc.checks["plastic-zone"]
    assert not zone.passed and zone.detail["near_gain"] < zone.detail["needed"] < 0.1 * zone.detail["gain"]
    assert f"within {NEAR_ZONE:g} R_eq" in zone.text and "do not show it" in zone.text
    assert acc.grade == "explained" and d.grade == "explained"


def test_a_yielding_truth_that_cannot_be_solved_is_drawn_again(bench, tmp_path, monkeypatch):
    """The benchmark redraws a yielding case whose truth's fine-mesh run does not converge (ForwardFailure),
    deterministically from the seed: draw 1 of the same case number, its stream of its own; the first draw
    of every case stays as it was."""
    from geoback.errors import ForwardFailure
    from geoback.inference import synthetic

    first = bench.random_yielding_case(40, 2024)
    assert first["draw"] == 0 and first["magnitude"] == pytest.approx(66.408, abs=1e-3)  # as drawn before
    again = bench.random_yielding_case(40, 2024, draw=1)
    assert again["draw"] == 1 and again["magnitude"] != first["magnitude"]
    assert bench.random_yielding_case(40, 2024, draw=1)["data"] == again["data"]  # from the seed alone

    seen = []

    class Stop(Exception):
        pass

    def unsolvable_first(loaded, **kw):  # the truth's run: the first draw fails, the test stops at the next
        seen.append(loaded.case.ground.layers[0].c)
        if len(seen) == 1:
            raise ForwardFailure("elastoplastic solution failed (made up by the test)")
        raise Stop

    monkeypatch.setattr(synthetic, "synthetic_readings", unsolvable_first)
    with pytest.raises(Stop):
        bench.truth_readings(first, str(tmp_path))
    assert seen == [pytest.approx(first["strength"]["c"]), pytest.approx(again["strength"]["c"])]
    monkeypatch.setattr(bench, "MAX_DRAWS", 1)
    seen.clear()
    with pytest.raises(ForwardFailure):  # no draws left: the failure is reported
        bench.truth_readings(first, str(tmp_path))


def test_a_stratum_the_readings_below_it_do_not_show_is_not_named(bench, tmp_path, monkeypatch):
    """Check 8 on the leave-one-family-out benchmark's bench-004 of seed 2029: an anisotropic ground (n = 1.62,
    6.8 sigma) diagnosed without anisotropy was named 'a stiffer stratum below 11.6 m', every other check
    passed. The six inclinometer readings below that depth lie on the side of the model without the stratum
    (z = -1.72; their J rises by 2.9 with it) while the stratum moves them by 1.9 sigma: its gain (76) came
    from the readings above. Explained but not singled out, in words."""
    d = _leave_out_diagnosis(bench, tmp_path, monkeypatch, 2029, 4, "anisotropy")
    acc = d.accepted[0]
    assert acc.hypothesis.kind == "layer-boundary"
    seen = acc.checks["boundary-seen"]
    det = seen.detail
    assert det["depth"] == pytest.approx(acc.profile.z_hat)
    assert det["readings_below"] > 0 and det["testable"] and det["change_below"] >= -det["needed"]
    assert det["z"] < det["needed"] == pytest.approx(-1.6449, abs=1e-4)  # one-sided at the diagnosis' level
    assert det["below_gain"] < 0 < 10 * abs(det["below_gain"]) < det["gain"]  # worse below, the gain from above
    assert not seen.passed and "do not follow the change" in seen.text
    assert all(c.passed for k, c in acc.checks.items() if k != "boundary-seen")  # the only check it fails
    assert acc.grade == "explained" and d.grade == "explained"


def test_the_readings_below_a_boundary_are_scored_along_the_change_it_makes_there():
    """Check 8's statistic on given residuals: z = d . r1 / |d| over the readings below the boundary (d = r0 - r1).
    Readings the stratum explains (r1 noise) pass; readings left on the side of the model without it (r1 = -d,
    the base fitted them) fail; a change below smaller than the test's quantile cannot be tested and passes,
    saying the claim rests on the readings above; no reading below says which depth an instrument must reach."""
    from geoback.diagnosis.claims import boundary_seen

    pts = np.array([[5.0, -4.0], [5.0, -8.0], [5.0, -12.0], [5.0, -16.0]])
    block = SimpleNamespace(lengths=None, points=pts, weights=np.eye(4)[:, :, None] * np.array([1.0, 0.0]),
                            stations=pts, name="S1")
    data = SimpleNamespace(block_rows=lambda: [(block, slice(0, 4))])

    def check(r0, r1, depth=10.0, shallowest=None):
        base = SimpleNamespace(evaluate=lambda p: SimpleNamespace(r=np.asarray(r0, float)))
        ext = SimpleNamespace(evaluate=lambda p: SimpleNamespace(r=np.asarray(r1, float)), data=data,
                              values=lambda p: {"E[clay]": 10.0, "E[clay_below]": 25.0})
        return boundary_seen(base, np.zeros(1), ext, np.zeros(1), "clay", depth, 0.05, shallowest)

    told = check([3.0, 1.0, 2.0, 2.0], [0.1, -0.1, 0.1, -0.1])  # below: d = (1.9, 2.1), r1 across it
    assert told.passed and told.detail["testable"] and told.detail["readings_below"] == 2
    assert told.detail["z"] == pytest.approx((1.9 * 0.1 - 2.1 * 0.1) / np.hypot(1.9, 2.1))
    assert "agree with the change the stiffer stratum makes" in told.text
    contradicted = check([3.0, 1.0, 0.1, -0.1], [0.1, -0.1, -1.9, -2.1])  # the base fitted them: d = (2, 2)
    assert not contradicted.passed and contradicted.detail["z"] == pytest.approx((-2 * 1.9 - 2 * 2.1) / np.hypot(2, 2))
    assert contradicted.detail["below_gain"] < 0 and "do not follow the change" in contradicted.text
    faint = check([3.0, 1.0, -0.3, -0.5], [0.1, -0.1, -0.9, -0.9])  # |d| = 0.72: too small to tell
    assert faint.passed and not faint.detail["testable"] and "cannot tell" in faint.text
    # nothing read below 20 m, and the deepest point read at 16 m: the boundary is beyond every instrument's reach
    none = check([3.0, 1.0, 2.0, 2.0], [0.1, -0.1, 0.1, -0.1], depth=20.0)
    assert not none.passed and none.detail["readings_below"] == 0 and none.detail["deepest_reading"] == 16.0
    assert none.detail["reach"] == 16.0 and not none.detail["reached"]
    assert "no instrument reaches the boundary" in none.text and "(16 m, S1's deepest point)" in none.text
    assert "an instrument reaching below 20 m would test it" in none.text
    # ... its 95 % interval reaching up to 17 m: still beyond; up to 14 m: within reach, nothing to test it with
    assert not check([3.0, 1.0, 2.0, 2.0], [0.1, -0.1, 0.1, -0.1], 20.0, 17.0).passed
    within = check([3.0, 1.0, 2.0, 2.0], [0.1, -0.1, 0.1, -0.1], 20.0, 14.0)
    assert within.passed and within.detail["reached"] and within.detail["readings_below"] == 0
    assert "wholly below the boundary (20 m; the instruments reach 16 m, S1's deepest point, and its 95 % interval " \
           "reaches up to 14 m)" in within.text
    assert "95 % from 17 m" in check([3.0, 1.0, 2.0, 2.0], [0.1, -0.1, 0.1, -0.1], 20.0, 17.0).text


def test_readings_below_a_depth_are_located_where_they_are_taken():
    """Check 8's readings at or below a boundary: a linewise instrument's rows whose whole interval lies there (a
    row reads between its station and the one before it toward the reference end), a point instrument's where its
    points are; how deep an instrument reaches: an inclinometer fixed at its toe to the toe, one fixed at its head
    to its lowest station."""
    from geoback.diagnosis.claims import reach, readings_below

    pts = np.array([[5.0, -10.0], [5.0, -6.0], [5.0, -2.0]])  # stations counted up from the toe, at 14 m
    labels = [SimpleNamespace(station=i + 1) for i in range(3)]
    incl = SimpleNamespace(lengths=np.full(3, 4.0), points=pts, labels=labels, stations=pts,
                           reference=np.array([5.0, -14.0]))
    # a row reads the increment from the station before it (toward the toe) to its own, below it: the lowest 10-14 m
    assert readings_below(incl, 7.0).tolist() == [True, False, False]
    assert readings_below(incl, 12.0).tolist() == [False, False, False]  # the lowest row crosses 12 m
    assert reach(incl) == (14.0, "reference end")
    head = SimpleNamespace(**{**vars(incl), "points": pts[::-1], "stations": pts[::-1],
                              "reference": np.array([5.0, 0.0])})  # fixed at its head: rows above their stations
    assert reach(head) == (10.0, "deepest station")
    assert readings_below(head, 5.0).tolist() == [False, False, True]  # 6-10 m
    assert readings_below(head, 7.0).tolist() == [False, False, False]  # crossed by the row 6-10 m
    surface = SimpleNamespace(lengths=None, points=np.array([[0.0, 0.0], [8.0, -12.0]]),
                              weights=np.array([[[0.0, 1.0], [0.0, 0.0]], [[0.0, 0.0], [0.0, 1.0]]]))
    assert readings_below(surface, 10.0).tolist() == [False, True]


def test_the_readings_alone_are_fitted_as_the_fit_without_priors_fits_them(bench, tmp_path, monkeypatch):
    """Check 9's fit to the readings alone (``_readings_alone``: Gauss-Newton steps with the prior rows left
    out) reaches the minimum the project's own fit finds for the same misfit without its priors, and counts
    the directions the readings inform. The case: the leave-one-family-out benchmark's bench-009 of seed 2027,
    a one-step tunnel with a prior on E (5 %) whose truth released 83 % of the stress."""
    monkeypatch.setenv("GEOBACK_CACHE", str(tmp_path / "cache"))
    from dataclasses import replace

    from geoback.diagnosis.claims import _readings_alone
    from geoback.inference.estimate import fit

    problem = _leave_out_problem(bench, tmp_path, 2027, 9, "stress-release")
    misfit = problem.misfit
    params = misfit.parameters
    assert params.has_prior.tolist() == [n.startswith("E[") for n in params.names]
    with_prior = fit(misfit)
    nan = np.full(params.n, np.nan)
    alone = fit(replace(misfit, parameters=replace(params, prior_mean=nan, prior_std=nan)), p0=with_prior.p)
    J, rank = _readings_alone(misfit, with_prior.p)
    assert rank == params.n
    assert J == pytest.approx(alone.J, rel=1e-6)
    assert J < with_prior.J - 5  # the prior pulls: 3.6 sigma from the readings' E


def test_the_readings_share_of_a_prior_parameter_is_the_prior_variance_they_remove(bench, tmp_path, monkeypatch):
    """Check 9's second condition measures how much of a parameter with a prior the readings decide
    (``readings_share``: 1 - C_ii / C0_ii): for the same case it is 1 - (posterior std / prior std)^2, the
    posterior std as the fit's reliability reports it (eqn 55 with the prior rows)."""
    monkeypatch.setenv("GEOBACK_CACHE", str(tmp_path / "cache"))
    from geoback.diagnosis.claims import readings_share
    from geoback.inference.estimate import fit
    from geoback.inference.identification import assess

    misfit = _leave_out_problem(bench, tmp_path, 2027, 9, "stress-release").misfit
    p = fit(misfit).p
    rel = assess(misfit.evaluate(p, jacobian=True), misfit.parameters, misfit.logdet)
    share = readings_share(misfit, p)
    assert list(share) == ["E[clay]"]  # K0 has no prior
    expected = 1.0 - (rel.std[0] / misfit.parameters.prior_std[0]) ** 2
    assert share["E[clay]"] == pytest.approx(expected, rel=1e-6)
    assert 0.5 < share["E[clay]"] < 1.0  # 0.83: the readings decide E more than the 5 % prior does


def test_a_cause_whose_gain_rests_on_a_prior_is_not_named(bench, tmp_path, monkeypatch):
    """Check 9 (``prior_support``): the same case diagnosed without the release families was named 'a modulus
    of clay increasing with depth' (Egrad = 0.53 MPa/m, every other check passed, the final model adequate).
    Its gain came from the prior on E: the readings put E 3.6 sigma above it, and a gradient stiffens the
    response while E at the top stays at the prior. With the prior left out, the readings alone improve by
    less than chi^2(1) at 1 % with it: explained but not singled out, in words."""
    d = _leave_out_diagnosis(bench, tmp_path, monkeypatch, 2027, 9, "stress-release")
    acc = d.accepted[0]
    assert acc.hypothesis.kind == "stiffness-gradient" and d.adequate_after
    c = acc.checks["prior-support"]
    assert not c.passed and c.detail["dof"] == 1 and c.detail["gain"] < 1.0 and c.detail["level"] == 0.01
    assert c.detail["p_value"] > 0.3  # 0.72 on 1 dof
    assert "rests on the priors on E[clay]" in c.text
    assert all(ch.passed for k, ch in acc.checks.items() if k != "prior-support")  # the only check it fails
    assert acc.grade == "explained" and d.grade == "explained"


@pytest.mark.slow
def test_a_stratum_that_leaves_the_prior_modulus_to_a_crust_is_not_named(bench, tmp_path, monkeypatch):
    """Check 9's second condition: the leave-one-family-out benchmark's bench-011 of seed 2032 (a release,
    beta = 0.71, 7.3 sigma, a prior on E 5 %) diagnosed without the release families was named 'a stiffer
    stratum below 1.26 m' (E below 11.1 MPa, every check passed; the readings alone supported its shape,
    Delta J_alone = 8.3 on 1 dof). The modulus with the prior now stands for the top 1.26 m, which no
    reading tests: the readings' share of it falls from 79 % to 1 %, and the prior alone decides it. The
    stratum has moved what the prior states out of the readings' reach: not singled out (about 30 s)."""
    d = _leave_out_diagnosis(bench, tmp_path, monkeypatch, 2032, 11, "stress-release")
    acc = d.accepted[0]
    assert acc.hypothesis.kind == "layer-boundary" and acc.profile.z_hat < 2.0 and d.adequate_after
    c = acc.checks["prior-support"]
    assert not c.passed and c.detail["lost"] == ["E[clay]"]
    before, after = c.detail["readings_share"]["E[clay]"]
    assert before > 0.7 and after < 0.05
    assert c.detail["p_value"] < 0.01  # the shape alone would have passed: the share decides
    assert "the priors alone decide E[clay]" in c.text
    assert all(ch.passed for k, ch in acc.checks.items() if k != "prior-support")  # the only check it fails
    assert acc.grade == "explained" and d.grade == "explained"


def test_a_release_whose_effect_is_that_of_a_prior_parameter_rests_on_the_prior(bench, tmp_path, monkeypatch):
    """Check 9 on true releases, full library: the benchmark's bench-009 of seed 2031 (beta = 0.70, 7.5 sigma,
    a prior on E). The release has the modulus' effect on the readings, so the readings alone cannot test
    it (no dimension added): it passes, saying it rests on the prior. Its rival, a stratum below 1.4 m (the
    whole layer stiffer, 0.2 AIC behind), fails the check - its gain too is the prior's - and no longer
    keeps the release from being named (it was 'explained but not singled out' before the check)."""
    monkeypatch.setenv("GEOBACK_CACHE", str(tmp_path / "cache"))
    spec = bench.random_case(9, "stress-release", 2031)
    problem = bench.truth_readings(spec, str(tmp_path))[2]
    d = diagnose(problem)
    acc = d.accepted[0]
    assert acc.hypothesis.kind == "stress-release"
    c = acc.checks["prior-support"]
    assert c.passed and c.detail["dof"] == 0 and c.detail["applicable"] is False
    assert "rests on the priors as the case states them" in c.text
    dismissed = acc.checks["rivals"].detail["dismissed"]
    assert any(k.startswith("layer-boundary[") for k in dismissed)
    assert acc.grade == "named"
