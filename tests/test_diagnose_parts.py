"""Pieces of `geoback diagnose` checked without a finite-element model: the boundary depth's
profile-likelihood search, Akaike weights, the detectable size of a score test, the choice
between a determined and an undetermined hypothesis, and the cause of each kind."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from geoback.diagnosis.compare import akaike_weights, detectable_lambda
from geoback.diagnosis.depth import CHI2_1_95, profile_depth
from geoback.diagnosis.hypotheses import KINDS, cause_of
from geoback.diagnosis.procedure import _choose


def _refit(J):
    """refit_at for profile_depth from a function J(z)."""
    calls = []

    def refit_at(z, near):
        calls.append(z)
        if not np.isfinite(J(z)):
            raise ValueError("cannot mesh")
        return SimpleNamespace(refit=SimpleNamespace(J=J(z), p=np.array([z])), reliability=None)

    return refit_at, calls


def test_depth_profile_finds_the_minimum_and_the_chi2_interval():
    a, z0 = 40.0, 16.3  # J = 50 + a (z - z0)^2: 95 % interval z0 -+ sqrt(3.84 / a)
    refit_at, calls = _refit(lambda z: 50 + a * (z - z0) ** 2)
    prof = profile_depth("clay", refit_at, 0.0, 40.0, [5, 10, 15, 20, 25, 30, 35], tol=0.01)
    half = math.sqrt(CHI2_1_95 / a)
    assert prof.z_hat == pytest.approx(z0, abs=0.01)
    assert prof.low == pytest.approx(z0 - half, abs=0.01) and prof.high == pytest.approx(z0 + half, abs=0.01)
    assert not prof.low_open and not prof.high_open
    assert len(calls) <= 25  # seeds, a parabolic search and a few secant steps per end


def test_depth_profile_rough_and_kinked():
    """Re-meshing makes J rough; a boundary crossing the tunnel makes it kinked: still bracketed."""
    rng = np.random.default_rng(1)
    noise = {}

    def J(z):
        key = round(z, 3)
        noise.setdefault(key, rng.normal(0, 0.3))
        return 10 + 25 * abs(z - 21.0) ** 1.5 + noise[key]  # kinked at the minimum

    refit_at, _ = _refit(J)
    prof = profile_depth("clay", refit_at, 0.0, 40.0, list(np.linspace(4, 36, 7)), tol=0.02)
    assert prof.z_hat == pytest.approx(21.0, abs=0.15)
    assert prof.low < 21.0 < prof.high and prof.high - prof.low < 1.5


def test_depth_profile_open_end_and_unmeshable_depths():
    """J flat towards the layer's bottom: the interval is open there; depths that cannot be meshed
    are skipped and counted."""
    refit_at, _ = _refit(lambda z: np.inf if 14.0 < z < 15.0 else 20 + 30 * max(0.0, 30.0 - z))
    prof = profile_depth("clay", refit_at, 0.0, 40.0, [5, 10, 14.5, 20, 25, 30, 35], tol=0.02)
    assert prof.high_open and prof.high == 40.0
    assert prof.low == pytest.approx(30.0 - CHI2_1_95 / 30, abs=0.05)
    assert 14.5 in prof.failed and prof.refits == len(prof.points) + len(prof.failed)


def test_akaike_weights():
    w = akaike_weights({"a": 10.0, "b": 10.0 + 2 * math.log(2), "c": float("inf")})
    assert w["a"] == pytest.approx(2 / 3) and w["b"] == pytest.approx(1 / 3) and w["c"] == 0.0


def test_detectable_noncentrality():
    """chi^2_1 at 5 %, power 80 %: the classic (1.96 + 0.84)^2 = 7.85."""
    assert detectable_lambda(1, 0.05) == pytest.approx((1.959964 + 0.841621) ** 2, rel=1e-3)
    assert detectable_lambda(2, 0.01) > detectable_lambda(1, 0.01)


def _scored(key, aic, determined=True, group=""):
    h = SimpleNamespace(key=key, group=group, kind="layer-boundary" if group else "stiffness-gradient")
    return SimpleNamespace(hypothesis=h, aic=aic, determined=determined)


def test_choice_between_determined_and_undetermined():
    grad, deep = _scored("grad", -300.0), _scored("deep", -680.0, determined=False, group="lb")
    best, tentative = _choose([grad, deep])  # far better though its modulus is undetermined: tentative
    assert best is deep and tentative
    close = _scored("grad2", -679.0)
    best, tentative = _choose([close, deep])  # within 2 AIC: the determined one, not tentative
    assert best is close and not tentative
    assert _choose([]) == (None, False)


def test_every_kind_has_a_cause():
    instrument = {k for k in KINDS if cause_of(k) == "instrument"}
    assert instrument == {"integration-constant", "bias-shift", "depth-offset"}
    assert cause_of("some-new-ground-kind") == "ground"


def test_rivals_are_stated_with_the_readings_that_separate_them():
    """Two hypotheses within 2 AIC: a plain statement with their Akaike weights and the readings
    where their predictions differ most relative to sigma."""
    from conftest import CASES
    from geoback.case.loading import load_case
    from geoback.diagnosis.compare import separation
    from geoback.reports.diagnosis_report import rival_sentences
    from geoback.inference.identification import prepare

    data = prepare(load_case(CASES / "concealed" / "null-1.yaml")).misfit.data
    x = np.zeros(data.m)
    y = x.copy()
    k = [i for i, lab in enumerate(data.labels) if lab.instrument == "I2" and lab.station == 5][0]
    y[k] = 3e-3  # 3 mm at I2 station 5
    a = SimpleNamespace(refit=SimpleNamespace(x=x), misfit=None,
                        hypothesis=SimpleNamespace(key="stiffness-gradient[clay]", cause="ground",
                                                   title="modulus of 'clay' increasing with depth"), aic=-10.0,
                          rivals=[], separations={}, reliability=None)
    b = SimpleNamespace(refit=SimpleNamespace(x=y), misfit=None,
                        hypothesis=SimpleNamespace(key="layer-boundary[clay@20]", cause="ground",
                                                   title="a different stratum below 20 m in 'clay'"), aic=-9.7)
    sep = separation(a, b, data)
    assert sep.readings[0]["instrument"] == "I2" and sep.readings[0]["station"] == 5
    assert sep.instruments[0]["instrument"] == "I2" and sep.new_points == []
    rnd = SimpleNamespace(accepted=a, rival=b, separation=sep,
                          weights={a.hypothesis.key: 0.48, b.hypothesis.key: 0.41, "(no addition)": 0.11})
    text = rival_sentences(SimpleNamespace(rounds=[rnd]))[0]
    assert text.startswith("Modulus of 'clay' increasing with depth (ground physics) and a different stratum below "
                           "20 m in 'clay' (ground physics) fit about equally well (Akaike weights 0.48 / 0.41")
    assert "I2 station 5" in text


def test_every_rival_within_the_evidence_is_stated_in_words_its_aic_difference_bears():
    """Check 3's rivals (another family within 10 AIC): each is stated with what would tell it from the
    accepted cause (its own separation), and beyond 2 AIC the words say which fits better and that the
    margin does not single it out, never that the two fit 'about equally well' (a depth offset 9.1 AIC
    ahead has Akaike weight 0.99). Where the accepted refit leaves chi^2/dof c > 1 the difference is
    graded divided by c, as check 3 grades it."""
    from geoback.diagnosis.compare import Separation
    from geoback.reports.diagnosis_report import _rival_words, rival_sentences

    def hyp(key, cause, title, aic, **more):
        return SimpleNamespace(hypothesis=SimpleNamespace(key=key, cause=cause, title=title), aic=aic, **more)

    k0 = hyp("K0-gradient", "ground", "K0 varying with depth", -90.9)
    layer = hyp("layer-boundary[clay@15]", "ground", "a different stratum below 15 m in 'clay'", -99.0)
    far = Separation(new_points=[{"x": 0.0, "depth": 15.4, "component": "uy", "difference": -6.1e-3,
                                  "sigma_needed": 1.3e-3}])
    near = Separation(new_points=[{"x": 9.0, "depth": 3.0, "component": "ux", "difference": 2.0e-3,
                                   "sigma_needed": 0.43e-3}])
    acc = hyp("depth-offset[I1]", "instrument", "inclinometer I1: depth offset", -100.0, rivals=[layer, k0],
              separations={"K0-gradient": far, "layer-boundary[clay@15]": near},
              reliability=SimpleNamespace(reduced_chi2=1.1, p_value=0.2))
    rnd = SimpleNamespace(accepted=acc, rival=layer, separation=near,
                          weights={"depth-offset[I1]": 0.72, "layer-boundary[clay@15]": 0.28, "K0-gradient": 0.003})
    first, second = rival_sentences(SimpleNamespace(rounds=[rnd]))
    assert first.startswith("Inclinometer I1: depth offset (instrument error) and a different stratum below 15 m in "
                            "'clay' (ground physics) fit about equally well (Akaike weights 0.72 / 0.28, ΔAIC = 1)")
    assert "ux at x = 9 m, depth 3 m would differ by 2 mm" in first and "15.4" not in first
    assert second.startswith("Inclinometer I1: depth offset (instrument error) fits better than K0 varying with depth "
                             "(ground physics) (Akaike weights 0.72 / 0.003, ΔAIC = 9.1), but not by the 10 AIC units "
                             "that single a cause out: K0 varying with depth keeps some support")
    assert "uy at x = 0 m, depth 15.4 m would differ by 6.1 mm between them (read with σ ≤ 1.3 mm it would set " \
           "the two, as fitted now, 10 AIC apart with 90 % probability; refitted to it, they may take up part of " \
           "the difference)" in second and "about equally" not in second
    words = _rival_words(acc)
    assert words.index("a different stratum") < words.index("ux at x = 9 m") < words.index("K0 varying") < words.index(
        "uy at x = 0 m"), words
    # overdispersed: 9.1 AIC over chi^2/dof 5 is 1.8, within 2: about equally well, and the scaling said
    acc.reliability = SimpleNamespace(reduced_chi2=5.0, p_value=1e-6)
    second = rival_sentences(SimpleNamespace(rounds=[rnd]))[1]
    assert "fit about equally well" in second and "1.8 divided by the χ²/dof 5 the refit leaves" in second, second


def test_the_accuracy_a_separating_reading_needs_holds_in_monte_carlo():
    """A reading of sigma = sigma_to_separate(d), where two fitted models predict values d apart, puts the
    model it follows 10 AIC ahead of the other with probability 0.9 (200 000 draws, either model true)."""
    from geoback.diagnosis.compare import sigma_to_separate

    rng = np.random.default_rng(5)
    for d in (6.1e-3, -0.4e-3):
        sigma = sigma_to_separate(d)
        ma, mb = 0.0, -d
        e = rng.standard_normal(200_000)
        for truth, other in ((ma, mb), (mb, ma)):
            x = truth + sigma * e
            gain = ((x - other) ** 2 - (x - truth) ** 2) / sigma ** 2
            assert np.mean(gain >= 10.0) == pytest.approx(0.9, abs=0.003)
        assert sigma_to_separate(d, power=0.5) == pytest.approx(abs(d) / math.sqrt(10.0))  # z = 0: d^2 = margin
