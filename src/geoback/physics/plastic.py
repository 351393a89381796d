"""Excavation in elastic-perfectly plastic (Mohr-Coulomb) ground: readings at every construction stage
and their exact sensitivities, behind the ``Simulation`` interface.

The case's values map to the inputs of the incremental solver (``plasticity.solve``): per element
E, nu (the ground's fields, extensions included: ``ground.Ground.fields``) and the strength c, phi,
psi, tension of its layer (``strength.py``; linear-elastic layers get a strength no stress reaches);
per quadrature point the geostatic stress sigma0 = (K0 sv, sv, K0 sv, 0), sv = -gamma depth
(compression negative, K0 from the ground's fields at the point); the excavation load of eqn 33,
f = -int_S N^t sigma0 n dS, from the same stresses at the wall points (times the extension 'beta'
if switched on); the release lambda_k = beta_k of every stage (``construction.StagePlan``: the
stress is released in increments up to beta_1, then beta_2, ...; one stage releasing all of it
without a construction section). The readings of stage k are x = P u_k (eqn 29), u_k the
displacement accumulated up to it.

Everything in that map is plain arithmetic that accepts complex numbers, so the derivative of the
inputs with respect to any named value is one complex step (exact to rounding); the solver turns
them into du_k/dv by direct differentiation of the incremental problem (``plasticity.incremental``,
eqns (3)-(4) there: one back-substitution per value and increment with the converged tangent).
Every sensitivity is the exact derivative of the discrete solution for the increments used.

Increments. A fixed schedule of ``INCREMENTS`` equal increments per unit of release (at least
``MIN_STAGE`` per stage), fixed for the simulation's lifetime from the case's release fractions,
so that x(v) is one smooth function of v for an optimiser (an adaptive schedule would change the
discrete model from one point to the next); an increment whose Newton iteration fails is halved
(down to 1e-4 of the release), and then that run's schedule differs. A run that still fails raises
``plasticity.NonConvergence`` (a ``ForwardFailure``: in a fit, the trial step is rejected).

One forward run gives x and A together: the last run is remembered, and a run asked for readings
only computes the sensitivities of the names asked last, as long as the requests alternate with
sensitivity requests (an optimiser asks for A at the point it has just accepted). Each increment's
Newton iteration starts from the last run's solution of that increment, carried to the new values to
first order by that run's sensitivities when it had them (u + du/dv dv), when the residual is smaller
there than at the previous converged state (warm start: an optimiser's next point is near its last;
measured at 50 k DOFs, 188 Newton iterations of an identification became 167); the converged
solution is the same to the Newton tolerance either way. The elastic part of the mesh, condensed onto
the region that may yield, is kept from run to run too (``plasticity.condensed.Region``).

The last run whose sensitivities were asked for is kept as well (an optimiser's accepted point: the
assessment and the outputs ask for it again after rejected trial points, and get it without a new
run, which could fail where this one converged). A run longer than ``FIRST_WORDS`` seconds says
where it is (stage k of n, increment, Newton iteration) every ``EVERY`` seconds through
``case.budget.say``, and stops with ``errors.TimeLimit`` where it is once the command's time limit
and its grace have passed (``Watch``, the engine's observer).

A probe (readings only, inside ``probing()``: the check of a linearised interval, the readings on a finer
mesh) is a question answered far coarser than Newton's tolerance: whether J rises by 3.84 within a
factor of two, or a difference of readings against 0.3 sigma. Its increments stop at ``PROBE_TOL``
(``Runs.options``); on ``cases/plastic-tunnel.yaml`` the probes' J moved by less than 2e-6 from
their values at 1e-10 (1e-5 gave 2e-5); the probes factorised 72 tangents instead of 100, the
finer mesh's run 17 instead of 20. A probe's run is not reused outside a probe.

Composition: the case's ``Domain`` (``domain.py``), the quadrature-point operators, and the last runs
with their warm start (``Runs``), shared with views on other instruments (``Simulation.surveying``:
nothing survey-dependent is cached, so a view reads the last run without a new one). Names are
resolved by ``Names`` over the plan, the strength and the ground. Not modelled: a lining on yielding
ground (refused by the case checks), cross-anisotropic elasticity.
"""
from __future__ import annotations

