"""The cross-section as reports and figures show it, for either geometry: the circular tunnel of a half-model
(``geometry: {radius, axis_depth, ...}``) or a section with openings (``geometry: {model, width, depth,
openings}``: every opening's outline, its parts' cut lines and the linings' bands, as
``case/layout.py`` gives them), with the frames of the two panels (the whole model and a zoom on the
openings) and the words for the x axis (a half-model's symmetry axis, or a full model's x).

What is excavated and which linings stand depend on the stage: ``stage_state`` says it for every
element of a section mesh (``physics/section_mesh.SectionMesh``: `part`, `band`) from the case's
construction (``case/sequence.py``), so a figure can draw the section as it stands after a stage and
name that stage, and field.vtu can carry each element's state at every stage. No matplotlib here (the
drawing functions take the axes they draw on).
"""
from __future__ import annotations

import math

import numpy as np

LINING = "#2a6f97"
OPENING = "#1f77b4"


def has_openings(case) -> bool:
    return hasattr(case.geometry, "openings")


def half_model(case) -> bool:
    """Symmetric about x = 0 (the circular tunnel's half-model, or `model: half`)."""
    g = case.geometry
    return not has_openings(case) or g.model == "half"


def box(case) -> tuple[float, float, float]:
    """x_min, x_max and depth of the model."""
    g = case.geometry
    if not has_openings(case):
        return 0.0, g.width, g.depth
    from geoback.case.layout import box as layout_box

    return layout_box(g)


def size(case) -> float:
    """A length the section's movement is drawn against: the tunnel's radius, or the equivalent radius
    of the largest opening (the radius of the circle of the same area)."""
    g = case.geometry
    if not has_openings(case):
        return g.radius
    from geoback.case.layout import polygon

    return max(math.sqrt(polygon(op).area / math.pi) for op in g.openings)


def x_label(case) -> str:
    return "x, distance from the symmetry axis [m]" if half_model(case) else "x [m]"


def whole_title(case) -> str:
    if half_model(case):
        return "Whole model (half section, symmetry axis at x = 0)"
    return "Whole model (full section)"


def zoom_title(case) -> str:
    if has_openings(case) and len(case.geometry.openings) > 1:
        return "Around the openings"
    if has_openings(case) and wall_names(case):
        return "Around the excavation"
    return "Around the tunnel"


def wall_names(case) -> list[str]:
    """The retaining walls of the case (construction.walls), by name."""
    c = getattr(case, "construction", None)
    return [w.name for w in (getattr(c, "walls", None) or [])] if c is not None else []


def instrument_label(case, block) -> str:
    """An instrument as a legend names it: a load cell with the prop or anchor it reads."""
    if block.kind == "load_cell":
        ins = next((i for i in case.instruments if i.name == block.name), None)
        support = getattr(ins, "support", None)
        c = getattr(case, "construction", None)
        kind = "anchor" if c is not None and any(a.name == support for a in (c.anchors or [])) else "prop"
        return f"{block.name} (load cell on {kind} '{support}')"
    return f"{block.name} ({block.kind.replace('_', ' ')}) stations"


def frames(case) -> tuple:
    """Limits of the two panels of a cross-section (the whole model; the openings with about one and a
    half of their size around them, cut at the ground surface) and their width ratios: (full_x, full_y,
    zoom_x, zoom_y, ratios)."""
    g = case.geometry
    if not has_openings(case):
        from geoback.reports.plots.common import section_frames

        return section_frames(g)
    from geoback.case.layout import polygon

    x0, x1, depth = box(case)
    bounds = np.array([polygon(op).bounds for op in g.openings])
    lo_x, lo_y = bounds[:, 0].min(), bounds[:, 1].min()
    hi_x, hi_y = bounds[:, 2].max(), bounds[:, 3].max()
    largest = max(max(b[2] - b[0], b[3] - b[1]) for b in bounds)
    reach = 0.8 * max(largest, 2 * size(case))  # each opening with its near field (as 2.6 R around a circle)
    zx0 = max(x0, lo_x - reach) if g.model == "full" else -0.04 * (hi_x + reach)
    zx = (zx0, min(x1, hi_x + reach))
    ztop = 0.0 if hi_y + 2 * reach > 0 else hi_y + reach  # keep a shallow cover whole
    zy = (max(-depth, lo_y - reach), ztop + 0.04 * (zx[1] - zx[0]))
    span = x1 - x0
    full_x, full_y = (x0 - 0.02 * span, x1 + 0.02 * span), (-1.02 * depth, 0.04 * depth)
    ratios = [(full_x[1] - full_x[0]) / (full_y[1] - full_y[0]), (zx[1] - zx[0]) / (zy[1] - zy[0])]
    return full_x, full_y, zx, zy, ratios


