"""Identification of a case: prepare (mesh, simulation, misfit), fit, assess, return a frozen result.

    analysis = prepare(load_case("cases/tunnel-paper.yaml"))
    result = identify(analysis)            # or identify(loaded): prepares it first
    result["E[clay]"].value, result["E[clay]"].std, result["E[clay]"].interval
    print(geoback.fit_report(result))

The result holds numbers only (no model): figures and files read it, and what they need beyond
it (an objective slice, the field) comes from ``explore`` (explicit, counted separately).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from geoback.case.loading import LoadedCase, stage_names
from geoback.errors import GeobackError
from geoback.inference.estimate import Fit, Settings, fit
from geoback.inference.misfit import Data, Misfit
from geoback.inference.parameters import ParameterSet, parameter_limits, resolve
from geoback.observation.readings import measured_values, survey_blocks
from geoback.inference.caveats import fit_caveats, status_words
from geoback.inference.reliability import Reliability, assess
from geoback.inference.scales import groups_of
from geoback.physics.factory import make_simulation
from geoback.physics.simulation import Prediction, Simulation, is_constant
from geoback.inference.replicates import Replicates, identify_replicates  # noqa: F401 (part of this module's API)


@dataclass(frozen=True)
class Analysis:
    """A case made ready to fit: its simulation (physics), the parameters and the named values
    they are set into, its misfit (readings, C_x, priors; None when the case has no readings)
    and the fit settings."""

    loaded: LoadedCase
    simulation: Simulation
    parameters: ParameterSet
    base_values: dict
    misfit: Misfit | None
    settings: Settings
    notices: tuple = ()  # unusual input values (geoback.inference.caveats), carried into the results

    @property
    def case(self):
        return self.loaded.case

    def values_at(self, p) -> dict:
        """Named values with the parameters set to p."""
        values = dict(self.base_values)
        values.update(zip(self.parameters.names, map(float, p)))
        return values

    @property
    def values(self) -> dict:
        """Named values the case starts from (parameters at their initial values)."""
        return self.values_at(self.parameters.initial)

    def predict(self, p, sensitivities: bool = False) -> Prediction:
        """Computed readings at parameter values p and, if asked, A = dx/dp (eqns 29, 34-42)."""
        return self.simulation.predict(self.values_at(p), self.parameters.names, sensitivities)

    def with_readings(self, measured: np.ndarray, weighting: str | None = None) -> "Analysis":
        """The same case (simulation and its factorisations shared) with other readings x*, in
        survey order: study data, Monte Carlo replicates."""
        if self.misfit is not None and weighting in (None, self.misfit.weighting):
            return replace(self, misfit=self.misfit.with_measured(measured))
        identified = {n for n in self.parameters.names if is_constant(n)}
        blocks = self.simulation.survey.blocks
        data = Data.build(blocks, np.asarray(measured, float), identified)
        return replace(self, misfit=Misfit(self.simulation, data, self.parameters, self.base_values,
                                           weighting or self.case.fit.weighting, groups_of(self.case, blocks)))


def prepare(loaded: LoadedCase, mesh=None, backend: str | None = None, parameters=None,
            values: Mapping | None = None, with_readings: bool = True, simulation: Simulation | None = None,
            weighting: str | None = None) -> Analysis:
    """Mesh, assemble and read a case: the simulation, and the misfit of its readings.

    parameters: case Parameter models to identify instead of the case's; values: named values
    that replace the case's (e.g. an extension switched on); with_readings=False: no misfit."""
    case = loaded.case
    if simulation is None:
        blocks, measured = survey_blocks(loaded, stage_names(case), read=with_readings)
        simulation = make_simulation(loaded, mesh=mesh, backend=backend, blocks=blocks)
    else:
        measured = measured_values(loaded, simulation.survey.blocks)
    specs = case.parameters if parameters is None else parameters
    own = parameters is None

    def located(i, message, field="name"):
        if own:
            return loaded.error(("parameters", i, field), message)
        return GeobackError(message)

    params, base, notices = resolve(specs, simulation, values, error=located)
    notices += input_notices(case, simulation)
    misfit = None
    if with_readings:
        if measured is not None:
            identified = {n for n in params.names if is_constant(n)}
            data = Data.build(simulation.survey.blocks, measured, identified)
            misfit = Misfit(simulation, data, params, base, weighting or case.fit.weighting,
                            groups_of(case, simulation.survey.blocks))
    return Analysis(loaded, simulation, params, base, misfit, Settings.of(case.fit), tuple(notices))


