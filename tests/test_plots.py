"""Figures of `geoback run --plots` (paper Figs. 2-5 and 8): files written, every axis labelled."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from geoback.reports import plots
from geoback.case.loading import load_case
from geoback.inference.explore import explore
from geoback.inference.identification import identify, prepare
from geoback.reports.plots.common import nice_factor

ROOT = Path(__file__).resolve().parents[1]
PAPER_CASE = ROOT / "cases" / "tunnel-paper.yaml"
EXPECTED = [f"{name}.{fmt}" for name in plots.FIGURES for fmt in ("png", "svg")]


@pytest.fixture(scope="module")
def cache_dir(tmp_path_factory):
    """Meshes of this module are cached in a temporary folder (GEOBACK_CACHE)."""
    folder = tmp_path_factory.mktemp("geoback-cache")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("GEOBACK_CACHE", str(folder))
        yield folder


@pytest.fixture(scope="module")
def paper_analysis(cache_dir, tmp_path_factory):
    case = tmp_path_factory.mktemp("case") / "tunnel-paper.yaml"
    shutil.copy(PAPER_CASE, case)
    return prepare(load_case(case))


@pytest.fixture(scope="module")
def paper_run(paper_analysis):
    return identify(paper_analysis)


@pytest.fixture(scope="module")
def exploration(paper_analysis, paper_run):
    return explore(paper_analysis.misfit, paper_run, plots.exploration_for(), paper_analysis.settings)


@pytest.fixture(scope="module")
def figures(paper_run, exploration):
    figs = plots.build_figures(paper_run, exploration)
    yield figs
    for fig in figs.values():
        fig.clear()


def _data_axes(fig):
    return [ax for ax in fig.axes if ax.get_visible() and ax.get_label() != "<colorbar>"]


def test_every_figure_is_built(figures):
    assert list(figures) == list(plots.FIGURES)


def test_every_axis_has_labels_and_a_title(figures):
    for name, fig in figures.items():
        axes = _data_axes(fig)
        assert axes, name
        suptitle = fig.get_suptitle() if hasattr(fig, "get_suptitle") else ""
        for ax in axes:
            assert ax.get_xlabel().strip(), f"{name}: an axis without x label ({ax.get_title()!r})"
            assert ax.get_ylabel().strip(), f"{name}: an axis without y label ({ax.get_title()!r})"
            assert ax.get_title().strip() or ax.get_title(loc="left").strip() or suptitle, name
        for cb in (ax for ax in fig.axes if ax.get_label() == "<colorbar>"):
            assert (cb.get_ylabel() or cb.get_xlabel()).strip(), f"{name}: a colour bar without label"


def test_units_on_the_axes(figures):
    """Units in brackets on every numeric axis (displacements in mm, E in MPa here); the
    categorical axes list readings."""
    for name, fig in figures.items():
        for ax in _data_axes(fig):
            for label in (ax.get_xlabel(), ax.get_ylabel()):
                if label.startswith(("reading", "chord")):
                    continue
                assert "[" in label and "]" in label, f"{name}: no unit in {label!r}"
    ax = _data_axes(figures["objective_contours"])[0]
    assert ax.get_xlabel() == "E[clay] [MPa]" and ax.get_ylabel() == "K0 [-]"


def test_contours_show_both_methods_and_the_svd_directions(figures, paper_run):
    ax = _data_axes(figures["objective_contours"])[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any(t.startswith("Levenberg-Marquardt") for t in labels)
    assert any(t.startswith("Gauss-Newton") for t in labels)
    assert any(t.startswith("V1") for t in labels) and any(t.startswith("V2") for t in labels)
    assert "40×40" in ax.get_title()  # E and K0 only: one factorisation serves the whole grid
    # the estimate is inside the frame, and so is the start
    x0, x1 = ax.get_xlim()
    y0, y1 = ax.get_ylim()
    for p in (paper_run.fit.p, paper_run.parameters.initial):
        assert x0 < p[0] / 1e3 < x1 and y0 < p[1] < y1


def test_building_figures_leaves_the_run_counters_alone(paper_analysis, paper_run, exploration):
    """Figures read the result and the exploration: building them runs no model."""
    before = dict(vars(paper_analysis.simulation.counters))
    figs = plots.build_figures(paper_run, exploration)
    assert list(figs) == list(plots.FIGURES)
    assert dict(vars(paper_analysis.simulation.counters)) == before


def test_batched_objective_equals_single_predictions(paper_analysis, paper_run, exploration):
    """The slice's grid values are the objective at those points; at the estimate it is the fit's J."""
    slc = exploration.slice
    p_hat = paper_run.fit.p
    picks = [(0, 0), (len(slc.b) // 2, len(slc.a) // 3), (len(slc.b) - 1, len(slc.a) - 1)]
    batched = [slc.J[r, c] for r, c in picks]
    single = [paper_analysis.misfit.J(np.array([slc.a[c], slc.b[r]])) for r, c in picks]
    np.testing.assert_allclose(batched, single, rtol=1e-9)
    assert paper_analysis.misfit.J(p_hat) == pytest.approx(paper_run.fit.J, rel=1e-6)


def test_save_figures_writes_png_and_svg(figures, tmp_path):
    paths = plots.save_figures(figures, tmp_path, dpi=60)  # small: the CLI test writes the real ones
    assert sorted(p.name for p in paths) == sorted(EXPECTED)
    for p in paths:
        data = p.read_bytes()
        assert len(data) > 500, p
        if p.suffix == ".png":
            assert data[:8] == b"\x89PNG\r\n\x1a\n"
        else:
            assert b"<svg" in data[:2000]


def test_unknown_figure_name(paper_run, exploration):
    with pytest.raises(ValueError, match="unknown figure"):
        plots.build_figures(paper_run, exploration, names=("nope",))


def test_nice_factor():
    assert nice_factor(0.5) == 1.0
    assert nice_factor(4.6) == 2.0
    assert nice_factor(10.8) == 10.0
    assert nice_factor(730.0) == 500.0


def test_cli_run_with_plots_writes_the_figures(cache_dir, tmp_path):
    out = tmp_path / "out"
    env = dict(os.environ, GEOBACK_CACHE=str(cache_dir))
    exe = Path(sys.executable).with_name("geoback")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "geoback.commands.cli"]
    proc = subprocess.run(cmd + ["run", str(PAPER_CASE), "--out", str(out), "--plots", "-q"],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    for name in EXPECTED:
        f = out / name
        assert f.exists() and f.stat().st_size > 1000, name
    # the summary still reports the identification's own work, not the figures'
    import json

    summary = json.loads((out / "summary.json").read_text())
    assert summary["factorisations"] == 1
    assert summary["forward_runs"] < 40


@pytest.mark.slow
def test_contour_grid_is_sized_when_every_point_refactorises(cache_dir, tmp_path):
    """With nu identified each grid point needs its own factorisation: asked for the model's own map,
    the grid is sized to a time budget; the title says what the map is in plain words, not how it was
    computed (issue 18 reversed the old expectation of "capped: every grid point refactorises" in the
    title). By default such a map is the linearised model's (test_figures.py)."""
    text = PAPER_CASE.read_text().replace("  - {name: K0, initial: 0.5, bounds: [0.05, 5.0]}",
                                          '  - {name: "nu[clay]", initial: 0.4, bounds: [0.1, 0.495]}')
    case = tmp_path / "nu.yaml"
    case.write_text(text)
    analysis = prepare(load_case(case))
    res = identify(analysis)
    fig = plots.objective_contours_figure(res, explore(analysis.misfit, res, ("slice",), budget=0.5,
                                                       objective_map="model"))
    title = _data_axes(fig)[0].get_title()
    assert "capped" not in title and "refactoris" not in title
    import re

    size = int(re.search(r"on a (\d+)×\1 grid", title).group(1))
    assert 9 <= size < 40  # sized to the time budget, not the full 40 x 40
