"""The identified parameters: names, initial values, bounds, log transforms and Gaussian priors.

``resolve`` turns the case's ``parameters:`` entries into a ``ParameterSet`` with canonical names
('E' -> 'E[clay]'), checked against what the simulation knows, and the named values the model
starts from (the case's values, extensions at their null values).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from .errors import GeobackError
from .simulation import Simulation, is_constant

UNITS = {"A": "m", "B": "m", "C": "rad", "D": "m"}


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

    def with_initial(self, p: np.ndarray) -> "ParameterSet":
        return ParameterSet(self.names, np.asarray(p, float).copy(), self.lower, self.upper, self.log,
                            self.prior_mean, self.prior_std, self.units)


def resolve(specs: Sequence, simulation: Simulation, values: Mapping | None = None,
            error=None) -> tuple[ParameterSet, dict]:
    """Canonical ParameterSet of the `specs` (case Parameter models) and the named values to start
    from: the simulation's quantities, `values`, and extensions at their null values.

    error(i, message) builds the exception for spec i (e.g. located in the case file)."""
    error = error or (lambda i, message: GeobackError(message))
    base = dict(simulation.quantities())
    base.update(values or {})
    names, init, lo, hi, log, pm, ps, units = [], [], [], [], [], [], [], []
    constants = set(simulation.survey.constant_names)
    for i, p in enumerate(specs):
        if is_constant(p.name):
            if p.name not in constants:
                raise error(i, f"'{p.name}': no linewise instrument has this integration constant")
            name, unit = p.name, UNITS[p.name[0]]
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
            unit = simulation.unit(name)
        if name in names:
            raise error(i, f"'{p.name}' is the same parameter as '{specs[names.index(name)].name}': "
                           "list each parameter once")
        names.append(name)
        init.append(p.initial)
        lo.append(p.bounds[0] if p.bounds else -np.inf)
        hi.append(p.bounds[1] if p.bounds else np.inf)
        log.append(p.log)
        pm.append(p.prior.mean if p.prior else np.nan)
        ps.append(p.prior.std if p.prior else np.nan)
        units.append(unit)
    params = ParameterSet(names, np.array(init, float), np.array(lo, float), np.array(hi, float),
                          np.array(log, bool), np.array(pm, float), np.array(ps, float), units)
    return params, base


def _hint(name: str, simulation: Simulation) -> str:
    known = simulation.known_names()
    stem = name.split("[")[0]
    same = [k for k in known if k.split("[")[0].lower() == stem.lower()]
    if same:
        return "known: " + ", ".join(same)
    return "known names: " + ", ".join(known[:12]) + (", ..." if len(known) > 12 else "") + \
        "; extensions such as Egrad[layer], n[layer], K0grad, beta"
