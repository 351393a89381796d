"""Intervals that allow for a cause's selection (issue 24, diagnosis/selection.py): the truncated-normal
interval holds the truth in 95 % of the causes accepted, near the detection limit too, where the usual
interval does not; far above the limit it is the usual one; the verdict shows it where it differs."""
import json

import numpy as np
import pytest

from conftest import CASES
from geoback.diagnosis.selection import critical_value, mu_interval, selective_interval

Q = 1.959963984540054


@pytest.mark.parametrize("offset", [-1.0, 0.0, 1.0, 3.0])
def test_holds_the_truth_in_95_percent_of_the_accepted(offset):
    """Monte Carlo: z ~ N(mu, 1), accepted when |z| > c (c of a Bonferroni level 0.05 / 13, as a round
    of the diagnosis has it); over the accepted draws, the interval holds mu in 95 % (+- 3 standard errors),
    while the usual z +- 1.96 undercovers near the limit (mu = c - 1: about 84 %)."""
    c = critical_value(0.05 / 13)
    mu = c + offset
    rng = np.random.default_rng(24)
    z = mu + rng.standard_normal(40000)
    z = z[np.abs(z) > c][:2500]
    assert len(z) == 2500
    ends = np.array([mu_interval(v, c) for v in z])
    covered = np.mean((ends[:, 0] <= mu) & (mu <= ends[:, 1]))
    se = np.sqrt(0.95 * 0.05 / len(z))
    assert abs(covered - 0.95) <= 3 * se, covered
    usual = np.mean(np.abs(z - mu) <= Q)
    if offset == -1.0:
        assert usual < 0.88, usual  # the winner's curse the adjustment corrects
    assert np.all(ends[:, 0] < ends[:, 1])


def test_far_above_the_limit_it_is_the_usual_interval_and_symmetric_in_sign():
    c = critical_value(0.05 / 10)
    lo, hi = mu_interval(c + 9.0, c)
    assert lo == pytest.approx(c + 9.0 - Q, abs=1e-7) and hi == pytest.approx(c + 9.0 + Q, abs=1e-7)
    a, b = mu_interval(-(c + 0.4), c)
    a2, b2 = mu_interval(c + 0.4, c)
    assert (a, b) == pytest.approx((-b2, -a2), abs=1e-9)
    # just above the limit the interval reaches below the null: how large the cause is is not known
    lo, hi = mu_interval(c + 0.05, c)
    assert lo < 0 < hi < c + 0.05 + Q
    with pytest.raises(ValueError):
        mu_interval(0.5 * c, c)


def test_the_reported_interval_moved_by_the_selection_shift():
    """A linear model (usual interval theta_hat +- 1.96 sigma, dJ = z^2): theta0 + sigma [mu_lo, mu_hi] exactly;
    an asymmetric (profile) interval keeps its asymmetry, each end moved in units of its own side."""
    c = critical_value(0.01)
    lo, hi = mu_interval(3.0, c)
    got = selective_interval(1.3, 1.3 - Q * 0.1, 1.3 + Q * 0.1, 9.0, 1.0, 0.01)
    assert (got.low, got.high) == pytest.approx((1.0 + 0.1 * lo, 1.0 + 0.1 * hi), rel=1e-12)
    assert got.z == pytest.approx(3.0) and got.c == pytest.approx(c) and got.noticeable
    below = selective_interval(0.7, 0.7 - Q * 0.1, 0.7 + Q * 0.1, 9.0, 1.0, 0.01)  # the other side of the null
    assert (below.low, below.high) == pytest.approx((1.0 - 0.1 * hi, 1.0 - 0.1 * lo), rel=1e-12)
    skew = selective_interval(1.3, 1.3 - Q * 0.1, 1.3 + Q * 0.3, 9.0, 1.0, 0.01)
    assert skew.low == pytest.approx(got.low, rel=1e-12)
    assert skew.high == pytest.approx(1.3 + 0.3 * (hi - 3.0), rel=1e-12)
    far = selective_interval(2.0, 2.0 - Q * 0.1, 2.0 + Q * 0.1, 100.0, 1.0, 0.01)
    assert not far.noticeable and far.low == pytest.approx(2.0 - Q * 0.1, rel=1e-6)
    # the statistic, not estimate / std, says how far above the limit it was accepted
    assert selective_interval(1.3, 1.3 - Q * 0.1, 1.3 + Q * 0.1, 4.0, 1.0, 0.01) is None  # |z| = 2 < c
    assert selective_interval(1.3, float("nan"), 1.5, 9.0, 1.0, 0.01) is None


def test_verdict_and_json_show_it_where_it_differs(tmp_path):
    """On a real diagnosis (the shipped bias-shift case, its shift 7.5 sigma: far above the limit) the
    interval allowing for selection is in diagnosis.json and equals the usual one; with the round's level
    set so that the shift lies just above its limit (what a weaker shift would give), the verdict gives
    both intervals in words and the adjusted one reaches towards zero."""
    from geoback.case.loading import load_case
    from geoback.diagnosis import diagnose
    from geoback.reports.diagnosis_report import _accepted_words, write_diagnosis
    from scipy import special

    d = diagnose(load_case(CASES / "concealed" / "bias-shift.yaml"))
    s = d.accepted[0]
    write_diagnosis(d, tmp_path, plots=False)
    est = json.loads((tmp_path / "diagnosis.json").read_text())["missing"][0]["estimates"]["bias[I2]"]
    sel = est["ci95_selective"]
    assert sel["differs"] is False and abs(sel["z"]) > sel["accepted_above"] + 3
    assert sel["ci95"][0] <= 4e-4 <= sel["ci95"][1]
    assert "allowing for its selection" not in _accepted_words(d, s)

    z = abs(d.selective(s)["bias[I2]"].z)
    assert z == pytest.approx(np.sqrt(s.dJ))  # the refit's likelihood ratio, signed
    d.round_of(s).threshold = float(2 * special.ndtr(-(z - 0.3)))  # its limit 0.3 below the statistic
    near = d.selective(s)["bias[I2]"]
    assert near.noticeable and near.c == pytest.approx(z - 0.3)
    (_, v, _, lo, hi), = d.estimates(s)
    assert near.low < lo and near.high < hi  # pulled towards the null value (no shift)
    words = _accepted_words(d, s)
    assert "allowing for its selection near the detection limit" in words and f"{z:.2f}" in words
