"""Closed-form convergence-confinement of a deep circular tunnel with an elastic lining.

Plane strain, infinite elastic ground (E, nu) under the in-situ stress sigma_xx = K0 sigma_v,
sigma_yy = sigma_v (compression negative). The wall is released to the fraction beta of the
in-situ stress while unsupported; a thick elastic ring (inner radius a = R - t, outer R; E_l, nu_l)
is then bonded to the wall stress-free (no slip) and the remaining (1 - beta) is released on the
ground-lining system. In polar coordinates (phi from the x axis) the released traction is the sum
of a mean mode P and a deviatoric mode Q cos 2 phi, P = (sxx + syy)/2, Q = (sxx - syy)/2.

Mean mode: Lame (u = A r + B / r in the ring, C / r in the ground); this is the ground reaction
line u_R = beta p0 R / k_g + p_l R / k_g meeting the support line p_l = k_s u / R, k_g = 2 G,
k_s = E_l (R^2 - a^2) / ((1 + nu_l)((1 - 2 nu_l) R^2 + a^2)) (thick ring). Deviatoric mode: Airy
stress function f(r) cos 2 phi with f = A r^2 + B r^4 + C r^-2 + D (Michell), four constants in the
ring and two in the ground (bounded at infinity), found from the six interface and intrados
conditions. Displacements from Barber, Elasticity, Table 8.1 (kappa = 3 - 4 nu), checked by
`check_michell` below.

Thrust N = -int sigma_tt dr (compression +), moment M = int sigma_tt (r_c - r) dr about the
centreline r_c = (a + R)/2 (intrados in tension +), as in geoback.physics.lining.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _lame(E, nu):
    mu = E / (2 * (1 + nu))
    return E * nu / ((1 + nu) * (1 - 2 * nu)), mu, 3 - 4 * nu


def _airy_rows(r, mu, kap):
    """Coefficient rows (of A, B, C, D) of sigma_rr, sigma_tt, tau (per cos/sin 2phi) and u_r, u_t."""
    srr = [-2, 0, -6 / r ** 4, -4 / r ** 2]
    stt = [2, 12 * r ** 2, 6 / r ** 4, 0]
    srt = [2, 6 * r ** 2, -6 / r ** 4, -2 / r ** 2]
    ur = [-2 * r / (2 * mu), (kap - 3) * r ** 3 / (2 * mu), 2 / r ** 3 / (2 * mu), (kap + 1) / r / (2 * mu)]
    ut = [2 * r / (2 * mu), (kap + 3) * r ** 3 / (2 * mu), 2 / r ** 3 / (2 * mu), -(kap - 1) / r / (2 * mu)]
    return np.array([srr, stt, srt, ur, ut])


@dataclass
class LinedTunnel:
    R: float
    t: float
    E: float
    nu: float
    El: float
    nul: float
    sv: float  # in-situ vertical stress (negative)
    K0: float
    beta: float

    def __post_init__(self):
        self.a = self.R - self.t
        self.P = 0.5 * (self.K0 * self.sv + self.sv)
        self.Q = 0.5 * (self.K0 * self.sv - self.sv)
        lg, mg, kg = _lame(self.E, self.nu)
        ll, ml, kl = _lame(self.El, self.nul)
        R, a, beta = self.R, self.a, self.beta
        # mean mode, stage 2: unknowns ring A1, B1 (u = A1 r + B1/r), ground C1 (u = C1/r)
        M = np.array([[2 * (ll + ml), -2 * ml / a ** 2, 0.0],
                      [R, 1 / R, -1 / R],
                      [-2 * (ll + ml), 2 * ml / R ** 2, -2 * mg / R ** 2]])
        self.mean = np.linalg.solve(M, [0.0, 0.0, -(1 - beta) * self.P])
        self._ml, self._ll = ml, ll
        # deviatoric mode, stage 2: ring A, B, C, D; ground C, D (no A, B: stresses vanish far away)
        ring_a, ring_R = _airy_rows(a, ml, kl), _airy_rows(R, ml, kl)
        grd_R = _airy_rows(R, mg, kg)[:, 2:]
        Z = np.zeros(2)
        rows = [np.concatenate([ring_a[0], Z]), np.concatenate([ring_a[2], Z]),  # free intrados
                np.concatenate([-ring_R[3], grd_R[3]]), np.concatenate([-ring_R[4], grd_R[4]]),  # bonded
                np.concatenate([-ring_R[0], grd_R[0]]), np.concatenate([-ring_R[2], grd_R[2]])]  # released
        rhs = [0, 0, 0, 0, -(1 - beta) * self.Q, (1 - beta) * self.Q]
        self.dev = np.linalg.solve(np.array(rows), rhs)
        # stage 1 (unlined, beta released): ground C, D of the deviatoric mode, C of the mean mode
        g = np.array([grd_R[0], grd_R[2]])
        self.dev1 = np.linalg.solve(g, [-beta * self.Q, beta * self.Q])
        self.mean1 = beta * self.P * R ** 2 / (2 * mg)

    # ------------------------------------------------------------------ the wall
    def wall_displacement(self, phi):
        """Radial and tangential displacement of the wall (end of stage 2), phi from the x axis."""
        R = self.R
        mg = self.E / (2 * (1 + self.nu))
        kg = 3 - 4 * self.nu
        rows = _airy_rows(R, mg, kg)[:, 2:]
        ur_mean = self.mean1 / R + self.mean[2] / R
        dev = self.dev1 + self.dev[4:]
        return ur_mean + rows[3] @ dev * np.cos(2 * phi), rows[4] @ dev * np.sin(2 * phi)

    def lining_pressure(self) -> float:
        """Mean radial pressure on the lining (compression +)."""
        ll, ml = self._ll, self._ml
        A1, B1, _ = self.mean
        return -(2 * (ll + ml) * A1 - 2 * ml * B1 / self.R ** 2)

    # ------------------------------------------------------------------ the lining
    def hoop_stress(self, r, phi):
        ll, ml = self._ll, self._ml
        A1, B1, _ = self.mean
        mean = 2 * (ll + ml) * A1 + 2 * ml * B1 / r ** 2
        kl = 3 - 4 * self.nul
        return mean + _airy_rows(r, ml, kl)[1] @ self.dev[:4] * np.cos(2 * phi)

    def forces(self, angle_from_crown_deg):
        """N (compression +) and M (intrados in tension +) at angles from the crown."""
        phi = np.pi / 2 - np.radians(np.asarray(angle_from_crown_deg, float))
        x, w = np.polynomial.legendre.leggauss(40)
        r = 0.5 * (self.a + self.R) + 0.5 * (self.R - self.a) * x
        w = 0.5 * (self.R - self.a) * w
        rc = 0.5 * (self.a + self.R)
        s = np.array([[self.hoop_stress(ri, p) for ri in r] for p in np.atleast_1d(phi)])
        return -(s @ w), s @ (w * (rc - r))


def support_stiffness(R, t, El, nul) -> float:
    """k_s of the thick ring: external pressure per unit radial strain u/R at its outer face."""
    a = R - t
    return El * (R ** 2 - a ** 2) / ((1 + nul) * ((1 - 2 * nul) * R ** 2 + a ** 2))


def ccm(R, t, E, nu, El, nul, p0, beta):
    """Convergence-confinement with K0 = 1: (wall displacement inward [m], lining pressure, thrust).
    Ground reaction line: u = (p0 - p) R / (2 G); support line from u at installation: p = k_s du / R."""
    kg = E / (1 + nu)  # 2 G
    ks = support_stiffness(R, t, El, nul)
    pl = (1 - beta) * p0 * ks / (ks + kg)
    return (p0 - pl) * R / kg, pl, pl * R


def check_michell(mu=3.0, nu=0.3, r=1.3, phi=0.37, h=1e-6) -> float:
    """Largest relative difference between the Airy stresses and Hooke's law applied to the table's
    displacements (finite differences): the displacement table is right if this is ~1e-9."""
    lam = 2 * mu * nu / (1 - 2 * nu)
    kap = 3 - 4 * nu
    coef = np.array([0.7, -0.3, 1.1, 0.4])

    def u(r, p):
        rows = _airy_rows(r, mu, kap)
        return rows[3] @ coef * np.cos(2 * p), rows[4] @ coef * np.sin(2 * p)

    ur, ut = u(r, phi)
    durdr = (u(r + h, phi)[0] - u(r - h, phi)[0]) / (2 * h)
    dutdr = (u(r + h, phi)[1] - u(r - h, phi)[1]) / (2 * h)
    durdp = (u(r, phi + h)[0] - u(r, phi - h)[0]) / (2 * h)
    dutdp = (u(r, phi + h)[1] - u(r, phi - h)[1]) / (2 * h)
    err, ett, g = durdr, (ur + dutdp) / r, dutdr - ut / r + durdp / r
    hooke = np.array([lam * (err + ett) + 2 * mu * err, lam * (err + ett) + 2 * mu * ett, mu * g])
    rows = _airy_rows(r, mu, kap)
    airy = np.array([rows[0] @ coef * np.cos(2 * phi), rows[1] @ coef * np.cos(2 * phi), rows[2] @ coef * np.sin(2 * phi)])
    return float(np.max(np.abs(hooke - airy)) / np.max(np.abs(airy)))
