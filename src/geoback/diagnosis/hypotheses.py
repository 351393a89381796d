"""The library of model extensions `diagnose` can propose: physics the baseline model may lack.

Each hypothesis names its extra parameter(s) with the value that switches it off (the null
value, where the extended model equals the baseline) and bounds, fixed extra values (e.g. the
depth of a layer boundary), and a plain-words description. Their sensitivity columns are exact:
the extensions stay linear-elastic and are differentiated like the baseline (eqns 34-40).
"""
from __future__ import annotations

from dataclasses import dataclass, field

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


KINDS = {
    "stiffness-gradient": "modulus increasing linearly with depth",
    "layer-boundary": "a layer boundary with a different modulus below it",
    "anisotropy": "cross-anisotropic stiffness (horizontal modulus differs from vertical)",
    "K0-gradient": "K0 varying with depth",
    "integration-constant": "a linewise instrument's reference end moved (integration constant not zero)",
    "stress-release": "only part of the initial stress released before support (beta < 1)",
    "bias-shift": "an inclinometer's readings carry a constant slope offset (error growing along the casing)",
    "depth-offset": "an inclinometer's probe was read at depths shifted from those recorded",
    "release-before-lining": "more (or less) stress released before the lining than assumed",
    "lining-stiffness": "a stiffer or softer lining than assumed",
}

# What a kind of hypothesis blames: the instruments (their reference, their systematic errors) or the
# ground model. A kind not listed here is ground physics.
INSTRUMENT_KINDS = frozenset({"integration-constant", "bias-shift", "depth-offset"})
CAUSES = {"instrument": "instrument error", "ground": "ground physics"}


def cause_of(kind: str) -> str:
    """'instrument' or 'ground' (see ``INSTRUMENT_KINDS``)."""
    return "instrument" if kind in INSTRUMENT_KINDS else "ground"


def _param(name: str, initial: float, lo: float, hi: float) -> Parameter:
    return Parameter(name=name, initial=initial, bounds=(lo, hi))


def candidate_hypotheses(misfit, p_hat: np.ndarray) -> list[Hypothesis]:
    """Every extension that applies to the misfit's model, with null values taken at its fit p_hat."""
    case = misfit.simulation.loaded.case
    values = misfit.values(p_hat)
    out: list[Hypothesis] = []
    tops = [layer.top for layer in case.ground.layers] + [case.geometry.depth]
    baseline = set(misfit.parameters.names)
    R, zc = case.geometry.radius, case.geometry.axis_depth
    for i, layer in enumerate(case.ground.layers):
        name = layer.name
        E = values[f"E[{name}]"]
        thick = tops[i + 1] - tops[i]
        if f"Egrad[{name}]" not in baseline:
            g_max = 20 * E / max(thick, 1.0)
            out.append(Hypothesis(
                f"stiffness-gradient[{name}]", "stiffness-gradient", f"modulus of '{name}' increasing with depth",
                f"E in layer '{name}' grows linearly with depth below its top (E = E_top + Egrad * (depth - top)).",
                [_param(f"Egrad[{name}]", 0.0, -E / max(thick, 1.0) * 0.9, g_max)]))
        if f"n[{name}]" not in baseline:
            out.append(Hypothesis(
                f"anisotropy[{name}]", "anisotropy", f"cross-anisotropic stiffness in '{name}'",
                f"The horizontal modulus of '{name}' differs from the vertical one (E_h = n E_v; "
                f"G_vh = E_v / (2 (1 + nu))).",
                [_param(f"n[{name}]", 1.0, 0.2, 5.0)]))
        # candidate boundary depths: within the layer, away from its edges, a grid of ~R/2
        step = max(0.5, R / 2)
        depths = np.arange(tops[i] + step, tops[i + 1] - step / 2, step)
        for z in depths:
            out.append(Hypothesis(
                f"layer-boundary[{name}@{z:g}]", "layer-boundary",
                f"a stiffer or softer stratum below {z:g} m in '{name}'",
                f"Below {z:g} m depth the ground of '{name}' has another modulus (an unmodelled layer boundary).",
                [_param(f"Esplit[{name}]", E, E / 20, E * 20)], {f"zsplit[{name}]": float(z)},
                group=f"layer-boundary[{name}]"))
    if "K0grad" not in baseline:
        out.append(Hypothesis(
            "K0-gradient", "K0-gradient", "K0 varying with depth",
            f"K0 changes linearly with depth (K0 = K0_axis + K0grad * (depth - {zc:g} m)).",
            [_param("K0grad", 0.0, -0.5, 0.5)]))
    if case.construction is not None:
        out += _construction_hypotheses(case, values, baseline)
    elif "beta" not in baseline:  # staged cases model the release before support explicitly
        out.append(Hypothesis(
            "stress-release", "stress-release", "partial stress release before support",
            "Only a fraction beta of the initial stress on the tunnel wall was released by the excavation.",
            [_param("beta", 1.0, 0.05, 1.5)]))
    constants: dict[str, list[str]] = {}  # an instrument read at several stages: every survey's constants
    for block in misfit.data.blocks:
        constants.setdefault(block.name, []).extend(block.constant_names)
    errors = set(misfit.simulation.survey.error_names)
    if not getattr(misfit.simulation, "reads_depth_offsets", False):
        errors = {n for n in errors if not n.startswith("zoff[")}
    for block in {b.name: b for b in misfit.data.blocks}.values():
        out += _instrument_error_hypotheses(block, case, errors - baseline)
        names = [n for n in constants[block.name] if n not in baseline]
        if not names:
            continue
        what = {"inclinometer": "toe (or head) moved", "sliding_micrometer": "anchor moved",
                "extensometer": "anchor moved", "deflectometer": "reference end moved and rotated"}[block.kind]
        out.append(Hypothesis(
            f"integration-constant[{block.name}]", "integration-constant", f"{block.kind} {block.name}: {what}",
            f"The reference end of {block.kind} '{block.name}' was assumed fixed but moved "
            f"(integration constant{'s' if len(names) > 1 else ''} {', '.join(names)} of eqns 11/15/18).",
            [_param(n, 0.0, -1.0, 1.0) for n in names]))
    return out


