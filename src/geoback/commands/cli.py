"""Command line: a thin layer that parses, calls the library and prints."""
from __future__ import annotations

import json
import os
import sys
from enum import Enum
from functools import wraps
from pathlib import Path
from typing import Optional

# Dense linear algebra here is small (readings x parameters): BLAS threads cost more than they
# give. Set before numpy loads; MKL's threads (PARDISO) are not affected.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import typer  # noqa: E402

from geoback.errors import GeobackError  # noqa: E402

app = typer.Typer(add_completion=False, pretty_exceptions_enable=False, no_args_is_help=True, rich_markup_mode=None,
                  help="Maximum-likelihood back-analysis of tunnel and excavation instrumentation.")


def _version(value: bool) -> None:
    if value:
        from geoback import __version__

        typer.echo(f"geoback {__version__}")
        raise typer.Exit(0)


@app.callback()
def _main(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="print the version and exit")):
    """Maximum-likelihood back-analysis of tunnel and excavation instrumentation."""


class ObjectiveMap(str, Enum):
    """How `run --plots` draws the objective map (``inference.explore``)."""

    auto = "auto"
    model = "model"
    linearised = "linearised"


class Method(str, Enum):
    """The estimation method (paper eqns 27-30); case-insensitive on the command line."""

    lm = "lm"
    lm_scaled = "lm-scaled"
    gn = "gn"


class Format(str, Enum):
    table = "table"
    csv = "csv"
    json = "json"


def _json_option():
    return typer.Option(False, "--json", help="print the result as JSON on stdout (the file this command writes; "
                                              "progress and the final line go to stderr)")


def _print_json(path: Path) -> None:
    typer.echo(json.dumps(json.loads(Path(path).read_text())))


def _err(message: str) -> None:
    typer.echo(f"error: {message}", err=True)


def friendly(func):
    """Answer user mistakes with one clear line and exit code 2, never a traceback."""

    @wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except GeobackError as exc:
            _err(str(exc))
            raise typer.Exit(exc.exit_code) from None
        except (ValueError, OSError) as exc:
            if os.environ.get("GEOBACK_DEBUG"):
                raise
            _err(str(exc))
            raise typer.Exit(2) from None
        except KeyboardInterrupt:
            from geoback.reports.resultsets import interrupted_note

            _err(f"interrupted; {interrupted_note()}")
            raise typer.Exit(130) from None

    return wrapper


def _say(message: str) -> None:
    """Progress on stderr, printed verbatim (names such as E[clay] are never read as markup)."""
    typer.echo(f"  {message}", err=True)


ALLOW_LARGE_HELP = ("accept a mesh estimated beyond the default limit of 500,000 DOFs (about 1.8 GB and a "
                    "minute for `run`; GEOBACK_MAX_DOFS changes the limit)")


def _allow_large():
    return typer.Option(False, "--allow-large", help=ALLOW_LARGE_HELP)


TIME_LIMIT_HELP = ("wall-clock limit: past it the work stops with what it found (the fit's best point, the "
                   "diagnosis so far), written with exit code 1; work that cannot stop early (a forward run) is "
                   "cut after a grace of a quarter of the limit (at least 30 s) with where it was. Seconds or "
                   "'90 min', '2 h'; 'none' for no limit (default 1 h, or GEOBACK_TIME_LIMIT)")


def _time_limit_option():
    return typer.Option(None, "--time-limit", help=TIME_LIMIT_HELP)


def _limited(time_limit: Optional[str], say=None):
    """The command's budget (geoback.case.budget): its time limit and where progress lines go."""
    from geoback.case import budget

    seconds = budget.default_seconds() if time_limit is None else budget.parse_seconds(time_limit)
    return budget.limited(seconds, say=say)


def _cut_short(what: str) -> bool:
    """Say so when the time limit stopped the work early (True then)."""
    from geoback.case import budget

    where = budget.reached()
    if where:
        typer.echo(f"warning: {what} stopped at {budget.describe_limit()} (reached in {where}): what it had found is "
                   f"written; raise the limit with --time-limit to let it finish", err=True)
    return bool(where)


def _load(case: Path, allow_large: bool = False):
    from geoback.case.loading import load_case

    return load_case(case, allow_large=allow_large)


