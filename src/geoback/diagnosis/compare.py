"""How the hypotheses of a round compare: Akaike weights, rivals that explain the readings about
as well as the accepted one (and the readings that would tell them apart), and the size of effect
each score test could have detected.

Akaike weights (Burnham & Anderson 2002, sec. 2.9): w_i = exp(-Delta_i / 2) / sum_j exp(-Delta_j / 2),
Delta_i = AIC_i - min AIC, over the refitted hypotheses and the model without any of them; w_i is
the weight of evidence that model i is the best of the set. Two models within 2 AIC (weights
within a factor e of each other) are "about equally" supported.

A new reading's accuracy: read where two fitted models predict values d apart, a reading x = m_a + sigma e
(e standard normal) changes J_b - J_a by (d^2 + 2 d sigma e) / sigma^2, which reaches the margin M that
singles a cause out (claims.RIVAL_AIC) with probability P when d / sigma >= z + sqrt(z^2 + M), z =
Phi^-1(P): the sigma such a reading needs (the models as fitted; refitting their other parameters can
take up part of d).

Detectable size: under an alternative with the extension at theta, the score statistic is
non-central chi^2(k, lambda), lambda = ||M2 theta||^2 (M2: the part of the whitened sensitivity the
baseline parameters cannot mimic). The size detected with probability POWER at the round's level
is sqrt(lambda*) / ||M2_j||, lambda* solving P(chi^2(k, lambda*) > chi^2_k(1 - level)) = POWER
(one parameter moved at a time, the linearisation of the score test).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from statistics import NormalDist

import numpy as np

from geoback.case.covariance import NotPositiveDefinite
from geoback.diagnosis.claims import RIVAL_AIC
from geoback.inference.misfit import whiten_block
from geoback.units import size_text

EQUAL_AIC = 2.0  # within this many AIC units two hypotheses explain the readings about equally
POWER = 0.8
SEPARATE_POWER = 0.9  # the probability with which a new reading of the accuracy asked for separates two causes


def sigma_to_separate(difference: float, margin: float = RIVAL_AIC, power: float = SEPARATE_POWER) -> float:
    """The standard deviation a new reading needs to put two fitted models `margin` AIC apart by itself with
    probability `power`, read where their predictions differ by `difference` (module docstring)."""
    z = NormalDist().inv_cdf(power)
    return abs(difference) / (z + math.sqrt(z * z + margin))


def akaike_weights(aics: dict[str, float]) -> dict[str, float]:
    """Akaike weights of the models keyed in `aics` (non-finite AICs get weight 0)."""
    finite = {k: v for k, v in aics.items() if np.isfinite(v)}
    if not finite:
        return {k: 0.0 for k in aics}
    best = min(finite.values())
    raw = {k: float(np.exp(-(v - best) / 2)) if np.isfinite(v) else 0.0 for k, v in aics.items()}
    total = sum(raw.values())
    return {k: v / total for k, v in raw.items()}


@dataclass
class Separation:
    """Where two refitted hypotheses' predictions differ most relative to the readings' sigma."""

    readings: list = field(default_factory=list)  # dicts: instrument, station, where, difference [m], in sigma
    instruments: list = field(default_factory=list)  # dicts: instrument, chi2 distance (whitened), readings
    new_points: list = field(default_factory=list)  # dicts: x, depth, component, difference [m]

    def as_dict(self) -> dict:
        return {"readings": self.readings, "instruments": self.instruments, "new_points": self.new_points}

    def text(self, a: str, b: str) -> str:
        parts = []
        if self.readings:
            r = self.readings[0]
            lead = ("the existing readings that differ most are" if abs(r["sigmas"]) >= 2 else
                    f"no existing reading tells them apart by more than {abs(r['sigmas']):.2g} σ (the most:")
            parts.append(f"{lead} {r['instrument']} station {r['station']} "
                         f"({r['where']}: {abs(r['difference']) * 1e3:.2g} mm, {abs(r['sigmas']):.2g} σ)"
                         + ("".join(f", {q['instrument']} station {q['station']} ({abs(q['sigmas']):.2g} σ)"
                                    for q in self.readings[1:3])) + (")" if abs(r["sigmas"]) < 2 else ""))
        if self.instruments:
            i = self.instruments[0]
            parts.append(f"instrument {i['instrument']} separates them most (whitened distance "
                         f"{np.sqrt(i['chi2']):.2g})")
        if self.new_points:
            p = self.new_points[0]
            parts.append(f"a new reading of {p['component']} at x = {p['x']:.3g} m, depth {p['depth']:.3g} m would "
                         f"differ by {abs(p['difference']) * 1e3:.2g} mm between them (read with σ ≤ "
                         f"{p['sigma_needed'] * 1e3:.2g} mm it would set the two, as fitted now, {RIVAL_AIC:g} AIC "
                         f"apart with {100 * SEPARATE_POWER:.0f} % probability; refitted to it, they may take up "
                         f"part of the difference)")
        return "; ".join(parts)


def separation(a, b, data, top: int = 5) -> Separation:
    """Readings (and candidate new points) where the refitted hypotheses a and b (``Scored``)
    predict most differently, in units of each reading's standard deviation; for linewise
    instruments also per interval (primary-reading space, W^-1 d / sigma)."""
    d = a.refit.x - b.refit.x
    sigma = np.sqrt(np.diag(data.covariance))
    out = Separation()
    rows = []
    for block, sl in data.block_rows():
        db = d[sl]
        try:
            w = whiten_block(block, db, data.covariance[sl, sl])
            chi2 = float(w @ w)
        except (NotPositiveDefinite, np.linalg.LinAlgError):
            chi2 = float(np.sum((db / sigma[sl]) ** 2))
        out.instruments.append({"instrument": block.name, "kind": block.kind, "chi2": chi2, "readings": block.m})
        for k, lab in enumerate(block.labels):
            where = (f"{-lab.y:.3g} m depth" if block.kind == "inclinometer" else f"({lab.x:.3g}, {lab.y:.3g})")
            rows.append({"instrument": block.name, "station": lab.station, "component": lab.component,
                         "where": where, "difference": float(db[k]), "sigmas": float(db[k] / sigma[sl][k])})
    rows.sort(key=lambda r: -abs(r["sigmas"]))
    out.readings = rows[:top]
    out.instruments.sort(key=lambda r: -r["chi2"])
    out.new_points = _new_points(a, b)
    return out


def _new_points(a, b, top: int = 3) -> list[dict]:
    """Points of the ground where the two models' displacements differ most (candidate readings)."""
    try:
        sa, sb = a.misfit.simulation, b.misfit.simulation
        case = sa.loaded.case
        g = case.geometry
        if hasattr(g, "openings"):
            pts = _section_points(case)
        else:
            xs = np.linspace(0.0, min(g.width, g.axis_depth + 6 * g.radius), 13)
            zs = np.linspace(0.0, min(g.depth, g.axis_depth + 8 * g.radius), 15)
            pts = np.array([(x, -z) for x in xs for z in zs
                            if np.hypot(x, -z + g.axis_depth) > 1.1 * g.radius and z < 0.97 * g.depth
                            and x < 0.97 * g.width])
        ua = sa.displacements_at(a.misfit.values(a.refit.p), pts)
        ub = sb.displacements_at(b.misfit.values(b.refit.p), pts)
    except Exception:  # noqa: BLE001 - a suggestion only: never fail the diagnosis for it
        return []
    diff = ua - ub
    found = []
    for c, comp in enumerate(("ux", "uy")):
        for i in np.argsort(-np.abs(diff[:, c]))[:top]:
            found.append({"x": float(pts[i, 0]), "depth": float(-pts[i, 1]), "component": comp,
                          "difference": float(diff[i, c]), "sigma_needed": sigma_to_separate(diff[i, c])})
    found.sort(key=lambda r: -abs(r["difference"]))
    return found[:top]


