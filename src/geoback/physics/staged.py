"""Staged construction with linear-elastic ground and an elastic lining: readings at every stage and
their exact sensitivities (eqns 31-42 through the stages).

The plan (``construction.py``) gives each stage its release increment and configuration; with
linear ground every stage is a solve with the stiffness of its configuration, so (module docstring
of ``construction``)

    u_k = sum_c a_kc w_c,   w_0 = K_g^-1 f  (the ground alone),   w_1 = (K_g + U S U^t)^-1 f,

where f is the full release load (eqn 33), K_g the ground's stiffness and S the lining condensed
onto the wall dofs U (``lining.py``). Readings of stage k are x = P u_k (the stage of each survey row).

One factorisation per configuration, reused through a whole identification. The ground's K_g is
factorised once while K_g(v) = s K_g(ref) (one modulus, fixed nu; eqns 41-42), exactly as in the
one-step model. The lined configuration is NOT refactorised when the ground's modulus changes and
the lining's does not (K_g + U S U^t is then no multiple of the last one): it is factorised as the
ground's factor plus the wall flexibility G = U^t K_g^-1 U (n_w back-substitutions, once, counted
as one factorisation) and the readings' view of it PW = P K_g^-1 U. Every lined solve is then

    z0 = K_g^-1 q,   (I + G S) z_w = U^t z0 (dense, n_w unknowns),   P z = P z0 - PW S z_w,

and since G and PW scale as 1/s with the ground, new E, K0, beta or lining values cost a dense
n_w x n_w Cholesky and no sparse work at all (the loads are in the span cache).

That pays only while the ground's factorisation is reused. Once the ground has had to be
refactorised (two moduli, nu, an E gradient changing: the n_w back-substitutions would then cost
several factorisations at every step), the lined configuration is factorised directly instead:
the ground and lining matrices assembled on the ground's free dofs plus the lining's inner dofs,
kept while all their coefficients scale together, with eqn 34 on that system for sensitivities.

Sensitivities (eqn 34, per configuration) dw_c/dv = K_c^-1 (df/dv - dK_c/dv w_c):
- ground values: dK_1/dv = dK_g/dv; when dK_g/dv = alpha K_g (a modulus scaling K_g, eqn 42),
  K_g^-1 dK_g/dv w_1 = alpha (w_0 - W lambda) with lambda = S z_w, W = K_g^-1 U: no back-substitution;
  otherwise dK_g/dv w_1 is formed (one back-substitution for w_1, one per value);
- the lining's values: dK_1/dv = U dS/dv U^t, dS exact (lining.py): PW and Sigma serve, no sparse work;
- beta[stage]: only the weights a_kc change (linear).

Composition: the case's ``Domain`` (``domain.py``), the ground's ``FactorCache`` (``stiffness.py``)
and, with a lining, its ``RingModel`` (``lining.py``) and ``LinedSystem`` (``lined_system.py``: the
condensed and assembled forms); these are shared with views on other instruments (``surveying``),
while the last solution and the condensation's readings view are kept per survey.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from geoback.case.loading import LoadedCase
from geoback.physics.domain import build_domain
from geoback.physics.ground import COMPLEX_STEP
from geoback.observation.instruments import InstrumentBlock
from geoback.physics.lined_system import LinedSystem, Condensation, Interface
from geoback.physics.lining import LiningForces, RingModel
from geoback.physics.mesh import Mesh
from geoback.physics.names import Names
from geoback.physics.simulation import Field, Prediction, Simulation
from geoback.physics.solver import sequential_blas
from geoback.physics.stiffness import FactorCache, proportion

@dataclass
class _Solution:
    key: tuple
    state: object  # GroundState
    fact: object
    s: float
    coords: np.ndarray
    f: np.ndarray
    w0: np.ndarray  # K_g^-1 f (free dofs)
    Y: np.ndarray  # (m, 2) P w_c
    a: np.ndarray  # (nstages, 2) release fractions under each configuration
    interface: Interface | None = None
    z_w: np.ndarray | None = None  # wall dofs of w_1
    ring_coeffs: np.ndarray | None = None
    w1: np.ndarray | None = None  # w_1 on the free dofs (formed on demand)
    direct: tuple | None = None  # (factorisation, scale, w_1 on ground and inner lining dofs) when direct


class StagedSimulation(Simulation):
    """A case with a construction section: stages, an optional lining, readings at every stage."""

    reads_depth_offsets = False  # it observes with survey.P alone: no inclinometer depth offsets (zoff)
    SHARED = ("stiffness", "lined_system")
    SURVEY_CACHES = ("_sol", "_cond")

    def __init__(self, loaded: LoadedCase, mesh: Mesh | None = None, blocks: list[InstrumentBlock] | None = None,
                 extensions: Mapping | None = None, backend: str | None = None):
        domain = build_domain(loaded, mesh, blocks, backend, extensions)
        super().__init__(domain, Names(domain.ground, domain.plan))
        t0 = time.perf_counter()
        g, plan = loaded.case.geometry, domain.plan
        self.ring = RingModel(self.fe, plan.lining, g.width, g.depth) if plan.lining is not None else None
        self.timings["lining"] = time.perf_counter() - t0
        self.stiffness = FactorCache(domain.counters, backend)  # the ground's
        self.lined_system = LinedSystem(self.fe, self.ring, domain.counters, backend) if self.ring is not None else None
        self._cond: Condensation | None = None  # the lined configuration condensed, read by this survey
        self._sol: _Solution | None = None

    @property
    def solver(self) -> str | None:
        fact = self.stiffness.current
        return fact.backend if fact is not None else None

    def _ground_values(self, values: Mapping) -> dict:
        """The values the ground reads (its extension table would take beta[stage] for 'beta')."""
        return {k: v for k, v in values.items() if not self.plan.knows(k)}

    @property
    def lined(self) -> bool:
        """Does any release act on the lined configuration?"""
        return self.ring is not None and 1 in self.plan.configurations

    # ------------------------------------------------------------------ the lined configuration
    def _survey_changed(self) -> None:
        self._sol = None
        cond = self._cond
        if cond is not None and cond.fact is self.stiffness.current:  # the wall's Schur complement kept
            self._cond = Condensation(cond.fact, self.lined_system.wall_view(cond.fact, self.survey.P), cond.Sigma)
        else:
            self._cond = None

    def _condensation(self, fact) -> Condensation:
        """Sigma and PW for the ground's current factorisation (reference coefficients)."""
        if self._cond is None or self._cond.fact is not fact:
            self._cond = self.lined_system.condensation(fact, self.stiffness.reference, self.survey.P)
        return self._cond

    def release(self) -> None:
        self.stiffness.release()
        if self.lined_system is not None:
            self.lined_system.release()
        self._cond, self._sol = None, None

    def _solve(self, fact, s: float, rhs, coords: np.ndarray | None = None) -> np.ndarray:
        return self.stiffness.solve(fact, s, rhs, coords)

    # ------------------------------------------------------------------ forward
    def _solution(self, values: Mapping) -> _Solution:
        key = tuple(sorted(values.items()))
        sol = self._sol
        if sol is not None and sol.key == key and sol.fact is self.stiffness.current:
            return sol
        st = self.ground.state(self._ground_values(values))
        fact, s = self.stiffness.factorised(st.coeffs, lambda: self.fe.matrix(st.coeffs))
        self.counters.forward_runs += 1
        coords = np.concatenate([st.sigma_v, st.sigma_h])
        f = self.fe.load(st.sigma_v, st.sigma_h)
        w0 = self._solve(fact, s, f, coords)
        P = self.survey.P
        Y = np.zeros((self.survey.m, 2))
        Y[:, 0] = P @ w0
        sol = _Solution(key, st, fact, s, coords, f, w0, Y, self.plan.weights(values))
        if self.lined:
            sol.ring_coeffs = self.ring.coefficients(values).real
            # condensed while the ground's factorisation is the first (or the condensation's own)
            if (self._cond is not None and self._cond.fact is fact) or \
                    (self.lined_system.condense and self.stiffness.made <= 1):
                cond = self._condensation(fact)
                S = self.ring.condensed(sol.ring_coeffs)
                sol.interface = Interface(cond, s, S)
                sol.z_w = sol.interface.solve(w0[self.ring.wall_dofs])
                Y[:, 1] = Y[:, 0] - sol.interface.PW @ (S @ sol.z_w)
            else:  # the ground keeps changing: factorise the lined configuration itself
                self._cond = None
                lf, ls = self.lined_system.factorised(st.coeffs, sol.ring_coeffs)
                rhs = np.concatenate([f, np.zeros(len(self.ring.i))])
                wl = self._solve(lf, ls, rhs, coords)
                sol.direct = (lf, ls, wl)
                sol.w1 = wl[:self.fe.nfree]
                sol.z_w = wl[self.ring.wall_dofs]
                Y[:, 1] = P @ sol.w1
        self._sol = sol
        return sol

    def _w1(self, sol: _Solution) -> np.ndarray:
        """w_1 = K_g^-1 (f - U S z_w) on the free dofs (one back-substitution, on demand)."""
        if sol.w1 is None:
            rhs = sol.f.copy()
            rhs[self.ring.wall_dofs] -= sol.interface.S @ sol.z_w
            sol.w1 = self._solve(sol.fact, sol.s, rhs)
        return sol.w1

    def stage_displacements(self, values: Mapping) -> np.ndarray:
        """u_k on the free dofs after every stage (nstages, nfree)."""
        with sequential_blas():
            sol = self._solution(values)
        out = np.outer(sol.a[:, 0], sol.w0)
        if self.lined:
            out += np.outer(sol.a[:, 1], self._w1(sol))
        return out

    def _readings(self, values: Mapping, wrt: Sequence[str]) -> Prediction:
        with sequential_blas():
            return self._readings_of(values, wrt)

    def _readings_of(self, values: Mapping, wrt: Sequence[str]) -> Prediction:
        sol = self._solution(values)
        rows = self.domain.row_stage
        x = np.einsum("ic,ic->i", sol.a[rows], sol.Y)
        if not wrt:
            return Prediction(x)
        A = np.zeros((len(x), len(wrt)))
        ground = [j for j, n in enumerate(wrt) if not self.plan.knows(n)]
        for j, name in enumerate(wrt):
            if name in self.plan.values:
                A[:, j] = np.einsum("ic,ic->i", self.plan.weights_derivative(name)[rows], sol.Y)
            elif name in self.plan.lining_names():
                A[:, j] = sol.a[rows, 1] * self._lining_column(sol, values, name)
        if ground:
            dY = self._ground_columns(sol, values, [wrt[j] for j in ground])
            for k, j in enumerate(ground):
                A[:, j] = np.einsum("ic,ic->i", sol.a[rows], dY[:, :, k])
        return Prediction(x, A)

    def _lined_column(self, sol: _Solution, Pt: np.ndarray, SUt: np.ndarray) -> np.ndarray:
        """P K_1^-1 q from P K_g^-1 q and Sigma U^t K_g^-1 q (the interface equations)."""
        it = sol.interface
        z = it.solve_sigma(SUt)
        return Pt - it.PW @ (it.S @ z)

    def _lining_column(self, sol: _Solution, values: Mapping, name: str) -> np.ndarray:
        """d(P w_1)/dv for a lining value: q = -U dS U^t w_1."""
        if not self.lined:
            return np.zeros(self.survey.m)
        v = dict(values)
        h = COMPLEX_STEP * max(1.0, abs(values[name]))
        v[name] = values[name] + 1j * h
        dcoeffs = self.ring.coefficients(v).imag / h
        if sol.direct is not None:  # K_L^-1 (-dK_ring w_1) on the assembled system
            lf, ls, wl = sol.direct
            n = len(wl)
            rhs = -self.fe.symmetric_product(self.lined_system.embed_ring(self.ring.fe.matrix(dcoeffs), n), wl)
            return self.survey.P @ self._solve(lf, ls, rhs)[:self.fe.nfree]
        mu = self.ring.condensed_derivative(sol.ring_coeffs, dcoeffs) @ sol.z_w
        it = sol.interface  # q = -U mu: P K_g^-1 q = -PW mu, Sigma U^t K_g^-1 q = -mu
        return self._lined_column(sol, -it.PW @ mu, -mu)

    def _ground_columns(self, sol: _Solution, values: Mapping, names: list[str]) -> np.ndarray:
        """d(P w_c)/dv (m, 2, len(names)) for ground values (eqns 34-42 for each configuration)."""
        st, fact, s = sol.state, sol.fact, sol.s
        n = len(names)
        out = np.zeros((self.survey.m, 2, n))
        T0 = np.empty((self.fe.nfree, n))  # K_g^-1 (df/dv - dK_g/dv w_0)
        alphas: list[float | None] = []
        keyed, raw, lined_raw = [], [], []
        derivs = self.ground.derivatives(self._ground_values(values), names)
        for j, d in enumerate(derivs):
            r = self.fe.load(d.sigma_v, d.sigma_h)
            dcoords = np.concatenate([d.sigma_v, d.sigma_h])
            alpha = proportion(d.coeffs, st.coeffs) if np.any(d.coeffs) else 0.0
            alphas.append(alpha)
            if alpha is not None:  # dK/dv = alpha K: dK/dv w_0 = alpha f (eqn 42)
                keyed.append((j, r - alpha * sol.f, dcoords - alpha * sol.coords))
            else:
                dK = self.fe.matrix(d.coeffs)
                raw.append((j, r - self.fe.symmetric_product(dK, sol.w0)))
                if self.lined:
                    lined_raw.append((j, r, dK))
        if keyed:
            T0[:, [j for j, _, _ in keyed]] = self._solve(fact, s, np.column_stack([r for _, r, _ in keyed]),
                                                          np.column_stack([c for _, _, c in keyed]))
        if raw:
            T0[:, [j for j, _ in raw]] = self._solve(fact, s, np.column_stack([r for _, r in raw]))
        P = self.survey.P
        out[:, 0, :] = P @ T0
        if not self.lined:
            return out
        if sol.direct is not None:  # K_L^-1 (df/dv - dK_g/dv w_1) on the assembled system
            lf, ls, wl = sol.direct
            n, ni = self.fe.nfree, len(self.ring.i)
            keys, raws = [], []
            for j, d in enumerate(derivs):
                r = self.fe.load(d.sigma_v, d.sigma_h)
                if np.any(d.coeffs):
                    rhs = r - self.fe.symmetric_product(self.fe.matrix(d.coeffs), sol.w1)
                    raws.append((j, np.concatenate([rhs, np.zeros(ni)])))
                else:  # a load only (K0, the release): in the span cache
                    keys.append((j, np.concatenate([r, np.zeros(ni)]), np.concatenate([d.sigma_v, d.sigma_h])))
            if keys:
                T = self._solve(lf, ls, np.column_stack([r for _, r, _ in keys]), np.column_stack([c for _, _, c in keys]))
                out[:, 1, [j for j, _, _ in keys]] = P @ T[:n]
            if raws:
                T = self._solve(lf, ls, np.column_stack([r for _, r in raws]))
                out[:, 1, [j for j, _ in raws]] = P @ T[:n]
            return out
        it, U = sol.interface, self.ring.wall_dofs
        lam = it.S @ sol.z_w
        for j, alpha in enumerate(alphas):
            if alpha is None:
                continue  # below
            Pt = out[:, 0, j] + alpha * (it.PW @ lam)  # K_g^-1 (df/dv - alpha K_g w_1) = t_0 + alpha W lambda
            SUt = it.Sigma @ T0[U, j] + alpha * lam  # Sigma U^t W lambda = lambda
            out[:, 1, j] = self._lined_column(sol, Pt, SUt)
        if lined_raw:
            w1 = self._w1(sol)
            rhs = np.column_stack([r - self.fe.symmetric_product(dK, w1) for _, r, dK in lined_raw])
            T1 = self._solve(fact, s, rhs)
            for k, (j, _, _) in enumerate(lined_raw):
                out[:, 1, j] = self._lined_column(sol, P @ T1[:, k], it.Sigma @ T1[U, k])
        return out

    # ------------------------------------------------------------------ fields and the lining
    def _ring_unit(self, sol: _Solution) -> np.ndarray:
        """The ring's dofs (ring-local) per unit release on the lined configuration."""
        if sol.direct is not None:
            wl = sol.direct[2]
            free = wl[self.lined_system.augmented_index()]
            return self.ring.fe.expand(free)
        self.ring.condensed(sol.ring_coeffs)
        return self.ring.ring_displacement(sol.z_w)

    def lining_forces(self, values: Mapping) -> LiningForces | None:
        """N, V, M around the lining and its centreline's movement after every stage it acts in."""
        if not self.lined:
            return None
        with sequential_blas():
            sol = self._solution(values)
        ring = self.ring
        unit = self._ring_unit(sol)
        N1, V1, M1 = ring.section_forces(unit, sol.ring_coeffs)
        d1 = ring.centreline_displacement(unit)
        ks = list(range(self.plan.installed_at, len(self.plan.names)))
        a = sol.a[ks, 1]
        name = self.plan.lining_name
        return LiningForces(name, ring.spec.thickness, float(values[f"E[{name}]"]), float(values[f"nu[{name}]"]),
                            ring.mesh.centreline, [self.plan.names[k] for k in ks], ring.section_angle,
                            ring.section_arc, ring.section_points, np.outer(a, N1), np.outer(a, V1), np.outer(a, M1),
                            a[:, None, None] * d1[None], {k: float(v) for k, v in values.items()})

    def field(self, values: Mapping) -> Field:
        """The ground (and the lining, as more elements) after the last stage; the displacement
        after every stage as point data `displacement[stage]`. The lining's nodes are drawn where
        the wall was when it was installed plus its movement since."""
        U = self.stage_displacements(values)
        full = [self.fe.expand(u).reshape(-1, 2) for u in U]
        stress = self.domain.elastic_stress(self._ground_values(values), full[-1].ravel())
        cell = {"stress_xx": stress[:, 0], "stress_yy": stress[:, 1], "stress_xy": stress[:, 2]}
        if not self.lined:
            point = {f"displacement[{n}]": u for n, u in zip(self.stages, full)} if len(self.stages) > 1 else {}
            return Field(self.mesh, full[-1], cell, point)
        sol = self._solution(values)
        ring, rm = self.ring, self.ring.mesh
        unit = self._ring_unit(sol).reshape(-1, 2)
        inner = np.arange(rm.n_wall, len(rm.nodes))
        wall_of = np.tile(np.arange(rm.n_wall), len(rm.radii) - 1)  # wall position of each inner node
        k0 = self.plan.installed_at
        at_install = full[k0 - 1][rm.wall_nodes] if k0 > 0 else np.zeros((rm.n_wall, 2))
        moved = []
        for k, u in enumerate(full):
            if k < k0:  # not installed yet: drawn riding on the wall
                ring_u = u[rm.wall_nodes][wall_of]
            else:
                ring_u = at_install[wall_of] + sol.a[k, 1] * unit[inner]
            moved.append(np.vstack([u, ring_u]))
        nn = len(self.mesh.nodes)
        glob = np.concatenate([rm.wall_nodes, nn + np.arange(len(inner))])
        mesh = Mesh(np.vstack([self.mesh.nodes, rm.nodes[inner]]),
                    np.vstack([self.mesh.triangles, glob[rm.triangles]]),
                    np.concatenate([self.mesh.region, np.full(len(rm.triangles), len(self.mesh.region_names),
                                                              self.mesh.region.dtype)]),
                    tuple(self.mesh.region_names) + (ring.spec.name,), self.mesh.tunnel_edges,
                    self.mesh.key + "+lining")
        rs = ring.element_stress(sol.a[-1, 1] * self._ring_unit(sol), ring.coefficients(values).real)
        cell = {k: np.concatenate([v, rs[:, i]]) for i, (k, v) in enumerate(cell.items())}
        point = {f"displacement[{n}]": u for n, u in zip(self.stages, moved)}
        return Field(mesh, moved[-1], cell, point)
