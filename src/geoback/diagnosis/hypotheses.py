"""The library of model extensions `diagnose` can propose: physics the baseline model may lack.

Each hypothesis names its extra parameter(s) with the value that switches it off (the null
value, where the extended model equals the baseline) and bounds, fixed extra values (e.g. the
depth of a layer boundary), and a plain-words description. Their sensitivity columns are exact:
the extensions stay linear-elastic and are differentiated like the baseline (eqns 34-40).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from geoback.case.loading import Parameter


@dataclass
class Hypothesis:
    key: str  # e.g. "stiffness-gradient[clay]"
    kind: str  # one of KINDS
    title: str  # short plain words
    description: str  # one sentence on the physics
    parameters: list[Parameter]  # extra parameters, initial = null value
    extra_values: dict = field(default_factory=dict)  # fixed values the extension needs
    group: str = ""  # hypotheses of one group (layer-boundary depths) are alternatives

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.parameters]

    @property
    def cause(self) -> str:
        """'instrument' (error of an instrument) or 'ground' (physics the ground model lacks)."""
        return cause_of(self.kind)


@dataclass(frozen=True)
class Context:
    """What every row of the catalogue proposes from: the fitted model (its case, named values at
    the fit, the parameters it already has) and its survey."""

    misfit: object
    case: object
    values: dict
    baseline: frozenset

    @classmethod
    def of(cls, misfit, p_hat: np.ndarray) -> "Context":
        return cls(misfit, misfit.simulation.loaded.case, misfit.values(p_hat), frozenset(misfit.parameters.names))

    @property
    def tops(self) -> list[float]:
        """Layer tops and the model's bottom."""
        return [layer.top for layer in self.case.ground.layers] + [self.case.geometry.depth]

    def instruments(self) -> list:
        """One block per instrument (an instrument read at several stages: its first survey)."""
        return list({b.name: b for b in self.misfit.data.blocks}.values())


@dataclass(frozen=True)
class Kind:
    """One row of the catalogue: a kind of thing the model may lack.

    key: its name in reports and diagnosis.json; meaning: what it is, in words; cause: 'ground'
    (physics the ground model lacks) or 'instrument' (an error of an instrument: its reference,
    its systematic errors); propose: the hypotheses of this kind that apply to a fitted model,
    with null values at the fit (None: proposed by a screen of its own and tested by a refit only,
    as yielding is in ``yielding.py``)."""

    key: str
    meaning: str
    cause: str
    propose: Callable[[Context], list[Hypothesis]] | None


def _param(name: str, initial: float, lo: float, hi: float) -> Parameter:
    return Parameter(name=name, initial=initial, bounds=(lo, hi))


def _layers(ctx: Context):
    """(layer name, its modulus at the fit, its thickness, its top, its bottom) of every layer."""
    tops = ctx.tops
    for i, layer in enumerate(ctx.case.ground.layers):
        yield layer.name, ctx.values[f"E[{layer.name}]"], tops[i + 1] - tops[i], tops[i], tops[i + 1]


def _stiffness_gradient(ctx: Context) -> list[Hypothesis]:
    out = []
    for name, E, thick, _, _ in _layers(ctx):
        if f"Egrad[{name}]" not in ctx.baseline:
            out.append(Hypothesis(
                f"stiffness-gradient[{name}]", "stiffness-gradient", f"modulus of '{name}' increasing with depth",
                f"E in layer '{name}' grows linearly with depth below its top (E = E_top + Egrad * (depth - top)).",
                [_param(f"Egrad[{name}]", 0.0, -E / max(thick, 1.0) * 0.9, 20 * E / max(thick, 1.0))]))
    return out


def _anisotropy(ctx: Context) -> list[Hypothesis]:
    return [Hypothesis(
        f"anisotropy[{name}]", "anisotropy", f"cross-anisotropic stiffness in '{name}'",
        f"The horizontal modulus of '{name}' differs from the vertical one (E_h = n E_v; G_vh = E_v / (2 (1 + nu))).",
        [_param(f"n[{name}]", 1.0, 0.2, 5.0)]) for name, *_ in _layers(ctx) if f"n[{name}]" not in ctx.baseline]


def unlogged_from(case, top: float) -> float:
    """The shallowest depth of a layer (whose top is `top`) where a stratum boundary the model lacks may be:
    its top, or the depth the case's boreholes log the strata to (``ground.logged_to``) if deeper."""
    logged = case.ground.logged_to
    return float(top if logged is None else max(top, logged))


