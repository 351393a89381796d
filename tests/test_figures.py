"""What the figures show, read back from the matplotlib Figure objects the plot functions return
(before saving; no pixel tests): readings against their real positions, nothing hidden behind a
box, residual labels thinned on a many-station instrument, no empty panels, an identified boundary
drawn, plain words in titles, the lining and the stage named, depth for vertical lines everywhere,
forecasts with the readings so far; the new figures (measured against predicted, the mesh, a forward
run's readings); the objective map linearised where the model's own map would be costly; engineering
units and no float noise in the tables."""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
import yaml
from matplotlib.collections import PolyCollection

from conftest import CASES
from geoback.case.loading import load_case
from geoback.inference.explore import explore
from geoback.inference.identification import identify, prepare
from geoback.reports import plots
from geoback.reports.plots.instruments import (BOUNDARY, LABELS_MAX, Boundary, grid_shape, instruments_figure,
                                               labelled, predicted_figure)

GEOBACK = [sys.executable, "-m", "geoback.commands.cli"]
CODE_WORDS = ("capped", "refactoris", "factorisation", "refactor", "slc", "exploration")


def _panels(fig):
    """The instrument panels (axes with a title), in order."""
    return [ax for ax in fig.axes if ax.get_visible() and ax.axison and ax.get_label() != "<colorbar>"]


def _panel(fig, name):
    return next(ax for ax in _panels(fig) if ax.get_title().startswith(f"{name} ("))


@pytest.fixture(scope="module")
def staged():
    analysis = prepare(load_case(CASES / "staged-tunnel.yaml"))
    res = identify(analysis)
    ex = explore(analysis.misfit, res, plots.exploration_for(), analysis.settings)
    return analysis, res, ex


@pytest.fixture(scope="module")
def boundary_case():
    analysis = prepare(load_case(CASES / "concealed" / "layer-boundary.yaml"))
    res = identify(analysis)
    return analysis, res, explore(analysis.misfit, res, ("profiles",))


@pytest.fixture(scope="module")
def forecast_run():
    from geoback.worth.forecast import forecast

    analysis = prepare(load_case(CASES / "staged-forecast.yaml"))
    res = identify(analysis)
    return replace(res, forecasts=forecast(analysis, res, draws=0))


# --------------------------------------------------------------------------- the instruments figure
def test_settlement_points_are_drawn_at_their_x(staged):
    """No categorical axis ('uy at (3, 0)'): the computed readings sit at the points' x in metres."""
    _, res, ex = staged
    fig = instruments_figure(res, ex)
    ax = _panel(fig, "S1")
    assert ax.get_xlabel() == "horizontal distance from the symmetry axis x [m]"
    assert "u_y" in ax.get_ylabel() and "[mm]" in ax.get_ylabel()
    assert not any("at (" in t.get_text() for t in ax.get_xticklabels())
    block = next(b for b in res.data.blocks if b.name == "S1")
    xs = sorted({round(float(x)) for ln in ax.lines if ln.get_marker() == "o" for x in ln.get_xdata()})
    assert xs == sorted(round(p[0]) for p in block.points)  # 0, 3, 6, 9, 12, 18 m, stages side by side
    # the computed values at the points are the fit's, in mm
    rows = next(sl for b, sl in res.data.block_rows() if b.name == "S1")
    first = next(ln for ln in ax.lines if ln.get_marker() == "o")
    np.testing.assert_allclose(first.get_ydata(), res.fit.x[rows] * 1e3)
    # the model's trough between the points, along x
    trough = [ln for ln in ax.lines if len(ln.get_xdata()) > 20]
    assert trough and min(trough[0].get_xdata()) == pytest.approx(0.0) and max(trough[0].get_xdata()) == \
        pytest.approx(18.0)
    fig.clear()


def test_misfit_is_in_the_titles_not_in_a_box_over_the_readings(staged):
    _, res, ex = staged
    fig = instruments_figure(res, ex)
    for ax in _panels(fig):
        assert "Σ r′²" in ax.get_title()
        assert not any("Σ r′²" in t.get_text() for t in ax.texts)
    fig.clear()


