"""The depth of an unmodelled layer boundary by profile likelihood over a continuous depth.

The depth z of a boundary is not a parameter the FE model can differentiate (the mesh conforms
to it), so it is profiled: at each depth tried, the model is re-meshed with the boundary there
and every other parameter refitted, giving the profile J(z) = min J over the others. The depths
tried are a few seeds over the layer, then a parabolic (or golden-section) search for the
minimum, then a secant search on sqrt(J(z) - J_min) for each end of the 95 % interval
(J(z) - J_min = 3.84, chi^2_1): sqrt(Delta J) is about linear in z near a smooth minimum, so the
ends take two or three refits each. An end that reaches the layer's top or bottom (or a depth
that cannot be meshed) without J rising enough is open. Each depth costs a mesh, a factorisation
and a fit (about 0.3-1 s on the shipped cases); the number of refits and the seconds are kept.

Re-meshing makes J(z) a slightly rough function (the discretisation error changes with the
mesh); the boundary crossing the tunnel makes it kinked. The search tolerates both: it works on
the depths actually refitted, and the minimum is the best of them after refinement to `tol`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

CHI2_1_95 = 3.841458820694124
GOLDEN = 0.3819660112501051
MAX_REFINE = 8
MAX_END_STEPS = 4


@dataclass
class DepthProfile:
    """J(z) refitted at the depths in `points` (sorted): the ML depth and its 95 % interval."""

    layer: str
    lo_limit: float  # the depths the boundary may take (the layer's top and bottom)
    hi_limit: float
    points: list = field(default_factory=list)  # (z, J, Scored) sorted by z
    failed: list = field(default_factory=list)  # depths that could not be meshed or fitted
    z_hat: float = float("nan")
    J_min: float = float("nan")
    low: float = float("nan")
    high: float = float("nan")
    low_open: bool = False
    high_open: bool = False
    seconds: float = 0.0

    @property
    def refits(self) -> int:
        return len(self.points) + len(self.failed)

    @property
    def best(self):
        """The Scored of the ML depth."""
        return min(self.points, key=lambda t: t[1])[2]

    def interval_text(self) -> str:
        lo = f"{self.low:.3g} m" if not self.low_open else f"the layer's top ({self.low:.3g} m)"
        hi = f"{self.high:.3g} m" if not self.high_open else f"the layer's bottom ({self.high:.3g} m)"
        return f"{lo} to {hi}"

    def text(self) -> str:
        return (f"depth {self.z_hat:.3g} m by profile likelihood (95 % interval {self.interval_text()}, "
                f"ΔJ = 3.84; {len(self.points)} conforming refits"
                + (f", {len(self.failed)} depth(s) not meshable" if self.failed else "")
                + f", {self.seconds:.1f} s)")

    def as_dict(self) -> dict:
        return {"layer": self.layer, "estimate": self.z_hat, "ci95": [self.low, self.high],
                "ci95_open": [self.low_open, self.high_open], "J_min": self.J_min,
                "profile": [[z, J] for z, J, _ in self.points], "failed": list(self.failed),
                "refits": self.refits, "seconds": self.seconds, "limits": [self.lo_limit, self.hi_limit]}

    def modulus_interval(self, name: str, at_best: tuple[float, float] | None = None) -> tuple[float, float]:
        """95 % interval of a parameter (the lower stratum's modulus) with the depth profiled out:
        the union over the depths refitted of {v: (v - v(z))^2 / sd(z)^2 <= 3.84 - (J(z) - J_min)},
        i.e. J minimised over z and the others, quadratic in v at each depth (and `at_best`, the
        interval at the ML depth, e.g. by profile likelihood, taken in as it is)."""
        lo, hi = (np.inf, -np.inf) if at_best is None else at_best
        for z, J, t in self.points:
            room = CHI2_1_95 - (J - self.J_min)
            if room <= 0 or t.reliability is None or name not in t.reliability.names:
                continue
            i = t.reliability.names.index(name)
            v, sd = float(t.refit.p[i]), float(t.reliability.std[i])
            if not (np.isfinite(sd) and sd < 0.3 * abs(v)):  # not quadratic in v there: the interval at
                continue  # the ML depth (a profile-likelihood one) stands for it
            half = np.sqrt(room) * sd
            if t.reliability.log is not None and t.reliability.log[i] and v > 0:
                f = np.exp(half / v)
                lo, hi = min(lo, v / f), max(hi, v * f)
            else:
                lo, hi = min(lo, v - half), max(hi, v + half)
        return float(lo), float(hi)


def profile_depth(layer: str, refit_at: Callable, lo: float, hi: float, seeds, tol: float,
                  say=lambda msg: None) -> DepthProfile:
    """Profile J over the boundary depth in (lo, hi). refit_at(z, start) returns a refitted Scored
    (its ``refit.J`` the profile value) or raises where the depth cannot be meshed; `start` is the
    Scored of the nearest depth already refitted (for a warm start) or None."""
    t0 = time.perf_counter()
    prof = DepthProfile(layer, float(lo), float(hi))
    done: dict[float, tuple] = {}
    margin = max(tol, 1e-3 * (hi - lo))

    def attempt(z: float):
        z = float(np.clip(round(float(z), 3), lo + margin, hi - margin))
        if z in done or z in prof.failed:
            return done.get(z)
        near = min(done.values(), key=lambda t: abs(t[0] - z))[2] if done else None
        say(f"refitting with a layer boundary at {z:g} m in '{layer}'")
        try:
            s = refit_at(z, near)
        except Exception as exc:  # noqa: BLE001 - a depth gmsh cannot mesh (through the tunnel's edge)
            say(f"  skipped depth {z:g} m: {exc}")
            prof.failed.append(z)
            return None
        if s.refit is None or not np.isfinite(s.refit.J):
            prof.failed.append(z)
            return None
        done[z] = (z, float(s.refit.J), s)
        return done[z]

    for z in seeds:
        attempt(z)
    if not done:
        prof.seconds = time.perf_counter() - t0
        return prof

    # the minimum: parabola through the best and its neighbours, golden section where that fails
    for _ in range(MAX_REFINE):
        pts = sorted(done.values())
        zs = np.array([p[0] for p in pts])
        Js = np.array([p[1] for p in pts])
        k = int(np.argmin(Js))
        if k == 0 or k == len(pts) - 1:  # best at an end: look between it and the layer's edge
            edge = lo + margin if k == 0 else hi - margin
            if abs(edge - zs[k]) <= tol:
                break
            other = zs[1] if (k == 0 and len(zs) > 1) else (zs[-2] if len(zs) > 1 else zs[k])
            target = edge if abs(edge - zs[k]) <= 0.5 * abs(other - zs[k]) + tol else zs[k] + 0.5 * (edge - zs[k])
            if attempt(target) is None and abs(target - edge) > tol:
                if attempt(0.5 * (zs[k] + target)) is None:
                    break
            continue
        z0, z1, z2 = zs[k - 1:k + 2]
        J0, J1, J2 = Js[k - 1:k + 2]
        if max(z1 - z0, z2 - z1) <= 2 * tol:
            break
        num = (z1 - z0) ** 2 * (J1 - J2) - (z1 - z2) ** 2 * (J1 - J0)
        den = (z1 - z0) * (J1 - J2) - (z1 - z2) * (J1 - J0)
        z_new = z1 - 0.5 * num / den if den != 0 else np.nan
        if not (np.isfinite(z_new) and z0 < z_new < z2) or min(abs(z_new - z1), abs(z_new - z0),
                                                                 abs(z_new - z2)) < 0.5 * tol:
            # golden section into the wider side
            z_new = z1 + GOLDEN * ((z2 - z1) if z2 - z1 > z1 - z0 else (z0 - z1))
        if attempt(z_new) is None:
            break

    best = min(done.values(), key=lambda t: t[1])
    prof.z_hat, prof.J_min = best[0], best[1]

    # each end of the 95 % interval: secant on sqrt(J - J_min), which is ~linear in z
    def end(sign: int) -> tuple[float, bool]:
        limit = hi - margin if sign > 0 else lo + margin
        for _ in range(MAX_END_STEPS + 1):
            pts = sorted(done.values())
            side = [p for p in pts if sign * (p[0] - prof.z_hat) > 0]
            side.sort(key=lambda p: abs(p[0] - prof.z_hat))
            inside = [(prof.z_hat, 0.0)] + [(p[0], p[1] - prof.J_min) for p in side if p[1] - prof.J_min < CHI2_1_95]
            outside = [(p[0], p[1] - prof.J_min) for p in side if p[1] - prof.J_min >= CHI2_1_95]
            a = max(inside, key=lambda q: abs(q[0] - prof.z_hat))  # farthest depth still inside
            b = min(outside, key=lambda q: abs(q[0] - prof.z_hat)) if outside else None
            if b is not None and abs(b[0] - a[0]) <= tol:
                return _cross(a, b), False
            if b is None:  # nothing outside yet: extrapolate sqrt(dJ) from the inside points, or go to the limit
                if abs(limit - a[0]) <= tol:
                    return limit, True
                slope = np.sqrt(max(a[1], 0.0)) / abs(a[0] - prof.z_hat) if a[0] != prof.z_hat else 0.0
                step = (np.sqrt(CHI2_1_95) / slope) * 1.2 if slope > 0 else abs(limit - prof.z_hat) / 2
                z_try = prof.z_hat + sign * min(abs(limit - prof.z_hat), max(step, 2 * tol))
                if abs(z_try - a[0]) <= tol:
                    z_try = a[0] + sign * 2 * tol
                if attempt(z_try) is None:
                    return a[0], True
                continue
            z_try = _cross(a, b)
            if min(abs(z_try - a[0]), abs(z_try - b[0])) < 0.25 * tol:
                return z_try, False
            if attempt(z_try) is None:
                return z_try, False
        pts = sorted(done.values())
        side = [p for p in pts if sign * (p[0] - prof.z_hat) > 0]
        inside = [(prof.z_hat, 0.0)] + [(p[0], p[1] - prof.J_min) for p in side if p[1] - prof.J_min < CHI2_1_95]
        outside = [(p[0], p[1] - prof.J_min) for p in side if p[1] - prof.J_min >= CHI2_1_95]
        a = max(inside, key=lambda q: abs(q[0] - prof.z_hat))
        if not outside:
            return a[0], True
        return _cross(a, min(outside, key=lambda q: abs(q[0] - prof.z_hat))), False

    for _ in range(2):  # a lower J found while looking for an end moves the minimum: once more from it
        prof.low, prof.low_open = end(-1)
        prof.high, prof.high_open = end(+1)
        best = min(done.values(), key=lambda t: t[1])
        if best[1] >= prof.J_min:
            break
        prof.z_hat, prof.J_min = best[0], best[1]
    if prof.low_open:
        prof.low = lo
    if prof.high_open:
        prof.high = hi
    prof.points = sorted(done.values())
    prof.seconds = time.perf_counter() - t0
    return prof


def _cross(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Depth between a (inside) and b (outside) where sqrt(Delta J) reaches sqrt(3.84), linearly."""
    ra, rb = np.sqrt(max(a[1], 0.0)), np.sqrt(max(b[1], 0.0))
    t = (np.sqrt(CHI2_1_95) - ra) / (rb - ra) if rb > ra else 0.5
    return float(a[0] + np.clip(t, 0.0, 1.0) * (b[0] - a[0]))
