"""The observational method stage by stage: what a fit up to one stage forecasts for the readings
of the stages after it, how the surveys of a stage score against the forecast made before they were
read, and the trigger levels (TARP) with the probability of exceeding them.

Forecast of a later reading (first order, eqn 55 propagated): x_f = P u(p*) at its stage (increments
since the instrument's installation), model covariance A C_p A^t with A = dx/dp exact; what will be
*read* adds the reading's error, C = A C_p A^t + C_x. A survey scored against it gives per reading
z_i = (x_i - x_f,i) / sqrt(C_ii) (inside the 95 % band when |z| <= 1.96) and per survey of an
instrument chi2 = r^t C^-1 r with m degrees of freedom.

Trigger levels are on the magnitude of the movement (or force): P(|q| > L) for q ~ N(x_f, A C_p A^t)
(the ground's movement, not a reading's error), the first-order band; a reading's status now is its
latest survey's magnitude against the levels.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from scipy import stats

Z95 = 1.959963984540054
STATUS = ("green", "amber", "red")


@dataclass(frozen=True)
class SurveyForecast:
    """One instrument's survey (or a stage it will be read at) as forecast after the fit through
    `fitted`: readings at the estimate, their model std and the std of a reading of them; measured
    values and scores once the survey is read (NaN before)."""

    fitted: str
    stage: str
    survey: str | None
    instrument: str
    kind: str
    labels: tuple
    forecast: np.ndarray
    model_covariance: np.ndarray  # A C_p A^t: the model's band
    reading_covariance: np.ndarray  # C_x of a survey of it
    measured: np.ndarray | None = None

    @property
    def std_model(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.model_covariance), 0.0, None))

    @property
    def covariance(self) -> np.ndarray:
        """A C_p A^t + C_x: what will be read."""
        return self.model_covariance + self.reading_covariance

    def rows(self, rows, labels, survey, reading_covariance) -> "SurveyForecast":
        """The forecast of a survey that kept `rows` of the instrument (readings marked missing dropped)."""
        rows = list(rows)
        return replace(self, survey=survey, labels=tuple(labels), forecast=self.forecast[rows],
                       model_covariance=self.model_covariance[np.ix_(rows, rows)],
                       reading_covariance=reading_covariance)

    @property
    def std_reading(self) -> np.ndarray:
        return np.sqrt(np.diag(self.covariance))

    @property
    def z(self) -> np.ndarray:
        return (self.measured - self.forecast) / self.std_reading

    @property
    def chi2(self) -> float:
        r = self.measured - self.forecast
        return float(r @ np.linalg.solve(self.covariance, r))

    @property
    def p(self) -> float:
        return float(stats.chi2.sf(self.chi2, len(self.forecast)))

    @property
    def inside(self) -> int:
        return int(np.sum(np.abs(self.z) <= Z95))

    def sentence(self) -> str:
        """The survey's largest deviation from its forecast, in words."""
        z = self.z
        i = int(np.argmax(np.abs(z)))
        lab = self.labels[i]
        unit, f = ("kN", 1.0) if self.kind == "load_cell" else ("mm", 1e3)
        where = _where(lab)
        when = f"survey {self.survey}" if self.survey else f"stage {self.stage}"
        side = "above" if z[i] > 0 else "below"
        verdict = ("inside" if abs(z[i]) <= Z95 else "outside") + " its 95 % band"
        return (f"{self.instrument} ({when}): {what(lab)} at {where} read {f * self.measured[i]:.3g} {unit}, "
                f"{abs(z[i]):.1f} σ {side} what the fit through stage '{self.fitted}' forecast "
                f"({f * self.forecast[i]:.3g} ± {Z95 * f * self.std_reading[i]:.2g} {unit}), {verdict}; "
                f"{self.inside} of {len(z)} readings inside, χ² = {self.chi2:.1f} on {len(z)} (p = {self.p:.2g})")


def what(lab) -> str:
    return {"ux": "the horizontal displacement", "uy": "the vertical displacement (up +)",
            "along": "the displacement along the line", "normal": "the displacement normal to the line",
            "force": "the force"}.get(lab.component, lab.component)