def test_residual_labels_are_thinned_beyond_a_count():
    r = np.zeros(100)
    r[[7, 8, 55]] = [2.5, -3.0, 2.1]
    show = labelled(r)
    assert {7, 8, 55} <= set(show)
    assert len(show) <= LABELS_MAX + 3
    steps = np.diff(np.sort(show))
    assert steps.min() >= 1
    assert list(labelled(np.ones(LABELS_MAX))) == list(range(LABELS_MAX))  # up to the count: every one


def test_many_station_inclinometer_has_readable_residuals(tmp_path):
    """60 stations: at most LABELS_MAX residuals written (every k-th, and all beyond 2), not a smear."""
    data = yaml.safe_load((CASES / "tunnel-paper.yaml").read_text())
    inc = data["instruments"][0]
    inc.update(spacing=0.35, stations=60)
    inc.pop("readings")
    data["instruments"] = [inc]
    case = tmp_path / "many.yaml"
    case.write_text(yaml.safe_dump(data, sort_keys=False))
    from geoback.commands.simulate import without_readings

    plain = prepare(without_readings(case), parameters=[], with_readings=False)
    x = plain.simulation.predict(plain.values).x
    rng = np.random.default_rng(1)
    inc["readings"] = [float(v) for v in x * 1.05 + rng.normal(0, 2e-4, len(x))]
    case.write_text(yaml.safe_dump(data, sort_keys=False))
    analysis = prepare(load_case(case))
    res = identify(analysis, profile="none")
    fig = instruments_figure(res, explore(analysis.misfit, res, ("profiles",)))
    ax = _panel(fig, "I1")
    written = [t for t in ax.texts if t.get_text().startswith(("+", "-")) and t.get_text()[1:2].isdigit()]
    assert 10 <= len(written) <= LABELS_MAX + int(np.sum(np.abs(res.standardised) > 2))
    fig.clear()


def test_panels_fill_the_grid_and_the_legend_takes_a_spare_one(boundary_case):
    for n in range(1, 13):
        rows, cols = grid_shape(n)
        assert rows * cols >= n and rows * cols - n <= max(1, cols - 1) and cols <= 4
    assert grid_shape(4) == (2, 2) and grid_shape(5) == (2, 3)
    _, res, ex = boundary_case
    fig = instruments_figure(res, ex)
    hidden = [ax for ax in fig.axes if not ax.axison]
    assert len(_panels(fig)) == 4 and hidden == []  # four instruments: 2 x 2, no blank panel
    fig.clear()
    # five panels: the spare sixth holds the legend
    data = _five_panels(res)
    fig = instruments_figure(data, ex)
    spare = [ax for ax in fig.axes if not ax.axison]
    assert len(spare) == 1 and spare[0].get_legend() is not None
    fig.clear()


def _five_panels(res):
    """The result with one instrument's readings split into a fifth (renamed) instrument."""
    blocks = list(res.data.blocks)
    s = next(b for b in blocks if b.kind == "points")
    blocks.append(replace(s, name="S-copy", labels=[replace(lab, instrument="S-copy") for lab in s.labels]))
    rows = np.concatenate([np.arange(sl.start, sl.stop) for _, sl in res.data.block_rows()] +
                          [np.arange(sl.start, sl.stop) for b, sl in res.data.block_rows() if b.name == s.name])
    data = replace(res.data, blocks=blocks, measured=res.data.measured[rows],
                   covariance=res.data.covariance[np.ix_(rows, rows)], labels=[res.data.labels[i] for i in rows])
    return replace(res, data=data, fit=replace(res.fit, x=res.fit.x[rows]), standardised=res.standardised[rows])


def test_an_identified_boundary_is_drawn_with_its_interval(boundary_case):
    _, res, ex = boundary_case
    fig = instruments_figure(res, ex, boundaries=[Boundary(16.0, 15.9, 16.1, "identified boundary at 16 m")])
    for name in ("I1", "I2"):  # inclinometers to 30 m depth: the boundary crosses them
        ax = _panel(fig, name)
        lines = [ln for ln in ax.lines if ln.get_color() == BOUNDARY]
        assert lines and np.allclose(lines[0].get_ydata(), 16.0)
        assert any(abs(p.get_extents().height) > 0 for p in ax.patches)  # the 95 % band
    ax = _panel(fig, "X1")  # the extensometer ends at 8 m: not stretched to the boundary
    assert not [ln for ln in ax.lines if ln.get_color() == BOUNDARY] and max(ax.get_ylim()) < 12
    legend = [t.get_text() for lg in fig.legends for t in lg.get_texts()]
    assert "identified boundary at 16 m" in legend
    fig.clear()