OUT_HELP = ("output folder (default results/<name>); this command's previous results there are replaced "
            "as a whole, other files kept")


def _check_out(out: Optional[str], option: str = "--out", **kwargs) -> Optional[Path]:
    """--out refused before any work when it cannot take results (a file, '', not writable, ...)."""
    from geoback.reports.resultsets import check_out

    return check_out(out, option, **kwargs)


def _out_dir(loaded, out: Optional[Path]) -> Path:
    """The results folder: --out (checked already), else the case's output.dir, else
    results/<name> (checked here, before any meshing)."""
    if out is not None:
        return out
    if loaded.case.output.dir:
        return _check_out(str(loaded.folder / loaded.case.output.dir), "output.dir of the case")
    return _check_out(str(Path("results") / loaded.case.name), "the results folder")


@app.command()
@friendly
def validate(case: Path = typer.Argument(..., help="case file (YAML)"), allow_large: bool = _allow_large()):
    """Check a case file: schema, physics, mesh size, instruments, readings and parameters; list every problem."""
    from geoback.errors import CaseError

    try:
        loaded = _load(case, allow_large)  # schema errors first: no heavy imports before them
        from geoback.commands.validation import check_case

        verdict = check_case(loaded)
    except CaseError as exc:
        if len(exc.problems) > 1:
            for problem in exc.problems:
                _err(str(problem))
            raise typer.Exit(exc.exit_code) from None
        raise
    typer.echo(verdict)


@app.command()
@friendly
def schema():
    """Print the JSON Schema of case files (for editors)."""
    from geoback.case.loading import case_schema

    typer.echo(json.dumps(case_schema(), indent=2))


@app.command()
@friendly
def mesh(case: Path = typer.Argument(..., help="case file (YAML)"),
         out: Optional[str] = typer.Option(None, help=OUT_HELP),
         plots: bool = typer.Option(True, help="also draw the mesh with its layers and instruments (mesh.png)"),
         allow_large: bool = _allow_large()):
    """Mesh the case with gmsh; write mesh.msh, mesh.vtu and a picture of it, mesh.png."""
    out = _check_out(out)
    from geoback.physics.mesh import build_mesh
    from geoback.reports.fields import write_mesh
    from geoback.reports.resultsets import result_set

    loaded = _load(case, allow_large)
    folder = _out_dir(loaded, out)
    if hasattr(loaded.case.geometry, "openings"):  # a section with openings: meshed inside them too
        from geoback.physics.section_mesh import build_section_mesh

        m = build_section_mesh(loaded.case)
    else:
        m = build_mesh(loaded.case, allow_large=allow_large)
    with result_set(folder, "mesh") as staging:
        write_mesh(m, staging / "mesh.msh")
        write_mesh(m, staging / "mesh.vtu")
        if plots:
            from geoback.reports.plots import save_mesh_picture

            save_mesh_picture(loaded, m, staging)
    typer.echo(f"{len(m.triangles)} elements, {len(m.nodes)} nodes ({2 * len(m.nodes)} dofs) -> {folder}/mesh.msh, "
               f"mesh.vtu" + (", mesh.png" if plots else ""))


@app.command()
@friendly
def simulate(case: Path = typer.Argument(..., help="case file (YAML)"),
             out: Optional[str] = typer.Option(None, help=OUT_HELP),
             vtu: bool = typer.Option(True, help="write the displacement/stress field as field.vtu"),
             set_: list[str] = typer.Option([], "--set", help="NAME=VALUE with the case's names and units (repeatable): "
                                            "E[clay]=12 MPa, Egrad[clay]=400, n[clay]=1.5, K0grad=0.05, beta=0.7, "
                                            "B[I1]=4 mm, zsplit[clay]=15 with Esplit[clay]=25 MPa; an inclinometer's bias "
                                            "shift bias[I1]=0.2 mrad or depth offset zoff[I1]=300 mm"),
             refine: Optional[float] = typer.Option(None, help="mesh this many times finer than the case says "
                                                    "(default 2 for study data, 1 for a forward run)"),
             noise: bool = typer.Option(False, "--noise", help="add noise drawn from each instrument's C_x"),
             seed: int = typer.Option(0, help="seed of the noise"),
             readings_out: Optional[str] = typer.Option(None, help="write study data: readings as a CSV usable as "
                                                        "readings_file (a finer mesh than the case's by default)"),
             plots: Optional[bool] = typer.Option(None, "--plots/--no-plots", help="--plots: also draw the predicted "
                                                  "readings along every instrument (predicted.png and .svg); "
                                                  "--no-plots: draw no figure at all (not the lining, walls or "
                                                  "plastic-zone figures either: their CSV files are written; for "
                                                  "a loop of forward runs)"),
             as_json: bool = _json_option(),
             allow_large: bool = _allow_large(),
             time_limit: Optional[str] = _time_limit_option()):
    """Forward run: predicted readings and the field; or study data (--readings-out, --noise)."""
    with _limited(time_limit, _say):
        _simulate(case, out, vtu, set_, refine, noise, seed, readings_out, as_json, allow_large, plots)


