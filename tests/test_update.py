"""Construction as it happens: dated surveys, baselines, instruments installed after a stage,
`geoback update` stage by stage, forecast checks and trigger levels (TARP).

The shipped case cases/dated-tunnel.yaml (readings exported by generate_dated_tunnel.py from a mesh
twice as fine) is used throughout; bad inputs are copies of it with one mistake, run through the
real CLI (exit 2, file, line and field named)."""
from __future__ import annotations

import csv
import datetime as dt
import json
import shutil
from dataclasses import replace
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from geoback.case.dates import parse_date, stage_on
from geoback.case.loading import load_case, stage_names
from geoback.inference.identification import identify, prepare
from geoback.observation.readings import read_readings, survey_blocks
from geoback.observation.instruments import case_blocks, stage_constants

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "cases" / "dated-tunnel.yaml"
FILES = ("dated-tunnel-I1.csv", "dated-tunnel-X1.csv", "dated-tunnel-S1.csv")


def _rows(name):
    with open(ROOT / "cases" / name, newline="", encoding="utf-8") as fh:
        return list(csv.reader(fh))


@pytest.mark.quick
def test_dates_are_read_without_guessing():
    assert parse_date("2026-03-05") == dt.datetime(2026, 3, 5)
    assert parse_date("05.03.2026 08:30") == dt.datetime(2026, 3, 5, 8, 30)
    assert parse_date("2026-03-05T08:30:15") == dt.datetime(2026, 3, 5, 8, 30, 15)
    assert parse_date(dt.date(2026, 3, 5)) == dt.datetime(2026, 3, 5)
    for bad in ("03/05/2026", "2026-02-30", "March 5", "5.3.26"):
        with pytest.raises(ValueError, match="expected a"):
            parse_date(bad)


@pytest.mark.quick
def test_a_survey_belongs_to_the_stage_in_force():
    periods = [("heading", dt.datetime(2026, 3, 1), None), ("bench", dt.datetime(2026, 3, 10), dt.datetime(2026, 3, 20)),
               ("invert", dt.datetime(2026, 4, 1), None)]
    assert stage_on(periods, dt.datetime(2026, 2, 27)) is None  # before construction
    assert stage_on(periods, dt.datetime(2026, 3, 1)) == "heading"
    assert stage_on(periods, dt.datetime(2026, 3, 9, 23)) == "heading"
    assert stage_on(periods, dt.datetime(2026, 3, 20, 18)) == "bench"  # its end day, inclusive
    assert stage_on(periods, dt.datetime(2026, 5, 1)) == "invert"
    with pytest.raises(ValueError, match="lies in no construction stage: after stage 'bench' ended"):
        stage_on(periods, dt.datetime(2026, 3, 25))


@pytest.mark.quick
def test_baselines_are_subtracted_and_surveys_placed_by_date():
    loaded = load_case(CASE)
    stages = stage_names(loaded.case)
    report = read_readings(loaded, case_blocks(loaded), stages)
    # I1: every survey minus the baseline of 25 Feb, in station order from the toe (deepest first)
    rows = _rows("dated-tunnel-I1.csv")[1:]
    base = {float(r[1]): float(r[2]) for r in rows if r[0] == "2026-02-25"}
    for date, stage in (("2026-03-05", "advance"), ("2026-03-12", "advance"), ("2026-03-18", "lined"),
                        ("2026-03-25", "lined")):
        want = np.array([float(r[2]) - base[float(r[1])] for r in rows if r[0] == date]) * 1e-3
        got = report.values["I1"][f"{stage}@{date}"]
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
        assert report.sets["I1"].sets[f"{stage}@{date}"].stage == stage
    assert report.sets["I1"].since is None  # baseline before construction
    assert report.sets["X1"].since == "advance"  # zeroed on 10 Mar, during the advance
    assert set(report.values["X1"]) == {"lined@2026-03-18", "lined@2026-03-25"}
    # S1: reduced levels, u_y = level - baseline level (up positive)
    rows = _rows("dated-tunnel-S1.csv")[1:]
    base = {r[1]: float(r[2]) for r in rows if r[0] == "2026-02-25"}
    want = np.array([float(r[2]) - base[r[1]] for r in rows if r[0] == "2026-03-18"])
    np.testing.assert_allclose(report.values["S1"]["lined@2026-03-18"], want, atol=1e-12)
    # each survey is its own block with its own C_x and reading constants (A[X1.<set>])
    blocks, x = survey_blocks(loaded, stages)
    assert [(b.name, b.survey) for b in blocks if b.name == "X1"] == [("X1", "2026-03-18"), ("X1", "2026-03-25")]
    assert {n for b in stage_constants(blocks) if b.name == "X1" for n in b.constant_names} == \
        {"A[X1.lined@2026-03-18]", "A[X1.lined@2026-03-25]"}
    assert len(x) == 44 + 10 + 24


