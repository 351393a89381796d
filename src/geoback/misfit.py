"""The seam between physics and statistics: measured readings, their covariance and the priors.

    J(p) = || L^-1 (x* - x(p)) ||^2 + (p - p0)^t C_p0^-1 (p - p0),      C_x = L L^t

(eqns 6 and 9, whitened as eqn 53 is corrected in the errata). ``Data`` holds x* and C_x =
blockdiag(C_x,i) over instruments (eqn 9); ``Misfit`` adds a simulation and the parameters and is
the only place where anything is whitened: an ``Evaluation`` carries the whitened residual
r' = L^-1 (x* - x) and sensitivity A' = L^-1 A, with the prior rows appended, in physical units.
The optimiser, the reliability measures and `diagnose` see nothing but this object.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Mapping, Sequence

import numpy as np
import scipy.linalg as sla

from . import covariance as cov
from .errors import GeobackError
from .instruments import InstrumentBlock, Reading
from .parameters import ParameterSet, resolve
from .simulation import Simulation, is_constant

WEIGHTINGS = ("full", "diagonal", "identity")
_trtrs = sla.lapack.dtrtrs


@dataclass(frozen=True)
class Data:
    """Measured readings x* (None for a forward run) and their covariance C_x (eqn 9), in the
    survey's row order, with the instrument blocks they belong to."""

    blocks: tuple[InstrumentBlock, ...]
    measured: np.ndarray | None
    covariance: np.ndarray
    labels: tuple[Reading, ...]

    @classmethod
    def build(cls, blocks: Sequence[InstrumentBlock], measured: np.ndarray | None,
              identified_constants: set[str] | frozenset = frozenset()) -> "Data":
        C = sla.block_diag(*[b.covariance_given(identified_constants) for b in blocks])
        labels = tuple(lab for b in blocks for lab in b.labels)
        if measured is not None:
            measured = np.asarray(measured, float).copy()
            measured.setflags(write=False)
        return cls(tuple(blocks), measured, C, labels)

    @property
    def m(self) -> int:
        return len(self.labels)

    def block_rows(self) -> list[tuple[InstrumentBlock, slice]]:
        out, start = [], 0
        for b in self.blocks:
            out.append((b, slice(start, start + b.m)))
            start += b.m
        return out

    def noise(self, rng: np.random.Generator, scale: float = 1.0) -> np.ndarray:
        """A draw from N(0, C_x): every instrument's readings with its own covariance (eqn 10)."""
        return scale * np.concatenate([cov.cholesky_factor(self.covariance[rows, rows], b.name)
                                       @ rng.standard_normal(b.m) for b, rows in self.block_rows()])

    def with_measured(self, measured: np.ndarray) -> "Data":
        measured = np.asarray(measured, float).copy()
        if measured.shape != (self.m,):
            raise ValueError(f"expected {self.m} readings, found {measured.shape}")
        measured.setflags(write=False)
        return replace(self, measured=measured)


def weighting_factor(data: Data, weighting: str) -> np.ndarray:
    """Lower-triangular L with L L^t the covariance used in J: C_x (full, eqn 9), its diagonal,
    or I (eqn 8). Factorised block by block, so a bad block is named."""
    if weighting not in WEIGHTINGS:
        raise GeobackError(f"weighting must be one of {', '.join(WEIGHTINGS)}, not '{weighting}'")
    if weighting == "identity":
        return np.eye(data.m)
    if weighting == "diagonal":
        return np.diag(np.sqrt(np.diag(data.covariance)))
    factors = [cov.cholesky_factor(data.covariance[rows, rows], b.name) for b, rows in data.block_rows()]
    return sla.block_diag(*factors)


@dataclass(frozen=True)
class Evaluation:
    """The misfit at p: computed readings x, their sensitivity A (physical units, None unless
    asked), and the residual vector r = [L^-1 (x* - x); sqrt(C_p0^-1) (p0 - p)] with its Jacobian
    B = -dr/dp = [L^-1 A; sqrt(C_p0^-1)] (rows of parameters with a prior only). J = r^t r."""

    p: np.ndarray
    x: np.ndarray
    A: np.ndarray | None
    r: np.ndarray
    B: np.ndarray | None
    m: int  # data rows of r (the rest are prior rows)

    @property
    def J(self) -> float:
        return float(self.r @ self.r)

    @property
    def J_data(self) -> float:
        rd = self.r[:self.m]
        return float(rd @ rd)

    @property
    def whitened_residual(self) -> np.ndarray:
        return self.r[:self.m]

    @property
    def whitened_sensitivity(self) -> np.ndarray | None:
        return None if self.B is None else self.B[:self.m]


