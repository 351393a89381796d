"""Regenerate the figures of this folder from the shipped paper case.

    python docs/figures/make_figures.py

The same figures as `geoback run cases/tunnel-paper.yaml --plots` (PNG only), plus the objective
and the information density with the identity weighting of the paper's synthetic example (C_x = I,
eqn 8; its Figs. 2 and 5), and the lining and per-stage instrument figures of the staged case
(cases/staged-tunnel.yaml), the trough forecast and the design figure of cases/staged-forecast.yaml.
"""
from pathlib import Path

from geoback.reports import plots
from geoback.case.loading import load_case
from geoback.inference.explore import explore
from geoback.inference.identification import identify, prepare

HERE = Path(__file__).resolve().parent
CASE = HERE.parents[1] / "cases" / "tunnel-paper.yaml"
STAGED = HERE.parents[1] / "cases" / "staged-tunnel.yaml"
FORECAST = HERE.parents[1] / "cases" / "staged-forecast.yaml"


def figures(analysis, weighting=None, names=plots.FIGURES):
    res = identify(analysis, weighting=weighting)
    exploration = explore(analysis.misfit, res, plots.exploration_for(names), analysis.settings)
    return plots.build_figures(res, exploration, names)


def main() -> None:
    analysis = prepare(load_case(CASE))
    paths = plots.save_figures(figures(analysis), HERE, formats=("png",))
    ident = figures(analysis, "identity", ("objective_contours", "information_density"))
    paths += plots.save_figures({f"{k}_identity": v for k, v in ident.items()}, HERE, formats=("png",))
    staged = figures(prepare(load_case(STAGED)), None, ("instruments", "lining"))
    paths += plots.save_figures({"lining": staged["lining"], "instruments_staged": staged["instruments"]}, HERE,
                                formats=("png",))
    from geoback.worth.design import design
    from geoback.worth.forecast import forecast
    from geoback.reports.plots.design import design_figure
    from geoback.reports.plots.forecast import forecast_figure

    analysis = prepare(load_case(FORECAST))
    res = identify(analysis)
    paths += plots.save_figures({"forecast_trough": forecast_figure(forecast(analysis, res), "trough"),
                                 "design": design_figure(design(analysis, res))}, HERE, formats=("png",))
    for p in paths:
        print(f"{p.relative_to(HERE.parents[1])}  {p.stat().st_size // 1024} KB")


if __name__ == "__main__":
    main()
