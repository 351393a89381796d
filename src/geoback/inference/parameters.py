"""The identified parameters: names, initial values, bounds, log transforms and Gaussian priors.

``resolve`` turns the case's ``parameters:`` entries into a ``ParameterSet`` with canonical names
('E' -> 'E[clay]'), checked against what the simulation knows, and the named values the model
starts from (the case's values, extensions at their null values).
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from geoback.errors import GeobackError
from geoback.observation.instruments import ERROR_STEMS, is_instrument_error
from geoback.case.limits import BIAS_SHIFT, CONSTANT_ANGLE, CONSTANT_LENGTH, DEPTH_OFFSET
from geoback.physics.simulation import Simulation, is_constant

UNITS = {"A": "m", "B": "m", "C": "rad", "D": "m", **ERROR_STEMS}


@dataclass(frozen=True)
class ParameterSet:
    names: list[str]
    initial: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    log: np.ndarray  # bool
    prior_mean: np.ndarray  # nan where no prior
    prior_std: np.ndarray
    units: list[str]

    @property
    def n(self) -> int:
        return len(self.names)

    @property
    def has_prior(self) -> np.ndarray:
        return np.isfinite(self.prior_mean)

    def prior_precision(self) -> np.ndarray:
        """Diagonal of C_p0^-1 in physical units (0 where no prior)."""
        return np.where(self.has_prior, 1.0 / np.where(self.has_prior, self.prior_std, 1.0) ** 2, 0.0)

    def index(self, name: str) -> int:
        return self.names.index(name)

    def __add__(self, other: "ParameterSet") -> "ParameterSet":
        cat = np.concatenate
        return ParameterSet(self.names + other.names, cat([self.initial, other.initial]),
                            cat([self.lower, other.lower]), cat([self.upper, other.upper]),
                            cat([self.log, other.log]), cat([self.prior_mean, other.prior_mean]),
                            cat([self.prior_std, other.prior_std]), self.units + other.units)

    def vector(self, p, what: str = "parameter values") -> np.ndarray:
        """p as a vector of one finite number per parameter, in the set's order; refused (GeobackError
        naming the expected parameters) otherwise."""
        try:
            v = np.asarray(p, dtype=float)
        except (TypeError, ValueError):
            raise GeobackError(f"{what}: expected {self.n} numbers ({', '.join(self.names)}), found {p!r}") from None
        if v.ndim != 1 or len(v) != self.n:
            raise GeobackError(f"{what}: expected {self.n} value{'s' if self.n != 1 else ''}, one for each of "
                               f"{', '.join(self.names)} in that order, found {v.size if v.ndim else 1} "
                               f"value{'s' if v.size != 1 else ''}")
        if not np.all(np.isfinite(v)):
            bad = [n for n, x in zip(self.names, v) if not np.isfinite(x)]
            raise GeobackError(f"{what}: expected finite numbers, found {', '.join(bad)} not finite")
        return v

    def within_bounds(self, p, what: str = "initial values") -> np.ndarray:
        """p (see ``vector``) with every value inside its bounds (the case's bounds cut to the allowed
        range: what the fit may explore); refused otherwise, naming the parameter and its bounds."""
        v = self.vector(p, what)
        for i, name in enumerate(self.names):
            if not self.lower[i] <= v[i] <= self.upper[i]:
                unit = "" if self.units[i] in ("-", "") else f" {self.units[i]}"
                raise GeobackError(f"{what}: expected {name} within its bounds [{self.lower[i]:g}, {self.upper[i]:g}]"
                                   f"{unit} (the case's bounds within its allowed range), found {v[i]:g}")
        return v

    def with_initial(self, p: np.ndarray) -> "ParameterSet":
        return ParameterSet(self.names, np.asarray(p, float).copy(), self.lower, self.upper, self.log,
                            self.prior_mean, self.prior_std, self.units)


def parameter_limits(simulation: Simulation, name: str, values: Mapping):
    """Allowed and usual range of a parameter (``limits.Limits``)."""
    if is_constant(name):
        return CONSTANT_ANGLE if name[0] == "C" else CONSTANT_LENGTH
    if is_instrument_error(name):
        return BIAS_SHIFT if name.startswith("bias[") else DEPTH_OFFSET
    return simulation.limits(name, values)


def _instrument_term(name: str, simulation: Simulation) -> tuple[str, str] | None:
    """(name, unit) of an instrument's integration constant or systematic error; None if `name` is
    not one; GeobackError if the survey has no such term."""
    if is_constant(name):
        known = simulation.survey.constant_names
        what = "integration constants"
    elif is_instrument_error(name):
        known = simulation.survey.error_names
        what = "systematic errors (inclinometers' bias and zoff)"
    else:
        return None
    if name not in known:
        raise GeobackError(f"unknown name '{name}': the instruments' {what} are "
                           f"{', '.join(known) or 'none'}")
    return name, UNITS[name.split("[")[0]]


def resolve(specs: Sequence, simulation: Simulation, values: Mapping | None = None,
            error=None, clip_bounds: bool = False) -> tuple[ParameterSet, dict, list]:
    """Canonical ParameterSet of the `specs` (case Parameter models), the named values to start
    from (the simulation's quantities, `values`, extensions at their null values), and notices
    (``caveats.Caveat``) about unusual initial values.

    Every parameter stays inside its allowed range (``parameter_limits``, from
    ``case.limits.QUANTITIES``: the one statement of the ranges, which ``resolve_values`` (``--set``)
    applies too): an initial value, prior or bound outside it is refused (a release fraction
    beta above 1, a modulus bound below 1 Pa). clip_bounds: the bounds are cut to that range
    instead (the diagnosis' own hypotheses, whose search ranges are generic).
    error(i, message, field) builds the exception for spec i (e.g. located in the case file)."""
    from geoback.inference.caveats import Caveat

    error = error or (lambda i, message, field="name": GeobackError(message))
    base = dict(simulation.quantities())
    base.update(values or {})
    names, init, lo, hi, log, pm, ps, units = [], [], [], [], [], [], [], []
    notices = []
    constants = set(simulation.survey.constant_names)
    canonical = []
    for i, p in enumerate(specs):
        if is_constant(p.name):
            if p.name not in constants:
                raise error(i, f"'{p.name}': no linewise instrument has this integration constant")
            name = p.name
        elif is_instrument_error(p.name):
            if p.name not in simulation.survey.error_names:
                raise error(i, f"'{p.name}': no inclinometer has this systematic error (known: "
                               f"{', '.join(simulation.survey.error_names) or 'none'})")
            name = p.name
        else:
            name = simulation.canonical(p.name)
            if name is None:
                raise error(i, f"unknown parameter '{p.name}' ({_hint(p.name, simulation)})")
            if name not in base:
                null = simulation.null_value(name, base)
                if null is None:
                    raise error(i, f"'{p.name}' has no value in the case to start from"
                                   + (" (give this layer a K0 in ground.layers)" if name.startswith("K0") else ""))
                base[name] = null
        if name in canonical:
            raise error(i, f"'{p.name}' is the same parameter as '{specs[canonical.index(name)].name}': "
                           "list each parameter once")
        canonical.append(name)
    # ranges that depend on other quantities (n's limit on nu) are those at the initial values
    start = {**base, **{name: p.initial for name, p in zip(canonical, specs)
                         if not (is_constant(name) or is_instrument_error(name))}}
    for i, (p, name) in enumerate(zip(specs, canonical)):
        unit = (UNITS[name.split("[")[0]] if is_constant(name) or is_instrument_error(name)
                else simulation.unit(name))
        lim = parameter_limits(simulation, name, start)
        span = f"{lim.lo:g} to {lim.hi:g}" + (f" {unit}" if unit not in ("-", "") else "")
        if not lim.contains(p.initial):
            raise error(i, f"expected an initial value of {name} within its allowed range ({span}), found "
                           f"{p.initial:g}", "initial")
        b_lo, b_hi = (p.bounds if p.bounds else (-np.inf, np.inf))
        if p.bounds and not clip_bounds and not (lim.contains(b_lo) and lim.contains(b_hi)):
            raise error(i, f"expected bounds of {name} within its allowed range ({span}), found "
                           f"[{p.bounds[0]:g}, {p.bounds[1]:g}]", "bounds")
        b_lo, b_hi = max(b_lo, lim.lo), min(b_hi, lim.hi)
        if not b_lo < b_hi:
            raise error(i, f"expected bounds overlapping the allowed range of {name} ({span}), found "
                           f"[{p.bounds[0]:g}, {p.bounds[1]:g}]", "bounds")
        if p.prior is not None:
            if not lim.contains(p.prior.mean):
                raise error(i, f"expected a prior mean of {name} within its allowed range ({span}), found "
                               f"{p.prior.mean:g}", "prior")
            floor = 1e-9 * max(abs(p.prior.mean), abs(p.initial), 1e-12)
            if p.prior.std < floor:
                raise error(i, f"expected a prior std of at least {floor:.3g} (1e-9 of the parameter's size), found "
                               f"{p.prior.std:g}; to fix {name}, leave it out of the parameters and give its value "
                               "in the case", "prior")
        if not lim.plausible[0] <= p.initial <= lim.plausible[1]:
            notices.append(Caveat("implausible-input",
                                  f"the initial value of {name}, {p.initial:g}" + (f" {unit}" if unit not in ("-", "")
                                                                                    else "")
                                  + f", is outside the usual range for {lim.usual_for} ({lim.plausible[0]:g} to "
                                    f"{lim.plausible[1]:g}); check its unit", name))
        names.append(name)
        init.append(p.initial)
        lo.append(b_lo)
        hi.append(b_hi)
        log.append(p.log)
        pm.append(p.prior.mean if p.prior else np.nan)
        ps.append(p.prior.std if p.prior else np.nan)
        units.append(unit)
    params = ParameterSet(names, np.array(init, float), np.array(lo, float), np.array(hi, float),
                          np.array(log, bool), np.array(pm, float), np.array(ps, float), units)
    return params, base, notices


def _hint(name: str, simulation: Simulation) -> str:
    known = simulation.known_names()
    stem = name.split("[")[0]
    same = [k for k in known if k.split("[")[0].lower() == stem.lower()]
    if same:
        return "known: " + ", ".join(same)
    return "known names: " + ", ".join(known[:12]) + (", ..." if len(known) > 12 else "") + \
        "; extensions such as Egrad[layer], n[layer], K0grad, beta"


_SCALES = {"kPa": {"pa": 1e-3, "kpa": 1.0, "mpa": 1e3, "gpa": 1e6},
           "kPa/m": {"pa/m": 1e-3, "kpa/m": 1.0, "mpa/m": 1e3},
           "m": {"m": 1.0, "cm": 1e-2, "mm": 1e-3},
           "rad": {"rad": 1.0, "mrad": 1e-3},
           "1/m": {"1/m": 1.0}}


def parse_quantity(text, unit: str) -> float:
    """A value as the case file accepts it: a number in the quantity's SI unit, or a number with a
    unit of the same kind ('50 MPa' for a modulus in kPa, '4 mm' for a length in m)."""
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        return float(text)
    m = re.fullmatch(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([A-Za-z/]+)?\s*", str(text))
    if not m:
        raise ValueError(f"expected a number{f' (in {unit})' if unit not in ('-', '') else ''}, found '{text}'")
    value = float(m.group(1))
    if m.group(2):
        scales = _SCALES.get(unit, {})
        factor = scales.get(m.group(2).lower())
        if factor is None:
            raise ValueError(f"expected a unit of {unit} ({', '.join(scales) or 'none: a plain number'}), "
                             f"found '{m.group(2)}'")
        value *= factor
    if not np.isfinite(value):
        raise ValueError(f"expected a finite number, found '{text}'")
    return value


def resolve_values(simulation: Simulation, assignments: Mapping[str, object]) -> dict[str, float]:
    """Named values given by a person (``--set E[clay]=50 MPa``): canonical names, values in SI,
    each checked against the quantities the simulation knows and their allowed range."""
    out: dict[str, float] = {}
    base = dict(simulation.quantities())
    for raw, text in assignments.items():
        term = _instrument_term(raw, simulation)
        if term is not None:
            name, unit = term
        else:
            name = simulation.canonical(raw)
            if name is None:
                raise GeobackError(f"unknown name '{raw}' ({_hint(raw, simulation)})")
            unit = simulation.unit(name)
        try:
            value = parse_quantity(text, unit)
        except ValueError as exc:
            raise GeobackError(f"{raw}={text}: expected NAME=NUMBER, with a unit if wished as in the case file "
                               f"({exc})") from None
        lim = parameter_limits(simulation, name, {**base, **out})
        if not lim.contains(value):
            raise GeobackError(f"{raw}: expected a value within {lim.lo:g} to {lim.hi:g}"
                               f"{'' if unit in ('-', '') else ' ' + unit}, found {value:g}")
        out[name] = value
    return out