class Misfit:
    """Readings, covariance and priors of a case against a simulation (see the module docstring).

    values: the named values the parameters are set into (case values, extensions' null values,
    fixed extra values); weighting: 'full' (C_x of eqn 9), 'diagonal' or 'identity' (eqn 8).
    """

    def __init__(self, simulation: Simulation, data: Data, parameters: ParameterSet, values: Mapping,
                 weighting: str = "full"):
        if data.measured is None:
            raise GeobackError("the case has instruments without readings: give 'readings' or 'readings_file' "
                               "for every instrument to identify parameters")
        self.simulation = simulation
        self.data = data
        self.parameters = parameters
        self.base_values = dict(values)
        self.weighting = weighting
        self.L = weighting_factor(data, weighting)
        self._Lf = np.asfortranarray(self.L)
        self.logdet = 2.0 * float(np.sum(np.log(np.abs(np.diag(self.L)))))
        has = parameters.has_prior
        self._prior_index = np.flatnonzero(has)
        self._prior_sqrt = np.sqrt(parameters.prior_precision()[has])
        self._prior_rows = np.zeros((len(self._prior_index), parameters.n))
        self._prior_rows[np.arange(len(self._prior_index)), self._prior_index] = self._prior_sqrt
        self._held = np.zeros(0)  # prior rows of parameters held fixed (profiles): constant terms of J

    # ------------------------------------------------------------------ the one place that whitens
    def whiten(self, v: np.ndarray) -> np.ndarray:
        """L^-1 v (v: a vector or the columns of a matrix of readings), by LAPACK's triangular solve
        called directly (scipy's wrapper costs ten times the solve on small systems), column by
        column (BLAS's multi-right-hand-side solve spends ~1 ms starting threads on small ones)."""
        if v.ndim == 1:
            x, info = _trtrs(self._Lf, v, lower=1)
            return x
        out = np.empty(v.shape)
        for j in range(v.shape[1]):
            out[:, j] = _trtrs(self._Lf, v[:, j], lower=1)[0]
        return out

    # ------------------------------------------------------------------ evaluation
    @property
    def m(self) -> int:
        return self.data.m

    @property
    def n(self) -> int:
        return self.parameters.n

    def values(self, p: np.ndarray) -> dict:
        """Named values with the parameters set to p."""
        values = dict(self.base_values)
        values.update(zip(self.parameters.names, map(float, p)))
        return values

    def evaluate(self, p: np.ndarray, jacobian: bool = False) -> Evaluation:
        """x(p), the whitened residual with the prior rows, and (if asked) their Jacobian."""
        p = np.asarray(p, float)
        pred = self.simulation.predict(self.values(p), self.parameters.names, sensitivities=jacobian)
        prior_r = self._prior_sqrt * (self.parameters.prior_mean[self._prior_index] - p[self._prior_index])
        r = np.concatenate([self.whiten(self.data.measured - pred.x), prior_r, self._held])
        B = np.vstack([self.whiten(pred.A), self._prior_rows, np.zeros((len(self._held), self.n))]) \
            if jacobian else None
        return Evaluation(p, pred.x, pred.A, r, B, self.m)

    def J(self, p: np.ndarray) -> float:
        return self.evaluate(p).J

    # ------------------------------------------------------------------ derived misfits
    def with_measured(self, measured: np.ndarray) -> "Misfit":
        """The same misfit for other readings (Monte Carlo replicates, study data)."""
        new = object.__new__(Misfit)
        new.__dict__.update(self.__dict__)
        new.data = self.data.with_measured(measured)
        return new

    def holding(self, index: int, value: float) -> "Misfit":
        """The misfit with parameter `index` held at `value` and the others free (a profile of the
        likelihood); its prior, if any, stays in J as a constant term."""
        params = self.parameters
        keep = [i for i in range(params.n) if i != index]
        sub = ParameterSet([params.names[i] for i in keep], params.initial[keep], params.lower[keep],
                           params.upper[keep], params.log[keep], params.prior_mean[keep], params.prior_std[keep],
                           [params.units[i] for i in keep])
        base = dict(self.base_values)
        base[params.names[index]] = float(value)
        new = Misfit(self.simulation, self.data, sub, base, self.weighting)
        held = [] if not params.has_prior[index] else \
            [(params.prior_mean[index] - value) / params.prior_std[index]]
        new._held = np.concatenate([self._held, held])
        return new

    def with_weighting(self, weighting: str) -> "Misfit":
        return Misfit(self.simulation, self.data, self.parameters, self.base_values, weighting)

    def extended(self, specs: Sequence, values: Mapping | None = None, simulation: Simulation | None = None,
                 start: np.ndarray | None = None) -> "Misfit":
        """A misfit with more parameters (`specs`, case Parameter models) and fixed `values`, on the
        same simulation (so its factorisations are shared) or on `simulation` (another mesh);
        the current parameters start from `start` (default: their initial values)."""
        simulation = simulation or self.simulation
        values = {**{k: v for k, v in self.base_values.items()}, **(values or {})}
        extra, base, _ = resolve(specs, simulation, values)
        current = self.parameters if start is None else self.parameters.with_initial(start)
        params = current + extra
        constants = {n for n in params.names if is_constant(n)}
        data = self.data
        if constants != {n for n in self.parameters.names if is_constant(n)}:
            data = Data.build(self.data.blocks, self.data.measured, constants)
        return Misfit(simulation, data, params, base, self.weighting)
