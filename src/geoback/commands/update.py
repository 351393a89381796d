"""`geoback update`: the observational method as construction proceeds.

For every construction stage with surveys up to the cut-off (a stage, or a date), in order: fit all
surveys read by the end of that stage (a joint refit: the update is exact, and its last step *is* the
fit of every survey up to the cut-off), forecast every instrument at every later stage with its band,
score the surveys of that stage against what the previous step forecast before they were read, and
put every trigger level (TARP) against the latest reading and the forecasts of the next stage and of
the end (``worth/updating.py``). The mesh is made once and shared by the steps.
"""
from __future__ import annotations

from pathlib import Path

from geoback.case.loading import LoadedCase, stage_names


def update_case(loaded: LoadedCase, out: Path, until=None, say=None, plots: bool = False, draws: int | None = None):
    """Run the update (module docstring) and write its files to `out`; the steps (``UpdateStep``). The
    last step's forecasts run the sampling check (`draws`, default the forecast's) for their triggers."""
    from dataclasses import replace

    from geoback.inference.identification import identify, prepare
    from geoback.observation.readings import survey_blocks
    from geoback.reports.update_report import write_update
    from geoback.worth.updating import (UpdateStep, forecast_surveys, later_blocks, scored, sequential_step,
                                        trigger_table)

    say = say or (lambda text: None)
    stages = stage_names(loaded.case)
    cut = loaded.up_to(until if until is not None else stages[-1])
    blocks, _ = survey_blocks(cut, stages)
    if not blocks:
        raise loaded.error(("instruments",), f"expected surveys up to {_cut_words(until)}, found none")
    read = [s for s in stages if any(b.stage == s for b in blocks)]
    since = {b.name: b.since for b in blocks}  # from every survey up to the cut-off (a baseline says it)
    steps, mesh, previous, previous_blocks = [], None, None, []
    for k, stage in enumerate(read):
        last = k == len(read) - 1
        step_cut = until if (last and until is not None and not isinstance(until, str)) else stage
        lk = loaded.up_to(step_cut)
        analysis = prepare(lk, mesh=mesh)
        mesh = analysis.simulation.mesh
        fitted = [b for b in analysis.simulation.survey.blocks]
        say(f"update through stage '{stage}'{'' if step_cut == stage else f' (surveys to {_cut_words(step_cut)})'}: "
            f"fitting {len(fitted)} surveys of {len({b.name for b in fitted})} instruments")
        res = identify(analysis)
        say(f"  {res.status}: " + ", ".join(f"{n} = {v:.4g}" for n, v in zip(res.parameters.names, res.fit.p)))
        ahead = forecast_surveys(analysis, res, later_blocks(analysis, stage, since), stage)
        checks = ()
        if previous is not None:
            mine = [b for b in fitted if b.stage == stage]
            values = _measured_of(analysis, mine)
            checks = tuple(scored(_per_survey(previous.ahead, mine), mine, values))
            for c in checks:
                say(f"  {c.sentence()}")
        sequential = None
        if previous is not None:  # the check: the previous posterior as the prior of the new surveys alone
            old = {(b.name, b.set_name) for b in previous_blocks}
            new = [b for b in fitted if (b.name, b.set_name) not in old]
            prev = previous.result
            sequential = sequential_step(analysis, new, _measured_of(analysis, new), prev.fit.p,
                                         prev.reliability.covariance, res.fit.p, res.reliability.std)
            say("  sequential Bayesian update (the previous posterior as prior): "
                + ", ".join(f"{n} {d:+.2g} σ" for n, d in zip(res.parameters.names, sequential.difference_std))
                + " from the joint refit")
        forecasts = None
        if loaded.case.forecasts:
            from geoback.worth.forecast import forecast, unusable_estimate

            if not unusable_estimate(res):
                forecasts = forecast(analysis, res, draws=draws if last else 0)
        step = UpdateStep(stage, res, tuple(f"{b.name} {b.set_name}" for b in fitted), tuple(ahead), checks,
                          forecasts=forecasts, sequential=sequential)
        step = replace(step, triggers=tuple(trigger_table(analysis, stage, ahead, forecasts)))
        steps.append(step)
        previous, previous_blocks = step, fitted
    write_update(steps, loaded, Path(out), until, plots=plots)
    return steps


def _cut_words(until) -> str:
    from geoback.case.dates import shown_date

    return f"stage '{until}'" if isinstance(until, str) else shown_date(until) if until is not None else "the end"


def _measured_of(analysis, blocks):
    """The readings of `blocks` (blocks of the analysis' survey), stacked in their order."""
    import numpy as np

    survey = analysis.simulation.survey.blocks
    x = analysis.misfit.data.measured
    out, r0 = {}, 0
    for b in survey:
        out[id(b)] = x[r0:r0 + b.m]
        r0 += b.m
    return np.concatenate([out[id(b)] for b in blocks]) if blocks else np.zeros(0)


def _per_survey(ahead, blocks):
    """The previous step's forecast of (instrument, stage) for each survey block read at that stage:
    the same model and band, the survey's own C_x, restricted to the rows the survey kept."""
    by = {(f.instrument, f.stage): f for f in ahead}
    out = []
    for b in blocks:
        f = by.get((b.name, b.stage))
        if f is not None:
            rows = b.kept if b.kept is not None else range(len(f.forecast))
            out.append(f.rows(rows, b.labels, b.survey, b.covariance))
    return out
