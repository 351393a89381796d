"""Ill-posed inputs (issue 9, item 5): each refused with a located message (exit 2) or answered with
a status and warnings that tell the truth; `--strict` turns warnings into exit 3."""
from __future__ import annotations

import copy
import json
import re

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from conftest import CASES
from geoback.commands.cli import app

PAPER = yaml.safe_load((CASES / "tunnel-paper.yaml").read_text())


def run(tmp_path, change, *flags):
    data = copy.deepcopy(PAPER)
    change(data)
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["run", str(path), "-q", "--out", str(out), *flags])
    text = result.output
    assert "Traceback" not in text, text
    summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else None
    return result.exit_code, text, summary


def set_param(i, **fields):
    return lambda d: d["parameters"].__setitem__(i, fields)


REFUSED = {  # change -> (field, words) of the exit-2 message
    "negative initial modulus": (set_param(0, name="E", initial=-5000), "parameters[0].initial",
                                 "expected an initial value of E[clay] within its allowed range"),
    "zero initial modulus": (set_param(0, name="E", initial=0), "parameters[0].initial", "allowed range"),
    "tiny initial modulus": (set_param(0, name="E", initial=1e-300), "parameters[0].initial", "allowed range"),
    "a parameter listed twice": (lambda d: d["parameters"].append({"name": "E[clay]", "initial": 6000}),
                                 "parameters[2].name", "is the same parameter as 'E'"),
    "tiny prior std": (lambda d: d["parameters"][1].__setitem__("prior", {"mean": 1.0, "std": 1e-300}),
                       "parameters[1].prior", "expected a prior std of at least"),
    "huge prior mean": (lambda d: d["parameters"][1].__setitem__("prior", {"mean": 1e300, "std": 1.0}),
                        "parameters[1].prior", "expected a prior mean of K0 within its allowed range"),
    "anisotropy beyond positive definiteness": (
        lambda d: d["parameters"].append({"name": "n[clay]", "initial": 5.0}), "parameters[2].initial",
        "expected an initial value of n[clay] within its allowed range (0.01 to 1.06"),
    "one reading for two parameters": (
        lambda d: d.__setitem__("instruments", [{"name": "P", "kind": "points", "points": [[0, 0]],
                                                 "components": ["uy"], "sigma": 0.001, "readings": [0.03]}]),
        "parameters", "expected more readings than parameters, found 1 reading(s) for 2 parameters"),
}


@pytest.mark.parametrize("what", sorted(REFUSED))
def test_refused_with_a_located_message(tmp_path, what):
    change, field, words = REFUSED[what]
    code, text, summary = run(tmp_path, change)
    assert code == 2, text
    assert re.search(r"case\.yaml:\d+:\d+: " + re.escape(field) + ": ", text), text
    assert words in text, text
    assert summary is None  # refused before any work


def test_gauss_newton_from_far_away_says_it_did_not_move(tmp_path):
    def change(d):
        d["parameters"][0] = {"name": "E", "initial": 1e9}
        d["fit"]["method"] = "gn"

    code, text, summary = run(tmp_path, change)
    assert code == 1
    assert summary["status"] == "stopped without moving" and not summary["converged"]
    codes = {w["code"] for w in summary["warnings"]}
    assert {"did-not-move", "implausible-input"} <= codes


def test_readings_the_model_cannot_explain(tmp_path):
    def change(d):
        for ins in d["instruments"]:
            ins["readings"] = [1e3] * len(ins["readings"])  # 1 km

    code, text, summary = run(tmp_path, change)
    assert code == 0
    assert summary["status"].startswith("converged; model inadequate (p = ")
    codes = [w["code"] for w in summary["warnings"]]
    assert "model-rejected" in codes and "at-bound" in codes
    assert "model inadequate" in text and "warning(s)" in text
    code, _, _ = run(tmp_path, change, "--strict")
    assert code == 3


def test_all_zero_readings_pin_a_parameter_at_its_bound(tmp_path):
    def change(d):
        for ins in d["instruments"]:
            ins["readings"] = [0.0] * len(ins["readings"])

    code, text, summary = run(tmp_path, change, "--strict")
    assert code == 3
    assert {"at-bound", "not-determined"} <= {w["code"] for w in summary["warnings"]}


