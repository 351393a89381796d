"""Staged excavation of openings of any shape by element removal in yielding (Mohr-Coulomb) ground:
readings at every stage and their exact sensitivities.

The section, its meshing and the construction as data are those of ``excavation.py`` (read its
docstring first); the ground is elastic-perfectly plastic (``plasticity/mohr_coulomb.py``), solved
by the incremental Newton method of ``plasticity/incremental.py`` applied stage by stage to the body
that is there.

The stage recursion
-------------------
Stage k has an active body A_k (the ground not yet removed and the linings installed and not yet
removed: ``ExcavationSimulation._material``) and a load made of the release groups of the sequence
(``case/sequence.py``). With sigma the stress at every quadrature point (compression negative,
(sxx, syy, szz, sxy)), starting from the geostatic sigma_0 = (K0 sv, sv, K0 sv, 0), sv = - sum of
the unit weights over the depth, and F_X(sigma) = sum_{e in X} int_e B^t sigma dV:

1. *Removal.* The elements S_g the stage removes (its group g) load what remains with what they
   exerted on it, from their current (elastoplastic) stress and their weight:

       f_g = F_{S_g}(sigma) - sum_{e in S_g} int_e N^t b dV,   b = (0, -gamma_e)          (R1)

   (linings weigh nothing here, as in ``excavation.py``), times the extension 'beta' if on.
2. *Activation.* A lining installed in the stage joins the body stress-free: sigma = 0 at its points
   from then on its stress is D_l (eps(u) - eps(u_install)), as its return mapping with a strength
   no stress reaches accumulates it.
3. *Release.* The stage releases Delta beta_kg = beta_kg - beta_(k-1)g of every group (``Sequence.
   fractions``), in increments s in (0, 1] of its own schedule, each solved by full Newton with the
   consistent tangent on the active body's dofs:

       R_k(u, s) = F_{A_k}(sigma(u) - sigma_(k-1)) - s sum_g Delta beta_kg f_g = 0,        (R2)

   which is eqn (1) of ``plasticity/incremental.py`` with the stage's start stress sigma_(k-1) in
   place of sigma_0, its load sum_g Delta beta_kg f_g in place of f and lambda = s: the engine solves
   it unchanged on the operators of the active body (``PointOperators.restricted``). Equivalently,
   at the end of every stage the body is in equilibrium under its weight with the fractions
   1 - beta_g of every removal load still held as a support pressure. For linear-elastic ground (R2)
   is exactly the recursion u_k = u_(k-1) + K_k^-1 sum_g Delta beta_kg f_g of ``excavation.py``.
   Newton's residual is measured as in one run releasing everything so far: against
   ||sum_g beta_(k-1)g f_g + s sum_g Delta beta_kg f_g|| (``solve(f_before=...)``), not the stage's
   share alone (a stage releasing the last 30 % of a group would otherwise ask a residual below the
   rounding of the stress it starts from).

A lining installed in the stage that excavates its part replaces ground that is removed: that
ground's stress goes into the stage's load (R1) with the rest of the part, and the lining starts
stress-free (as ``excavation.py`` does).

The readings of stage k are x = P u_k (eqn 29), u_k the displacement accumulated up to it.

Nothing of a removed element enters later stages (its nodes that no active element holds keep the
displacement they had); readings of ground removed by their stage are refused (``_check_survey``).

Sensitivities (DDM)
-------------------
The direct differentiation of eqns (3)-(4) of ``plasticity/incremental.py`` runs inside each stage
with d sigma_(k-1)/dp as the start of the stress history and the derivative of the stage's load,

    d(sum_g Delta beta_kg f_g) = sum_g (d Delta beta_kg f_g + Delta beta_kg d f_g),
    d f_g = F_{S_g}(d sigma/dp) - sum int N^t db                                         (R3)

from the removed elements' stress sensitivities at their removal (the engine returns d sigma/dp at
the end of a stage: ``Result.dsigma``); an activated lining starts with d sigma/dp = 0. The inputs'
derivatives (material per element, sigma_0, gamma, beta, the lining's E and nu) are one complex step
of the case-to-inputs map each (exact to rounding). The result is the exact derivative of the
discrete solution for the increments used: finite differences must replay them (``replaying``).

Increments, warm starts, progress, probes and the time limit are those of ``plastic.py``: a fixed schedule of
``INCREMENTS`` per unit of the largest fraction a stage releases (at least ``MIN_STAGE``), a failed
increment halved, each increment's Newton iteration started from the last run with sensitivities
carried to the new values to first order (its solution of the increment plus du/dp dp: ``Runs.predicted``;
else the last run's solution) where that is closer (on the heading-and-bench case's identification,
1077 factorisations became 891, the estimates the same to six digits), progress lines and
``errors.TimeLimit`` through ``plastic.Watch``. A run that does not converge raises ``plasticity.NonConvergence`` naming the construction stage. A replay for finite
differences (``replaying``) iterates each increment to the residual's rounding floor (``REPLAY_TOL``,
``REPLAY_FLOOR``: ``Options.floor``). ``_Run.branch`` (the yielding points after every increment) tells
whether two runs are on the same branch, between which finite differences converge to the sensitivities.

Not modelled: cross-anisotropic elasticity with yielding ground (``plastic.UNMODELLED``); linings
are linear elastic.
"""
from __future__ import annotations

