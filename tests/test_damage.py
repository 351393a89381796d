"""Building damage (worth/damage.py): the category limits, the Burland & Wroth (1974) deep-beam
formulas against hand-computed worked numbers, the combination with the horizontal strain, the
sagging/hogging split of a Gaussian trough at its inflection point; `geoback run` on the shipped staged
tunnel (a building) writes trough.csv, damage.csv and the report's sections; a building off the model
is refused located (exit 2)."""
from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from geoback.worth.damage import (CATEGORIES, assess, bending_factor, category, combined, limiting_strains,
                                  shear_factor, split)

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.quick
def test_category_limits_and_their_boundaries():
    # Boscardin & Cording (1989), Burland (1995) Table: 0 < 0.05 %, 1 0.05-0.075, 2 0.075-0.15, 3 0.15-0.3, 4-5 > 0.3
    assert [category(e) for e in (0.0, 0.00049, 0.0005, 0.0007, 0.00075, 0.0014, 0.0015, 0.0029, 0.003, 0.01)] == \
        [0, 0, 1, 1, 2, 2, 3, 3, 4, 4]
    assert CATEGORIES[category(0.0006)] == "1 very slight"
    assert CATEGORIES[category(0.004)] == "4-5 severe to very severe"


@pytest.mark.quick
def test_deep_beam_worked_example():
    """Burland & Wroth (1974), as Burland (1995) and Mair, Taylor & Burland (1996) give it:
    Delta/L = (L/(12 t) + 3 I E / (2 t L H G)) eps_b and Delta/L = (1 + H L^2 G / (18 I E)) eps_d.
    Worked by hand for L/H = 1, E/G = 2.6, Delta/L = 0.05 %:
    sagging (I = H^3/12, t = H/2): 1/6 + 0.65 = 0.81667 -> eps_b = 0.061224 %;
                                    1 + 12/46.8 = 1.25641 -> eps_d = 0.039796 %;
    hogging (I = H^3/3, t = H):     1/12 + 1.3 = 1.38333 -> eps_b = 0.036145 %;
                                    1 + 3/46.8 = 1.064103 -> eps_d = 0.046988 %."""
    H = 10.0
    assert bending_factor(H, H, 2.6, False) == pytest.approx(1 / 6 + 0.65, rel=1e-12)
    assert shear_factor(H, H, 2.6, False) == pytest.approx(1 + 12 / 46.8, rel=1e-12)
    eb, ed = limiting_strains(0.0005, H, H, 2.6, hogging=False)
    assert eb == pytest.approx(0.00061224, rel=1e-4)
    assert ed == pytest.approx(0.00039796, rel=1e-4)
    eb, ed = limiting_strains(0.0005, H, H, 2.6, hogging=True)
    assert eb == pytest.approx(0.00036145, rel=1e-4)
    assert ed == pytest.approx(0.00046988, rel=1e-4)
    # with eps_h (Boscardin & Cording 1989; Burland 1995), nu = 0.3, eps_h = 0.02 %, eps_d = 0.04 %:
    # eps_dr = 0.0002 * 0.35 + sqrt(0.0002^2 * 0.65^2 + 0.0004^2) = 0.00007 + 0.00042059 = 0.00049059
    br, dr = combined(0.0003, 0.0004, 0.0002, 0.3)
    assert br == pytest.approx(0.0005, rel=1e-12)
    assert dr == pytest.approx(0.00049059, rel=1e-4)


@pytest.mark.quick
def test_sagging_and_hogging_split_at_the_inflection_point_of_a_gaussian_trough():
    i = 10.0
    x = np.linspace(2.0, 30.0, 161)  # the building straddles the inflection point x = i
    uy = -0.02 * np.exp(-0.5 * (x / i) ** 2)
    parts = split(x, uy)
    assert [m for _, _, m in parts] == ["sagging", "hogging"]
    assert x[parts[0][1]] == pytest.approx(i, abs=0.4)
    got = assess(x, np.zeros_like(x), uy, 8.0)
    assert got[0].x_b == got[1].x_a and got[0].mode == "sagging" and got[1].mode == "hogging"
    # the deflection from the chord of each part, computed directly
    for p in got:
        sel = (x >= p.x_a - 1e-12) & (x <= p.x_b + 1e-12)
        xs, us = x[sel], uy[sel]
        chord = us[0] + (us[-1] - us[0]) * (xs - xs[0]) / (xs[-1] - xs[0])
        d = (chord - us).max() if p.mode == "sagging" else (us - chord).max()
        assert p.deflection == pytest.approx(d, rel=1e-12)
    # a parabola u = a x^2 (sagging) has Delta = a L^2 / 4 from its chord
    xs = np.linspace(0.0, 12.0, 121)
    (p,) = assess(xs, np.zeros_like(xs), 1e-5 * (xs - 6.0) ** 2, 6.0)
    assert p.mode == "sagging" and p.deflection_ratio == pytest.approx(1e-5 * 12.0 / 4, rel=1e-9)