def input_notices(case, simulation: Simulation) -> list:
    """Case values outside the usual range for ground (a modulus written in Pa, say)."""
    from geoback.inference.caveats import Caveat

    out = []
    values = simulation.quantities()
    for name, v in values.items():
        lim = simulation.limits(name, values)
        if not lim.plausible[0] <= v <= lim.plausible[1]:
            unit = simulation.unit(name)
            hint = " (was it written in Pa? the case's stresses are in kPa: write e.g. '60 MPa')" \
                if unit == "kPa" and v > lim.plausible[1] else ""
            out.append(Caveat("implausible-input", f"{name} = {v:g} {unit if unit != '-' else ''} in the case is "
                                                   f"outside the usual range for ground ({lim.plausible[0]:g} to "
                                                   f"{lim.plausible[1]:g}){hint}".replace("  ", " "), name))
    return out


@dataclass(frozen=True)
class Estimate:
    """One identified parameter: value, standard deviation and 95 % interval (eqn 55)."""

    name: str
    unit: str
    initial: float
    value: float
    std: float
    low: float
    high: float
    at_bound: bool

    @property
    def interval(self) -> tuple[float, float]:
        return self.low, self.high

    def __repr__(self) -> str:
        bound = ", at a bound" if self.at_bound else ""
        unit = f" {self.unit}" if self.unit not in ("-", "") else ""
        return (f"{self.name} = {self.value:.6g} ± {self.std:.3g}{unit} "
                f"(95 % [{self.low:.6g}, {self.high:.6g}]{bound})")


@dataclass(frozen=True)
class Identification:
    """What `identify` found: the fit (estimate, history, status), its reliability (C_p,
    correlations, SVD, information density, chi^2, AIC, BIC) and the data it was fitted to.

    result["E[clay]"] -> Estimate; result.estimates -> all of them; geoback.fit_report(result) -> text."""

    case: object  # the Case model (pydantic, frozen)
    case_hash: str
    parameters: ParameterSet
    fit: Fit
    reliability: Reliability
    data: Data
    weighting: str
    counts: dict  # factorisations, solves, forward runs of the fit
    seconds: dict
    dofs: int
    elements: int
    solver: str | None
    standardised: np.ndarray  # L^-1 (x* - x) with the case's full C_x, whatever the weighting
    profiled: dict = field(default_factory=dict)  # name -> (low, high, low open, high open): profile-
    # likelihood 95 % intervals; an open end is a limit (bound or allowed range) the readings do not move away from
    caveats: tuple = ()  # what not to trust, in words and codes (geoback.inference.caveats)
    mesh_error: object = None  # geoback.inference.mesh_error.MeshError, if checked
    mesh_error_included: bool = False  # its variance added to C_x before the final fit
    forecasts: object = None  # geoback.worth.forecast.Forecasts at the estimate, if the case asks for any
    prior_posterior: object = None  # geoback.inference.identifiability.PriorPosterior: what the readings add to a prior

    @property
    def status(self) -> str:
        """'converged', 'converged; model inadequate (p = ...)', 'not converged' or 'stopped without moving'."""
        return status_words(self.fit, self.reliability)

    def intervals95(self) -> tuple[np.ndarray, np.ndarray]:
        """The 95 % interval of each parameter: profile likelihood where it was computed, else linearised."""
        lo, hi = self.reliability.interval95()
        lo, hi = lo.copy(), hi.copy()
        for name, (a, b, _, _) in self.profiled.items():
            i = self.parameters.index(name)
            lo[i], hi[i] = a, b
        return lo, hi

    @property
    def name(self) -> str:
        return self.case.name

    @property
    def estimates(self) -> list[Estimate]:
        lo, hi = self.intervals95()
        p = self.parameters
        return [Estimate(n, p.units[i], float(p.initial[i]), float(self.fit.p[i]), float(self.reliability.std[i]),
                         float(lo[i]), float(hi[i]), bool(self.fit.at_bound[i])) for i, n in enumerate(p.names)]

    def __getitem__(self, name: str) -> Estimate:
        for e in self.estimates:
            if e.name == name:
                return e
        raise KeyError(f"{name!r} is not an identified parameter ({', '.join(self.parameters.names)})")

    @property
    def residual(self) -> np.ndarray:
        return self.data.measured - self.fit.x

    def __repr__(self) -> str:
        rel = self.reliability
        lines = [f"<Identification {self.name}: {self.fit.status}, {self.fit.iterations} iterations, "
                 f"chi2/dof = {rel.reduced_chi2:.4g} (p = {rel.p_value:.3g})>"]
        lines += [f"  {e!r}" for e in self.estimates]
        return "\n".join(lines)


