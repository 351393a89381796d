"""Walls and supports at the estimate: every wall's deflection, shear and bending moment after every
stage, every prop's and anchor's axial force after every stage, each with its first-order std from
the parameters' covariance C_p (as the forecasts: var q = F C_p F^t, F = dq/dp).

F of a prop's or anchor's force is exact (``ExcavationSimulation.connector_force`` with the
parameters as `wrt`: the direct sensitivities of the staged run); F of a wall's section forces and
deflection comes from central differences (relative step 1e-4, as the lining's forces: they are
smooth in every value), 2 n forward runs for n parameters. Quantities not identified are taken as
exact; before a wall or a support is installed its values are NaN (no force, no band).

Also the levels an engineer reads the wall against: the excavation level in front of the wall after
each stage (the deepest dug region touching the wall's face) and the depths of the supports on it.
Readers (``reports/walls.py``, ``reports/plots/walls.py``) take a ``WallsAndSupports`` and run nothing.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geoback.errors import GeobackError
from geoback.physics.simulation import is_constant

STEP = 1e-4  # relative central-difference step of the wall's section forces


@dataclass(frozen=True)
class WallResult:
    """One wall after every stage (stages x depths; NaN before it is installed): centreline deflection
    ux [m] (+ towards larger x), shear V [kN/m], bending moment M [kNm/m] (+ the face at larger x in
    tension), with their std (None: nothing identified); the excavation level in front of it after
    each stage (depth [m], 0 before any digging beside it) and the supports on it (name -> depth)."""

    name: str
    x: float
    top: float
    toe: float
    thickness: float
    depths: np.ndarray
    stages: tuple
    ux: np.ndarray
    V: np.ndarray
    M: np.ndarray
    ux_std: np.ndarray | None
    V_std: np.ndarray | None
    M_std: np.ndarray | None
    formation: np.ndarray
    supports: dict
    pit_side: float  # -1: the excavation on the wall's left (smaller x), +1 on its right

    def largest(self, quantity: str, k: int) -> tuple[float, float, float]:
        """(value, depth, std) where |quantity| is largest after stage k (NaN before installation)."""
        v = getattr(self, quantity)[k]
        if not np.isfinite(v).any():
            return np.nan, np.nan, np.nan
        i = int(np.nanargmax(np.abs(v)))
        s = getattr(self, f"{quantity}_std")
        return float(v[i]), float(self.depths[i]), float(s[k, i]) if s is not None else np.nan


@dataclass(frozen=True)
class SupportResult:
    """A prop (compression +) or anchor (tension +) after every stage: axial force per metre run N
    [kN/m] (NaN before it is installed) and its std; `spacing` [m] (None: given per metre run), so one
    prop or anchor carries spacing * N [kN]."""

    name: str
    kind: str
    wall: str
    depth: float
    spacing: float | None
    installed: str
    stages: tuple
    force: np.ndarray
    std: np.ndarray | None

    @property
    def per_support(self) -> float:
        return self.spacing if self.spacing is not None else 1.0


@dataclass(frozen=True)
class WallsAndSupports:
    walls: dict  # name -> WallResult
    supports: dict  # name -> SupportResult
    parameters: tuple  # the identified values the stds account for ('' none)
    z: float  # the 95 % band is value +- z std

    @property
    def banded(self) -> bool:
        return bool(self.parameters)


def formation_levels(case, band, stages) -> np.ndarray:
    """The excavation level in front of the wall `band` after each stage: the deepest point of the
    regions dug by then that touch the wall's face (0: nothing dug beside it yet)."""
    from geoback.case.layout import regions
    from geoback.case.sequence import Sequence

    regs = regions(case.geometry)
    wall = band.polygon()
    reach = 1e-6 * max(1.0, band.thickness)
    out, deepest = np.zeros(len(stages)), 0.0
    for k, step in enumerate(Sequence.of(case).steps):
        for r in step.excavate:
            if r in regs and regs[r][1].distance(wall) < reach:
                deepest = max(deepest, -regs[r][1].bounds[1])
        out[k] = deepest
    return out


class WallsUnavailable(GeobackError):
    """The simulation's wall forces are not of its own solution (refused rather than written wrong)."""


def checked_wall_forces(sim, values: dict):
    """``sim.wall_forces(values)``, checked against the simulation's own displacements: each wall's
    centreline deflection after every stage it stands must be the ground's displacement there
    (``stage_displacements_at``). A simulation whose wall forces come from another run (e.g. a linear
    run of yielding ground) is refused (WallsUnavailable), never written."""
    forces = sim.wall_forces(values)
    for name, f in (forces or {}).items():
        band = sim.plan.walls[name]
        pick = np.unique(np.linspace(0, len(f.depths) - 1, 9).astype(int))
        pts = np.column_stack([np.full(len(pick), band.x), -np.asarray(f.depths)[pick]])
        for k, stage in enumerate(f.stages):
            if not np.isfinite(f.ux[k]).all():
                continue
            u = sim.stage_displacements_at(values, pts, stage)[:, 0]
            if np.abs(f.ux[k][pick] - u).max() > 1e-6 * max(np.abs(u).max(), 1e-9):
                raise WallsUnavailable(
                    f"the section forces of wall '{name}' do not come from this model's solution (the wall's "
                    f"deflection after stage '{stage}' is {1e3 * f.ux[k][pick][0]:.4g} mm at its top, the "
                    f"ground's there {1e3 * u[0]:.4g} mm): walls.csv, supports.csv and wall forecasts are not "
                    f"available for {type(sim).__name__} yet")
    return forces