def _simulate(case, out, vtu, set_, refine, noise, seed, readings_out, as_json, allow_large, plots=None):
    if seed < 0:
        raise GeobackError(f"--seed: expected a whole number 0 or above, found {seed}")
    out = _check_out(out)
    readings_out = _check_out(readings_out, "--readings-out", single_file=True)
    from geoback.inference.identification import prepare
    from geoback.commands.simulate import simulate as run_simulation, write_readings_csv
    from geoback.inference.synthetic import synthetic_readings

    loaded = _load(case, allow_large)
    assignments = {}
    for item in set_:
        name, eq, value = item.partition("=")
        if not eq or not name.strip() or not value.strip():
            raise GeobackError(f"--set expects NAME=VALUE (e.g. --set \"E[clay]=12 MPa\"), found '{item}'")
        assignments[name.strip()] = value.strip()
    if readings_out is not None or noise:
        factor = 2.0 if refine is None else refine
        if factor < 1:
            raise GeobackError(f"--refine must be at least 1 (a mesh finer than the case's), found {factor:g}")
        if readings_out is None:
            _out_dir(loaded, out)
        staged = loaded.case.construction is not None
        readings = synthetic_readings(loaded, factor, assignments, noise_seed=seed if noise else None,
                                      by_stage=staged)
        target = readings_out or _out_dir(loaded, out) / "readings.csv"
        used = ", ".join(f"{k} = {v}" for k, v in assignments.items()) or "the case's values"
        mesh = "the case's mesh (inverse crime: fitting these readings on it proves little)" if factor == 1 else \
            f"a mesh {factor:g} times finer than the case's"
        notes = [f"geoback simulate {case.name}: {used}; {mesh}" + (f"; noise from each C_x, seed {seed}" if noise
                                                                    else "; no noise")]
        write_readings_csv(loaded, readings, target, notes)
        count = sum(len(v) for sets in readings.values() for v in (sets.values() if staged else [sets]))
        if as_json:
            typer.echo(json.dumps({"file": str(target), "readings": {
                name: ({s: list(map(float, v)) for s, v in sets.items()} if staged else list(map(float, sets)))
                for name, sets in readings.items()}}))
        typer.echo(f"{count} readings ({used}; {mesh}"
                   f"{', noise seed ' + str(seed) if noise else ''}) -> {target}", err=as_json)
        return
    if refine not in (None, 1.0):
        raise GeobackError("--refine applies to study data (--readings-out or --noise)")
    folder = _out_dir(loaded, out)
    analysis = prepare(loaded, parameters=[], with_readings=False)
    from geoback.inference.parameters import resolve_values

    values = {**analysis.values, **resolve_values(analysis.simulation, assignments)}
    res = run_simulation(analysis, folder, values=values, vtu=vtu and loaded.case.output.vtu, plots=plots,
                         values_text=", ".join(f"{k} = {v}" for k, v in assignments.items()))
    used = ", ".join(f"{k} = {v}" for k, v in assignments.items())
    if as_json:
        _print_json(folder / "predicted.json")
    typer.echo(f"{analysis.simulation.survey.m} readings predicted on {res['dofs']} dofs"
               f"{' with ' + used if used else ''} -> {folder}/predicted.csv"
               + (", lining.csv, lining.png" if res.get("lining") is not None else "")
               + (", walls.csv, supports.csv, walls.png" if res.get("walls") is not None else "")
               + (", predicted.png" if plots else ""), err=as_json)