def test_unseen_deep_layer_is_not_determined(tmp_path):
    def change(d):
        d["ground"]["layers"].append({"name": "deep", "top": 27.0, "E": "50 MPa", "nu": 0.3})
        d["parameters"][0]["name"] = "E[clay]"
        d["parameters"].append({"name": "E[deep]", "initial": "40 MPa"})

    code, text, summary = run(tmp_path, change)
    assert code == 0
    deep = [w for w in summary["warnings"] if w["parameter"] == "E[deep]"]
    assert deep and deep[0]["code"] == "not-determined" and "no instrument sees it" in deep[0]["message"]
    p = summary["parameters"]["E[deep]"]
    assert p["ci95_method"] == "profile likelihood" and p["ci95_open"] == [False, True]
    assert p["ci95"][0] > 0  # never a negative modulus


def test_log_parameter_interval_is_made_in_log_space(tmp_path):
    """A log-transformed modulus with a wide interval: never negative, asymmetric in kPa."""
    def change(d):
        d["parameters"][0]["log"] = True
        d["instruments"] = d["instruments"][1:]  # the extensometer alone: E and K0 poorly separated
        d["parameters"][1]["prior"] = {"mean": 1.0, "std": 0.5}

    code, text, summary = run(tmp_path, change, "--profile")
    E = summary["parameters"]["E[clay]"]
    lo, hi = E["ci95"]
    assert 0 < lo < E["estimate"] < hi
    from geoback.case.loading import load_case
    from geoback.inference.identification import identify

    res = identify(load_case(tmp_path / "case.yaml"), profile="none")
    lin_lo, lin_hi = res.reliability.interval95()
    p, sd = res.fit.p[0], res.reliability.std[0]
    assert lin_lo[0] == pytest.approx(p * np.exp(-1.96 * sd / p), rel=1e-3)
    assert lin_hi[0] == pytest.approx(p * np.exp(1.96 * sd / p), rel=1e-3)


def test_modulus_written_in_pascal_is_flagged(tmp_path):
    code, text, summary = run(tmp_path, lambda d: d["ground"]["layers"][0].__setitem__("E", 60000000))
    assert code == 0
    w = [w for w in summary["warnings"] if w["code"] == "implausible-input"]
    assert w and "written in Pa" in w[0]["message"]


@pytest.mark.quick
def test_a_fit_at_a_natural_limit_is_a_finding_not_a_bound():
    """A prop's preload may be 0 (lost at lock-off): an estimate there, or a 95 % interval reaching it, is what
    the readings found, bounded on the other side - not 'at-bound', not 'not-determined' for its relative error,
    and its interval closed at 0. A modulus at its search bound keeps both caveats and its open end."""
    from types import SimpleNamespace

    from geoback.case.limits import MODULUS, PRELOAD
    from geoback.inference.caveats import fit_caveats
    from geoback.inference.identification import interval_records
    from geoback.inference.parameters import ParameterSet

    n = np.array
    params = ParameterSet(["preload[P2]", "E[marl]"], n([50.0, 9e4]), n([0.0, 9e3]), n([150.0, 9e5]),
                          n([False, False]), n([np.nan, np.nan]), n([np.nan, np.nan]), ["kN/m", "kPa"])
    std = n([3.3, 1e4])
    fit = SimpleNamespace(p=n([0.0, 9e3]), at_bound=n([True, True]), status="converged", moved=True, warnings=(),
                          reason="")
    rel = SimpleNamespace(total_dof=100, dof=100, p_value=0.5, error_scales=(), undetermined=(), std=std,
                          interval95=lambda: (fit.p - 1.96 * std, fit.p + 1.96 * std))
    codes = {(c.code, c.parameter) for c in fit_caveats(fit, rel, params, [PRELOAD, MODULUS], {})}
    assert ("at-bound", "E[marl]") in codes and ("not-determined", "E[marl]") in codes  # 100 % of 9 MPa
    assert not any(p == "preload[P2]" for _, p in codes)
    pre, mod = interval_records(fit, rel, params, [PRELOAD, MODULUS], {})
    assert (pre.low, pre.open) == (0.0, (False, False)) and pre.high == pytest.approx(1.96 * 3.3)
    assert mod.method == "linearised in ln p" and 0 < mod.low < 9e3  # a modulus' interval: in ln p, never below 0
    # away from 0 a preload is judged as any quantity without a ratio scale: by its interval against its usual range
    fit.p, fit.at_bound = n([20.0, 9e4]), n([False, False])
    rel.std = std = n([30.0, 1e3])
    assert not any(p == "preload[P2]" for _, p in
                   {(c.code, c.parameter) for c in fit_caveats(fit, rel, params, [PRELOAD, MODULUS], {})})
    rel.std = n([1500.0, 1e3])  # a 95 % interval wider than a prop's usual 0-5000 kN/m: not determined
    assert ("not-determined", "preload[P2]") in {(c.code, c.parameter)
                                                  for c in fit_caveats(fit, rel, params, [PRELOAD, MODULUS], {})}