import copy
from dataclasses import dataclass, replace
from typing import Mapping, Sequence as Seq

import numpy as np
import scipy.sparse as sp

from geoback.case.strength import ELASTIC, INCREMENTS, Strength, stage_increments
from geoback.errors import ForwardFailure, GeobackError
from geoback.physics.excavation import ExcavationSimulation
from geoback.physics.ground import COMPLEX_STEP
from geoback.physics.names import Names
from geoback.physics.plastic import DEG, UNMODELLED, Runs, Watch, one_thread
from geoback.physics.plastic_zone import PlasticZone, equivalent_plastic_strain, measure
from geoback.physics.plasticity.condensed import Region
from geoback.physics.plasticity.linear import Counters as EngineCounters
from geoback.physics.simulation import Field, Prediction

REPLAY_TOL, REPLAY_FLOOR = 1e-13, 1e-11  # a replay's Newton tolerance (plastic.py's) and where a residual that no
# longer falls is taken as converged: the rounding floor of the residual here is 5e-14 to 1.3e-12 from stage to stage
# (linings raising it), above 1e-13 at times
LINED_CONTRAST = 125.0  # the stiffness contrast (a lining's E over the ground's) REPLAY_FLOOR was measured at
PRELOAD_INCREMENTS = 2  # increments of a support's preload (the jack), before it locks
PROBE = 1e-9  # a zero preload's derivative: the one-sided one, by a jack of this share of the load released
LINING_STRENGTH = (ELASTIC["c"], ELASTIC["phi"] * DEG, ELASTIC["psi"] * DEG, ELASTIC["tension"])  # never reached


class _Sources:
    """The strength's names and the unit weights' as one names source (``names.Names``)."""

    def __init__(self, *sources):
        self.sources = sources

    def _owner(self, name: str):
        return next((s for s in self.sources if s.knows(name)), None)

    def quantities(self) -> dict[str, float]:
        out = {}
        for s in self.sources:
            out.update(s.quantities())
        return out

    def knows(self, name: str) -> bool:
        return self._owner(name) is not None

    def canonical(self, name: str) -> str | None:
        return next((full for full in (s.canonical(name) for s in self.sources) if full is not None), None)

    def unit(self, name: str) -> str | None:
        owner = self._owner(name)
        return owner.unit(name) if owner is not None else None

    def limits(self, name: str, values: Mapping):
        owner = self._owner(name)
        return owner.limits(name, values) if owner is not None else None


@dataclass
class _Inputs:
    """What the values change (complex-safe; a derivative has the same fields): the ground's material
    per element (angles in radians), each lining's (E, nu), sigma_0 per point, the unit weight per
    element, the release factor (the extension 'beta') and the fractions released (nstages, ngroups)."""

    E: np.ndarray
    nu: np.ndarray
    c: np.ndarray
    phi: np.ndarray
    psi: np.ndarray
    tension: np.ndarray
    linings: dict
    sigma0: np.ndarray
    gamma: np.ndarray
    release: object
    fractions: np.ndarray

    def imag(self, h: float) -> "_Inputs":
        """The derivative carried by a complex step of size h."""
        im = (lambda v: np.imag(np.asarray(v)) / h)
        return _Inputs(*(im(getattr(self, f)) for f in ("E", "nu", "c", "phi", "psi", "tension")),
                       {n: (im(E), im(nu)) for n, (E, nu) in self.linings.items()},
                       im(self.sigma0), im(self.gamma), float(im(self.release)), im(self.fractions))

    def real(self) -> "_Inputs":
        re = (lambda v: np.real(np.asarray(v)))
        return _Inputs(*(re(getattr(self, f)) for f in ("E", "nu", "c", "phi", "psi", "tension")),
                       {n: (float(re(E)), float(re(nu))) for n, (E, nu) in self.linings.items()},
                       re(self.sigma0), re(self.gamma), float(re(self.release)), re(self.fractions))


