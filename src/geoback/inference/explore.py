"""The exploration step: what figures and field files need beyond the fit, computed on request.

``explore(misfit, result)`` runs the model where the identification did not: the objective on
a slice through the estimate (paper Fig. 2), the other method's iteration path (Figs. 3-4), the
field at the estimate and the model along each instrument. Its work is counted on its own, so a
run's summary reports the identification only; figures and writers read the result and the
exploration and never run the model.

The objective map is drawn by the model itself where that is cheap: when one factorisation
serves every grid point (E and K0 of one layer, a release factor, ...) a 40 x 40 grid costs
back-substitutions only. Where every point would need its own factorisation or a non-linear run
(several moduli, nu, yielding ground) the map comes from the linearised model at the estimate
instead, J(p) ~ ||r* - B (p - p*)||^2 = J* + dp^t A'^t A' dp at the minimum (the Gauss-Newton
approximation: no model run), and the other method's path is not run, unless asked for
(``objective_map="model"``: the model on a grid sized to a time budget, the other method run).
A probe (one forward run off the estimate) tells which case applies; the figure and the report say
which map they show.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field as _field

import numpy as np

from geoback.inference.estimate import Fit, Settings, fit
from geoback.inference.identification import Identification
from geoback.inference.misfit import Misfit
from geoback.physics.simulation import Field

GRID = 40  # grid points per axis when one factorisation serves the whole grid
GRID_MIN = 9
LINE_POINTS = 160  # model values along a linewise instrument
TROUGH_POINTS = 80  # model values along a row (or column) of points
WHAT = ("slice", "other", "field", "profiles", "lining", "plastic_zone")
OBJECTIVE_MAPS = ("auto", "model", "linearised")  # how the objective map is drawn (see the module docstring)


@dataclass(frozen=True)
class ObjectiveSlice:
    """J on a grid of two parameters (indices i, j) through the estimate, the others held there;
    with one parameter, j is None and J is a curve over `a`."""

    i: int
    j: int | None
    a: np.ndarray
    b: np.ndarray | None
    J: np.ndarray
    refactorises: bool  # every grid point would need its own factorisation (or a non-linear run)
    directions: np.ndarray | None = None  # (n, 2) SVD directions of the slice at the estimate
    singular_values: np.ndarray | None = None
    whole_svd: bool = True  # directions are those of the whole problem (n = 2)
    source: str = "model"  # "model": J computed at every grid point; "linearised": the Gauss-Newton
    # quadratic form at the estimate (no model run)
    requested: bool = False  # the source was asked for (objective_map), not chosen by cost

    @property
    def linearised(self) -> bool:
        return self.source == "linearised"

    def words(self) -> str:
        """Which map this is, in plain words (for the figure and the report)."""
        size = f"{len(self.a)}×{len(self.b)} grid" if self.b is not None else f"{len(self.a)} points"
        if not self.linearised:
            return f"the objective computed by the model on a {size}"
        why = ("as asked" if self.requested else
               "computing it at every point would need a new solution of the model each; "
               "`--objective-map model` computes it")
        return f"the objective of the model linearised at the estimate, J* + Δpᵀ A′ᵀA′ Δp ({why})"


@dataclass(frozen=True)
class Profile:
    """A linewise instrument: points along it from its reference end and the model's displacement
    in the measured direction there; and every instrument's displacement at its stations and
    along its line (for the deformed-field figure)."""

    along: np.ndarray | None  # arc length [m] of the dense points (linewise only)
    line: np.ndarray | None  # (k, 2) dense points (linewise; or a row or column of settlement points)
    line_displacement: np.ndarray | None  # (k, 2)
    line_reading: np.ndarray | None  # (k,) what the instrument would read there (relative to its
    # reference end for a relative instrument), without integration constants (linewise only)
    station_displacement: np.ndarray  # (npts, 2) at the stations
    stage_readings: dict = _field(default_factory=dict)  # stage -> line_reading after that stage, for an
    # instrument read at several construction stages (the attributes above are at the last of them)
    stage_line_displacement: dict = _field(default_factory=dict)  # stage -> (k, 2) along `line` (points)


@dataclass(frozen=True)
class Exploration:
    other: Fit | None = None
    other_note: str = ""  # why the other method's path is missing, in words ("not run ...", "failed: ...")
    slice: ObjectiveSlice | None = None
    field: Field | None = None
    profiles: dict = _field(default_factory=dict)
    lining: object | None = None  # lining.LiningForces at the estimate (models with a lining)
    plastic_zone: object | None = None  # plastic_zone.PlasticZone at the estimate (ground that can yield)
    counts: dict = _field(default_factory=dict)
    seconds: float = 0.0
    refactorises: bool | None = None  # the probe: a point off the estimate needs its own factorisation
    # (or a non-linear run); None when not probed
    walls: object | None = None  # worth.walls.WallsAndSupports at the estimate with their bands (cases with
    # walls; set by `geoback run`, which may call worth: this room may not)
    trough: object | None = None  # worth.trough.Troughs: measured and model settlement troughs per stage
    # (tunnels with surface settlement readings or a `trough:` section; set by `geoback run`)
    damage: object | None = None  # worth.damage.Damage: the buildings' greenfield damage (set by `geoback run`)
    triggers: tuple | None = None  # worth.updating.TriggerRow: the trigger levels (TARP; set by `geoback run`)


def other_method(method: str) -> str:
    return "lm" if method == "gn" else "gn"


def pick_pair(result: Identification) -> tuple[int, int | None]:
    """The two most correlated parameters (the pair itself for n = 2; j None for n = 1)."""
    n = result.parameters.n
    if n == 1:
        return 0, None
    if n == 2:
        return 0, 1
    C = np.abs(np.nan_to_num(result.reliability.correlation, nan=0.0))
    np.fill_diagonal(C, -1)
    i, j = np.unravel_index(np.argmax(C), C.shape)
    return int(min(i, j)), int(max(i, j))


def _range(result: Identification, paths: list[Fit], i: int, pad_min: float) -> tuple[float, float]:
    """Grid range of parameter i: both paths and the estimate, padded, inside the bounds."""
    p_hat = result.fit.p
    params = result.parameters
    pts = np.array([h.p[i] for f in paths for h in f.history if h.accepted] + [p_hat[i]])
    span = max(pts.max() - pts.min(), 0.1 * max(abs(p_hat[i]), 1e-12))
    lo, hi = pts.min() - 0.12 * span, pts.max() + 0.12 * span
    lo, hi = min(lo, p_hat[i] - pad_min * span), max(hi, p_hat[i] + pad_min * span)
    if np.isfinite(params.lower[i]):
        lo = max(lo, params.lower[i] + 1e-9 * abs(params.lower[i]))
    if np.isfinite(params.upper[i]):
        hi = min(hi, params.upper[i] - 1e-9 * abs(params.upper[i]))
    return lo, hi


def _probe(misfit: Misfit, result: Identification, index, relative: float = 0.03) -> tuple[bool, float]:
    """Whether J at a point off the estimate (parameters `index` moved by `relative`, inside their
    bounds) needs a new factorisation (or a non-linear run), and the seconds it took. (Two probes
    take different steps: the simulation keeps its last factorisation.)"""
    sim, p = misfit.simulation, result.fit.p.copy()
    params = result.parameters
    for k in index:
        step = relative * (abs(p[k]) if p[k] != 0 else 1.0)
        up = p[k] + step
        p[k] = up if not np.isfinite(params.upper[k]) or up < params.upper[k] else p[k] - step
    before, t0 = sim.counters.factorisations, time.perf_counter()
    try:
        misfit.J(p)
    except Exception:  # noqa: BLE001 - no solution there: treat as costly
        return True, time.perf_counter() - t0
    return sim.counters.factorisations > before, time.perf_counter() - t0


def objective_slice(misfit: Misfit, result: Identification, paths: list[Fit], budget: float,
                    progress=None, source: str = "auto", refactorises: bool | None = None) -> ObjectiveSlice:
    """J over the two most correlated parameters (or one) through the estimate (paper Fig. 2).

    source: 'model' (J at every grid point; sized to `budget` seconds when every point refactorises),
    'linearised' (the Gauss-Newton quadratic form at the estimate) or 'auto' (the model when one
    factorisation serves the grid, else linearised); refactorises: the probe's answer, if known."""
    if source not in OBJECTIVE_MAPS:
        raise ValueError(f"unknown objective map '{source}' (known: {', '.join(OBJECTIVE_MAPS)})")
    p_hat = result.fit.p
    i, j = pick_pair(result)
    pair = [i] if j is None else [i, j]
    per_point = None
    if source != "linearised" and (refactorises is None or source == "model"):
        refactorises, per_point = _probe(misfit, result, pair, 0.045)
    refactorises = bool(refactorises)
    linear = source == "linearised" or (source == "auto" and refactorises)
    requested = source != "auto"
    ev = misfit.evaluate(p_hat, jacobian=True)  # the Jacobian at the estimate: SVD directions, linearised map

    def model_J(p):
        try:
            return misfit.J(p)
        except Exception:  # noqa: BLE001 - a failed forward run leaves a hole in the grid
            return np.nan

    def linear_J(p):
        d = (p - p_hat)[pair]
        r = ev.r - ev.B[:, pair] @ d
        return float(r @ r)

    J = linear_J if linear else model_J
    kind = "linearised" if linear else "model"
    if j is None:
        lo, hi = _range(result, paths, i, 0.0)
        pts = np.array([h.p[i] for f in paths for h in f.history if h.accepted])
        a = np.union1d(np.linspace(lo, hi, 120), pts[(pts >= lo) & (pts <= hi)])
        return ObjectiveSlice(i, None, a, None, np.array([J(np.array([v])) for v in a]), refactorises,
                              source=kind, requested=requested)
    (alo, ahi), (blo, bhi) = _range(result, paths, i, 0.3), _range(result, paths, j, 0.3)

    def at(u, v):
        p = p_hat.copy()
        p[i], p[j] = u, v
        return p

    ng = GRID
    if refactorises and not linear:  # the model asked for where every point costs a factorisation
        ng = int(np.clip(np.sqrt(budget / max(per_point or 1e-6, 1e-6)), GRID_MIN, GRID))
    a, b = np.linspace(alo, ahi, ng), np.linspace(blo, bhi, ng)
    Jg = np.full((ng, ng), np.nan)
    last = time.perf_counter()
    for r, v in enumerate(b):
        for c, u in enumerate(a):
            Jg[r, c] = J(at(u, v))
        if progress and time.perf_counter() - last > 2.0:
            progress(f"objective on a {ng}×{ng} grid: row {r + 1} of {ng}")
            last = time.perf_counter()
    # SVD directions at the minimum (eqns 44-49) of the slice's two whitened sensitivity columns
    n = result.parameters.n
    if n == 2:
        V, sv, whole = result.reliability.directions, result.reliability.singular_values, True
    else:
        As = ev.whitened_sensitivity[:, [i, j]] * np.where(p_hat[[i, j]] != 0, np.abs(p_hat[[i, j]]), 1.0)
        _, sv, Vt = np.linalg.svd(As, full_matrices=False)
        V = np.zeros((n, 2))
        V[[i, j], :] = Vt.T
        whole = False
    return ObjectiveSlice(i, j, a, b, Jg, refactorises, V, sv, whole, kind, requested)


