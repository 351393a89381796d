"""Forecasts: quantities the engineer needs next (a settlement trough at the next stage, what an
inclinometer will read, the lining's thrust), at the estimate with their uncertainty.

For a forecast q(p) with sensitivity F = dq/dp at the estimate, the parameters' covariance C_p
(eqn 55) gives the first-order (FOSM) covariance

    C_q = F C_p F^t,      95 % band  q +- z sqrt(diag C_q)

(``LinearAnalysis.prediction_covariance`` and ``prediction_std`` of the fit's ``Reliability.linear``;
the std is infinite for a forecast that depends on a combination the readings do not determine)

(z the normal quantile, or Student t's on the ellipse's degrees of freedom when error scales are
estimated). F comes from the simulation's exact sensitivities (eqns 34-42) for displacements,
chords and instrument readings, read through another survey on the same factorisations
(``Simulation.surveying``), and from central differences for the lining's section forces.

The band is linearised. A sampling check draws parameter sets from N(p, C_p) (in log space for
parameters fitted as ln p), runs the model at each, and compares the 2.5-97.5 % range of the
forecasts with the band; where they differ by more than 10 % of the band (beyond the sampling's own
error) the model is non-linear over C_p, neither range is exact, and a warning says so; the
sampled range is reported beside the band. (``studies/forecast_coverage.py`` checks the band's
coverage by noisy replicates: 93-97 % on the paper case, also on the staged case the check flags.) The forecast is the model's (the true movement), not a future
reading: a reading adds its instrument's error. Quantities not identified are taken as exact.
"""
from __future__ import annotations

import math
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from types import SimpleNamespace

import numpy as np

from geoback.case.checks import line_points
from geoback.observation.instruments import build_block, case_blocks
from geoback.inference.reliability import Z95
from geoback.physics.simulation import is_constant

UNITS = {"ux": "m", "uy": "m", "chord": "m", "along": "m", "normal": "m", "N": "kN/m", "M": "kNm/m", "V": "kN/m"}
WORDS = {"points": "displacement", "line": "displacement along a line", "convergence": "chord length change",
         "instrument": "instrument readings", "lining": "lining section forces",
         "support": "axial force of a prop or anchor", "wall": "retaining wall section forces"}
DRAWS, SECONDS = 400, 20.0  # sampling check: at most this many draws, within about this many seconds


@dataclass(frozen=True)
class Forecast:
    """One named forecast of a ``Forecasts``, point by point (``fc["trough"]``): where, the value,
    its std and 95 % band, the sampled range, the alert level and the probability of exceeding it,
    each in `unit` (SI: m for displacements, kN/m and kNm/m for the lining's forces)."""

    name: str
    kind: str
    stage: str
    quantity: tuple[str, ...]
    unit: str
    x: np.ndarray
    y: np.ndarray
    position: np.ndarray
    position_label: str
    values: np.ndarray
    std: np.ndarray
    low: np.ndarray
    high: np.ndarray
    alert: float
    p_exceed: np.ndarray
    sampled_low: np.ndarray | None = None
    sampled_high: np.ndarray | None = None
    nonlinear: bool = False  # the sampled range differs from the linearised band (a warning)

    def __post_init__(self):
        for k, v in self.__dict__.items():
            if isinstance(v, np.ndarray):
                v = v.copy()
                v.setflags(write=False)
                object.__setattr__(self, k, v)

    @property
    def band(self) -> tuple[np.ndarray, np.ndarray]:
        """The linearised 95 % band (low, high) of every point."""
        return self.low, self.high

    def __len__(self) -> int:
        return len(self.values)

    def as_dict(self) -> dict:
        """JSON-ready, point by point."""
        def num(v):
            return [float(x) if np.isfinite(x) else None for x in v] if v is not None else None

        return {"name": self.name, "kind": self.kind, "stage": self.stage, "unit": self.unit,
                "quantity": list(self.quantity), "position_label": self.position_label,
                "position": num(self.position), "x": num(self.x), "y": num(self.y), "values": num(self.values),
                "std": num(self.std), "band": [num(self.low), num(self.high)],
                "alert": float(self.alert) if np.isfinite(self.alert) else None, "p_exceed": num(self.p_exceed),
                "sampled": None if self.sampled_low is None else [num(self.sampled_low), num(self.sampled_high)],
                "nonlinear": self.nonlinear}


