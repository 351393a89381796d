"""Props and anchors on the finite elements: each connector's operator c (e = c^t u, its shortening or
elongation, ``case/supports.py``), its stiffness k c c^t, the load of its preload -P c, and the wall's
section forces integrated from the wall's stresses.

An end of a connector is the mean displacement along a segment (across the wall at the support's
depth, or along an anchor's fixed length), by Gauss-Legendre points read with the elements' shape
functions: the connector acts on the wall's whole section (no point load at one node) and passes an
anchor's force evenly into the ground along its fixed length.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

GAUSS = 8  # points along a segment


def segment_mean(fe, segment) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """Rows (1 x nfree) giving the mean u_x and u_y along a segment."""
    (x0, y0), (x1, y1) = segment
    t, w = np.polynomial.legendre.leggauss(GAUSS)
    s = (t + 1) / 2
    pts = np.column_stack([x0 + s * (x1 - x0), y0 + s * (y1 - y0)])
    Ix, Iy = fe.interpolation(pts)
    w = sp.csr_matrix(w[None, :] / w.sum())
    return (w @ Ix).tocsr(), (w @ Iy).tocsr()


def operators(fe, connectors: dict) -> sp.csr_matrix:
    """C (nconnectors x nfree): row i is c_i, connector i's shortening (prop) or elongation (anchor) per
    unit displacement, in the order of `connectors`."""
    rows = []
    for cn in connectors.values():
        dx, dy = cn.direction
        row = sp.csr_matrix((1, fe.nfree))
        for segment, sign in cn.ends:
            mx, my = segment_mean(fe, segment)
            row = row + sign * (dx * mx + dy * my)
        rows.append(row)
    return sp.vstack(rows).tocsr() if rows else sp.csr_matrix((0, fe.nfree))


def spring_matrix(C: sp.csr_matrix, k: np.ndarray, act: np.ndarray) -> sp.csr_matrix:
    """The upper triangle of sum_i k_i c_i c_i^t on the active dofs `act`."""
    Ca = C[:, act]
    return sp.triu(Ca.T @ sp.diags(np.asarray(k, float)) @ Ca).tocsr()


# ---------------------------------------------------------------------------- the wall's section forces
@dataclass(frozen=True)
class WallForces:
    """A wall after every stage: its centreline's horizontal displacement ux [m], shear V [kN/m] and
    bending moment M [kNm/m] at `depths` (stages x depths; NaN before the wall is installed). M is
    positive when the wall's face at larger x is in tension; V is the section's sxy integrated."""

    wall: str
    depths: np.ndarray
    stages: tuple
    ux: np.ndarray
    V: np.ndarray
    M: np.ndarray


def section_points(band, depths: np.ndarray) -> np.ndarray:
    """Gauss-Legendre points across the wall at each depth (depth-major)."""
    x0, x1 = band.faces
    t, _ = np.polynomial.legendre.leggauss(GAUSS)
    xi = (x0 + x1) / 2 + (x1 - x0) / 2 * t
    return np.column_stack([np.tile(xi, len(depths)), np.repeat(-np.asarray(depths, float), len(xi))])


def section_forces(band, depths: np.ndarray, stress_at) -> np.ndarray:
    """(len(depths), 3): axial force N [kN/m, compression positive], shear V [kN/m] and bending moment M
    [kNm/m] of the wall at each depth, integrated across its thickness from the stresses
    `stress_at(section_points(band, depths))` -> (n, 3) (sxx, syy, sxy)."""
    x0, x1 = band.faces
    t, w = np.polynomial.legendre.leggauss(GAUSS)
    xi = (x0 + x1) / 2 + (x1 - x0) / 2 * t
    wx = w * (x1 - x0) / 2
    s = np.asarray(stress_at(section_points(band, depths))).reshape(len(depths), len(xi), 3)
    arm = xi - band.x
    N = -(s[..., 1] * wx).sum(axis=1)
    V = (s[..., 2] * wx).sum(axis=1)
    M = (s[..., 1] * arm * wx).sum(axis=1)
    return np.column_stack([N, V, M])
