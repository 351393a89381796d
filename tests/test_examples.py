"""The examples in docs/examples/ run as they are and show what they say, checked by number
(scikit-fem style: documentation that is tested). Each example's module globals are its results."""
import runpy
import sys
from pathlib import Path

import numpy as np
import pytest

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "docs" / "examples").glob("*.py"))


def run_example(stem: str, monkeypatch, capsys, *args) -> tuple[dict, str]:
    path = next(p for p in EXAMPLES if p.stem == stem)
    monkeypatch.setattr(sys, "argv", [str(path), *map(str, args)])
    names = runpy.run_path(str(path), run_name="__main__")
    out = capsys.readouterr().out
    assert out.strip(), "an example prints what it shows"
    return names, out


def test_identify_paper_case(monkeypatch, capsys):
    """The paper's tunnel (readings from E = 10 MPa, K0 = 1 on a finer mesh): recovered within 0.1 %
    and 0.1 %, the linearised std of the README (213 kPa, 0.030), one factorisation, nothing missing."""
    ex, out = run_example("identify_paper_case", monkeypatch, capsys)
    E, K0 = ex["result"]["E[clay]"], ex["result"]["K0"]
    assert E.value == pytest.approx(10_000.0, rel=1e-3)
    assert K0.value == pytest.approx(1.0, abs=1e-3)
    assert E.std == pytest.approx(213.0, rel=0.01) and K0.std == pytest.approx(0.0298, rel=0.01)
    assert E.low < 10_000.0 < E.high and K0.low < 1.0 < K0.high
    assert abs(ex["result"].reliability.correlation[0, 1]) < 0.3
    assert ex["result"].counts["factorisations"] == 1
    assert ex["d"].adequate_before and ex["d"].accepted == []
    assert "E = 10.00 MPa" in out


def test_monte_carlo(monkeypatch, capsys):
    """50 noisy replicates: every fit converges on one factorisation, and the sample std of each
    parameter agrees with C_p's within the sampling error of a 50-sample std (3 sigma: +-30 %)."""
    ex, out = run_example("monte_carlo", monkeypatch, capsys, 50)
    rep, cp = ex["rep"], ex["cp"]
    assert ex["N"] == 50 and rep.converged.sum() == 50
    assert ex["analysis"].simulation.counters.factorisations == 1
    ratio = rep.p.std(axis=0, ddof=1) / np.sqrt(np.diag(cp))
    assert np.all(np.abs(ratio - 1) < 3 / np.sqrt(2 * 49)), ratio
    assert "50 replicates" in out


def test_forecast_and_design(monkeypatch, capsys):
    """The staged case read before the lining (truth E = 40 MPa, K0 = 0.7 on a finer mesh): the
    truth inside the 95 % intervals, beta left to its prior (identifiability < 0.1, E and K0 > 0.9),
    the forecast inside its band, and the best candidate narrows the trough's band."""
    ex, out = run_example("forecast_and_design", monkeypatch, capsys)
    result, pp, fc, d, i = ex["result"], ex["pp"], ex["fc"], ex["d"], ex["i"]
    assert result["E[clay]"].low < 40_000 < result["E[clay]"].high
    assert result["K0"].low < 0.7 < result["K0"].high
    ident = dict(zip(pp.names, pp.identifiability))
    assert ident["beta[advance]"] < 0.1 and ident["E[clay]"] > 0.9 and ident["K0"] > 0.9
    assert fc.low[i] < fc.value[i] < fc.high[i] < 0  # a settlement: negative uy
    assert 0 < fc.p_exceed[i] < 0.05
    k = d.ranking[0]
    assert d.after[k] < d.before
    assert "best next instrument" in out


def test_openings(monkeypatch, capsys):
    """The horseshoe dug as heading and bench (truth E = 60 MPa, K0 = 0.8, beta = 0.35) and the twin tunnels
    (truth E = 45 MPa, K0 = 0.65), readings from a mesh twice as fine: each fit converges, every truth
    lies inside its 95 % interval, the readings are consistent with their stated sigma (chi-square
    p > 0.05), and the stds are those the README quotes."""
    ex, out = run_example("openings", monkeypatch, capsys)
    for name, truth in ex["TRUTH"].items():
        result = ex["results"][name]
        assert result.fit.status == "converged", name
        for p, true in truth.items():
            r = result[p]
            assert r.low < true < r.high, (name, p, r.low, true, r.high)
        pp = result.reliability
        assert pp.p_value > 0.05, name
    natm, twin = ex["results"]["natm-heading-bench"], ex["results"]["twin-tunnels"]
    assert natm["E[clay]"].value == pytest.approx(59_000.0, rel=0.01)  # 1.3 std below the truth (noise)
    assert natm["E[clay]"].std == pytest.approx(800.0, rel=0.1) and natm["K0"].std == pytest.approx(0.0039, rel=0.1)
    assert natm["beta[heading]"].std == pytest.approx(0.0079, rel=0.1)
    assert twin["E[clay]"].std == pytest.approx(1140.0, rel=0.1) and twin["K0"].std == pytest.approx(0.028, rel=0.1)
    assert "stages heading, heading-lined, bench, ring-closed" in out and "OUTSIDE" not in out


def test_propped_excavation(monkeypatch, capsys):
    """The propped excavation (truth E[soft] = 25 MPa, E[stiff] = 90 MPa, K0 = 0.9, k[P1] = 35 MN/m/m, readings
    from a mesh twice as fine after the first four stages): every truth inside its 95 % interval, readings
    consistent with their sigma, and the final lift's forecast bands hold what the truth then reads (the
    wall's deflection at every station, the level-2 prop force)."""
    ex, out = run_example("propped_excavation", monkeypatch, capsys)
    result = ex["result"]
    assert result.fit.status == "converged"
    for p, true in ex["TRUTH"].items():
        assert result[p].low < true < result[p].high, p
    assert result.reliability.p_value > 0.05
    assert ex["held"] == 1.0
    fc, i = ex["fc"], ex["prop"]
    assert fc.low[i] < ex["true_prop"] < fc.high[i]
    assert "OUTSIDE" not in out


def test_every_example_is_tested():
    tested = {name.removeprefix("test_") for name in globals() if name.startswith("test_")}
    assert {p.stem for p in EXAMPLES} <= tested


def test_update_on_site(monkeypatch, capsys, tmp_path):
    """The dated tunnel updated stage by stage: the last step is the joint fit (to 1e-6 relative), every
    truth inside its final interval, the sequential check within 0.25 std, the lined surveys scored."""
    ex, out = run_example("update_on_site", monkeypatch, capsys, tmp_path / "u")
    steps, joint = ex["steps"], ex["joint"]
    assert [s.stage for s in steps] == ["advance", "lined"]
    assert abs(steps[-1].result.fit.p - joint.fit.p).max() <= 1e-6 * abs(joint.fit.p).max()
    assert ex["inside"] == list(ex["TRUTH"])
    assert abs(steps[-1].sequential.difference_std).max() < 0.25
    assert len(steps[-1].checks) == 6 and "forecast" in out
    assert (tmp_path / "u" / "report.html").is_file()