def _layer_boundary(ctx: Context) -> list[Hypothesis]:
    """Candidate boundary depths: within the layer, away from its edges and below the depth the
    case's boreholes log the strata to, a grid of ~R/2 (a group: the depths of one layer are
    alternatives, refined by ``boundary.py``)."""
    out = []
    size = tunnel_size(ctx.case)
    step = max(0.5, size / 2 if not hasattr(ctx.case.geometry, "openings") else round(2 * size) / 4)  # whole 0.5 m
    for name, E, _, top, bottom in _layers(ctx):
        for z in np.arange(unlogged_from(ctx.case, top) + step, bottom - step / 2, step):
            out.append(Hypothesis(
                f"layer-boundary[{name}@{z:g}]", "layer-boundary", f"a stiffer or softer stratum below {z:g} m in '{name}'",
                f"Below {z:g} m depth the ground of '{name}' has another modulus (an unmodelled layer boundary).",
                [_param(f"Esplit[{name}]", E, E / 20, E * 20)], {f"zsplit[{name}]": float(z)},
                group=f"layer-boundary[{name}]"))
    return out


def _k0_gradient(ctx: Context) -> list[Hypothesis]:
    if "K0grad" in ctx.baseline:
        return []
    from geoback.case.layout import reference_depth

    zc = reference_depth(ctx.case)
    return [Hypothesis("K0-gradient", "K0-gradient", "K0 varying with depth",
                       f"K0 changes linearly with depth (K0 = K0_axis + K0grad * (depth - {zc:.3g} m)).",
                       [_param("K0grad", 0.0, -0.5, 0.5)])]


def _stress_release(ctx: Context) -> list[Hypothesis]:
    """One-step models only: staged cases model the release before support explicitly."""
    if ctx.case.construction is not None or "beta" in ctx.baseline:
        return []
    return [Hypothesis("stress-release", "stress-release", "partial stress release before support",
                       "Only a fraction beta of the initial stress on the tunnel wall was released by the excavation.",
                       [_param("beta", 1.0, 0.05, 1.0)])]


def _staged_plan(ctx: Context):
    from geoback.case.construction import StagePlan

    if ctx.case.construction is None:
        return None
    plan = StagePlan.of(ctx.case)
    return plan if plan.lining is not None else None


def _release_before_lining(ctx: Context) -> list[Hypothesis]:
    """The release before the lining acts (the convergence-confinement beta), free from its assumed value."""
    if hasattr(ctx.case.geometry, "openings"):
        return _section_releases(ctx)
    plan = _staged_plan(ctx)
    name = plan.last_release_before_lining() if plan is not None else None
    if name is None or name in ctx.baseline:
        return []
    beta = float(ctx.values[name])
    later = [float(ctx.values[r]) for r, lined in zip(plan.release, plan.lined) if r is not None and lined]
    return [Hypothesis(
        "release-before-lining", "release-before-lining", "more or less stress released before the lining than assumed",
        f"The ground took another fraction of the in-situ stress than the assumed {beta:g} before the lining "
        f"'{plan.lining_name}' acted ({name}: the face was further or nearer, the lining later or earlier).",
        [_param(name, beta, 0.02, later[0] if later else 1.0)])]


def _lining_stiffness(ctx: Context) -> list[Hypothesis]:
    if hasattr(ctx.case.geometry, "openings"):
        return _section_linings(ctx)
    plan = _staged_plan(ctx)
    if plan is None or f"E[{plan.lining_name}]" in ctx.baseline:
        return []
    E = f"E[{plan.lining_name}]"
    El = float(ctx.values[E])
    return [Hypothesis(
        "lining-stiffness", "lining-stiffness", "a stiffer or softer lining than assumed",
        f"The lining '{plan.lining_name}' is stiffer or softer than its assumed E = {El:.4g} kPa (young or "
        f"cracked shotcrete, joints between segments, another thickness).",
        [_param(E, El, El / 50, El * 50)])]