def test_predicted_figure_has_no_measured_values(staged):
    analysis, res, ex = staged
    fig = predicted_figure(analysis.simulation.survey.blocks, res.fit.x, ex.profiles, "staged-tunnel")
    for ax in _panels(fig):
        assert "Σ r′²" not in ax.get_title()
        assert not [ln for ln in ax.lines if ln.get_marker() in ("x", "+")]  # no measured markers
        assert ax.get_xlabel().endswith("]") and ax.get_ylabel().endswith("]")
    assert "predicted" in fig.get_suptitle()
    fig.clear()


# --------------------------------------------------------------------------- other figures
def test_titles_use_plain_words(staged):
    _, res, ex = staged
    figs = plots.build_figures(res, ex)
    for name, fig in figs.items():
        texts = [fig.get_suptitle()] + [ax.get_title() for ax in fig.axes] + [ax.get_title(loc="left") for ax in fig.axes]
        for t in texts:
            assert not any(w in t.lower() for w in CODE_WORDS), (name, t)
        fig.clear()


def test_staged_field_draws_the_lining_and_names_the_stage(staged):
    _, res, ex = staged
    fig = plots.field_figure(res, ex)
    assert "after stage 'lined'" in fig.get_suptitle()
    lining = [c for ax in fig.axes for c in ax.collections if isinstance(c, PolyCollection)
              and "lining 'shotcrete'" in str(c.get_label())]
    assert len(lining) == 2  # both panels
    n = int((ex.field.mesh.region == ex.field.mesh.region_names.index("shotcrete")).sum())
    assert len(lining[0].get_paths()) == n
    fig.clear()


def test_vertical_lines_against_depth_everywhere(staged, forecast_run):
    """The vertical extensometer: against depth in the instruments figure and in its forecast."""
    from geoback.reports.plots.forecast import forecast_figure

    _, res, ex = staged
    fig = instruments_figure(res, ex)
    assert _panel(fig, "X1").get_ylabel() == "depth below the surface [m]"
    fig.clear()
    fc = forecast_run.forecasts
    fig = forecast_figure(fc, "X1-lined", forecast_run)
    ax = fig.axes[0]
    assert ax.get_ylabel() == "depth below the surface [m]"
    rows = fc.rows("X1-lined")
    line = next(ln for ln in ax.lines if ln.get_label() == "forecast at the estimate")
    np.testing.assert_allclose(sorted(line.get_ydata()), sorted(-fc.y[rows]))
    assert ax.yaxis_inverted()
    fig.clear()
    from geoback.reports.forecast_report import HEADER, forecast_rows, summary_lines

    table = [dict(zip(HEADER, r)) for r in forecast_rows(fc) if r[0] == "X1-lined"]  # forecast.csv
    assert all(r["position_is"] == "depth [m]" and r["position"] == pytest.approx(-r["y"]) for r in table)
    assert "m depth" in next(line for line in summary_lines(fc) if "X1-lined" in line)


def test_forecasts_are_drawn_with_the_readings_so_far(forecast_run):
    from geoback.reports.plots.forecast import forecast_figure

    res, fc = forecast_run, forecast_run.forecasts
    fig = forecast_figure(fc, "X1-lined", res)
    labels = [t.get_text() for lg in fig.legends for t in lg.get_texts()] + \
             [t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts()]
    assert "X1 read after stage 'advance' (± 2σ)" in labels
    rows = next(sl for b, sl in res.data.block_rows() if b.name == "X1")
    shown = [c for c in fig.axes[0].containers if c.get_label().startswith("X1 read")][0]
    np.testing.assert_allclose(shown.lines[0].get_xdata(), res.data.measured[rows] * 1e3)
    fig.clear()
    fig = forecast_figure(fc, "trough", res)  # the trough runs through the settlement points S1
    ax = fig.axes[0]
    assert any(c.get_label() == "S1 read after stage 'advance' (± 2σ)" for c in ax.containers)
    fig.clear()
    fig = forecast_figure(fc, "trough")  # without the identification: the forecast alone
    assert not fig.axes[0].containers
    fig.clear()