def _section_points(case) -> np.ndarray:
    """A grid of candidate points around the openings of a section (in the ground, out of every opening
    by a tenth of its size), as ``_new_points`` searches around a circular tunnel."""
    from shapely import contains_xy

    from geoback.case.layout import box, polygon

    g = case.geometry
    x0, x1, depth = box(g)
    polys = [polygon(op) for op in g.openings]
    lo = np.min([p.bounds[:2] for p in polys], axis=0)
    hi = np.max([p.bounds[2:] for p in polys], axis=0)
    reach = 3 * max(hi - lo)
    xs = np.linspace(max(x0, lo[0] - reach), min(x1, hi[0] + reach), 13)
    zs = np.linspace(0.0, min(depth, -lo[1] + reach), 15)
    X, Z = np.meshgrid(xs, zs, indexing="ij")
    x, y = X.ravel(), -Z.ravel()
    keep = (y > -0.97 * depth) & (x > x0 + 0.03 * (x1 - x0) - (0.03 * (x1 - x0) if x0 == 0 else 0.0)) & \
        (x < x1 - 0.03 * (x1 - x0))
    for p in polys:
        keep &= ~contains_xy(p.buffer(0.1 * np.sqrt(p.area / np.pi)), x, y)
    return np.column_stack([x[keep], y[keep]])


def detectable_lambda(k: int, level: float, power: float = POWER) -> float:
    """Non-centrality at which the chi^2(k) test at `level` rejects with probability `power`."""
    from scipy import optimize, stats

    crit = stats.chi2.isf(level, k)

    def miss(lam):
        return stats.ncx2.sf(crit, k, lam) - power

    hi = 10.0
    while miss(hi) < 0:
        hi *= 2
    return float(optimize.brentq(miss, 1e-9, hi, xtol=1e-6))


