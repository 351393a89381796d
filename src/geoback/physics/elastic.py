"""The one-step linear-elastic excavation: x(v) = P K(v)^-1 f(v) and exact sensitivities (eqns 31-42).

One factorisation per distinct stiffness: when the stiffness of new values is a multiple s of a
factorised one (one modulus, fixed nu: K = E k, eqn 41), u = k^-1 f / s reuses it. Every
sensitivity column is a back-substitution, du/dv = K^-1 (df/dv - dK/dv u) (eqn 34); when dK/dv is
itself a multiple of K (a modulus that scales the whole stiffness) dK/dv u = alpha f without a
matrix product (eqn 42). Loads are remembered by their wall stresses (the factorisation's span
cache keyed by them), so a load in the span of earlier ones costs no back-substitution.

Composition: the case's ``Domain`` (``domain.py``), the ground's ``FactorCache`` (``stiffness.py``)
and the last forward solution; names resolved by ``Names`` over the ground alone.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from geoback.case.loading import LoadedCase
from geoback.physics.domain import build_domain
from geoback.physics.fem import FEModel
from geoback.observation.instruments import InstrumentBlock
from geoback.physics.mesh import Mesh
from geoback.physics.names import Names
from geoback.physics.simulation import Field, Prediction, Simulation
from geoback.physics.stiffness import FactorCache, proportion


class _Load:
    """The excavation load f = -int N^t sigma0 n dS of a ground state, assembled on first use."""

    def __init__(self, fe: FEModel, state):
        self.fe, self.state, self._f = fe, state, None

    @property
    def vector(self) -> np.ndarray:
        if self._f is None:
            self._f = self.fe.load(self.state.sigma_v, self.state.sigma_h)
        return self._f


class Memo:
    """The last result computed and what it was computed for (`key`), kept by a component that a
    simulation shares with its views."""

    def __init__(self):
        self.key, self.value = None, None


class ElasticSimulation(Simulation):
    """A case meshed and assembled, predicting readings of its instruments for any values.

    Holds its ``Domain``, the ground's factorisation (``stiffness``, a ``FactorCache``) and the last
    forward solution (``_last``), both shared with its views (``surveying``)."""

    reads_depth_offsets = True
    SHARED = ("stiffness", "_last")

    def __init__(self, loaded: LoadedCase, mesh: Mesh | None = None, blocks: list[InstrumentBlock] | None = None,
                 extensions: Mapping | None = None, backend: str | None = None):
        if loaded.case.construction is not None:
            raise ValueError("a case with a construction section is a StagedSimulation (make_simulation chooses)")
        domain = build_domain(loaded, mesh, blocks, backend, extensions)
        super().__init__(domain, Names(domain.ground))
        self.stiffness = FactorCache(domain.counters, backend)
        self._last = Memo()  # values key -> forward solution of the last forward run

    @property
    def solver(self) -> str | None:
        fact = self.stiffness.current
        return fact.backend if fact is not None else None

    # ------------------------------------------------------------------ solves
    def release(self) -> None:
        """Drop the kept factorisation (what a code without reuse does before every solve)."""
        self.stiffness.release()

    def _forward(self, values: Mapping):
        """Ground state, factorisation, load and u at `values` (eqn 31). The last one is remembered:
        an optimiser asks for the sensitivities at the point it has just evaluated."""
        key = tuple(sorted(values.items()))
        last = self._last
        if last.key == key and self.stiffness.current is not None and self.stiffness.current is last.value[1]:
            return last.value
        st = self.ground.state(values)
        fact, s = self.stiffness.factorised(st.coeffs, lambda: self.fe.matrix(st.coeffs))
        self.counters.forward_runs += 1
        coords = np.concatenate([st.sigma_v, st.sigma_h])
        load = _Load(self.fe, st)  # assembled only if the span of earlier loads cannot answer
        u = self.stiffness.solve(fact, s, lambda cols: load.vector, coords)
        out = (st, fact, s, coords, load, u)
        last.key, last.value = key, out
        return out

    def displacement(self, values: Mapping) -> np.ndarray:
        """u on the free dofs for the given named values (eqn 31)."""
        return self._forward(values)[-1]

    def stage_displacements(self, values: Mapping) -> np.ndarray:
        return self.displacement(values)[None]

    def _readings(self, values: Mapping, wrt: Sequence[str]) -> Prediction:
        st, fact, s, coords, f, u = self._forward(values)  # f: the load (a _Load)
        P = self.survey.operator(values)  # read at the inclinometers' depth offsets, if any
        x = P @ u
        if not wrt:
            return Prediction(x)
        du = np.empty((self.fe.nfree, len(wrt)))
        keyed, raw = [], []  # sensitivities whose load is known by its wall stresses, and the others
        for j, d in enumerate(self.ground.derivatives(values, list(wrt))):
            dcoords = np.concatenate([d.sigma_v, d.sigma_h])
            alpha = proportion(d.coeffs, st.coeffs) if np.any(d.coeffs) else 0.0
            if alpha is not None:  # dK/dv = alpha K (a modulus scaling K): dK/dv u = alpha f (eqn 42)
                keyed.append((j, d, alpha, dcoords - alpha * coords))
            else:
                r = self.fe.load(d.sigma_v, d.sigma_h)
                raw.append((j, r - self.fe.symmetric_product(self.fe.matrix(d.coeffs), u)))
        if keyed:
            def rhs(cols):  # df/dv - alpha f, assembled for the columns the span cannot answer
                return np.column_stack([self.fe.load(keyed[c][1].sigma_v, keyed[c][1].sigma_h)
                                        - keyed[c][2] * f.vector for c in cols])

            cols = [j for j, _, _, _ in keyed]
            du[:, cols] = self.stiffness.solve(fact, s, rhs, np.column_stack([c for _, _, _, c in keyed]))
        if raw:
            du[:, [j for j, _ in raw]] = self.stiffness.solve(fact, s, np.column_stack([r for _, r in raw]))
        return Prediction(x, np.asarray(P @ du))

    # ------------------------------------------------------------------ fields
    def element_stress(self, values: Mapping, u_full: np.ndarray) -> np.ndarray:
        """Total stress (sxx, syy, sxy) per element: initial geostatic + excavation increment."""
        return self.domain.elastic_stress(values, u_full)

    def field(self, values: Mapping) -> Field:
        u = self.fe.expand(self.displacement(values))
        stress = self.element_stress(values, u)
        return Field(self.mesh, u.reshape(-1, 2), {"stress_xx": stress[:, 0], "stress_yy": stress[:, 1],
                                        "stress_xy": stress[:, 2]})