@dataclass(frozen=True)
class Forecasts:
    """Every forecast row at the estimate: where, what, value, std and 95 % bands (linearised and
    sampled), the probability of exceeding an alert level; readers only from here on."""

    forecast: list[str]  # forecast name of each row
    kind: list[str]
    stage: list[str]
    quantity: list[str]
    unit: list[str]
    x: np.ndarray
    y: np.ndarray
    position: np.ndarray  # offset along a line [m], angle from the crown [deg], depth, or point number
    position_label: list[str]
    value: np.ndarray
    std: np.ndarray
    low: np.ndarray
    high: np.ndarray
    sensitivity: np.ndarray  # F = dq/dp (rows, parameters)
    covariance: np.ndarray  # C_q
    parameters: list[str]
    z: float
    covariance_of_parameters: np.ndarray  # C_p the forecasts were made with
    alert: np.ndarray  # nan where none
    p_exceed: np.ndarray  # P(|q| > alert), FOSM
    sampled_low: np.ndarray | None = None
    sampled_high: np.ndarray | None = None
    sampled_exceed: np.ndarray | None = None
    samples: np.ndarray | None = None  # the sampling check's forecasts (draws, rows): trigger probabilities
    draws: int = 0
    rejected: int = 0
    nonlinear: list[str] = field(default_factory=list)  # forecasts whose sampled band differs from the linear one
    counts: dict = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def names(self) -> list[str]:
        return list(dict.fromkeys(self.forecast))

    def rows(self, name: str) -> np.ndarray:
        return np.array([i for i, f in enumerate(self.forecast) if f == name], np.int64)

    def __getitem__(self, name: str) -> Forecast:
        """The forecast called `name` (the case's forecasts[].name), point by point: ``fc["trough"]``."""
        if not isinstance(name, str) or name not in self.forecast:
            raise KeyError(f"{name!r}: expected the name of a forecast of the case ({', '.join(self.names)})")
        i = self.rows(name)
        units = {self.unit[k] for k in i}
        sampled = self.sampled_low is not None
        return Forecast(name, self.kind[i[0]], self.stage[i[0]], tuple(self.quantity[k] for k in i),
                        units.pop() if len(units) == 1 else ", ".join(sorted(units)),
                        self.x[i], self.y[i], self.position[i], self.position_label[i[0]], self.value[i],
                        self.std[i], self.low[i], self.high[i], float(self.alert[i[0]]), self.p_exceed[i],
                        self.sampled_low[i] if sampled else None, self.sampled_high[i] if sampled else None,
                        name in self.nonlinear)

    def __contains__(self, name) -> bool:
        return name in self.forecast

    def __iter__(self):
        """The forecasts by name, each a ``Forecast`` (``for f in fc: f.name, f.values, f.band``)."""
        return (self[n] for n in self.names)

    def __len__(self) -> int:
        return len(self.names)

    def keys(self) -> list[str]:
        return self.names

    def contributions(self) -> np.ndarray:
        """Fraction of each row's variance that knowing parameter j exactly would remove (correlations
        included: C_p conditioned on p_j, a Schur complement): (F C_p[:, j])^2 / (C_p[j, j] var q)."""
        C = self.covariance_of_parameters
        d = np.diag(C)
        FC = self.sensitivity @ C  # (rows, n)
        with np.errstate(invalid="ignore", divide="ignore"):
            share = FC ** 2 / (d[None, :] * (self.std ** 2)[:, None])
        return np.clip(np.nan_to_num(share, nan=0.0, posinf=0.0), 0.0, 1.0)


# ---------------------------------------------------------------------------- what each forecast reads
@dataclass
class _Spec:
    """One forecast as survey blocks (displacement-type) or lining sections."""

    name: str
    kind: str
    stage: str
    alert: float
    block: object | None = None  # an InstrumentBlock at `stage`
    quantities: tuple = ()  # lining, wall
    position: np.ndarray | None = None
    position_label: str = ""
    support: str | None = None  # a prop or anchor (kind 'support')
    wall: str | None = None  # a retaining wall (kind 'wall')
    unit: str | None = None  # the rows' unit where the quantity alone does not say it (a load cell's force)


