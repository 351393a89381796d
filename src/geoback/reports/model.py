"""report.md's "The model" section: what was fitted, read from the result alone (``res.case``, the parsed
case; ``res.parameters`` and the intervals for what was identified; ``res.data`` for the readings).

Geometry, the ground layers with every value and whether it was identified (estimate and 95 % interval)
or fixed at the case's value, the construction stages (the words of ``case/sequence.describe`` for a
section with openings, the same words here for the circular tunnel's stage plan), the linings, walls,
props and anchors, the mesh's size and the instruments with their readings per stage. Values in
engineering units (MPa, kPa, kN/m³, mm). Nothing here runs the model.
"""
from __future__ import annotations

import math
from collections import Counter

from geoback.units import number, shown

UNIT_TEXT = {"kN/m3": "kN/m³", "deg": "°", "-": "", "": ""}
STRENGTH = ("c", "phi", "psi", "tension")  # a mohr-coulomb layer's strength (schema.MC_FIELDS)
WORDS = {"E": "E (Young's modulus)", "nu": "ν (Poisson's ratio)", "K0": "K0 (earth pressure at rest)",
         "gamma": "γ (unit weight)", "c": "c′ (cohesion)", "phi": "φ′ (friction angle)",
         "psi": "ψ (dilation angle)", "tension": "tension cut-off", "k": "k (axial stiffness per metre run)",
         "preload": "preload (per metre run)"}
UNITS = {"E": "kPa", "nu": "-", "K0": "-", "gamma": "kN/m3", "c": "kPa", "phi": "deg", "psi": "deg",
         "tension": "kPa"}


def _unit(unit: str) -> str:
    return UNIT_TEXT.get(unit, unit)


def value_text(value: float, unit: str, like: float | None = None, digits: int = 4) -> str:
    """'10 MPa', '0.49', '20 kN/m³', '25°': a value in the unit engineers read it in (a modulus in kPa
    shown in MPa or GPa, as ``units.shown`` says for a value about `like`)."""
    factor, shown_unit = (1e3, "mm") if unit == "m" else shown(unit, value if like is None else like)
    u = _unit(shown_unit)
    text = number(value * factor, digits)
    return text + ("" if not u else u if u == "°" else f" {u}")


class Claims:
    """The identified parameters by name, each told once: the layer table and the structures' table
    claim theirs; what is left is listed apart."""

    def __init__(self, res):
        self.res = res
        self.names = list(res.parameters.names)
        self.claimed: set[str] = set()

    def has(self, name: str) -> bool:
        return name in self.names

    def row(self, name: str, case_value: float | None, unit: str) -> tuple[str, str, str]:
        """(value, status, 95 % interval) of a named quantity: the estimate where it was identified,
        else the case's value, fixed."""
        if not self.has(name):
            return (value_text(case_value, unit) if case_value is not None else "-", "fixed", "")
        self.claimed.add(name)
        i = self.names.index(name)
        p = float(self.res.fit.p[i])
        iv = self.res.interval(name)
        if iv.exists:
            lo = ("≤ " if iv.open[0] else "") + value_text(iv.low, unit, like=p)
            hi = ("≥ " if iv.open[1] else "") + value_text(iv.high, unit, like=p)
            cell = f"[{lo}, {hi}]"
        else:
            cell = f"none: {iv.reason}"
        return f"**{value_text(p, unit, like=p)}**", "identified", cell

    def unclaimed(self) -> list[str]:
        return [n for n in self.names if n not in self.claimed]


# ---------------------------------------------------------------------------------------------- geometry
def _point(p) -> str:
    return f"({number(p[0], 4)}, {number(p[1], 4)})"


