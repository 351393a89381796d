"""The surface settlement trough: the standard Gaussian trough (Peck 1969; O'Reilly & New 1982;
Mair, Taylor & Bracegirdle 1993)

    S(x) = S_max exp(-(x - x0)^2 / (2 i^2))          (settlement S down positive)

fitted per construction stage to (a) the measured surface settlements (settlement points reading
u_y at the ground surface, S = -u_y) and (b) the model's predicted surface settlement at the
estimate (a dense line of surface points), with

    V_s = sqrt(2 pi) i S_max   [m3/m]      the volume of the whole trough per metre of tunnel,
    V_L = 100 V_s / A          [%]         volume loss (A: the area excavated by that stage),
    K   = i / z0               [-]         trough width parameter (z0: depth of the tunnel axis;
                                           for openings, of the centroid of the ground excavated).

A half-model (symmetry plane at the tunnel axis, x0 = 0) holds half a trough: it is fitted with x0
fixed at 0 on |x| and the volume of the whole (mirrored) trough is the formula above, twice the
half-trough's integral. In a full model x0 is fitted, or fixed at the centre (the centroid's x) of the
ground excavated by that stage when the readings do not determine it (no reading on one side of it,
or its std above i); ``trough.axis_x`` in the case fixes it.

The fit is weighted least squares, theta = (S_max, i[, x0]), r = s - S(x; theta), minimising
r^t W r with W = C_x^-1 for the readings (their covariance, times k^2 where an error scale k is
estimated) and W = I for the model's dense profile. Its derivative with respect to the data is
exact (the implicit-function theorem at the minimum, r != 0 included):

    dtheta/ds = H^-1 J^t W,   H = J^t W J - sum_k (W r)_k d2S_k/dtheta2,   J = dS/dtheta,

which is (J^t J)^-1 J^t (Gauss-Newton) where the trough fits exactly. So

    measured:   C_theta = (dtheta/ds) C_x (dtheta/ds)^t       (= (J^t W J)^-1 at a perfect fit)
    predicted:  dtheta/dp = (dtheta/ds) (ds/dp),  C_theta = (dtheta/dp) C_p (dtheta/dp)^t

with ds/dp the exact sensitivities of the surface settlement (``Simulation.surveying``). V_L and K
(and the curve's band) follow by the delta method, grad(V_L) = 100 sqrt(2 pi) (i, S_max) / A.

A fit is called not determined, and said so in words instead of numbers, with fewer readings than
unknowns + 1, an i at the bound of the fit (no fall-off within the points: the width unbounded), an
S_max <= 0 or within 2 std of zero (no trough), or an i whose std exceeds half of it.
Readers (``reports/trough.py``, ``reports/plots/trough.py``) take a ``Troughs`` and run nothing.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

SQRT2PI = math.sqrt(2.0 * math.pi)
SURFACE_TOL = 1e-6  # m: a reading is at the ground surface within this of y = 0
DEFAULT_EXTENT = 2.5  # the predicted profile reaches this many z0 from the axis without measured points
DENSE = 121  # points of the predicted profile (a half-model's side; twice in a full model)
I_MAX = 2.0  # i beyond this many times the farthest point from x0: the width is not determined


# ---------------------------------------------------------------------------- the Gaussian and its fit
def gaussian(x, S_max: float, i: float, x0: float = 0.0) -> np.ndarray:
    """S(x) = S_max exp(-(x - x0)^2 / (2 i^2))."""
    x = np.asarray(x, float)
    return S_max * np.exp(-0.5 * ((x - x0) / i) ** 2)


def _derivatives(x, theta, fit_x0: bool):
    """S, J = dS/dtheta (n, k) and the second derivatives (n, k, k) of theta = (S_max, i[, x0])."""
    S_max, i = theta[0], theta[1]
    x0 = theta[2] if fit_x0 else 0.0
    d = np.asarray(x, float) - x0
    e = np.exp(-0.5 * (d / i) ** 2)
    g = S_max * e
    dS, di = e, g * d ** 2 / i ** 3
    cols = [dS, di]
    k = 3 if fit_x0 else 2
    Hs = np.zeros((len(d), k, k))
    Hs[:, 0, 1] = Hs[:, 1, 0] = e * d ** 2 / i ** 3
    Hs[:, 1, 1] = g * (d ** 4 / i ** 6 - 3 * d ** 2 / i ** 4)
    if fit_x0:
        dx0 = g * d / i ** 2
        cols.append(dx0)
        Hs[:, 0, 2] = Hs[:, 2, 0] = e * d / i ** 2
        Hs[:, 1, 2] = Hs[:, 2, 1] = g * (d ** 3 / i ** 5 - 2 * d / i ** 3)
        Hs[:, 2, 2] = g * (d ** 2 / i ** 4 - 1 / i ** 2)
    return g, np.column_stack(cols), Hs


@dataclass(frozen=True)
class GaussianFit:
    """theta = (S_max, i, x0) fitted to settlements s at x (x0 given where not fitted); `gain` =
    dtheta/ds (3, n) exact at the minimum (module docstring; the x0 row zero where x0 is fixed);
    `at_bound`: i ended at the fit's bound; chi2 = r^t W r."""

    theta: np.ndarray
    fit_x0: bool
    gain: np.ndarray
    chi2: float
    n: int
    at_bound: str  # '' or 'upper' / 'lower' (i)
    i_bounds: tuple

    @property
    def unknowns(self) -> int:
        return 3 if self.fit_x0 else 2