@dataclass
class _Run:
    """A forward run: after every stage the displacement (nstages, nfree), its sensitivities
    (nstages, nfree, len(names)), the stress at every point (nstages, npts, 4), the points yielded so
    far and those yielding in the stage's last increment (nstages, npts); the schedule it used (per
    stage, the fractions s where increments ended) and the engine's counters summed."""

    key: tuple
    names: tuple
    u: np.ndarray
    du: np.ndarray | None
    sigma: np.ndarray
    yielded: np.ndarray
    plastic: np.ndarray
    schedule: tuple
    counters: object = None  # the engine's counters summed over the stages (plasticity.linear.Counters)
    branch: tuple = ()  # per stage, the yielding points after each increment: a run on the same branch as another
    # (the same points yield in the same increments) has the same counts, and finite differences between
    # such runs converge to the sensitivities (across a change of branch they pick up a kink)
    e_ref: np.ndarray = None  # each prop's or anchor's shortening / elongation when it was locked
    de_ref: np.ndarray = None
    probe: bool = False  # solved to plastic.PROBE_TOL only (plastic.Runs): not reused outside a probe

    @property
    def wrt(self) -> tuple:
        return self.names


class YieldingExcavationSimulation(ExcavationSimulation):
    """Openings excavated by element removal in stages, in ground with Mohr-Coulomb layers (module
    docstring)."""

    piecewise_smooth = True  # a point that starts to yield in another increment makes a kink
    SHARED = ("_runs", "_configurations")

    def __init__(self, loaded, mesh=None, blocks=None, extensions: Mapping | None = None, backend: str | None = None,
                 increments: int = INCREMENTS):
        import time

        from geoback.physics.plasticity import Options
        from geoback.physics.plasticity.linear import default_backend
        from geoback.physics.plasticity.operators import PointOperators

        super().__init__(loaded, mesh=mesh, blocks=blocks, extensions=extensions, backend=backend)
        self.strength = Strength.of(loaded.case)
        self.names = Names(self.ground, self.plan, _Sources(self.strength, self.weights), UNMODELLED)
        t0 = time.perf_counter()
        self.ops = PointOperators(self.fe)
        self._point_depth = -self.ops.point_coordinates()[:, 1]
        self._point_layer = np.repeat(self.fe.region, self.ops.nq)
        self._N = self.fe.element_quadrature(np.zeros(1, np.int64))[4]  # shape values at the points (nb, nq)
        self.timings["assembly"] += time.perf_counter() - t0
        self.options = Options(schedule=self._schedule(increments), refine=True, backend=backend)
        self._runs = Runs()
        self._regions = {}  # engine run key -> plasticity.condensed.Region
        self._configurations: dict = {}
        self._backend = backend or default_backend(self.fe.nfree)
        self._pardiso = self._backend == "pardiso"

    @property
    def solver(self) -> str | None:
        return self._backend if self.counters.factorisations else None

    def probing(self):
        return self._runs.probing()

    def release(self) -> None:
        """Forget the last runs (and the warm start they offer): the next run starts from scratch."""
        self._runs.run, self._runs.kept, self._runs.warm, self._runs.base = None, None, None, None
        for region in self._regions.values():
            region.release()
        self._regions = {}

    def replaying(self, values: Mapping) -> "YieldingExcavationSimulation":
        """A copy replaying the increments of the run at `values` (no halving) with a tight Newton
        tolerance, from scratch: its readings near `values` are the discrete function whose exact
        derivatives the sensitivities at `values` are."""
        fd = copy.copy(self)
        inp = self._inputs({k: np.real(v) for k, v in values.items()}).real()
        stiffest = max([float(E) for E, _ in inp.linings.values()] + [float(inp.E.max())])
        contrast = stiffest / float(inp.E.min())  # the residual's rounding floor grows with it (a wall: 1500)
        fd.options = replace(self.options, schedule=self.solution(values).schedule, refine=False, tol=REPLAY_TOL,
                             floor=REPLAY_FLOOR * max(1.0, contrast / LINED_CONTRAST))
        fd._regions = {}  # its own (release() frees them)
        fd.release()
        return fd

    def _schedule(self, increments: int) -> tuple:
        """Fractions of each stage where increments end: `increments` per unit of the largest fraction
        the stage releases of any group, at least MIN_STAGE (``strength.stage_increments``)."""
        frac = np.real(self.plan.fractions(self.plan.values))
        steps = np.diff(np.vstack([np.zeros((1, frac.shape[1])), frac]), axis=0).max(axis=1, initial=0.0)
        release = tuple(tuple(np.linspace(0.0, 1.0, n + 1)[1:]) for n in stage_increments(steps, increments))
        jacked = sorted(set(int(k) for k in self._installed))  # a preload sub-step in each stage installing supports
        return release + tuple(tuple(np.linspace(0.0, 1.0, PRELOAD_INCREMENTS + 1)[1:]) for _ in jacked)

    # ------------------------------------------------------------------ the inputs of the engine
    def _inputs(self, values: Mapping) -> _Inputs:
        """The case's values as the engine's inputs (complex-safe: module docstring)."""
        own = {k: v for k, v in values.items()
               if not (self.plan.knows(k) or self.weights.knows(k) or self.strength.knows(k))}  # the ground's
        pts = self.ground.fields(own, self._point_depth, self._point_layer)
        if np.any(pts.n != 1) or np.any(pts.m != 1):  # (canonical() does not know n, m)
            raise GeobackError("cross-anisotropic stiffness (n, m) is not modelled with mohr-coulomb ground")
        dtype = complex if any(isinstance(v, complex) for v in values.values()) else float
        gammas = self.weights.of_layers(values)
        sv = -self._overburden(self._point_depth, gammas, dtype)
        k0 = pts.k0
        sigma0 = np.stack([k0 * sv, sv + 0 * k0, k0 * sv, 0 * k0], axis=1)
        layer_fields = [self.strength.fields(values, name) for name in self.ground.layers]
        per = np.array([[np.nan if v is None else v for v in lf] for lf in layer_fields], dtype=dtype)
        strength = per[self.fe.region]  # (ne, 4): c, phi, psi, tension
        linings = {n: (values[f"E[{n}]"], values[f"nu[{n}]"]) for n in self.plan.bands}  # linings' and walls'

        return _Inputs(pts.E * np.ones(self.fe.ne), pts.nu * np.ones(self.fe.ne), strength[:, 0], strength[:, 1] * DEG,
                       strength[:, 2] * DEG, strength[:, 3], linings, sigma0,
                       np.array(gammas, dtype=dtype)[self.fe.region], pts.release, self.plan.fractions(values))

    def _input_derivative(self, values: Mapping, name: str) -> _Inputs:
        v = dict(values)
        h = COMPLEX_STEP * max(1.0, abs(values[name]))
        v[name] = values[name] + 1j * h
        return self._inputs(v).imag(h)

    def _configured(self, inp: _Inputs, mat: np.ndarray, active: np.ndarray, derivative: bool = False):
        """The engine's Material per active element: the ground's, a lining's where one is installed."""
        from geoback.physics.plasticity import Material

        m = mat[active]
        fields = [np.array(getattr(inp, f)[active], float) for f in ("E", "nu", "c", "phi", "psi", "tension")]
        for i, name in enumerate(self.mesh.band_names):
            sel = m == 1 + i
            if not sel.any():
                continue
            E, nu = inp.linings[name]
            for j, value in enumerate((E, nu) + ((0.0,) * 4 if derivative else LINING_STRENGTH)):
                fields[j][sel] = value
        return Material(*fields)

    def _region(self, key, ops_k):
        """What may yield in the engine runs of `key` (a stage, or its supports' preload), condensed and kept
        from run to run (``plasticity.condensed``)."""
        if key not in self._regions:
            self._regions[key] = Region(ops_k.element_dofs(), ops_k.nfree)
        return self._regions[key]

    def _configuration(self, mat: np.ndarray):
        """(active elements, active dofs, the engine's operators of that body), one per configuration."""
        key = mat.tobytes()
        if key not in self._configurations:
            active = np.flatnonzero(mat >= 0)
            dofs = self._active(mat)
            self._configurations[key] = (active, dofs, self.ops.restricted(active, dofs))
        return self._configurations[key]

    def _points(self, elements: np.ndarray) -> np.ndarray:
        nq = self.ops.nq
        return (elements[:, None] * nq + np.arange(nq)).ravel()

    def _internal_force(self, gone: np.ndarray, sigma: np.ndarray) -> np.ndarray:
        """F_S(sigma) on the free dofs for the elements `gone`: sigma (npts, 4[, P]) at every point."""
        pts = self._points(gone)
        only = np.zeros_like(sigma)
        only[pts] = sigma[pts]
        return self.ops.internal_force(only)

    def _weight(self, gone: np.ndarray, prev: np.ndarray, gamma: np.ndarray) -> np.ndarray:
        """- sum int N^t b dV, b = (0, -gamma_e), over the elements `gone` on the free dofs (ground
        weighs, a lining does not: its material in `prev` is not 0)."""
        fe = self.fe
        g = np.where(prev[gone] == 0, gamma[gone], 0.0)
        nodal = g[:, None] * np.einsum("bq,eq->eb", self._N, self.ops.w[gone])
        out = np.zeros(fe.ndof)
        np.add.at(out, fe.edofs[gone][:, 1::2].ravel(), nodal.ravel())
        return out[fe.free]

    # ------------------------------------------------------------------ forward
    def _check_strength(self, values: Mapping, inp: _Inputs) -> None:
        from geoback.physics.plasticity import mohr_coulomb as mc

        for layer, plastic in zip(self.strength.layers, self.strength.plastic):
            if not plastic:
                continue
            phi, psi = (float(np.real(values[f"{f}[{layer}]"])) for f in ("phi", "psi"))
            if psi > phi:
                raise ForwardFailure(f"dilation angle psi[{layer}] = {psi:.4g} deg above the friction angle phi[{layer}] "
                                     f"= {phi:.4g} deg: not admissible")
        mat = self._configured(inp, self._material(-1), np.arange(self.fe.ne))
        mat = type(mat)(*(np.repeat(v, self.ops.nq) for v in mat.values()))  # per point
        fy, ft = mc.yield_functions(inp.sigma0, mat)
        scale = np.abs(inp.sigma0).max(axis=1) + np.abs(mat.c)
        outside = (fy > 1e-9 * scale) | (ft > 1e-9 * scale)
        if outside.any():
            layers = sorted({self.ground.layers[i] for i in self._point_layer[outside]})
            raise ForwardFailure(f"the in-situ stress exceeds the Mohr-Coulomb strength at these values at "
                                 f"{int(outside.sum())} of {self.ops.npts} points (layer {', '.join(layers)})")

    def _solution(self, values: Mapping, wrt: tuple):
        return self.solution(values, wrt)

    def solution(self, values: Mapping, wrt: Seq[str] = ()) -> _Run:
        """The staged elastoplastic solution at `values` with du/dv for `wrt` (the last ones reused:
        ``plastic.Runs.answer``)."""
        return self._runs.answer(values, wrt, lambda key, names: self._solve(values, key, names))

    def _solve(self, values: Mapping, key: tuple, names: tuple) -> _Run:
        """The stage recursion (R1)-(R3)."""
        from geoback.physics.plasticity import NonConvergence, ParameterDerivative, solve

        base = self._inputs(values)
        inp = base.real()
        self._check_strength(values, inp)
        dinp = [self._input_derivative(values, n) for n in names]
        fe, ops, plan = self.fe, self.ops, self.plan
        P, n, ns = len(names), fe.nfree, len(plan.steps)
        sigma = inp.sigma0.copy()
        dsigma = np.stack([d.sigma0 for d in dinp], axis=-1) if P else None
        u, du = np.zeros(n), np.zeros((n, P))
        loads, dloads = [], []
        out = dict(u=np.zeros((ns, n)), du=np.zeros((ns, n, P)) if P else None, sigma=np.zeros((ns,) + sigma.shape),
                   yielded=np.zeros((ns, ops.npts), bool), plastic=np.zeros((ns, ops.npts), bool))
        yielded = np.zeros(ops.npts, bool)
        schedule = list(self.options.schedule)
        warm = self._runs.predicted(values) or {}  # (engine run, its increment) -> u: carried to first order
        new_warm, new_warm_du = {}, {}
        branch = [()] * ns
        frac = inp.fractions
        self.counters.forward_runs += 1
        self._runs.number += 1
        watch = Watch(self._runs.number, self.stages)
        totals = EngineCounters()  # the engine's, summed over the stages
        prev = self._material(-1)
        C_all = self._C
        ks = np.array([float(np.real(values[f"k[{m}]"])) for m in self.connectors])
        preload = np.array([float(np.real(values[f"preload[{m}]"])) for m in self.connectors])
        dks = np.array([[float(nm == f"k[{m}]") for nm in names] for m in self.connectors]).reshape(len(ks), P)
        dpre = np.array([[float(nm == f"preload[{m}]") for nm in names] for m in self.connectors]).reshape(len(ks), P)
        e_ref, de_ref = np.zeros(len(ks)), np.zeros((len(ks), P))
        jacked = sorted(set(int(j) for j in self._installed))
        state = dict(u=u, du=du, sigma=sigma, dsigma=dsigma, yielded=yielded)

        def engine(k, key, mat, g, dgs, before, on, plastic_now, forward=True):
            """One engine run on stage k's body (elements `mat`, springs `on`): release g (dg/dp `dgs`)
            from the state so far, in the increments of `schedule[key]`; updates the state in place (with
            `forward` False only the sensitivities: g is then a vanishing probe of the direction)."""
            active, dofs, ops_k = self._configuration(mat)
            pts = self._points(active)
            springs = None
            if on.any():
                from geoback.physics.supports import spring_matrix

                Ku = spring_matrix(C_all[on], ks[on], dofs)
                springs = (Ku + sp.triu(Ku, 1).T).tocsr()
            derivs = None
            if P:
                derivs = []
                for j, (name, d) in enumerate(zip(names, dinp)):
                    dm = self._configured(d, mat, active, derivative=True)
                    dK = None
                    if on.any() and np.any(dks[on, j]):
                        Kd = spring_matrix(C_all[on], dks[on, j], dofs)
                        dK = (Kd + sp.triu(Kd, 1).T).tocsr()
                    derivs.append(ParameterDerivative(name, *dm.values(), sigma0=state["dsigma"][pts, :, j],
                                                      f=dgs[:, j][dofs], stages=0.0, springs=dK))
            material = self._configured(inp, mat, active)

            def observer(p, _k=k):
                watch(replace(p, stage=_k + 1, stages=ns))

            try:
                with one_thread(self._pardiso):
                    res = solve(fe, material, state["sigma"][pts], g[dofs], [1.0], derivatives=derivs,
                                options=replace(self._runs.options(self.options, names), schedule=(schedule[key],)),
                                operators=ops_k,
                                warm={i: u for (k_, i), u in warm.items() if k_ == key} or None, observer=observer,
                                f_before=before[dofs], springs=springs,
                                region=self._region(key, ops_k))
            except NonConvergence as exc:
                self._count(exc.counters)
                _add(totals, exc.counters)
                watch.done(totals, failed=True)
                what = "the preload of its supports" if key != k else "the stage's release"
                exc.args = (f"construction stage '{plan.steps[k].name}' ({k + 1} of {ns}), {what}: "
                            + str(exc).replace("(stage 1, lambda", "(fraction of the stage's release"),)
                raise
            except ValueError as exc:  # the start stress outside the strength
                if "yield condition" in str(exc):
                    raise ForwardFailure(f"construction stage '{plan.steps[k].name}': the stress exceeds the "
                                         f"Mohr-Coulomb strength at these values ({exc})") from None
                raise
            self._count(res.counters)
            _add(totals, res.counters)
            if P:
                state["du"][dofs] += res.du_dp[0]
                state["dsigma"][pts] = res.dsigma
            if not forward:
                return ()
            state["u"][dofs] += res.u[0]
            state["sigma"][pts] = res.sigma[0].reshape(-1, 4)
            state["yielded"][pts] |= res.yielded[0].reshape(-1)
            plastic_now[pts] = res.plastic[0].reshape(-1)
            schedule[key] = res.schedule[0]
            new_warm.update({(key, i): u for i, u in res.warm.items()})
            new_warm_du.update({(key, i): du for i, du in res.warm_du.items()})
            return tuple(log.plastic_points for log in res.increments if log.converged)

        for k, step in enumerate(plan.steps):
            mat = self._material(k)
            plastic_now = np.zeros(ops.npts, bool)
            sigma, dsigma = state["sigma"], state["dsigma"]
            if step.excavate or step.remove:  # (R1) and its derivative (R3)
                # removed, or ground a lining replaces (a wall installed in ground that stays removes nothing)
                gone = np.flatnonzero((prev >= 0) & (mat != prev) & ((self.removed_at <= k) | (mat < 0)))
                f = self._internal_force(gone, sigma) + self._weight(gone, prev, inp.gamma)
                loads.append(inp.release * f)
                dl = np.zeros((n, P))
                if P:
                    dl = inp.release * self._internal_force(gone, dsigma)
                    for j, d in enumerate(dinp):
                        dl[:, j] += inp.release * self._weight(gone, prev, d.gamma) + d.release * f
                dloads.append(dl)
            walls = [1 + i for i, m in enumerate(self.mesh.band_names) if m in (plan.walls or {})]
            started = np.flatnonzero((mat > 0) & (prev != mat) & ~np.isin(mat, walls))  # linings: stress-free
            if len(started):  # (a wall installed keeps the ground's stress)
                pts = self._points(started)
                sigma[pts] = 0.0
                if P:
                    dsigma[pts] = 0.0
            before = sum((frac[k - 1, i] * loads[i] for i in range(len(loads)) if k and frac[k - 1, i]), np.zeros(n))
            new = self._installed == k
            if new.any():  # props and anchors jacked to their preload, then locked (as in excavation.py)
                g = -(C_all.T @ (preload * new))
                dgs = -(C_all.T @ (dpre * new[:, None])) if P else np.zeros((n, 0))
                key_k = len(plan.steps) + jacked.index(k)
                if np.any(g):
                    engine(k, key_k, mat, g, dgs, before, self._installed < k, plastic_now)
                elif np.any(dgs):  # no preload, one identified: its derivative at 0 (a jack of vanishing load)
                    probe = -(C_all.T @ new.astype(float)) * PROBE * max(1.0, float(np.abs(before).max()))
                    engine(k, key_k, mat, probe, dgs, before, self._installed < k, plastic_now, forward=False)
                e_ref[new] = C_all[new] @ state["u"]
                if P:
                    de_ref[new] = C_all[new] @ state["du"]
            inc = frac[k] - (frac[k - 1] if k else 0.0)
            g = sum((inc[i] * loads[i] for i in range(len(loads)) if inc[i] != 0), np.zeros(n))
            if np.any(inc != 0) and np.any(g):
                dgs = np.zeros((n, P))
                for j, d in enumerate(dinp):
                    dinc = d.fractions[k] - (d.fractions[k - 1] if k else 0.0)
                    dgs[:, j] = sum((inc[i] * dloads[i][:, j] + dinc[i] * loads[i] for i in range(len(loads))),
                                    np.zeros(n))
                branch[k] = engine(k, k, mat, g, dgs, before, self._installed <= k, plastic_now)
            here = np.repeat(mat == 0, ops.nq)  # ground present at the stage
            out["u"][k] = state["u"]
            out["sigma"][k] = state["sigma"]
            out["yielded"][k] = state["yielded"] & here
            out["plastic"][k] = plastic_now & here
            if P:
                out["du"][k] = state["du"]
            prev = mat
        watch.done(totals)
        self._runs.warm = new_warm
        if P and new_warm_du.keys() == new_warm.keys():  # a run with sensitivities: the next starts from it
            self._runs.base = (dict(values), tuple(names), new_warm, new_warm_du)  # carried (plastic.Runs.predicted)
        return _Run(key, tuple(names), out["u"], out["du"], out["sigma"], out["yielded"], out["plastic"],
                    tuple(schedule), totals, tuple(branch), e_ref, de_ref)

    def _count(self, c) -> None:
        """Add a solver run's counters (plasticity.linear.Counters) to the simulation's."""
        self.counters.add_engine(c)

    # ------------------------------------------------------------------ the interface
    def stage_displacements(self, values: Mapping) -> np.ndarray:
        return self.solution(values).u

    def _readings(self, values: Mapping, wrt: Seq[str]) -> Prediction:
        run = self.solution(values, tuple(wrt))
        rows = self.domain.row_stage
        P = self.survey.P
        X = P @ run.u.T  # (m, nstages)
        x = X[np.arange(len(rows)), rows]
        if not wrt:
            self._load_cells(values, wrt, run, x, None)
            return Prediction(x)
        A = np.empty((len(x), len(wrt)))
        cols = [run.names.index(n) for n in wrt]
        for k in range(len(self.stages)):
            sel = rows == k
            if sel.any():
                A[sel] = P[sel] @ run.du[k][:, cols]
        self._load_cells(values, wrt, run, x, A)
        return Prediction(x, A)

    def element_stress(self, values: Mapping, k: int | None = None) -> np.ndarray:
        """Mean total stress (sxx, syy, sxy) per element after stage k (default the last); NaN where
        the element is excavated (a lining's from its installation on)."""
        run = self.solution(values)
        k = len(self.stages) - 1 if k is None else k
        w = self.ops.w
        s = run.sigma[k].reshape(self.fe.ne, self.ops.nq, 4)
        mean = (s * w[..., None]).sum(axis=1) / w.sum(axis=1)[:, None]
        out = mean[:, [0, 1, 3]]
        out[self._material(k) < 0] = np.nan
        return out

    def _plastic_strain(self, values: Mapping, run: _Run) -> np.ndarray:
        """Equivalent plastic strain at every point after every stage (nstages, npts); 0 where the
        ground is not there (excavated) or is a lining."""
        inp = self._inputs({k: np.real(v) for k, v in values.items()}).real()
        E, nu = (np.repeat(v, self.ops.nq) for v in (inp.E, inp.nu))
        out = np.zeros((len(self.stages), self.ops.npts))
        for k in range(len(self.stages)):
            here = np.repeat(self._material(k) == 0, self.ops.nq)
            eps = equivalent_plastic_strain(self.ops.strain(run.u[k]), run.sigma[k] - inp.sigma0, E, nu)
            out[k] = np.where(here, eps, 0.0)
        return out

    def plastic_zone(self, values: Mapping) -> PlasticZone:
        """Extent, depth range and area of the yielded ground after every stage (``plastic_zone.py``),
        radii measured from the centroid of the first opening and against its equivalent radius
        sqrt(area / pi); areas over the whole cross-section."""
        from geoback.case import layout as lay

        run = self.solution(values)
        g = self.loaded.case.geometry
        poly = lay.polygon(g.openings[0])
        centre, radius = (poly.centroid.x, poly.centroid.y), float(np.sqrt(poly.area / np.pi))
        frac = np.real(self.plan.fractions(values))
        release = np.array([frac[k, max(i for i, s in enumerate(self.plan.groups) if s <= k)] if
                            any(s <= k for s in self.plan.groups) else 0.0 for k in range(len(self.stages))])
        w = self.ops.w.reshape(-1) * (1.0 if g.model == "half" else 0.5)  # (measure doubles a half-model's area)
        return measure(self.stages, release, self.ops.point_coordinates(), w, run.yielded, centre, radius, self.mesh,
                       self._plastic_strain(values, run), {k: float(np.real(v)) for k, v in values.items()},
                       f"the centroid of opening '{g.openings[0].name}'")

    def field(self, values: Mapping) -> Field:
        """Displacement after the last stage (and after each stage as point data when there are several);
        per cell the stress after the last stage (quadrature mean, NaN where excavated), and per stage the
        share of the cell that has yielded (``plastic[stage]``) and its equivalent plastic strain."""
        run = self.solution(values)
        full = [self.fe.expand(u).reshape(-1, 2) for u in run.u]
        w = self.ops.w
        s = run.sigma[-1].reshape(self.fe.ne, self.ops.nq, 4)
        mean = (s * w[..., None]).sum(axis=1) / w.sum(axis=1)[:, None]
        mean[self._material(len(self.stages) - 1) < 0] = np.nan
        cell = {"stress_xx": mean[:, 0], "stress_yy": mean[:, 1], "stress_zz": mean[:, 2], "stress_xy": mean[:, 3]}
        zone = self.plastic_zone(values)
        for k, stage in enumerate(self.stages):
            cell[f"plastic[{stage}]"] = zone.cell_yielded[k]
            cell[f"plastic_strain[{stage}]"] = zone.cell_plastic_strain[k]
        point = {f"displacement[{n}]": u for n, u in zip(self.stages, full)} if len(self.stages) > 1 else {}
        return Field(self.mesh, full[-1], cell, point)


__all__ = ["YieldingExcavationSimulation"]


def _add(total, c) -> None:
    """Add the counts of an engine run's counters `c` to `total` (both plasticity.linear.Counters)."""
    if c is None:
        return
    for name in ("factorisations", "factorised_unknowns", "backsubstitutions", "increments", "newton_iterations",
                 "cutbacks", "apex_points", "warm_starts", "elastic_steps", "condensations", "condensations_reused"):
        setattr(total, name, getattr(total, name) + getattr(c, name))
    for name, seconds in c.seconds.items():
        total.seconds[name] += seconds