def geometry_lines(case) -> list[str]:
    g = case.geometry
    if not hasattr(g, "openings"):
        cover = g.axis_depth - g.radius
        return [f"- circular tunnel of radius R = {number(g.radius)} m, its axis at {number(g.axis_depth)} m depth "
                f"(cover {number(cover)} m above the crown)",
                f"- half-model, symmetric about the tunnel's vertical axis x = 0: {number(g.width)} m wide from the "
                f"axis, {number(g.depth)} m deep (plane strain; the bottom fixed, the sides on rollers)"]
    from geoback.case.layout import polygon

    half = g.model == "half"
    out = [(f"- half-model, symmetric about x = 0: {number(g.width)} m wide from the symmetry axis"
            if half else f"- full model: {number(g.width)} m wide (x from {number(-g.width / 2)} to "
                         f"{number(g.width / 2)} m)") + f", {number(g.depth)} m deep (plane strain; the bottom fixed, the "
                                           "sides on rollers)"]
    for op in g.openings:
        x0, y0, x1, y1 = (round(v, 6) + 0.0 for v in polygon(op).bounds)  # (no -0, no sampling noise)
        if op.shape == "circle":
            shape = f"circle of radius {number(op.radius)} m about {_point(op.centre)}"
        elif op.shape == "horseshoe":
            shape = (f"horseshoe {number(2 * op.crown_radius)} m wide and {number(op.height)} m high, crown arc "
                     f"centred at {_point(op.centre)}")
        else:
            shape = f"polygon of {sum(1 for v in op.boundary if isinstance(v, (tuple, list)))} corners"
        extent = f"from {number(0.0 - y1, 4)} to {number(0.0 - y0, 4)} m depth, x from {number(x0, 4)} to {number(x1, 4)} m"
        parts = f"; in parts {', '.join(p.name for p in op.parts)}" if op.parts else "; excavated whole"
        out.append(f"- opening '{op.name}': {shape}, {extent}{parts}")
    return out


# ---------------------------------------------------------------------------------------------- ground
def ground_lines(res, claims: Claims) -> list[str]:
    case = res.case
    g = case.ground
    layers = list(g.layers)
    bottom = [layer.top for layer in layers[1:]] + [case.geometry.depth]
    out = ["| layer | depth [m] | quantity | value | status | 95 % interval |", "|---|---|---|---|---|---|"]
    for layer, low in zip(layers, bottom):
        depth = f"{number(layer.top, 4)} to {number(low, 4)}"
        own_k0 = layer.K0 is not None
        rows = [("E", f"E[{layer.name}]", layer.E), ("nu", f"nu[{layer.name}]", layer.nu),
                ("K0", f"K0[{layer.name}]" if own_k0 else "K0", layer.K0 if own_k0 else g.K0)]
        gamma = layer.unit_weight if layer.unit_weight is not None else g.unit_weight
        rows.append(("gamma", f"gamma[{layer.name}]", gamma))
        if layer.model == "mohr-coulomb":
            rows += [(q, f"{q}[{layer.name}]", getattr(layer, q)) for q in STRENGTH
                     if getattr(layer, q) is not None or claims.has(f"{q}[{layer.name}]")]
        for k, (stem, name, v) in enumerate(rows):
            if stem == "K0" and not own_k0 and v is None and not claims.has(name):
                continue
            value, status, cell = claims.row(name, v, UNITS[stem])
            if stem == "K0" and not own_k0:
                status += " (the ground's K0)"
            if stem == "gamma" and layer.unit_weight is None:
                status += " (the ground's)"
            first = k == 0
            out.append(f"| {layer.name if first else ''} | {depth if first else ''} | {WORDS[stem]} | {value} | "
                       f"{status} | {cell} |")
    models = sorted({layer.model for layer in layers})
    words = {"linear-elastic": "linear elastic", "mohr-coulomb": "elastic-perfectly plastic (Mohr-Coulomb)"}
    return ([f"Ground: {', '.join(words.get(m, m) for m in models)}; initial stresses σv = γ z, σh = K0 σv. "
             "Identified values are in bold (the estimate); fixed ones are the case's.", ""] + out)


# ---------------------------------------------------------------------------------------------- construction
def _sequence(case):
    if hasattr(case.geometry, "openings"):
        from geoback.case.sequence import Sequence

        return Sequence.of(case)
    return None


