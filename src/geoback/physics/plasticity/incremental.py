"""Elastoplastic excavation: incremental-iterative forward solution and exact sensitivities.

The problem
-----------
Ground with Mohr-Coulomb parameters (:class:`~geoback.physics.plasticity.mohr_coulomb.Material`) at
every quadrature point, initial (geostatic) stress sigma0 at every point (in equilibrium by
assumption), excavation load f = -int_S N^t sigma0 n dS (free dofs, ``FEModel.load``) released
by a factor lambda. With B the strain operator and sigma(u) the stress after the return mapping,

    R(u, lambda) = int B^t (sigma(u) - sigma0) dV - lambda f = 0,                          (1)

so that a linear-elastic ground gives K u = lambda f exactly. The load goes from lambda = 0 to
the last of the requested release fractions ``stages`` (lambda_1 < lambda_2 < ...), in
increments lambda_n; inside stage i an increment ends at lambda = lambda_{i-1} + s (lambda_i -
lambda_{i-1}), s in (0, 1] (the *schedule*). Each increment is solved by full Newton with the
consistent tangent K_t = int B^t C_alg B dV (C_alg = d sigma_{n+1} / d strain, non-symmetric
when psi != phi), starting with the tangent of the last converged state, until

    || R ||_2  <=  tol || lambda_{n+1} f ||_2          (tol = 1e-10 by default),           (2)

or, with ``floor``, until a residual below floor || lambda_{n+1} f || no longer halves (the rounding floor).

A Newton that fails (``max_iterations`` reached, residual not finite or growing 1e6-fold) is
retried with half the increment (adaptive schedule, or a fixed one with ``refine``) down to
``min_increment``; a fixed schedule without ``refine``, a too small increment or
``max_increments`` attempts raise :class:`NonConvergence`
naming the increment, lambda and the residual - never a silent result. After a quick
convergence (<= ``fast`` iterations) the next increment grows by ``growth``, up to
``max_increment`` (fractions of the final lambda). While the state is elastic, the ends of a fixed
schedule that an elastic step reaches with every point elastic are one increment (the response is
linear there, so the solution and its sensitivities are the same; ``schedule.elastic_reach``),
solved as that linear step, u += dlambda K_e^-1 f, without Newton (``_Problem.elastic_step``). The
residual (2) is measured against at least ``LAM_FLOOR`` of the full release: below it the rounding of
the in-situ stress' internal force exceeds tol |lambda f| (a first release of 1e-6 failed so). A
singular tangent is a failed Newton iteration (``linear.SingularMatrix``), as is a non-finite
stress. A run may start each increment's Newton iteration from an earlier run's solution of it
(``warm``: a simulation gives the last run carried to the new values by its sensitivities,
``Result.warm_du``); an ``observer`` sees every Newton iteration and converged increment (``Progress``: the
progress lines and the time limit of ``plastic.py``).

Direct differentiation (DDM)
----------------------------
(Michaleris, Tortorelli & Vidal 1994, Int. J. Numer. Meth. Eng. 37; Kleiber, Antunez, Hien &
Kowalczyk 1997, *Parameter Sensitivity in Nonlinear Mechanics*.) For a parameter p the caller
gives dMaterial/dp, d sigma0/dp, df/dp and d lambda_i/dp of the stages (e.g. lambda_i = beta t_i:
d lambda_i / d beta = t_i); increments inside a stage follow d lambda_n/dp = d lambda_{i-1}/dp +
s (d lambda_i/dp - d lambda_{i-1}/dp). The local update sigma_{n+1} = S(sigma_n, B(u_{n+1} -
u_n), m) gives

    d sigma_{n+1}/dp = C_alg B du_{n+1}/dp + e_{n+1},
    e_{n+1} = dS along (d sigma_n/dp, -B du_n/dp, dm/dp)   (u_{n+1} held fixed),           (3)

and differentiating (1) at the converged increment,

    K_t du_{n+1}/dp = d lambda_{n+1}/dp f + lambda_{n+1} df/dp - int B^t (e_{n+1} - d sigma0/dp) dV,   (4)

with K_t the consistent tangent at the converged state (factorised once there; it also serves
as the first Newton matrix of the next increment), so every parameter costs one
back-substitution per increment. A run without sensitivities does not factorise the converged
tangent: the last Newton matrix (the tangent one iterate earlier) starts the next increment. (Reaching
K_t by iterative refinement from the last Newton matrix instead was measured slower at 50 k DOFs:
PARDISO stalls at a relative residual of 3e-13 to 5e-13 after two or three refinement steps, and
three back-substitutions of four columns cost more than one factorisation; a run with four
sensitivities took 10.3-11.2 s that way against 9.4-10.1 s factorising K_t.) e_{n+1} is one
complex-step evaluation of the return mapping per parameter (exact to rounding); the history d sigma_n/dp starts at d sigma0/dp. The result
is the exact derivative of the discrete solution for the schedule used: finite differences
must replay that schedule (``Options(schedule=result.schedule)``).

Factorising only what yields
----------------------------
With PARDISO from ``condensed.CONDENSE_FROM`` unknowns up (``Options.condense``), every tangent is
factorised through ``condensed.Region``: the elastic part of the mesh is condensed once onto the dofs of
the elements that may yield, and each Newton step factorises only that region plus a dense interface
block (equations C1-C2 of ``condensed.py``). The linear algebra is the same, so Newton's iterates and
the sensitivities (4) are the same to rounding; a caller's ``region`` is kept from run to run.

A caller's ``region`` also keeps the run's two factorisations (the converged tangent's and the Newton
iteration's) from run to run, condensed or whole: the tangents of every run share one sparsity pattern,
so PARDISO analyses it once (phase 11, about three refactorisations at 2.4 k DOFs) instead of twice a run.

API
---
``solve(fe, material, sigma0, f, stages, derivatives=None, options=None, operators=None, warm=None)``

* ``fe``: :class:`~geoback.physics.fem.FEModel`; ``operators``: a :class:`PointOperators` of ``fe`` to
  reuse between runs (built if not given).
* ``material``: :class:`Material`, each field a scalar, (ne,) per element or (ne, nq) per point.
* ``sigma0``: (4,), (npts, 4) or (ne, nq, 4): (sxx, syy, szz, sxy), compression negative.
* ``f``: (nfree,) excavation load (``fe.load(sigma_v, sigma_h)`` at the wall points).
* ``stages``: increasing release fractions lambda_i > 0 where results are wanted.
* ``derivatives``: list of :class:`ParameterDerivative` (fields default to zero).
* ``options``: :class:`Options` (tolerance, increments, backend, fixed schedule).
* ``warm``: the ``Result.warm`` of an earlier run (same schedule) to start each increment from.
* ``region``: a ``condensed.Region`` kept by the caller from run to run (else one for the run): the region
  that may yield, its condensation and the run's factorisations.

Returns :class:`Result`: ``u`` (n_stages, nfree), ``du_dp`` (n_stages, nfree, n_params) or
None, ``sigma`` (n_stages, ne, nq, 4), ``plastic`` / ``yielded`` (n_stages, ne, nq) booleans
(yielding in the stage's last increment / at any increment so far), ``increments`` (log of
every Newton attempt with its residual history), ``schedule`` (to replay), ``counters``
(factorisations, back-substitutions, Newton iterations, increments, cutbacks, apex points, warm
starts, seconds by part), ``warm`` (every increment's solution), ``dsigma`` (d sigma/dp at the end,
(npts, 4, n_params), or None). Raises :class:`NonConvergence`
(a ``ForwardFailure``, itself a ``GeobackError``) or ``ValueError`` for
inputs of the wrong shape, non-increasing stages or an initial stress outside the yield surface.

Limits
------
Perfect plasticity with non-associated flow (psi < phi) can lose uniqueness of the incremental
problem (Hill 1958; Rudnicki & Rice 1975: shear bands). On fine meshes with little dilation the
tangent's eigenvalues of least real part approach zero and Newton cycles between patterns of
loading and unloading points (spiral bands around a tunnel): measured on the deep tunnel with
psi = 0 and wall elements of R/14 or finer (9.9 k and 18 k DOFs), at lambda = 0.83-0.93, while
R/10 elements converge (up to 12.8 k DOFs); psi = 10 deg converged at 18 k DOFs but needed 61
increments instead of 7. The run then stops with NonConvergence (see studies/plastic_convergence.py).
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from geoback.errors import ForwardFailure
from geoback.physics.plasticity import mohr_coulomb as mc
from geoback.physics.plasticity.condensed import CONDENSE_FROM, Region, keyed, pattern
from geoback.physics.plasticity.linear import LU, Counters, SingularMatrix
from geoback.physics.solver import available_backends
from geoback.physics.plasticity.schedule import Steps, elastic_reach
from geoback.physics.plasticity.mohr_coulomb import Material
from geoback.physics.plasticity.operators import PointOperators


NEAR = 0.5  # a region that may yield, when it grows, takes in the elements mobilising this much of their strength:
# measured at 50 k DOFs, a fresh run condensed 5 times with none (3.9 s), 3 times at 0.85, twice at 0.5 (3.4 s) and 0.3
LAM_FLOOR = 1e-3  # residuals are measured against at least this fraction of the full release: below it the
# rounding of the internal force of the in-situ stress (|sigma0| >> its increment) exceeds tol |lambda f|


class NonConvergence(ForwardFailure):
    """The global Newton failed; carries the increment number, lambda and the residual."""

    def __init__(self, increment: int, stage: int, lam_from: float, lam_to: float, residual: float,
                 iterations: int, reason: str, tol: float):
        self.increment, self.stage, self.lam, self.residual = increment, stage, lam_to, residual
        self.iterations, self.reason = iterations, reason
        self.counters = None  # the run's Counters, attached by solve()
        super().__init__(
            f"elastoplastic solution failed in increment {increment} (stage {stage}, lambda {lam_from:.6g} -> "
            f"{lam_to:.6g}): relative residual {residual:.3e} after {iterations} Newton iterations "
            f"(tolerance {tol:.1e}); {reason}")


@dataclass(frozen=True)
class Options:
    tol: float = 1e-10  # relative residual (2) at convergence
    max_iterations: int = 15
    first_increment: float = 0.1  # fractions of the final lambda
    max_increment: float = 0.2
    min_increment: float = 1e-4
    growth: float = 1.5
    fast: int = 4  # converged in at most this many iterations: the next increment grows
    max_increments: int = 400  # Newton attempts (converged or not) in the whole run
    schedule: tuple | None = None  # fixed: per stage, increasing fractions s in (0, 1], ending at 1
    refine: bool = False  # a fixed schedule's failed increment is halved (down to min_increment) instead of failing
    backend: str | None = None  # 'pardiso' | 'scipy' | None (plasticity.linear.default_backend)
    condense: bool | None = None  # factorise only the region that may yield (condensed.py); None: with PARDISO
    # from condensed.CONDENSE_FROM unknowns up
    floor: float | None = None  # a residual (2) below this that no longer halves in an iteration counts as converged:
    # the rounding floor, for a tolerance asked below it (a replay for finite differences: Newton then goes to the
    # floor, wherever that is, instead of stopping anywhere below a looser tolerance)


@dataclass
class ParameterDerivative:
    """Derivatives of the inputs with respect to one parameter p (all zero unless given).

    Material fields: scalar, (ne,) or (ne, nq); sigma0: (4,), (npts, 4) or (ne, nq, 4);
    f: (nfree,); stages: scalar or (n_stages,) = d lambda_i / dp."""

    name: str
    E: object = 0.0
    nu: object = 0.0
    c: object = 0.0
    phi: object = 0.0
    psi: object = 0.0
    tension: object = 0.0
    sigma0: object = 0.0
    f: object = 0.0
    stages: object = 0.0
    springs: object = None  # d K_s / dp (nfree x nfree, sparse) where ``solve(springs=...)`` depends on p


@dataclass
class IncrementLog:
    number: int  # converged increments before it + 1
    stage: int  # 1-based
    lam: float  # lambda at its end
    dlam: float
    residuals: list  # relative residual (2) after each Newton solve
    converged: bool
    plastic_points: int = 0
    reason: str = ""


@dataclass
class Result:
    stages: np.ndarray  # lambda_i (n_stages,)
    u: np.ndarray  # (n_stages, nfree) displacements caused by the excavation
    du_dp: np.ndarray | None  # (n_stages, nfree, n_params), parameters in the order of `names`
    names: list  # parameter names (ParameterDerivative.name)
    sigma: np.ndarray  # (n_stages, ne, nq, 4) total stress (sxx, syy, szz, sxy)
    plastic: np.ndarray  # (n_stages, ne, nq) yielding in the stage's last increment
    yielded: np.ndarray  # (n_stages, ne, nq) yielded in some increment up to the stage
    increments: list  # IncrementLog of every Newton attempt, converged or not
    schedule: tuple  # per stage, the fractions s where increments ended (Options(schedule=...) replays)
    counters: Counters
    tol: float
    warm: dict = field(default_factory=dict)  # (stage index, s) -> u at the end of every converged increment
    dsigma: np.ndarray | None = None  # (npts, 4, n_params) d sigma/dp at the end of the last stage (the history (3)
    # a later computation continues from: element removal in stages, ``excavation_plastic.py``)
    warm_du: dict = field(default_factory=dict)  # (stage index, s) -> du/dp (nfree, n_params) at every converged
    # increment, with derivatives: a run at values p + dp starts there from warm + warm_du dp (first order)

    def converged_residuals(self) -> np.ndarray:
        """Final relative residual of every converged increment."""
        return np.array([log.residuals[-1] for log in self.increments if log.converged])


# ---------------------------------------------------------------------------------- inputs
def _material(material: Material, ops: PointOperators, name="material") -> Material:
    return Material(*(ops.per_point(v, f"{name}.{n}") for n, v in zip(Material.names(), material.values())))


def _stress(sigma, ops: PointOperators, name="sigma0") -> np.ndarray:
    s = np.asarray(sigma, float)
    if s.ndim == 0 and s == 0:
        return np.zeros((ops.npts, 4))
    if s.shape == (4,):
        return np.tile(s, (ops.npts, 1))
    if s.shape in ((ops.npts, 4), (ops.ne, ops.nq, 4)):
        return s.reshape(ops.npts, 4).copy()
    raise ValueError(f"{name}: expected (4,), ({ops.npts}, 4) or ({ops.ne}, {ops.nq}, 4), found {s.shape}")


@dataclass
class _Derivatives:
    names: list
    material: list  # Material per parameter, (npts,) fields
    sigma0: np.ndarray  # (npts, 4, P)
    f: np.ndarray  # (nfree, P)
    stages: np.ndarray  # (n_stages, P)
    springs: list = None  # d K_s / dp per parameter (None: K_s does not depend on it)


def _derivatives(derivs, ops, n_stages) -> _Derivatives | None:
    if not derivs:
        return None
    P = len(derivs)
    mats, s0 = [], np.zeros((ops.npts, 4, P))
    f = np.zeros((ops.nfree, P))
    st = np.zeros((n_stages, P))
    for j, d in enumerate(derivs):
        mats.append(Material(*(ops.per_point(getattr(d, n), f"d{n}/d{d.name}") for n in Material.names())))
        s0[:, :, j] = _stress(d.sigma0, ops, f"dsigma0/d{d.name}")
        fj = np.asarray(d.f, float)
        if fj.ndim == 0:
            if fj != 0:
                raise ValueError(f"df/d{d.name}: expected a vector of {ops.nfree} free dofs")
        elif fj.shape == (ops.nfree,):
            f[:, j] = fj
        else:
            raise ValueError(f"df/d{d.name}: expected shape ({ops.nfree},), found {fj.shape}")
        sj = np.asarray(d.stages, float)
        if sj.ndim > 0 and sj.shape != (n_stages,):
            raise ValueError(f"dstages/d{d.name}: expected a scalar or {n_stages} values, found {sj.shape}")
        st[:, j] = sj
    return _Derivatives([d.name for d in derivs], mats, s0, f, st, [d.springs for d in derivs])


# ---------------------------------------------------------------------------------- solver
@dataclass
class _State:
    u: np.ndarray
    sigma: np.ndarray
    lam: float
    du: np.ndarray | None = None  # (nfree, P)
    dsigma: np.ndarray | None = None  # (npts, 4, P)
    dlam: np.ndarray | None = None  # (P,)
    dstrain: np.ndarray | None = None  # (npts, 3, P): the strain of du (made with d sigma; the next increment's)


@dataclass
class _Converged:
    u: np.ndarray
    sigma: np.ndarray
    deps: np.ndarray
    mode: np.ndarray
    C: np.ndarray
    residuals: list = field(default_factory=list)
    refactorised: bool = False  # the last correction used a tangent factorised in this increment (in `work`)


class _Failed(Exception):
    def __init__(self, residuals, reason):
        self.residuals, self.reason = residuals, reason


class _Problem:
    def __init__(self, ops, mat, sigma0, f, opts, counters, f_before=None, springs=None):
        self.ops, self.mat, self.sigma0, self.f, self.opts, self.counters = ops, mat, sigma0, f, opts, counters
        self.f_norm = np.linalg.norm(f)
        self.f_before = f_before  # the load released before this run (only what (2) is measured against)
        self.springs = springs  # K_s: linear springs between dofs (props, anchors), or None
        self._w = None  # K_e^-1 f and its strain, once asked (elastic_response)
        with counters.timed("assemble tangent"):
            self.Ke_elastic = ops.element_matrices(mc.elastic_matrix(mat))
            self.K_ground = ops.assemble(self.Ke_elastic)
            if springs is not None:  # every tangent plus K_s on one pattern (_with_springs)
                self._union = _union_pattern(self.K_ground, springs)
            self.K_elastic = self._with_springs(self.K_ground)

    def _with_springs(self, K):
        """K + K_s on one pattern for every K of the ground's pattern (a sparse sum would drop entries that cancel,
        and the condensed factorisation reads every tangent on the elastic stiffness' pattern)."""
        if self.springs is None:
            return K
        (indptr, indices), at_K, at_S, S = self._union
        if not K.has_sorted_indices:
            K.sort_indices()
        data = np.zeros(len(indices))
        data[at_K] = K.data
        data[at_S] += S.data
        return sp.csr_matrix((data, indices, indptr), shape=K.shape)

    def residual(self, sigma, lam, u):
        """(2) with the springs' force K_s u (u: this run's displacement)."""
        with self.counters.timed("internal force"):
            r = self.ops.internal_force(sigma - self.sigma0) - lam * self.f
            return r if self.springs is None else r + self.springs @ u

    def tangent(self, C, mode):
        """Consistent tangent: the elastic stiffness, corrected on the elements with plastic points;
        and those elements."""
        with self.counters.timed("assemble tangent"):
            plastic = np.flatnonzero((mode != mc.ELASTIC).reshape(self.ops.ne, self.ops.nq).any(axis=1))
            if not len(plastic):
                return self.K_elastic, plastic
            Ke = self.ops.element_matrices(C, plastic) - self.Ke_elastic[plastic]
            return self._with_springs(self.ops.assemble(Ke, plastic, base=self.K_ground.data)), plastic

    def near_yield(self, sigma) -> np.ndarray:
        """Elements with a point mobilising NEAR of its strength or more (a region that may yield grows to them)."""
        rho = mc.mobilised(sigma, self.mat).reshape(self.ops.ne, self.ops.nq)
        return np.flatnonzero((rho >= NEAR).any(axis=1))

    def elastic_response(self, elastic: LU) -> tuple[np.ndarray, np.ndarray]:
        """w = K_e^-1 f and its strain at every point (one back-substitution a run)."""
        if self._w is None:
            w = elastic.solve(self.f)
            self._w = (w, self.ops.strain(w))
        return self._w

    def reference(self, lam: float) -> float:
        """What the residual (2) is measured against: |lambda| ||f||, at least LAM_FLOOR ||f||; after a
        load f_before released by earlier runs (``solve(f_before=...)``), ||f_before + lambda f||, at least
        LAM_FLOOR ||f_before + f||: the whole load released so far, as in one run."""
        if self.f_before is None:
            return max(abs(lam), LAM_FLOOR) * self.f_norm
        return max(np.linalg.norm(self.f_before + lam * self.f), LAM_FLOOR * np.linalg.norm(self.f_before + self.f))

    def elastic_step(self, state: _State, lam: float, elastic: LU) -> _Converged | None:
        """The increment state.lam -> lam as one linear step u += (lam - state.lam) K_e^-1 f, for an
        end every point reaches elastically (``schedule.elastic_reach``): exact, no Newton iteration
        (whose residual test would be at the mercy of rounding: the internal force of the in-situ
        stress against a tiny release). None if a point is not elastic after all."""
        w, w_strain = self.elastic_response(elastic)
        dlam = lam - state.lam
        with self.counters.timed("return mapping and tangent"):
            deps = dlam * w_strain
            sigma, C, mode = mc.update_with_tangent(state.sigma, deps, self.mat)
        if np.any(mode != mc.ELASTIC):
            return None
        u = state.u + dlam * w
        rel = float(np.linalg.norm(self.residual(sigma, lam, u)) / self.reference(lam))
        self.counters.elastic_steps += 1
        return _Converged(u, sigma, deps, mode, C, [rel], False)

    def newton(self, state: _State, lam: float, first: LU, work: LU, start: np.ndarray | None = None,
               observer=None) -> _Converged:
        """Full Newton for the increment state.lam -> lam; the first correction with `first`
        (the converged tangent of the previous state), the next ones refactorise into `work`. It
        starts from the previous state, or from `start` (an earlier run's solution of this
        increment) when the residual is smaller there. `observer(iteration, residual)` is called
        after every iteration."""
        ops, opts = self.ops, self.opts
        ref = self.reference(lam)
        r = self.residual(state.sigma, lam, state.u)
        u = state.u.copy()
        lu = first
        residuals = []
        if start is not None:
            with self.counters.timed("return mapping and tangent"):
                deps = ops.strain(start - state.u)
                sigma, mode = mc.update(state.sigma, deps, self.mat)
            r_start = self.residual(sigma, lam, start)
            if np.linalg.norm(r_start) < np.linalg.norm(r):
                self.counters.warm_starts += 1
                u, r = start.copy(), r_start
                rel = float(np.linalg.norm(r) / ref)
                if rel <= opts.tol:  # the same increment solved before
                    C = mc.consistent_tangent(state.sigma, deps, self.mat, mode)
                    return _Converged(u, sigma, deps, mode, C, [rel], False)
        for it in range(1, opts.max_iterations + 1):
            try:
                u += lu.solve(-r, correction=True)
            except SingularMatrix as exc:
                raise _Failed(residuals, str(exc)) from None
            self.counters.newton_iterations += 1
            with self.counters.timed("return mapping and tangent"):
                deps = ops.strain(u - state.u)
                sigma, C, mode = mc.update_with_tangent(state.sigma, deps, self.mat)
            r = self.residual(sigma, lam, u)
            rel = float(np.linalg.norm(r) / ref)
            residuals.append(rel)
            if observer is not None:
                observer(it, rel)
            if not np.isfinite(rel):
                raise _Failed(residuals, "residual not finite")
            if rel <= opts.tol or (opts.floor is not None and rel <= opts.floor and it > 1
                                   and rel > 0.5 * residuals[-2]):  # (at the rounding floor: it no longer falls)
                return _Converged(u, sigma, deps, mode, C, residuals, lu is work)
            if rel > 1e6 * residuals[0] and it > 1:
                raise _Failed(residuals, "residual grew a million-fold")
            if it == opts.max_iterations:
                break
            try:
                lu = work.factorise(*self.tangent(C, mode), near=lambda: self.near_yield(sigma))
            except SingularMatrix as exc:
                raise _Failed(residuals, str(exc)) from None
        raise _Failed(residuals, f"no convergence in {opts.max_iterations} iterations")


