"""Forward model and exact sensitivities: x(p) = P u(p) - G c and A = dx/dp (eqns 31-42).

One factorisation per distinct stiffness: when the new stiffness is a multiple s of a
factorised one (one modulus, fixed nu: K = E k, eqn 41), u = k^-1 f / s reuses it; every
sensitivity column is a back-substitution du/dp = K^-1 (df/dp - dK/dp u) (eqn 34).
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field

import numpy as np

from .case import LoadedCase
from .errors import CaseError
from .fem import FEModel
from .ground import EXTENSIONS, Ground
from .instruments import Observations, build_observations
from .mesh import Mesh, build_mesh
from .parameters import ParameterSet, unit_of
from .solver import Factorisation


@dataclass
class Counters:
    factorisations: int = 0
    solves: int = 0  # right-hand sides back-substituted
    forward_runs: int = 0
    seconds_factorising: float = 0.0
    seconds_solving: float = 0.0
    seconds_assembling: float = 0.0
    extra: dict = field(default_factory=dict)


class Problem:
    """A case meshed and assembled, ready to predict readings for any parameter values."""

    def __init__(self, loaded: LoadedCase, mesh: Mesh | None = None, backend: str | None = None,
                 extra_values: dict | None = None, parameters: list | None = None, with_readings: bool = True):
        self.loaded = loaded
        case = self.case = loaded.case
        self.timings: dict[str, float] = {}
        t0 = time.perf_counter()
        self.mesh = mesh or build_mesh(case, allow_large=getattr(loaded, "allow_large", False))
        t1 = time.perf_counter()
        g = case.geometry
        self.fe = FEModel(self.mesh, g.width, g.depth, (0.0, -g.axis_depth), g.radius)
        t2 = time.perf_counter()
        self.timings.update(mesh=t1 - t0, assembly=t2 - t1)
        self.ground = Ground(case, -self.fe.centroid[:, 1], self.fe.region, -self.fe.wall_points[:, 1])
        self.values = self.ground.baseline()
        self.values.update(extra_values or {})
        self.backend = backend
        self.counters = Counters()
        self._cache: dict = {"factor": None}  # shared with derived problems (same mesh)
        self.obs: Observations | None = None
        self._with_readings = with_readings
        self._set_parameters(parameters if parameters is not None else case.parameters)
        self.timings["observations"] = time.perf_counter() - t2

    def _set_parameters(self, specs) -> None:
        self.params = self._parameters(specs)
        consts = {n for n in self.params.names if n.split("[")[0] in ("A", "B", "C", "D")}
        if self.obs is None or set(self.obs.identified_constants) != consts:
            measured = self.obs.measured if self.obs is not None else None
            self.obs = build_observations(self.loaded, self.fe, consts, self._with_readings)
            if measured is not None:  # readings set in memory (studies, diagnose) carry over
                self.obs.measured = measured
        unknown = [n for n in consts if n not in self.obs.constant_names]
        if unknown:
            raise self._param_error(unknown[0], "no linewise instrument has this integration constant")
        self._const_index = [self.obs.constant_names.index(n) if n in consts else -1 for n in self.params.names]

    def derive(self, parameters, extra_values: dict | None = None) -> "Problem":
        """The same mesh, FE model, readings and factorisation cache with other parameters/values
        (how `diagnose` adds a hypothesis to the baseline model)."""
        new = copy.copy(self)
        new.values = dict(self.values)
        new.values.update(extra_values or {})
        new._set_parameters(parameters)
        return new

    @property
    def _factor(self):
        return self._cache["factor"]

    # ------------------------------------------------------------------ parameters
    def _param_error(self, name: str, why: str) -> CaseError:
        idx = next((i for i, p in enumerate(self.case.parameters) if p.name == name), None)
        at = ("parameters", idx, "name") if idx is not None else ("parameters",)
        return self.loaded.error(at, f"'{name}': {why}")

    def _parameters(self, specs) -> ParameterSet:
        names, init, lo, hi, log, pm, ps = [], [], [], [], [], [], []
        for i, p in enumerate(specs):
            base = p.name.split("[")[0]
            if base in ("A", "B", "C", "D"):
                name = p.name
            else:
                name = self.ground.canonical(p.name)
                if name is None:
                    hint = (f"layers are {', '.join(self.ground.layers)}" if "[" in p.name or base in ("E", "nu")
                            else "known names: E[layer], nu[layer], K0, K0[layer], Egrad[layer], K0grad, beta, "
                                 "n[layer], m[layer], A/B/C/D[instrument]")
                    raise self.loaded.error(("parameters", i, "name"), f"unknown parameter '{p.name}' ({hint})")
                if name not in self.values:
                    if base in EXTENSIONS:
                        self.values[name] = EXTENSIONS[base]
                    elif base == "Esplit":
                        self.values[name] = self.values["E" + name[len("Esplit"):]]
                    else:
                        raise self.loaded.error(("parameters", i, "name"),
                                                f"'{p.name}' has no value in the case to start from"
                                                + (" (give this layer a K0 in ground.layers)" if base == "K0" else ""))
            names.append(name)
            init.append(p.initial)
            lo.append(p.bounds[0] if p.bounds else -np.inf)
            hi.append(p.bounds[1] if p.bounds else np.inf)
            log.append(p.log)
            pm.append(p.prior.mean if p.prior else np.nan)
            ps.append(p.prior.std if p.prior else np.nan)
        return ParameterSet(names, np.array(init, float), np.array(lo, float), np.array(hi, float),
                            np.array(log, bool), np.array(pm, float), np.array(ps, float),
                            [unit_of(n) for n in names])

    def values_for(self, p: np.ndarray) -> dict:
        values = dict(self.values)
        for name, v in zip(self.params.names, p):
            values[name] = float(v)
        return values

    # ------------------------------------------------------------------ forward
    def _factorised(self, coeffs: np.ndarray) -> tuple[Factorisation, float]:
        """Factorisation of K(coeffs) and the scale s with K(coeffs) = s K(factorised)."""
        if self._factor is not None:
            ref, fact = self._factor
            s = float(np.vdot(ref, coeffs) / np.vdot(ref, ref))
            if s > 0 and np.linalg.norm(coeffs - s * ref) <= 1e-13 * np.linalg.norm(coeffs):
                return fact, s
            if fact.backend == "pardiso":
                fact.release()
        t0 = time.perf_counter()
        K = self.fe.matrix(coeffs)
        t1 = time.perf_counter()
        fact = Factorisation(K, self.backend)
        self.counters.factorisations += 1
        self.counters.seconds_assembling += t1 - t0
        self.counters.seconds_factorising += time.perf_counter() - t1
        self._cache["factor"] = (coeffs.copy(), fact)
        return fact, 1.0

    def _solve(self, fact: Factorisation, s: float, rhs: np.ndarray) -> np.ndarray:
        """K^-1 rhs with K = s K(factorised); counts real back-substitutions only."""
        t0 = time.perf_counter()
        before = fact.backsubstitutions
        out = fact.solve(rhs) / s
        self.counters.solves += fact.backsubstitutions - before
        self.counters.seconds_solving += time.perf_counter() - t0
        return out

    def forget_factorisation(self) -> None:
        """Drop the kept factorisation (what a code without reuse does before every solve)."""
        if self._factor is not None:
            self._factor[1].release()
        self._cache["factor"] = None

    def displacement(self, values: dict) -> np.ndarray:
        """u on the free dofs for the given named values (eqn 31)."""
        st = self.ground.state(values)
        fact, s = self._factorised(st.coeffs)
        self.counters.forward_runs += 1
        return self._solve(fact, s, self.fe.load(st.sigma_v, st.sigma_h))

    def _readings(self, u: np.ndarray, p: np.ndarray) -> np.ndarray:
        x = self.obs.P @ u
        for j, k in enumerate(self._const_index):
            if k >= 0:
                x = x - self.obs.G[:, k] * p[j]
        return x

    def predict(self, p: np.ndarray) -> np.ndarray:
        """Computed readings x(p)."""
        return self._readings(self.displacement(self.values_for(p)), p)

    def predict_with_sensitivity(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """x(p) and the sensitivity matrix A = dx/dp (eqns 29, 34-42), physical units."""
        values = self.values_for(p)
        st = self.ground.state(values)
        fact, s = self._factorised(st.coeffs)
        self.counters.forward_runs += 1
        f = self.fe.load(st.sigma_v, st.sigma_h)
        u = self._solve(fact, s, f)
        x = self._readings(u, p)
        fe_names = [n for n, k in zip(self.params.names, self._const_index) if k < 0]
        A = np.zeros((len(x), self.params.n))
        if fe_names:
            derivs = self.ground.derivatives(values, fe_names)
            rhs = np.empty((self.fe.nfree, len(fe_names)))
            for j, d in enumerate(derivs):
                r = self.fe.load(d.sigma_v, d.sigma_h)
                alpha = _proportion(d.coeffs, st.coeffs)
                if alpha is not None:  # dK/dp = alpha K (a modulus scaling K): dK/dp u = alpha f (eqn 42)
                    r = r - alpha * f
                elif np.any(d.coeffs):
                    r = r - self.fe.symmetric_product(self.fe.matrix(d.coeffs), u)
                rhs[:, j] = r
            du = self._solve(fact, s, rhs)
            dx = self.obs.P @ du
            cols = [j for j, k in enumerate(self._const_index) if k < 0]
            A[:, cols] = dx
        for j, k in enumerate(self._const_index):
            if k >= 0:
                A[:, j] = -self.obs.G[:, k]
        return x, A


def _proportion(a: np.ndarray, b: np.ndarray) -> float | None:
    """alpha with a = alpha b (to rounding), or None."""
    bb = float(np.vdot(b, b))
    if bb == 0:
        return None
    alpha = float(np.vdot(b, a) / bb)
    return alpha if np.linalg.norm(a - alpha * b) <= 1e-13 * max(np.linalg.norm(a), 1e-300) else None
