"""The one-step linear-elastic excavation: x(v) = P K(v)^-1 f(v) and exact sensitivities (eqns 31-42).

One factorisation per distinct stiffness: when the stiffness of new values is a multiple s of a
factorised one (one modulus, fixed nu: K = E k, eqn 41), u = k^-1 f / s reuses it. Every
sensitivity column is a back-substitution, du/dv = K^-1 (df/dv - dK/dv u) (eqn 34); when dK/dv is
itself a multiple of K (a modulus that scales the whole stiffness) dK/dv u = alpha f without a
matrix product (eqn 42). Loads are remembered by their wall stresses (the factorisation's span
cache keyed by them), so a load in the span of earlier ones costs no back-substitution.

Proportionality is tested entry by entry (max-norm), which, unlike a test on vector norms, does
not fail from rounding as the mesh grows.
"""
from __future__ import annotations

import time
from typing import Mapping, Sequence

import numpy as np

from geoback.case.loading import LoadedCase
from geoback.physics.fem import FEModel
from geoback.physics.ground import Ground
from geoback.observation.instruments import InstrumentBlock
from geoback.physics.mesh import Mesh, build_mesh
from geoback.physics.simulation import Counters, Field, Prediction, Simulation, Stopwatch, stage_survey
from geoback.physics.solver import Factorisation

PROPORTIONAL = 1e-13  # entry-wise relative tolerance of "K(v) = s K(v_ref)"


def proportion(a: np.ndarray, b: np.ndarray) -> float | None:
    """s with a = s b entry by entry (to rounding, max-norm), or None."""
    a, b = np.asarray(a).ravel(), np.asarray(b).ravel()
    k = int(np.argmax(np.abs(b)))
    if b[k] == 0:
        return None
    s = float(a[k] / b[k])
    scale = max(float(np.abs(a).max()), abs(s) * float(np.abs(b).max()))
    if scale == 0:
        return s
    return s if float(np.abs(a - s * b).max()) <= PROPORTIONAL * scale else None


class _Load:
    """The excavation load f = -int N^t sigma0 n dS of a ground state, assembled on first use."""

    def __init__(self, fe: FEModel, state):
        self.fe, self.state, self._f = fe, state, None

    @property
    def vector(self) -> np.ndarray:
        if self._f is None:
            self._f = self.fe.load(self.state.sigma_v, self.state.sigma_h)
        return self._f