@pytest.mark.quick
def test_an_instrument_installed_after_a_stage_reads_increments_with_exact_sensitivities():
    """x = P (u_lined - u_advance) for X1, and dx/dp against central differences of it."""
    loaded = load_case(CASE)
    analysis = prepare(loaded)
    sim = analysis.simulation
    values = analysis.values_at(analysis.parameters.initial)
    x1 = [b for b in sim.survey.blocks if b.name == "X1"][0]
    names = ["E[clay]", "K0", "beta[advance]"]
    inc = sim.surveying([x1]).predict(values, names, sensitivities=True)
    at_lined = sim.surveying([replace(x1, since=None)]).predict(values, names, sensitivities=True)
    at_advance = sim.surveying([replace(x1.at("advance"), since=None)]).predict(values, names, sensitivities=True)
    np.testing.assert_allclose(inc.x, at_lined.x - at_advance.x, rtol=1e-12, atol=1e-15)
    assert np.max(np.abs(inc.x)) > 1e-4  # the increment is not nothing
    for j, n in enumerate(names):
        h = 1e-6 * abs(values[n])
        up, dn = dict(values), dict(values)
        up[n] += h
        dn[n] -= h
        fd = (sim.surveying([x1]).predict(up).x - sim.surveying([x1]).predict(dn).x) / (2 * h)
        np.testing.assert_allclose(inc.A[:, j], fd, rtol=2e-6, atol=1e-9 * np.max(np.abs(fd)))


@pytest.mark.quick
def test_update_ends_at_the_joint_fit_and_scores_each_stage_against_the_previous_forecast(tmp_path):
    from geoback.commands.update import update_case

    loaded = load_case(CASE)
    steps = update_case(loaded, tmp_path / "upd")
    joint = identify(prepare(loaded))
    assert [s.stage for s in steps] == ["advance", "lined"]
    np.testing.assert_allclose(steps[-1].result.fit.p, joint.fit.p, rtol=1e-9)
    np.testing.assert_allclose(steps[-1].result.reliability.covariance, joint.reliability.covariance, rtol=1e-7)
    # the first step had only the advance surveys (X1 not yet installed), and forecast the lined stage
    assert all("lined" not in s for s in steps[0].surveys) and not any(s.startswith("X1") for s in steps[0].surveys)
    ahead = {(a.instrument, a.stage) for a in steps[0].ahead}
    assert ahead == {("I1", "lined"), ("X1", "lined"), ("S1", "lined")}
    # every lined survey is scored against the advance step's forecast: z = (x - x_f) / sqrt(diag C)
    checks = steps[1].checks
    assert {(c.instrument, c.survey) for c in checks} == {(n, d) for n in ("I1", "X1", "S1")
                                                        for d in ("2026-03-18", "2026-03-25")}
    first = steps[0]
    for c in checks:
        f = next(a for a in first.ahead if a.instrument == c.instrument)
        np.testing.assert_allclose(c.forecast, f.forecast)
        block = next(b for b in prepare(loaded).simulation.survey.blocks
                     if b.name == c.instrument and b.survey == c.survey)
        C = f.model_covariance + block.covariance
        np.testing.assert_allclose(c.z, (c.measured - f.forecast) / np.sqrt(np.diag(C)), rtol=1e-10)
        assert np.max(np.abs(c.z)) < 4.0  # the forecast is right (X1: increments since the advance)
        assert c.chi2 == pytest.approx(float((c.measured - f.forecast) @ np.linalg.solve(C, c.measured - f.forecast)))
    # the sequential Bayesian update (the advance posterior as the prior of the lined surveys) is near the
    # joint refit on this non-linear model (measured: at most 0.14 std)
    seq = steps[1].sequential
    assert seq is not None and np.max(np.abs(seq.difference_std)) < 0.25, seq.difference_std
    out = tmp_path / "upd"
    for name in ("history.csv", "forecast_checks.csv", "forecasts_ahead.csv", "triggers.csv", "report.md",
                 "report.html", "summary.json"):
        assert (out / name).is_file(), name
    text = (out / "report.md").read_text()
    assert "the stage in force on its date" in text and "σ" in text and "Trigger levels" in text
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] in ("green", "amber", "red") and len(summary["steps"]) == 2


