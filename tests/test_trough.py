"""The settlement trough (worth/trough.py): the Gaussian fit recovers V_L and i from noisy synthetic
settlements and its 95 % intervals cover at 95 % (pure numpy, hundreds of replicates); fits the
readings cannot determine say so; the model's trough's sensitivities (the delta method through the
exact settlement sensitivities) agree with central differences of the whole fit through the model, and
its C_p band with a Monte Carlo of the linearised model (the shipped staged tunnel)."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from geoback.worth.trough import (SQRT2PI, Opening, fit_gaussian, gaussian, measured_trough, troughs)

ROOT = Path(__file__).resolve().parents[1]
Z = 1.959963984540054


def _covariance(n: int, sigma: float, common: float) -> np.ndarray:
    """Levelling: independent sigma per point and a common benchmark error (correlated readings)."""
    return sigma ** 2 * np.eye(n) + common ** 2 * np.ones((n, n))


@pytest.mark.quick
@pytest.mark.parametrize("half", [True, False], ids=["half-model", "full-model-x0-fitted"])
def test_noisy_gaussian_recovered_and_intervals_cover_at_95_percent(half):
    rng = np.random.default_rng(11)
    S, i, x0, R, z0 = 0.012, 8.0, 0.0 if half else 1.5, 3.0, 16.0
    op = Opening(math.pi * R ** 2, z0, 0.0, "the depth of the tunnel axis")
    x = np.arange(0.0, 31.0, 3.0) if half else np.arange(-27.0, 28.0, 3.0)
    C = _covariance(len(x), 0.0006, 0.0003)
    Lc = np.linalg.cholesky(C)
    truth = {"V_L": 100 * SQRT2PI * i * S / op.area, "i": i, "K": i / z0, "S_max": S}
    hits = {q: 0 for q in truth}
    est = {q: [] for q in truth}
    n = 400
    for _ in range(n):
        s = gaussian(x, S, i, x0) + Lc @ rng.standard_normal(len(x))
        tr = measured_trough("s", x, s, C, op, half)
        assert tr.determined, tr.reason
        assert tr.x0_how == ("symmetry axis" if half else "fitted")
        for q in truth:
            lo, hi = tr.interval(q, Z)
            hits[q] += lo <= truth[q] <= hi
            est[q].append(tr.values[q])
    cover = {q: hits[q] / n for q in truth}
    print("coverage of the 95 % intervals over", n, "replicates:", cover)
    for q in truth:
        assert 0.92 <= cover[q] <= 0.98, (q, cover)
        assert abs(np.mean(est[q]) - truth[q]) < 0.02 * truth[q], (q, np.mean(est[q]), truth[q])


@pytest.mark.quick
def test_exact_gaussian_gives_its_volume_loss_and_width_and_the_covariance_is_the_inverse_information():
    x = np.linspace(0, 30, 11)
    op = Opening(math.pi * 9, 15.0, 0.0, "")
    C = _covariance(len(x), 0.0005, 0.0)
    tr = measured_trough("s", x, gaussian(x, 0.01, 7.5), C, op, True)
    assert tr.values["i"] == pytest.approx(7.5, rel=1e-9)
    assert tr.values["V_L"] == pytest.approx(100 * SQRT2PI * 7.5 * 0.01 / (9 * math.pi), rel=1e-9)
    assert tr.values["K"] == pytest.approx(0.5, rel=1e-9)
    J = np.column_stack([np.exp(-0.5 * (x / 7.5) ** 2), 0.01 * np.exp(-0.5 * (x / 7.5) ** 2) * x ** 2 / 7.5 ** 3])
    Cth = np.linalg.inv(J.T @ np.linalg.inv(C) @ J)  # (J^t W J)^-1 at a perfect fit
    assert tr.std["S_max"] == pytest.approx(math.sqrt(Cth[0, 0]), rel=1e-6)
    assert tr.std["i"] == pytest.approx(math.sqrt(Cth[1, 1]), rel=1e-6)


@pytest.mark.quick
def test_the_exact_gain_is_the_derivative_of_the_fit_with_residuals():
    """dtheta/ds = H^-1 J^t W (r != 0) against central differences of the refit."""
    rng = np.random.default_rng(3)
    x = np.linspace(-20, 25, 16)
    s = gaussian(x, 0.01, 6.0, 1.0) + 0.0008 * rng.standard_normal(len(x))
    f = fit_gaussian(x, s, None, 0.0, True)
    G = np.zeros_like(f.gain)
    for k in range(len(x)):
        d = np.zeros(len(x))
        d[k] = 1e-5  # (settlements of about 10 mm)
        G[:, k] = (fit_gaussian(x, s + d, None, 0.0, True).theta - fit_gaussian(x, s - d, None, 0.0, True).theta) / 2e-5
    assert np.abs(f.gain - G).max(axis=1) == pytest.approx(0, abs=2e-5 * np.abs(G).max())


@pytest.mark.quick
def test_undetermined_fits_say_why_in_words():
    op = Opening(math.pi * 9, 15.0, 0.0, "")
    C2 = _covariance(2, 0.0005, 0.0)
    few = measured_trough("s", [0.0, 5.0], [0.01, 0.008], C2, op, True)
    assert not few.determined and "too few points" in few.reason
    x = np.array([0.0, 1.0, 2.0, 3.0])  # all inside the flat middle of a wide trough: no fall-off
    flat = measured_trough("s", x, np.full(4, 0.01) + np.array([0, 1e-5, -1e-5, 0]), _covariance(4, 0.0005, 0), op,
                           True)
    assert not flat.determined and "not determined" in flat.reason and "i" in flat.reason
    rng = np.random.default_rng(0)
    x = np.linspace(0, 30, 8)
    none = measured_trough("s", x, 0.0005 * rng.standard_normal(8), _covariance(8, 0.0005, 0), op, True)
    assert not none.determined and ("no settlement trough" in none.reason or "not determined" in none.reason)


# ---------------------------------------------------------------------------- the model's trough
@pytest.fixture(scope="module")
def staged():
    from geoback.case.loading import load_case
    from geoback.inference.identification import identify, prepare

    analysis = prepare(load_case(ROOT / "cases" / "staged-tunnel.yaml"))
    return analysis, identify(analysis)


def _at(result, p):
    return replace(result, fit=replace(result.fit, p=np.asarray(p, float)))


@pytest.mark.quick
def test_predicted_trough_sensitivities_agree_with_central_differences_through_the_model(staged):
    analysis, res = staged
    tr = troughs(analysis, res)
    p = res.fit.p
    worst = 0.0
    for stage, T in tr.predicted.items():
        assert T.determined
        F = T.theta_sensitivity  # d(S_max, i, x0)/dp
        for j in range(len(p)):
            h = 1e-3 * abs(p[j])  # (the refit converges to ~1e-9 m: a step large enough to rise above it)
            up, down = p.copy(), p.copy()
            up[j] += h
            down[j] -= h
            a, b = troughs(analysis, _at(res, up)).predicted[stage], troughs(analysis, _at(res, down)).predicted[stage]
            for k, q in enumerate(("S_max", "i")):
                fd = (a.values[q] - b.values[q]) / (2 * h)
                assert F[k, j] == pytest.approx(fd, rel=1e-3, abs=1e-5 * abs(T.values[q] / p[j])), (stage, q, j)
                worst = max(worst, abs(F[k, j] - fd) / max(abs(fd), abs(T.values[q] / p[j])))
    print(f"delta method against central differences through the model: worst {worst:.2g} (relative to "
          f"max(|FD|, value/p))")


@pytest.mark.quick
def test_predicted_band_matches_a_monte_carlo_of_the_linearised_model(staged):
    analysis, res = staged
    tr = troughs(analysis, res)
    T = tr.predicted["lined"]
    C = res.reliability.covariance
    rng = np.random.default_rng(5)
    # the model's settlement linearised at the estimate: s = s0 + F dp (F: exact sensitivities), refitted per draw
    from types import SimpleNamespace

    from geoback.observation.instruments import build_block

    pts = [(float(a), 0.0) for a in T.x]
    block = build_block(SimpleNamespace(kind="points", name="t", points=pts, components=["uy"], sigma=1.0),
                        analysis.loaded, 0).at("lined")
    pred = analysis.simulation.surveying([block]).predict(analysis.values_at(res.fit.p), list(res.parameters.names),
                                                          True)
    s0, F = -pred.x, -pred.A
    L = np.linalg.cholesky(C)
    VL, ii = [], []
    for _ in range(1000):
        s = s0 + F @ (L @ rng.standard_normal(len(res.fit.p)))
        f = fit_gaussian(T.x, s, None, 0.0, False)
        VL.append(100 * SQRT2PI * f.theta[0] * f.theta[1] / T.area)
        ii.append(f.theta[1])
    assert np.std(VL) == pytest.approx(T.std["V_L"], rel=0.1)
    assert np.std(ii) == pytest.approx(T.std["i"], rel=0.1)
    print(f"V_L std: delta method {T.std['V_L']:.4g} %, Monte Carlo {np.std(VL):.4g} %; "
          f"i std: {T.std['i']:.4g} m, {np.std(ii):.4g} m")