def _section_releases(ctx: Context) -> list[Hypothesis]:
    """With openings: every stage's release (beta[stage], the part of an excavation's load taken before
    the support acts) the fit does not identify, free from its assumed value (``case/sequence.py``)."""
    from geoback.case.sequence import Sequence

    plan = Sequence.of(ctx.case)
    out = []
    for k, step in enumerate(plan.steps):
        name = step.release
        if name is None or name in ctx.baseline or name not in ctx.values:
            continue
        beta = float(ctx.values[name])
        later = [plan.steps[j] for j in range(k + 1, len(plan.steps)) if plan.steps[j].install]
        support = f"the linings installed at stage '{later[0].name}'" if later else "the support"
        out.append(Hypothesis(
            f"release-before-lining[{step.name}]", "release-before-lining",
            f"more or less of stage '{step.name}' released before its support than assumed",
            f"The ground took another fraction of the load of what stage '{step.name}' removed than the assumed "
            f"{beta:g} before {support} acted ({name}: the face was further or nearer, the support later or earlier).",
            [_param(name, beta, 0.02, 1.0)]))
    return out


def _section_linings(ctx: Context) -> list[Hypothesis]:
    """With openings: each lining's modulus E[lining] the fit does not identify, free."""
    from geoback.case.sequence import Sequence

    out = []
    for name in Sequence.of(ctx.case).linings:
        E = f"E[{name}]"
        if E in ctx.baseline or E not in ctx.values:
            continue
        El = float(ctx.values[E])
        out.append(Hypothesis(
            f"lining-stiffness[{name}]", "lining-stiffness", f"a stiffer or softer lining '{name}' than assumed",
            f"The lining '{name}' is stiffer or softer than its assumed E = {El:.4g} kPa (young or cracked shotcrete, "
            f"joints, another thickness).", [_param(E, El, El / 50, El * 50)]))
    return out


def _has_structures(case) -> bool:
    """Walls, props or anchors: a section with openings whose construction has them."""
    c = case.construction
    return hasattr(case.geometry, "openings") and c is not None and bool(c.walls or c.props or c.anchors)


def _walls(ctx: Context) -> list[Hypothesis]:
    """With retaining walls: each wall's modulus E[wall] the fit does not identify, free (a cracked section:
    E scales EI and EA together)."""
    from geoback.case.sequence import Sequence

    if not _has_structures(ctx.case):
        return []
    out = []
    for name in Sequence.of(ctx.case).walls or {}:
        E = f"E[{name}]"
        if E in ctx.baseline or E not in ctx.values:
            continue
        Ew = float(ctx.values[E])
        out.append(Hypothesis(
            f"wall-stiffness[{name}]", "wall-stiffness", f"a stiffer or softer wall '{name}' than assumed",
            f"The wall '{name}' bends more or less than its assumed E = {Ew:.4g} kPa gives (a cracked section, "
            f"another thickness or panel joints: E scales its EI and EA together).",
            [_param(E, Ew, Ew / 50, Ew * 5)]))
    return out


def _supports(ctx: Context, what: str) -> list[Hypothesis]:
    """With props or anchors: each one's stiffness k[name] (what='stiffness') or its preload (what='preload',
    where one is assumed) the fit does not identify, free."""
    from geoback.case.sequence import Sequence

    if not _has_structures(ctx.case):
        return []
    out = []
    for name, cn in (Sequence.of(ctx.case).connectors or {}).items():
        key = f"k[{name}]" if what == "stiffness" else f"preload[{name}]"
        if key in ctx.baseline or key not in ctx.values:
            continue
        v = float(ctx.values[key])
        if what == "stiffness":
            out.append(Hypothesis(
                f"support-stiffness[{name}]", "support-stiffness", f"{cn.kind} {name} stiffer or softer than designed",
                f"The {cn.kind} '{name}' takes load at another stiffness than its assumed {v:.4g} kN/m per m run (a "
                f"slack connection, shrinkage or creep of a slab, a waler that bends, a longer free length).",
                [_param(key, v, v / 100, v * 10)]))
        elif v > 0:
            out.append(Hypothesis(
                f"preload-lost[{name}]", "preload-lost", f"{cn.kind} {name}: preload not as assumed",
                f"The {cn.kind} '{name}' was locked at another load than its assumed {v:.4g} kN/m per m run (preload "
                f"lost at lock-off, a jack not fully pressed, relaxation).",
                [_param(key, v, 0.0, 3 * v)]))
    return out


def tunnel_size(case) -> float:
    """The tunnel's radius, or with openings the smallest opening's equivalent radius (the radius of
    the circle of the same area): the length candidate depths and screens are spaced by."""
    g = case.geometry
    if not hasattr(g, "openings"):
        return g.radius
    from geoback.case.layout import polygon

    return min(float(np.sqrt(polygon(op).area / np.pi)) for op in g.openings)