def circular_stage_lines(case) -> list[str]:
    """The circular tunnel's stages in the words of ``Sequence.describe``: what each installs and the
    cumulative fraction of the in-situ stress on the tunnel wall it releases."""
    c = case.construction
    if c is None:
        return ["stage 'excavation': excavates the tunnel, releases all of the in-situ stress on its wall "
                "(100 %, by default)"]
    out = []
    for s in c.stages:
        did = []
        if s.install:
            did.append("installs " + ", ".join([s.install] if isinstance(s.install, str) else s.install))
        if s.release is not None:
            did.append(f"releases the in-situ stress on the tunnel wall to {100 * float(s.release):g} % "
                       f"(beta[{s.name}])")
        out.append(f"stage '{s.name}': " + (", ".join(did) if did else "nothing"))
    return out


def construction_lines(res, claims: Claims) -> list[str]:
    case = res.case
    seq = _sequence(case)
    stages = seq.describe() if seq is not None else circular_stage_lines(case)
    out = ["As the case states them (the values the fit identified are in bold in the tables below):", ""]
    out += [f"- {line}" for line in stages]
    structures = structure_rows(case, seq, claims)
    if structures:
        out += ["", "Linings, walls, props and anchors:", "",
                "| structure | what and where | installed | removed | quantity | value | status | 95 % interval |",
                "|---|---|---|---|---|---|---|---|"] + structures
    releases = _release_rows(case, seq, claims)
    if releases:
        out += ["", "Releases (cumulative fraction of the stage's load released, β):", "",
                "| stage | value | status | 95 % interval |", "|---|---|---|---|"] + releases
    return out


def _release_rows(case, seq, claims: Claims) -> list[str]:
    c = case.construction
    if c is None:
        return []
    rows = []
    for s in c.stages:
        if s.release is None:
            continue
        value, status, cell = claims.row(f"beta[{s.name}]", float(s.release), "-")
        rows.append(f"| {s.name} | {value} | {status} | {cell} |")
    return rows


def _stage_of(case, name: str, field: str) -> str:
    c = case.construction
    for s in (c.stages if c is not None else []):
        v = getattr(s, field, None)
        names = [v] if isinstance(v, str) else (v or [])
        if name in names:
            return s.name
    return ""


def structure_rows(case, seq, claims: Claims) -> list[str]:
    c = case.construction
    if c is None:
        return []
    rows = []

    def add(name, what, values):
        installed = _stage_of(case, name, "install") or "from the start"
        removed = _stage_of(case, name, "remove") or "-"
        for k, (q, case_value, unit) in enumerate(values):
            value, status, cell = claims.row(f"{q}[{name}]", case_value, unit)
            head = (f"| {name} | {what} | {installed} | {removed} " if k == 0 else "| | | | ")
            rows.append(head + f"| {WORDS.get(q, q)} | {value} | {status} | {cell} |")

    linings = ([c.lining] if getattr(c, "lining", None) is not None else []) + list(getattr(c, "linings", None) or [])
    for ln in linings:
        on = getattr(ln, "on", None)
        where = ("inside the tunnel wall" if on is None else
                 f"across the cut of '{on}'" if getattr(ln, "side", "wall") == "cut" else f"on the wall of '{on}'")
        add(ln.name, f"lining {number(ln.thickness)} m thick {where}", [("E", ln.E, "kPa"), ("nu", ln.nu, "-")])
    for name, w in ((seq.walls or {}) if seq is not None else {}).items():
        add(name, f"wall {number(w.thickness, 4)} m thick at x = {number(w.x)} m, from {number(w.top)} to "
                  f"{number(w.toe)} m depth", [("E", w.E, "kPa"), ("nu", w.nu, "-")])
    for name, cn in ((seq.connectors or {}) if seq is not None else {}).items():
        add(name, f"{cn.kind} on '{cn.wall}' at {number(-cn.head[1])} m depth to {cn.far}",
            [("k", cn.stiffness, "kN/m/m"), ("preload", cn.preload, "kN/m")])
    return rows


