"""Figures of a run (`geoback run --plots`), after the paper's Figs. 2-5 and 8, one module each:

- ``objective``: J over the two most correlated parameters with the Gauss-Newton and
  Levenberg-Marquardt paths and the SVD directions V1, V2 at the minimum (Fig. 2);
- ``convergence``: J and the parameters (relative to their final values) per iteration (Figs. 3-4);
- ``information``: rows of Q for the readings of highest leverage, and Q itself (Figs. 5, 8);
- ``instruments``: measured and computed readings along every instrument with +-2 sigma bands;
- ``field``: the deformed mesh coloured by the displacement magnitude, with the instruments;
- ``measured_vs_predicted``: every reading, measured against computed, with ±2σ and the 1:1 line;
- ``mesh``: the finite-element mesh by layer, with the instruments' stations;
- ``lining``: thrust, bending moment and shear around the lining per construction stage (models
  with a lining only);
- ``plastic``: the plastic zone around the tunnel after every stage (ground that can yield only);
- ``trough``: the settlement trough per stage, measured and the model's, with their bands; ``damage``:
  the buildings over the greenfield settlement and their damage categories' probabilities;
- ``walls``: each retaining wall's deflection, bending moment and shear against depth per stage, and
  the props' and anchors' forces per stage (``supports``) (cases with walls only).

Figures are built as :class:`matplotlib.figure.Figure` objects without pyplot (no global state,
headless) from an ``Identification`` and an ``Exploration`` (``geoback.inference.explore``): building them
runs no model. :func:`build_figures` returns them, :func:`save_figures` writes them and
:func:`plot_run` does both.
"""
from __future__ import annotations

import io
from pathlib import Path

import matplotlib

from geoback.outputs import write_atomic
from geoback.reports.plots.common import DPI, RC
from geoback.reports.plots.convergence import convergence_figure
from geoback.reports.plots.field import field_figure
from geoback.reports.plots.information import information_density_figure
from geoback.reports.plots.instruments import instruments_figure
from geoback.reports.plots.lining import lining_figure
from geoback.reports.plots.measured import measured_vs_predicted_figure
from geoback.reports.plots.mesh import mesh_figure
from geoback.reports.plots.objective import objective_contours_figure
from geoback.reports.plots.plastic import plastic_zone_figure
from geoback.reports.plots.trough import damage_figure, trough_figure
from geoback.reports.plots.walls import supports_figure, walls_figure

FIGURES = ("objective_contours", "convergence", "information_density", "instruments", "field",
           "measured_vs_predicted", "mesh")
OPTIONAL = ("lining", "plastic_zone", "walls", "supports", "trough", "damage")  # figures of what only some models have, built when
# the exploration holds it
FORMATS = ("png", "svg")
NEEDS = {"objective_contours": ("slice", "other"), "convergence": ("other",), "information_density": (),
         "instruments": ("profiles",), "field": ("field", "profiles"), "measured_vs_predicted": (),
         "mesh": ("field",),
         "lining": ("lining",), "plastic_zone": ("plastic_zone",),
         "walls": (), "supports": (), "trough": (), "damage": ()}  # what each reads from the exploration (walls: set by `geoback run`)
_BUILD = {"objective_contours": objective_contours_figure, "convergence": convergence_figure,
          "information_density": lambda res, exploration: information_density_figure(res),
          "instruments": instruments_figure, "field": field_figure,
          "measured_vs_predicted": measured_vs_predicted_figure,
          "mesh": lambda res, exploration: mesh_figure(exploration.field.mesh, res.case, res.data.blocks, res.name),
          "lining": lambda res, exploration: lining_figure(exploration.lining, res) if exploration.lining else None,
          "plastic_zone": lambda res, exploration: (plastic_zone_figure(exploration.plastic_zone, res)
                                                    if exploration.plastic_zone else None),
          "walls": lambda res, exploration: walls_figure(getattr(exploration, "walls", None), res),
          "supports": lambda res, exploration: supports_figure(getattr(exploration, "walls", None), res),
          "trough": lambda res, exploration: trough_figure(getattr(exploration, "trough", None), res),
          "damage": lambda res, exploration: damage_figure(getattr(exploration, "damage", None), res)}
HOLDS = {"supports": lambda exploration: getattr(getattr(exploration, "walls", None), "supports", None)}


CAPTIONS = {
    "objective_contours": "The objective J over the two most correlated parameters, with the paths of the fit",
    "convergence": "Convergence: J and the parameters at each iteration",
    "information_density": "Information density: which readings determine which",
    "instruments": "Measured and computed readings along every instrument (±2σ)",
    "field": "Displacements at the estimate (deformed mesh) with the instruments",
    "measured_vs_predicted": "Every reading: measured against computed at the estimate",
    "mesh": "The finite-element mesh by layer, with the instruments' stations",
    "lining": "Thrust, bending moment and shear in the lining at each stage",
    "plastic_zone": "The plastic zone after each stage",
    "walls": "Retaining walls: deflection, bending moment and shear against depth at each stage",
    "supports": "Forces in the props and anchors at each stage",
}


