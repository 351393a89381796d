"""The identified parameters: names, initial values, bounds, log transforms and Gaussian priors.

The optimiser works on internal coordinates q (q = ln p for log-transformed parameters);
the objective J = r'^t r' + (p - p0)^t C_p0^-1 (p - p0) keeps the prior in physical units.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
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

    def to_internal(self, p: np.ndarray) -> np.ndarray:
        p = np.asarray(p, float)
        return np.where(self.log, np.log(np.where(self.log, p, 1.0)), p)

    def to_physical(self, q: np.ndarray) -> np.ndarray:
        q = np.asarray(q, float)
        return np.where(self.log, np.exp(np.where(self.log, q, 0.0)), q)

    def dp_dq(self, q: np.ndarray) -> np.ndarray:
        """Diagonal of the Jacobian of the transform, d p / d q."""
        return np.where(self.log, self.to_physical(q), 1.0)

    def internal_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        lo = np.where(self.log, np.log(np.where(self.lower > 0, self.lower, 1.0)), self.lower)
        hi = np.where(self.log, np.log(np.where(self.upper > 0, self.upper, 1.0)), self.upper)
        lo = np.where(self.log & ~(self.lower > 0), -np.inf, lo)
        return lo, hi

    @property
    def has_prior(self) -> np.ndarray:
        return np.isfinite(self.prior_mean)

    def prior_precision(self) -> np.ndarray:
        """Diagonal of C_p0^-1 in physical units (0 where no prior)."""
        return np.where(self.has_prior, 1.0 / np.where(self.has_prior, self.prior_std, 1.0) ** 2, 0.0)


def unit_of(name: str) -> str:
    base = name.split("[")[0]
    return {"E": "kPa", "Egrad": "kPa/m", "nu": "-", "K0": "-", "K0grad": "1/m", "beta": "-",
            "n": "-", "m": "-", "A": "m", "B": "m", "C": "rad", "D": "m"}.get(base, "-")
