"""`geoback run`: prepare, identify, explore what the outputs need, write every file of one case."""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from geoback.case.loading import LoadedCase
from geoback.inference.identification import Identification, identify, prepare
from geoback.case.strength import is_plastic


def run_case(loaded: LoadedCase, out: Path, method: str | None = None, progress=None, vtu: bool | None = None,
             plots: bool = False, say=None, prepared=None, profile: str = "auto", matched=None,
             objective_map: str = "auto") -> Identification:
    """identify() the case, explore what the field file and figures need, write all outputs to `out`.

    progress(iteration) follows the fit; say(text) the steps after it and how the readings were
    matched; prepared(analysis) is called once the case is meshed and read, before the fit;
    matched(lines) with how the readings were matched (also in report.md and summary.json);
    objective_map: how the objective map of the figures is drawn ('auto', 'model', 'linearised':
    ``inference.explore``). Instruments without readings are refused, named."""
    from geoback.inference.explore import explore
    from geoback.observation.readings import readings_report, require_readings
    from geoback.reports.report import write_run

    analysis = prepare(loaded)
    readings = readings_report(loaded)
    require_readings(loaded, readings)
    lines = readings.lines()
    if matched is not None:
        matched(lines)
    if say is not None:
        for line in lines:
            say(f"readings: {line}")
    if prepared is not None:
        prepared(analysis)
    res = identify(analysis, method=method, progress=progress, profile=profile, mesh_error=None)
    if loaded.case.forecasts:
        from geoback.worth.forecast import forecast, unusable_estimate
        from geoback.reports.forecast_report import forecast_caveats

        names = ", ".join(f.name for f in loaded.case.forecasts)
        why = unusable_estimate(res)
        if why:  # what the library's forecast() refuses, said here and kept with the results
            from geoback.inference.caveats import Caveat

            if say is not None:
                say(f"forecasts: {names} not computed: {why}")
            res = replace(res, caveats=tuple(res.caveats) + (Caveat("forecast-skipped", f"forecasts {names} not "
                                                                                        f"computed: {why}"),))
        else:
            if say is not None:
                say(f"forecasts: {names}")
            fc = forecast(analysis, res, progress=say)
            res = replace(res, forecasts=fc, caveats=tuple(res.caveats) + tuple(forecast_caveats(fc)))
    vtu = loaded.case.output.vtu if vtu is None else vtu
    what = ("field",) if vtu else ()
    construction = loaded.case.construction
    if construction is not None and construction.lining is not None:
        what += ("lining",)  # thrust and moments around the lining: lining.csv, lining.vtu, the figure
    if is_plastic(loaded.case):
        what += ("plastic_zone",)  # the yielded ground: plastic_zone.csv, report section, the figure
    if plots:
        from geoback.reports.plots import exploration_for

        what = tuple(sorted(set(what) | set(exploration_for())))
    exploration = explore(analysis.misfit, res, what, analysis.settings, progress=say,
                          objective_map=objective_map) if what else None
    if construction is not None and construction.walls:  # walls.csv, supports.csv, the report's section, figures
        from geoback.inference.explore import Exploration
        from geoback.worth.walls import of_result

        from geoback.worth.walls import WallsUnavailable

        if say is not None:
            say("walls and supports: section forces and support forces per stage with their bands")
        try:
            exploration = replace(exploration or Exploration(), walls=of_result(analysis, res))
        except WallsUnavailable as exc:  # refused, said and kept with the results: never written wrong
            from geoback.inference.caveats import Caveat

            if say is not None:
                say(f"walls and supports: not written: {exc}")
            res = replace(res, caveats=tuple(res.caveats) + (Caveat("walls-skipped", f"walls.csv and supports.csv "
                                                                                      f"not written: {exc}"),))
    exploration, res = _trough_and_damage(analysis, res, exploration, say)
    exploration = _triggers(analysis, res, exploration, say)
    write_run(res, Path(out), exploration, plots=plots, readings=lines)
    return res



def _triggers(analysis, res, exploration, say):
    """The trigger levels (TARP: triggers.csv, the report's section) where the case gives any: the latest
    survey against them, and the probability of exceeding each at the next stage and the end."""
    case = analysis.loaded.case
    if not any(i.triggers for i in case.instruments) and not any(f.triggers for f in case.forecasts):
        return exploration
    from geoback.case.loading import stage_names
    from geoback.inference.explore import Exploration
    from geoback.worth.forecast import unusable_estimate
    from geoback.worth.updating import forecast_surveys, later_blocks, trigger_table  # (0.6 s of imports)

    if unusable_estimate(res):
        return exploration
    stages = stage_names(case)
    stage = stages[max(stages.index(b.stage) for b in analysis.simulation.survey.blocks)]
    if say is not None:
        say(f"trigger levels: the readings through stage '{stage}' and the forecasts of the later stages")
    triggered = {i.name for i in case.instruments if i.triggers is not None}
    ahead = forecast_surveys(analysis, res, [b for b in later_blocks(analysis, stage) if b.name in triggered], stage)
    rows = tuple(trigger_table(analysis, stage, ahead, res.forecasts))
    return replace(exploration or Exploration(), triggers=rows)


def _trough_and_damage(analysis, res, exploration, say):
    """The settlement troughs (trough.csv, the report's section, trough.png) and the buildings' damage
    (damage.csv, its section, damage.png) at the estimate, where the case has them."""
    from geoback.inference.explore import Exploration
    from geoback.worth import damage, trough

    case = analysis.loaded.case
    found = {}
    if trough.wanted(case, res.data.labels):
        if say is not None:
            say("settlement trough: Gaussian fits to the measured and the model's surface settlement per stage")
        found["trough"] = trough.of_result(analysis, res)
    if case.buildings:
        if say is not None:
            say(f"building damage (greenfield): {', '.join(b.name for b in case.buildings)}")
        found["damage"] = damage.of_result(analysis, res)
    if found:
        exploration = replace(exploration or Exploration(), **found)
    return exploration, res
