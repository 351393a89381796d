"""Staged excavation of openings of any shape by element removal, linings by element activation, with
linear-elastic ground: readings at every stage and their exact sensitivities.

The section (``case/layout.py``) is meshed inside its openings (``section_mesh.py``); construction
(``case/sequence.py``) removes elements and activates others. Removing a set S of elements loads the
ground that remains with what S exerted on it: the internal force of S's current stress less S's
weight,

    f_S = sum_{e in S} int_e B^t sigma dV - int_e N^t b dV,   b = (0, -gamma),

on the nodes that remain (on nodes inside S it vanishes: S was in equilibrium). For the geostatic
stress this equals the traction release of eqn 33 (divergence theorem); later, sigma = sigma_0 +
D eps(u) holds what earlier stages did, so staged removal of linear ground equals removal at once.
A stage's load is released in the fractions of ``Sequence.fractions`` (beta), each increment solved
with the stiffness of the stage's configuration (the active ground, the installed linings) on its
active dofs:

    u_k = u_(k-1) + K_k^-1 sum_g (beta_kg - beta_(k-1)g) f_g.

A lining is its band of elements switched to the lining's material, stress-free when installed (its
stress is D_l eps(u - u_install)); removing it releases that stress like any removal.

Sensitivities are exact (direct differentiation of the recursion, eqn 34 stage by stage):
d(du_k) = K_k^-1 (dg_k - dK_k du_k), dg_k through dbeta, df_g = int B^t (dsigma_0 + dD eps(u) + D eps(du))
- int N^t db, with dD, dsigma_0, dgamma by complex step of the ground's map (exact to rounding).
One factorisation per configuration; a configuration whose stiffness is a multiple of the one it
factorised (one modulus, no lining) reuses it (``stiffness.FactorCache``, eqns 41-42).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Mapping, Sequence as Seq

import numpy as np

from geoback.case.limits import QUANTITIES
from geoback.case.sequence import Sequence
from geoback.physics.domain import Domain
from geoback.physics.fem import FEModel
from geoback.physics.ground import COMPLEX_STEP, Ground, plane_strain_isotropic
from geoback.physics.names import Names
from geoback.physics.simulation import Counters, Field, Prediction, Simulation, stage_survey
from geoback.physics.stiffness import FactorCache, proportion

NEVER = 1e9  # removal stage of an element no stage removes


class UnitWeights:
    """Named unit weights: ``gamma`` (the ground's) and ``gamma[layer]`` for a layer that gives its own
    (a names source for ``Names``)."""

    def __init__(self, case):
        self.case = case
        self.layers = [ly.name for ly in case.ground.layers]
        self.own = {ly.name: float(ly.unit_weight) for ly in case.ground.layers if ly.unit_weight is not None}

    def quantities(self) -> dict[str, float]:
        out = {"gamma": float(self.case.ground.unit_weight)}
        out.update({f"gamma[{n}]": v for n, v in self.own.items()})
        return out

    def knows(self, name: str) -> bool:
        return name in self.quantities()

    def canonical(self, name: str) -> str | None:
        if name == "gamma" and len(self.layers) == 1 and self.layers[0] in self.own:
            return f"gamma[{self.layers[0]}]"
        return name if self.knows(name) else None

    def unit(self, name: str) -> str | None:
        return QUANTITIES["gamma"][0] if self.knows(name) else None

    def limits(self, name: str, values: Mapping):
        return QUANTITIES["gamma"][1] if self.knows(name) else None

    def of_layers(self, values: Mapping) -> list:
        return [values.get(f"gamma[{n}]", values["gamma"]) if n in self.own else values["gamma"] for n in self.layers]


@dataclass
class _Run:
    """A forward run: displacement after every stage (nstages, nfree), and its sensitivities."""

    key: tuple
    u: np.ndarray
    du: np.ndarray | None
    wrt: tuple
    e_ref: np.ndarray = None  # each connector's shortening / elongation when it was locked
    de_ref: np.ndarray = None


class ExcavationSimulation(Simulation):
    """Openings of any shape excavated by element removal in stages (module docstring)."""

    reads_depth_offsets = False
    SHARED = ("factors", "_memo")

    def __init__(self, loaded, mesh=None, blocks=None, extensions: Mapping | None = None, backend: str | None = None):
        from geoback.physics.section_mesh import build_section_mesh
        from geoback.case import layout as lay

        case = loaded.case
        plan = Sequence.of(case)
        t0 = time.perf_counter()
        mesh = mesh or build_section_mesh(case)
        t1 = time.perf_counter()
        x0, x1, depth = lay.box(case.geometry)
        self.removed_at = self._removal_stage(mesh, plan)
        fe = FEModel(mesh, x1, depth, (0.0, 0.0), 1.0, x_min=x0, priority=self.removed_at)
        t2 = time.perf_counter()
        ground = Ground(case, -fe.centroid[:, 1], fe.region, np.zeros(0), extensions or {})
        survey = stage_survey(loaded, blocks, list(plan.names), fe)
        timings = {"mesh": t1 - t0, "assembly": t2 - t1, "observations": time.perf_counter() - t2}
        domain = Domain(loaded, mesh, fe, ground, plan, survey, Counters(), timings, backend)
        self.weights = UnitWeights(case)
        super().__init__(domain, Names(ground, plan, self.weights))
        self._check_survey()
        self.factors: dict = {}
        self._memo: dict = {"run": None}
        removable = np.flatnonzero((mesh.part >= 0) | (mesh.band >= 0))
        self._removable = removable
        self._local = -np.ones(fe.ne, np.int64)
        self._local[removable] = np.arange(len(removable))
        self._quad = fe.element_quadrature(removable) if len(removable) else None
        from geoback.physics.supports import operators

        self.connectors = dict(plan.connectors or {})
        self._C = operators(fe, self.connectors)
        self._installed = np.array([plan.installed_at(n) for n in self.connectors], int)

    # ------------------------------------------------------------------ set-up
    @staticmethod
    def _removal_stage(mesh, plan: Sequence) -> np.ndarray:
        """The stage that removes each element as ground (NEVER for ground no stage excavates)."""
        out = np.full(len(mesh.triangles), NEVER)
        for k, step in enumerate(plan.steps):
            for name in step.excavate:
                out[(mesh.part == mesh.part_names.index(name)) & (out == NEVER)] = k
        return out

    def _check_survey(self) -> None:
        """A reading of ground already excavated at its stage is refused, located (the point named)."""
        fe = self.fe
        stages = list(self.plan.names)
        for b in self.survey.blocks:
            elem, _ = fe.locate(b.points)
            k = stages.index(b.stage)
            gone = np.flatnonzero((elem >= 0) & (self.removed_at[np.maximum(elem, 0)] <= k))
            if len(gone):
                x, y = b.points[gone[0]]
                stage = stages[int(self.removed_at[elem[gone[0]]])]
                what = "point" if b.kind in ("points", "convergence") else "station"
                raise self.loaded.error(("instruments", b.index),
                                        f"{b.kind} '{b.name}': expected readings of the ground at stage '{b.stage}', "
                                        f"found {what} {gone[0] + 1} at ({x:g}, {y:g}) in ground excavated by stage "
                                        f"'{stage}'" + (" (mirrored from x < 0)" if self.loaded.case.geometry.model == "half"
                                                         else ""))

    @property
    def solver(self) -> str | None:
        for cache in self.factors.values():
            if cache.current is not None:
                return cache.current.backend
        return None

    def release(self) -> None:
        for cache in self.factors.values():
            cache.release()

    # ------------------------------------------------------------------ the ground's map
    def _state(self, values: Mapping) -> dict:
        """Everything the values change, complex-safe: ground coefficients (ne, 4), each lining's D,
        the geostatic stress at the removable elements' quadrature points, their unit weight, the
        release factor (the extension 'beta') and the fractions released."""
        ground, fe, mesh = self.ground, self.fe, self.mesh
        own = {k: v for k, v in values.items() if not (self.plan.knows(k) or self.weights.knows(k))}  # the ground's
        coeffs = ground.state(own).coeffs
        linings = {}  # every band's D: the linings' and the walls'
        for name in self.plan.bands:
            linings[name] = np.array(plane_strain_isotropic(values[f"E[{name}]"], values[f"nu[{name}]"]))
        springs = np.array([values[f"k[{n}]"] for n in self.connectors])
        preloads = np.array([values[f"preload[{n}]"] for n in self.connectors])
        gammas = self.weights.of_layers(values)
        dtype = complex if any(isinstance(v, complex) for v in values.values()) else float
        sig0 = gam = None
        release = 1.0
        if self._quad is not None:
            xq = self._quad[5]
            depth = -xq[..., 1]
            layer = np.repeat(fe.region[self._removable][:, None], depth.shape[1], axis=1)
            sv = -self._overburden(depth, gammas, dtype)
            fields = ground.fields(own, depth.ravel(), layer.ravel())
            k0 = fields.k0.reshape(depth.shape)
            release = fields.release
            sig0 = np.stack([k0 * sv, sv, np.zeros_like(sv)], axis=-1)
            gam = np.array(gammas, dtype=dtype)[fe.region[self._removable]]
        return {"coeffs": coeffs, "linings": linings, "sigma0": sig0, "gamma": gam, "release": release,
                "fractions": self.plan.fractions(values), "springs": springs, "preloads": preloads}

    def _overburden(self, depth: np.ndarray, gammas, dtype) -> np.ndarray:
        tops = self.ground.tops
        bottoms = self.ground.bottoms
        out = np.zeros(depth.shape, dtype)
        for i, g in enumerate(gammas):
            out = out + g * np.clip(depth - tops[i], 0.0, bottoms[i] - tops[i])
        return out

    def _state_derivative(self, values: Mapping, name: str, base: dict) -> dict:
        if name in self.plan.values:  # a release: only the fractions change (linearly)
            return {"coeffs": np.zeros_like(base["coeffs"]), "linings": {k: np.zeros(4) for k in base["linings"]},
                    "sigma0": None if base["sigma0"] is None else np.zeros_like(base["sigma0"]),
                    "gamma": None if base["gamma"] is None else np.zeros_like(base["gamma"]), "release": 0.0,
                    "fractions": self.plan.fractions_derivative(name), "springs": np.zeros(len(self.connectors)),
                    "preloads": np.zeros(len(self.connectors))}
        v = dict(values)
        h = COMPLEX_STEP * max(1.0, abs(values[name]))
        v[name] = values[name] + 1j * h
        s = self._state(v)
        out = {}
        for k, val in s.items():
            if k == "linings":
                out[k] = {n: np.imag(d) / h for n, d in val.items()}
            elif val is None:
                out[k] = None
            else:
                out[k] = np.imag(np.asarray(val)) / h
        return out

    # ------------------------------------------------------------------ configurations
    def _material(self, k: int) -> np.ndarray:
        """Material of every element during stage k's release: -1 off, 0 ground, 1 + i lining i."""
        cache = self._memo.setdefault("material", {})
        if k not in cache:
            cache[k] = self._materials(k)
        return cache[k]

    def _materials(self, k: int) -> np.ndarray:
        mesh, plan = self.mesh, self.plan
        mat = np.where(self.removed_at <= k, -1, 0)
        names = list(mesh.band_names)
        for n in plan.walls or {}:  # a wall in place from the start
            if plan.installed_at(n) < 0:
                mat[mesh.band == names.index(n)] = 1 + names.index(n)
        for j in range(k + 1):
            step = plan.steps[j]
            for n in step.install:
                if n in names:
                    mat[mesh.band == names.index(n)] = 1 + names.index(n)
            for n in step.remove:
                mat[mesh.band == names.index(n)] = -1
        return mat

    def _springs_at(self, k: int) -> np.ndarray:
        """Which connectors act at stage k (installed by then)."""
        return self._installed <= k

    def _coeffs(self, mat: np.ndarray, st: dict) -> np.ndarray:
        out = np.where((mat == 0)[:, None], st["coeffs"], 0.0)
        for i, n in enumerate(self.mesh.band_names):
            d = st["linings"].get(n)
            if d is not None and np.any(mat == 1 + i):
                out = np.where((mat == 1 + i)[:, None], np.asarray(d)[None, :], out)
        return out

    def _active(self, mat: np.ndarray) -> np.ndarray:
        """Free dofs (indices into the free numbering) of nodes that active elements hold (remembered by
        configuration)."""
        key = mat.tobytes()
        cache = self._memo.setdefault("active", {})
        if key not in cache:
            cache[key] = self._active_dofs(mat)
        return cache[key]

    def _active_dofs(self, mat: np.ndarray) -> np.ndarray:
        fe = self.fe
        nodes = np.unique(fe.tri[mat >= 0])
        dofs = np.sort(np.concatenate([2 * nodes, 2 * nodes + 1]))
        idx = fe.free_index[dofs]
        return idx[idx >= 0]

    def _factor(self, mat: np.ndarray, coeffs: np.ndarray, act: np.ndarray, on: np.ndarray, ks: np.ndarray):
        """The factorisation of the configuration (elements `mat`, connectors `on` of stiffness `ks`) and
        its scale (a configuration whose coefficients and springs are a multiple of the factorised one's
        reuses it)."""
        key = (mat.tobytes(), on.tobytes())
        cache = self.factors.get(key)
        if cache is None:
            cache = self.factors[key] = FactorCache(self.counters, self.backend)
        springs = np.real(ks)[on]

        def assemble():
            K = self.fe.matrix(coeffs)[act][:, act].tocsr()
            if on.any():
                from geoback.physics.supports import spring_matrix

                K = (K + spring_matrix(self._C[on], springs, act)).tocsr()
            return K

        return cache.factorised(np.concatenate([np.ravel(coeffs), springs]), assemble)

    # ------------------------------------------------------------------ removal loads
    def _removal_load(self, elems: np.ndarray, mat: np.ndarray, st: dict, u: np.ndarray, uref: dict,
                      dst: dict | None = None, du: np.ndarray | None = None, duref: dict | None = None) -> np.ndarray:
        """f_S on the free dofs (module docstring) for the elements `elems` in their material `mat`
        before removal, u the free-dof displacement; with `dst`, `du`, `duref` its derivative instead."""
        fe = self.fe
        exx, eyy, gxy, w, N, _ = self._quad
        loc = self._local[elems]
        ex, ey, gx, ww = exx[loc], eyy[loc], gxy[loc], w[loc]
        edofs = fe.edofs[elems]

        def strain(vec_full):
            ue = vec_full[edofs]  # (n, 2nb)
            return (np.einsum("eaq,ea->eq", ex, ue), np.einsum("eaq,ea->eq", ey, ue), np.einsum("eaq,ea->eq", gx, ue))

        m = mat[elems]
        ground = m == 0
        coeffs_src = st if dst is None else dst
        D = np.zeros((len(elems), 4))
        D[ground] = np.real(coeffs_src["coeffs"][elems[ground]])
        for i, n in enumerate(self.mesh.band_names):
            sel = m == 1 + i
            if sel.any():
                D[sel] = coeffs_src["linings"][n]
        # strain of the displacement each element's stress is measured from
        full = fe.expand(u)
        e_u = strain(full)
        rel = [np.where(ground[:, None], c, 0.0) for c in e_u]
        for i, n in enumerate(self.mesh.band_names):
            sel = m == 1 + i
            if sel.any():
                e_ref = strain(fe.expand(uref[n]))
                for c in range(3):
                    rel[c][sel] = e_u[c][sel] - e_ref[c][sel]
        if dst is None:
            sxx = D[:, 0, None] * rel[0] + D[:, 2, None] * rel[1]
            syy = D[:, 2, None] * rel[0] + D[:, 1, None] * rel[1]
            sxy = D[:, 3, None] * rel[2]
            gam = np.zeros(len(elems))
            if st["sigma0"] is not None:
                s0 = np.real(st["sigma0"][loc])
                sxx = sxx + np.where(ground[:, None], s0[..., 0], 0.0)
                syy = syy + np.where(ground[:, None], s0[..., 1], 0.0)
                gam = np.where(ground, np.real(st["gamma"][loc]), 0.0)
        else:
            # d sigma = dD eps + D d eps (+ d sigma0 for ground)
            D0 = np.zeros((len(elems), 4))
            D0[ground] = st["coeffs"][elems[ground]].real
            for i, n in enumerate(self.mesh.band_names):
                sel = m == 1 + i
                if sel.any():
                    D0[sel] = st["linings"][n].real
            de_u = strain(fe.expand(du))
            drel = [np.where(ground[:, None], c, 0.0) for c in de_u]
            for i, n in enumerate(self.mesh.band_names):
                sel = m == 1 + i
                if sel.any():
                    de_ref = strain(fe.expand(duref[n]))
                    for c in range(3):
                        drel[c][sel] = de_u[c][sel] - de_ref[c][sel]
            sxx = D[:, 0, None] * rel[0] + D[:, 2, None] * rel[1] + D0[:, 0, None] * drel[0] + D0[:, 2, None] * drel[1]
            syy = D[:, 2, None] * rel[0] + D[:, 1, None] * rel[1] + D0[:, 2, None] * drel[0] + D0[:, 1, None] * drel[1]
            sxy = D[:, 3, None] * rel[2] + D0[:, 3, None] * drel[2]
            gam = np.zeros(len(elems))
            if dst["sigma0"] is not None:
                s0 = dst["sigma0"][loc]
                sxx = sxx + np.where(ground[:, None], s0[..., 0], 0.0)
                syy = syy + np.where(ground[:, None], s0[..., 1], 0.0)
                gam = np.where(ground, dst["gamma"][loc], 0.0)
        fe_local = (np.einsum("eaq,eq->ea", ex, sxx * ww) + np.einsum("eaq,eq->ea", ey, syy * ww)
                    + np.einsum("eaq,eq->ea", gx, sxy * ww))
        fe_local[:, 1::2] += gam[:, None] * np.einsum("bq,eq->eb", N, ww)  # - int N^t b, b = (0, -gamma)
        out = np.zeros(fe.ndof)
        np.add.at(out, edofs.ravel(), fe_local.ravel())
        return out[fe.free]

    # ------------------------------------------------------------------ the stages
    def _run(self, values: Mapping, wrt: tuple) -> _Run:
        key = (tuple(sorted((k, float(v)) for k, v in values.items())), wrt)
        memo = self._memo.get("run")
        if memo is not None and memo.key[0] == key[0] and set(wrt) <= set(memo.wrt):
            return memo
        from geoback.physics.solver import sequential_blas

        with sequential_blas():
            return self._stages(values, key, wrt)

    def _stages(self, values: Mapping, key: tuple, wrt: tuple) -> _Run:
        """The stage recursion (module docstring) at `values`, with du/dv for `wrt`."""
        fe, plan = self.fe, self.plan
        st = self._state(values)
        dsts = [self._state_derivative(values, n, st) for n in wrt]
        nw = len(wrt)
        n = fe.nfree
        u = np.zeros(n)
        du = np.zeros((n, nw))
        U = np.zeros((len(plan.steps), n))
        dU = np.zeros((len(plan.steps), n, nw)) if nw else None
        uref, duref = {}, {}
        loads, dloads = [], []
        release = st["release"]
        frac = np.real(st["fractions"])
        prev_mat = self._material(-1)
        ks = np.real(st["springs"])
        e_ref = np.zeros(len(self.connectors))  # each connector's e at installation (after its preload)
        de_ref = np.zeros((len(self.connectors), nw))
        self.counters.forward_runs += 1
        for k, step in enumerate(plan.steps):
            mat = self._material(k)
            if step.excavate or step.remove:
                # removed, or ground replaced by a lining installed in the stage that excavates it (its
                # ground stress is released like the rest of the part's; the lining starts stress-free);
                # a wall installed in ground that stays releases nothing
                gone = np.flatnonzero((prev_mat >= 0) & (mat != prev_mat) & ((self.removed_at <= k) | (mat < 0)))
                loads.append(self._removal_load(gone, prev_mat, st, u, uref) * np.real(release))
                dl = np.zeros((n, nw))
                for j, d in enumerate(dsts):
                    dl[:, j] = (self._removal_load(gone, prev_mat, st, u, uref, d, du[:, j],
                                                   {m: duref[m][:, j] for m in duref}) * np.real(release)
                                + loads[-1] / np.real(release) * d["release"])
                dloads.append(dl)
            for name in step.install:
                uref[name], duref[name] = u.copy(), du.copy()
            new = self._installed == k
            if new.any():  # props and anchors: jacked to their preload (the new ones not yet acting), then locked
                before = self._springs_at(k - 1)
                P = np.real(st["preloads"]) * new
                g = -(self._C.T @ P)
                dg = np.column_stack([-(self._C.T @ (d["preloads"] * new)) for d in dsts]) if nw else np.zeros((n, 0))
                if np.any(g != 0) or np.any(dg != 0):
                    self._solve_increment(mat, st, dsts, before, ks, g, dg, u, du)
                e_ref[new] = self._C[new] @ u
                if nw:
                    de_ref[new] = self._C[new] @ du
            inc = frac[k] - (frac[k - 1] if k else 0.0)
            if np.any(inc != 0):
                g = sum(inc[i] * loads[i] for i in range(len(loads)) if inc[i] != 0)
                dg = np.zeros((n, nw))
                for j, d in enumerate(dsts):
                    dinc = d["fractions"][k] - (d["fractions"][k - 1] if k else 0.0)
                    for i in range(len(loads)):
                        dg[:, j] += inc[i] * dloads[i][:, j] + dinc[i] * loads[i]
                self._solve_increment(mat, st, dsts, self._springs_at(k), ks, g, dg, u, du)
            U[k] = u
            if nw:
                dU[k] = du
            prev_mat = mat
        run = _Run(key, U, dU, wrt, e_ref, de_ref)
        self._memo["run"] = run
        return run

    def _solve_increment(self, mat, st, dsts, on, ks, g, dg, u, du) -> None:
        """u += K^-1 g on the configuration's active dofs (elements `mat`, connectors `on`), and with it
        du += K^-1 (dg - dK du_step) (eqn 34): in place."""
        from geoback.physics.stiffness import counted_solve

        fe = self.fe
        coeffs = self._coeffs(mat, st)
        act = self._active(mat)
        real = np.real(coeffs)
        fact, s = self._factor(mat, real, act, on, ks)
        step_u = counted_solve(self.counters, fact, s, g[act][:, None])[:, 0]
        u[act] += step_u
        if not len(dsts):
            return
        rhs = dg[act].copy()
        full_step = np.zeros(fe.nfree)
        full_step[act] = step_u
        e_step = self._C[on] @ full_step if on.any() else np.zeros(0)
        ref = np.concatenate([real.ravel(), ks[on]])
        for j, d in enumerate(dsts):
            dc = self._coeffs(mat, d)
            dk = np.asarray(d["springs"])[on]
            if not (np.any(dc) or np.any(dk)):
                continue
            alpha = proportion(np.concatenate([dc.ravel(), dk]), ref)
            if alpha is not None:  # dK = alpha K (a modulus scaling the whole configuration): dK du = alpha g
                rhs[:, j] -= alpha * g[act]
                continue
            if np.any(dc):
                dK = fe.matrix(dc)[act][:, act]
                rhs[:, j] -= FEModel.symmetric_product(dK.tocsr(), step_u)
            if np.any(dk):
                rhs[:, j] -= (self._C[on].T @ (dk * e_step))[act]
        du[act] += counted_solve(self.counters, fact, s, rhs)

    # ------------------------------------------------------------------ the interface
    def stage_displacements(self, values: Mapping) -> np.ndarray:
        return self._run(values, ()).u

    def _solution(self, values: Mapping, wrt: tuple):
        """The forward run (u, du per stage, the connectors' locked e) whatever the ground."""
        return self._run(values, wrt)

    def _readings(self, values: Mapping, wrt: Seq[str]) -> Prediction:
        run = self._run(values, tuple(wrt))
        P = self.survey.P
        stage = self.domain.row_stage
        x = np.zeros(P.shape[0])
        A = np.zeros((P.shape[0], len(wrt))) if wrt else None
        for k in range(len(self.stages)):
            rows = np.flatnonzero(stage == k)
            if not len(rows):
                continue
            Pk = P[rows]
            x[rows] = Pk @ run.u[k]
            if wrt:
                cols = [run.wrt.index(n) for n in wrt]
                A[rows] = Pk @ run.du[k][:, cols]
        self._load_cells(values, wrt, run, x, A)
        return Prediction(x, A)

    def _load_cells(self, values: Mapping, wrt, run, x: np.ndarray, A: np.ndarray | None) -> None:
        """The rows of the load cells: the force of their prop or anchor (per prop), in place."""
        r0 = 0
        for b in self.survey.blocks:
            if b.kind == "load_cell":
                name = b.support
                k = list(self.stages).index(b.stage)
                f, df = self.connector_force(values, name, k, run, wrt)
                scale = self.connectors[name].per_support()
                x[r0:r0 + b.m] = scale * f
                if A is not None and len(wrt):
                    A[r0:r0 + b.m] = scale * df
            r0 += b.m

    def connector_force(self, values: Mapping, name: str, k: int, run=None, wrt: Seq[str] = ()):
        """Axial force per metre run N of a prop (compression) or anchor (tension) after stage k
        (``case/supports.py``: N = P + k (e - e_installed); 0 before it is installed), and dN/d(wrt)."""
        run = run or self._solution(values, tuple(wrt))
        i = list(self.connectors).index(name)
        if self._installed[i] > k:
            return 0.0, np.zeros(len(wrt))
        c = self._C[i]
        e = float((c @ run.u[k])[0]) - run.e_ref[i]
        stiff, pre = float(np.real(values[f"k[{name}]"])), float(np.real(values[f"preload[{name}]"]))
        N = pre + stiff * e
        dN = np.zeros(len(wrt))
        for j, n in enumerate(wrt):
            col = run.wrt.index(n)
            dN[j] = stiff * (float((c @ run.du[k][:, col])[0]) - run.de_ref[i, col])
            dN[j] += (n == f"preload[{name}]") + (n == f"k[{name}]") * e
        return N, dN

    def element_stress(self, values: Mapping, k: int | None = None) -> np.ndarray:
        """Mean total stress (sxx, syy, sxy) per element after stage k (default the last); NaN where
        the element is excavated."""
        run = self._run(values, ())
        k = len(self.stages) - 1 if k is None else k
        st = self._state(values)
        mat = self._material(k)
        fe = self.fe
        eps = fe.element_strain(fe.expand(run.u[k]))
        coeffs = np.real(self._coeffs(mat, st))
        d11, d22, d12, d33 = coeffs.T
        out = np.column_stack([d11 * eps[:, 0] + d12 * eps[:, 1], d12 * eps[:, 0] + d22 * eps[:, 1], d33 * eps[:, 2]])
        gammas = [float(np.real(g)) for g in self.weights.of_layers(values)]
        depth = -fe.centroid[:, 1]
        sv = -self._overburden(depth, gammas, float)
        own = {k: v for k, v in values.items() if not (self.plan.knows(k) or self.weights.knows(k))}
        k0 = np.real(self.ground.fields(own, depth, fe.region).k0)
        walls = np.isin(mat, [1 + i for i, n in enumerate(self.mesh.band_names) if n in (self.plan.walls or {})])
        ground = (mat == 0) | walls  # a wall keeps the ground stress it was installed in
        out[ground] += np.column_stack([k0 * sv, sv, np.zeros_like(sv)])[ground]
        ground_D = np.real(st["coeffs"]).T
        for i, n in enumerate(self.mesh.band_names):  # a band's stress from its installation on
            sel = mat == 1 + i
            if sel.any():
                k_in = self.plan.installed_at(n)
                ref = fe.element_strain(fe.expand(run.u[k_in - 1] if k_in > 0 else np.zeros(fe.nfree)))
                out[sel] -= np.column_stack([d11 * ref[:, 0] + d12 * ref[:, 1], d12 * ref[:, 0] + d22 * ref[:, 1],
                                             d33 * ref[:, 2]])[sel]
                if n in (self.plan.walls or {}):  # plus what the ground there had taken until then
                    g11, g22, g12, g33 = ground_D
                    out[sel] += np.column_stack([g11 * ref[:, 0] + g12 * ref[:, 1], g12 * ref[:, 0] + g22 * ref[:, 1],
                                                 g33 * ref[:, 2]])[sel]
        out[mat < 0] = np.nan
        return out

    # ------------------------------------------------------------------ walls and supports
    def wall_forces(self, values: Mapping, run=None):
        """Every wall's deflection, shear and bending moment after every stage (``supports.WallForces``),
        integrated across the wall from its stress (its increment since installation: the geostatic
        stress it was installed with bends nothing); None without walls."""
        from geoback.physics.supports import WallForces, section_forces

        if not self.plan.walls:
            return None
        run = run or self._solution(values, ())
        out = {}
        for name, band in self.plan.walls.items():
            depths = self._wall_depths(band)
            ops = self._memo.setdefault("wall_ops", {})
            if name not in ops:
                ops[name] = self._section_strain(band, depths)
            E, nu = float(np.real(values[f"E[{name}]"])), float(np.real(values[f"nu[{name}]"]))
            d11, d22, d12, d33 = plane_strain_isotropic(E, nu)
            k_in = self.plan.installed_at(name)
            Ix, ex, ey, gx = ops[name]
            M, V, ux = [], [], []
            for k in range(len(self.stages)):
                if k < k_in:
                    M.append(np.full(len(depths), np.nan)), V.append(np.full(len(depths), np.nan))
                    ux.append(np.full(len(depths), np.nan))
                    continue
                u = run.u[k] - (run.u[k_in - 1] if k_in > 0 else 0.0)
                e1, e2, e3 = ex @ u, ey @ u, gx @ u

                def stress(_pts, e1=e1, e2=e2, e3=e3):
                    return np.column_stack([d11 * e1 + d12 * e2, d12 * e1 + d22 * e2, d33 * e3])

                f = section_forces(band, depths, stress)
                V.append(f[:, 1]), M.append(f[:, 2]), ux.append(Ix @ run.u[k])
            out[name] = WallForces(name, depths, tuple(self.stages), np.array(ux), np.array(V), np.array(M))
        return out

    @staticmethod
    def _wall_depths(band) -> np.ndarray:
        length = band.toe - band.top
        n = max(41, int(math.ceil(length / 0.1)) + 1)
        eps = 1e-6 * length
        return np.linspace(band.top + eps, band.toe - eps, n)

    def _section_strain(self, band, depths):
        """Operators at the Gauss points across the wall at `depths`: u_x on the centreline, and the
        strains exx, eyy, gxy (``supports.section_points`` order)."""
        from geoback.physics.supports import section_points

        pts = section_points(band, depths)
        Dx, Dy = self.fe.interpolation(pts, derivative=0), self.fe.interpolation(pts, derivative=1)
        Ix, _ = self.fe.interpolation(np.column_stack([np.full(len(depths), band.x), -depths]))
        return Ix, Dx[0], Dy[1], (Dy[0] + Dx[1]).tocsr()

    def field(self, values: Mapping) -> Field:
        run = self._run(values, ())
        u = self.fe.expand(run.u[-1])
        stress = self.element_stress(values)
        point_data = {f"displacement[{s}]": self.fe.expand(run.u[k]).reshape(-1, 2) for k, s in enumerate(self.stages)}
        return Field(self.mesh, u.reshape(-1, 2), {"stress_xx": stress[:, 0], "stress_yy": stress[:, 1],
                                                   "stress_xy": stress[:, 2]}, point_data)