import contextlib
import copy
import time
from dataclasses import dataclass, replace
from typing import Mapping, Sequence

import numpy as np

from geoback.case import budget
from geoback.case.loading import LoadedCase
from geoback.errors import ForwardFailure, GeobackError
from geoback.physics.domain import build_domain
from geoback.physics.ground import COMPLEX_STEP
from geoback.observation.instruments import InstrumentBlock
from geoback.physics.mesh import Mesh
from geoback.physics.names import Names
from geoback.physics.plasticity.condensed import Region
from geoback.physics.plastic_zone import PlasticZone, equivalent_plastic_strain, measure
from geoback.physics.simulation import Field, Prediction, Simulation
from geoback.case.strength import INCREMENTS, MC_FIELDS, Strength, stage_increments

ANTICIPATE = 3  # readings-only runs after a sensitivity request that compute the sensitivities asked last
FIRST_WORDS = 3.0  # seconds a forward run goes before it says where it is (then every EVERY seconds)
EVERY = 5.0
PROBE_TOL = 1e-6  # Newton's relative residual (2) for a probe's increments (module docstring)
DEG = np.pi / 180
UNMODELLED = ("n", "m")  # extensions not available with yielding ground (cross-anisotropic elasticity)


_CONTROLLERS: dict = {}


def one_thread(pardiso: bool):
    """One thread for BLAS, MKL (PARDISO) and OpenMP during an elastoplastic run: its many
    factorisations, back-substitutions and point-wise updates gain little from a second thread and
    lose much when the cores are shared (measured at 17 k DOFs on two busy cores: a forward run in
    1.7 s with one thread, 3.9-8.2 s with two). `pardiso`: the run factorises with PARDISO (loaded
    first, so that its MKL threads are seen and limited too)."""
    if pardiso not in _CONTROLLERS:
        from threadpoolctl import ThreadpoolController

        if pardiso:
            from geoback.physics.solver import point_pypardiso_at_mkl

            point_pypardiso_at_mkl()
            import pypardiso  # noqa: F401
        _CONTROLLERS[pardiso] = ThreadpoolController()
    return _CONTROLLERS[pardiso].limit(limits=1)


@dataclass
class _Run:
    key: tuple
    names: tuple  # the values differentiated
    u: np.ndarray  # (nstages, nfree)
    du: np.ndarray | None  # (nstages, nfree, len(names))
    result: object  # plasticity.Result
    probe: bool = False  # solved to PROBE_TOL only: not reused outside a probe


