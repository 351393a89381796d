"""Regenerate the figures of this folder from the shipped cases.

    python docs/figures/make_figures.py

The same figures as `geoback run cases/tunnel-paper.yaml --plots` (PNG only), plus the objective
and the information density with the identity weighting of the paper's synthetic example (C_x = I,
eqn 8; its Figs. 2 and 5); the lining, per-stage instrument and deformed-field figures of the staged
case (cases/staged-tunnel.yaml); the trough and extensometer forecasts (with the readings so far) and
the design figure of cases/staged-forecast.yaml; the plastic zone and the linearised objective map
of cases/plastic-tunnel.yaml; and the diagnosis of cases/concealed/layer-boundary.yaml. About a
minute or two.
"""
from dataclasses import replace
from pathlib import Path

from geoback.case.loading import load_case
from geoback.inference.explore import explore
from geoback.inference.identification import identify, prepare
from geoback.reports import plots

HERE = Path(__file__).resolve().parent
CASES = HERE.parents[1] / "cases"
CASE = CASES / "tunnel-paper.yaml"
STAGED = CASES / "staged-tunnel.yaml"
FORECAST = CASES / "staged-forecast.yaml"
PLASTIC = CASES / "plastic-tunnel.yaml"
BOUNDARY = CASES / "concealed" / "layer-boundary.yaml"


def figures(analysis, weighting=None, names=plots.FIGURES):
    res = identify(analysis, weighting=weighting)
    exploration = explore(analysis.misfit, res, plots.exploration_for(names), analysis.settings)
    return plots.build_figures(res, exploration, names)


def main() -> None:
    analysis = prepare(load_case(CASE))
    save = lambda figs: plots.save_figures(figs, HERE, formats=("png",))  # noqa: E731
    paths = save(figures(analysis))
    ident = figures(analysis, "identity", ("objective_contours", "information_density"))
    paths += save({f"{k}_identity": v for k, v in ident.items()})
    staged = figures(prepare(load_case(STAGED)), None, ("instruments", "lining", "field"))
    paths += save({"lining": staged["lining"], "instruments_staged": staged["instruments"],
                   "field_staged": staged["field"]})
    from geoback.worth.design import design
    from geoback.worth.forecast import forecast
    from geoback.reports.plots.design import design_figure
    from geoback.reports.plots.forecast import forecast_figure

    analysis = prepare(load_case(FORECAST))
    res = identify(analysis)
    res = replace(res, forecasts=forecast(analysis, res))
    paths += save({"forecast_trough": forecast_figure(res.forecasts, "trough", res),
                   "forecast_extensometer": forecast_figure(res.forecasts, "X1-lined", res),
                   "design": design_figure(design(analysis, res))})
    plastic = figures(prepare(load_case(PLASTIC)), None, ("plastic_zone", "objective_contours"))
    paths += save({"plastic_zone": plastic["plastic_zone"], "objective_contours_plastic": plastic["objective_contours"]})
    from geoback.diagnosis import diagnose
    from geoback.reports.plots.diagnosis import before_after_figure

    d = diagnose(load_case(BOUNDARY))
    paths += save({"diagnosis_layer_boundary": before_after_figure(d, explore(d.final_misfit, d.final, ("profiles",)))})
    for p in paths:
        print(f"{p.relative_to(HERE.parents[1])}  {p.stat().st_size // 1024} KB")


if __name__ == "__main__":
    main()
