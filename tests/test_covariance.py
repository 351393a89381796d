"""Tests of geoback.case.covariance (Ledesma, Gens & Alonso 1996, eqns 10-26 + ERRATA)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.linalg import cho_factor, cho_solve

from geoback.case.covariance import (
    KINDS,
    NotPositiveDefinite,
    cholesky_factor,
    constant_matrix,
    constant_names,
    deflectometer_covariance,
    inclinometer_covariance,
    instrument_covariance,
    integration_matrix,
    normalise_kind,
    render_matrix,
    sliding_micrometer_covariance,
    station_lengths,
    structure_matrix,
)

pytestmark = pytest.mark.quick  # the edit-test loop tier (`pytest -m quick`)

UNEQUAL = np.array([0.5, 1.0, 0.5, 2.0, 1.0, 0.75])
SIGMA = 0.7
VARIANCES = {
    "sliding_micrometer": {"A": 0.2},
    "inclinometer": {"B": 0.3},
    "deflectometer": {"C": 0.05, "D": 0.4},
}


def _integrate(kind: str, lengths: np.ndarray, primary: np.ndarray, consts: dict) -> np.ndarray:
    """Explicit cumulative integration along the last axis (eqns 11, 15, 18 corrected).

    Written independently of ``integration_matrix``: the deflectometer's slope on
    segment k is C + sum_{i<=k} kappa_i l_i, and u_n = D + sum_{k<=n} slope_k l_k.
    """
    if kind == "sliding_micrometer":
        return np.cumsum(primary, axis=-1) + consts["A"][..., None]
    if kind == "inclinometer":
        return np.cumsum(primary * lengths, axis=-1) + consts["B"][..., None]
    slope = consts["C"][..., None] + np.cumsum(primary * lengths, axis=-1)
    return np.cumsum(slope * lengths, axis=-1) + consts["D"][..., None]


# 1. closed forms == sigma^2 W W^t + G diag(var) G^t ---------------------------


@pytest.mark.parametrize("kind", KINDS)
def test_closed_form_equals_wwt(kind):
    W = integration_matrix(kind, UNEQUAL)
    G = constant_matrix(kind, UNEQUAL)
    var = np.array([VARIANCES[kind][c] for c in constant_names(kind)])
    expected = SIGMA**2 * W @ W.T + G @ np.diag(var) @ G.T
    C = instrument_covariance(kind, UNEQUAL, SIGMA, VARIANCES[kind])
    assert C.shape == (6, 6)
    np.testing.assert_allclose(C, expected, rtol=1e-12, atol=0)
    # the variance grows away from the reference end
    assert np.all(np.diff(np.diag(C)) > 0)


def test_closed_form_deflectometer_long_random_line():
    rng = np.random.default_rng(7)
    lengths = rng.uniform(0.2, 3.0, size=60)
    W = integration_matrix("deflectometer", lengths)
    G = constant_matrix("deflectometer", lengths)
    expected = 2.0**2 * W @ W.T + G @ np.diag([0.01, 0.2]) @ G.T
    C = deflectometer_covariance(lengths, 2.0, var_c=0.01, var_d=0.2)
    np.testing.assert_allclose(C, expected, rtol=1e-12, atol=0)


def test_deflectometer_matches_errata_sum_by_hand():
    # eqn 20 as corrected, evaluated as literal nested loops
    l = UNEQUAL
    n = l.size
    L = np.cumsum(l)
    vc, vd = 0.05, 0.4
    E = np.zeros((n, n))
    for i in range(n):
        for j in range(n):
            tot = 0.0
            for m in range(min(i, j) + 1):
                tot += l[m] ** 2 * l[m : i + 1].sum() * l[m : j + 1].sum()
            E[i, j] = tot + L[i] * L[j] * vc + vd
    np.testing.assert_allclose(
        deflectometer_covariance(l, 1.0, var_c=vc, var_d=vd), E, rtol=1e-13, atol=0
    )


def test_integration_matrices_by_hand():
    l = [0.5, 1.0, 2.0]
    np.testing.assert_array_equal(
        integration_matrix("sliding_micrometer", l), [[1, 0, 0], [1, 1, 0], [1, 1, 1]]
    )
    np.testing.assert_array_equal(
        integration_matrix("inclinometer", l), [[0.5, 0, 0], [0.5, 1, 0], [0.5, 1, 2]]
    )
    # W_ni = l_i * sum_{k=i}^n l_k
    np.testing.assert_array_equal(
        integration_matrix("deflectometer", l),
        [[0.25, 0, 0], [0.75, 1, 0], [1.75, 3, 4]],
    )
    np.testing.assert_array_equal(constant_matrix("deflectometer", l), [[0.5, 1], [1.5, 1], [3.5, 1]])
    np.testing.assert_array_equal(constant_matrix("inclinometer", l), np.ones((3, 1)))
    np.testing.assert_array_equal(constant_matrix("extensometer", l), np.ones((3, 1)))
    assert constant_names("sliding-micrometer") == ("A",)
    assert constant_names("inclinometer") == ("B",)
    assert constant_names("deflectometer") == ("C", "D")


def test_sliding_micrometer_closed_form_values():
    C = sliding_micrometer_covariance(4, 2.0, var_a=0.5)
    np.testing.assert_array_equal(C, 4.0 * np.minimum.outer(np.arange(1, 5), np.arange(1, 5)) + 0.5)
    # the micrometer's covariance does not depend on the lengths
    np.testing.assert_array_equal(
        instrument_covariance("sliding_micrometer", [0.1, 5, 2, 3], 2.0, {"A": 0.5}), C
    )


# 2. Monte Carlo --------------------------------------------------------------


@pytest.mark.parametrize("kind", KINDS)
def test_monte_carlo_covariance(kind):
    rng = np.random.default_rng(20240601)
    N = 200_000
    n = UNEQUAL.size
    primary = rng.normal(0.0, SIGMA, size=(N, n))
    consts = {
        name: rng.normal(0.0, np.sqrt(v), size=N) for name, v in VARIANCES[kind].items()
    }
    x = _integrate(kind, UNEQUAL, primary, consts)
    sample = np.cov(x, rowvar=False)
    C = instrument_covariance(kind, UNEQUAL, SIGMA, VARIANCES[kind])
    rel = np.linalg.norm(sample - C) / np.linalg.norm(C)
    assert rel < 0.02, f"{kind}: relative Frobenius error {rel:.4f}"


def test_monte_carlo_rejects_printed_eqn18_and_missing_constants():
    """The 2 % Monte Carlo check is sharp enough to reject the wrong models.

    The printed eqn 18 (u_n = sum kappa_i l_i L_n, ERRATA) and a covariance that
    ignores the constants' variances both miss the sample covariance by > 2 %.
    """
    rng = np.random.default_rng(20240601)
    N = 200_000
    l = UNEQUAL
    primary = rng.normal(0.0, SIGMA, size=(N, l.size))
    consts = {name: rng.normal(0.0, np.sqrt(v), size=N) for name, v in VARIANCES["deflectometer"].items()}
    sample = np.cov(_integrate("deflectometer", l, primary, consts), rowvar=False)
    L = np.cumsum(l)
    W_printed = np.tril(np.outer(L, l))
    C_printed = SIGMA**2 * W_printed @ W_printed.T + 0.05 * np.outer(L, L) + 0.4
    C_no_consts = instrument_covariance("deflectometer", l, SIGMA)
    C_right = instrument_covariance("deflectometer", l, SIGMA, VARIANCES["deflectometer"])
    rel = lambda C: np.linalg.norm(sample - C) / np.linalg.norm(C)  # noqa: E731
    assert rel(C_right) < 0.02
    assert rel(C_printed) > 0.2
    assert rel(C_no_consts) > 0.04


# 3. invariance (eqns 21-26) --------------------------------------------------


@pytest.mark.parametrize("kind", KINDS)
def test_invariance_j1_equals_j2(kind):
    rng = np.random.default_rng(11)
    lengths = rng.uniform(0.3, 2.5, size=8)
    sigma = 0.37
    W = integration_matrix(kind, lengths)
    C = instrument_covariance(kind, lengths, sigma)  # constants' variances 0
    factor = cho_factor(C, lower=True)
    for _ in range(5):
        d_primary = rng.normal(size=lengths.size)
        dx = W @ d_primary
        J1 = dx @ cho_solve(factor, dx)
        J2 = d_primary @ d_primary / sigma**2
        assert J1 == pytest.approx(J2, rel=1e-10)


# 4. acceptance value -----------------------------------------------------------


def test_acceptance_inclinometer_values_and_csv_roundtrip():
    C = instrument_covariance("inclinometer", [0.5, 1, 0.5, 2, 1], sigma=1, variances={"B": 0.3})
    assert C.shape == (5, 5)
    assert C[0, 0] == 0.55
    assert C[4, 4] == 6.8
    assert C[1, 3] == 1.55
    assert C[3, 1] == 1.55
    assert C[2, 4] == 1.8  # 0.25 + 1 + 0.25 + 0.3
    text = render_matrix(C, "csv", header=False)
    lines = text.strip().splitlines()
    assert len(lines) == 5
    assert lines[0].split(",")[0] == "0.55"
    assert lines[1].split(",")[3] == "1.55"
    parsed = np.array([[float(v) for v in line.split(",")] for line in lines])
    assert parsed[0, 0] == 0.55
    assert parsed[4, 4] == 6.8
    assert parsed[1, 3] == 1.55
    np.testing.assert_array_equal(parsed, C)  # exact doubles


def test_render_formats():
    C = instrument_covariance("inclinometer", [0.5, 1, 0.5], 1.0, {"B": 0.3})
    csv = render_matrix(C, "csv").splitlines()
    assert csv[0] == "s1,s2,s3"
    assert len(csv) == 4
    data = json.loads(render_matrix(C, "json", labels=["a", "b", "c"]))
    assert data["labels"] == ["a", "b", "c"]
    np.testing.assert_array_equal(np.array(data["matrix"]), C)
    table = render_matrix(C, "table").splitlines()
    assert len(table) == 4
    assert table[0].split() == ["s1", "s2", "s3"]
    assert table[1].split() == ["s1", "0.55", "0.55", "0.55"]
    assert len({len(line) for line in table}) == 1  # aligned
    with pytest.raises(ValueError, match="labels"):
        render_matrix(C, "csv", labels=["a"])
    with pytest.raises(ValueError, match="format"):
        render_matrix(C, "xml")


# 5. error paths --------------------------------------------------------------


def test_cholesky_factor_ok_and_non_pd():
    C = instrument_covariance("deflectometer", UNEQUAL, SIGMA, {"C": 0.1})
    L = cholesky_factor(C, "DEF-1")
    np.testing.assert_allclose(L @ L.T, C, rtol=1e-12, atol=0)
    assert np.allclose(L, np.tril(L))
    bad = np.array([[1.0, 2.0], [2.0, 1.0]])  # eigenvalues 3, -1
    with pytest.raises(NotPositiveDefinite, match="INC-7") as info:
        cholesky_factor(bad, name="INC-7")
    assert "-1" in str(info.value)
    assert isinstance(info.value, ValueError)
    with pytest.raises(NotPositiveDefinite, match="EXT-2"):
        cholesky_factor(np.array([[2.0, 1.0], [0.0, 2.0]]), name="EXT-2")  # not symmetric


def test_station_lengths_valid_and_invalid():
    np.testing.assert_array_equal(station_lengths(stations=4, spacing=0.5), [0.5] * 4)
    np.testing.assert_array_equal(station_lengths(lengths=[1, 2, 3]), [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(station_lengths(stations=3, lengths=[1, 2, 3]), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="> 0"):
        station_lengths(lengths=[1.0, -0.5, 2.0])
    with pytest.raises(ValueError, match="> 0"):
        station_lengths(lengths=[1.0, 0.0])
    with pytest.raises(ValueError, match="stations = 4"):
        station_lengths(stations=4, lengths=[1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="spacing"):
        station_lengths(stations=3, spacing=0.0)
    with pytest.raises(ValueError, match="spacing"):
        station_lengths(stations=3, spacing=-1.0)
    with pytest.raises(ValueError):
        station_lengths(stations=3)
    with pytest.raises(ValueError):
        station_lengths()
    with pytest.raises(ValueError):
        station_lengths(stations=0, spacing=1.0)
    with pytest.raises(ValueError):
        station_lengths(stations=2.5, spacing=1.0)
    with pytest.raises(ValueError):
        station_lengths(spacing=1.0, lengths=[1.0, 1.0])
    with pytest.raises(ValueError):
        station_lengths(lengths=[])
    with pytest.raises(ValueError):
        integration_matrix("inclinometer", [1.0, -1.0])


def test_normalise_kind():
    assert normalise_kind("extensometer") == "sliding_micrometer"
    assert normalise_kind("sliding-micrometer") == "sliding_micrometer"
    assert normalise_kind("Sliding_Micrometer") == "sliding_micrometer"
    assert normalise_kind("inclinometer") == "inclinometer"
    assert normalise_kind("Deflectometer") == "deflectometer"
    for bad in ("piezometer", "", "inclino"):
        with pytest.raises(ValueError, match="unknown instrument kind"):
            normalise_kind(bad)
    with pytest.raises(ValueError):
        normalise_kind(None)


def test_instrument_covariance_rejects_bad_arguments():
    with pytest.raises(ValueError, match="'B'"):
        instrument_covariance("deflectometer", UNEQUAL, 1.0, {"B": 0.1})
    with pytest.raises(ValueError):
        instrument_covariance("inclinometer", UNEQUAL, 1.0, {"B": -0.1})
    with pytest.raises(ValueError):
        instrument_covariance("inclinometer", UNEQUAL, 0.0)


# 6. eigen check ----------------------------------------------------------------


@pytest.mark.parametrize("kind", KINDS)
def test_structure_matrices_spd(kind):
    rng = np.random.default_rng(3)
    for lengths in (UNEQUAL, rng.uniform(0.05, 4.0, size=25), np.array([1.3])):
        for variances in (None, VARIANCES[kind]):
            E = structure_matrix(kind, lengths, SIGMA, variances)
            assert np.array_equal(E, E.T)
            assert np.linalg.eigvalsh(E)[0] > 0
            np.testing.assert_allclose(
                E * SIGMA**2, instrument_covariance(kind, lengths, SIGMA, variances), rtol=1e-14
            )
