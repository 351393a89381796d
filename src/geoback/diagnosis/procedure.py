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
   significant one (Bonferroni over the hypotheses refitted) whose extra parameters the readings
   determine (a significant hypothesis with an undetermined parameter, e.g. a deep stratum of
   unbounded modulus, is accepted only when nothing determined is, and then as tentative); look
   once more; stop when adequate or nothing more is significant. A layer boundary's depth is
   profiled over a continuous depth (``depth.py``), for every layer whose boundary's score test is
   significant, whether or not it ranks among the `refit_top` best (a score is linear at the null, and a
   modulus several times another is far from it: a soft layer reaching 6 m deeper than stated ranked 8th
   of 13 and was never searched). Hypotheses that no score test can rank
   (yielding: at an elastic state every sensitivity to the strength is zero; ``yielding.py``) are
   screened instead and refitted whenever the model is not adequate, in the same Bonferroni family.
   Every refit starts from the base model's optimum with the extension at its null value (a layer
   boundary's split mesh: also from a neighbouring depth's optimum, whichever is lower), and a refit
   that ends above the model it extends is no improvement (``refit.compare``: 'worse'). Hypotheses
   no score test can rank are screened and refitted: yielding (``yielding.py``) and, for a one-step
   unlined model, a support before the full release (``support.py``).
5. Compare (``compare.py``): Akaike weights of the refitted hypotheses and of the model without
   them; a rival within 2 AIC of the accepted one is reported with the readings that would tell
   them apart; the size of effect each score test could have detected.
   The accepted hypothesis is then tested as a claim (``claims.py``): determined and off its search
   bounds, predicting each instrument left out better than the model without it, for an error of one
   instrument explaining the readings alone (every other instrument explained without it, each one
   left out predicted within its band), for yielding ground a plastic zone the readings near the
   opening see (they improve by a significant amount themselves), no rival of another family within
   10 quasi-AIC that passes the checks of its round itself, and (after the final joint fit) no
   structure left in any instrument's residuals, a final model that explains the readings, and every
   extra parameter's 95 % interval there closed by the readings (not at a limit). A cause that passes is
   *named*; one that fails is *explained but not singled out* (``results.GRADES``). The last round's
   score tests, with no refit left to confirm them, never make the model inadequate: a score test
   alone is a linear approximation.
6. Report every accepted parameter from the final joint fit (profile-likelihood intervals where
   the linearised ones are not reliable); a boundary depth accepted before another effect is
   profiled again in the final model.

Causes: hypotheses blame either an instrument (its reference end moved, a bias shift, a depth
offset: ``hypotheses.INSTRUMENT_KINDS``) or the ground model (every other kind).

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

from dataclasses import replace

import numpy as np
from scipy import special

from geoback.inference.estimate import Fit, Settings, fit
from geoback.inference.identification import Identification, conclude
from geoback.inference.misfit import Misfit
from geoback.inference.reliability import Reliability, chi2_sf
from geoback.physics.simulation import is_instrument_term
from geoback.diagnosis import claims, support, yielding
from geoback.diagnosis.compare import EQUAL_AIC, akaike_weights, detectable_lambda, separation
from geoback.diagnosis.refit import REFIT_ITERATIONS, compare, fit_and_assess, judge
from geoback.diagnosis.hypotheses import Hypothesis, candidate_hypotheses, not_applicable
from geoback.diagnosis.boundary import boundary_interval, refit_layer_boundary, reprofile_boundary
from geoback.diagnosis.results import NO_ADDITION, Diagnosis, Mismatch, Round, Scored  # noqa: F401 (Mismatch: re-exported)