@pytest.mark.quick
def test_sequential_and_joint_updates_agree_exactly_where_the_model_is_linear(tmp_path):
    """The inclinometer's bias shift alone (the ground fixed): readings linear in it, so the previous
    posterior as prior of the new surveys gives the joint estimate to round-off (Gaussian conjugacy)."""
    from geoback.commands.update import update_case

    data = yaml.safe_load(CASE.read_text())
    data["parameters"] = [{"name": "bias[I1]", "initial": 0.0}]
    data["forecasts"] = []
    for name in FILES:
        shutil.copy(ROOT / "cases" / name, tmp_path / name)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    steps = update_case(load_case(tmp_path / "c.yaml"), tmp_path / "out")
    assert steps[1].sequential is not None
    assert np.max(np.abs(steps[1].sequential.difference_std)) < 1e-5
    np.testing.assert_allclose(steps[1].sequential.covariance, steps[1].result.reliability.covariance, rtol=1e-6)


@pytest.mark.quick
def test_trigger_probabilities_and_status_until_a_stage(tmp_path):
    """Up to the advance: the lined stage is forecast; P(> level) is the normal tail of the band."""
    from scipy import stats

    from geoback.commands.update import update_case

    steps = update_case(load_case(CASE), tmp_path / "u", until="advance")
    last = steps[-1]
    rows = {(t.quantity, t.when): t for t in last.triggers}
    assert ("I1", "end") in rows and ("S1", "end") in rows and ("X1", "end") in rows
    crown = rows[("crown-settlement", "forecast")]  # sampled through the model at the last step
    assert np.isfinite(crown.p_amber_sampled) and abs(crown.p_amber_sampled - crown.p_amber) < 0.1
    t = rows[("S1", "end")]
    p = stats.norm.sf((t.red - t.value) / t.std) + stats.norm.cdf((-t.red - t.value) / t.std)
    assert t.p_red == pytest.approx(p, rel=1e-9) and 0.0 <= t.p_red <= t.p_amber <= 1.0
    now = rows[("I1", "now (2026-03-12)")]
    assert now.measured and now.status == ("red" if abs(now.value) > now.red else
                                           "amber" if abs(now.value) > now.amber else "green")


def _bad_case(tmp_path, change, files=None):
    data = yaml.safe_load(CASE.read_text())
    change(data)
    for name in FILES:
        shutil.copy(ROOT / "cases" / name, tmp_path / name)
    for name, edit in (files or {}).items():
        p = tmp_path / name
        p.write_text(edit(p.read_text()))
    path = tmp_path / "case.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def _refused(path, command="validate"):
    r = subprocess.run([sys.executable, "-m", "geoback.commands.cli", command, str(path)], capture_output=True, text=True,
                       cwd=path.parent)
    assert r.returncode == 2, r.stdout + r.stderr
    assert "Traceback" not in r.stderr
    return r.stderr


def _set(path, value):
    def change(d):
        node = d
        for k in path[:-1]:
            node = node[k]
        node[path[-1]] = value
    return change