def _check(ops: PointOperators, material, sigma0, f, stages, opts: Options):
    mat = _material(material, ops)
    sig0 = _stress(sigma0, ops)
    f = np.asarray(f, float)
    if f.shape != (ops.nfree,):
        raise ValueError(f"f: expected shape ({ops.nfree},), found {f.shape}")
    if not np.any(f):
        raise ValueError("f is zero: nothing to release")
    stages = np.atleast_1d(np.asarray(stages, float))
    if stages[0] <= 0 or np.any(np.diff(stages) <= 0):
        raise ValueError(f"stages must be increasing release fractions > 0, found {stages.tolist()}")
    if opts.schedule is not None and len(opts.schedule) != len(stages):
        raise ValueError(f"schedule has {len(opts.schedule)} stages, stages has {len(stages)}")
    fy, ft = mc.yield_functions(sig0, mat)
    scale = np.abs(sig0).max(axis=1) + np.abs(mat.c)
    outside = (fy > 1e-9 * scale) | (ft > 1e-9 * scale)
    if outside.any():
        raise ValueError(f"the initial stress violates the yield condition at {int(outside.sum())} of "
                         f"{ops.npts} quadrature points")
    return mat, sig0, f, stages


@dataclass(frozen=True)
class Progress:
    """Where a run is, for an observer (``solve(observer=...)``): after every Newton iteration
    (`iteration` >= 1, its relative residual) and after every converged increment (`converged`)."""

    stage: int  # 1-based
    stages: int
    increment: int  # the attempt's number: converged increments before it + 1
    lam: float  # lambda at the increment's end
    iteration: int
    residual: float
    converged: bool = False
    cutbacks: int = 0  # increments halved so far in the run