def fit_gaussian(x, s, whiten=None, x0: float = 0.0, fit_x0: bool = False, i_bounds=None) -> GaussianFit:
    """The Gaussian trough through settlements s (down positive) at x, minimising r^t W r with W = C^-1
    given by `whiten` (v -> L^-1 v for C = L L^t, the rows of a matrix as well: ``readings_whitener``;
    default W = I); x0 fixed at `x0` unless `fit_x0`. i is bounded by `i_bounds` (default: 1e-3 to I_MAX
    times the farthest point from x0)."""
    from scipy.optimize import least_squares

    x, s = np.asarray(x, float), np.asarray(s, float)
    n = len(x)
    Li = np.eye(n) if whiten is None else np.asarray(whiten(np.eye(n)), float)  # L^-1: W = L^-t L^-1
    reach = max(float(np.abs(x - x0).max()) if not fit_x0 else float(np.ptp(x)), 1e-9)
    lo, hi = i_bounds if i_bounds is not None else (1e-3 * reach, I_MAX * reach)
    # start: the largest settlement and the second moment of the positive settlements about x0
    j = int(np.argmax(s))
    c = float(x[j]) if fit_x0 else x0
    w = np.clip(s, 0, None)
    i0 = math.sqrt(float(np.sum(w * (x - c) ** 2) / np.sum(w))) if w.sum() > 0 else 0.5 * reach
    i0 = min(max(i0, 1.01 * lo), 0.99 * hi)
    start = [max(float(s[j]), 1e-12), i0] + ([c] if fit_x0 else [])
    lower = [-np.inf, lo] + ([float(x.min())] if fit_x0 else [])
    upper = [np.inf, hi] + ([float(x.max())] if fit_x0 else [])
    if fit_x0 and not lower[2] < start[2] < upper[2]:
        start[2] = 0.5 * (lower[2] + upper[2])

    def res(t):
        return Li @ (_derivatives(x, t, fit_x0)[0] - s)

    def jac(t):
        return Li @ _derivatives(x, t, fit_x0)[1]

    sol = least_squares(res, start, jac=jac, bounds=(lower, upper), method="trf", xtol=1e-15, ftol=1e-15,
                        gtol=1e-15, max_nfev=2000, x_scale="jac")
    t = np.asarray(sol.x, float)
    g, J, Hs = _derivatives(x, t, fit_x0)
    r = s - g
    Jw = Li @ J
    Wr = Li.T @ (Li @ r)
    H = Jw.T @ Jw - np.einsum("n,nab->ab", Wr, Hs)
    JtW = Jw.T @ Li
    if np.all(np.linalg.eigvalsh(0.5 * (H + H.T)) > 0):
        gain = np.linalg.solve(H, JtW)
    else:  # not a proper minimum (a bound): the Gauss-Newton gain
        gain = np.linalg.lstsq(Jw.T @ Jw, JtW, rcond=None)[0]
    full = np.zeros((3, n))
    full[:len(t)] = gain
    theta = np.array([t[0], t[1], t[2] if fit_x0 else x0])
    tol = 1e-6 * (hi - lo)
    bound = "upper" if t[1] >= hi - tol else "lower" if t[1] <= lo + tol else ""
    return GaussianFit(theta, fit_x0, full, float(r @ Wr), n, bound, (lo, hi))