@pytest.mark.parametrize("change, files, words", [
    # a survey dated before its instrument's baseline
    (_set(["instruments", 1, "baseline"], "2026-03-18"), None,
     ["dated-tunnel-X1.csv", "dated before its baseline survey"]),
    # a survey date outside every stage (the advance ends on 10 Mar; the lined stage begins on 16 Mar)
    (_set(["construction", "stages", 0, "date"], ["2026-03-02", "2026-03-10"]), None,
     ["lies in no construction stage", "after stage 'advance' ended"]),
    # two baselines: the case's and a survey named 'baseline' in the file
    (lambda d: d["instruments"][1].update(baseline="2026-03-10"),
     {"dated-tunnel-X1.csv": lambda t: "survey," + t.replace("\n", "\nS,", t.count("\n") - 1).replace(
         "S,2026-03-10", "baseline,2026-03-10", 1).replace("S,2026-03-18", "baseline,2026-03-18", 1)},
     ["two baselines"]),
    # a trigger level in the wrong unit
    (_set(["instruments", 2, "triggers"], {"amber": "5 kN", "red": "7 mm"}), None,
     ["instruments[2].triggers.amber", "expected a displacement", "5 kN"]),
    (_set(["forecasts", 0, "triggers"], {"amber": "10 mm", "red": "5 mm"}), None, ["red level above the amber"]),
    # a slashed date
    (_set(["construction", "stages", 1, "date"], "16/03/2026"), None, ["construction.stages[1].date", "ambiguous"]),
    # stages out of order, a date on one stage only, a baseline not in the file
    (_set(["construction", "stages", 1, "date"], "2026-03-01"), None, ["to begin after stage 'advance'"]),
    (lambda d: d["construction"]["stages"][1].pop("date"), None, ["expected a date on every stage"]),
    (_set(["instruments", 0, "baseline"], "2026-02-24"), None, ["before construction began", "only the baseline survey may come before"]),
])
def test_bad_time_input_is_refused_located(tmp_path, change, files, words):
    err = _refused(_bad_case(tmp_path, change, files))
    first = err.splitlines()[0]
    assert first.startswith("error: ") and "case.yaml:" in first, err
    for w in words:
        assert w in err, (w, err)


def test_update_cli_strict_exits_4_when_red_is_likely(tmp_path):
    path = _bad_case(tmp_path, _set(["forecasts", 0, "triggers"], {"amber": "1 mm", "red": "2 mm"}))
    r = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "update", str(path), "--out", str(tmp_path / "o"),
                        "--strict", "--quiet"], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 4, r.stdout + r.stderr
    assert "red more likely than 5 %" in r.stderr
    # `geoback run` writes the same table (triggers.csv, report section, summary.json) and --strict exits 4 too
    r = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "run", str(path), "--out", str(tmp_path / "r"),
                        "--strict", "--quiet"], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 4, r.stdout + r.stderr
    assert "## Trigger levels (TARP)" in (tmp_path / "r" / "report.md").read_text()
    rows = list(csv.DictReader(open(tmp_path / "r" / "triggers.csv")))
    crown = next(t for t in rows if t["quantity"] == "crown-settlement")
    assert crown["status"] == "red" and float(crown["p_red"]) > 0.99
    assert float(crown["p_red_sampled"]) > 0.99  # the sampling check's draws through the model agree
    r = subprocess.run([sys.executable, "-m", "geoback.commands.cli", "update", str(CASE), "--out", str(tmp_path / "p"),
                        "--until", "2026-02-01"], capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 2 and "expected surveys up to 2026-02-01" in r.stderr, r.stderr


@pytest.mark.quick
def test_surveys_of_a_stage_averaged_with_their_covariance_divided(tmp_path):
    data = yaml.safe_load(CASE.read_text())
    data["instruments"][0]["surveys"] = "average"
    for name in FILES:
        shutil.copy(ROOT / "cases" / name, tmp_path / name)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    loaded, separate = load_case(tmp_path / "c.yaml"), load_case(CASE)
    stages = stage_names(loaded.case)
    avg = read_readings(loaded, case_blocks(loaded), stages)
    sep = read_readings(separate, case_blocks(separate), stages)
    assert set(avg.values["I1"]) == {"advance", "lined"} and avg.sets["I1"].sets["lined"].count == 2
    np.testing.assert_allclose(avg.values["I1"]["lined"], 0.5 * (sep.values["I1"]["lined@2026-03-18"]
                                                                 + sep.values["I1"]["lined@2026-03-25"]))
    one = [b for b in survey_blocks(loaded, stages)[0] if b.name == "I1"]
    two = [b for b in survey_blocks(separate, stages)[0] if b.name == "I1"]
    assert len(one) == 2 and len(two) == 4
    np.testing.assert_allclose(one[0].covariance, two[0].covariance / 2)
    from geoback.observation.readings import measured_values  # each averaged block finds its readings again

    np.testing.assert_allclose(measured_values(loaded, one), np.concatenate([avg.values["I1"]["advance"],
                                                                            avg.values["I1"]["lined"]]))


@pytest.mark.quick
def test_inline_readings_of_an_instrument_installed_after_a_stage(tmp_path):
    """Inline increments with installed_after; readings before the installation are refused."""
    data = yaml.safe_load(CASE.read_text())
    x1 = data["instruments"][1]
    for key in ("readings_file", "baseline"):
        x1.pop(key)
    x1["installed_after"] = "advance"
    x1["readings"] = {"lined": [0.0004, 0.0003, 0.0002, 0.0001, 0.0001]}
    for name in FILES:
        shutil.copy(ROOT / "cases" / name, tmp_path / name)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    blocks, _ = survey_blocks(load_case(tmp_path / "c.yaml"), ["advance", "lined"])
    assert [b.since for b in blocks if b.name == "X1"] == ["advance"]
    x1["installed_after"] = "lined"
    x1["readings"] = {"advance": [0.0] * 5, "lined": [0.0] * 5}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(data, sort_keys=False))
    err = _refused(tmp_path / "c.yaml")
    assert "instruments[1].readings" in err and "before it was installed (after stage 'lined')" in err