def _row(points: np.ndarray) -> np.ndarray | None:
    """A dense line through a row (same depth) or column (same x) of three or more points, else None."""
    if len(points) < 3:
        return None
    x, y = points[:, 0], points[:, 1]
    span = max(np.ptp(x), np.ptp(y))
    if np.ptp(y) <= 1e-9 * max(span, 1.0):
        t = np.linspace(x.min(), x.max(), TROUGH_POINTS)
        return np.column_stack([t, np.full_like(t, y.mean())])
    if np.ptp(x) <= 1e-9 * max(span, 1.0):
        t = np.linspace(y.min(), y.max(), TROUGH_POINTS)
        return np.column_stack([np.full_like(t, x.mean()), t])
    return None


def profiles(sim, values: dict) -> dict[str, Profile]:
    """The model along every instrument and at its stations after the last construction stage (for
    the instrument and field figures), and along the line after each stage an instrument was read at."""
    out = {}
    read_at: dict[str, list[str]] = {}
    for block in sim.survey.blocks:
        read_at.setdefault(block.name, []).append(block.stage)
    final = sim.stages[-1]
    for block in sim.survey.blocks:
        if block.name in out:  # the same instrument read at another stage
            continue
        line = along = disp = reading = None
        by_stage = {}
        stations = block.stations
        if block.integration is not None:
            s = np.cumsum(block.lengths)
            start, d, direction = block.reference, block.along, block.measured
            along = np.linspace(0.0, s[-1], LINE_POINTS)
            line = start[None] + along[:, None] * d[None]

            def at(stage, since=block.since):
                u = sim.stage_displacements_at(values, np.vstack([line, start]), stage)
                ref, u = u[-1], u[:-1]
                reading = (u - ref) @ direction if block.relative else u @ direction
                if since is not None:  # installed after a stage: it reads the increment since then
                    reading = reading - at(since, None)[1]
                return u, reading

            try:
                disp, reading = at(final)
                if len(read_at[block.name]) > 1:
                    by_stage = {stage: at(stage)[1] for stage in read_at[block.name]}
            except ValueError:
                line = along = disp = reading = None
        by_stage_line = {}
        if block.kind == "points" and (line := _row(block.points)) is not None:  # the trough between the points
            try:
                zero = (sim.stage_displacements_at(values, line, block.since) if block.since is not None
                        else 0.0)  # installed after a stage: the increment since then
                by_stage_line = {stage: sim.stage_displacements_at(values, line, stage) - zero
                                 for stage in read_at[block.name]}
                disp = sim.stage_displacements_at(values, line, final)
            except ValueError:
                line, by_stage_line = None, {}
        out[block.name] = Profile(along, line, disp, reading, sim.displacements_at(values, stations), by_stage,
                                  by_stage_line)
    return out