def _specs(loaded, stages: list[str], read_blocks=()) -> list[_Spec]:
    """What each forecast of the case reads; `read_blocks`: the blocks the fit read (an instrument's
    installation stage, from its baseline survey, is theirs)."""
    case = loaded.case
    by_name = None
    out = []
    for i, f in enumerate(case.forecasts):
        stage = f.stage or stages[-1]
        alert = float(f.alert) if f.alert is not None else math.nan
        s = _Spec(f.name, f.kind, stage, alert)
        if f.kind == "points":
            s.block = build_block(SimpleNamespace(kind="points", name=f.name, points=f.points,
                                                  components=f.components, sigma=1.0), loaded, i)
            s.position, s.position_label = np.repeat(np.arange(1, len(f.points) + 1), len(f.components)), "point"
        elif f.kind == "line":
            pts = line_points(f.start, f.end, f.points)
            s.block = build_block(SimpleNamespace(kind="points", name=f.name, points=pts, components=[f.component],
                                                  sigma=1.0), loaded, i)
            xy, a = np.asarray(pts), np.asarray(f.start, float)
            if f.start[1] == f.end[1]:  # horizontal: by offset from the tunnel's axis (a full model: by x)
                full = getattr(loaded.case.geometry, "model", "half") == "full"
                axis = "symmetry axis" if hasattr(loaded.case.geometry, "openings") else "tunnel axis"
                s.position, s.position_label = xy[:, 0], "x, horizontal position [m]" if full else \
                    f"offset from the {axis} [m]"
            elif f.start[0] == f.end[0]:  # vertical: by depth
                s.position, s.position_label = -xy[:, 1], "depth [m]"
            else:
                s.position, s.position_label = np.hypot(*(xy - a).T), "distance along the line [m]"
        elif f.kind == "convergence":
            s.block = build_block(SimpleNamespace(kind="convergence", name=f.name, points=f.points, sigma=1.0),
                                  loaded, i)
            s.position, s.position_label = np.array([1.0]), "chord"
        elif f.kind == "instrument":
            by_name = by_name or {b.name: b for b in case_blocks(loaded)}
            b = by_name[f.instrument]
            read = [x for x in read_blocks if x.name == f.instrument]
            if read:  # installed after a stage (by a dated baseline): the forecast reads increments too
                b = replace(b, since=read[0].since)
            m = b.m
            s.block = replace(b, name=f.name, constants=np.zeros((m, 0)), constant_names=[], constant_variances={})
            pts = b.stations
            if b.kind == "inclinometer":
                s.position, s.position_label = -pts[:, 1], "depth [m]"
            elif b.lengths is not None:
                s.position, s.position_label = np.cumsum(b.lengths), "distance from the reference end [m]"
            else:
                s.position, s.position_label = np.arange(1.0, m + 1), "reading"
            if b.kind == "load_cell":  # the force of one prop or anchor (per metre run without a spacing)
                s.unit = support_unit(loaded.case, case.instruments[b.index].support)
        elif f.kind == "support":
            s.support, s.unit = f.support, support_unit(loaded.case, f.support)
            s.position, s.position_label = np.array([1.0]), "support"
        elif f.kind == "wall":
            s.wall, s.quantities = f.wall, tuple(f.quantities)
            s.position_label = "depth [m]"
        else:
            s.quantities = tuple(f.quantities)
            s.position_label = "angle from the crown [deg]"
        if s.block is not None:
            s.block = s.block.at(stage)
        out.append(s)
    return out


def support_unit(case, name: str) -> str:
    """The unit of a prop's or anchor's force as a load cell reads it and a forecast gives it: kN per
    prop or anchor where the case gives their spacing, else kN per metre run of wall."""
    c = case.construction
    for sup in (c.props or []) + (c.anchors or []):
        if sup.name == name:
            return "kN" if sup.spacing is not None else "kN/m"
    return "kN/m"