class Runs:
    """The last run, the last run whose sensitivities were asked for (an optimiser's accepted point:
    asked for again after rejected trials, by the assessment and the outputs, and never solved
    twice), the warm start they offer, and the names asked last (``solution``)."""

    def __init__(self):
        self.run: _Run | None = None
        self.kept: _Run | None = None  # the last run whose sensitivities were asked for
        self.warm: dict | None = None  # the last run's increments, to start the next one from (plasticity.solve)
        self.base: tuple | None = None  # the last run with sensitivities: (values, names, warm, warm_du)
        self.wanted: tuple = ()
        self.plain_requests = 0
        self.probes = 0  # open ``probing()`` contexts: readings-only runs there differentiate nothing
        self.number = 0  # runs started (for progress lines)

    def predicted(self, values: Mapping) -> dict | None:
        """Starts for a run at `values`: the last run with sensitivities carried to `values` to first order
        (u + du/dv dv for the values it differentiated), else the last run's solution."""
        if self.base is None:
            return self.warm
        base, names, warm, warm_du = self.base
        if set(values) != set(base) or any(values[k] != v for k, v in base.items() if k not in names):
            return self.warm
        dv = np.array([float(np.real(values[n])) - float(np.real(base[n])) for n in names])
        return {key: u + warm_du[key] @ dv for key, u in warm.items() if key in warm_du}

    def remembered(self, key: tuple, wrt) -> _Run | None:
        for run in (self.run, self.kept):
            if (run is not None and run.key == key and set(wrt) <= set(run.names)
                    and (self.probes or not run.probe)):
                return run
        return None

    def options(self, options, names: Sequence[str]):
        """The solver's options for a run differentiating `names`: a probe's Newton stops at PROBE_TOL."""
        if self.probes and not names and options.tol < PROBE_TOL:
            return replace(options, tol=PROBE_TOL)
        return options

    def answer(self, values: Mapping, wrt: Sequence[str], compute) -> _Run:
        """The run at `values` with du/dv for `wrt`: a remembered one, or `compute(key, names)` (a new run
        differentiating `names`: those asked, or for a readings-only run shortly after a sensitivity
        request, those asked then). A run asked with sensitivities is kept."""
        key = tuple(sorted(values.items()))
        if wrt:
            self.wanted, self.plain_requests = tuple(wrt), 0
        run = self.remembered(key, wrt)
        if run is None:
            run = self.run = compute(key, self._names_to_compute(values, wrt))
            run.probe = bool(self.probes and not run.names)
        if wrt:
            self.kept = run
        return run

    @contextlib.contextmanager
    def probing(self):
        """Readings-only runs asked inside are probes, not an optimiser's trial points: no sensitivities ahead."""
        self.probes += 1
        try:
            yield
        finally:
            self.probes -= 1

    def _names_to_compute(self, values: Mapping, wrt: Sequence[str]) -> tuple:
        if wrt:
            return tuple(wrt)
        if self.probes:
            return ()
        self.plain_requests += 1
        if self.plain_requests <= ANTICIPATE:
            return tuple(n for n in self.wanted if n in values)
        return ()


class Watch:
    """A run's progress lines (after FIRST_WORDS seconds, then every EVERY seconds: stage, increment,
    Newton iteration) and its time limit (``geoback.case.budget``: past it, the run stops where it is)."""

    def __init__(self, number: int, stages: list[str]):
        self.number, self.stages = number, stages
        self.t0 = time.monotonic()
        self.next = self.t0 + FIRST_WORDS
        self.spoke = False
        self.at = None

    def where(self) -> str:
        p = self.at
        if p is None:
            return f"forward run {self.number} (Mohr-Coulomb), setting up"
        return (f"forward run {self.number} (Mohr-Coulomb) at stage {p.stage} of {p.stages} "
                f"({self.stages[p.stage - 1]}), increment {p.increment} (lambda {p.lam:.4g})"
                + (f", Newton iteration {p.iteration}" if not p.converged else ""))

    def __call__(self, p) -> None:
        self.at = p
        budget.check(self.where)
        now = time.monotonic()
        if now >= self.next:
            self.next = now + EVERY
            self.spoke = True
            what = (f"converged in {p.iteration} Newton iteration{'s' if p.iteration != 1 else ''}" if p.converged
                    else f"Newton iteration {p.iteration}, residual {p.residual:.1e}")
            halved = f", {p.cutbacks} increment{'s' if p.cutbacks != 1 else ''} halved" if p.cutbacks else ""
            budget.say(f"  forward run {self.number}: stage {p.stage} of {p.stages} ({self.stages[p.stage - 1]}), "
                       f"increment {p.increment} (lambda {p.lam:.4g}), {what}{halved}; {now - self.t0:.0f} s",
                       remember=False)

    def done(self, counters, failed: bool = False) -> None:
        if self.spoke:
            c = counters
            budget.say(f"  forward run {self.number} {'failed' if failed else 'done'}: {c.increments} increments, "
                       f"{c.newton_iterations} Newton iterations, {c.factorisations} factorisations"
                       + (f", {c.cutbacks} halved" if c.cutbacks else "")
                       + f"; {time.monotonic() - self.t0:.0f} s", remember=False)