def figure_size(ratios, extra_width: float, height: float = 5.6, widest: float = 15.0) -> tuple[float, float]:
    """(width, height) of a two-panel section figure: 4.9 inches a unit of the panels' width ratios, as
    the circular tunnel's figures are drawn, shrunk to at most `widest` inches for a wide full model."""
    width = 4.9 * (ratios[0] + ratios[1])
    if width + extra_width <= widest:
        return width + extra_width, height
    scale = (widest - extra_width) / width
    return widest, 2.4 + (height - 2.4) * scale  # (titles, labels and the legend keep their size)


def boundary_line(case) -> tuple[list, list]:
    """The model's outline (x, y) as drawn (before excavation)."""
    x0, x1, depth = box(case)
    return [x0, x1, x1, x0, x0], [0, 0, -depth, -depth, 0]


def layer_label_x(case) -> float:
    return box(case)[1] - 0.01 * (box(case)[1] - box(case)[0])


# ---------------------------------------------------------------------------- the state after a stage
def stage_names(case) -> list[str]:
    from geoback.case.construction import stage_names as names

    return names(case)


def stage_state(case, mesh, k: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(void, lining) per element of a section mesh after stage k (default the last): `void` the
    elements excavated and not lined, `lining` the index into mesh.band_names of the lining standing
    in the element (-1: none; a retaining wall counts as a lining band, standing from its installation,
    or from the start when no stage installs it). A mesh without parts (a circular tunnel's) has
    neither."""
    n = len(mesh.triangles)
    part = getattr(mesh, "part", None)
    if part is None or not has_openings(case):
        return np.zeros(n, bool), -np.ones(n, np.int64)
    from geoback.case.sequence import Sequence

    plan = Sequence.of(case)
    k = len(plan.steps) - 1 if k is None else k
    void = np.zeros(n, bool)
    lining = -np.ones(n, np.int64)
    names = list(mesh.band_names)
    for name in plan.walls or {}:  # a wall in place before construction (wished in place)
        if name in names and plan.installed_at(name) < 0:
            lining[mesh.band == names.index(name)] = names.index(name)
    for step in plan.steps[:k + 1]:
        for region in step.excavate:
            if region in mesh.part_names:
                void |= part == mesh.part_names.index(region)
        for name in step.install:
            if name in names:
                lining[mesh.band == names.index(name)] = names.index(name)
        for name in step.remove:
            if name in names:
                lining[mesh.band == names.index(name)] = -1
    void &= lining < 0
    return void, lining


def installed_at(case) -> dict[str, str]:
    """The stage that installs each lining (a section with openings)."""
    from geoback.case.sequence import Sequence

    return {n: s.name for s in Sequence.of(case).steps for n in s.install}


# ---------------------------------------------------------------------------- drawing
def draw_section(ax, case, label: bool = True, colour: str = OPENING) -> None:
    """The openings' outlines (dashed), their parts' cut lines (dotted) and, for a circular tunnel, its
    wall (dashed); the linings are left to the caller (they are elements, standing or not by stage)."""
    g = case.geometry
    if not has_openings(case):
        theta = np.linspace(-np.pi / 2, np.pi / 2, 200)
        ax.plot(g.radius * np.cos(theta), -g.axis_depth + g.radius * np.sin(theta), color=colour, lw=1.4, ls="--",
                label="tunnel wall before excavation" if label else None)
        return
    from geoback.case import layout as lay

    ground = lay.ground_polygon(g)
    for i, op in enumerate(g.openings):
        pts = lay.sample(lay.outline(op))
        pts = np.vstack([pts, pts[:1]])
        if g.model == "half":  # the modelled side only, broken where the outline leaves it
            kept = np.flatnonzero(pts[:, 0] >= -1e-9)
            gaps = np.flatnonzero(np.diff(kept) > 1) + 1
            pts = np.insert(pts[kept], gaps, np.nan, axis=0)
        ax.plot(pts[:, 0], pts[:, 1], color=colour, lw=1.3, ls="--",
                label="openings' walls before excavation" if label and i == 0 else None)
        poly = lay.polygon(op)
        for a, b in op.cuts:
            seg = _clip(a, b, poly, ground)
            if seg is not None:
                ax.plot(seg[:, 0], seg[:, 1], color=colour, lw=0.9, ls=":",
                        label="cut lines between parts" if label and i == 0 and (a, b) == op.cuts[0] else None)


def _clip(a, b, poly, ground):
    """The cut line through a and b within the opening and the modelled ground, as two points, or None."""
    from shapely.geometry import LineString

    n = math.hypot(b[0] - a[0], b[1] - a[1])
    if not n > 0:
        return None
    d = np.array([b[0] - a[0], b[1] - a[1]]) / n
    reach = 4 * max(poly.bounds[2] - poly.bounds[0], poly.bounds[3] - poly.bounds[1]) + n
    line = LineString([np.array(a) - reach * d, np.array(a) + reach * d]).intersection(poly).intersection(ground)
    if line.is_empty or line.length <= 0:
        return None
    pieces = getattr(line, "geoms", [line])
    pts = np.vstack([np.array(piece.coords) for piece in pieces])
    return pts[[int(np.argmin(pts @ d)), int(np.argmax(pts @ d))]]