def _where(lab) -> str:
    if lab.kind == "inclinometer":
        return f"{-lab.y:g} m depth"
    if lab.kind == "points":
        return f"point {lab.station} (x {lab.x:g} m)"
    if lab.kind == "load_cell":
        return "the cell"
    return f"station {lab.station} ({-lab.y:g} m depth)" if lab.x == 0 else f"station {lab.station}"


def forecast_surveys(analysis, result, blocks, fitted: str, measured: np.ndarray | None = None
                     ) -> list[SurveyForecast]:
    """What the fit `result` (of `analysis`, through stage `fitted`) forecasts for the instrument blocks
    `blocks` (each an instrument at a stage, increments since its installation), with `measured` their
    readings stacked in block order (None: not read yet)."""
    if not blocks:
        return []
    sim = analysis.simulation
    names = result.parameters.names
    values = analysis.values_at(result.fit.p)
    with sim.surveying(list(blocks)) as view:
        pred = view.predict(values, names, sensitivities=True)
    Cp = result.reliability.covariance
    out, r0 = [], 0
    for b in blocks:
        rows = slice(r0, r0 + b.m)
        A = pred.A[rows]
        model = A @ Cp @ A.T
        out.append(SurveyForecast(fitted, b.stage, b.survey, b.name,
                                  b.kind, tuple(b.labels), pred.x[rows].copy(), model, b.covariance,
                                  None if measured is None else measured[rows].copy()))
        r0 += b.m
    return out


def scored(forecasts: list[SurveyForecast], blocks, measured: np.ndarray) -> list[SurveyForecast]:
    """The forecasts of surveys that have now been read, with their readings (matched by instrument,
    stage and survey)."""
    at, r0 = {}, 0
    for b in blocks:
        at[(b.name, b.stage, b.survey)] = (b, measured[r0:r0 + b.m])
        r0 += b.m
    out = []
    for f in forecasts:
        hit = at.get((f.instrument, f.stage, f.survey))
        if hit is not None and len(hit[1]) == len(f.forecast):
            out.append(replace(f, measured=hit[1].copy()))
    return out


# --------------------------------------------------------------------- the sequential check
@dataclass(frozen=True)
class Sequential:
    """The sequential Bayesian update of one step: the previous step's posterior N(p_prev, C_prev) as
    the prior of this step's new surveys alone, maximised by Gauss-Newton with exact sensitivities
    (J = (x - x(p))^t C_x^-1 (x - x(p)) + (p - p_prev)^t C_prev^-1 (p - p_prev)); its estimate, its
    covariance and the difference from the joint refit in units of the joint std."""

    p: np.ndarray
    covariance: np.ndarray
    iterations: int
    difference_std: np.ndarray  # (p_sequential - p_joint) / std_joint


def sequential_step(analysis, blocks, measured: np.ndarray, p_prev: np.ndarray, C_prev: np.ndarray,
                    p_joint: np.ndarray, std_joint: np.ndarray, tol: float = 1e-10, iterations: int = 30
                    ) -> Sequential:
    """This step's new surveys (`blocks`, their readings `measured`) with the previous posterior as the
    prior (``Sequential``); starts from the previous estimate. For a model linear in the parameters it
    is the joint refit exactly (Gaussian conjugacy); otherwise they differ by the curvature the
    linearisation of the previous step leaves out. The readings are whitened by the seam
    (``misfit.whiten_block``) and every inverse is eqn 55's (``LinearAnalysis``)."""
    from geoback.inference.linear_analysis import LinearAnalysis
    from geoback.inference.misfit import whiten_block

    names = analysis.parameters.names
    P0 = LinearAnalysis.from_information(C_prev).covariance  # C_prev^-1: the prior's information

    def whitened(pred):
        r, A, r0 = [], [], 0
        for b in blocks:
            rows = slice(r0, r0 + b.m)
            r.append(whiten_block(b, measured[rows] - pred.x[rows]))
            A.append(whiten_block(b, pred.A[rows]))
            r0 += b.m
        return np.concatenate(r), np.vstack(A)

    p = np.array(p_prev, float)
    with analysis.simulation.surveying(list(blocks)) as view:
        for k in range(1, iterations + 1):
            r, A = whitened(view.predict(analysis.values_at(p), names, sensitivities=True))
            post = LinearAnalysis.from_information(A.T @ A + P0)
            step = post.covariance @ (A.T @ r - P0 @ (p - p_prev))
            p = p + step
            if np.all(np.abs(step) <= tol * np.maximum(np.abs(p), 1e-12)):
                break
        _, A = whitened(view.predict(analysis.values_at(p), names, sensitivities=True))
    C = LinearAnalysis.from_information(A.T @ A + P0).covariance
    return Sequential(p, np.array(C), k, (p - np.asarray(p_joint)) / np.asarray(std_joint))