# ---------------------------------------------------------------------------- evaluation
class ForecastModel:
    """The forecast quantities as one vector q(values) of the simulation (and dq/dp)."""

    def __init__(self, simulation, specs: list[_Spec]):
        self.sim, self.specs = simulation, specs
        self.blocks = [s.block for s in specs if s.block is not None]
        self.lining = [s for s in specs if s.kind == "lining"]
        self.supports = [s for s in specs if s.kind == "support"]
        self.walls = [s for s in specs if s.kind == "wall"]
        self._walls_checked = False
        self._view = None  # the simulation reading the forecasts' blocks, inside reading()

    @contextmanager
    def reading(self):
        """The context in which the model reads the forecasts' blocks through one view of the
        simulation (``Simulation.surveying``: one view of the wall and one set of interpolation rows
        for every evaluation); the simulation itself is left as it was."""
        self._view = self.sim.surveying(self.blocks) if self.blocks else None
        try:
            yield self
        finally:
            self._view = None

    def __call__(self, values: dict, names: list[str] = (), sensitivities: bool = False):
        values = {k: v for k, v in values.items() if not is_constant(k)}
        physical = [n for n in names if not is_constant(n)]
        parts, jac = [], []
        if self.blocks:  # through the view of reading() (or one made for this call)
            view = self._view if self._view is not None else self.sim.surveying(self.blocks)
            pred = view.predict(values, physical, sensitivities)
            parts.append(pred.x)
            jac.append(pred.A)
        if self.lining:
            q = self._lining(values)
            parts.append(q)
            if sensitivities:
                jac.append(self._lining_jacobian(values, physical, q))
        if self.supports:  # exact: the staged run's direct sensitivities
            q, dq = self._supports(values, physical if sensitivities else [])
            parts.append(q)
            if sensitivities:
                jac.append(dq)
        if self.walls:
            if not self._walls_checked:  # the simulation's wall forces are of its own solution (else refused)
                from geoback.worth.walls import checked_wall_forces

                checked_wall_forces(self.sim, values)
                self._walls_checked = True
            q = self._walls(values)
            parts.append(q)
            if sensitivities:  # on the discrete function at `values` (a yielding run's increments replayed)
                fd = self.sim.replaying(values)
                jac.append(self._central(lambda v: self._walls(v, fd), values, physical, q))
        x = np.concatenate(parts)
        if not sensitivities:
            return x, None
        A = np.zeros((len(x), len(names)))
        cols = [j for j, n in enumerate(names) if not is_constant(n)]
        A[:, cols] = np.vstack(jac) if jac else 0.0
        return x, A

    def _lining(self, values: dict) -> np.ndarray:
        lf = self.sim.lining_forces(values)
        out = []
        for s in self.lining:
            k = lf.stages.index(s.stage)
            out += [getattr(lf, q)[k] for q in s.quantities]
        return np.concatenate(out)

    def _lining_jacobian(self, values: dict, names: list[str], q0: np.ndarray) -> np.ndarray:
        """Central differences (relative step 1e-4; the section forces are smooth in every value)."""
        return self._central(self._lining, values, names, q0)

    @staticmethod
    def _central(f, values: dict, names: list[str], q0: np.ndarray) -> np.ndarray:
        A = np.zeros((len(q0), len(names)))
        for j, n in enumerate(names):
            h = 1e-4 * max(abs(values[n]), 1e-3)
            up, down = dict(values), dict(values)
            up[n], down[n] = values[n] + h, values[n] - h
            A[:, j] = (f(up) - f(down)) / (2 * h)
        return A

    def _supports(self, values: dict, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
        """Each support forecast's axial force (per prop or anchor where it has a spacing) and its exact
        sensitivity (``ExcavationSimulation.connector_force``)."""
        q, dq = np.zeros(len(self.supports)), np.zeros((len(self.supports), len(names)))
        stages = list(self.sim.stages)
        for i, s in enumerate(self.supports):
            scale = self.sim.connectors[s.support].per_support()
            N, dN = self.sim.connector_force(values, s.support, stages.index(s.stage), wrt=list(names))
            q[i], dq[i] = scale * N, scale * np.asarray(dN)
        return q, dq

    def _walls(self, values: dict, sim=None) -> np.ndarray:
        wf = (sim or self.sim).wall_forces(values)
        out = []
        for s in self.walls:
            f = wf[s.wall]
            k = list(f.stages).index(s.stage)
            out += [getattr(f, q)[k] for q in s.quantities]
        return np.concatenate(out)

    def layout(self, values: dict):
        """Row labels: forecast, kind, stage, quantity, x, y, position, position label, alert, unit."""
        rows = []
        for s in self.specs:
            if s.block is None:
                continue
            for lab, pos in zip(s.block.labels, s.position):
                rows.append((s.name, s.kind, s.stage, lab.component, lab.x, lab.y, float(pos), s.position_label,
                             s.alert, s.unit or UNITS.get(lab.component, "m")))
        if self.lining:
            lf = self.sim.lining_forces(values)
            for s in self.lining:
                for q in s.quantities:
                    for a, (px, py) in zip(lf.angle, lf.points):
                        rows.append((s.name, s.kind, s.stage, q, px, py, float(a), s.position_label, s.alert,
                                     UNITS[q]))
        for s in self.supports:
            hx, hy = self.sim.connectors[s.support].head
            rows.append((s.name, s.kind, s.stage, "N", hx, hy, 1.0, s.position_label, s.alert, s.unit))
        if self.walls:
            wf = self.sim.wall_forces(values)
            for s in self.walls:
                x = self.sim.plan.walls[s.wall].x
                for q in s.quantities:
                    for d in wf[s.wall].depths:
                        rows.append((s.name, s.kind, s.stage, q, x, -float(d), float(d), s.position_label, s.alert,
                                     UNITS[q]))
        return rows


def _normal_cdf(t):
    return 0.5 * np.vectorize(math.erfc)(-np.asarray(t, float) / math.sqrt(2.0))


def forecast_model(analysis) -> ForecastModel:
    """The case's forecasts as a function of the named values (for studies: q, F at any estimate)."""
    return ForecastModel(analysis.simulation, _specs(analysis.loaded, analysis.simulation.stages,
                                                         analysis.simulation.survey.blocks))


def _exceed(mean, std, alert):
    """P(|q| > alert) for q ~ N(mean, std^2)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(std > 0, std, np.nan)
        p = _normal_cdf((-alert - mean) / s) + 1.0 - _normal_cdf((alert - mean) / s)
        exact = (np.abs(mean) > alert).astype(float)
    return np.where(np.isnan(alert), np.nan, np.where(std > 0, p, exact))


def unusable_estimate(result) -> str:
    """Why `result` has no estimate to forecast from, in words ('' when it has one). A fit that never
    moved from the initial values has only the initial guess: forecasts there, with a band from the
    sensitivities at the guess, would look like the readings' answer and are not. (A fit that moved but
    stopped early - a time limit, the iteration limit - has its best point, and says so in its caveats.)
    One statement for the library's ``forecast`` (refused) and `geoback run` (skipped, with a caveat)."""
    if not result.fit.moved:
        return ("the identification stopped without moving from the initial values (no step decreased J), so "
                "there is no estimate to forecast from, only the initial guess; fix the case (initial values, "
                "bounds, or fit method lm) and identify again")
    return ""