class PlasticSimulation(Simulation):
    """A case with mohr-coulomb ground, meshed, predicting readings at every construction stage."""

    piecewise_smooth = True  # a quadrature point that starts to yield in another increment makes a kink

    SHARED = ("_runs",)  # nothing is cached per survey row: a view reads the last run

    def __init__(self, loaded: LoadedCase, mesh: Mesh | None = None, blocks: list[InstrumentBlock] | None = None,
                 extensions: Mapping | None = None, backend: str | None = None, increments: int = INCREMENTS):
        from geoback.physics.plasticity import Options
        from geoback.physics.plasticity.linear import default_backend
        from geoback.physics.plasticity.operators import PointOperators

        c = loaded.case.construction
        if c is not None and c.lining is not None:
            raise loaded.error(("construction", "lining"), "expected no lining with mohr-coulomb ground: a lining on "
                                                           "yielding ground is not modelled")
        domain = build_domain(loaded, mesh, blocks, backend, extensions)
        self.strength = Strength.of(loaded.case)
        super().__init__(domain, Names(domain.ground, domain.plan, self.strength, UNMODELLED))
        t0 = time.perf_counter()
        self.ops = PointOperators(self.fe)
        xy = self.ops.point_coordinates()
        self._point_depth = -xy[:, 1]
        self._point_layer = np.repeat(self.fe.region, self.ops.nq)
        self.timings["assembly"] += time.perf_counter() - t0
        self.options = Options(schedule=self._schedule(increments), refine=True, backend=backend)
        self._runs = Runs()
        self._region = Region(self.ops.element_dofs(), self.fe.nfree)  # what may yield, condensed (kept)
        self._backend = backend or default_backend(self.fe.nfree)
        self._pardiso = self._backend == "pardiso"

    @property
    def solver(self) -> str | None:
        return self._backend if self.counters.factorisations else None

    def _schedule(self, increments: int) -> tuple:
        """Fractions of each stage where increments end: INCREMENTS per unit of release, MIN_STAGE per stage."""
        beta = self.plan.cumulative(self.plan.values)
        steps = np.diff(np.concatenate([[0.0], beta]))
        return tuple(tuple(np.linspace(0.0, 1.0, n + 1)[1:]) for n in stage_increments(steps, increments))

    # ------------------------------------------------------------------ the inputs of the solver
    def _inputs(self, values: Mapping):
        """Material per element, sigma0 per point, the load f and the stages' lambda (complex-safe)."""
        from geoback.physics.plasticity import Material

        own = {k for k in values if self.plan.knows(k) or self.strength.knows(k)}
        ground = {k: v for k, v in values.items() if k not in own}
        pts = self.ground.fields(ground, self._point_depth, self._point_layer)
        if np.any(pts.n != 1) or np.any(pts.m != 1):  # (canonical() does not know n, m)
            raise GeobackError("cross-anisotropic stiffness (n, m) is not modelled with mohr-coulomb ground")
        wall = self.ground.fields(ground)
        gamma = self.loaded.case.ground.unit_weight
        sv = -gamma * self._point_depth
        k0 = pts.k0
        sigma0 = np.stack([k0 * sv, sv + 0 * k0, k0 * sv, 0 * k0], axis=1)
        sv_wall = -gamma * self.ground.wall_depth * wall.release
        f = self.fe.load(sv_wall, wall.k0 * sv_wall)
        layer_fields = [self.strength.fields(values, name) for name in self.ground.layers]
        dtype = complex if any(isinstance(v, complex) for v in values.values()) else float
        per = np.array([[np.nan if v is None else v for v in lf] for lf in layer_fields], dtype=dtype)
        strength = per[self.fe.region]  # (ne, 4): c, phi, psi, tension
        mat = Material(pts.E, pts.nu, strength[:, 0], strength[:, 1] * DEG, strength[:, 2] * DEG, strength[:, 3])
        lam = self.plan.cumulative(values)
        return mat, sigma0, f, lam

    def _derivatives(self, values: Mapping, names: Sequence[str]) -> list:
        """d inputs / d value for every name, one complex step each (exact for this analytic map)."""
        from geoback.physics.plasticity import ParameterDerivative

        out = []
        for name in names:
            v = dict(values)
            h = COMPLEX_STEP * max(1.0, abs(values[name]))
            v[name] = values[name] + 1j * h
            mat, sigma0, f, lam = self._inputs(v)
            d = {n: np.imag(getattr(mat, n)) / h for n in ("E", "nu", "c", "phi", "psi", "tension")}
            out.append(ParameterDerivative(name, sigma0=np.imag(sigma0) / h, f=np.imag(f) / h,
                                           stages=np.imag(lam) / h, **d))
        return out

    def _check_strength(self, values: Mapping) -> None:
        for layer, plastic in zip(self.strength.layers, self.strength.plastic):
            if not plastic:
                continue
            phi, psi = (float(np.real(values[f"{f}[{layer}]"])) for f in ("phi", "psi"))
            if psi > phi:
                raise ForwardFailure(f"dilation angle psi[{layer}] = {psi:.4g} deg above the friction angle phi[{layer}] "
                                     f"= {phi:.4g} deg: not admissible")

    def _check_releases(self, lam: np.ndarray) -> None:
        """The engine releases the stress in increments: every stage must release more (a parameter
        beta[stage] below the stage before it cannot be run: a point without solution)."""
        names = [n or f"beta[{stage}]" for n, stage in zip(self.plan.release, self.stages)]
        if lam[0] > 0 and np.all(np.diff(lam) > 0):
            return
        k = 0 if not lam[0] > 0 else int(np.flatnonzero(np.diff(lam) <= 0)[0]) + 1
        before = f" after {names[k - 1]} = {lam[k - 1]:.4g}" if k else ""
        raise ForwardFailure(f"the releases must increase from stage to stage with mohr-coulomb ground, found "
                             f"{names[k]} = {lam[k]:.4g}{before}")

    # ------------------------------------------------------------------ forward
    def solution(self, values: Mapping, wrt: Sequence[str] = ()) -> _Run:
        """The non-linear solution at `values` with du/dv for `wrt` (the last one is reused: ``Runs.answer``)."""
        return self._runs.answer(values, wrt, lambda key, names: self._solve(values, key, names))

    def _solve(self, values: Mapping, key: tuple, names: tuple) -> _Run:
        from geoback.physics.plasticity import NonConvergence, solve

        runs = self._runs
        self._check_strength(values)
        mat, sigma0, f, lam = self._inputs(values)
        self._check_releases(np.real(lam))
        derivs = self._derivatives(values, names) if names else None
        self.counters.forward_runs += 1
        runs.number += 1
        watch = Watch(runs.number, self.stages)
        try:
            with one_thread(self._pardiso):
                res = solve(self.fe, mat, sigma0, f, lam, derivatives=derivs, options=runs.options(self.options, names),
                            operators=self.ops, warm=runs.predicted(values), observer=watch, region=self._region)
        except NonConvergence as exc:
            self._count(exc.counters)
            watch.done(exc.counters, failed=True)
            raise
        except ValueError as exc:  # the in-situ stress outside the strength at these values
            if "yield condition" in str(exc):
                raise ForwardFailure(f"the in-situ stress exceeds the Mohr-Coulomb strength at these values "
                                     f"({exc})") from None
            raise
        self._count(res.counters)
        watch.done(res.counters)
        runs.warm = res.warm
        if res.warm_du:
            runs.base = (dict(values), tuple(names), res.warm, res.warm_du)
        return _Run(key, tuple(names), res.u, res.du_dp, res)

    def _count(self, c) -> None:
        """Add a solver run's counters (plasticity.linear.Counters) to the simulation's."""
        self.counters.add_engine(c)

    def _readings(self, values: Mapping, wrt: Sequence[str]) -> Prediction:
        run = self.solution(values, wrt)
        rows = self.domain.row_stage
        P = self.survey.P
        X = P @ run.u.T  # (m, nstages)
        x = X[np.arange(len(rows)), rows]
        if not wrt:
            return Prediction(x)
        A = np.empty((len(x), len(wrt)))
        cols = [run.names.index(n) for n in wrt]
        for k in range(len(self.stages)):
            sel = rows == k
            if sel.any():
                A[sel] = (P[sel] @ run.du[k][:, cols])
        return Prediction(x, A)

    def stage_displacements(self, values: Mapping) -> np.ndarray:
        """u_k on the free dofs after every stage (nstages, nfree)."""
        return self.solution(values).u

    def probing(self):
        return self._runs.probing()

    def release(self) -> None:
        """Forget the last runs (and the warm start they offer): the next run starts from scratch."""
        self._runs.run, self._runs.kept, self._runs.warm, self._runs.base = None, None, None, None
        self._region.release()

    def replaying(self, values: Mapping) -> "PlasticSimulation":
        """A copy replaying the increments of the run at `values` (no halving) with a tight Newton
        tolerance, from scratch: its readings near `values` are the discrete function whose exact
        derivatives the sensitivities at `values` are (finite differences of it converge to them)."""
        fd = copy.copy(self)
        fd.options = replace(self.options, schedule=self.solution(values).result.schedule, refine=False, tol=1e-13)
        fd._region = Region(self.ops.element_dofs(), self.fe.nfree)
        fd.release()
        return fd

    # ------------------------------------------------------------------ fields and the plastic zone
    def _point_plastic_strain(self, values: Mapping, run: _Run) -> np.ndarray:
        """Equivalent plastic strain at every point after every stage (nstages, npts)."""
        mat, sigma0, _, _ = self._inputs(values)
        E, nu = (self.ops.per_point(np.real(v)) for v in (mat.E, mat.nu))
        s0 = np.real(sigma0)
        out = np.empty((len(self.stages), self.ops.npts))
        for k in range(len(self.stages)):
            strain = self.ops.strain(run.u[k])
            out[k] = equivalent_plastic_strain(strain, run.result.sigma[k].reshape(-1, 4) - s0, E, nu)
        return out

    def plastic_zone(self, values: Mapping) -> PlasticZone:
        """Extent, depth range and area of the yielded ground after every stage (``plastic_zone.py``)."""
        run = self.solution(values)
        res = run.result
        g = self.loaded.case.geometry
        yielded = res.yielded.reshape(len(self.stages), -1)
        return measure(self.stages, np.real(self.plan.cumulative(values)), self.ops.point_coordinates(),
                       self.ops.w.reshape(-1), yielded, (0.0, -g.axis_depth), g.radius, self.mesh,
                       self._point_plastic_strain(values, run), {k: float(np.real(v)) for k, v in values.items()})

    def field(self, values: Mapping) -> Field:
        """Displacement after the last stage (and after each stage as point data when there are several);
        per cell the stress after the last stage (quadrature mean), and per stage the share of the cell
        that has yielded (``plastic[stage]``) and its equivalent plastic strain (``plastic_strain[stage]``)."""
        run = self.solution(values)
        full = [self.fe.expand(u).reshape(-1, 2) for u in run.u]
        w = self.ops.w
        mean = (run.result.sigma[-1] * w[..., None]).sum(axis=1) / w.sum(axis=1)[:, None]
        cell = {"stress_xx": mean[:, 0], "stress_yy": mean[:, 1], "stress_zz": mean[:, 2], "stress_xy": mean[:, 3]}
        zone = self.plastic_zone(values)
        for k, stage in enumerate(self.stages):
            cell[f"plastic[{stage}]"] = zone.cell_yielded[k]
            cell[f"plastic_strain[{stage}]"] = zone.cell_plastic_strain[k]
        point = {f"displacement[{n}]": u for n, u in zip(self.stages, full)} if len(self.stages) > 1 else {}
        return Field(self.mesh, full[-1], cell, point)


__all__ = ["PlasticSimulation", "INCREMENTS", "MC_FIELDS"]