def test_measured_against_predicted(staged):
    _, res, ex = staged
    fig = plots.measured_vs_predicted_figure(res, ex)
    ax = fig.axes[0]
    assert ax.get_xlabel() == "measured reading [mm]" and ax.get_ylabel() == "computed reading at the estimate [mm]"
    x = np.concatenate([c.lines[0].get_xdata() for c in ax.containers])
    y = np.concatenate([c.lines[0].get_ydata() for c in ax.containers])
    np.testing.assert_allclose(np.sort(x), np.sort(res.data.measured * 1e3))
    np.testing.assert_allclose(np.sort(y), np.sort(res.fit.x * 1e3))
    one = [ln for ln in ax.lines if ln.get_linestyle() == "--"]
    assert one and np.allclose(one[0].get_xdata(), one[0].get_ydata())  # the 1:1 line
    colours = {}
    for c, (block, _) in zip(ax.containers, res.data.block_rows()):
        colours.setdefault(block.name, set()).add(c.lines[0].get_color())
    assert all(len(v) == 1 for v in colours.values()) and len({next(iter(v)) for v in colours.values()}) == 3
    fig.clear()


def test_mesh_picture(staged, tmp_path):
    analysis, res, ex = staged
    fig = plots.mesh_figure(ex.field.mesh, res.case, res.data.blocks, res.name)
    assert f"{len(ex.field.mesh.triangles):,} quadratic triangles" in fig.get_suptitle()
    legend = [t.get_text() for lg in fig.legends for t in lg.get_texts()]
    assert "lining 'shotcrete'" in legend and "layer 'clay'" in legend
    fig.clear()
    out = subprocess.run(GEOBACK + ["mesh", str(CASES / "tunnel-paper.yaml"), "--out", str(tmp_path / "m")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "m" / "mesh.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_simulate_plots(tmp_path):
    out = subprocess.run(GEOBACK + ["simulate", str(CASES / "tunnel-paper.yaml"), "--plots", "--no-vtu", "--out",
                                    str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert (tmp_path / "predicted.png").stat().st_size > 10_000 and (tmp_path / "predicted.svg").exists()
    out = subprocess.run(GEOBACK + ["simulate", str(CASES / "tunnel-paper.yaml"), "--no-vtu", "--out",
                                    str(tmp_path / "b")], capture_output=True, text=True, timeout=300)
    assert not (tmp_path / "b" / "predicted.png").exists()  # drawn on request only
    # --no-plots (a loop of forward runs): no figure at all, the plastic zone's CSV still written
    out = subprocess.run(GEOBACK + ["simulate", str(CASES / "plastic-tunnel.yaml"), "--no-vtu", "--no-plots", "--out",
                                    str(tmp_path / "c")], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    written = sorted(p.name for p in (tmp_path / "c").iterdir() if not p.name.startswith("."))  # (the set's manifest)
    assert written == ["plastic_zone.csv", "predicted.csv", "predicted.json"]
    assert len((tmp_path / "c" / "plastic_zone.csv").read_text().splitlines()) > 10


# --------------------------------------------------------------------------- the objective map's cost
@pytest.fixture(scope="module")
def nu_case(tmp_path_factory):
    """The paper case with nu identified instead of K0: every point off the estimate refactorises."""
    text = (CASES / "tunnel-paper.yaml").read_text().replace(
        "  - {name: K0, initial: 0.5, bounds: [0.05, 5.0]}", '  - {name: "nu[clay]", initial: 0.4, bounds: [0.1, 0.495]}')
    case = tmp_path_factory.mktemp("nu") / "nu.yaml"
    case.write_text(text)
    analysis = prepare(load_case(case))
    return analysis, identify(analysis)


def test_costly_objective_map_is_linearised_and_says_so(nu_case):
    analysis, res = nu_case
    ex = explore(analysis.misfit, res, ("slice", "other"), analysis.settings)
    slc = ex.slice
    assert slc.linearised and not slc.requested and ex.other is None and "not run" in ex.other_note
    assert ex.counts["forward_runs"] <= 4  # the probe and the Jacobian at the estimate: no grid of model runs
    # the quadratic form is exact at the estimate and close to the model near it
    r, c = np.unravel_index(np.argmin(np.abs(slc.a[None, :] - res.fit.p[0]) + np.abs(slc.b[:, None] - res.fit.p[1])),
                            slc.J.shape)
    near = analysis.misfit.J(np.array([slc.a[c], slc.b[r]]))
    assert slc.J[r, c] == pytest.approx(near, rel=0.2)
    fig = plots.objective_contours_figure(res, ex)
    ax = fig.axes[0]
    assert "linearised" in ax.get_title() and "--objective-map model" in ax.get_title()
    assert "linearised" in fig.axes[1].get_ylabel()  # the colour bar
    fig.clear()
    fig = plots.convergence_figure(res, ex)
    assert "Gauss-Newton not run for comparison" in fig.get_suptitle()
    fig.clear()
    from geoback.reports.report import report_text, summary

    assert "linearised at the estimate" in report_text(res, ex)
    assert summary(res, ex)["exploration"]["objective_map"] == "linearised"


def test_objective_map_from_the_model_on_request(nu_case):
    analysis, res = nu_case
    ex = explore(analysis.misfit, res, ("slice", "other"), analysis.settings, budget=0.3, objective_map="model")
    assert not ex.slice.linearised and ex.other is not None
    fig = plots.objective_contours_figure(res, ex)
    title = fig.axes[0].get_title()
    assert f"J computed by the model on a {len(ex.slice.a)}×{len(ex.slice.a)} grid" in title
    fig.clear()
    with pytest.raises(ValueError, match="objective map"):
        explore(analysis.misfit, res, ("slice",), objective_map="exact")


def test_cheap_objective_map_is_the_models(staged):
    _, res, ex = staged
    assert not ex.slice.linearised and ex.other is not None and ex.refactorises is False


# --------------------------------------------------------------------------- tables in engineering units
def test_tables_in_engineering_units_without_float_noise(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run(GEOBACK + ["run", str(CASES / "tunnel-paper.yaml"), "--out", str(out)],
                          capture_output=True, text=True, timeout=300, env=dict(os.environ))
    assert proc.returncode == 0, proc.stderr
    summary = json.loads((out / "summary.json").read_text())
    E = summary["parameters"]["E[clay]"]
    report = (out / "report.md").read_text()
    assert "| E[clay] | MPa |" in report and f"{E['estimate'] / 1e3:.6g}" in report
    assert "e+0" not in report.split("Most informative")[0]  # no e-notation in the tables
    for header in [ln for ln in report.splitlines() if ln.startswith("| ") and "---" not in ln]:
        cells = [c.strip() for c in header.strip("|").split("|")]
        if cells[0] in ("parameter", "group"):  # a header row: every numeric column names its unit
            assert all("[" in c or c in ("parameter", "unit", "group", "treatment", "prior") for c in cells) or \
                "unit" in cells, header
    with open(out / "parameters.csv", newline="") as fh:
        rows = {r["name"]: r for r in csv.DictReader(fh)}
    assert rows["E[clay]"]["unit"] == "kPa" and float(rows["E[clay]"]["estimate"]) == E["estimate"]  # the case's
    assert rows["E[clay]"]["unit_shown"] == "MPa"
    assert float(rows["E[clay]"]["estimate_shown"]) == pytest.approx(E["estimate"] / 1e3, rel=1e-11)
    with open(out / "readings.csv", newline="") as fh:
        table = list(csv.reader(fh))
    assert table[0][5:] == ["x [m]", "y [m]", "measured [mm]", "computed [mm]", "residual [mm]",
                            "whitened_residual [-]", "leverage [-]"]
    for row in table[1:]:
        for cell in row[5:]:
            digits = cell.lstrip("-").replace(".", "").split("e")[0].lstrip("0")
            assert len(digits) <= 12, cell  # no float noise (-0.0011916000000000001)
    assert float(table[1][7]) == pytest.approx(-4.62415)  # mm
    assert "E[clay] = 9.99" in proc.stderr + proc.stdout and "MPa +/-" in proc.stderr + proc.stdout