def forecast(analysis, result, draws: int | None = None, seconds: float = SECONDS, seed: int = 0,
             progress=None) -> Forecasts | None:
    """The case's forecasts at the estimate of `result` (an Identification of `analysis`): value,
    FOSM std and band, probability of exceeding the alert levels, and a sampling check through the
    model (`draws` parameter sets at most, within about `seconds`; 0 to skip). None without forecasts.
    An identification of another case (or of a model with other quantities), or one without an
    estimate (``unusable_estimate``: a fit that never moved), is refused."""
    from geoback.errors import GeobackError

    analysis.check_identification(result, "forecast")
    why = unusable_estimate(result)
    if why:
        raise GeobackError(f"forecast: {why}")
    loaded = analysis.loaded
    if not loaded.case.forecasts:
        return None
    t0 = time.perf_counter()
    sim = analysis.simulation
    before = sim.counters.snapshot()
    model = forecast_model(analysis)
    with model.reading():
        out = _forecast(model, analysis, result, DRAWS if draws is None else draws, seconds, seed, progress)
    return replace(out, counts=sim.counters.since(before), seconds=time.perf_counter() - t0)


def _forecast(model: ForecastModel, analysis, result, n: int, seconds: float, seed: int, progress) -> Forecasts:
    params = result.parameters
    p = result.fit.p
    values = analysis.values_at(p)
    q, F = model(values, params.names, sensitivities=True)
    rel = result.reliability
    Cp = rel.covariance
    Cq = rel.linear.prediction_covariance(F)  # F C_p F^t (eqn 55 propagated)
    std = rel.linear.prediction_std(F)  # inf for a forecast that depends on an undetermined combination
    z = Z95
    if np.isfinite(rel.ellipse_dof) and rel.scales_estimated:
        from scipy import special

        z = float(special.stdtrit(rel.ellipse_dof, 0.975))
    rows = model.layout(values)
    alert = np.array([r[8] for r in rows], float)
    out = Forecasts([r[0] for r in rows], [r[1] for r in rows], [r[2] for r in rows], [r[3] for r in rows],
                    [r[9] for r in rows], np.array([r[4] for r in rows]),
                    np.array([r[5] for r in rows]), np.array([r[6] for r in rows]), [r[7] for r in rows],
                    q, std, q - z * std, q + z * std, F, Cq, list(params.names), z, Cp, alert,
                    _exceed(q, std, alert))
    if n > 0 and np.all(np.isfinite(Cp)):
        out = _sampled(out, model, analysis, result, n, seconds, seed, progress)
    return out