def identify(case, method: str | None = None, progress=None, weighting: str | None = None,
             p0: np.ndarray | None = None, profile: str = "auto", require_dof: bool = True,
             mesh_error: str | None = "ignore") -> Identification:
    """Identify the case's parameters and assess the estimate (no files written).

    case: a LoadedCase (prepared here) or an Analysis (its simulation and factorisations reused);
    profile: 'auto' (profile-likelihood intervals where the linearised ones are unreliable), 'all'
    or 'none'; require_dof: refuse a case with no more readings (and priors) than parameters;
    mesh_error: 'check' or 'include' the discretisation error of the readings (geoback.inference.mesh_error;
    one more forward run on a finer mesh), 'ignore' it, or None for the case's fit.mesh_error."""
    t0 = time.perf_counter()
    analysis = case if isinstance(case, Analysis) else prepare(case)
    t1 = time.perf_counter()
    misfit = analysis.misfit
    if misfit is None:
        raise GeobackError("the case has instruments without readings: give 'readings' or 'readings_file' "
                           "for every instrument to identify parameters")
    if misfit.n == 0:
        raise GeobackError("the case lists no parameters to identify (add a 'parameters' section)")
    priors = int(np.count_nonzero(misfit.parameters.has_prior))
    if require_dof and misfit.m + priors <= misfit.n:
        raise analysis.loaded.error(("parameters",),
            f"expected more readings than parameters, found {misfit.m} reading(s)"
            + (f" and {priors} prior(s)" if priors else "") + f" for {misfit.n} parameters "
            f"({', '.join(misfit.parameters.names)}): the fit would have {misfit.m + priors - misfit.n} degrees of "
            "freedom and nothing could test it; add readings or priors, or identify fewer parameters")
    if weighting and weighting != misfit.weighting:
        misfit = misfit.with_weighting(weighting)
    sim = analysis.simulation
    before = sim.counters.snapshot()
    result = fit(misfit, analysis.settings, method=method, p0=p0, progress=progress)
    mode = analysis.case.fit.mesh_error if mesh_error is None else mesh_error
    merr, notices = None, analysis.notices
    if mode != "ignore" and result.moved:
        from geoback.inference.caveats import Caveat
        from geoback.inference.mesh_error import WARN, discretisation_error

        merr = discretisation_error(analysis, misfit, result.p)
        if mode == "include" and not merr.skipped:  # the mesh's error as an independent error of each reading
            data = misfit.data
            widened = Data(data.blocks, data.measured, data.covariance + np.diag(merr.difference ** 2), data.labels)
            misfit = Misfit(misfit.simulation, widened, misfit.parameters, misfit.base_values, misfit.weighting,
                            misfit.scales)
            result = fit(misfit, analysis.settings, method=method, p0=result.p, progress=progress)
        elif merr.max_sigma > WARN:
            notices = tuple(notices) + (Caveat(
                "mesh-error", merr.text() + f": above {WARN:g} sigma, the mesh may bias the estimate; refine the "
                "mesh near the instruments (mesh.size_tunnel, mesh.size_instruments) or add the error to C_x "
                "with fit: {mesh_error: include}"),)
    counts = sim.counters.since(before)
    t2 = time.perf_counter()
    out = conclude(misfit, result, analysis.case, analysis.loaded.digest(), counts,
                   dict(sim.timings, setup=t1 - t0, fit=t2 - t1), analysis.settings, profile, notices)
    return replace(out, seconds={**out.seconds, "assess": time.perf_counter() - t2}, mesh_error=merr,
                   mesh_error_included=mode == "include" and merr is not None and not merr.skipped)