def _physical(names) -> list[str]:  # the named values of the model (not instruments' constants)
    return [n for n in names if not is_constant(n)]


def wall_jacobian(sim, values: dict, names: list[str]) -> dict:
    """d(ux, V, M)/d(names) of every wall by central differences: {wall: {q: (stages, depths, n)}} (zero
    for an integration constant of an instrument: no wall force depends on it)."""
    out = {}
    fd = sim.replaying(values)  # the same discrete function of the values (a yielding run's increments)
    for j, n in enumerate(names):
        if is_constant(n):
            continue
        h = STEP * max(abs(values[n]), 1e-3)
        up, down = dict(values), dict(values)
        up[n], down[n] = values[n] + h, values[n] - h
        a, b = fd.wall_forces(up), fd.wall_forces(down)
        for w in a:
            d = out.setdefault(w, {})
            for q in ("ux", "V", "M"):
                arr = d.setdefault(q, np.zeros(getattr(a[w], q).shape + (len(names),)))
                arr[..., j] = (getattr(a[w], q) - getattr(b[w], q)) / (2 * h)
    return out


def _std(F: np.ndarray, std_of) -> np.ndarray:
    """std of every row of F (..., n), NaN where F is (a quantity not there yet)."""
    shape = F.shape[:-1]
    G = F.reshape(-1, F.shape[-1])
    bad = ~np.isfinite(G).all(axis=1)
    s = std_of(np.where(bad[:, None], 0.0, G)) if G.shape[1] else np.zeros(len(G))
    return np.where(bad, np.nan, s).reshape(shape)


def walls_and_supports(sim, case, values: dict, names=(), std_of=None, z: float = 1.959963984540054):
    """Every wall and support of the case at `values` (an excavation simulation with walls; None
    without), with stds from `std_of(F)` (``LinearAnalysis.prediction_std``: sqrt diag F C_p F^t) for
    the parameters `names` (none: no std)."""
    from geoback.case.supports import pit_side

    if not getattr(getattr(sim, "plan", None), "walls", None):
        return None
    names = list(names) if std_of is not None else []
    physical = _physical(names)
    cols = [j for j, n in enumerate(names) if not is_constant(n)]
    if not physical:
        names = []
    stages = tuple(sim.stages)
    forces = checked_wall_forces(sim, values)
    jac = wall_jacobian(sim, values, names) if names else {}
    walls = {}
    for w, f in forces.items():
        band = sim.plan.walls[w]
        on = {n: -c.head[1] for n, c in sim.connectors.items() if c.wall == w}
        stds = {q: _std(jac[w][q], std_of) if names else None for q in ("ux", "V", "M")}
        walls[w] = WallResult(w, band.x, band.top, band.toe, band.thickness, np.asarray(f.depths), stages,
                              np.asarray(f.ux), np.asarray(f.V), np.asarray(f.M), stds["ux"], stds["V"], stds["M"],
                              formation_levels(case, band, stages), on, pit_side(case, band))
    supports = {}
    for n, c in sim.connectors.items():
        k_in = sim.plan.installed_at(n)
        N = np.full(len(stages), np.nan)
        F = np.full((len(stages), len(names)), np.nan)
        for k in range(max(k_in, 0), len(stages)):
            N[k], dN = sim.connector_force(values, n, k, wrt=physical)
            F[k] = 0.0
            F[k, cols] = dN
        supports[n] = SupportResult(n, c.kind, c.wall, -c.head[1], c.spacing, stages[k_in] if k_in >= 0 else
                                    "before construction", stages, N, _std(F, std_of) if names else None)
    return WallsAndSupports(walls, supports, tuple(physical), float(z))


def band_z(reliability) -> float:
    """The 95 % band's multiplier: the normal quantile, or Student t's on the ellipse's degrees of
    freedom when error scales are estimated (as the forecasts)."""
    from geoback.inference.reliability import Z95

    if np.isfinite(reliability.ellipse_dof) and reliability.scales_estimated:
        from scipy import special

        return float(special.stdtrit(reliability.ellipse_dof, 0.975))
    return float(Z95)


def of_result(analysis, result):
    """``walls_and_supports`` at the estimate of an identification, with its bands."""
    rel = result.reliability
    values = analysis.values_at(result.fit.p)
    return walls_and_supports(analysis.simulation, analysis.loaded.case, values, list(result.parameters.names),
                              rel.linear.prediction_std, band_z(rel))
