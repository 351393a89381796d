"""Shape functions and quadrature rules of the reference triangle and line (P1 and P2).

Reference triangle (0,0), (1,0), (0,1) with the P2 nodes in gmsh's order: vertices, then the
mid-sides of edges 01, 12, 20; reference line [0, 1] with its vertices, then its mid-point.
Quadrature: the 3-point (degree 2) and 6-point (degree 4, Strang & Fix / Dunavant) triangle rules
and Gauss-Legendre on the line. Plain numpy, vectorised over evaluation points.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_A4, _B4 = 0.44594849091596488632, 0.09157621350977074346  # degree-4 rule: two orbits of three points
_W4A, _W4B = 0.22338158967801146570 / 2, 0.10995174365532186764 / 2


def triangle_rule(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Points (2, nq) and weights (nq,) integrating polynomials of `degree` exactly on the reference triangle."""
    if degree <= 1:
        return np.array([[1 / 3], [1 / 3]]), np.array([0.5])
    if degree == 2:
        pts = np.array([[1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])
        return pts, np.full(3, 1 / 6)
    if degree <= 4:
        a, b = _A4, _B4
        x = [a, 1 - 2 * a, a, b, 1 - 2 * b, b]
        y = [a, a, 1 - 2 * a, b, b, 1 - 2 * b]
        return np.array([x, y]), np.array([_W4A] * 3 + [_W4B] * 3)
    raise ValueError(f"no triangle rule of degree {degree} here")


def line_rule(degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Legendre points (1, nq) and weights on [0, 1], exact for polynomials of `degree`."""
    n = degree // 2 + 1
    t, w = np.polynomial.legendre.leggauss(n)
    return ((t + 1) / 2)[None, :], w / 2


@dataclass(frozen=True)
class Element:
    """Lagrange element on a reference cell: `basis(X)` -> values (nb, n), gradients (nb, dim, n)."""

    cell: str  # "triangle" or "line"
    order: int

    @property
    def nodes(self) -> int:
        return {("triangle", 1): 3, ("triangle", 2): 6, ("line", 1): 2, ("line", 2): 3}[(self.cell, self.order)]

    def basis(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        X = np.atleast_2d(np.asarray(X, dtype=float))
        if self.cell == "line":
            t = X[0]
            one, zero = np.ones_like(t), np.zeros_like(t)
            if self.order == 1:
                return np.array([1 - t, t]), np.array([[-one], [one]])
            return (np.array([(1 - t) * (1 - 2 * t), t * (2 * t - 1), 4 * t * (1 - t)]),
                    np.array([[4 * t - 3], [4 * t - 1], [4 - 8 * t]]))
        x, y = X[0], X[1]
        l0, l1, l2 = 1 - x - y, x, y
        one, zero = np.ones_like(x), np.zeros_like(x)
        if self.order == 1:
            return np.array([l0, l1, l2]), np.array([[-one, -one], [one, zero], [zero, one]])
        N = np.array([l0 * (2 * l0 - 1), l1 * (2 * l1 - 1), l2 * (2 * l2 - 1), 4 * l0 * l1, 4 * l1 * l2, 4 * l2 * l0])
        d0 = 4 * l0 - 1  # d(l0 (2 l0 - 1))/dl0; dl0/dx = dl0/dy = -1
        dN = np.array([[-d0, -d0], [4 * l1 - 1, zero], [zero, 4 * l2 - 1],
                       [4 * (l0 - l1), -4 * l1], [4 * l2, 4 * l1], [-4 * l2, 4 * (l0 - l2)]])
        return N, dN
