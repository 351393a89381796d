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
        linings = {}
        for name in self.plan.linings:
            linings[name] = np.array(plane_strain_isotropic(values[f"E[{name}]"], values[f"nu[{name}]"]))
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
                "fractions": self.plan.fractions(values)}

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
                    "fractions": self.plan.fractions_derivative(name)}
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
        for j in range(k + 1):
            step = plan.steps[j]
            for n in step.install:
                mat[mesh.band == names.index(n)] = 1 + names.index(n)
            for n in step.remove:
                mat[mesh.band == names.index(n)] = -1
        return mat

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

    def _factor(self, k: int, mat: np.ndarray, coeffs: np.ndarray, act: np.ndarray):
        key = mat.tobytes()
        cache = self.factors.get(key)
        if cache is None:
            cache = self.factors[key] = FactorCache(self.counters, self.backend)
        return cache.factorised(coeffs, lambda: self.fe.matrix(coeffs)[act][:, act].tocsr())

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
        self.counters.forward_runs += 1
        for k, step in enumerate(plan.steps):
            mat = self._material(k)
            if step.excavate or step.remove:
                # removed, or ground replaced by a lining installed in the stage that excavates it (its
                # ground stress is released like the rest of the part's; the lining starts stress-free)
                gone = np.flatnonzero((prev_mat >= 0) & (mat != prev_mat))
                loads.append(self._removal_load(gone, prev_mat, st, u, uref) * np.real(release))
                dl = np.zeros((n, nw))
                for j, d in enumerate(dsts):
                    dl[:, j] = (self._removal_load(gone, prev_mat, st, u, uref, d, du[:, j],
                                                   {m: duref[m][:, j] for m in duref}) * np.real(release)
                                + loads[-1] / np.real(release) * d["release"])
                dloads.append(dl)
            for name in step.install:
                uref[name], duref[name] = u.copy(), du.copy()
            inc = frac[k] - (frac[k - 1] if k else 0.0)
            if np.any(inc != 0):
                g = sum(inc[i] * loads[i] for i in range(len(loads)) if inc[i] != 0)
                dg = np.zeros((n, nw))
                for j, d in enumerate(dsts):
                    dinc = d["fractions"][k] - (d["fractions"][k - 1] if k else 0.0)
                    for i in range(len(loads)):
                        dg[:, j] += inc[i] * dloads[i][:, j] + dinc[i] * loads[i]
                coeffs = self._coeffs(mat, st)
                act = self._active(mat)
                fact, s = self._factor(k, mat, np.real(coeffs), act)
                from geoback.physics.stiffness import counted_solve

                step_u = counted_solve(self.counters, fact, s, g[act][:, None])[:, 0]
                u[act] += step_u
                if nw:
                    rhs = dg[act].copy()
                    full_step = np.zeros(n)
                    full_step[act] = step_u
                    real = np.real(coeffs)
                    for j, d in enumerate(dsts):
                        dc = self._coeffs(mat, d)
                        if not np.any(dc):
                            continue
                        alpha = proportion(dc, real)
                        if alpha is not None:  # dK = alpha K (a modulus scaling the whole configuration): dK du = alpha g
                            rhs[:, j] -= alpha * g[act]
                        else:
                            dK = fe.matrix(dc)[act][:, act]
                            rhs[:, j] -= FEModel.symmetric_product(dK.tocsr(), step_u)
                    du[act] += counted_solve(self.counters, fact, s, rhs)
            elif nw:
                pass
            U[k] = u
            if nw:
                dU[k] = du
            prev_mat = mat
        run = _Run(key, U, dU, wrt)
        self._memo["run"] = run
        return run

    # ------------------------------------------------------------------ the interface
    def stage_displacements(self, values: Mapping) -> np.ndarray:
        return self._run(values, ()).u

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
        return Prediction(x, A)

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
        ground = mat == 0
        out[ground] += np.column_stack([k0 * sv, sv, np.zeros_like(sv)])[ground]
        for i, n in enumerate(self.mesh.band_names):  # a lining's stress from its installation on
            sel = mat == 1 + i
            if sel.any():
                k_in = next(j for j, s in enumerate(self.plan.steps) if n in s.install)
                ref = fe.element_strain(fe.expand(run.u[k_in - 1] if k_in else np.zeros(fe.nfree)))
                out[sel] -= np.column_stack([d11 * ref[:, 0] + d12 * ref[:, 1], d12 * ref[:, 0] + d22 * ref[:, 1],
                                             d33 * ref[:, 2]])[sel]
        out[mat < 0] = np.nan
        return out

    def field(self, values: Mapping) -> Field:
        run = self._run(values, ())
        u = self.fe.expand(run.u[-1])
        stress = self.element_stress(values)
        point_data = {f"displacement[{s}]": self.fe.expand(run.u[k]).reshape(-1, 2) for k, s in enumerate(self.stages)}
        return Field(self.mesh, u.reshape(-1, 2), {"stress_xx": stress[:, 0], "stress_yy": stress[:, 1],
                                                   "stress_xy": stress[:, 2]}, point_data)