@pytest.mark.quick
def test_a_compressive_horizontal_strain_is_not_credited():
    x = np.linspace(0, 10, 101)
    uy = 1e-5 * (x - 5) ** 2
    a = assess(x, -1e-4 * x, uy, 5.0)[0]  # compression
    b = assess(x, np.zeros_like(x), uy, 5.0)[0]
    assert a.eps_h < 0 and a.critical == pytest.approx(b.critical)
    c = assess(x, 2e-4 * x, uy, 5.0)[0]  # extension adds
    assert c.eps_br == pytest.approx(b.eps_b + 2e-4)


# ---------------------------------------------------------------------------- the CLI
def _run(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "geoback.commands.cli", *args], capture_output=True, text=True,
                          cwd=cwd)


@pytest.fixture(scope="module")
def staged_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("staged")
    r = _run("run", str(ROOT / "cases" / "staged-tunnel.yaml"), "--out", str(out), "--quiet")
    assert r.returncode == 0, r.stderr
    return out


@pytest.mark.quick
def test_run_writes_trough_and_damage(staged_run):
    out = staged_run
    rows = list(csv.DictReader(open(out / "trough.csv")))
    assert {(r["stage"], r["source"]) for r in rows} == {(s, k) for s in ("advance", "lined")
                                                         for k in ("measured", "model")}
    for r in rows:
        assert r["determined"] == "True" and 0.1 < float(r["V_L [%]"]) < 2 and 5 < float(r["i [m]"]) < 25
        assert float(r["V_L_low95 [%]"]) < float(r["V_L [%]"]) < float(r["V_L_high95 [%]"])
    dmg = list(csv.DictReader(open(out / "damage.csv")))
    whole = [r for r in dmg if r["part"] == "whole"]
    assert {r["stage"] for r in whole} == {"advance", "lined"} and {r["building"] for r in whole} == {"terrace"}
    for r in whole:
        assert sum(float(r[k]) for k in r if k.startswith("P(")) == pytest.approx(1.0)
    assert {r["mode"] for r in dmg if r["part"] != "whole"} == {"sagging", "hogging"}
    text = (out / "report.md").read_text()
    assert "## Settlement trough" in text and "## Building damage (greenfield)" in text
    assert "half-model" in text and "greenfield" in text.split("## Building damage (greenfield)")[1]
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["trough"]["stages"]) == {"advance", "lined"}
    assert summary["damage"]["greenfield"] is True and "terrace" in summary["damage"]["buildings"]


def test_run_plots_trough_and_damage_figures(tmp_path):
    r = _run("run", str(ROOT / "cases" / "staged-tunnel.yaml"), "--out", str(tmp_path), "--quiet", "--plots")
    assert r.returncode == 0, r.stderr
    for name in ("trough", "damage"):
        assert (tmp_path / f"{name}.png").stat().st_size > 10_000


@pytest.mark.quick
@pytest.mark.parametrize("field, value, words", [
    ("length", "60.0", "beyond the model"),
    ("foundation_depth", "40.0", "deeper than the model"),
    ("x_start", "-50.0", "outside the model"),
])
def test_a_building_off_the_model_is_refused_located(tmp_path, field, value, words):
    text = (ROOT / "cases" / "staged-tunnel.yaml").read_text()
    old = {"length": "    length: 22.0", "foundation_depth": "    foundation_depth: 1.0",
           "x_start": "    x_start: 4.0"}[field]
    assert old in text
    lines = text.replace("readings_file: staged-tunnel-readings.csv",
                         f"readings_file: {ROOT / 'cases' / 'staged-tunnel-readings.csv'}").split("\n")
    at = next(k for k, ln in enumerate(lines) if ln.startswith(old))
    lines[at] = old.split(":")[0] + ": " + value
    case = tmp_path / "bad.yaml"
    case.write_text("\n".join(lines))
    r = _run("run", str(case), "--out", str(tmp_path / "out"))
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert f"bad.yaml:{at + 1}:" in r.stderr and f"buildings[0].{field}" in r.stderr and words in r.stderr, r.stderr
    assert "expected" in r.stderr and "found" in r.stderr