@app.command()
@friendly
def diagnose(case: Path = typer.Argument(..., help="case file (YAML)"),
             out: Optional[str] = typer.Option(None, help=OUT_HELP),
             alpha: float = typer.Option(0.05, help="significance level of the adequacy and hypothesis tests, "
                                         "between 0 and 1"),
             plots: bool = typer.Option(True, help="write the before/after figure"),
             exclude: Optional[list[str]] = typer.Option(None, "--exclude", help="a kind of the library not to "
                                                         "propose (what the case knows is not so), e.g. "
                                                         "layer-boundary; repeat for several"),
             quiet: bool = typer.Option(False, "--quiet", "-q"),
             as_json: bool = _json_option(),
             allow_large: bool = _allow_large(),
             time_limit: Optional[str] = _time_limit_option()):
    """Is the model adequate? If not: where is the mismatch, what physics is missing, how much better it fits."""
    from geoback.diagnosis import diagnose as run_diagnosis
    from geoback.reports.diagnosis_report import diagnosis_text, write_diagnosis
    from geoback.reports.diagnosis_report import verdict
    from geoback.inference.explore import explore

    if not 0.0 < alpha < 1.0:  # (nan fails too) checked again by the library; here before any work
        raise GeobackError(f"--alpha: expected a significance level between 0 and 1 (e.g. 0.05), found {alpha:g}")
    from geoback.diagnosis.hypotheses import KINDS

    unknown = [k for k in exclude or [] if k not in KINDS]
    if unknown:
        raise GeobackError(f"--exclude: expected a kind of the library ({', '.join(KINDS)}), found '{unknown[0]}'")
    say = None if quiet else _say
    limit = _limited(time_limit, say)
    out = _check_out(out)
    loaded = _load(case, allow_large)
    folder = _out_dir(loaded, out)
    with limit:
        d = run_diagnosis(loaded, alpha=alpha, progress=say, exclude=exclude or ())
        exploration = explore(d.final_misfit, d.final, ("profiles",)) if plots else None
        write_diagnosis(d, folder, plots=plots, exploration=exploration)
        if as_json:
            _print_json(folder / "diagnosis.json")
        elif not quiet:
            typer.echo(diagnosis_text(d))
        else:
            typer.echo(verdict(d))
        amended = ", amended.yaml (the case with the accepted extensions: `geoback run` it to go on)" \
            if d.accepted else ""
        zone = ", plastic_zone.csv (where the ground yields)" if (folder / "plastic_zone.csv").exists() else ""
        typer.echo(f"-> {folder}/diagnosis.md, diagnosis.html, diagnosis.json{zone}{amended}", err=True)
        if _cut_short("the diagnosis"):
            raise typer.Exit(1)


EXIT_CODES = """Exit codes: 0 converged (warnings, if any, are printed); 1 the fit did not converge or did not
move from the initial values, or was stopped at the time limit (--time-limit); 2 the input was refused
(the message names file, line and field); 3 with --strict: converged, but with warnings; 4 with --strict: a red
trigger level is more likely than --red-probability (or already read); 130 interrupted."""