def readings_whitener(C, name: str = "the settlement readings"):
    """v -> L^-1 v for C = L L^t, the readings' covariance (the seam's whitening, ``whiten_block``)."""
    from geoback.inference.misfit import whiten_block

    block = SimpleNamespace(name=name, covariance=np.asarray(C, float))
    return lambda v: whiten_block(block, v, block.covariance)


def derived_gradient(theta, area: float, z0: float) -> np.ndarray:
    """d(S_max, i, x0, V_s, V_L, K)/d(S_max, i, x0) (6, 3) (the delta method's rows)."""
    S, i = theta[0], theta[1]
    D = np.zeros((6, 3))
    D[0, 0] = D[1, 1] = D[2, 2] = 1.0
    D[3, 0], D[3, 1] = SQRT2PI * i, SQRT2PI * S
    D[4] = 100.0 * D[3] / area
    D[5, 1] = 1.0 / z0
    return D


# ---------------------------------------------------------------------------- results
QUANTITIES = ("S_max", "i", "x0", "V_s", "V_L", "K")


@dataclass(frozen=True)
class Trough:
    """One fitted trough (measured or predicted) of one stage: the values of QUANTITIES (S_max [m],
    i [m], x0 [m], V_s [m3/m], V_L [%], K [-]) with their std (NaN: none; inf: not determined by the
    parameters' readings), the opening it is read against (area [m2], z0 [m]), how x0 was set, the
    points fitted (x, settlement s [m], their std) and the fitted curve with its std on `curve_x`.
    `reason`: why the fit is not determined ('' when it is)."""

    source: str  # 'measured' or 'predicted'
    stage: str
    values: dict
    std: dict
    area: float
    z0: float
    x0_how: str  # 'symmetry axis', 'fitted', 'opening centre (the readings do not determine it)', 'given'
    half: bool
    x: np.ndarray
    s: np.ndarray
    s_std: np.ndarray | None
    curve_x: np.ndarray
    curve: np.ndarray
    curve_std: np.ndarray
    chi2: float
    dof: int
    reason: str = ""
    instruments: tuple = ()
    theta_covariance: np.ndarray | None = None  # of (S_max, i, x0)
    theta_sensitivity: np.ndarray | None = None  # predicted: d(S_max, i, x0)/dp (3, n)

    @property
    def determined(self) -> bool:
        return not self.reason

    def interval(self, q: str, z: float) -> tuple[float, float]:
        v, s = self.values[q], self.std[q]
        return v - z * s, v + z * s


@dataclass(frozen=True)
class Troughs:
    """The troughs of a run: per stage the measured fit (where surface settlements were read) and the
    model's (at the estimate, band from C_p); what was assumed, in words (`assumed`)."""

    measured: dict  # stage -> Trough
    predicted: dict  # stage -> Trough
    stages: tuple
    z: float  # the predicted band: value +- z std (normal, or Student t as the forecasts)
    z_measured: float
    parameters: tuple
    assumed: tuple  # sentences: the axis, z0, the area, the window of the predicted profile, ...
    extent: dict = field(default_factory=dict)  # stage -> (x_low, x_high) of the predicted profile

    def __bool__(self) -> bool:
        return bool(self.measured or self.predicted)


# ---------------------------------------------------------------------------- the case's openings
@dataclass(frozen=True)
class Opening:
    """What a stage's trough is read against: the area excavated by then [m2] (whole opening, both
    sides of a half-model), z0 [m] and the centre's x [m]; `words` says what z0 is."""

    area: float
    z0: float
    centre: float
    words: str