@pytest.mark.quick
def test_a_forward_run_reads_an_instrument_installed_later_as_it_reads(tmp_path):
    """`geoback simulate` (every instrument at every stage, no readings fitted): X1, zeroed during the
    advance, is predicted at the lined stage only, as the increment since the advance."""
    from geoback.commands.simulate import simulate

    loaded = load_case(CASE)
    analysis = prepare(loaded, with_readings=False)
    x1 = [b for b in analysis.simulation.survey.blocks if b.name == "X1"]
    assert [(b.stage, b.since) for b in x1] == [("lined", "advance")]
    values = analysis.values
    total = analysis.simulation.surveying([replace(x1[0], since=None)]).predict(values).x
    before = analysis.simulation.surveying([replace(x1[0].at("advance"), since=None)]).predict(values).x
    simulate(analysis, tmp_path / "sim", vtu=False)
    rows = [r for r in csv.DictReader(open(tmp_path / "sim" / "predicted.csv")) if r["instrument"] == "X1"]
    np.testing.assert_allclose([float(r["computed"]) for r in rows], total - before, rtol=1e-9)


@pytest.mark.quick
def test_the_figures_model_line_of_an_instrument_installed_later_is_its_increment():
    """The model along X1 in the instruments figure (``explore.profiles``) is what X1 reads: the
    increment since the advance, at its stations the computed readings (not the total movement)."""
    from geoback.inference.explore import profiles

    analysis = prepare(load_case(CASE))
    sim, values = analysis.simulation, analysis.values
    x1 = next(b for b in sim.survey.blocks if b.name == "X1")
    prof = profiles(sim, values)["X1"]
    computed = sim.surveying([x1]).predict(values).x
    at_stations = np.interp(np.cumsum(x1.lengths), prof.along, prof.line_reading)
    assert np.max(np.abs(at_stations - computed)) < 0.02 * np.max(np.abs(computed))


def test_a_moved_reference_end_of_one_survey_is_a_hypothesis_of_the_dated_case():
    """Each survey of a dated case has its own integration constants, named with their reading set
    ('B[I1.advance@2026-03-05]'): `geoback diagnose` proposes a moved reference end for each (it stopped on
    the parameter name's pattern before), and a case may name such a parameter, a survey's time included;
    a name with text after its brackets is still refused."""
    from geoback.case.schema import Parameter
    from geoback.diagnosis.hypotheses import candidate_hypotheses
    from geoback.inference.estimate import fit
    from pydantic import ValidationError

    a = prepare(load_case(CASE))
    f = fit(a.misfit, a.settings)
    moved = [h for h in candidate_hypotheses(a.misfit, f.p) if h.kind == "integration-constant"]
    names = {n for h in moved for n in h.names}
    assert {"B[I1.advance@2026-03-05]", "A[X1.lined@2026-03-25]"} <= names
    h = next(h for h in moved if "B[I1.advance@2026-03-05]" in h.names)
    ext = a.misfit.extended(h.parameters, h.extra_values, start=f.p)
    assert ext.parameters.names[-len(h.names):] == h.names
    assert Parameter(name="B[I1.lined@2026-03-18 08:30]", initial=0.0).name.endswith("08:30]")
    for bad in ("E[clay]x", "E[]", "E[a[b]]"):
        with pytest.raises(ValidationError):
            Parameter(name=bad, initial=1.0)