def _error_names(ctx: Context) -> set:
    """The survey's systematic-error terms the model can take and does not already have."""
    errors = set(ctx.misfit.simulation.survey.error_names)
    if not getattr(ctx.misfit.simulation, "reads_depth_offsets", False):
        errors = {n for n in errors if not n.startswith("zoff[")}
    return errors - ctx.baseline


def _bias_shift(ctx: Context) -> list[Hypothesis]:
    available, out = _error_names(ctx), []
    for block in ctx.instruments():
        bias = f"bias[{block.name}]"
        if bias in available:
            out.append(Hypothesis(
                f"bias-shift[{block.name}]", "bias-shift", f"inclinometer {block.name}: bias shift",
                f"Every reading of inclinometer '{block.name}' carries the same slope offset (a probe bias shift "
                f"between surveys), so its displacements are in error by bias x the distance from the "
                f"{block.reference_end}, growing along the casing.",
                [_param(bias, 0.0, -0.01, 0.01)]))
    return out


def _depth_offset(ctx: Context) -> list[Hypothesis]:
    available, out = _error_names(ctx), []
    for block in ctx.instruments():
        zoff = f"zoff[{block.name}]"
        if zoff in available:
            lo, hi = depth_offset_range(block, ctx.case)
            if hi - lo > 0.05:
                out.append(Hypothesis(
                    f"depth-offset[{block.name}]", "depth-offset", f"inclinometer {block.name}: depth offset",
                    f"The probe of inclinometer '{block.name}' was read at depths shifted from those recorded "
                    f"(zoff > 0: deeper), so each reading is the movement at another depth.",
                    [_param(zoff, 0.0, lo, hi)]))
    return out


def _integration_constant(ctx: Context) -> list[Hypothesis]:
    """A linewise instrument's reference end moved: its integration constants (eqns 11, 15, 18), every
    survey's when it was read at several stages."""
    constants: dict[str, list[str]] = {}
    for block in ctx.misfit.data.blocks:
        constants.setdefault(block.name, []).extend(block.constant_names)
    out = []
    for block in ctx.instruments():
        names = [n for n in constants[block.name] if n not in ctx.baseline]
        if names:
            out.append(Hypothesis(
                f"integration-constant[{block.name}]", "integration-constant",
                f"{block.kind} {block.name}: {block.reference_end_moved}",
                f"The reference end of {block.kind} '{block.name}' was assumed fixed but moved "
                f"(integration constant{'s' if len(names) > 1 else ''} {', '.join(names)} of eqns 11/15/18).",
                [_param(n, 0.0, -1.0, 1.0) for n in names]))
    return out


# The catalogue: one kind a row. Adding a hypothesis is adding a row (and, for new physics, its
# extension in ``physics/extensions.py``); the order is the order hypotheses are proposed in.
CATALOGUE: tuple[Kind, ...] = (
    Kind("stiffness-gradient", "modulus increasing linearly with depth", "ground", _stiffness_gradient),
    Kind("anisotropy", "cross-anisotropic stiffness (horizontal modulus differs from vertical)", "ground", _anisotropy),
    Kind("layer-boundary", "a layer boundary with a different modulus below it", "ground", _layer_boundary),
    Kind("K0-gradient", "K0 varying with depth", "ground", _k0_gradient),
    Kind("stress-release", "only part of the initial stress released before support (beta < 1)", "ground",
         _stress_release),
    Kind("release-before-lining", "more (or less) stress released before the lining than assumed", "ground",
         _release_before_lining),
    Kind("lining-stiffness", "a stiffer or softer lining than assumed", "ground", _lining_stiffness),
    Kind("wall-stiffness", "a stiffer or softer retaining wall than assumed (a cracked section)", "ground", _walls),
    Kind("support-stiffness", "a prop or anchor stiffer or softer than designed (a slack connection)", "ground",
         lambda ctx: _supports(ctx, "stiffness")),
    Kind("preload-lost", "a prop's preload or an anchor's lock-off load not as assumed", "ground",
         lambda ctx: _supports(ctx, "preload")),
    Kind("yielding", "the ground yields around the tunnel (Mohr-Coulomb plastic zone)", "ground", None),
    Kind("supported-release", "the tunnel was supported before the full release (a release fraction, then a lining)",
         "ground", None),
    Kind("bias-shift", "an inclinometer's readings carry a constant slope offset (error growing along the casing)",
         "instrument", _bias_shift),
    Kind("depth-offset", "an inclinometer's probe was read at depths shifted from those recorded", "instrument",
         _depth_offset),
    Kind("integration-constant", "a linewise instrument's reference end moved (integration constant not zero)",
         "instrument", _integration_constant),
)
KINDS = {k.key: k.meaning for k in CATALOGUE}
INSTRUMENT_KINDS = frozenset(k.key for k in CATALOGUE if k.cause == "instrument")
CAUSES = {"instrument": "instrument error", "ground": "ground physics"}