def openings_by_stage(case, stages) -> dict:
    """stage -> Opening (None before anything is excavated)."""
    from geoback.case.schema import Geometry

    g = case.geometry
    if isinstance(g, Geometry):
        op = Opening(math.pi * g.radius ** 2, g.axis_depth, 0.0, "the depth of the tunnel axis")
        return {s: op for s in stages}
    from shapely.ops import unary_union

    from geoback.case.layout import regions
    from geoback.case.sequence import Sequence

    regs = regions(g)
    out, dug = {}, []
    for step, stage in zip(Sequence.of(case).steps, stages):
        dug += [regs[r][1] for r in step.excavate if r in regs]
        if not dug:
            out[stage] = None
            continue
        u = unary_union(dug)
        c = u.centroid
        out[stage] = Opening(float(u.area), float(-c.y), 0.0 if g.model == "half" else float(c.x),
                             "the depth of the centroid of the ground excavated by that stage")
    return out


def is_tunnel(case) -> str:
    """'' when the case is a tunnel a trough applies to, else why not (in words)."""
    from geoback.case.schema import Geometry

    g = case.geometry
    if isinstance(g, Geometry):
        return ""
    c = case.construction
    if c is not None and c.walls:
        return "an excavation with retaining walls (no tunnel trough; add a `trough:` section to ask for one)"
    from geoback.case.layout import regions

    if any(p.bounds[3] > -SURFACE_TOL for _, p in regions(g).values()):
        return "an opening reaches the ground surface (an open excavation, not a tunnel)"
    return ""


def surface_rows(labels, instruments=None) -> dict:
    """stage -> row indices of the readings of settlement points (u_y) at the ground surface
    (of `instruments` only, when given); unstaged readings count for stage None."""
    out = {}
    for k, lab in enumerate(labels):
        if lab.kind != "points" or lab.component != "uy" or abs(lab.y) > SURFACE_TOL:
            continue
        if instruments is not None and lab.instrument not in instruments:
            continue
        out.setdefault(lab.stage, []).append(k)
    return out


def wanted(case, labels) -> bool:
    """Does the run compute troughs? A tunnel with surface settlement readings, or a `trough:` section."""
    if getattr(case, "trough", None) is not None:
        return True
    return not is_tunnel(case) and bool(surface_rows(labels))


# ---------------------------------------------------------------------------- one trough
def _verdict(fit: GaussianFit, std_S: float, std_i: float, source: str) -> str:
    if fit.n < fit.unknowns + 1:
        return (f"too few points: {fit.n} surface reading{'s' if fit.n != 1 else ''} for {fit.unknowns} unknowns "
                f"(S_max, i{', x0' if fit.fit_x0 else ''}): at least {fit.unknowns + 1} are needed")
    S, i = fit.theta[0], fit.theta[1]
    if not np.isfinite(S) or S <= 0:
        return ("no settlement trough: the " + ("readings show" if source == "measured" else "model predicts")
                + " heave or no settlement at the surface")
    if fit.at_bound == "upper":
        return (f"the trough width i is not determined: the settlements do not fall off within the points "
                f"(i would exceed {fit.i_bounds[1]:.3g} m, {I_MAX:g} times the farthest point from the axis)")
    if fit.at_bound == "lower":
        return "the trough width i is not determined: narrower than the points can show"
    if source == "measured" and np.isfinite(std_S) and S < 2 * std_S:
        return (f"no settlement trough: S_max = {1e3 * S:.2g} mm is within 2 std ({1e3 * std_S:.2g} mm) of zero")
    if source == "measured" and np.isfinite(std_i) and std_i > 0.5 * i:
        return (f"the trough width i is not determined by these points: i = {i:.3g} m with a std of "
                f"{std_i:.2g} m (more than half of it)")
    return ""


