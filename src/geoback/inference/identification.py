"""Identification of a case: prepare (mesh, simulation, misfit), fit, assess, return a frozen result.

    analysis = prepare(load_case("cases/tunnel-paper.yaml"))
    result = identify(analysis)            # or identify(loaded) or identify("case.yaml"): prepares it first
    result["E[clay]"].value, result["E[clay]"].std, result["E[clay]"].interval
    for e in result: print(e.name, e.value, e.unit)      # the estimates, in the case's order
    result.correlation("E[clay]", "K0"), result.to_dict()  # JSON-ready
    print(geoback.fit_report(result))

The result holds numbers only (no model): figures and files read it, and what they need beyond
it (an objective slice, the field) comes from ``explore`` (explicit, counted separately).
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field, replace
from typing import Mapping

import numpy as np

from geoback.case.limits import natural_limit
from geoback.case.loading import LoadedCase, stage_names
from geoback.errors import GeobackError
from geoback.inference.estimate import Fit, Settings, fit
from geoback.inference.misfit import Data, Misfit, whiten_block
from geoback.inference.parameters import ParameterSet, parameter_limits, resolve
from geoback.observation.readings import measured_values, survey_blocks
from geoback.inference.caveats import fit_caveats, instrument_caveats, status_words
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
        """Computed readings at parameter values p (one per parameter, in ``parameters.names``'
        order, each within its allowed range) and, if asked, A = dx/dp (eqns 29, 34-42)."""
        p = self.checked(p, "predict")
        return self.simulation.predict(self.values_at(p), self.parameters.names, sensitivities)

    def checked(self, p, what: str = "parameter values") -> np.ndarray:
        """p as a vector of the analysis' parameters, each within its allowed range (``limits``: the
        same ranges the case file and ``--set`` are checked against); GeobackError otherwise."""
        p = self.parameters.vector(p, what)
        values = self.values_at(p)
        for i, name in enumerate(self.parameters.names):
            lim = parameter_limits(self.simulation, name, values)
            if lim is not None and not lim.contains(p[i]):
                unit = self.parameters.units[i]
                raise GeobackError(f"{what}: expected {name} within its allowed range ({lim.lo:g} to {lim.hi:g}"
                                   f"{'' if unit in ('-', '') else ' ' + unit}), found {p[i]:g}")
        return p

    def check_identification(self, result: "Identification", what: str = "forecast") -> None:
        """Refuse an identification of another case (or of other parameters than this analysis'
        simulation knows): its estimate would be put into a model it was not fitted to."""
        digest = self.loaded.digest()
        theirs = getattr(result, "case_hash", None)
        if theirs != digest:
            other = getattr(getattr(result, "case", None), "name", "?")
            raise GeobackError(f"{what}: expected an identification of case '{self.case.name}' (digest {digest}), "
                               f"found one of case '{other}' (digest {theirs}): identify this analysis first "
                               f"(geoback.identify(analysis))")
        survey = self.simulation.survey
        unknown = [n for n in result.parameters.names
                   if not (n in self.parameters.names or n in survey.constant_names or n in survey.error_names
                           or self.simulation.canonical(n) == n)]
        if unknown:
            raise GeobackError(f"{what}: the identification's parameters {', '.join(unknown)} are not quantities of "
                               f"this analysis' model (was it identified on an extended model, e.g. by diagnose? "
                               f"prepare that model's case, e.g. the diagnosis' amended.yaml)")

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


def loaded_case(case) -> LoadedCase:
    """A case as the public functions accept it: a LoadedCase, or the path of a case file (str or
    Path; loaded and checked here)."""
    if isinstance(case, LoadedCase):
        return case
    if isinstance(case, (str, os.PathLike)):
        from geoback.case.loading import load_case

        return load_case(case)
    raise GeobackError(f"expected a case: a case file's path (str or Path), a LoadedCase (geoback.load_case) or a "
                       f"prepared Analysis (geoback.prepare), found {type(case).__name__}")


def analysis_of(case) -> "Analysis":
    """An Analysis from what a user has: a path, a LoadedCase (prepared here) or an Analysis."""
    return case if isinstance(case, Analysis) else prepare(loaded_case(case))


def prepare(loaded: LoadedCase, mesh=None, backend: str | None = None, parameters=None,
            values: Mapping | None = None, with_readings: bool = True, simulation: Simulation | None = None,
            weighting: str | None = None) -> Analysis:
    """Mesh, assemble and read a case (a LoadedCase, or a case file's path): the simulation, and
    the misfit of its readings.

    parameters: case Parameter models to identify instead of the case's; values: named values
    that replace the case's (e.g. an extension switched on); with_readings=False: no misfit."""
    loaded = loaded_case(loaded)
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
    notices += input_notices(case, simulation, loaded)
    misfit = None
    if with_readings:
        if measured is not None:
            identified = {n for n in params.names if is_constant(n)}
            data = Data.build(simulation.survey.blocks, measured, identified)
            misfit = Misfit(simulation, data, params, base, weighting or case.fit.weighting,
                            groups_of(case, simulation.survey.blocks))
    return Analysis(loaded, simulation, params, base, misfit, Settings.of(case.fit), tuple(notices))


def input_notices(case, simulation: Simulation, loaded: LoadedCase | None = None) -> list:
    """Case values outside the usual range of what they describe (ground, or a concrete lining:
    ``limits``): allowed, so not refused, but most often a unit slip - a modulus written in Pa, or a
    lining's in MPa where GPa was meant (a bare number is kPa) - that leaves the model a thousand times
    off without a word. Said with the field (file and line, when `loaded` has them) and the value it
    would have been in the unit meant."""
    from geoback.inference.caveats import Caveat

    out = []
    values = simulation.quantities()
    for name, v in values.items():
        lim = simulation.limits(name, values)
        lo, hi = lim.plausible
        if lo <= v <= hi:
            continue
        unit = simulation.unit(name)
        text = (f"{name} = {_shown(v, unit)} in the case is outside the usual range for {lim.usual_for} "
                f"({_shown(lo, unit)} to {_shown(hi, unit)}){_unit_hint(v, unit, lo, hi)}")
        at = _field_of(case, name)
        if at is not None and loaded is not None:
            text = str(loaded.error(at, text))
        elif at is not None:
            from geoback.case.yamlmarks import format_path

            text = f"{format_path(at)}: {text}"
        out.append(Caveat("implausible-input", text, name))
    return out


def _shown(v: float, unit: str) -> str:
    """A value as engineers read it: 30000 kPa as '30 MPa', 3e7 kPa as '30 GPa'."""
    from geoback.units import number, shown

    factor, shown_unit = shown(unit, v)
    return number(v * factor) + ("" if shown_unit in ("-", "") else f" {shown_unit}")


def _unit_hint(v: float, unit: str, lo: float, hi: float) -> str:
    """Which unit slip would explain a stress outside its usual range ('' for other quantities)."""
    if unit != "kPa":
        return ""
    if v > hi:
        if lo <= v / 1e3 <= hi:
            return (f"; was it written in Pa? the case's stresses are in kPa: write the unit, e.g. "
                    f"'{_shown(v / 1e3, unit)}'")
        return "; check its unit (a number without a unit is read in kPa)"
    for factor in (1e3, 1e6):  # MPa written (or a bare number read in kPa) where GPa (or MPa) was meant
        if lo <= v * factor <= hi:
            meant = _shown(v * factor, unit)
            return f"; was {meant} meant? a number without a unit is read in kPa: write the unit, e.g. '{meant}'"
    return "; check its unit (a number without a unit is read in kPa)"


def _field_of(case, name: str) -> tuple | None:
    """Where a named value of the case is written (the lining's E and nu, a layer's E, nu or K0, the
    ground's K0, a stage's release), for a warning's file and line; None for any other name."""
    stem, _, rest = name.partition("[")
    key = rest[:-1] if rest.endswith("]") else None
    construction = getattr(case, "construction", None)
    lining = getattr(construction, "lining", None)
    if lining is not None and key == lining.name and stem in ("E", "nu"):
        return ("construction", "lining", stem)
    if construction is not None and stem == "beta":
        k = next((k for k, s in enumerate(construction.stages) if s.name == key), None)
        return None if k is None else ("construction", "stages", k, "release")
    if stem not in ("E", "nu", "K0"):
        return None
    layers = case.ground.layers
    i = next((i for i, layer in enumerate(layers) if layer.name == key), 0 if len(layers) == 1 else None)
    if i is not None and getattr(layers[i], stem, None) is not None:
        return ("ground", "layers", i, stem)
    return ("ground", stem) if getattr(case.ground, stem, None) is not None else None


@dataclass(frozen=True)
class Interval:
    """A parameter's 95 % interval and how it was found: 'linearised' (eqn 55, p ± z std),
    'linearised in ln p' (p exp(± z std / p): a positive quantity whose linearised interval would
    cross its lower limit, or a parameter fitted as ln p), 'profile likelihood', or 'none' (low and
    high nan; `reason` says why: the fit did not converge, the readings do not determine it). An
    open end is a limit (a bound or the allowed range) the readings do not move the parameter from."""

    low: float
    high: float
    method: str = "linearised"
    open: tuple[bool, bool] = (False, False)
    reason: str = ""

    @property
    def exists(self) -> bool:
        return self.method != "none"

    def as_dict(self) -> dict:
        """JSON-ready: the ends (None where there is no interval), the method, open ends and why."""
        ends = [float(self.low), float(self.high)] if self.exists else None
        return {"ci95": ends, "ci95_method": self.method, "ci95_open": list(map(bool, self.open)),
                **({"ci95_reason": self.reason} if self.reason else {})}


def interval_records(fit: Fit, rel: Reliability, params: ParameterSet, limits, profiled: dict) -> tuple:
    """Every parameter's ``Interval``: none where the fit did not converge (a linearised interval
    about a point that is not the optimum means nothing) or the std is not finite; a positive
    quantity (its allowed range starts at 0 or above: E, c', K0, nu) never gets an end below its
    lower limit: its interval is linearised in ln p instead, and an end beyond the allowed range is
    that limit, open (the readings do not bound it there)."""
    if not fit.moved:
        why = "the fit stopped without moving from the initial values: there is no estimate to put an interval on"
        return tuple(Interval(math.nan, math.nan, "none", reason=why) for _ in params.names)
    if fit.status != "converged":
        why = (f"the fit did not converge ({fit.reason}): a linearised interval about a point that is not the "
               f"optimum means nothing")
        return tuple(Interval(math.nan, math.nan, "none", reason=why) for _ in params.names)
    lo, hi = rel.interval95()
    out = []
    for i, name in enumerate(params.names):
        if name in profiled:
            a, b, a_open, b_open = profiled[name]
            out.append(Interval(float(a), float(b), "profile likelihood", (bool(a_open), bool(b_open))))
            continue
        p, sd = float(fit.p[i]), float(rel.std[i])
        if not np.isfinite(sd):
            out.append(Interval(math.nan, math.nan, "none",
                                reason="the readings do not determine it (its standard deviation is infinite)"))
            continue
        lim = limits[i]
        a, b = float(lo[i]), float(hi[i])
        method = "linearised in ln p" if params.log[i] else "linearised"
        if lim is not None and lim.ratio_scale and a < lim.lo and p > 0 and not params.log[i]:
            f = math.exp(min((b - p) / p, 700.0))  # z std / p, as the linearised interval used
            a, b, method = p / f, p * f, "linearised in ln p"
        a_open = b_open = False
        if lim is not None:
            if a < lim.lo:  # (a natural limit, no preload, closes the interval there: a finding)
                a, a_open = float(lim.lo), not lim.natural_lo
            if b > lim.hi:
                b, b_open = float(lim.hi), True
        reason = ""
        if a_open or b_open:
            ends = " and ".join(w for w, o in (("below", a_open), ("above", b_open)) if o)
            reason = f"the readings do not bound it {ends}: the interval ends at its allowed range there"
        out.append(Interval(a, b, method, (a_open, b_open), reason))
    return tuple(out)


@dataclass(frozen=True)
class Estimate:
    """One identified parameter: value, standard deviation and 95 % interval (eqn 55; how it was
    found in `method`, 'none' with the `reason` where there is none: low and high are then nan)."""

    name: str
    unit: str
    initial: float
    value: float
    std: float
    low: float
    high: float
    at_bound: bool
    method: str = "linearised"
    open: tuple[bool, bool] = (False, False)
    reason: str = ""

    @property
    def interval(self) -> tuple[float, float] | None:
        """(low, high), or None where there is no interval (``reason`` says why)."""
        return None if self.method == "none" else (self.low, self.high)

    def as_dict(self) -> dict:
        """JSON-ready (nan as None)."""
        return {"name": self.name, "unit": self.unit, "initial": _num(self.initial), "value": _num(self.value),
                "std": _num(self.std), "interval": None if self.interval is None else [_num(self.low), _num(self.high)],
                "interval_method": self.method, "interval_open": list(map(bool, self.open)),
                "interval_reason": self.reason or None, "at_bound": bool(self.at_bound)}

    def __repr__(self) -> str:
        bound = ", at a bound" if self.at_bound else ""
        unit = f" {self.unit}" if self.unit not in ("-", "") else ""
        if self.interval is None:
            return f"{self.name} = {self.value:.6g} ± {self.std:.3g}{unit} (no 95 % interval: {self.reason}{bound})"
        how = "" if self.method == "linearised" else f", {self.method}"
        return (f"{self.name} = {self.value:.6g} ± {self.std:.3g}{unit} "
                f"(95 % [{self.low:.6g}, {self.high:.6g}]{how}{bound})")


def _num(v) -> float | None:
    """A JSON-ready number: a float, None for nan and infinities."""
    v = float(v)
    return v if math.isfinite(v) else None


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
    intervals: tuple = ()  # an Interval per parameter: its 95 % interval, how it was found, or why there is none

    @property
    def status(self) -> str:
        """'converged', 'converged; model inadequate (p = ...)', 'not converged' or 'stopped without moving'."""
        return status_words(self.fit, self.reliability)

    def intervals95(self) -> tuple[np.ndarray, np.ndarray]:
        """The 95 % interval of each parameter (``interval``: profile likelihood where it was
        computed, else linearised; nan where there is none, e.g. the fit did not converge)."""
        if self.intervals:
            return (np.array([iv.low for iv in self.intervals], float),
                    np.array([iv.high for iv in self.intervals], float))
        lo, hi = self.reliability.interval95()
        lo, hi = lo.copy(), hi.copy()
        for name, (a, b, _, _) in self.profiled.items():
            i = self.parameters.index(name)
            lo[i], hi[i] = a, b
        return lo, hi

    def interval(self, name: str) -> Interval:
        """The 95 % interval of parameter `name` with how it was found (or why there is none)."""
        i = self._index(name)
        if self.intervals:
            return self.intervals[i]
        lo, hi = self.intervals95()
        got = self.profiled.get(name)
        return Interval(float(lo[i]), float(hi[i]), "profile likelihood" if got else "linearised",
                        (bool(got[2]), bool(got[3])) if got else (False, False))

    @property
    def name(self) -> str:
        return self.case.name

    @property
    def estimates(self) -> list[Estimate]:
        p = self.parameters
        out = []
        for i, n in enumerate(p.names):
            iv = self.interval(n)
            out.append(Estimate(n, p.units[i], float(p.initial[i]), float(self.fit.p[i]), float(self.reliability.std[i]),
                                float(iv.low), float(iv.high), bool(self.fit.at_bound[i]), iv.method, iv.open,
                                iv.reason))
        return out

    def _index(self, name: str) -> int:
        if name not in self.parameters.names:
            raise KeyError(f"{name!r} is not an identified parameter ({', '.join(self.parameters.names)})")
        return self.parameters.index(name)

    def __getitem__(self, name: str) -> Estimate:
        return self.estimates[self._index(name)]

    def __iter__(self):
        """The estimates, in the parameters' order (``for e in result: e.name, e.value, e.std``)."""
        return iter(self.estimates)

    def __len__(self) -> int:
        return self.parameters.n

    def __contains__(self, name) -> bool:
        return name in self.parameters.names

    def keys(self) -> list[str]:
        """The parameters' names (``dict(zip(result.keys(), result))``)."""
        return list(self.parameters.names)

    def correlation(self, a: str, b: str) -> float:
        """The correlation of the estimates of parameters `a` and `b` (from C_p, eqn 55)."""
        i, j = sorted((self._index(a), self._index(b)))  # (the same number whichever way it is asked)
        return float(self.reliability.correlation[i, j])

    @property
    def correlations(self) -> dict[tuple[str, str], float]:
        """Every pair's correlation by names: {("E[clay]", "K0"): -0.12, ...} (each pair once, in order)."""
        names, C = self.parameters.names, self.reliability.correlation
        return {(a, names[j]): float(C[i, j]) for i, a in enumerate(names) for j in range(i + 1, len(names))}

    def to_dict(self) -> dict:
        """The result as plain JSON-ready data: status, the estimates (value, std, interval, unit),
        chi-square, correlations by names and the caveats (nan and infinities as None)."""
        rel, f = self.reliability, self.fit
        return {
            "case": self.name, "case_hash": self.case_hash, "status": self.status,
            "converged": f.status == "converged", "stop_reason": f.reason, "method": f.method,
            "iterations": int(f.iterations), "weighting": self.weighting,
            "estimates": {e.name: e.as_dict() for e in self.estimates},
            "chi2": _num(rel.chi2), "dof": _num(rel.dof), "reduced_chi2": _num(rel.reduced_chi2),
            "p_value": _num(rel.p_value), "aic": _num(rel.aic), "bic": _num(rel.bic), "readings": int(self.data.m),
            "correlations": {f"{a}, {b}": _num(c) for (a, b), c in self.correlations.items()},
            "caveats": [c.as_dict() for c in self.caveats],
        }

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

    case: a case file's path or a LoadedCase (prepared here), or an Analysis (its simulation and
    factorisations reused); p0: where the fit starts instead of the case's initial values (one value
    per parameter, each within its bounds: refused otherwise, as the case file's are); profile: 'auto' (profile-likelihood intervals where the linearised ones are unreliable), 'all'
    or 'none'; require_dof: refuse a case with no more readings (and priors) than parameters;
    mesh_error: 'check' or 'include' the discretisation error of the readings (geoback.inference.mesh_error;
    one more forward run on a finer mesh), 'ignore' it, or None for the case's fit.mesh_error."""
    t0 = time.perf_counter()
    analysis = analysis_of(case)
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
    if p0 is not None:
        p0 = misfit.parameters.within_bounds(p0, "p0 (the initial values)")
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
    if merr is not None and merr.skipped.startswith("the model could not be solved"):
        from geoback.inference.caveats import Caveat

        # (the fit is kept: its finer mesh has no solution, so the check is skipped and the result says so)
        notices = tuple(notices) + (Caveat("model-unsolved", f"discretisation error not checked: {merr.skipped}"),)
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
    caveats = (tuple(notices) + tuple(fit_caveats(result, rel, misfit.parameters, limits, profiled))
               + tuple(instrument_caveats(rel, misfit.data, result.x, whiten_block)))
    from geoback.inference.identifiability import prior_posterior

    return Identification(
        case, case_hash, misfit.parameters, result, rel, misfit.data, misfit.weighting,
        {k: counts.get(k, 0) for k in ("factorisations", "solves", "forward_runs")}, dict(seconds),
        getattr(sim, "dofs", 0), len(getattr(sim.mesh, "triangles", ())), getattr(sim, "solver", None),
        standardised, profiled, caveats,
        prior_posterior=prior_posterior(rel.information, misfit.parameters, result.p, limits),
        intervals=interval_records(result, rel, misfit.parameters, limits, profiled))


