"""Model diagnosis: is the fit adequate, where is the mismatch, which missing physics explains it.

1. Adequacy: chi^2 = J_min against chi^2(m - n) (the sigma's in the case are absolute).
2. Location: each instrument's share of J; standardised residuals per reading, and for linewise
   instruments per interval in primary-reading space (W^-1 r / sigma, eqns 11/15/18), scanned for
   the run of same-signed residuals that stands out most.
3. Ranking: the score (Lagrange-multiplier) statistic of every hypothesis at the baseline optimum,
   S = ||P r'||^2 with P the projector on the part of the extension's whitened sensitivity that
   the baseline parameters cannot mimic; S ~ chi^2(k) if the extension is absent. An extension
   whose sensitivity lies in the baseline's span cannot be identified together with it: said so.
4. Refit the most promising; likelihood-ratio test dJ ~ chi^2(k), AIC, BIC; accept the best
   significant one (Bonferroni over the hypotheses refitted); look once more; stop when adequate
   or nothing more is significant. Hypotheses that no score test can rank (yielding: at an elastic
   state every sensitivity to the strength is zero; ``yielding.py``) are screened instead and
   refitted whenever the model is not adequate, in the same Bonferroni family.

Error scales (the case's ``error_scales``, scales.py). A free scale must not explain a mismatch
away, so:
- scales are estimated only where the case says so; every other sigma stays as stated;
- adequacy is three tests, all of which must pass: (a) chi^2 of the readings whose sigma is known
  (and of the priors), on Satterthwaite's dof (skipped when every scale is estimated, said so);
  (b) each estimated scale against what the case allows (Bonferroni over them): with a prior, the
  prior-predictive test (do the readings ask for a larger k than the prior allows?); without one,
  the F test of its scale against the pooled scale of every other instrument (a scale far above
  the others' is a located mismatch: named by `locate`, "I2's errors are 3.1x what the case
  states ... either I2 was read less accurately than stated or the model misses something that
  shows at I2"); (c) the score tests of the hypotheses, computed with the scales held at their
  estimates under the null (the baseline fit), so a hypothesis is scored against the noise level
  the baseline leaves;
- the mismatch shares of `locate` use the stated sigma's (the misfit a scale absorbed shows where
  it is);
- refits re-estimate the scales with the extension's parameters; likelihood ratios, AIC and BIC
  use the support function maximised over the scales (maximum-likelihood profile, eqn 5); a
  missing physics that explained a large scale brings it back towards 1 and the round after
  passes (b).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import special

from ..case import Parameter
from ..estimate import Fit, Settings, fit
from ..identification import Identification, conclude
from ..misfit import Misfit
from ..reliability import Reliability, chi2_sf
from ..simulation import is_constant
from . import yielding
from .hypotheses import Hypothesis, candidate_hypotheses

COLLINEAR = 1e-6  # relative norm of the part of a column the baseline cannot mimic
DEPTH_SEEDS = 7  # layer-boundary depths refitted evenly over a layer before bisection
REFIT_ITERATIONS = 100
STALLED = 0.01  # a refit whose J fell by less than this in its last step has stopped moving


@dataclass
class Mismatch:
    instrument: str
    kind: str
    share: float  # of J
    where: str  # plain words, e.g. "6-9 m depth"
    size: float  # displacement mismatch over the stretch [m] (measured - computed)
    sigmas: float  # its significance in standard deviations
    text: str


@dataclass
class Scored:
    hypothesis: Hypothesis
    score: float
    dof: int
    p_score: float
    collinear_with: str | None = None  # combination of baseline parameters it duplicates
    refit: Fit | None = None
    reliability: Reliability | None = None
    J0: float = float("nan")
    dJ: float = float("nan")
    p_lr: float = float("nan")
    aic: float = float("nan")
    bic: float = float("nan")
    misfit: Misfit | None = None  # the baseline extended with the hypothesis


@dataclass
class Round:
    chi2: float
    dof: int
    p_value: float
    mismatches: list[Mismatch]
    ranking: list[Scored]
    accepted: Scored | None
    adequate: bool = False  # chi^2 test passed and no hypothesis' score test is significant
    threshold: float = float("nan")  # per-hypothesis level alpha / K (Bonferroni over the library)
    scales: list = field(default_factory=list)  # scales.ScaleEstimate of every group at this round's fit
    scale_threshold: float = float("nan")  # per-scale level alpha / G (Bonferroni over the estimated scales)


@dataclass
class Diagnosis:
    case: str
    alpha: float
    rounds: list[Round]
    baseline: Identification  # the case's model fitted
    final: Identification  # the model with every accepted extension, fitted
    final_misfit: Misfit
    accepted: list[Scored] = field(default_factory=list)

    @property
    def baseline_fit(self) -> Fit:
        return self.baseline.fit

    @property
    def baseline_reliability(self) -> Reliability:
        return self.baseline.reliability

    @property
    def final_fit(self) -> Fit:
        return self.final.fit

    @property
    def final_reliability(self) -> Reliability:
        return self.final.reliability

    @property
    def adequate_before(self) -> bool:
        return self.rounds[0].adequate

    @property
    def adequate_after(self) -> bool:
        return self.rounds[-1].adequate


# ---------------------------------------------------------------------------------------------
def _fit_and_assess(misfit: Misfit, settings: Settings, method: str, max_iterations=None):
    res = fit(misfit, settings, method=method, max_iterations=max_iterations)
    return res, conclude(misfit, res, None, "", {}, {}).reliability


def scale_tests(rel: Reliability, alpha: float) -> tuple[list, float]:
    """The estimated scales tested against what the case allows, and the per-scale level."""
    tested = [e for e in rel.error_scales if e.estimated and e.allowed_test]
    return tested, alpha / max(len(tested), 1)


def locate(misfit: Misfit, res: Fit, rel: Reliability, alpha: float = 0.05) -> list[Mismatch]:
    """Each instrument's share of J (stated sigma's) and its most significant stretch of misfit;
    an estimated error scale larger than the case allows is a mismatch too."""
    out = []
    data = misfit.data
    r = data.measured - res.x
    scaled = rel.scales_estimated
    J = rel.chi2 if not scaled else rel.stated_J  # data and priors
    residual = rel.whitened_residual if not scaled else rel.stated_residual
    offset = 0
    for block in data.blocks:
        m = len(block.labels)
        rw = residual[offset:offset + m]
        ri = r[offset:offset + m]
        meas = data.measured[offset:offset + m]
        share = float(rw @ rw) / J if J > 0 else 0.0
        if block.integration is not None:
            z = np.linalg.solve(block.integration, ri) / block.sigma  # standardised primary residuals
        else:
            z = ri / np.sqrt(np.diag(block.covariance))
        i0, i1, stat = _strongest_run(z)
        if block.integration is not None:
            before = ri[i0 - 1] if i0 > 0 else 0.0
            size = float(ri[i1] - before)
            where = _stretch(block, i0, i1)
            what = {"inclinometer": "horizontal displacement", "deflectometer": "normal displacement"}.get(
                block.kind, "displacement along the line")
        else:
            size = float(ri[i0:i1 + 1].mean())
            labs = block.labels[i0:i1 + 1]
            where = (f"reading{'s' if i1 > i0 else ''} {i0 + 1}{'-' + str(i1 + 1) if i1 > i0 else ''} "
                     f"({', '.join(sorted({lab.component for lab in labs}))})")
            what = "displacement" if block.kind == "points" else "chord length change"
        direction = "under-predicted" if np.sign(size) == np.sign(np.mean(meas[i0:i1 + 1])) else "over-predicted"
        text = (f"{block.kind} {block.name}, {where}: {what} {direction} by {abs(size) * 1000:.2g} mm "
                f"({abs(stat):.1f} σ); {100 * share:.0f} % of J")
        out.append(Mismatch(block.name, block.kind, share, where, size, float(abs(stat)), text))
        offset += m
    params = misfit.parameters
    for i in np.flatnonzero(params.has_prior):  # a prior the readings contradict is a mismatch too
        z = (res.p[i] - params.prior_mean[i]) / params.prior_std[i]
        share = z * z / J if J > 0 else 0.0
        text = (f"prior on {params.names[i]}: the readings put it at {res.p[i]:.4g} {params.units[i]}, "
                f"{abs(z):.1f} σ from the prior {params.prior_mean[i]:.4g} ± {params.prior_std[i]:.2g}; "
                f"{100 * share:.0f} % of J")
        out.append(Mismatch(f"prior:{params.names[i]}", "prior", share, "", float(res.p[i] - params.prior_mean[i]),
                            float(abs(z)), text))
    tested, level = scale_tests(rel, alpha)
    for e in tested:
        if e.p_allowed < level:
            share = e.J / J if J > 0 else 0.0
            out.append(Mismatch(e.name, "error-scale", share, "all its readings", float(e.factor),
                                float(special.ndtri(1 - e.p_allowed / 2)) if e.p_allowed > 0 else float("inf"),
                                e.text + f"; {100 * share:.0f} % of J at the stated σ's"))
    # an instrument whose error scale is out of range is named as such before its stretches (same share)
    return sorted(out, key=lambda mm: (-round(mm.share, 9), mm.kind != "error-scale"))


def _strongest_run(z: np.ndarray) -> tuple[int, int, float]:
    """Contiguous stretch maximising |sum z| / sqrt(length)."""
    best = (0, 0, 0.0)
    c = np.concatenate([[0.0], np.cumsum(z)])
    for i in range(len(z)):
        for j in range(i, len(z)):
            s = (c[j + 1] - c[i]) / np.sqrt(j - i + 1)
            if abs(s) > abs(best[2]):
                best = (i, j, float(s))
    return best


def _stretch(block, i0: int, i1: int) -> str:
    """Where intervals i0..i1 of a linewise instrument lie (interval k ends at station k)."""
    pts = block.stations
    d = (pts[1] - pts[0]) / np.linalg.norm(pts[1] - pts[0]) if len(pts) > 1 else np.array([0.0, 1.0])
    reference = pts[0] - d * block.lengths[0]
    start = pts[i0 - 1] if i0 > 0 else reference
    end = pts[i1]
    if abs(start[0] - end[0]) < 1e-9:  # vertical line: depths
        a, b = sorted((abs(start[1]), abs(end[1])))
        return f"{a:.3g}-{b:.3g} m depth"
    return f"from ({start[0]:.3g}, {start[1]:.3g}) to ({end[0]:.3g}, {end[1]:.3g})"


def score_hypotheses(misfit: Misfit, p_hat: np.ndarray, hypotheses: list[Hypothesis]) -> list[Scored]:
    """Score statistic of each hypothesis at the baseline optimum (no refit). The statistic is the
    squared norm of the whitened residual projected on the part of the extension's whitened
    sensitivity the baseline cannot mimic; it does not depend on how parameters are scaled."""
    n = misfit.n
    out = []
    held = misfit.scales_at(p_hat)  # estimated error scales held at their null estimates (None: none)
    for h in hypotheses:
        ext = misfit.extended(h.parameters, h.extra_values, start=p_hat)
        p0 = np.concatenate([p_hat, [q.initial for q in h.parameters]])
        ev = ext.with_fixed_scales(held).evaluate(p0, jacobian=True)
        r, B = ev.r, ev.B
        J0 = float(r @ r) if held is None else ext.evaluate(p0).support
        B1, B2 = B[:, :n], B[:, n:]
        Q1, _ = np.linalg.qr(B1)
        M2 = B2 - Q1 @ (Q1.T @ B2)
        rel_norm = np.linalg.norm(M2, axis=0) / np.maximum(np.linalg.norm(B2, axis=0), 1e-300)
        k = len(h.parameters)
        if np.all(rel_norm < COLLINEAR):
            coef = np.linalg.lstsq(B1, B2[:, 0], rcond=None)[0]
            combo = ", ".join(nm for nm, c in zip(misfit.parameters.names, coef) if abs(c) > 1e-3 * np.abs(coef).max())
            out.append(Scored(h, 0.0, k, 1.0, collinear_with=combo, J0=J0, misfit=ext))
            continue
        coef = np.linalg.lstsq(M2, r, rcond=None)[0]
        S = float(np.sum((M2 @ coef) ** 2))
        out.append(Scored(h, S, k, chi2_sf(S, k), J0=J0, misfit=ext))
    return out


def _modelled(misfit: Misfit, h: Hypothesis) -> bool:
    """Can the misfit's simulation take the hypothesis' parameters (yielding ground has no anisotropy)?"""
    sim = misfit.simulation
    return all(sim.canonical(q.name) is not None for q in h.parameters if not is_constant(q.name))


def _lr_objective(misfit: Misfit, f: Fit) -> float:
    """What a likelihood ratio compares: J, or with estimated scales the support function maximised
    over them (maximum-likelihood profile; restricted likelihoods of different models don't compare)."""
    if not misfit.free:
        return f.J
    return misfit.evaluate(f.p).support


def _best_of_groups(scored: list[Scored]) -> list[Scored]:
    """One entry per group (the layer-boundary depth with the largest score, its p-value
    multiplied by the number of depths searched: Bonferroni within the group)."""
    best: dict[str, Scored] = {}
    size: dict[str, int] = {}
    for s in scored:
        g = s.hypothesis.group or s.hypothesis.key
        size[g] = size.get(g, 0) + 1
        if g not in best or s.score > best[g].score:
            best[g] = s
    for g, s in best.items():
        s.p_score = min(1.0, s.p_score * size[g])
    return sorted(best.values(), key=lambda s: (s.p_score, -s.score))


def _settled(f: Fit) -> bool:
    """Converged, or stopped by the iteration limit while J no longer moves."""
    if f.status == "converged":
        return True
    Js = [h.J for h in f.history if h.accepted]
    return len(Js) >= 2 and Js[-2] - Js[-1] < STALLED


def _choose(significant: list[Scored]) -> Scored | None:
    """Lowest AIC; a hypothesis with a searched depth must beat the others by more than 2 AIC
    (within 2 the data cannot tell them apart and the simpler search-free one is kept)."""
    if not significant:
        return None
    best = min(significant, key=lambda s: s.aic)
    plain = [s for s in significant if not s.hypothesis.group]
    if best.hypothesis.group and plain:
        rival = min(plain, key=lambda s: s.aic)
        if rival.aic - best.aic < 2.0:
            return rival
    return best


def _compare(s: Scored, J0: float, searched: int) -> None:
    """Likelihood-ratio test and information criteria of a refitted hypothesis; `searched` counts
    extra quantities chosen by search rather than by the fit (a boundary's depth)."""
    extra = len(s.hypothesis.parameters) + searched
    s.J0 = J0
    s.dJ = J0 - _lr_objective(s.misfit, s.refit)
    s.p_lr = chi2_sf(max(s.dJ, 0.0), extra)
    m = len(s.reliability.whitened_residual)
    s.aic = s.reliability.aic + 2 * searched
    s.bic = s.reliability.bic + searched * np.log(m)


def _split_layer_misfit(current: Misfit, case, loaded, layer: str, z: float, p_hat: np.ndarray,
                        E_below: float) -> Misfit:
    """The current model with layer `layer` split at depth z into two meshed layers (conforming
    boundary) and the lower layer's modulus identified."""
    from ..simulation import make_simulation

    layers = list(case.ground.layers)
    i = [ly.name for ly in layers].index(layer)
    lower = layers[i].model_copy(update={"name": f"{layer}_below", "top": float(z), "E": float(E_below)})
    ground = case.ground.model_copy(update={"layers": layers[:i + 1] + [lower] + layers[i + 1:]})
    split = loaded.with_case(case.model_copy(update={"ground": ground}))
    sim = make_simulation(split, backend=getattr(current.simulation, "backend", None),
                          blocks=list(current.data.blocks))
    spec = Parameter(name=f"E[{layer}_below]", initial=float(E_below), bounds=(float(E_below) / 50, float(E_below) * 50))
    return current.extended([spec], simulation=sim, start=p_hat)


def _refit_layer_boundary(current: Misfit, cur_fit: Fit, group: list[Scored], settings: Settings, method: str,
                          say) -> Scored:
    """Profile the boundary depth: conforming refits at the best-scored depths, then bisect."""
    layer = group[0].hypothesis.key.split("[", 1)[1].split("@")[0]
    key = f"zsplit[{layer}]"
    depths = sorted(t.hypothesis.extra_values[key] for t in group)
    step = depths[1] - depths[0] if len(depths) > 1 else 1.0
    sim = current.simulation
    case = sim.loaded.case
    names = [ly.name for ly in case.ground.layers]
    lo_z = case.ground.layers[names.index(layer)].top
    hi_z = ([ly.top for ly in case.ground.layers if ly.top > lo_z] + [case.geometry.depth])[0]
    by_depth = {t.hypothesis.extra_values[key]: t for t in group}
    E0 = float(current.values(cur_fit.p)[f"E[{layer}]"])
    tried: dict[float, Scored] = {}

    def attempt(z: float, template: Scored) -> None:
        z = round(float(z), 3)
        if z in tried or not lo_z < z < hi_z:
            return
        say(f"refitting with a layer boundary at {z:g} m in '{layer}'")
        try:
            misfit = _split_layer_misfit(current, case, sim.loaded, layer, z, cur_fit.p, E0)
        except Exception as exc:  # a depth gmsh cannot mesh (too close to the tunnel): skip it
            say(f"  skipped depth {z:g} m: {exc}")
            return
        h = template.hypothesis
        hyp = Hypothesis(f"layer-boundary[{layer}@{z:g}]", h.kind, f"a different stratum below {z:g} m in '{layer}'",
                         f"Below {z:g} m depth the ground of '{layer}' has another modulus (an unmodelled layer "
                         f"boundary, meshed as a new layer '{layer}_below').",
                         [Parameter(name=f"E[{layer}_below]", initial=E0)], {key: z}, group=h.group)
        t = Scored(hyp, template.score, template.dof, template.p_score, misfit=misfit)
        t.refit, t.reliability = _fit_and_assess(misfit, settings, method, REFIT_ITERATIONS)
        _compare(t, _lr_objective(current, cur_fit), 1)
        tried[z] = t

    # the score is a linear approximation that can overrate deep boundaries: besides the three
    # best-scored depths, seed refits evenly over the layer, then bisect around the best
    for t in group[:3]:
        attempt(t.hypothesis.extra_values[key], t)
    for z in np.linspace(lo_z, hi_z, DEPTH_SEEDS + 2)[1:-1]:
        attempt(min(depths, key=lambda d: abs(d - z)), by_depth[min(depths, key=lambda d: abs(d - z))])
    for width in (step / 2, step / 4):
        best_z = min(tried, key=lambda z: tried[z].refit.J)
        nearest = by_depth[min(by_depth, key=lambda d: abs(d - best_z))]
        attempt(best_z - width, nearest)
        attempt(best_z + width, nearest)
    best = min(tried.values(), key=lambda t: t.refit.J)
    within = [z for z, t in tried.items() if t.refit.J - best.refit.J < 3.84]  # profile likelihood, 95 %
    best.hypothesis.description += (f" Depths tried: {', '.join(f'{z:g}' for z in sorted(tried))} m; those within the "
                                    f"95 % profile-likelihood band: {min(within):g}-{max(within):g} m.")
    return best


def diagnose(case, alpha: float = 0.05, max_rounds: int = 2, refit_top: int = 4, method: str = "lm",
             progress=None) -> Diagnosis:
    """Find what the model is missing (see the module docstring). case: a LoadedCase or an Analysis."""
    from ..identification import Analysis, prepare

    analysis = case if isinstance(case, Analysis) else prepare(case)
    if analysis.misfit is None:
        from ..errors import GeobackError

        raise GeobackError("the case has instruments without readings: give 'readings' or 'readings_file' "
                           "for every instrument to diagnose it")
    settings = analysis.settings
    say = progress or (lambda msg: None)
    say("baseline fit")
    base = analysis.misfit
    base_fit = fit(base, settings, method=method)
    baseline = conclude(base, base_fit, analysis.case, analysis.loaded.digest(), {}, {})
    current, cur_fit, cur_rel = base, base_fit, baseline.reliability
    rounds: list[Round] = []
    accepted: list[Scored] = []
    for k in range(max_rounds + 1):
        mismatches = locate(current, cur_fit, cur_rel, alpha)
        tested, scale_level = scale_tests(cur_rel, alpha)
        if cur_rel.total_dof <= 0:
            rounds.append(Round(cur_rel.chi2, cur_rel.dof, cur_rel.p_value, mismatches, [], None, True,
                                scales=cur_rel.error_scales, scale_threshold=scale_level))
            break
        hyps = [h for h in candidate_hypotheses(current, cur_fit.p) if _modelled(current, h)]
        say(f"scoring {len(hyps)} hypotheses")
        ranking = _best_of_groups(scored := score_hypotheses(current, cur_fit.p, hyps))
        testable = [s for s in ranking if s.collinear_with is None]
        unscored = yielding.screen(current, cur_fit.p)  # likelihood-ratio refits only (yielding.py)
        threshold = alpha / max(len(testable) + len(unscored), 1)
        # adequate: the omnibus chi^2 test passes (readings of known sigma), every estimated error
        # scale is within what the case allows, and no targeted alternative is significant
        chi2_ok = cur_rel.p_value >= alpha if cur_rel.dof > 0 else True
        scales_ok = all(e.p_allowed >= scale_level for e in tested)
        adequate = chi2_ok and scales_ok and all(s.p_score >= threshold for s in testable)
        rnd = Round(cur_rel.chi2, cur_rel.dof, cur_rel.p_value, mismatches, ranking, None, adequate, threshold,
                    cur_rel.error_scales, scale_level)
        rounds.append(rnd)
        if adequate or k == max_rounds:
            break
        for s in testable[:refit_top]:
            if s.hypothesis.group:
                group = sorted((t for t in scored if t.hypothesis.group == s.hypothesis.group), key=lambda t: -t.score)
                winner = _refit_layer_boundary(current, cur_fit, group, settings, method, say)
                winner.p_score = s.p_score
                ranking[ranking.index(s)] = winner
                continue
            say(f"refitting with {s.hypothesis.title}")
            s.refit, s.reliability = _fit_and_assess(s.misfit, settings, method, REFIT_ITERATIONS)
            _compare(s, s.J0, 0)
        ranking += [s for s in (yielding.refit(h, current, cur_fit, settings, method, say) for h in unscored) if s]
        significant = [s for s in ranking if s.refit is not None and s.p_lr < threshold and _settled(s.refit)]
        rnd.accepted = _choose(significant)
        if rnd.accepted is None:
            rnd.adequate = chi2_ok and scales_ok  # nothing in the library does better
            break
        accepted.append(rnd.accepted)
        current, cur_fit, cur_rel = rnd.accepted.misfit, rnd.accepted.refit, rnd.accepted.reliability
    final = conclude(current, cur_fit, current.simulation.loaded.case, analysis.loaded.digest(), {}, {})
    return Diagnosis(analysis.case.name, alpha, rounds, baseline, final, current, accepted)
