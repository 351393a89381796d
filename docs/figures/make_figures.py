"""Regenerate the figures of this folder from the shipped paper case.

    GEOBACK_CACHE=/tmp/geoback-cache .venv/bin/python docs/figures/make_figures.py

The same figures as `geoback run cases/tunnel-paper.yaml --plots` (PNG only), plus the objective
and the information density with the identity weighting of the paper's synthetic example (C_x = I,
eqn 8; its Figs. 2 and 5).
"""
from pathlib import Path

from geoback import plots
from geoback.case import load_case
from geoback.identification import identify

HERE = Path(__file__).resolve().parent
CASE = HERE.parents[1] / "cases" / "tunnel-paper.yaml"


def main() -> None:
    loaded = load_case(CASE)
    figs = plots.build_figures(identify(loaded))
    paths = plots.save_figures(figs, HERE, formats=("png",))
    ident = plots.build_figures(identify(loaded, weighting="identity"),
                                names=("objective_contours", "information_density"))
    paths += plots.save_figures({f"{k}_identity": v for k, v in ident.items()}, HERE, formats=("png",))
    for p in paths:
        print(f"{p.relative_to(HERE.parents[1])}  {p.stat().st_size // 1024} KB")


if __name__ == "__main__":
    main()