@app.command(epilog=EXIT_CODES)
@friendly
def run(case: Path = typer.Argument(..., help="case file (YAML)"),
        out: Optional[str] = typer.Option(None, help=OUT_HELP),
        method: Optional[Method] = typer.Option(None, case_sensitive=False,
                                                help="estimation method (default: the case's fit.method)"),
        plots: bool = typer.Option(False, "--plots", help="also write figures (PNG and SVG)"),
        objective_map: ObjectiveMap = typer.Option(
            ObjectiveMap.auto, "--objective-map", case_sensitive=False,
            help="how --plots draws the objective map: 'auto' computes it with the model where one factorisation "
                 "serves the grid, else from the model linearised at the estimate (and runs the other method "
                 "for comparison only where it is as cheap); 'model' computes both with the model however long "
                 "it takes; 'linearised' always linearises"),
        profile: bool = typer.Option(False, "--profile", help="profile-likelihood intervals for every parameter "
                                     "(by default only where the linearised interval is unreliable)"),
        strict: bool = typer.Option(False, "--strict", help="exit 3 if the result carries any warning, 4 if a red "
                                                            "trigger level is likely (for CI)"),
        red_probability: float = typer.Option(0.05, "--red-probability", min=0.0, max=1.0,
                                              help="with --strict: the largest acceptable probability of red"),
        quiet: bool = typer.Option(False, "--quiet", "-q", help="print only the final line"),
        as_json: bool = _json_option(),
        allow_large: bool = _allow_large(),
        time_limit: Optional[str] = _time_limit_option()):
    """Identify the case's parameters by maximum likelihood and write all results."""
    method = method.value if method is not None else None
    talk = not quiet and not as_json
    limit = _limited(time_limit, _say if talk else None)  # (a bad --time-limit is refused before any work)
    out = _check_out(out)
    loaded = _load(case, allow_large)  # schema errors first: no heavy imports before them
    folder = _out_dir(loaded, out)
    from geoback.reports.report import report_text, summary
    from geoback.commands.run import run_case

    names: list[str] = []
    units: list[str] = []
    from geoback.units import number, shown

    def progress(it):
        if talk:
            vals = "  ".join(f"{n} = {number(v * shown(u, v)[0])}" + ("" if shown(u, v)[1] in ("-", "")
                                                                       else f" {shown(u, v)[1]}")
                             for n, u, v in zip(names, units, it.p))
            mark = ("accepted" if it.accepted else "rejected" if it.J < float("inf")
                    else "rejected (the model has no solution there)")
            _say(f"iteration {it.k:2d}  mu = {it.mu:8.2g}  J = {it.J:<12.6g} {mark}  {vals}")

    def named(analysis):
        names[:] = analysis.parameters.names
        units[:] = analysis.parameters.units

    matched: list[str] = []
    with limit:
        res = run_case(loaded, folder, method=method, progress=progress, plots=plots, say=_say if talk else None,
                       prepared=named, profile="all" if profile else "auto", matched=matched.extend,
                       objective_map=objective_map.value)
        _cut_short("the identification")
    if as_json:
        _print_json(folder / "summary.json")
    elif not quiet:
        typer.echo(report_text(res, readings=matched))
    s = summary(res)
    def _estimate(n, v):
        fct, unit = shown(v["unit"], v["estimate"])
        unit = "" if unit in ("-", "") else f" {unit}"
        return f"{n} = {number(v['estimate'] * fct)}{unit} +/- {number(v['std'] * fct, 3)}{unit}"

    estimates = ", ".join(_estimate(n, v) for n, v in s["parameters"].items())
    warned = f"; {len(res.caveats)} warning(s): {', '.join(sorted({c.code for c in res.caveats}))}" \
        if res.caveats else ""
    typer.echo(f"{res.status}: {estimates} ({s['iterations']} iterations, {s['factorisations']} "
               f"factorisation(s){warned}) -> {folder}", err=as_json)
    if res.fit.status != "converged" or not res.fit.moved:
        raise typer.Exit(1)
    if strict:
        _red_exit(json.loads((folder / "summary.json").read_text()).get("triggers", []), red_probability)
    if strict and res.caveats:
        raise typer.Exit(3)


UPDATE_EXIT = """Exit codes: 0 done; 1 a step's fit did not converge; 2 the input was refused (file, line, field);
4 with --strict: a red trigger level is more likely than --red-probability at the next stage or the end (or a
survey already reads above red); 130 interrupted."""


