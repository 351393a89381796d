"""One factorisation per distinct stiffness (DESIGN.md, eqns 41-42): a stiffness whose coefficients are
a multiple s of the factorised one's reuses its factorisation, u = K_ref^-1 f / s.

``FactorCache`` keeps the last factorisation of one kind of matrix (the ground's, or the ground and
lining assembled together) with the coefficients it was made from; ``counted_solve`` is the
back-substitution every physics counts. Proportionality is tested entry by entry (max-norm), which,
unlike a test on vector norms, does not fail from rounding as the mesh grows.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from geoback.physics.simulation import Counters, Stopwatch
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


def counted_solve(counters: Counters, fact: Factorisation, s: float, rhs, coords: np.ndarray | None = None) -> np.ndarray:
    """K^-1 rhs with K = s K(fact) (``Factorisation.solve``: rhs may be a function of the columns to
    build, answered from the span of earlier loads by `coords`); counts real back-substitutions only."""
    before = fact.backsubstitutions
    with Stopwatch(counters, "seconds_solving"):
        out = fact.solve(rhs, coords) / s
    counters.solves += fact.backsubstitutions - before
    return out


class FactorCache:
    """The last factorisation of a stiffness and the coefficients it was made from: K(coeffs) is
    factorised only when it is no positive multiple of the kept one (the kept one is then released).
    Counts into `counters`; `made` is the number of factorisations this cache has made."""

    def __init__(self, counters: Counters, backend: str | None = None):
        self.counters, self.backend = counters, backend
        self.kept: tuple[np.ndarray, Factorisation] | None = None  # (coefficients, factorisation)
        self.made = 0

    @property
    def current(self) -> Factorisation | None:
        return self.kept[1] if self.kept is not None else None

    @property
    def reference(self) -> np.ndarray | None:
        """The coefficients the kept factorisation was made from."""
        return self.kept[0] if self.kept is not None else None

    def factorised(self, coeffs: np.ndarray, assemble: Callable[[], object]) -> tuple[Factorisation, float]:
        """The factorisation of K(coeffs) and s with K(coeffs) = s K(factorised); `assemble()` gives
        K(coeffs) as an upper CSR matrix, called only when a new factorisation is needed."""
        if self.kept is not None:
            ref, fact = self.kept
            s = proportion(coeffs, ref)
            if s is not None and s > 0:
                return fact, s
            fact.release()
        with Stopwatch(self.counters, "seconds_assembling"):
            K = assemble()
        with Stopwatch(self.counters, "seconds_factorising"):
            fact = Factorisation(K, self.backend)
        self.counters.factorisations += 1
        self.made += 1
        self.kept = (np.array(coeffs, float), fact)
        return fact, 1.0

    def solve(self, fact: Factorisation, s: float, rhs, coords: np.ndarray | None = None) -> np.ndarray:
        return counted_solve(self.counters, fact, s, rhs, coords)

    def release(self) -> None:
        """Drop the kept factorisation (what a code without reuse does before every solve)."""
        if self.kept is not None:
            self.kept[1].release()
        self.kept = None