def _trough(source, stage, x, s, s_std, fit: GaussianFit, C_theta, opening: Opening, x0_how, half, curve_x,
            instruments=(), theta_sens=None) -> Trough:
    D = derived_gradient(fit.theta, opening.area, opening.z0)
    vals = dict(zip(QUANTITIES, [fit.theta[0], fit.theta[1], fit.theta[2], SQRT2PI * fit.theta[1] * fit.theta[0],
                                 100 * SQRT2PI * fit.theta[1] * fit.theta[0] / opening.area,
                                 fit.theta[1] / opening.z0]))
    if C_theta is None:
        std = {q: math.nan for q in QUANTITIES}
        cs = np.full(len(curve_x), np.nan)
    else:
        C = D @ C_theta @ D.T
        std = {q: float(math.sqrt(max(C[k, k], 0.0))) if np.isfinite(C[k, k]) else math.inf
               for k, q in enumerate(QUANTITIES)}
        _, Jc, _ = _derivatives(curve_x, fit.theta, True)  # d S(x)/d(S_max, i, x0) on the curve
        vc = np.einsum("ij,jk,ik->i", Jc, C_theta, Jc)
        cs = np.sqrt(np.clip(np.where(np.isfinite(vc), vc, np.inf), 0, None))
    reason = _verdict(fit, std["S_max"], std["i"], source)
    curve = gaussian(curve_x, *fit.theta)
    return Trough(source, stage, vals, std, opening.area, opening.z0, x0_how, half, np.asarray(x, float),
                  np.asarray(s, float), None if s_std is None else np.asarray(s_std, float), np.asarray(curve_x, float),
                  curve, cs, fit.chi2, fit.n - fit.unknowns, reason, tuple(instruments), C_theta, theta_sens)


def measured_trough(stage, x, s, C, opening: Opening, half: bool, axis_x=None, instruments=(),
                    curve_x=None) -> Trough:
    """The Gaussian trough through measured settlements s (down positive, m) at x with covariance C:
    x0 at 0 on |x| (half model), at `axis_x` (given), else fitted where readings lie on both sides of the
    opening's centre and determine it, else fixed at that centre."""
    x, s, C = np.asarray(x, float), np.asarray(s, float), np.asarray(C, float)
    W = readings_whitener(C, ", ".join(instruments) or "the settlement readings")
    if half:
        x = np.abs(x)
        fits = [(fit_gaussian(x, s, W, 0.0, False), "symmetry axis")]
    elif axis_x is not None:
        fits = [(fit_gaussian(x, s, W, float(axis_x), False), "given")]
    else:
        c = opening.centre
        fixed = (fit_gaussian(x, s, W, c, False), "opening centre (the readings do not determine it)")
        fits = [fixed]
        if (x < c).any() and (x > c).any() and len(x) >= 4:
            f = fit_gaussian(x, s, W, c, True)
            Ct = f.gain @ C @ f.gain.T
            sx = math.sqrt(max(Ct[2, 2], 0.0))
            if np.isfinite(sx) and sx < f.theta[1] and not f.at_bound and f.theta[0] > 0 \
                    and x.min() < f.theta[2] < x.max():
                fits = [(f, "fitted")]
    f, how = fits[0]
    Ct = f.gain @ C @ f.gain.T
    if curve_x is None:
        lo, hi = (0.0, x.max()) if half else (x.min(), x.max())
        curve_x = np.linspace(lo, hi, 121)
    return _trough("measured", stage, x, s, np.sqrt(np.diag(C)), f, Ct, opening, how, half, curve_x, instruments)


def predicted_trough(stage, x, s, F, covariance_of, opening: Opening, half: bool, axis_x=None,
                     curve_x=None) -> Trough:
    """The Gaussian trough through the model's dense settlement profile s(x) (least squares, W = I), with
    dtheta/dp = gain F (F = ds/dp, exact) and C_theta = covariance_of(dtheta/dp) (``LinearAnalysis
    .prediction_covariance``; None: no band). x0 at 0 (half model), `axis_x` (given), else fitted."""
    x, s = np.asarray(x, float), np.asarray(s, float)
    if half:
        f, how = fit_gaussian(x, s, None, 0.0, False), "symmetry axis"
    elif axis_x is not None:
        f, how = fit_gaussian(x, s, None, float(axis_x), False), "given"
    else:
        f, how = fit_gaussian(x, s, None, opening.centre, True), "fitted"
    Ft = f.gain @ F if F is not None else None
    Ct = covariance_of(Ft) if Ft is not None and covariance_of is not None else None
    return _trough("predicted", stage, x, s, None, f, Ct, opening, how, half,
                   x if curve_x is None else curve_x, theta_sens=Ft)