@app.command(epilog=UPDATE_EXIT)
@friendly
def update(case: Path = typer.Argument(..., help="case file (YAML) with dated surveys or readings at several stages"),
           until: Optional[str] = typer.Option(None, help="the surveys up to this stage (its name) or date "
                                                          "(2026-03-20) only, as the engineer had them then "
                                                          "(default: every survey)"),
           out: Optional[str] = typer.Option(None, help="output folder (default results/<name>-update); this "
                                                        "command's previous results there are replaced as a whole"),
           plots: bool = typer.Option(False, "--plots", help="also write the figures (history, forecast checks)"),
           strict: bool = typer.Option(False, "--strict", help="exit 4 when a red level is more likely than "
                                                               "--red-probability"),
           red_probability: float = typer.Option(0.05, "--red-probability", min=0.0, max=1.0,
                                                 help="with --strict: the largest acceptable probability of red"),
           quiet: bool = typer.Option(False, "--quiet", "-q", help="print only the final lines"),
           allow_large: bool = _allow_large()):
    """Fit the surveys stage by stage as construction proceeds: forecast the later stages, score each
    stage's surveys against the previous forecast, and report the trigger levels (TARP)."""
    out = _check_out(out)
    loaded = _load(case, allow_large)
    cut = _until(loaded, until)
    folder = out if out is not None else _check_out(str(Path("results") / f"{loaded.case.name}-update"),
                                                    "the results folder")
    from geoback.commands.update import update_case

    steps = update_case(loaded, folder, cut, say=None if quiet else _say, plots=plots)
    last = steps[-1]
    for t in last.triggers:
        if not quiet:
            typer.echo(f"trigger {t.quantity} ({t.when}, {t.stage}): {t.status}"
                       + ("" if t.measured else f", P(> red) = {100 * t.p_red:.1f} %"))
    estimates = ", ".join(f"{n} = {v:.6g}" for n, v in zip(last.result.parameters.names, last.result.fit.p))
    typer.echo(f"{last.result.status} through stage '{last.stage}' ({len(steps)} step(s)): {estimates} -> {folder}")
    if any(s.result.fit.status != "converged" for s in steps):
        raise typer.Exit(1)
    if strict:
        _red_exit(json.loads((folder / "summary.json").read_text())["triggers"], red_probability)


def _p_red(t: dict) -> float:
    """A trigger row's probability of red: sampled through the model where the model is non-linear there."""
    return t["p_red_sampled"] if t.get("nonlinear") and t.get("p_red_sampled") is not None else t["p_red"]


def _red_exit(triggers, red_probability: float) -> None:
    """--strict: exit 4 when a red level is read already or more likely than `red_probability`."""
    over = [t["quantity"] for t in triggers if t["red"] is not None and
            ((t["std"] == 0 and t["when"].startswith("now") and abs(t["value"]) > t["red"])
             or (not t["when"].startswith("now") and _p_red(t) > red_probability))]
    if over:
        typer.echo(f"strict: red more likely than {100 * red_probability:g} % (or read already) for "
                   f"{', '.join(sorted(set(over)))}", err=True)
        raise typer.Exit(4)


def _until(loaded, until: Optional[str]):
    """--until as a stage name or a date; refused (exit 2) when it is neither."""
    if until is None:
        return None
    from geoback.case.dates import parse_date
    from geoback.case.loading import stage_names
    from geoback.errors import GeobackError

    stages = stage_names(loaded.case)
    if until in stages:
        return until
    try:
        return parse_date(until)
    except ValueError as exc:
        raise GeobackError(f"--until: expected a construction stage ({', '.join(stages)}) or a date: {exc}") from None


@app.command()
@friendly
def design(case: Path = typer.Argument(..., help="case file (YAML) with a design section"),
           out: Optional[str] = typer.Option(None, help=OUT_HELP),
           plots: bool = typer.Option(True, help="write the figure (design.png, design.svg)"),
           separate: bool = typer.Option(False, "--separate", help="also rank the candidates by their power to "
                                         "tell apart the two hypotheses `geoback diagnose` finds leading "
                                         "(runs the diagnosis first)"),
           as_json: bool = _json_option(),
           allow_large: bool = _allow_large(),
           time_limit: Optional[str] = _time_limit_option()):
    """Rank candidate instruments by how much they would narrow the forecasts (or the parameters)."""
    with _limited(time_limit, _say):
        _design(case, out, plots, separate, as_json, allow_large)