def explore(misfit: Misfit, result: Identification, what=WHAT, settings: Settings = Settings(),
            budget: float | None = None, progress=None, objective_map: str = "auto") -> Exploration:
    """Run the model where figures and field files need it (see the module docstring).

    misfit: the one the result was fitted with; what: any of 'slice' (objective slice), 'other'
    (the other method's fit, with `settings`), 'field' (the field at the estimate) and 'profiles'
    (the model along the instruments), 'lining' (thrust and moments around a lining, if the model has
    one), 'plastic_zone' (the yielded ground, if the ground can yield); objective_map: 'auto' (the
    model's own map and the other method's path where one factorisation serves them, else the
    linearised map and no other path), 'model' (both from the model whatever they cost) or
    'linearised'; budget: seconds a model map may take when every grid point refactorises
    (default: the fit's own time, at least 1 s)."""
    unknown = set(what) - set(WHAT)
    if unknown:
        raise ValueError(f"unknown exploration(s): {', '.join(sorted(unknown))} (known: {', '.join(WHAT)})")
    if objective_map not in OBJECTIVE_MAPS:
        raise ValueError(f"unknown objective map '{objective_map}' (known: {', '.join(OBJECTIVE_MAPS)})")
    say = progress or (lambda msg: None)
    if result.weighting != misfit.weighting:
        misfit = misfit.with_weighting(result.weighting)
    sim = misfit.simulation
    before, t0 = sim.counters.snapshot(), time.perf_counter()
    if misfit.free and ("other" in what or "slice" in what):  # estimated error scales: the objective of the result
        misfit = misfit.anchored(result.fit.p)
    other, note, costly = None, "", None
    if ("other" in what or "slice" in what) and objective_map != "model":
        costly, _ = _probe(misfit, result, range(result.parameters.n))  # does a step off the estimate refactorise?
    if "other" in what:
        method = other_method(result.fit.method)
        if costly:
            note = ("not run for comparison: each of its steps would need a new solution of the model "
                    "(geoback run --plots --objective-map model runs it)")
        else:
            say(f"the other method's path ({method})")
            try:
                other = fit(misfit, settings, method=method)
            except Exception as exc:  # noqa: BLE001 - figures are still useful with one path
                note = f"failed: {exc}"
    slc = None
    if "slice" in what:
        say("objective around the estimate")
        budget = budget if budget is not None else max(1.0, result.seconds.get("fit", 1.0))
        slc = objective_slice(misfit, result, [result.fit] + ([other] if other else []), budget, say,
                              source=objective_map,
                              refactorises=costly if costly is False or result.parameters.n <= 2 else None)
    values = misfit.values(result.fit.p)
    fld = sim.field(values) if "field" in what else None
    prof = profiles(sim, values) if "profiles" in what else {}
    lining = sim.lining_forces(values) if "lining" in what else None
    zone = sim.plastic_zone(values) if "plastic_zone" in what else None
    return Exploration(other, note, slc, fld, prof, lining, zone, sim.counters.since(before),
                       time.perf_counter() - t0, costly)
