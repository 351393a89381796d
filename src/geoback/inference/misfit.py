"""The seam between physics and statistics: measured readings, their covariance and the priors.

    J(p) = || L^-1 (x* - x(p)) ||^2 + (p - p0)^t C_p0^-1 (p - p0),      C_x = L L^t

(eqns 6 and 9, whitened as eqn 53 is corrected in the errata). ``Data`` holds x* and C_x =
blockdiag(C_x,i) over instruments (eqn 9); ``Misfit`` adds a simulation and the parameters and is
the only place where anything is whitened: an ``Evaluation`` carries the whitened residual
r' = L^-1 (x* - x) and sensitivity A' = L^-1 A, with the prior rows appended, in physical units.
The optimiser, the reliability measures and `diagnose` see nothing but this object. An instrument
outside the survey (a candidate of `design`) is whitened here too, by its own factor L_c
(``whiten_block``), and noise N(0, C_x) is drawn here, block by block (``block_noise``).

Error scales (eqns 5 and 10, ``scales.py``): where the case says an instrument's sigma is known
only up to a factor k, the misfit profiles k^2 in closed form at every p and re-weights: the
residual and sensitivity rows of a group are whitened by its estimated scale, and the objective
is S*(p) (the support function with the scales profiled out, equal to J when every k is 1) instead
of r^t r; its gradient is still -2 B^t r, so the optimiser needs no change and no new solves. The
restricted degrees of freedom c_g the profile uses are taken at the optimum (``anchored``).
A misfit without estimated scales takes exactly the code path it always took.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Mapping, Sequence

import numpy as np
import scipy.linalg as sla

from geoback.case import covariance as cov
from geoback.inference import scales as sc
from geoback.errors import GeobackError
from geoback.observation.instruments import InstrumentBlock, Reading
from geoback.inference.parameters import ParameterSet, resolve
from geoback.physics.simulation import Simulation, is_constant

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
        C.setflags(write=False)
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
        """A draw from N(0, C_x): every instrument's readings with its own covariance (eqn 10),
        block by block in survey order (``block_noise``)."""
        return scale * np.concatenate([block_noise(b, rng, self.covariance[rows, rows])
                                       for b, rows in self.block_rows()])

    def with_measured(self, measured: np.ndarray) -> "Data":
        """The same instruments and covariance with other readings; the covariance's factors, a
        function of the (unchanged, read-only) covariance alone, are shared."""
        measured = np.asarray(measured, float).copy()
        if measured.shape != (self.m,):
            raise ValueError(f"expected {self.m} readings, found {measured.shape}")
        measured.setflags(write=False)
        new = replace(self, measured=measured)
        object.__setattr__(new, "_factors", self._factors)
        return new

    @cached_property
    def _factors(self) -> dict:
        return {}

    def factor(self, weighting: str) -> np.ndarray:
        """L with L L^t = C_x (``weighting_factor``), factorised once per weighting (read-only)."""
        if weighting not in self._factors:
            L = weighting_factor(self, weighting)
            L.setflags(write=False)
            self._factors[weighting] = L
        return self._factors[weighting]


def weighting_factor(data: Data, weighting: str) -> np.ndarray:
    """Lower-triangular L with L L^t the covariance used in J: C_x (full, eqn 9), its diagonal,
    or I (eqn 8). Factorised block by block, so a bad block is named."""
    if weighting not in WEIGHTINGS:
        raise GeobackError(f"weighting must be one of {', '.join(WEIGHTINGS)}, not '{weighting}'")
    if weighting == "identity":
        return np.eye(data.m)
    if weighting == "diagonal":
        return np.diag(np.sqrt(np.diag(data.covariance)))
    factors = [block_factor(b, data.covariance[rows, rows]) for b, rows in data.block_rows()]
    return sla.block_diag(*factors)


# ---------------------------------------------------------------------- one instrument's covariance factor
def block_factor(block: InstrumentBlock, covariance: np.ndarray | None = None) -> np.ndarray:
    """Lower-triangular L_i with L_i L_i^t = C_x,i, one instrument's covariance (eqns 10-20): the
    block's own, or `covariance` (its C_x with identified constants removed, as ``Data`` holds it).
    By ``cholesky_factor``, which names the block when C_x,i is not positive definite."""
    return cov.cholesky_factor(block.covariance if covariance is None else covariance, block.name)


def whiten_block(block: InstrumentBlock, v: np.ndarray, covariance: np.ndarray | None = None) -> np.ndarray:
    """L_i^-1 v for one instrument's readings outside the survey (a candidate instrument, or one
    instrument's rows of the data): v is a vector of its readings (r' = L_i^-1 r) or a matrix whose
    rows are its readings (A_c' = L_i^-1 A_c), whitened as ``Misfit.whiten`` whitens the survey's."""
    return solve_lower(np.asfortranarray(block_factor(block, covariance)), np.asarray(v, float))


def block_noise(block: InstrumentBlock, rng: np.random.Generator, covariance: np.ndarray | None = None) -> np.ndarray:
    """A draw from N(0, C_x,i) for one instrument's readings (eqn 10): L_i z with z =
    rng.standard_normal(block.m), L_i from ``block_factor`` (so a seed gives the same readings
    wherever noise is drawn: ``Data.noise``, ``synthetic_readings``)."""
    return block_factor(block, covariance) @ rng.standard_normal(block.m)


def solve_lower(Lf: np.ndarray, v: np.ndarray) -> np.ndarray:
    """L^-1 v for a lower-triangular L (Fortran order) and v a vector or the columns of a matrix,
    by LAPACK's triangular solve called directly (scipy's wrapper costs ten times the solve on small
    systems), column by column (BLAS's multi-right-hand-side solve spends ~1 ms starting threads on
    small ones)."""
    if v.ndim == 1:
        x, info = _trtrs(Lf, v, lower=1)
        return x
    out = np.empty(v.shape)
    for j in range(v.shape[1]):
        out[:, j] = _trtrs(Lf, v[:, j], lower=1)[0]
    return out


@dataclass(frozen=True)
class Evaluation:
    """The misfit at p: computed readings x, their sensitivity A (physical units, None unless
    asked), and the residual vector r = [L^-1 (x* - x); sqrt(C_p0^-1) (p0 - p)] with its Jacobian
    B = -dr/dp = [L^-1 A; sqrt(C_p0^-1)] (rows of parameters with a prior only). J = r^t r.

    With estimated error scales the data rows are whitened by the estimated scales as well and J
    is the profiled objective S* (``objective``; see scales.py), whose gradient is still -2 B^t r."""

    p: np.ndarray
    x: np.ndarray
    A: np.ndarray | None
    r: np.ndarray
    B: np.ndarray | None
    m: int  # data rows of r (the rest are prior rows)
    objective: float | None = None  # S*(p) when error scales are estimated
    scales: sc.ScaleState | None = None  # the scales profiled at p (None: every scale known)
    groups: tuple = ()  # the misfit's scale groups (one known group per instrument by default)

    @property
    def J(self) -> float:
        return float(self.r @ self.r) if self.objective is None else self.objective

    @property
    def support(self) -> float:
        """-2 ln L minus its constants (ln|C_x stated| + m ln 2 pi), maximised over the scales by
        maximum likelihood (c_g = m_g): J itself when every scale is known. For likelihood ratios."""
        if self.scales is None:
            return self.J
        prior = self.r[self.m:]
        return self.scales.support + float(prior @ prior)

    @property
    def stated_residual(self) -> np.ndarray:
        """The data residual whitened by the stated C_x (whatever the scales)."""
        if self.scales is None:
            return self.r[:self.m]
        return self.r[:self.m] * np.exp(self.scales.row_u / 2)

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


@dataclass(frozen=True, eq=False)
class Misfit:
    """Readings, covariance and priors of a case against a simulation (see the module docstring).

    A frozen value: every derived quantity (the factor L of the covariance used in J, its
    log-determinant, the prior rows) is computed from the fields on first use, so a misfit derived
    with ``dataclasses.replace`` (``with_measured``, ``with_fixed_scales``, ``with_scale_dof``,
    ``holding``, ...) can never carry another one's factor.

    Fields: ``simulation``; ``data`` (x*, C_x); ``parameters``; ``base_values``, the named values
    the parameters are set into (case values, extensions' null values, fixed extra values);
    ``weighting``, 'full' (C_x of eqn 9), 'diagonal' or 'identity' (eqn 8); ``scales``, the error
    scale groups (eqn 10; default one known group per instrument); ``scale_dof``, their restricted
    degrees of freedom c_g; ``row_u``, a fixed log variance factor u per reading (C_x = stated C_x
    times e^u, every scale known; None: none); ``held``, the whitened prior residuals of parameters
    held fixed (profiles), constant rows of r.
    """

    simulation: Simulation
    data: Data
    parameters: ParameterSet
    base_values: Mapping
    weighting: str = "full"
    scales: tuple = ()
    scale_dof: np.ndarray | None = None
    row_u: np.ndarray | None = None
    held: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self):
        if self.data.measured is None:
            raise GeobackError("the case has instruments without readings: give 'readings' or 'readings_file' "
                               "for every instrument to identify parameters")
        if self.weighting not in WEIGHTINGS:
            raise GeobackError(f"weighting must be one of {', '.join(WEIGHTINGS)}, not '{self.weighting}'")
        set_ = object.__setattr__
        set_(self, "base_values", dict(self.base_values))
        set_(self, "scales", tuple(self.scales) if self.scales else sc.default_groups(self.data.blocks))
        set_(self, "scale_dof", np.asarray(self.scale_dof, float).copy() if self.scale_dof is not None
             else sc.initial_dof(self.scales, self.parameters.n))
        if self.row_u is not None:
            row_u = np.asarray(self.row_u, float).copy()
            if row_u.shape != (self.data.m,):
                raise ValueError(f"expected one log variance factor per reading ({self.data.m}), found {row_u.shape}")
            set_(self, "row_u", row_u)
        set_(self, "held", np.asarray(self.held, float).copy())

    # ------------------------------------------------------------------ derived from the fields
    @cached_property
    def L(self) -> np.ndarray:
        """Lower-triangular L with L L^t the covariance used in J (eqn 9, ``weighting_factor``), each
        row scaled by e^(u/2) where ``row_u`` fixes the readings' variance factors."""
        L = self.data.factor(self.weighting)
        return L if self.row_u is None else L * np.exp(self.row_u / 2)[:, None]

    @cached_property
    def _Lf(self) -> np.ndarray:
        return np.asfortranarray(self.L)

    @cached_property
    def logdet(self) -> float:
        """ln |L L^t|."""
        return 2.0 * float(np.sum(np.log(np.abs(np.diag(self.L)))))

    @cached_property
    def free(self) -> bool:
        """Whether any error scale is estimated."""
        return any(g.estimated for g in self.scales)

    @cached_property
    def _prior_index(self) -> np.ndarray:
        return np.flatnonzero(self.parameters.has_prior)

    @cached_property
    def _prior_sqrt(self) -> np.ndarray:
        return np.sqrt(self.parameters.prior_precision()[self.parameters.has_prior])

    @cached_property
    def _prior_rows(self) -> np.ndarray:
        rows = np.zeros((len(self._prior_index), self.parameters.n))
        rows[np.arange(len(self._prior_index)), self._prior_index] = self._prior_sqrt
        return rows

    # ------------------------------------------------------------------ the one place that whitens
    def whiten(self, v: np.ndarray) -> np.ndarray:
        """L^-1 v (v: a vector or the columns of a matrix of readings; ``solve_lower``). An
        instrument outside the survey (a candidate) is whitened by ``whiten_block``."""
        return solve_lower(self._Lf, v)

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
        prior_r = np.concatenate([prior_r, self.held])  # held parameters' priors: constant rows
        prior_rows = self._prior_rows if not len(self.held) else \
            np.vstack([self._prior_rows, np.zeros((len(self.held), self.n))])
        if not self.free:
            r = np.concatenate([self.whiten(self.data.measured - pred.x), prior_r])
            B = np.vstack([self.whiten(pred.A), prior_rows]) if jacobian else None
            return Evaluation(p, pred.x, pred.A, r, B, self.m, groups=self.scales)
        # error scales profiled at p (closed form), each group's rows re-weighted by its scale
        rw = self.whiten(self.data.measured - pred.x)
        state = sc.profile_state(self.scales, rw, self.scale_dof)
        w = np.exp(-state.row_u / 2)
        r = np.concatenate([rw * w, prior_r])
        B = np.vstack([self.whiten(pred.A) * w[:, None], prior_rows]) if jacobian else None
        return Evaluation(p, pred.x, pred.A, r, B, self.m, state.objective + float(prior_r @ prior_r), state,
                          self.scales)

    def J(self, p: np.ndarray) -> float:
        return self.evaluate(p).J

    # ------------------------------------------------------------------ error scales
    def anchored(self, p: np.ndarray, rtol: float = 1e-6) -> "Misfit":
        """The misfit with the error scales' restricted degrees of freedom c_g = m_g - h_g taken at
        p (h_g: the group's leverage with the scales estimated there; a fixed point, computed
        without solves from the sensitivity at p). Returns itself when nothing is estimated or
        when its c already agrees within rtol: the optimiser refits until it does."""
        if not self.free:
            return self
        c = self._restricted_dof(np.asarray(p, float))
        if np.max(np.abs(c - self.scale_dof)) <= rtol * max(1.0, float(np.max(c))):
            return self
        return self.with_scale_dof(c)

    def _restricted_dof(self, p: np.ndarray) -> np.ndarray:
        ev = self.evaluate(p, jacobian=True)
        back = np.exp(ev.scales.row_u / 2)
        rw, As = ev.r[:self.m] * back, ev.B[:self.m] * back[:, None]  # whitened by the stated C_x
        m_g = np.array([g.m for g in self.scales], float)
        c = self.scale_dof.copy()
        for _ in range(200):
            state = sc.profile_state(self.scales, rw, np.maximum(c, 1e-9))
            w = np.exp(-state.row_u / 2)
            h = sc.leverage_by_group(self.scales, np.vstack([As * w[:, None], self._prior_rows]), self.m)
            c_new = m_g - h
            done = np.max(np.abs(c_new - c)) <= 1e-12 * max(1.0, float(np.max(m_g)))
            c = c_new
            if done:
                break
        for k, g in enumerate(self.scales):
            if g.kind == "free" and c[k] < sc.MIN_DOF:
                raise self._scale_error(g, f"expected readings left over by the parameters to estimate the scale of "
                                           f"'{g.name}', found {g.m} reading{'s' if g.m != 1 else ''} of which the "
                                           f"parameters take up {g.m - c[k]:.2g} (at least {sc.MIN_DOF:g} must "
                                           f"remain): give it a prior, group it with another instrument or make it known")
        return c

    def _scale_error(self, group, message: str) -> GeobackError:
        loaded = getattr(self.simulation, "loaded", None)
        if loaded is not None and group.at is not None and hasattr(loaded, "error"):
            return loaded.error(group.at, message)
        return GeobackError(f"error scale '{group.name}': {message}")

    def with_scale_dof(self, c: np.ndarray) -> "Misfit":
        """The same misfit with the error scales' restricted degrees of freedom set to c."""
        return replace(self, scale_dof=np.asarray(c, float))

    def scales_at(self, p: np.ndarray) -> np.ndarray | None:
        """The estimated log variance factor u = ln k^2 of every reading at p (restricted dof taken
        at p); None when every scale is known."""
        if not self.free:
            return None
        return self.anchored(p).evaluate(p).scales.row_u

    def with_fixed_scales(self, row_u: np.ndarray | None) -> "Misfit":
        """A misfit whose readings' covariance is the stated one times e^u per reading, every scale
        known: `diagnose` scores hypotheses with the scales held at their estimates under the null."""
        if row_u is None:
            return self
        u = np.asarray(row_u, float) + (self.row_u if self.row_u is not None else 0.0)
        return replace(self, row_u=u, scales=tuple(replace(g, kind="known") for g in self.scales))

    # ------------------------------------------------------------------ derived misfits
    def with_measured(self, measured: np.ndarray) -> "Misfit":
        """The same misfit for other readings (Monte Carlo replicates, study data)."""
        return replace(self, data=self.data.with_measured(measured))

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
        held = [] if not params.has_prior[index] else \
            [(params.prior_mean[index] - value) / params.prior_std[index]]
        return Misfit(self.simulation, self.data, sub, base, self.weighting, self.scales, row_u=self.row_u,
                      held=np.concatenate([self.held, held]))

    def with_weighting(self, weighting: str) -> "Misfit":
        return Misfit(self.simulation, self.data, self.parameters, self.base_values, weighting, self.scales,
                      row_u=self.row_u)

    def extended(self, specs: Sequence, values: Mapping | None = None, simulation: Simulation | None = None,
                 start: np.ndarray | None = None) -> "Misfit":
        """A misfit with more parameters (`specs`, case Parameter models) and fixed `values`, on the
        same simulation (so its factorisations are shared) or on `simulation` (another mesh);
        the current parameters start from `start` (default: their initial values)."""
        simulation = simulation or self.simulation
        values = {**{k: v for k, v in self.base_values.items()}, **(values or {})}
        extra, base, _ = resolve(specs, simulation, values, clip_bounds=True)
        current = self.parameters if start is None else self.parameters.with_initial(start)
        params = current + extra
        constants = {n for n in params.names if is_constant(n)}
        data = self.data
        if constants != {n for n in self.parameters.names if is_constant(n)}:
            data = Data.build(self.data.blocks, self.data.measured, constants)
        return Misfit(simulation, data, params, base, self.weighting, self.scales, row_u=self.row_u)