def _design(case, out, plots, separate, as_json, allow_large):
    out = _check_out(out)
    loaded = _load(case, allow_large)
    from geoback.worth.design import require_design, require_estimate

    require_design(loaded)
    folder = _out_dir(loaded, out)
    from geoback.worth.design import design as rank
    from geoback.reports.design_report import design_text, write_design
    from geoback.inference.identification import identify, prepare

    analysis = prepare(loaded)
    if analysis.misfit is None:
        from geoback.observation.readings import require_readings

        require_readings(loaded)  # names the instruments without readings
    _say("identifying the parameters at which the candidates are compared")
    res = identify(analysis)
    require_estimate(res)
    d = rank(analysis, res, progress=_say)
    if separate:
        from geoback.worth.design import separate as discriminate

        _say("diagnosing: which hypotheses explain the readings best")
        d = discriminate(analysis, d, progress=_say)
    write_design(d, folder, loaded.case.name, plots=plots)
    if as_json:
        _print_json(folder / "design.json")
    else:
        typer.echo(design_text(d, loaded.case.name))
    typer.echo(f"best: {d.best} ({100 * d.reduction[d.ranking[0]]:.0f} % narrower) -> {folder}/design.md", err=as_json)
    D = d.discrimination
    if D is not None and not D.found:
        typer.echo("diagnose refitted no hypothesis: nothing to tell apart", err=as_json)
    elif D is not None and D.separation.max() > 1e-9:
        k = int(D.separation.argmax())
        typer.echo(f"best to tell {D.a} from {D.b}: {D.names[k]} (power {D.power[k]:.2f})", err=as_json)


@app.command()
@friendly
def covariance(case: Optional[Path] = typer.Argument(None, help="case file: print an instrument's C_x"),
               name: Optional[str] = typer.Option(None, "--name", help="instrument name in the case"),
               instrument: Optional[str] = typer.Option(None, help="inclinometer, sliding-micrometer (extensometer), "
                                                        "deflectometer, points or convergence"),
               stations: Optional[int] = typer.Option(None, help="number of stations"),
               spacing: Optional[float] = typer.Option(None, help="equal station spacing [m]"),
               lengths: Optional[str] = typer.Option(None, help="station lengths l1,l2,... from the reference end [m]"),
               sigma: Optional[float] = typer.Option(None, help="std of one primary reading [m] (points, convergence: "
                                                   "of one reading)"),
               var_a: float = typer.Option(0.0, help="variance of A (sliding micrometer)"),
               var_b: float = typer.Option(0.0, help="variance of B (inclinometer)"),
               var_c: float = typer.Option(0.0, help="variance of C (deflectometer)"),
               var_d: float = typer.Option(0.0, help="variance of D (deflectometer)"),
               fmt: Format = typer.Option(Format.table, "--format", case_sensitive=False, help="output format"),
               header: bool = typer.Option(False, help="with --format csv: one header row of labels")):
    """Print a measurement covariance matrix C_x (eqns 10-20), in station order from the reference end."""
    import numpy as np

    from geoback.case import covariance as cov

    fmt = fmt.value
    if case is not None:
        if not name:
            raise GeobackError("give --name INSTRUMENT to choose an instrument of the case")
        from geoback.observation.instruments import build_block

        loaded = _load(case)
        idx = next((i for i, ins in enumerate(loaded.case.instruments) if ins.name == name), None)
        if idx is None:
            raise GeobackError(f"{case}: no instrument named '{name}' "
                               f"(instruments: {', '.join(i.name for i in loaded.case.instruments)})")
        block = build_block(loaded.case.instruments[idx], loaded, idx)
        labels = [f"{lab.component}{lab.station}" for lab in block.labels]
        _print_covariance(block.covariance, fmt, header, labels,
                          f"C_x of {block.kind} {name} [m²], readings in station order from the reference end")
        return
    if instrument is None or sigma is None:
        raise GeobackError("give a case file with --name, or --instrument KIND with --sigma and the stations")
    n_guess = stations if stations is not None else (len(lengths.split(",")) if lengths else 0)
    if n_guess and n_guess * n_guess * 8 > MAX_MATRIX_BYTES:
        raise GeobackError(f"--stations {n_guess}: expected at most {int((MAX_MATRIX_BYTES / 8) ** 0.5):,} stations "
                           f"(a dense {n_guess:,} x {n_guess:,} matrix takes {n_guess * n_guess * 8 / 1e9:.3g} GB)")
    if instrument.strip().lower() in ("points", "convergence"):
        if not sigma > 0:
            raise GeobackError(f"--sigma must be positive, found {sigma:g}")
        n = stations if stations is not None else 1
        _print_covariance(sigma ** 2 * np.eye(n), fmt, header, None,
                          f"C_x of {n} independent {instrument.strip().lower()} reading(s) [units of --sigma, squared]")
        return
    kind = cov.normalise_kind(instrument)
    ls = None
    if lengths is not None:
        try:
            ls = [float(v) for v in lengths.split(",") if v.strip()]
        except ValueError:
            raise GeobackError(f"--lengths must be numbers separated by commas, found '{lengths}'") from None
        if stations is not None and stations != len(ls):
            raise GeobackError(f"--stations {stations} but --lengths gives {len(ls)} lengths")
        stations = None
    ls = cov.station_lengths(stations=stations, spacing=spacing, lengths=ls)
    variances = {"sliding_micrometer": {"A": var_a}, "inclinometer": {"B": var_b},
                 "deflectometer": {"C": var_c, "D": var_d}}[kind]
    C = cov.instrument_covariance(kind, ls, sigma, variances)
    _print_covariance(C, fmt, header, None, f"C_x of {'an' if kind[0] in 'aeiou' else 'a'} {kind.replace('_', ' ')} with {len(ls)} stations "
                                            f"[units of --sigma, squared: m² with sigma in m], from the reference end")