COLLINEAR = 1e-6  # relative norm of the part of a column the baseline cannot mimic


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
        if block.integration is not None and block.kept is None:
            z = np.linalg.solve(block.integration, ri) / block.sigma  # standardised primary residuals
        elif block.integration is not None:  # stations dropped: increments between the stations read
            D = np.eye(m) - np.eye(m, k=-1)
            z = (D @ ri) / np.sqrt(np.diag(D @ block.covariance @ D.T))
        else:
            z = ri / np.sqrt(np.diag(block.covariance))
        i0, i1, stat = _strongest_run(z)
        if block.integration is not None:
            before = ri[i0 - 1] if i0 > 0 else 0.0
            size = float(ri[i1] - before)
            where = _stretch(block, i0, i1)
            what = block.measures
        else:
            size = float(ri[i0:i1 + 1].mean())
            labs = block.labels[i0:i1 + 1]
            where = (f"reading{'s' if i1 > i0 else ''} {i0 + 1}{'-' + str(i1 + 1) if i1 > i0 else ''} "
                     f"({', '.join(sorted({lab.component for lab in labs}))})")
            what = {"points": "displacement", "load_cell": "force"}.get(block.kind, "chord length change")
        direction = "under-predicted" if np.sign(size) == np.sign(np.mean(meas[i0:i1 + 1])) else "over-predicted"
        amount = f"{abs(size):.3g} kN" if block.kind == "load_cell" else f"{abs(size) * 1000:.2g} mm"
        text = (f"{block.kind} {block.name}, {where}: {what} {direction} by {amount} "
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
    start = pts[i0 - 1] if i0 > 0 else block.reference
    end = pts[i1]
    if abs(start[0] - end[0]) < 1e-9:  # vertical line: depths
        a, b = sorted((abs(start[1]), abs(end[1])))
        return f"{a:.3g}-{b:.3g} m depth"
    return f"from ({start[0]:.3g}, {start[1]:.3g}) to ({end[0]:.3g}, {end[1]:.3g})"


def score_hypotheses(misfit: Misfit, p_hat: np.ndarray, hypotheses: list[Hypothesis]) -> list[Scored]:
    """Score statistic of each hypothesis at the baseline optimum (no refit). The statistic is the
    squared norm of the whitened residual projected on the part of the extension's whitened
    sensitivity the baseline cannot mimic; it does not depend on how parameters are scaled.

    It is taken with the baseline's C_x: under the null the residual is the baseline's, whitened as the
    baseline whitens it, so that S is chi^2(k). (An identified integration constant takes its variance
    out of C_x, ``InstrumentBlock.covariance_given``: the extension that identifies a reference end's
    movement whitens with less variance, and its residual at A = 0 is not the baseline's. Scored with
    that C_x, an extensometer's anchor moved was significant at the Bonferroni level in 5-7 % of staged,
    lined null cases instead of 0.56 %; E[S] = 2.86 on two constants with the model exact, 200 noise
    draws. The refit and its likelihood ratio are unaffected: with the constant's column in the model,
    its estimate and J at the optimum are the same under either C_x, the variance lying along that column.)"""
    n = misfit.n
    out = []
    held = misfit.scales_at(p_hat)  # estimated error scales held at their null estimates (None: none)
    for h in hypotheses:
        ext = misfit.extended(h.parameters, h.extra_values, start=p_hat)
        scoring = ext if ext.data is misfit.data else replace(ext, data=misfit.data)  # the baseline's C_x
        p0 = np.concatenate([p_hat, [q.initial for q in h.parameters]])
        ev = scoring.with_fixed_scales(held).evaluate(p0, jacobian=True)
        r, B = ev.r, ev.B
        J0 = float(r @ r) if held is None else scoring.evaluate(p0).support
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
        out.append(Scored(h, S, k, chi2_sf(S, k), J0=J0, misfit=ext, m2=M2))
    return out


def _modelled(misfit: Misfit, h: Hypothesis) -> bool:
    """Can the misfit's simulation take the hypothesis' parameters (yielding ground has no anisotropy)?
    The survey's own terms (integration constants, an inclinometer's bias and depth offset) are
    offered only where the survey has them (``hypotheses.candidate_hypotheses``)."""
    sim = misfit.simulation
    return all(sim.canonical(q.name) is not None for q in h.parameters if not is_instrument_term(q.name))


def _group(s: Scored) -> str:
    """The group a hypothesis is tested in (the depths of one layer boundary; else itself)."""
    return s.hypothesis.group or s.hypothesis.key


def _group_sizes(scored: list[Scored]) -> dict[str, int]:
    """How many hypotheses each group tests (its Bonferroni factor)."""
    sizes: dict[str, int] = {}
    for s in scored:
        sizes[_group(s)] = sizes.get(_group(s), 0) + 1
    return sizes


def _best_of_groups(scored: list[Scored]) -> list[Scored]:
    """One entry per group (the layer-boundary depth with the largest score, its p-value
    multiplied by the number of depths searched: Bonferroni within the group)."""
    best: dict[str, Scored] = {}
    size = _group_sizes(scored)
    for s in scored:
        g = _group(s)
        if g not in best or s.score > best[g].score:
            best[g] = s
    for g, s in best.items():
        s.p_single, s.group_size = s.p_score, size[g]
        s.p_score = min(1.0, s.p_score * size[g])
    return sorted(best.values(), key=lambda s: (s.p_score, -s.score))


def _choose(significant: list[Scored]) -> tuple[Scored | None, bool]:
    """Lowest AIC among the significant hypotheses, and whether the choice is tentative. Within
    2 AIC the data cannot tell two apart, and the simpler one is kept: one whose extra parameters
    the readings determine over one they do not, then one without a searched depth over one with.
    A hypothesis with an undetermined parameter (caveats.py: e.g. a deep stratum's modulus
    1.3e6 +- 1.1e7 kPa) that beats every determined one by more than that is accepted as tentative:
    it says where, not how much."""
    if not significant:
        return None, False
    best = min(significant, key=lambda s: s.aic)
    for simpler in (lambda s: s.determined, lambda s: not s.hypothesis.group):
        if not simpler(best):
            pool = [s for s in significant if simpler(s) and (s.determined or not best.determined)]
            if pool:
                rival = min(pool, key=lambda s: s.aic)
                if rival.aic - best.aic < EQUAL_AIC:
                    best = rival
    return best, not best.determined


def _weigh(rnd: Round, cur_rel: Reliability, data) -> None:
    """Akaike weights of the round's refitted hypotheses and of its model without them; the rival
    of the accepted one (within 2 AIC) and the readings that would tell the two apart."""
    refitted = [s for s in rnd.ranking if s.settled and np.isfinite(s.aic)]
    if not refitted:
        return
    rnd.aic = cur_rel.aic
    rnd.weights = akaike_weights({NO_ADDITION: cur_rel.aic, **{s.hypothesis.key: s.aic for s in refitted}})
    for s in refitted:
        s.weight = rnd.weights[s.hypothesis.key]
    acc = rnd.accepted
    if acc is None:
        return
    rivals = [s for s in refitted if s is not acc and abs(s.aic - acc.aic) < EQUAL_AIC]
    if rivals:
        rnd.rival = min(rivals, key=lambda s: s.aic)
        rnd.separation = separation(acc, rnd.rival, data)


def _detectable(ranking: list[Scored], scored: list[Scored], threshold: float) -> None:
    """The size of each hypothesis' effect its score test would catch with 80 % probability at the
    round's level (members of a group at the level divided by the group's size, as tested)."""
    sizes = _group_sizes(scored)
    cache: dict = {}
    for s in scored:
        if s.collinear_with is not None or s.m2_norms is None:
            continue
        level = threshold / sizes[_group(s)]
        key = (s.dof, round(level, 12))
        if key not in cache:
            cache[key] = detectable_lambda(s.dof, level)
        lam = cache[key]
        s.detectable = {n: float(np.sqrt(lam) / nrm) if nrm > 0 else float("inf")
                        for n, nrm in zip(s.hypothesis.names, s.m2_norms)}


def diagnose(case, alpha: float = 0.05, max_rounds: int = 2, refit_top: int = 4, method: str = "lm",
             progress=None, exclude=()) -> Diagnosis:
    """Find what the model is missing (see the module docstring). case: a LoadedCase or an Analysis.
    exclude: kinds of the catalogue (``hypotheses.KINDS``) not to propose (what the case knows is not
    so; the leave-one-family-out benchmark)."""
    import time

    from geoback.inference.identification import Analysis, prepare

    if not (isinstance(alpha, (int, float)) and 0.0 < float(alpha) < 1.0):
        from geoback.errors import GeobackError

        raise GeobackError(f"alpha: expected a significance level between 0 and 1 (e.g. 0.05), found {alpha!r}")
    for name, value, least in (("max_rounds", max_rounds, 0), ("refit_top", refit_top, 1)):
        if not (isinstance(value, int) and value >= least):
            from geoback.errors import GeobackError

            raise GeobackError(f"{name}: expected a whole number of at least {least}, found {value!r}")
    exclude = _excluded(exclude)
    t_start = time.perf_counter()
    analysis = case if isinstance(case, Analysis) else prepare(case)
    if analysis.misfit is None:
        from geoback.errors import GeobackError
        from geoback.observation.readings import require_readings

        require_readings(analysis.loaded)  # names them
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
    strength: dict = {}  # key -> yielding.StrengthProfile of an accepted yielding cause
    for k in range(max_rounds + 1):
        mismatches = locate(current, cur_fit, cur_rel, alpha)
        tested, scale_level = scale_tests(cur_rel, alpha)
        if cur_rel.total_dof <= 0:
            rounds.append(Round(cur_rel.chi2, cur_rel.dof, cur_rel.p_value, mismatches, [], None, True,
                                scales=cur_rel.error_scales, scale_threshold=scale_level))
            break
        hyps = [h for h in candidate_hypotheses(current, cur_fit.p) if _modelled(current, h) and h.kind not in exclude]
        say(scoring_words(hyps))
        ranking = _best_of_groups(scored := score_hypotheses(current, cur_fit.p, hyps))
        testable = [s for s in ranking if s.collinear_with is None]
        unscored = [] if "yielding" in exclude else yielding.screen(current, cur_fit.p)  # LR refits only (yielding.py)
        if "supported-release" not in exclude:  # the rival family of a one-step model (support.py)
            unscored += support.propose(current, cur_fit.p)
        threshold = alpha / max(len(testable) + len(unscored), 1)
        _detectable(ranking, scored, threshold)
        # adequate: the omnibus chi^2 test passes (readings of known sigma), every estimated error
        # scale is within what the case allows, and no targeted alternative is significant
        chi2_ok = cur_rel.p_value >= alpha if cur_rel.dof > 0 else True
        scales_ok = all(e.p_allowed >= scale_level for e in tested)
        adequate = chi2_ok and scales_ok and all(s.p_score >= threshold for s in testable)
        rnd = Round(cur_rel.chi2, cur_rel.dof, cur_rel.p_value, mismatches, ranking, None, adequate, threshold,
                    cur_rel.error_scales, scale_level, hypotheses=len(hyps), screened=len(unscored))
        rounds.append(rnd)
        if k == max_rounds:  # no refit left to confirm a score test: a score test alone never makes a
            rnd.adequate = chi2_ok and scales_ok  # model inadequate (it is a linear approximation)
            break
        if adequate:
            break
        chosen = testable[:refit_top]  # the plain hypotheses first: a searched depth that cannot beat them
        # every significant layer boundary is searched too: its score, a linear approximation at the null, ranks a
        # large change of modulus poorly (a soft layer reaching 6 m deeper than stated scored 8th of 13, below
        # two modulus gradients, and was never refitted), and its depth search seeds the whole layer anyway
        chosen += [s for s in testable[refit_top:] if s.hypothesis.group and s.p_score < threshold]
        for s in sorted(chosen, key=lambda t: bool(t.hypothesis.group)):  # is not searched in detail
            if s.hypothesis.group:
                group = sorted((t for t in scored if t.hypothesis.group == s.hypothesis.group), key=lambda t: -t.score)
                plain = [t.refit.J for t in chosen if not t.hypothesis.group and t.settled]
                try:
                    winner = refit_layer_boundary(current, cur_fit, group, settings, method, say,
                                                   min(plain) if plain else None)
                except RuntimeError as exc:
                    say(f"  {exc}")
                    continue
                winner.tested_as(s)
                ranking[ranking.index(s)] = winner
                judge(winner)
                continue
            say(f"refitting with {s.hypothesis.title}")
            s.refit, s.reliability = fit_and_assess(s.misfit, settings, method, REFIT_ITERATIONS)
            compare(s, s.J0, 0)
            judge(s)
        for y in ((support if h.kind == "supported-release" else yielding).refit(h, current, cur_fit, settings,
                                                                                 method, say) for h in unscored):
            if y is not None:
                judge(y)
                ranking.append(y)
        significant = [s for s in ranking if s.p_lr < threshold and s.settled]  # never one worse than its base
        rnd.accepted, rnd.tentative = _choose(significant)
        if rnd.accepted is not None and rnd.accepted.profile is not None:
            boundary_interval(rnd, say)
        _weigh(rnd, cur_rel, current.data)
        if rnd.accepted is None:
            rnd.adequate = chi2_ok and scales_ok  # nothing in the library does better
            break
        _claim_checks(rnd, current, cur_fit, alpha, say)
        accepted.append(rnd.accepted)
        current, cur_fit, cur_rel = rnd.accepted.misfit, rnd.accepted.refit, rnd.accepted.reliability
        if rnd.accepted.hypothesis.kind == "yielding":  # its strength without the angles assumed (yielding.py)
            current, cur_fit, cur_rel = _yielding_strength(rnd.accepted, current, cur_fit, cur_rel, strength,
                                                           settings, method, say)
    final_profiles = {}
    for j, s in enumerate(accepted):  # a boundary accepted before other effects: its depth in the final model
        if s.profile is not None and j < len(accepted) - 1:
            say(f"profiling the boundary depth in '{s.profile.layer}' again in the final model")
            prof = reprofile_boundary(s, current, cur_fit, settings, method, say)
            if prof.points:
                final_profiles[s.hypothesis.key] = prof
                best = prof.best
                current, cur_fit = best.misfit, best.refit
    if accepted:  # the refits stop at REFIT_ITERATIONS or when J stalls: the final model fitted as `run` fits it
        say("final joint fit")
        cur_fit = fit(current, settings, method=method, p0=cur_fit.p)
    for j, s in enumerate(accepted):  # a yielding layer's strength again in the final model where its round's
        if s.hypothesis.kind == "yielding" and (j < len(accepted) - 1 or s.hypothesis.key not in strength):
            again = _strength_profile(s, current, cur_fit, settings, method, say)  # model was not the final one
            if again is not None:
                strength[s.hypothesis.key] = again
    if accepted:  # what a true cause leaves behind: no structure in any instrument's residuals
        say("claim checks: residual structure after the final joint fit")
        left = claims.residual_structure(current, cur_fit.p, min(alpha, claims.STRUCTURE_ALPHA))
    say("final joint fit: intervals")
    extended = current.simulation.loaded  # the case with the accepted extensions (a split layer) if any
    final = conclude(current, cur_fit, extended.case, extended.digest(), {}, {}, settings=settings)
    if accepted:  # ... and a final model that explains the readings (else the library lacks something)
        rel = final.reliability
        enough = claims.adequacy(rel.chi2, rel.dof, rel.p_value, alpha)  # (the level the verdict's 'adequate' uses)
        for s in accepted:
            s.checks["residual-structure"] = left
            s.checks["adequacy"] = enough
            s.grade = claims.grade(s.checks)
    intervals = _open_intervals(final, current, settings, [n for s in accepted for n in s.hypothesis.names])
    out = Diagnosis(analysis.case.name, alpha, rounds, baseline, final, current, accepted, final_profiles,
                    time.perf_counter() - t_start, intervals, analysis.loaded, method,
                    not_applicable(analysis.case), strength)
    claims.regrade_final(accepted, out.open_ends, rounds, alpha)  # checks 4 and 6 again, every cause graded
    return out


def _strength_profile(s: Scored, misfit: Misfit, result: Fit, settings: Settings, method: str, say):
    """An accepted yielding cause's strength with phi' and psi profiled out (step 3 of yielding.py's
    docstring), on the model `misfit` fitted at `result`; None where its angles are parameters."""
    layer = s.hypothesis.key[len("yielding["):-1]
    say(f"the strength of '{layer}' with phi' and psi not assumed: the fit with them held at the points of a grid")
    return yielding.strength_profile(layer, misfit, result, settings, method, say)


def _yielding_strength(s: Scored, current: Misfit, cur_fit: Fit, cur_rel, strength: dict, settings: Settings,
                       method: str, say) -> tuple:
    """The round's model after an accepted yielding cause: its strength profiled (kept in `strength`) and, where
    the grid's best angles fit much better than the assumed ones, the model with them (yielding.adopt, step 4)."""
    prof = _strength_profile(s, current, cur_fit, settings, method, say)
    if prof is None:
        return current, cur_fit, cur_rel
    if prof.to_adopt:
        got = yielding.adopt(prof, current, settings, method, say)
        if got is not None:
            current, cur_fit, prof = got
            cur_rel = conclude(current, cur_fit, None, "", {}, {}).reliability
    strength[s.hypothesis.key] = prof
    return current, cur_fit, cur_rel


def _excluded(exclude) -> frozenset:
    """The kinds `diagnose` is asked not to propose, checked against the catalogue."""
    from geoback.diagnosis.hypotheses import KINDS

    if isinstance(exclude, str):
        exclude = [exclude]
    out = frozenset(exclude or ())
    unknown = sorted(out - set(KINDS))
    if unknown:
        from geoback.errors import GeobackError

        raise GeobackError(f"exclude: expected kinds of the library ({', '.join(KINDS)}), found "
                           f"{', '.join(map(repr, unknown))}")
    return out


def _claim_checks(rnd: Round, current: Misfit, cur_fit: Fit, alpha: float, say) -> None:
    """The accepted hypothesis of a round tested as a claim (``claims.py``): determined and off its
    bounds, predicting each instrument left out better than the model without it, no rival of another
    family within the evidence (listed with the readings that separate them). Residual structure is
    tested after the final joint fit; the grade is given then."""
    acc = rnd.accepted
    say(f"claim checks of {acc.hypothesis.title}: cross-validation across instruments"
        + (" and stages" if claims.stages_of(current) > 1 else ""))
    acc.checks["determined"] = claims.determined_check(acc)
    acc.checks.update(claims.cross_validations(current, cur_fit.p, acc.misfit, acc.refit.p))
    alone = claims.single_instrument(acc.hypothesis.names)
    if alone is not None:  # an error of one instrument: every other reading explained without it
        say(f"claim checks of {acc.hypothesis.title}: an error of {alone} alone")
        acc.checks["instrument-alone"] = claims.instrument_alone(acc.misfit, acc.refit.p, alone)
    record = claims.stated_record(acc)
    if record is not None:  # a reference end's movement against what the case states of it
        acc.checks["installation-record"] = record
    backed = claims.prior_support(current, cur_fit.p, acc.misfit, acc.refit.p)
    if backed is not None:  # where the model has priors: the readings alone call for it
        say(f"claim checks of {acc.hypothesis.title}: the readings alone, the priors left out")
        acc.checks["prior-support"] = backed
    if acc.hypothesis.kind == "yielding":  # the readings that see the plastic zone improve with it
        acc.checks["plastic-zone"] = claims.zone_seen(current, cur_fit.p, acc.misfit, acc.refit.p)
    if acc.hypothesis.kind == "layer-boundary" and acc.profile is not None:  # the readings below it show it
        acc.checks["boundary-seen"] = claims.boundary_seen(current, cur_fit.p, acc.misfit, acc.refit.p,
                                                           acc.profile.layer, acc.profile.z_hat, alpha,
                                                           acc.profile.low if acc.profile.has_interval else None)
    near = claims.rivals(acc, [s for s in rnd.ranking if s.refit is not None])
    if near:
        say(f"claim checks of its rivals: {', '.join(s.hypothesis.title for s in near)}")
    acc.rivals = [s for s in near if claims.credible(s, current, cur_fit.p)]
    acc.checks["rivals"] = claims.rival_check(acc, acc.rivals, [s for s in near if s not in acc.rivals])
    acc.separations = {s.hypothesis.key: separation(acc, s, current.data) for s in acc.rivals}
    if acc.rivals and (rnd.rival is None or rnd.rival.family == acc.family):
        rnd.rival = acc.rivals[0]
        rnd.separation = acc.separations[rnd.rival.hypothesis.key]
    acc.grade = claims.grade(acc.checks)


def scoring_words(hyps: list[Hypothesis]) -> str:
    """The progress line of a round's score tests, saying what is counted: 'scoring 37 hypotheses
    in 12 tests (the 26 depths of a layer boundary in 'clay' are one test)'."""
    sizes: dict[str, int] = {}
    for h in hyps:
        sizes[h.group or h.key] = sizes.get(h.group or h.key, 0) + 1
    groups = [(g, n) for g, n in sizes.items() if n > 1]
    if not groups:
        return f"scoring {len(hyps)} hypotheses"
    inner = "; ".join(f"the {n} depths of a layer boundary in '{g.split('[', 1)[1][:-1]}' are one test"
                      for g, n in groups)
    return f"scoring {len(hyps)} hypotheses in {len(sizes)} tests ({inner})"


def _open_intervals(final: Identification, misfit: Misfit, settings: Settings, names: list[str]) -> dict:
    """Profile-likelihood intervals of every accepted parameter `conclude` left linearised (the
    missing physics is where the model is most non-linear in its parameters: a modulus gradient, a
    stratum's modulus; a few dozen fast fits each). An end at a limit (a bound or the allowed range)
    is open: the readings do not bound the parameter there."""
    from geoback.case.limits import natural_limit
    from geoback.inference.parameters import parameter_limits
    from geoback.inference.profile import profile_interval

    out = {}
    params, f, rel = misfit.parameters, final.fit, final.reliability
    if f.status != "converged":
        return out
    values = misfit.values(f.p)
    for name in names:
        if name in final.profiled or name not in params.names:
            continue
        i = params.names.index(name)
        sd = float(rel.std[i])
        lim = parameter_limits(misfit.simulation, name, values)
        lo, hi = max(params.lower[i], lim.lo), min(params.upper[i], lim.hi)
        try:
            a, b = profile_interval(misfit.anchored(f.p), settings, f.p, f.J, i, sd if np.isfinite(sd) else np.nan,
                                    lo, hi, bool(params.log[i]) or lim.lo > 0)
        except Exception:  # noqa: BLE001 - the linearised interval stays, with its caveat
            continue
        out[name] = (float(a), float(b), a <= lo and not natural_limit(lim, lo), b >= hi)  # (no preload: found)
    return out