def parameter_draws(C: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """n draws (n, k) of dp ~ N(0, C) (C a parameters' covariance; by its eigenvectors, so a singular C
    draws along what it determines): the parameter sets of a linearised Monte Carlo (``worth.damage``)."""
    w, V = np.linalg.eigh(0.5 * (C + C.T))
    return rng.standard_normal((n, len(w))) @ (V * np.sqrt(np.clip(w, 0, None))).T


def _sampled(out: Forecasts, model: ForecastModel, analysis, result, n: int, budget: float, seed: int, progress):
    """The sampling check: the forecasts at draws from N(p, C_p) (ln p for log parameters)."""
    params, p, Cp = result.parameters, result.fit.p, result.reliability.covariance
    log = np.asarray(params.log, bool) & (p > 0)
    scale = np.where(log, np.abs(p), 1.0)  # C of (ln p where log, p elsewhere)
    C = Cp / np.outer(scale, scale)
    try:
        L = np.linalg.cholesky(0.5 * (C + C.T))
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(0.5 * (C + C.T))
        L = V * np.sqrt(np.clip(w, 0, None))
    rng = np.random.default_rng(seed)
    sim = analysis.simulation
    from geoback.inference.parameters import parameter_limits

    samples, rejected, t0 = [], 0, time.perf_counter()
    for k in range(n * 2):
        if len(samples) >= n or (len(samples) >= 50 and time.perf_counter() - t0 > budget):
            break
        d = L @ rng.standard_normal(len(p))
        draw = p + d
        draw[log] = p[log] * np.exp(d[log])
        values = analysis.values_at(draw)
        if np.any(draw < params.lower) or np.any(draw > params.upper) or \
                not all(parameter_limits(sim, nm, values).contains(v) for nm, v in zip(params.names, draw)):
            rejected += 1
            continue
        try:
            samples.append(model(values)[0])
        except Exception:  # noqa: BLE001 - a draw the model cannot run (non-convergence) is counted, not hidden
            rejected += 1
        if progress is not None and len(samples) % 50 == 0:
            progress(f"forecast sampling check: {len(samples)} of {n} draws")
    if len(samples) < 20:
        return replace(out, draws=len(samples), rejected=rejected)
    S = np.array(samples)
    lo, hi = np.percentile(S, [2.5, 97.5], axis=0)
    exceed = np.where(np.isnan(out.alert), np.nan, np.mean(np.abs(S) > np.nan_to_num(out.alert, nan=np.inf), axis=0))
    # the sampled ends' own error (a quantile of N draws) against the band's width
    se = math.sqrt(0.025 * 0.975 / len(S)) / 0.05844 * out.std  # 0.0584 = phi(1.96)
    width = out.high - out.low
    off = np.maximum(np.abs(lo - out.low), np.abs(hi - out.high))
    bad = off > np.maximum(0.1 * width, 3 * se) + 1e-12 * np.abs(out.value).max(initial=0)
    nonlinear = [nm for nm in out.names if np.any(bad[out.rows(nm)])]
    return replace(out, sampled_low=lo, sampled_high=hi, sampled_exceed=exceed, samples=S, draws=len(S),
                   rejected=rejected, nonlinear=nonlinear)