# ---------------------------------------------------------------------------------------------- instruments
def _where(ins) -> str:
    kind = ins.kind
    if kind == "inclinometer":
        return (f"borehole at x = {number(ins.x)} m from {number(ins.head_depth)} to {number(ins.toe_depth)} m depth, "
                f"relative to its {ins.reference}")
    if kind in ("extensometer", "sliding_micrometer", "deflectometer"):
        return f"line from {_point(ins.start)} to {_point(ins.end)}"
    if kind == "points":
        pts = ins.points
        where = (", ".join(_point(p) for p in pts) if len(pts) <= 4
                 else f"{len(pts)} points from {_point(pts[0])} to {_point(pts[-1])}")
        return f"{where}; {', '.join(ins.components)}"
    if kind == "convergence":
        return f"chord {_point(ins.points[0])} to {_point(ins.points[1])}"
    if kind == "load_cell":
        return f"on '{ins.support}'"
    return ""


def _sigma(ins) -> str:
    s = getattr(ins, "sigma", None)
    if s is None:
        return ""
    if ins.kind == "inclinometer":
        return f"{number(1e3 * s, 3)} mrad"
    if ins.kind == "deflectometer":
        return f"{number(s, 3)} 1/m"
    if ins.kind == "load_cell":
        return f"{number(s, 3)} kN"
    return f"{number(1e3 * s, 3)} mm"


def instrument_lines(res) -> list[str]:
    case = res.case
    counts: dict[str, Counter] = {}
    for lab in res.data.labels:
        counts.setdefault(lab.instrument, Counter())[lab.stage or ""] += 1
    out = ["| instrument | kind | where [m] | σ of a reading | readings per stage |", "|---|---|---|---|---|"]
    for ins in case.instruments:
        per = counts.get(ins.name, Counter())
        read = ", ".join(f"{stage} {n}" if stage else f"{n}" for stage, n in per.items()) or "none"
        out.append(f"| {ins.name} | {ins.kind.replace('_', ' ')} | {_where(ins)} | {_sigma(ins)} | {read} |")
    return out


# ---------------------------------------------------------------------------------------------- mesh
def mesh_line(res) -> str:
    m = res.case.mesh
    order = ("6-node quadratic triangles" if m.order == 2 else "3-node linear triangles")
    sizes = []
    if m.size_tunnel is not None:
        at = "at the openings' walls" if hasattr(res.case.geometry, "openings") else "at the tunnel wall"
        sizes.append(f"{number(m.size_tunnel)} m {at}")
    if m.size_far is not None:
        sizes.append(f"{number(m.size_far)} m far away")
    return (f"- {res.elements:,} elements ({order}), {res.dofs // 2:,} nodes, {res.dofs:,} degrees of freedom"
            + (f"; element size {' and '.join(sizes)}" if sizes else ""))


# ---------------------------------------------------------------------------------------------- the section
def model_section(res) -> list[str]:
    """report.md's "## The model" section, as lines (module docstring)."""
    case = res.case
    claims = Claims(res)
    lines = ["## The model", ""]
    if getattr(case, "description", ""):
        lines += [case.description, ""]
    lines += ["### Geometry", ""] + geometry_lines(case)
    lines += ["", "### Ground", ""] + ground_lines(res, claims)
    lines += ["", "### Construction stages", ""] + construction_lines(res, claims)
    other = claims.unclaimed()
    if other:
        lines += ["", "Also identified: " + "; ".join(_other(res, n) for n in other) + "."]
    lines += ["", "### Mesh", "", mesh_line(res)]
    lines += ["", "### Instruments", ""] + instrument_lines(res)
    return lines + [""]


def _other(res, name: str) -> str:
    i = res.parameters.names.index(name)
    unit, p = res.parameters.units[i], float(res.fit.p[i])
    iv = res.interval(name)
    interval = (f" (95 % [{value_text(iv.low, unit, like=p)}, {value_text(iv.high, unit, like=p)}])"
                if iv.exists and all(map(math.isfinite, (iv.low, iv.high))) else "")
    return f"{name} = {value_text(p, unit, like=p)}{interval}"
