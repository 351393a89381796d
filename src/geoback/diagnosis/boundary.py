"""A layer boundary's depth in `diagnose`: conforming refits with the layer split at a depth,
seeded over the layer, every low basin refined, the accepted boundary re-profiled for its 95 %
interval (the profile itself: depth.py; the round that calls these: procedure.py)."""
from __future__ import annotations

import numpy as np

from geoback.case.loading import Parameter
from geoback.inference.estimate import Fit, Settings
from geoback.inference.misfit import Misfit
from geoback.diagnosis.depth import DepthProfile, profile_depth
from geoback.diagnosis.refit import REFIT_ITERATIONS, compare, fit_and_assess, judge, lr_objective, null_start
from geoback.diagnosis.hypotheses import Hypothesis, unlogged_from
from geoback.diagnosis.results import Round, Scored

DEPTH_SEEDS = 7  # layer-boundary depths refitted evenly over a layer before bisection
LOSING = 50.0  # J units: a boundary whose best seed depth is this far above another refit is not refined


LAYER_EXTENSIONS = ("Egrad", "n", "m")  # per-layer extensions a split's lower layer inherits


def inherited(current: Misfit, p_hat: np.ndarray, layer: str) -> dict:
    """The per-layer extensions the current model gives `layer` (a gradient, anisotropy), as fixed
    values of the lower part of a split: with them, the split at its null modulus is the current model."""
    values = current.values(p_hat)
    return {f"{stem}[{layer}_below]": float(values[f"{stem}[{layer}]"]) for stem in LAYER_EXTENSIONS
            if f"{stem}[{layer}]" in values}


def null_modulus(current: Misfit, p_hat: np.ndarray, layer: str, z: float, top: float) -> float:
    """The modulus of `layer` at depth z in the current model (with its gradient if it has one): the
    lower part's null value, where the split equals the current model."""
    values = current.values(p_hat)
    return float(values[f"E[{layer}]"] + values.get(f"Egrad[{layer}]", 0.0) * (z - top))


def _split_layer_misfit(current: Misfit, case, loaded, layer: str, z: float, p_hat: np.ndarray,
                        E_below: float) -> Misfit:
    """The current model with layer `layer` split at depth z into two meshed layers (conforming
    boundary) and the lower layer's modulus identified (starting from E_below, the others from p_hat);
    the lower layer keeps the per-layer extensions the current model gives the layer (``inherited``)."""
    from geoback.physics.factory import make_simulation

    layers = list(case.ground.layers)
    i = [ly.name for ly in layers].index(layer)
    lower = layers[i].model_copy(update={"name": f"{layer}_below", "top": float(z), "E": float(E_below)})
    ground = case.ground.model_copy(update={"layers": layers[:i + 1] + [lower] + layers[i + 1:]})
    split = loaded.with_case(case.model_copy(update={"ground": ground}))
    sim = make_simulation(split, backend=getattr(current.simulation, "backend", None),
                          blocks=list(current.data.blocks))
    E_ref = float(current.values(p_hat)[f"E[{layer}]"])
    spec = Parameter(name=f"E[{layer}_below]", initial=float(E_below), bounds=(E_ref / 50, E_ref * 50))
    return current.extended([spec], values=inherited(current, p_hat, layer), simulation=sim, start=p_hat)


def _objective_at(misfit: Misfit, p: np.ndarray) -> float:
    """What a likelihood ratio compares (``refit.lr_objective``) at a point, not at a fit."""
    try:
        ev = misfit.evaluate(p)
    except Exception:  # noqa: BLE001 - no null objective: the base's J0 is compared
        return float("nan")
    return float(ev.support) if misfit.free else float(ev.J)


def _moved_boundary_misfit(misfit: Misfit, below: str, z: float, start: np.ndarray) -> Misfit:
    """`misfit` (whose case has the meshed layer `below`) with that layer's top moved to depth z."""
    from geoback.physics.factory import make_simulation

    sim0 = misfit.simulation
    case = sim0.loaded.case
    layers = [ly.model_copy(update={"top": float(z)}) if ly.name == below else ly for ly in case.ground.layers]
    moved = sim0.loaded.with_case(case.model_copy(update={"ground": case.ground.model_copy(update={"layers": layers})}))
    sim = make_simulation(moved, backend=getattr(sim0, "backend", None), blocks=list(misfit.data.blocks))
    return misfit.extended([], simulation=sim, start=start)


def _layer_range(case, layer: str) -> tuple[float, float]:
    names = [ly.name for ly in case.ground.layers]
    lo_z = case.ground.layers[names.index(layer)].top
    hi_z = ([ly.top for ly in case.ground.layers if ly.top > lo_z] + [case.geometry.depth])[0]
    return float(lo_z), float(hi_z)


def _depth_tolerance(lo: float, hi: float) -> float:
    return float(min(0.05, max(0.01, 1e-3 * (hi - lo))))