def solve(fe, material: Material, sigma0, f, stages, derivatives: list | None = None,
          options: Options | None = None, operators: PointOperators | None = None,
          warm: dict | None = None, observer=None, f_before: np.ndarray | None = None, springs=None,
          region: Region | None = None) -> Result:
    """Release f in increments up to each of `stages`; see the module docstring. `f_before`: a load
    (nfree,) released before this run from a state of which sigma0 is the stress (a stage of a longer
    construction): the residual (2) is then measured against ||f_before + lambda f||. `warm`: the
    ``Result.warm`` of an earlier run at nearby values (same schedule): each increment's Newton
    iteration starts from that run's solution of it when its residual is smaller there.
    `observer(Progress)`: called after every Newton iteration and converged increment (progress
    lines, a time limit: an exception it raises ends the run). `springs`: K_s (nfree x nfree, symmetric,
    sparse), linear springs acting with the ground (props, anchors): (2) becomes
    F(sigma - sigma_0) + K_s u = lambda f, the tangent K_t + K_s, and (4) gains -dK_s/dp u on its right
    (``ParameterDerivative.springs``)."""
    opts = options or Options()
    ops = operators or PointOperators(fe)
    counters = Counters()
    mat, sig0, f, stages = _check(ops, material, sigma0, f, stages, opts)
    der = _derivatives(derivatives, ops, len(stages))
    if f_before is not None and np.shape(f_before) != (ops.nfree,):
        raise ValueError(f"f_before: expected shape ({ops.nfree},), found {np.shape(f_before)}")
    if springs is not None and np.shape(springs) != (ops.nfree, ops.nfree):
        raise ValueError(f"springs: expected shape ({ops.nfree}, {ops.nfree}), found {np.shape(springs)}")
    problem = _Problem(ops, mat, sig0, f, opts, counters, f_before, springs)
    own_region = region is None
    state = _State(np.zeros(ops.nfree), sig0.copy(), 0.0)
    if der is not None:
        P = len(der.names)
        state.du, state.dsigma, state.dlam = np.zeros((ops.nfree, P)), der.sigma0.copy(), np.zeros(P)
    condense = _condensing(ops, opts)
    if region is None:
        region = Region(ops.element_dofs(), ops.nfree)
    if condense:
        region.start(problem.K_elastic, counters)
    conv, work = region.factors(counters, opts.backend, condense)
    conv.factorise(problem.K_elastic)
    conv_elastic = True  # conv holds the elastic stiffness
    steps = Steps(opts, stages[-1])
    out = dict(u=[], du=[], sigma=[], plastic=[], yielded=[])
    yielded = np.zeros(ops.npts, bool)
    mode = np.zeros(ops.npts, int)
    logs, schedule = [], []
    solved = {}  # (stage, s) -> u of every converged increment, to warm-start a later run
    solved_du = {}  # (stage, s) -> du/dp there (with derivatives): a later run's start u + du/dp dp
    try:
        lam_a, dlam_a = 0.0, (np.zeros(len(der.names)) if der else None)
        for i, lam_b in enumerate(stages):
            steps.stage(i, lam_a, lam_b)
            s = 0.0
            while s < 1.0:
                # a fixed schedule's ends an elastic step reaches: one increment, solved exactly without Newton
                reach = conv_elastic and elastic_reach(problem, state, steps, conv)
                s_new = steps.next(s)
                lam = steps.lam(s_new)
                number = counters.increments + 1
                watch = None
                if observer is not None:
                    def watch(it, rel, _i=i, _n=number, _lam=lam):
                        observer(Progress(_i + 1, len(stages), _n, _lam, it, rel, False, counters.cutbacks))

                def failure(reason, residuals):
                    last = residuals[-1] if residuals else np.nan
                    return NonConvergence(number, i + 1, state.lam, lam, last, len(residuals), reason, opts.tol)

                if len(logs) >= opts.max_increments:
                    raise failure(f"budget of {opts.max_increments} Newton attempts exhausted", [])
                try:
                    res = problem.elastic_step(state, lam, conv) if reach else None
                    if res is None:
                        res = problem.newton(state, lam, conv, work, (warm or {}).get((i, s_new)), watch)
                except _Failed as fail:
                    logs.append(IncrementLog(number, i + 1, lam, lam - state.lam, fail.residuals, False,
                                             reason=fail.reason))
                    stop = steps.failed(lam - state.lam)
                    if stop:
                        raise failure(f"{fail.reason}; {stop}", fail.residuals) from None
                    counters.cutbacks += 1
                    continue
                counters.increments += 1
                mode = res.mode
                n_plastic = int(np.count_nonzero(mode))
                counters.apex_points += int(np.count_nonzero(mode == mc.APEX))
                logs.append(IncrementLog(number, i + 1, lam, lam - state.lam, res.residuals, True, n_plastic))
                if der is None and not (conv_elastic and n_plastic == 0):
                    if res.refactorised:  # no sensitivities: the last Newton matrix starts the next increment
                        conv, work = work, conv
                        conv_elastic = False
                elif not (conv_elastic and n_plastic == 0):
                    try:  # the tangent at the converged state: for the sensitivities and the next increment
                        conv.factorise(*problem.tangent(res.C, res.mode),
                                       near=lambda: problem.near_yield(res.sigma))
                    except SingularMatrix as exc:
                        raise failure(f"the tangent at the converged state is singular ({exc})",
                                      res.residuals) from None
                    conv_elastic = n_plastic == 0
                new = _State(res.u, res.sigma, lam)
                if der is not None:
                    new.dlam = dlam_a + s_new * (der.stages[i] - dlam_a)
                    try:
                        _sensitivities(problem, der, state, new, res, conv)
                    except SingularMatrix as exc:
                        raise failure(f"the tangent at the converged state is singular ({exc})",
                                      res.residuals) from None
                yielded |= mode != mc.ELASTIC
                solved[(i, s_new)] = res.u
                if der is not None:
                    solved_du[(i, s_new)] = new.du
                state, s = new, s_new
                steps.converged(s_new, len(res.residuals))
                if observer is not None:
                    observer(Progress(i + 1, len(stages), number, lam, len(res.residuals), res.residuals[-1], True,
                                      counters.cutbacks))
            schedule.append(tuple(steps.used))
            lam_a, dlam_a = lam_b, (der.stages[i] if der else None)
            out["u"].append(state.u.copy())
            out["sigma"].append(state.sigma.reshape(ops.ne, ops.nq, 4).copy())
            out["plastic"].append((mode != mc.ELASTIC).reshape(ops.ne, ops.nq))
            out["yielded"].append(yielded.reshape(ops.ne, ops.nq).copy())
            if der is not None:
                out["du"].append(state.du.copy())
    except NonConvergence as exc:
        exc.counters = counters  # what the failed run spent
        raise
    finally:
        region.close()
        if own_region:
            region.release()
    return Result(stages, np.array(out["u"]), np.array(out["du"]) if der else None, der.names if der else [],
                  np.array(out["sigma"]), np.array(out["plastic"]), np.array(out["yielded"]), logs,
                  tuple(schedule), counters, opts.tol, solved, state.dsigma if der else None, solved_du)