def conclude(misfit: Misfit, result: Fit, case, case_hash: str, counts: dict, seconds: dict,
             settings: Settings | None = None, profile: str = "auto", notices=()) -> Identification:
    """The frozen result of a fit: its reliability (eqns 43-55), profile-likelihood intervals where
    the linearised ones are not reliable (profile 'auto'; 'all' or 'none'; needs `settings`), what
    not to trust (caveats, with the input `notices`) and the data it was fitted to."""
    misfit = misfit.anchored(result.p)  # estimated error scales: restricted dof at the optimum
    rel = assess(misfit.evaluate(result.p, jacobian=True), misfit.parameters, misfit.logdet)
    full = misfit if misfit.weighting == "full" else misfit.with_weighting("full")
    standardised = full.whiten(misfit.data.measured - result.x)
    sim = misfit.simulation
    values = misfit.values(result.p)
    limits = [parameter_limits(sim, n, values) for n in misfit.parameters.names]
    profiled = {}
    if settings is not None and profile != "none" and result.status == "converged" and result.moved:
        profiled = _profiles(misfit, settings, result, rel, limits, profile == "all")
    caveats = tuple(notices) + tuple(fit_caveats(result, rel, misfit.parameters, limits, profiled))
    from geoback.inference.identifiability import prior_posterior

    return Identification(
        case, case_hash, misfit.parameters, result, rel, misfit.data, misfit.weighting,
        {k: counts.get(k, 0) for k in ("factorisations", "solves", "forward_runs")}, dict(seconds),
        getattr(sim, "dofs", 0), len(getattr(sim.mesh, "triangles", ())), getattr(sim, "solver", None),
        standardised, profiled, caveats,
        prior_posterior=prior_posterior(rel.information, misfit.parameters, result.p, limits))


def _profiles(misfit: Misfit, settings: Settings, result: Fit, rel: Reliability, limits, every: bool) -> dict:
    """Profile-likelihood intervals of the parameters whose linearised interval is not reliable: a
    coefficient of variation of 30 % or more, an interval crossing a bound or the allowed range,
    or J at the linearised interval's ends off the expected rise of 3.84 by more than a factor of
    two (every: all)."""
    CHI2_1_95 = 3.841458820694124  # chi^2_1 at 95 % (profile.CHI2_1_95; scipy.optimize loads only if needed)
    params = misfit.parameters
    p, J0 = result.p, result.J
    lo_lin, hi_lin = rel.interval95()
    out = {}
    for i, name in enumerate(params.names):
        sd = rel.std[i]
        if not np.isfinite(sd) or sd == 0 or result.at_bound[i]:
            continue
        lim = limits[i]
        lo = max(params.lower[i], lim.lo if lim else -np.inf)
        hi = min(params.upper[i], lim.hi if lim else np.inf)
        need = every
        if not need:
            positive = lim is not None and lim.lo >= 0
            need = (positive and sd / abs(p[i]) >= 0.30) or lo_lin[i] < lo or hi_lin[i] > hi
        if not need:  # J at the linearised interval's ends, the others at their linearised conditional optimum
            d = rel.covariance[:, i] / rel.covariance[i, i] * 1.96 * sd
            for sign in (-1, 1):
                q = p + sign * d
                if np.all(q >= params.lower) and np.all(q <= params.upper):
                    try:
                        rise = misfit.J(q) - J0
                    except Exception:  # noqa: BLE001 - a failed forward run says the linearisation is off
                        rise = np.inf
                    need = need or not 0.5 * CHI2_1_95 <= rise <= 2 * CHI2_1_95  # off by a factor 2
        if need:
            from geoback.inference.profile import profile_interval

            a, b = profile_interval(misfit, settings, p, J0, i, sd, lo, hi,
                                    bool(params.log[i]) or (lim is not None and lim.lo > 0))
            out[name] = (a, b, a == lo, b == hi)  # an end at a limit: the readings do not bound it there
    return out