def cause_of(kind: str) -> str:
    """'instrument' or 'ground': the cause class of a kind (its row of ``CATALOGUE``)."""
    return "instrument" if kind in INSTRUMENT_KINDS else "ground"


def not_applicable(case) -> list[tuple[str, str]]:
    """(kind, why) of every row of the catalogue that cannot apply to this case's model, said in the
    diagnosis instead of tested."""
    out = []
    c = case.construction
    if not hasattr(case.geometry, "openings") and c is not None and c.lining is not None:
        out.append(("yielding", "a lining on yielding ground is modelled for sections with openings only: the "
                                "circular tunnel's lined case is not refitted with yielding ground"))
    logged = case.ground.logged_to
    if logged:
        below = ("below it, tested" if logged < case.geometry.depth else
                 "the boreholes reach the model's bottom, so nowhere")
        out.append(("layer-boundary", f"not above {logged:g} m, the depth the case's boreholes log the strata to "
                                      f"(ground: logged_to); {below}"))
    return out


def candidate_hypotheses(misfit, p_hat: np.ndarray) -> list[Hypothesis]:
    """Every extension that applies to the misfit's model, with null values taken at its fit p_hat:
    the catalogue's rows in order, each proposing what applies."""
    ctx = Context.of(misfit, p_hat)
    return [h for kind in CATALOGUE if kind.propose is not None for h in kind.propose(ctx)]


MAX_DEPTH_OFFSET = 2.0  # m: larger depth offsets are searched for no further


def depth_offset_range(block, case) -> tuple[float, float]:
    """How far an inclinometer's sampling points (stations and reference end) can be read deeper
    (positive) or shallower while staying in the ground, out of the tunnel, within 2 m."""
    g = case.geometry
    lo, hi = -MAX_DEPTH_OFFSET, MAX_DEPTH_OFFSET
    margin = 1e-3 * g.depth
    if hasattr(g, "openings"):
        return _depth_offset_range_section(block, g, lo, hi, margin)
    for x, y in block.points:
        lo = max(lo, y + margin)  # y - zoff <= -margin  (zoff < 0 moves up)
        hi = min(hi, y + g.depth - margin)
        dx = abs(x)
        if dx < g.radius * 1.05:  # the vertical through the point meets the tunnel: stop short of it
            half = np.sqrt(max((g.radius * 1.05) ** 2 - dx * dx, 0.0))
            top, bottom = -g.axis_depth + half, -g.axis_depth - half
            if y >= top:
                hi = min(hi, y - top)
            elif y <= bottom:
                lo = max(lo, y - bottom)
    return float(lo), float(hi)


def _depth_offset_range_section(block, g, lo: float, hi: float, margin: float) -> tuple[float, float]:
    """``depth_offset_range`` with openings: stop short (5 % of its size) of every opening the vertical
    through a sampling point meets."""
    from shapely.geometry import LineString

    from geoback.case.layout import polygon

    polys = [polygon(op) for op in g.openings]
    for x, y in block.points:
        lo = max(lo, y + margin)
        hi = min(hi, y + g.depth - margin)
        for poly in polys:
            pad = 0.05 * np.sqrt(poly.area / np.pi)
            cut = LineString([(x, 1.0), (x, -g.depth - 1.0)]).intersection(poly.buffer(pad))
            if cut.is_empty:
                continue
            ys = np.array([c[1] for piece in getattr(cut, "geoms", [cut]) for c in piece.coords])
            top, bottom = float(ys.max()), float(ys.min())
            if y >= top:
                hi = min(hi, y - top)
            elif y <= bottom:
                lo = max(lo, y - bottom)
    return float(lo), float(hi)