def caption(name: str) -> str:
    """What a figure of the run shows, in a few words (report.md's figure captions)."""
    if name in CAPTIONS:
        return CAPTIONS[name]
    if name.startswith("forecast_"):
        return f"Forecast '{name[len('forecast_'):]}' with its 95 % band"
    return name.replace("_", " ").capitalize()


def exploration_for(names=FIGURES + OPTIONAL) -> tuple[str, ...]:
    """What ``explore`` must compute for these figures."""
    return tuple(sorted({w for n in names for w in NEEDS[n]}))


def build_figures(res, exploration, names: tuple[str, ...] | None = None) -> dict:
    """Every figure of the run, by name (the exploration must hold what they need); by default the
    FIGURES and, where the exploration has what they show (a lining), the OPTIONAL ones."""
    if names is None:
        names = FIGURES + tuple(n for n in OPTIONAL
                                if (bool(HOLDS[n](exploration)) if n in HOLDS else getattr(exploration, n, None) is not None))
    unknown = [n for n in names if n not in FIGURES + OPTIONAL]
    if unknown:
        raise ValueError(f"unknown figure(s): {', '.join(unknown)} (figures: {', '.join(FIGURES + OPTIONAL)})")
    with matplotlib.rc_context(RC):
        figs = {name: _BUILD[name](res, exploration) for name in names}
    return {name: fig for name, fig in figs.items() if fig is not None}


def _compact_png(data: bytes) -> bytes:
    """The PNG with an adaptive 256-colour palette (a third of the size, no visible change)."""
    try:
        from PIL import Image

        im = Image.open(io.BytesIO(data)).convert("RGB")
        q = im.quantize(colors=256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)  # a tenth of
        buf = io.BytesIO()  # median cut's time, as faithful on figures of few colours
        q.save(buf, format="PNG", compress_level=6)
        return buf.getvalue() if buf.tell() < len(data) else data
    except Exception:  # noqa: BLE001 - Pillow missing or too old: keep matplotlib's PNG
        return data


def save_figures(figs: dict, out: Path, formats: tuple[str, ...] = FORMATS, dpi: int = DPI,
                 compact: bool = True) -> list[Path]:
    """Write each figure as out/<name>.<format> (atomically); return the paths.

    compact: store PNGs with a 256-colour palette (Pillow), about three times smaller."""
    out = Path(out)
    paths = []
    with matplotlib.rc_context(RC):
        for name, fig in figs.items():
            for k, fmt in enumerate(formats):
                buf = io.BytesIO()
                meta = {"Date": None} if fmt == "svg" else {"Software": None} if fmt == "png" else None
                title = fig.get_suptitle() if hasattr(fig, "get_suptitle") else ""  # (matplotlib >= 3.8)
                if fmt == "svg" and title:  # the SVG says what it shows (dc:title)
                    meta["Title"] = " ".join(title.split())
                if k == 1:  # laid out by the first format's drawing: the others keep its positions
                    fig.set_layout_engine("none")
                fig.savefig(buf, format=fmt, dpi=dpi, metadata=meta)
                data = buf.getvalue()
                if fmt == "png" and compact:
                    data = _compact_png(data)
                path = out / f"{name}.{fmt}"
                write_atomic(path, data)
                paths.append(path)
    return paths


def save_mesh_picture(loaded, mesh, out: Path, formats: tuple[str, ...] = ("png",)) -> list[Path]:
    """`geoback mesh`'s picture of the mesh (mesh.png) with the case's instruments where they can be
    placed (a case whose instruments are not yet valid gets the mesh alone)."""
    from geoback.errors import GeobackError
    from geoback.observation.instruments import case_blocks

    try:
        blocks = case_blocks(loaded)
    except GeobackError:
        blocks = []
    with matplotlib.rc_context(RC):
        fig = mesh_figure(mesh, loaded.case, blocks)
    try:
        return save_figures({"mesh": fig}, out, formats)
    finally:
        fig.clear()


def plot_run(res, exploration, out: Path, formats: tuple[str, ...] = FORMATS) -> list[Path]:
    """Build every figure of the run and write PNG and SVG files into `out`; return the paths."""
    figs = build_figures(res, exploration)
    if getattr(res, "forecasts", None) is not None:
        from geoback.reports.plots.forecast import forecast_figures

        with matplotlib.rc_context(RC):
            figs.update(forecast_figures(res.forecasts, res))
    try:
        return save_figures(figs, out, formats)
    finally:
        for fig in figs.values():
            fig.clear()