# ---------------------------------------------------------------------------- a run's troughs
def _settings(case):
    t = getattr(case, "trough", None)
    return t if t is not None else SimpleNamespace(instruments=None, stages=None, axis_x=None, z0=None, extent=None)


def profile_points(case, opening: Opening, extent: float) -> np.ndarray:
    """The dense surface line of the predicted profile: from the axis out to `extent` (half model), or
    centre +- extent (full model), within the model."""
    from geoback.case.schema import Geometry

    g = case.geometry
    if isinstance(g, Geometry) or g.model == "half":
        return np.linspace(0.0, min(extent, g.width), DENSE)
    lo, hi = max(opening.centre - extent, -g.width / 2), min(opening.centre + extent, g.width / 2)
    return np.linspace(lo, hi, 2 * DENSE - 1)


def is_half(case) -> bool:
    from geoback.case.schema import Geometry

    g = case.geometry
    return isinstance(g, Geometry) or g.model == "half"


def troughs(analysis, result, view_of=None) -> Troughs | None:
    """Every stage's measured and predicted trough at the estimate of `result` (an Identification of
    `analysis`), or None where the case has no trough (``wanted``). The predicted band comes from C_p
    (``Reliability.linear``) through the exact sensitivities of the surface settlement."""
    from geoback.observation.instruments import build_block
    from geoback.physics.simulation import is_constant
    from geoback.worth.walls import band_z
    from geoback.inference.reliability import Z95

    loaded, case = analysis.loaded, analysis.loaded.case
    labels = result.data.labels
    if not wanted(case, labels):
        return None
    t = _settings(case)
    sim = analysis.simulation
    stages = tuple(sim.stages)
    chosen = tuple(t.stages) if t.stages else stages
    ops = openings_by_stage(case, stages)
    half = is_half(case)
    assumed = []
    if half:
        assumed.append("a half-model: its symmetry plane is the tunnel axis (x0 = 0); the half trough it holds is "
                       "fitted on |x| and mirrored, so V_s = √(2π) i S_max is the whole trough's volume (twice the "
                       "half's)")
    elif t.axis_x is not None:
        assumed.append(f"a full model: x0 fixed at {t.axis_x:g} m (trough.axis_x)")
    else:
        assumed.append("a full model: x0 fitted where the readings determine it (points on both sides of the "
                       "excavated opening's centre), else fixed at that centre; the model's trough has x0 fitted")
    first = next((o for o in ops.values() if o is not None), None)
    if first is not None:
        assumed.append(("z0 = %g m (trough.z0)" % t.z0) if t.z0 is not None else f"z0 is {first.words}")
        assumed.append("V_L = 100 V_s / A with A the area excavated by that stage (the whole opening, both sides "
                       "of the symmetry plane)")
    # measured
    names = set(t.instruments) if t.instruments else None
    rows = surface_rows(labels, names)
    C_all = result.data.covariance
    k2 = _scale_squares(result)
    measured = {}
    widest = 0.0
    for st, idx in rows.items():
        stage = st if st is not None else stages[-1]
        if stage not in chosen or ops.get(stage) is None:
            continue
        op = _with_z0(ops[stage], t.z0)
        idx = np.asarray(idx)
        x = np.array([labels[k].x for k in idx])
        s = -np.asarray(result.data.measured)[idx]
        C = C_all[np.ix_(idx, idx)] * np.sqrt(np.outer(k2[idx], k2[idx]))
        ins = tuple(dict.fromkeys(labels[k].instrument for k in idx))
        measured[stage] = measured_trough(stage, x, s, C, op, half, t.axis_x, ins)
        c = 0.0 if half else (t.axis_x if t.axis_x is not None else op.centre)
        widest = max(widest, float(np.abs((np.abs(x) if half else x) - c).max()))
    # predicted
    values = analysis.values_at(result.fit.p)
    pnames = [n for n in result.parameters.names if not is_constant(n)]
    cols = [j for j, n in enumerate(result.parameters.names) if not is_constant(n)]
    rel = result.reliability
    z = band_z(rel)
    predicted, extent, lines = {}, {}, []
    for stage in chosen:
        op = ops.get(stage)
        if op is None:
            continue
        op = _with_z0(op, t.z0)
        reach = t.extent if t.extent is not None else (widest if widest > 0 else DEFAULT_EXTENT * op.z0)
        pts = profile_points(case, op, reach)
        lines.append((stage, op, pts))
    if lines:
        blocks = [build_block(SimpleNamespace(kind="points", name=f"trough-{k}", points=[(float(a), 0.0) for a in pts],
                                              components=["uy"], sigma=1.0), loaded, 0).at(stage)
                  for k, (stage, _, pts) in enumerate(lines)]
        view = sim.surveying(blocks)
        pred = view.predict({k: v for k, v in values.items() if not is_constant(k)}, pnames, True)
        start = 0
        for stage, op, pts in lines:
            sl = slice(start, start + len(pts))
            start += len(pts)
            F = np.zeros((len(pts), len(result.parameters.names)))
            F[:, cols] = -pred.A[sl]
            cov = (lambda G: rel.linear.prediction_covariance(G)) if pnames else None
            tr = predicted_trough(stage, pts, -pred.x[sl], F if pnames else None, cov, op, half, t.axis_x)
            if pnames:  # undetermined combinations: infinite std (as the forecasts)
                theta = np.array([tr.values["S_max"], tr.values["i"], tr.values["x0"]])
                tr = _undetermined(tr, rel, derived_gradient(theta, op.area, op.z0))
            predicted[stage] = tr
            extent[stage] = (float(pts[0]), float(pts[-1]))
        what = ("from the tunnel axis" if half else "about the opening's centre")
        assumed.append(f"the model's trough is fitted to its surface settlement on {DENSE} points {what} out to "
                       + (f"{t.extent:g} m (trough.extent)" if t.extent is not None else
                          f"the farthest settlement point read ({widest:g} m), so that both troughs are fitted over "
                          f"the same stretch of surface" if widest > 0 else
                          f"{DEFAULT_EXTENT:g} z0 (no settlement points read)")
                       + ", least squares with equal weights")
    return Troughs(measured, predicted, chosen, float(z), float(Z95), tuple(pnames), tuple(assumed), extent)