SHORT = {"stiffness-gradient": "a modulus gradient", "layer-boundary": "a stratum with another modulus",
         "lining-stiffness": "a change of the lining's modulus", "release-before-lining": "another release before the lining",
         "anisotropy": "anisotropy", "K0-gradient": "a K0 gradient", "stress-release": "a partial stress release",
         "integration-constant": "a reference-end movement", "bias-shift": "a bias shift", "depth-offset": "a depth offset",
         "wall-stiffness": "a change of the wall's modulus", "support-stiffness": "a change of a support's stiffness",
         "preload-lost": "another preload", "supported-release": "a support before the full release",
         "yielding": "yielding"}
ABSURD = 10.0  # a detectable size this many times the parameter's usual range is "not detectable"


def detectable_text(ranking, level: float = None) -> str:
    """'a modulus gradient of ±0.062 MPa/m ('clay'); a bias shift of ±0.26 mrad (I1, I2); ...': the size
    of effect each kind of hypothesis in the library would have caught with probability POWER,
    one parameter at a time (a group of depths: the smallest and largest over its depths)."""
    by_kind: dict[str, dict[str, list[str]]] = {}
    groups: dict[str, list] = {}
    for s in ranking:
        if s.collinear_with is not None or not s.detectable:
            continue
        if s.hypothesis.group:
            groups.setdefault(s.hypothesis.group, []).append(s)
            continue
        for name, v in s.detectable.items():
            size = _size(name, v, s)
            if size:
                where = name.split("[", 1)[1].rstrip("]") if "[" in name else ""
                by_kind.setdefault(s.hypothesis.kind, {}).setdefault(size, []).append(where)
    parts = []
    for kind, sizes in by_kind.items():
        items = [size + (f" ({', '.join(w for w in where if w)})" if any(where) else "") for size, where in sizes.items()]
        parts.append(f"{SHORT.get(kind, kind)} of {', '.join(items)}")
    for g, members in groups.items():
        rel = []
        for m in members:
            null = m.hypothesis.parameters[0].initial
            v = next(iter(m.detectable.values()))
            if null and np.isfinite(v) and v / abs(null) < ABSURD:
                rel.append((next(iter(m.hypothesis.extra_values.values()), float("nan")), v / abs(null)))
        if not rel:
            continue
        layer = g.split("[", 1)[1].rstrip("]")
        lo, hi = min(rel, key=lambda r: r[1]), max(rel, key=lambda r: r[1])
        span = f"±{100 * lo[1]:.2g} % (below {lo[0]:.3g} m)"
        if hi[0] != lo[0]:
            span += f" to ±{100 * hi[1]:.2g} % (below {hi[0]:.3g} m)"
        parts.append(f"{SHORT['layer-boundary']} in '{layer}' of {span}")
    return "; ".join(parts)


def _size(name: str, v: float, s) -> str:
    """The detectable change of parameter `name` in words ('' when beyond anything plausible)."""
    from geoback.case.limits import BIAS_SHIFT, CONSTANT_ANGLE, CONSTANT_LENGTH, DEPTH_OFFSET

    stem = name.split("[")[0]
    p = next(q for q in s.hypothesis.parameters if q.name == name)
    if not np.isfinite(v):
        return ""
    usual = {"bias": BIAS_SHIFT, "zoff": DEPTH_OFFSET, "A": CONSTANT_LENGTH, "B": CONSTANT_LENGTH,
             "D": CONSTANT_LENGTH, "C": CONSTANT_ANGLE}.get(stem)
    if usual is not None and v > ABSURD * (usual.plausible[1] - usual.plausible[0]):
        return ""
    if stem in ("n", "m", "beta"):
        return f"{stem} = {p.initial:g} ± {v:.2g}" if v < ABSURD * max(abs(p.initial), 1.0) else ""
    if usual is None and p.bounds and v > ABSURD * (p.bounds[1] - p.bounds[0]):
        return ""
    return size_text(name, unit_of(s, name), v)


def unit_of(s, name: str) -> str:
    """The SI unit of a hypothesis' parameter (its extended misfit's, else by the name's stem)."""
    params = getattr(s.misfit, "parameters", None)
    if params is not None and name in params.names:
        return params.units[params.index(name)]
    from geoback.inference.parameters import UNITS

    stem = name.split("[")[0]
    return UNITS.get(stem, {"E": "kPa", "Esplit": "kPa", "Egrad": "kPa/m", "K0grad": "1/m", "c": "kPa",
                            "phi": "deg"}.get(stem, "-"))
