"""The depth of an unmodelled layer boundary by profile likelihood over a continuous depth.

The depth z of a boundary is not a parameter the FE model can differentiate (the mesh conforms
to it), so it is profiled: at each depth tried, the model is re-meshed with the boundary there
and every other parameter refitted, giving the profile J(z) = min J over the others. The depths
tried are a few seeds over the layer, then a parabolic (or golden-section) search for the
minimum in each basin of the seeds' profile not far above the lowest (J(z) can have several: a
boundary through the tunnel and one below it), then a secant search on sqrt(J(z) - J_min) for each end of the 95 % interval
(J(z) - J_min = 3.84, chi^2_1): sqrt(Delta J) is about linear in z near a smooth minimum, so the
ends take two or three refits each (only for a boundary that is accepted: `interval()`). An end that reaches the layer's top or bottom (or a depth
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
MAX_BASINS = 2  # local minima of the profile refined (the lowest and one not far above it)
BASIN_MARGIN = 25.0  # J units: a basin this close to the lowest seed is refined too
DENSIFY = 2  # passes looking between seeds where the profile is low on both sides
MIN_GAP = 0.75  # m: gaps narrower than this are left to the refinement
MAX_GAPS = 4  # gaps looked into per pass (the lowest)


@dataclass
class DepthProfile:
    """J(z) refitted at the depths in `points` (sorted): the ML depth and (``interval()``) its 95 %
    interval. Built by ``profile_depth``; keeps what it needs to refit more depths."""

    layer: str
    lo_limit: float  # the depths the boundary may take (the layer's top, or the depth the strata are logged to,
    hi_limit: float  # and the layer's bottom)
    tol: float = 0.02
    points: list = field(default_factory=list)  # (z, J, Scored) sorted by z
    failed: list = field(default_factory=list)  # depths that could not be meshed or fitted
    z_hat: float = float("nan")
    J_min: float = float("nan")
    low: float = float("nan")
    high: float = float("nan")
    low_open: bool = False
    high_open: bool = False
    seconds: float = 0.0
    refit_at: Callable | None = field(default=None, repr=False)
    say: Callable = field(default=lambda msg: None, repr=False)
    lo_words: str = "the layer's top"  # what lo_limit is, in words

    # ------------------------------------------------------------------ results
    @property
    def refits(self) -> int:
        return len(self.points) + len(self.failed)

    @property
    def best(self):
        """The Scored of the ML depth."""
        return min(self.points, key=lambda t: t[1])[2]

    @property
    def has_interval(self) -> bool:
        return bool(np.isfinite(self.low) and np.isfinite(self.high))

    def interval_text(self) -> str:
        if not self.has_interval:
            return "not computed"
        lo = f"{self.low:.3g} m" if not self.low_open else f"{self.lo_words} ({self.low:.3g} m)"
        hi = f"{self.high:.3g} m" if not self.high_open else f"the layer's bottom ({self.high:.3g} m)"
        return f"{lo} to {hi}"

    def text(self) -> str:
        interval = (f"95 % interval {self.interval_text()}, ΔJ = 3.84" if self.has_interval
                    else "its interval computed only if accepted")
        return (f"depth {self.z_hat:.3g} m by profile likelihood ({interval}; {len(self.points)} conforming refits"
                + (f", {len(self.failed)} depth(s) not meshable" if self.failed else "")
                + f", {self.seconds:.1f} s)")

    def as_dict(self) -> dict:
        return {"layer": self.layer, "estimate": self.z_hat,
                "ci95": [self.low, self.high] if self.has_interval else None,
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

    # ------------------------------------------------------------------ the search
    @property
    def _margin(self) -> float:
        return max(self.tol, 1e-3 * (self.hi_limit - self.lo_limit))

    def _done(self) -> dict:
        return {p[0]: p for p in self.points}

    def attempt(self, z: float):
        """Refit at depth z (clipped into the layer, rounded to mm); the (z, J, Scored) or None."""
        lo, hi, margin = self.lo_limit, self.hi_limit, self._margin
        z = float(np.clip(round(float(z), 3), lo + margin, hi - margin))
        done = self._done()
        if z in done or z in self.failed:
            return done.get(z)
        near = min(self.points, key=lambda t: abs(t[0] - z))[2] if self.points else None
        self.say(f"refitting with a layer boundary at {z:g} m in '{self.layer}'")
        t0 = time.perf_counter()
        try:
            s = self.refit_at(z, near)
        except Exception as exc:  # noqa: BLE001 - a depth gmsh cannot mesh (through the tunnel's edge)
            self.say(f"  skipped depth {z:g} m: {exc}")
            s = None
        self.seconds += time.perf_counter() - t0
        if s is None or s.refit is None or not np.isfinite(s.refit.J):
            self.failed.append(z)
            return None
        self.points = sorted(self.points + [(z, float(s.refit.J), s)], key=lambda p: p[0])
        if not self.J_min <= s.refit.J:
            self.z_hat, self.J_min = z, float(s.refit.J)
        return self.points[[p[0] for p in self.points].index(z)]

    def _refine(self, a: float, b: float) -> None:
        """The minimum of J inside [a, b] (a basin): parabola through the best point and its
        neighbours, golden section where that fails; a best point at the layer's edge is pushed there."""
        tol, margin = self.tol, self._margin
        for _ in range(MAX_REFINE):
            pts = [p for p in self.points if a <= p[0] <= b]
            if not pts:
                return
            zs = np.array([p[0] for p in pts])
            Js = np.array([p[1] for p in pts])
            k = int(np.argmin(Js))
            if k == 0 or k == len(pts) - 1:  # best at the bracket's end: only the layer's edge lies beyond
                if (k == 0 and zs[k] > a + tol) or (k == len(pts) - 1 and zs[k] < b - tol):
                    return  # the bracket's end is a worse point not yet refitted: nothing to refine
                edge = self.lo_limit + margin if k == 0 else self.hi_limit - margin
                if abs(edge - zs[k]) <= tol:
                    return
                other = zs[1] if (k == 0 and len(zs) > 1) else (zs[-2] if len(zs) > 1 else zs[k])
                target = edge if abs(edge - zs[k]) <= 0.5 * abs(other - zs[k]) + tol else zs[k] + 0.5 * (edge - zs[k])
                if self.attempt(target) is None and abs(target - edge) > tol:
                    if self.attempt(0.5 * (zs[k] + target)) is None:
                        return
                continue
            z0, z1, z2 = zs[k - 1:k + 2]
            J0, J1, J2 = Js[k - 1:k + 2]
            if max(z1 - z0, z2 - z1) <= 2 * tol:
                return
            num = (z1 - z0) ** 2 * (J1 - J2) - (z1 - z2) ** 2 * (J1 - J0)
            den = (z1 - z0) * (J1 - J2) - (z1 - z2) * (J1 - J0)
            z_new = z1 - 0.5 * num / den if den != 0 else np.nan
            if not (np.isfinite(z_new) and z0 < z_new < z2) or min(abs(z_new - z1), abs(z_new - z0),
                                                                     abs(z_new - z2)) < 0.5 * tol:
                z_new = z1 + GOLDEN * ((z2 - z1) if z2 - z1 > z1 - z0 else (z0 - z1))  # into the wider side
            if self.attempt(z_new) is None:
                return

    def search(self, seeds, stop_above: float | None = None) -> None:
        """Refit the seeds, look between them where the profile is low, refine its basins; only the
        seeds when the best of them is above `stop_above`."""
        for z in seeds:
            self.attempt(z)
        if not self.points or (stop_above is not None and self.J_min > stop_above):
            return
        # where the profile is low on both sides of a gap, look between them (a narrow basin hides
        # between two seeds: a boundary through the tunnel and one below it give two)
        for _ in range(DENSIFY):
            Js = [p[1] for p in self.points]
            low = min(Js) + max(BASIN_MARGIN, 0.1 * (max(Js) - min(Js)))
            gaps = sorted((max(a[1], b[1]), a[0], b[0]) for a, b in zip(self.points, self.points[1:])
                          if max(a[1], b[1]) <= low and b[0] - a[0] > MIN_GAP)
            if not gaps:
                break
            for _, a, b in gaps[:MAX_GAPS]:
                self.attempt(0.5 * (a + b))
        # the basins: local minima of the profile not far above the lowest, refined, lowest first
        pts, Js = self.points, [p[1] for p in self.points]
        low = min(Js) + max(BASIN_MARGIN, 0.1 * (max(Js) - min(Js)))
        basins = []
        for k, (z, J, _) in enumerate(pts):
            left = Js[k - 1] if k > 0 else np.inf
            right = Js[k + 1] if k + 1 < len(pts) else np.inf
            if J <= left and J <= right and J <= low:
                basins.append((J, pts[k - 1][0] if k > 0 else self.lo_limit,
                               pts[k + 1][0] if k + 1 < len(pts) else self.hi_limit))
        for _, a, b in sorted(basins)[:MAX_BASINS]:
            self._refine(a, b)

    def _end(self, sign: int) -> tuple[float, bool]:
        """One end of the 95 % interval: secant on sqrt(J - J_min), which is ~linear in z."""
        tol, limit = self.tol, (self.hi_limit - self._margin if sign > 0 else self.lo_limit + self._margin)
        for step in range(MAX_END_STEPS + 1):
            side = sorted((p for p in self.points if sign * (p[0] - self.z_hat) > 0),
                          key=lambda p: abs(p[0] - self.z_hat))
            inside = [(self.z_hat, 0.0)] + [(p[0], p[1] - self.J_min) for p in side if p[1] - self.J_min < CHI2_1_95]
            outside = [(p[0], p[1] - self.J_min) for p in side if p[1] - self.J_min >= CHI2_1_95]
            a = max(inside, key=lambda q: abs(q[0] - self.z_hat))  # the farthest depth still inside
            b = min(outside, key=lambda q: abs(q[0] - self.z_hat)) if outside else None
            if step == MAX_END_STEPS:
                return (a[0], True) if b is None else (_cross(a, b), False)
            if b is not None and abs(b[0] - a[0]) <= tol:
                return _cross(a, b), False
            if b is None:  # nothing outside yet: extrapolate sqrt(dJ) from the inside, or go to the limit
                if abs(limit - a[0]) <= tol:
                    return limit, True
                slope = np.sqrt(max(a[1], 0.0)) / abs(a[0] - self.z_hat) if a[0] != self.z_hat else 0.0
                reach = (np.sqrt(CHI2_1_95) / slope) * 1.2 if slope > 0 else abs(limit - self.z_hat) / 2
                z_try = self.z_hat + sign * min(abs(limit - self.z_hat), max(reach, 2 * tol))
                if abs(z_try - a[0]) <= tol:
                    z_try = a[0] + sign * 2 * tol
                if self.attempt(z_try) is None:
                    return a[0], True
                continue
            z_try = _cross(a, b)
            if min(abs(z_try - a[0]), abs(z_try - b[0])) < 0.25 * tol or self.attempt(z_try) is None:
                return z_try, False
        raise AssertionError("unreachable")

    def interval(self) -> "DepthProfile":
        """Compute the 95 % profile-likelihood interval of the depth (a few more refits; idempotent)."""
        if self.has_interval or not self.points:
            return self
        for _ in range(2):  # a lower J found while looking for an end moves the minimum: once more from it
            J_before = self.J_min
            self.low, self.low_open = self._end(-1)
            self.high, self.high_open = self._end(+1)
            if self.J_min >= J_before:
                break
        if self.low_open:
            self.low = self.lo_limit
        if self.high_open:
            self.high = self.hi_limit
        return self