def _union_pattern(K: sp.csr_matrix, S: sp.csr_matrix):
    """The union of two CSR patterns (sorted): its (indptr, indices), where each matrix's entries go in it, and
    S with sorted indices."""
    def keys(M):
        M = sp.csr_matrix(M, copy=True)
        M.sort_indices()
        return keyed(np.repeat(np.arange(M.shape[0]), np.diff(M.indptr)), M.indices, M.shape[1]), M

    kK, _ = keys(K)
    kS, S = keys(S)
    union = np.union1d(kK, kS)
    return pattern(union, K.shape), np.searchsorted(union, kK), np.searchsorted(union, kS), S


def _condensing(ops: PointOperators, opts: Options) -> bool:
    """Whether a run factorises its tangents through a condensation (``condensed.py``), or whole
    (``Options.condense``; by default with PARDISO from ``CONDENSE_FROM`` unknowns up)."""
    asked = opts.backend or os.environ.get("GEOBACK_SOLVER") or "pardiso"  # SuperLU asked for: no PARDISO at all
    pardiso = "pardiso" in available_backends() and asked == "pardiso"
    wanted = opts.condense if opts.condense is not None else (pardiso and ops.nfree >= CONDENSE_FROM)
    if wanted and not pardiso:
        raise ValueError("condensing the elastic part needs the PARDISO backend")
    return bool(wanted)


def _sensitivities(problem: _Problem, der: _Derivatives, old: _State, new: _State, res: _Converged, lu: LU):
    """Eqns (3)-(4): du/dp and d sigma/dp at the converged increment old -> new, in place on new."""
    ops = problem.ops
    timed = problem.counters.timed
    with timed("sensitivities"):
        with timed("sensitivities: local derivatives and right-hand sides"):
            P = len(der.names)
            old_strain = old.dstrain if old.dstrain is not None else ops.strain(old.du)
            e = mc.directional_derivatives(old.sigma, res.deps, problem.mat, old.dsigma, -old_strain,
                                           der.material, res.mode)
            rhs = problem.f[:, None] * new.dlam[None, :] + new.lam * der.f - ops.internal_force(e - der.sigma0)
            for j, dK in enumerate(der.springs or ()):
                if dK is not None:
                    rhs[:, j] -= dK @ new.u
        new.du = lu.solve(rhs)
        with timed("sensitivities: stress history"):
            new.dstrain = ops.strain(new.du)
            new.dsigma = e + res.C @ new.dstrain  # (batched matmul: 7x einsum's speed at 75 k points)