class ElasticSimulation(Simulation):
    """A case meshed and assembled, predicting readings of its instruments for any values."""

    reads_depth_offsets = True

    def __init__(self, loaded: LoadedCase, mesh: Mesh | None = None, blocks: list[InstrumentBlock] | None = None,
                 extensions: Mapping | None = None, backend: str | None = None):
        case = loaded.case
        self.loaded = loaded
        t0 = time.perf_counter()
        self.mesh = mesh or build_mesh(case, allow_large=getattr(loaded, "allow_large", False))
        t1 = time.perf_counter()
        g = case.geometry
        self.fe = FEModel(self.mesh, g.width, g.depth, (0.0, -g.axis_depth), g.radius)
        t2 = time.perf_counter()
        self.ground = Ground(case, -self.fe.centroid[:, 1], self.fe.region, -self.fe.wall_points[:, 1],
                             extensions or {})
        self.survey = stage_survey(loaded, blocks, self.stages, self.fe)
        self.timings = {"mesh": t1 - t0, "assembly": t2 - t1, "observations": time.perf_counter() - t2}
        self.backend = backend
        self.counters = Counters()
        self._factor: tuple[np.ndarray, Factorisation] | None = None
        self._last = None  # (values key, forward solution) of the last forward run

    # ------------------------------------------------------------------ names
    def quantities(self) -> dict[str, float]:
        return self.ground.baseline()

    def canonical(self, name: str) -> str | None:
        return self.ground.canonical(name)

    def null_value(self, name: str, values: Mapping) -> float | None:
        return self.ground.null_value(name, values)

    def unit(self, name: str) -> str:
        return self.ground.unit(name)

    def limits(self, name: str, values: Mapping):
        return self.ground.limits(name, values)

    @property
    def dofs(self) -> int:
        return self.fe.ndof

    @property
    def solver(self) -> str | None:
        return self._factor[1].backend if self._factor else None

    # ------------------------------------------------------------------ solves
    def _factorised(self, coeffs: np.ndarray) -> tuple[Factorisation, float]:
        """Factorisation of K(coeffs) and the scale s with K(coeffs) = s K(factorised)."""
        if self._factor is not None:
            ref, fact = self._factor
            s = proportion(coeffs, ref)
            if s is not None and s > 0:
                return fact, s
            fact.release()
        with Stopwatch(self.counters, "seconds_assembling"):
            K = self.fe.matrix(coeffs)
        with Stopwatch(self.counters, "seconds_factorising"):
            fact = Factorisation(K, self.backend)
        self.counters.factorisations += 1
        self._factor = (np.array(coeffs, float), fact)
        return fact, 1.0

    def _solve(self, fact: Factorisation, s: float, rhs: np.ndarray, coords: np.ndarray | None = None) -> np.ndarray:
        """K^-1 rhs with K = s K(factorised); counts real back-substitutions only."""
        before = fact.backsubstitutions
        with Stopwatch(self.counters, "seconds_solving"):
            out = fact.solve(rhs, coords) / s
        self.counters.solves += fact.backsubstitutions - before
        return out

    def release(self) -> None:
        """Drop the kept factorisation (what a code without reuse does before every solve)."""
        if self._factor is not None:
            self._factor[1].release()
        self._factor = None

    def _forward(self, values: Mapping):
        """Ground state, factorisation, load and u at `values` (eqn 31). The last one is remembered:
        an optimiser asks for the sensitivities at the point it has just evaluated."""
        key = tuple(sorted(values.items()))
        if self._last is not None and self._last[0] == key and self._factor is not None \
                and self._factor[1] is self._last[1][1]:
            return self._last[1]
        st = self.ground.state(values)
        fact, s = self._factorised(st.coeffs)
        self.counters.forward_runs += 1
        coords = np.concatenate([st.sigma_v, st.sigma_h])
        load = _Load(self.fe, st)  # assembled only if the span of earlier loads cannot answer
        u = self._solve(fact, s, lambda cols: load.vector, coords)
        out = (st, fact, s, coords, load, u)
        self._last = (key, out)
        return out

    def displacement(self, values: Mapping) -> np.ndarray:
        """u on the free dofs for the given named values (eqn 31)."""
        return self._forward(values)[-1]

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
            du[:, cols] = self._solve(fact, s, rhs, np.column_stack([c for _, _, _, c in keyed]))
        if raw:
            du[:, [j for j, _ in raw]] = self._solve(fact, s, np.column_stack([r for _, r in raw]))
        return Prediction(x, np.asarray(P @ du))

    # ------------------------------------------------------------------ fields
    def element_stress(self, values: Mapping, u_full: np.ndarray) -> np.ndarray:
        """Total stress (sxx, syy, sxy) per element: initial geostatic + excavation increment."""
        st = self.ground.state(values)
        eps = self.fe.element_strain(u_full)
        d11, d22, d12, d33 = st.coeffs.T.real
        ds = np.column_stack([d11 * eps[:, 0] + d12 * eps[:, 1], d12 * eps[:, 0] + d22 * eps[:, 1], d33 * eps[:, 2]])
        s0 = self.ground.initial_stress(values, -self.fe.centroid[:, 1], self.fe.region)
        return s0 + ds

    def field(self, values: Mapping) -> Field:
        u = self.fe.expand(self.displacement(values))
        stress = self.element_stress(values, u)
        return Field(self.mesh, u.reshape(-1, 2), {"stress_xx": stress[:, 0], "stress_yy": stress[:, 1],
                                        "stress_xy": stress[:, 2]})

    def displacements_at(self, values: Mapping, points: np.ndarray) -> np.ndarray:
        Ix, Iy = self.fe.interpolation(points)
        u = self.displacement(values)
        return np.column_stack([Ix @ u, Iy @ u])
