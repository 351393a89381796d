"""Building damage from the predicted greenfield ground movement: Burland & Wroth (1974), Burland
(1995), with the limiting tensile strains of Boscardin & Cording (1989) as Burland (1995) gives them.

A building is a line at its foundation level (`buildings:` in the case: x_start, length, height H,
foundation_depth, E/G, Poisson's ratio nu, stage). Along it, the model's settlement and horizontal
displacement at the estimate (greenfield: the building's own stiffness and weight are not in the model)
is split at the inflection points of the settlement profile into sagging parts (the ground concave
upwards, d2u_y/dx2 > 0) and hogging parts; each part of length L is assessed on its own (Mair,
Taylor & Burland 1996):

- deflection ratio Delta/L: the largest relative deflection from the chord joining the part's ends
  (sagging: below it, hogging: above it), over L;
- average horizontal strain eps_h = (u_x(end) - u_x(start)) / L (extension +; a compressive eps_h
  is taken as 0: no credit for compression);
- the deep beam of Burland & Wroth (1974), of length L, height H, E/G, neutral axis at mid-height for
  sagging (I = H^3/12, t = H/2) and at the bottom for hogging (I = H^3/3, t = H):

      bending:  Delta/L = (L / (12 t) + 3 I E / (2 t L H G)) eps_b,max
      shear:    Delta/L = (1 + H L^2 G / (18 I E)) eps_d,max

- combined with eps_h (Boscardin & Cording 1989; Burland 1995):

      eps_br = eps_h + eps_b,max
      eps_dr = eps_h (1 - nu)/2 + sqrt(eps_h^2 ((1 + nu)/2)^2 + eps_d,max^2)

  the part's critical strain is max(eps_br, eps_dr), the building's the largest of its parts';
- damage category by the limiting tensile strain: 0 negligible < 0.05 %, 1 very slight 0.05-0.075 %,
  2 slight 0.075-0.15 %, 3 moderate 0.15-0.3 %, 4-5 severe to very severe > 0.3 % (a strain on a limit
  belongs to the higher category).

The probability of each category comes from the parameters' uncertainty: p ~ N(p_hat, C_p) sampled,
the movements linearised at the estimate with their exact sensitivities (u = u_hat + F (p - p_hat),
``Simulation.surveying``), and the whole assessment (split, Delta/L, eps_h, category) repeated per draw.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np

LIMITS = (0.0005, 0.00075, 0.0015, 0.003)  # limiting tensile strain between categories [-]
CATEGORIES = ("0 negligible", "1 very slight", "2 slight", "3 moderate", "4-5 severe to very severe")
POINTS = 161  # points along a building
DRAWS = 4000
MIN_PART = 0.02  # a sagging or hogging stretch shorter than this fraction of the building joins its neighbour


# ---------------------------------------------------------------------------- the deep beam
def category(strain) -> np.ndarray | int:
    """Damage category index 0..4 of the critical tensile strain (a strain on a limit: the higher one)."""
    out = np.searchsorted(np.asarray(LIMITS), np.asarray(strain, float), side="right")
    return int(out) if np.ndim(out) == 0 else out


def beam(L: float, H: float, hogging: bool) -> tuple[float, float]:
    """(I, t) of the deep beam: neutral axis at mid-height (sagging), at the bottom (hogging)."""
    return (H ** 3 / 3.0, H) if hogging else (H ** 3 / 12.0, H / 2.0)


def bending_factor(L, H, E_over_G: float, hogging: bool):
    """(Delta/L) / eps_b,max = L/(12 t) + 3 I E / (2 t L H G) (Burland & Wroth 1974)."""
    I, t = beam(L, H, hogging)
    L = np.asarray(L, float)
    return L / (12.0 * t) + 3.0 * I * E_over_G / (2.0 * t * L * H)


def shear_factor(L, H, E_over_G: float, hogging: bool):
    """(Delta/L) / eps_d,max = 1 + H L^2 G / (18 I E) (Burland & Wroth 1974)."""
    I, _ = beam(L, H, hogging)
    L = np.asarray(L, float)
    return 1.0 + H * L ** 2 / (18.0 * I * E_over_G)


def limiting_strains(deflection_ratio, L, H, E_over_G: float, hogging: bool):
    """(eps_b,max, eps_d,max) of a deep beam deflected by Delta/L."""
    return (deflection_ratio / bending_factor(L, H, E_over_G, hogging),
            deflection_ratio / shear_factor(L, H, E_over_G, hogging))


def combined(eps_b, eps_d, eps_h, nu: float):
    """(eps_br, eps_dr) with the horizontal strain (Boscardin & Cording 1989; Burland 1995)."""
    eps_h = np.asarray(eps_h, float)
    br = eps_h + eps_b
    dr = eps_h * (1 - nu) / 2 + np.sqrt(eps_h ** 2 * ((1 + nu) / 2) ** 2 + np.asarray(eps_d, float) ** 2)
    return br, dr


# ---------------------------------------------------------------------------- a profile's parts
@dataclass(frozen=True)
class Part:
    """A sagging or hogging stretch of a building: from x_a to x_b [m], Delta [m], Delta/L, eps_h,
    eps_b, eps_d, eps_br, eps_dr, the critical strain and its category."""

    mode: str  # 'sagging' or 'hogging'
    x_a: float
    x_b: float
    deflection: float
    deflection_ratio: float
    eps_h: float
    eps_b: float
    eps_d: float
    eps_br: float
    eps_dr: float

    @property
    def length(self) -> float:
        return self.x_b - self.x_a

    @property
    def critical(self) -> float:
        return max(self.eps_br, self.eps_dr)

    @property
    def category(self) -> int:
        return category(self.critical)


KNOT_SPACING = 2.5  # m: the settlement's curvature is read off a least-squares cubic spline with knots this far
KNOTS = (3, 12)  # apart, within this many intervals along the building (the model's interpolation between
# element nodes is not smooth enough to show the curvature's sign point by point)


def curvature_operator(x) -> np.ndarray:
    """M (n, n): d2/dx2 of the least-squares cubic spline through values at x (uniform knots, KNOT_SPACING
    apart, KNOTS intervals at the least and most), so that the smoothed curvature is M u."""
    from scipy.interpolate import BSpline

    x = np.asarray(x, float)
    L = x[-1] - x[0]
    m = int(np.clip(math.ceil(L / KNOT_SPACING), *KNOTS))
    t = np.r_[[x[0]] * 4, np.linspace(x[0], x[-1], m + 1)[1:-1], [x[-1]] * 4]
    nb = len(t) - 4
    B = BSpline.design_matrix(x, t, 3).toarray()
    B2 = np.column_stack([BSpline(t, np.eye(nb)[j], 3).derivative(2)(x) for j in range(nb)])
    return B2 @ np.linalg.lstsq(B, np.eye(len(x)), rcond=None)[0]


def split(x, uy, M=None) -> list[tuple[int, int, str]]:
    """(start, end, mode) index ranges of the sagging and hogging parts of the profile u_y(x), split at
    its inflection points (sign changes of the smoothed d2u_y/dx2 = M u_y, ``curvature_operator``;
    stretches shorter than MIN_PART of the length merged into their neighbours)."""
    x, uy = np.asarray(x, float), np.asarray(uy, float)
    n = len(x)
    curv = (curvature_operator(x) if M is None else M) @ uy
    scale = np.abs(curv).max()
    if scale == 0:
        return [(0, n - 1, "sagging")]
    sign = np.where(curv >= 0, 1, -1)
    runs = []  # [start, end, sign]
    for k in range(n):
        if runs and runs[-1][2] == sign[k]:
            runs[-1][1] = k
        else:
            runs.append([k, k, sign[k]])
    span = x[-1] - x[0]
    changed = True
    while changed and len(runs) > 1:  # merge short runs into the longer neighbour
        changed = False
        lengths = [x[r[1]] - x[r[0]] for r in runs]
        j = int(np.argmin(lengths))
        if lengths[j] < MIN_PART * span:
            if j == 0:
                runs[1][0] = runs[0][0]
            elif j == len(runs) - 1:
                runs[-2][1] = runs[-1][1]
            elif lengths[j - 1] >= lengths[j + 1]:
                runs[j - 1][1] = runs[j][1]
            else:
                runs[j + 1][0] = runs[j][0]
            runs.pop(j)
            merged = [runs[0]]  # neighbours of one sign join
            for r in runs[1:]:
                if r[2] == merged[-1][2]:
                    merged[-1][1] = r[1]
                else:
                    merged.append(r)
            runs = merged
            changed = True
    out = []
    for k, (a, b, sg) in enumerate(runs):  # parts meet at the inflection points
        a = 0 if k == 0 else a - 1
        out.append((a, b, "sagging" if sg > 0 else "hogging"))
    return out


def assess(x, ux, uy, H: float, E_over_G: float = 2.6, nu: float = 0.3, M=None) -> list[Part]:
    """The parts of a building on the ground movement (ux, uy) at x along its foundation (module docstring);
    M: ``curvature_operator(x)`` (computed here if not given)."""
    x, ux, uy = (np.asarray(v, float) for v in (x, ux, uy))
    parts = []
    for a, b, mode in split(x, uy, M):
        xa, xb = x[a], x[b]
        L = xb - xa
        if L <= 0:
            continue
        seg = slice(a, b + 1)
        chord = uy[a] + (uy[b] - uy[a]) * (x[seg] - xa) / L
        rel = (chord - uy[seg]) if mode == "sagging" else (uy[seg] - chord)
        delta = max(float(rel.max()), 0.0)
        eps_h = (ux[b] - ux[a]) / L
        hog = mode == "hogging"
        eb, ed = limiting_strains(delta / L, L, H, E_over_G, hog)
        br, dr = combined(eb, ed, max(eps_h, 0.0), nu)
        parts.append(Part(mode, float(xa), float(xb), delta, delta / L, float(eps_h), float(eb), float(ed),
                          float(br), float(dr)))
    return parts


def critical(parts) -> float:
    return max((p.critical for p in parts), default=0.0)


# ---------------------------------------------------------------------------- results
@dataclass(frozen=True)
class BuildingStage:
    """One building after one stage: its parts, the critical strain and category at the estimate, the
    movement along it (x, ux, uy [m]) and the probability of each category (None: no C_p)."""

    stage: str
    parts: tuple
    x: np.ndarray
    ux: np.ndarray
    uy: np.ndarray
    probabilities: np.ndarray | None
    strain_quantiles: tuple | None = None  # (2.5 %, 50 %, 97.5 %) of the critical strain over the draws

    @property
    def critical(self) -> float:
        return critical(self.parts)

    @property
    def category(self) -> int:
        return category(self.critical)


@dataclass(frozen=True)
class BuildingDamage:
    name: str
    x_start: float
    length: float
    height: float
    foundation_depth: float
    E_over_G: float
    nu: float
    stages: dict  # stage -> BuildingStage


@dataclass(frozen=True)
class Damage:
    buildings: dict  # name -> BuildingDamage
    parameters: tuple
    draws: int
    method: str  # how the probabilities were found, in words


def _probabilities(x, u0x, u0y, Fx, Fy, C, H, eg, nu, draws, rng):
    """Category frequencies (5,) and strain quantiles over draws of p ~ N(0, C) on the linearised movement."""
    from geoback.worth.forecast import parameter_draws

    d = parameter_draws(C, draws, rng)
    UX, UY = u0x + d @ Fx.T, u0y + d @ Fy.T
    M = curvature_operator(x)
    strains = np.array([critical(assess(x, UX[k], UY[k], H, eg, nu, M)) for k in range(draws)])
    counts = np.bincount(category(strains), minlength=len(CATEGORIES))[:len(CATEGORIES)]
    return counts / draws, tuple(float(q) for q in np.percentile(strains, [2.5, 50, 97.5]))


def building_points(case, b) -> tuple[np.ndarray, np.ndarray, float]:
    """x along the building, the points where the model is read (mirrored to x >= 0 in a half-model)
    and the sign of u_x there (-1 where mirrored)."""
    from geoback.worth.trough import is_half

    x = np.linspace(b.x_start, b.x_start + b.length, POINTS)
    sign = np.where(x < 0, -1.0, 1.0) if is_half(case) else np.ones(POINTS)
    read = np.abs(x) if is_half(case) else x
    return x, read, sign


def damage(analysis, result, draws: int = DRAWS, seed: int = 0) -> Damage | None:
    """Every building of the case at the estimate of `result`, per stage, with the probability of each
    category (None without buildings)."""
    from geoback.observation.instruments import build_block
    from geoback.physics.simulation import is_constant

    loaded, case = analysis.loaded, analysis.loaded.case
    buildings = getattr(case, "buildings", None) or []
    if not buildings:
        return None
    sim = analysis.simulation
    stages = list(sim.stages)
    names = list(result.parameters.names)
    cols = [j for j, n in enumerate(names) if not is_constant(n)]
    pnames = [names[j] for j in cols]
    values = {k: v for k, v in analysis.values_at(result.fit.p).items() if not is_constant(k)}
    C = np.asarray(result.reliability.covariance, float)[np.ix_(cols, cols)] if cols else None
    usable = C is not None and np.all(np.isfinite(C)) and not np.any(result.reliability.linear.undetermined)
    rng = np.random.default_rng(seed)
    blocks, where = [], []
    for b in buildings:
        x, read, sign = building_points(case, b)
        for st in ([b.stage] if b.stage else stages):
            pts = [(float(a), -float(b.foundation_depth)) for a in read]
            blocks.append(build_block(SimpleNamespace(kind="points", name=f"building-{b.name}", points=pts,
                                                      components=["ux", "uy"], sigma=1.0), loaded, 0).at(st))
            where.append((b, st, x, sign))
    pred = sim.surveying(blocks).predict(values, pnames, bool(pnames))
    out, start = {}, 0
    for (b, st, x, sign) in where:
        m = 2 * len(x)
        u = pred.x[start:start + m].reshape(-1, 2)
        A = pred.A[start:start + m].reshape(len(x), 2, -1) if pnames else None
        start += m
        ux, uy = sign * u[:, 0], u[:, 1]
        eg = float(b.E_over_G)
        nu = float(b.nu)
        parts = tuple(assess(x, ux, uy, b.height, eg, nu))
        probs = q = None
        if usable:
            probs, q = _probabilities(x, ux, uy, sign[:, None] * A[:, 0, :], A[:, 1, :], C, b.height, eg, nu,
                                      draws, rng)
        bd = out.setdefault(b.name, BuildingDamage(b.name, float(b.x_start), float(b.length), float(b.height),
                                                   float(b.foundation_depth), eg, nu, {}))
        bd.stages[st] = BuildingStage(st, parts, x, ux, uy, probs, q)
    method = (f"{draws} draws of the identified parameters from N(p̂, C_p), the movements linearised at the "
              f"estimate with their exact sensitivities (u = û + F Δp)" if usable else
              "no probabilities: " + ("no identified parameters" if not cols else
                                      "C_p is not finite (a combination of parameters the readings do not determine)"))
    return Damage(out, tuple(pnames), draws if usable else 0, method)


def of_result(analysis, result) -> Damage | None:
    return damage(analysis, result)