def _boundary_hypothesis(h: Hypothesis, layer: str, z: float, E0: float) -> Hypothesis:
    key = f"zsplit[{layer}]"
    return Hypothesis(f"layer-boundary[{layer}@{z:g}]", h.kind, f"a different stratum below {z:.3g} m in '{layer}'",
                      f"Below {z:.3g} m depth the ground of '{layer}' has another modulus (an unmodelled layer "
                      f"boundary, meshed as a new layer '{layer}_below').",
                      [Parameter(name=f"E[{layer}_below]", initial=E0)], {key: z}, group=h.group)


def refit_layer_boundary(current: Misfit, cur_fit: Fit, group: list[Scored], settings: Settings, method: str,
                          say, rival_J: float | None = None) -> Scored:
    """Profile the boundary depth over a continuous depth (``depth.py``): conforming refits at seed
    depths (the three best-scored and a few spread over the layer), then a search for the minimum
    (not when the best seed is LOSING J units above `rival_J`, the best refit of another
    hypothesis: it cannot win); its 95 % interval is found if it is accepted."""
    layer = group[0].hypothesis.key.split("[", 1)[1].split("@")[0]
    sim = current.simulation
    case = sim.loaded.case
    top, hi_z = _layer_range(case, layer)
    lo_z = unlogged_from(case, top)  # no boundary above the depth the boreholes log the strata to
    J0 = lr_objective(current, cur_fit)
    template = group[0]

    def refit_at(z: float, near: Scored | None) -> Scored:
        # the null start (the current optimum, the lower part at the layer's modulus there: the current
        # model on the split mesh) and a neighbouring depth's optimum; the fit starts from the lower
        E_null = null_modulus(current, cur_fit.p, layer, z, top)
        misfit = _split_layer_misfit(current, case, sim.loaded, layer, z, cur_fit.p, E_null)
        null = null_start(misfit)
        starts = [null] if near is None else [null, np.concatenate([near.refit.p[:-1], near.refit.p[-1:]])]
        t = Scored(_boundary_hypothesis(template.hypothesis, layer, z, E_null), template.score, template.dof,
                   template.p_score, misfit=misfit)
        t.refit, t.reliability = fit_and_assess(misfit, settings, method, REFIT_ITERATIONS, starts=starts)
        compare(t, J0, 1, J_null=_objective_at(misfit, null))
        return t

    # the score is a linear approximation that can overrate deep boundaries: besides the three
    # best-scored depths, seed refits evenly over the layer
    key = f"zsplit[{layer}]"
    seeds = [t.hypothesis.extra_values[key] for t in group[:3]] + list(np.linspace(lo_z, hi_z, DEPTH_SEEDS + 2)[1:-1])
    prof = profile_depth(layer, refit_at, lo_z, hi_z, seeds, _depth_tolerance(lo_z, hi_z), say, interval=False,
                         stop_above=None if rival_J is None else rival_J + LOSING,
                         lo_words="the layer's top" if lo_z == top else "the depth the strata are logged to")
    if not prof.points:
        raise RuntimeError(f"no depth of a boundary in '{layer}' could be meshed and refitted")
    best = prof.best
    best.profile = prof
    return best


def reprofile_boundary(s: Scored, misfit: Misfit, f: Fit, settings: Settings, method: str, say) -> DepthProfile:
    """The depth of an accepted boundary profiled again in a model with more effects added after it."""
    layer = s.profile.layer
    below = f"{layer}_below"

    def refit_at(z: float, near: Scored | None) -> Scored:
        m = _moved_boundary_misfit(misfit, below, z, f.p if near is None else near.refit.p)
        t = Scored(_boundary_hypothesis(s.hypothesis, layer, z, s.hypothesis.parameters[0].initial), s.score,
                   s.dof, s.p_score, misfit=m)
        t.refit, t.reliability = fit_and_assess(m, settings, method, REFIT_ITERATIONS)
        return t

    old = s.profile
    seeds = [old.z_hat, old.low, old.high]
    return profile_depth(layer, refit_at, old.lo_limit, old.hi_limit, seeds,
                         _depth_tolerance(old.lo_limit, old.hi_limit), say, lo_words=old.lo_words)


def boundary_interval(rnd: Round, say) -> None:
    """An accepted boundary: its depth's 95 % interval (a few more refits); if looking for an end
    found a better depth, that depth is the accepted one."""
    acc = rnd.accepted
    say(f"profile-likelihood interval of the boundary depth in '{acc.profile.layer}'")
    prof = acc.profile.interval()
    best = prof.best
    if best is not acc:
        best.profile = prof
        best.tested_as(acc)
        judge(best)
        rnd.ranking[rnd.ranking.index(acc)] = best
        rnd.accepted, rnd.tentative = best, not best.determined
    rnd.accepted.hypothesis.description += f" The boundary's {prof.text()}."