def _profiles(misfit: Misfit, settings: Settings, result: Fit, rel: Reliability, limits, every: bool) -> dict:
    """Profile-likelihood intervals of the parameters whose linearised interval is not reliable: a
    coefficient of variation of 30 % or more, an interval crossing a bound or the allowed range,
    or J at the linearised interval's ends off the expected rise of 3.84 by more than a factor of
    two (every: all)."""
    CHI2_1_95 = 3.841458820694124  # chi^2_1 at 95 % (profile.CHI2_1_95; scipy.optimize loads only if needed)
    params = misfit.parameters
    sim = misfit.simulation
    p, J0 = result.p, result.J
    lo_lin, hi_lin = rel.interval95()
    out = {}
    for i, name in enumerate(params.names):
        sd = rel.std[i]
        lim = limits[i]
        if not np.isfinite(sd) or sd == 0 or (result.at_bound[i] and not natural_limit(lim, p[i])):
            continue  # (a fit ended at a natural limit, no preload, is profiled from there)
        lo = max(params.lower[i], lim.lo if lim else -np.inf)
        hi = min(params.upper[i], lim.hi if lim else np.inf)
        need = every
        if not need:
            ratio = lim is not None and lim.ratio_scale and p[i] != 0
            need = (ratio and sd / abs(p[i]) >= 0.30) or lo_lin[i] < lo or hi_lin[i] > hi
        if not need:  # J at the linearised interval's ends, the others at their linearised conditional optimum
            d = rel.covariance[:, i] / rel.covariance[i, i] * 1.96 * sd
            for sign in (-1, 1):
                q = p + sign * d
                if np.all(q >= params.lower) and np.all(q <= params.upper):
                    try:
                        with sim.probing():  # (not a fit's trial point: nothing to differentiate ahead)
                            rise = misfit.J(q) - J0
                    except Exception:  # noqa: BLE001 - a failed forward run says the linearisation is off
                        rise = np.inf
                    need = need or not 0.5 * CHI2_1_95 <= rise <= 2 * CHI2_1_95  # off by a factor 2
        if need:
            from geoback.inference.profile import profile_interval

            a, b = profile_interval(misfit, settings, p, J0, i, sd, lo, hi,
                                    bool(params.log[i]) or (lim is not None and lim.lo > 0))
            out[name] = (a, b, a == lo and not natural_limit(lim, lo), b == hi)  # an end at a limit: the readings
            # do not bound it there (at a natural limit, no preload, the end is a finding: closed)
    return out