def _with_z0(op: Opening, z0) -> Opening:
    return op if z0 is None else Opening(op.area, float(z0), op.centre, f"{z0:g} m as the case gives (trough.z0)")


def _scale_squares(result) -> np.ndarray:
    """k^2 of every reading whose error scale is estimated (1 elsewhere): its true variance is k^2 C_x."""
    labels = result.data.labels
    k2 = np.ones(len(labels))
    for e in getattr(result.reliability, "error_scales", ()) or ():
        if getattr(e, "estimated", False) and np.isfinite(e.factor):
            for j, lab in enumerate(labels):
                if lab.instrument in e.instruments:
                    k2[j] = e.factor ** 2
    return k2


def _undetermined(tr: Trough, rel, D) -> Trough:
    """Infinite std where a quantity depends on a combination of parameters the readings do not determine."""
    if tr.theta_sensitivity is None:
        return tr
    G = D @ tr.theta_sensitivity
    sd = rel.linear.prediction_std(G)
    std = dict(tr.std)
    for k, q in enumerate(QUANTITIES):
        if not np.isfinite(sd[k]):
            std[q] = math.inf
    from dataclasses import replace

    return replace(tr, std=std)


def of_result(analysis, result) -> Troughs | None:
    """``troughs`` at the estimate of an identification (what `geoback run` writes)."""
    return troughs(analysis, result)