MAX_DEPTH_OFFSET = 2.0  # m: larger depth offsets are searched for no further


def depth_offset_range(block, case) -> tuple[float, float]:
    """How far an inclinometer's sampling points (stations and reference end) can be read deeper
    (positive) or shallower while staying in the ground, out of the tunnel, within 2 m."""
    g = case.geometry
    lo, hi = -MAX_DEPTH_OFFSET, MAX_DEPTH_OFFSET
    margin = 1e-3 * g.depth
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


def _instrument_error_hypotheses(block, case, available: set) -> list[Hypothesis]:
    """An inclinometer's systematic errors (instruments.ERROR_STEMS) as hypotheses."""
    out = []
    bias, zoff = f"bias[{block.name}]", f"zoff[{block.name}]"
    end = "toe" if block.stations[0][1] < block.stations[-1][1] else "head"
    if bias in available:
        out.append(Hypothesis(
            f"bias-shift[{block.name}]", "bias-shift", f"inclinometer {block.name}: bias shift",
            f"Every reading of inclinometer '{block.name}' carries the same slope offset (a probe bias shift "
            f"between surveys), so its displacements are in error by bias x the distance from the {end}, "
            f"growing along the casing.",
            [_param(bias, 0.0, -0.01, 0.01)]))
    if zoff in available:
        lo, hi = depth_offset_range(block, case)
        if hi - lo > 0.05:
            out.append(Hypothesis(
                f"depth-offset[{block.name}]", "depth-offset", f"inclinometer {block.name}: depth offset",
                f"The probe of inclinometer '{block.name}' was read at depths shifted from those recorded "
                f"(zoff > 0: deeper), so each reading is the movement at another depth.",
                [_param(zoff, 0.0, lo, hi)]))
    return out


def _construction_hypotheses(case, values: dict, baseline: set) -> list[Hypothesis]:
    """Staged construction with a lining: the release before the lining acts (the CCM's beta) and
    the lining's stiffness, each free from its assumed value."""
    from geoback.case.construction import StagePlan

    plan = StagePlan.of(case)
    out: list[Hypothesis] = []
    if plan.lining is None:
        return out
    name = plan.last_release_before_lining()
    if name is not None and name not in baseline:
        beta = float(values[name])
        later = [float(values[r]) for r, lined in zip(plan.release, plan.lined) if r is not None and lined]
        stage = name[len("beta["):-1]
        out.append(Hypothesis(
            "release-before-lining", "release-before-lining",
            "more or less stress released before the lining than assumed",
            f"The ground took another fraction of the in-situ stress than the assumed {beta:g} before the lining "
            f"'{plan.lining_name}' acted ({name}: the face was further or nearer, the lining later or earlier).",
            [_param(name, beta, 0.02, later[0] if later else 1.0)]))
    E = f"E[{plan.lining_name}]"
    if E not in baseline:
        El = float(values[E])
        out.append(Hypothesis(
            "lining-stiffness", "lining-stiffness", "a stiffer or softer lining than assumed",
            f"The lining '{plan.lining_name}' is stiffer or softer than its assumed E = {El:.4g} kPa (young or "
            f"cracked shotcrete, joints between segments, another thickness).",
            [_param(E, El, El / 50, El * 50)]))
    return out