# ------------------------------------------------------------------------------------ triggers
def exceedance(mean, std, level) -> np.ndarray:
    """P(|q| > level) for q ~ N(mean, std^2) (exact 0/1 where std = 0)."""
    mean, std = np.asarray(mean, float), np.asarray(std, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        p = stats.norm.sf((level - mean) / std) + stats.norm.cdf((-level - mean) / std)
    return np.where(std > 0, p, (np.abs(mean) > level).astype(float))


def status_of(value: float, amber: float | None, red: float | None) -> str:
    v = abs(value)
    if red is not None and v > red:
        return "red"
    if amber is not None and v > amber:
        return "amber"
    return "green"


@dataclass(frozen=True)
class TriggerRow:
    """One quantity against its trigger levels at one stage: the measured magnitude (now) or the
    forecast with the probability of exceeding each level (the worst reading of an instrument)."""

    quantity: str  # instrument or forecast name
    when: str  # 'now', or the stage forecast
    stage: str
    where: str
    value: float  # SI
    std: float  # model std (0 for a measured value)
    amber: float | None
    red: float | None
    p_amber: float
    p_red: float
    unit: str
    measured: bool
    nonlinear: bool = False  # a forecast whose sampled band departs from the linear one
    p_amber_sampled: float = math.nan  # from the sampling check's draws through the model (NaN: none)
    p_red_sampled: float = math.nan

    @property
    def probabilities(self) -> tuple[float, float]:
        """(P amber, P red) the status is read from: the sampled ones where the model is non-linear
        (the sampled band departs from the linear one), else the first-order ones."""
        if self.nonlinear and np.isfinite(self.p_red_sampled):
            return self.p_amber_sampled, self.p_red_sampled
        return self.p_amber, self.p_red

    @property
    def status(self) -> str:
        if self.measured:
            return status_of(self.value, self.amber, self.red)
        pa, pr = self.probabilities
        if self.red is not None and pr >= 0.5:
            return "red"
        if (self.amber is not None and pa >= 0.5) or (self.red is not None and pr >= 0.05):
            return "amber"
        return "green"


def trigger_rows(name: str, when: str, stage: str, labels, mean, std, amber, red, unit: str,
                 measured: bool = False) -> TriggerRow:
    """The row of the reading most likely to exceed red (then amber; measured: the largest)."""
    mean, std = np.asarray(mean, float), np.asarray(std, float)
    if measured:
        i = int(np.argmax(np.abs(mean)))
        pa = float(abs(mean[i]) > amber) if amber is not None else math.nan
        pr = float(abs(mean[i]) > red) if red is not None else math.nan
    else:
        pa_all = exceedance(mean, std, amber) if amber is not None else np.full(len(mean), np.nan)
        pr_all = exceedance(mean, std, red) if red is not None else np.full(len(mean), np.nan)
        key = pr_all if red is not None else pa_all
        i = int(np.nanargmax(key)) if np.any(np.isfinite(key)) else 0
        pa, pr = float(pa_all[i]), float(pr_all[i])
    lab = labels[i] if labels else None
    return TriggerRow(name, when, stage, _where(lab) if lab is not None else "", float(mean[i]), float(std[i]),
                      amber, red, pa, pr, unit, measured)


def trigger_table(analysis, stage: str, ahead, forecasts) -> list[TriggerRow]:
    """TARP rows of every instrument and forecast of the case with trigger levels: the latest survey
    fitted (now), the next stage and the end (from `ahead`, ``SurveyForecast`` of later stages), and the
    case's forecasts (`forecasts`, ``worth.forecast.Forecasts``; a forecast whose sampled band departs
    from the linear one is marked: its probabilities are first order only)."""
    from geoback.case.loading import stage_names
    from geoback.case.timeline import forecast_quantity, instrument_quantity, levels

    case = analysis.loaded.case
    stages = stage_names(case)
    k = stages.index(stage)
    later = list(dict.fromkeys(s for s in (stages[k + 1] if k + 1 < len(stages) else None, stages[-1])
                               if s is not None and stages.index(s) > k))
    rows = []
    fitted = analysis.simulation.survey.blocks
    measured = analysis.misfit.data.measured
    for ins in case.instruments:
        if ins.triggers is None:
            continue
        q = instrument_quantity(ins)
        amber, red = levels(ins.triggers, q)
        unit = "kN" if q == "force" else "m"
        r0, latest = 0, None
        for b in fitted:
            if b.name == ins.name:
                latest = (b, measured[r0:r0 + b.m])
            r0 += b.m
        if latest is not None:
            b, v = latest
            rows.append(trigger_rows(ins.name, f"now ({b.survey or b.stage})", b.stage, b.labels, v, np.zeros(len(v)),
                                     amber, red, unit, measured=True))
        for s in later:
            f = next((f for f in ahead if f.instrument == ins.name and f.stage == s), None)
            if f is not None:
                rows.append(trigger_rows(ins.name, "end" if s == stages[-1] else "next stage", s, f.labels,
                                         f.forecast, f.std_model, amber, red, unit))
    if forecasts is not None:
        for f in case.forecasts:
            if f.triggers is None:
                continue
            amber, red = levels(f.triggers, forecast_quantity(case, f))
            fc = forecasts[f.name]
            row = replace(trigger_rows(f.name, "forecast", fc.stage, None, fc.values, fc.std, amber, red, fc.unit),
                          nonlinear=bool(fc.nonlinear))
            if forecasts.samples is not None:  # the same point's draws through the model
                i = int(np.argmin(np.abs(fc.values - row.value) + np.abs(fc.std - row.std)))
                S = np.abs(forecasts.samples[:, forecasts.rows(f.name)[i]])
                row = replace(row, p_amber_sampled=float(np.mean(S > amber)) if amber is not None else math.nan,
                              p_red_sampled=float(np.mean(S > red)) if red is not None else math.nan)
            rows.append(row)
    return rows


def later_blocks(analysis, stage: str, since: dict | None = None) -> list:
    """Every instrument of the case at every stage after `stage` (increments since its installation:
    `since` {instrument: stage}, default as the fit reads them), for the forecasts of what it will read."""
    from geoback.case.loading import stage_names
    from geoback.observation.instruments import case_blocks

    stages = stage_names(analysis.loaded.case)
    since = since if since is not None else {b.name: b.since for b in analysis.simulation.survey.blocks}
    out = []
    for s in stages[stages.index(stage) + 1:]:
        for g in case_blocks(analysis.loaded):
            g = replace(g, since=since.get(g.name, g.since))
            if g.since is None or stages.index(s) > stages.index(g.since):
                out.append(g.at(s))
    return out


@dataclass(frozen=True)
class UpdateStep:
    """One step of `geoback update`: the fit through `stage` (its Identification), the forecasts it made
    of the later surveys, and the surveys of this stage scored against the previous step's forecast."""

    stage: str
    result: object
    surveys: tuple  # the sets fitted ('I1 advance@2026-03-05', ...)
    ahead: tuple = ()  # SurveyForecast of every later survey (scored when read)
    checks: tuple = ()  # SurveyForecast with measured: this stage's surveys against the previous forecast
    triggers: tuple = ()  # TriggerRow
    forecasts: object = None  # the case's forecasts at this step (worth.forecast.Forecasts)
    sequential: Sequential | None = None  # the previous posterior as prior of the new surveys: the check