def profile_depth(layer: str, refit_at: Callable, lo: float, hi: float, seeds, tol: float,
                  say=lambda msg: None, interval: bool = True, stop_above: float | None = None,
                  lo_words: str = "the layer's top") -> DepthProfile:
    """Profile J over the boundary depth in (lo, hi). refit_at(z, start) returns a refitted Scored
    (its ``refit.J`` the profile value) or raises where the depth cannot be meshed; `start` is the
    Scored of the nearest depth already refitted (for a warm start) or None. interval: also find the
    95 % interval (else later, ``prof.interval()``); stop_above: only the seeds if none is below it;
    lo_words: what lo is, in words (the interval's words when it reaches it)."""
    prof = DepthProfile(layer, float(lo), float(hi), float(tol), refit_at=refit_at, say=say, lo_words=lo_words)
    prof.search(seeds, stop_above)
    if interval:
        prof.interval()
    return prof


def _cross(a: tuple[float, float], b: tuple[float, float]) -> float:
    """Depth between a (inside) and b (outside) where sqrt(Delta J) reaches sqrt(3.84), linearly."""
    ra, rb = np.sqrt(max(a[1], 0.0)), np.sqrt(max(b[1], 0.0))
    t = (np.sqrt(CHI2_1_95) - ra) / (rb - ra) if rb > ra else 0.5
    return float(a[0] + np.clip(t, 0.0, 1.0) * (b[0] - a[0]))