MAX_MATRIX_BYTES = 1e9  # a dense covariance printed by `geoback covariance`


def _print_covariance(C, fmt: str, header: bool, labels, caption: str) -> None:
    """The matrix in `fmt`, with its caption: the table's first line, json's "caption", stderr for csv
    (whose stdout stays plain numbers)."""
    import numpy as np

    from geoback.case import covariance as cov

    text = cov.render_matrix(np.asarray(C), fmt, header=header or fmt != "csv", labels=labels)
    if fmt == "json":
        text = json.dumps({"caption": caption, **json.loads(text)})
    elif fmt == "table":
        text = caption + "\n" + text
    else:
        typer.echo(caption, err=True)
    typer.echo(text.rstrip("\n"))


@app.command()
@friendly
def batch(targets: list[str] = typer.Argument(..., help="folders (every *.yaml in them, recursively), "
                                              "glob patterns ('cases/*.yaml') or case files"),
          workers: Optional[int] = typer.Option(None, help="local worker processes (default min(2, CPUs); unused with --scheduler)"),
          scheduler: Optional[str] = typer.Option(None, help="Dask scheduler address (tcp://host:8786) "
                                                  "instead of local processes"),
          out: str = typer.Option("results/batch", help="output folder: summary.csv and <case name>/"),
          as_json: bool = _json_option(),
          allow_large: bool = _allow_large()):
    """Identify many cases in parallel; write summary.csv and each case's results. Exit 1 if any failed."""
    out = _check_out(out, replaced=False)
    from geoback.commands.batch import failed, run_batch

    def progress(row):
        extra = f": {row['message']}" if row["message"] else ""
        typer.echo(f"  {row['case']} ({row['file']}): {row['status']}{extra}", err=True)

    try:
        rows = run_batch(targets, out, workers=workers, scheduler=scheduler, progress=progress,
                         allow_large=allow_large)
    except KeyboardInterrupt:
        _err(f"interrupted; each case's folder in {out} holds its previous or its new complete results; "
             f"{out / 'summary.csv'} was not updated")
        raise typer.Exit(130) from None
    bad = failed(rows)
    if as_json:
        typer.echo(json.dumps([{k: v for k, v in row.items() if k != "out"} for row in rows]))
    typer.echo(f"{len(rows) - len(bad)} of {len(rows)} case(s) converged -> {out / 'summary.csv'}", err=as_json)
    if bad:
        typer.echo("failed: " + ", ".join(f"{row['file']} ({row['status']})" for row in bad), err=True)
        raise typer.Exit(1)


@app.command()
@friendly
def init(path: Path = typer.Argument(Path("case.yaml"), help="file to write (default case.yaml)"),
         force: bool = typer.Option(False, "--force", help="overwrite an existing file")):
    """Write a commented template case (units and meaning of every field) that runs as it is."""
    from geoback.commands.template import write_template

    written = write_template(path, force=force)
    typer.echo(f"wrote {written}: check it with `geoback validate {written}`, fit it with `geoback run {written}`")


def main() -> None:  # pragma: no cover
    app()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
