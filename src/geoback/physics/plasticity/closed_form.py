"""Deep circular tunnel in Mohr-Coulomb ground: closed-form ground reaction (plane strain).

Hydrostatic initial stress p0 (> 0, compression), tunnel radius R, internal (support) pressure
p_i (>= 0): partial release by a fraction lambda of the excavation load is p_i = (1 - lambda) p0.
Linear elasticity (E, nu) up to yield, then perfectly plastic Mohr-Coulomb (c, phi > 0) with
dilation psi (non-associated flow, psi <= phi). Angles in radians.

Formulae (Salencon 1969, Ann. Ponts Chauss. 160; in the form of Carranza-Torres & Fairhurst
2000, Tunn. Undergr. Space Technol. 15(2), eqs. for the Mohr-Coulomb ground reaction curve),
with compression-positive pressures s_r, s_t (radial, hoop):

    K_p = (1 + sin phi) / (1 - sin phi),   K_psi = (1 + sin psi) / (1 - sin psi),
    s_c = 2 c cos phi / (1 - sin phi)                   (unconfined strength),  A = s_c / (K_p - 1)

    yield in the plastic zone:  s_t = K_p s_r + s_c
    critical pressure           p_cr = (2 p0 - s_c) / (1 + K_p)       (no plastic zone if p_i >= p_cr)
    plastic radius              R_p = R [ (p_cr + A) / (p_i + A) ]^(1 / (K_p - 1))
    plastic-zone stresses       s_r = (p_i + A) (r/R)^(K_p - 1) - A,  s_t = K_p s_r + s_c
    elastic zone (r >= R_p)     s_r, s_t = p0 -+ (p0 - p_cr) (R_p / r)^2

Displacements (convergence U = -u_r > 0). Elastic zone: U = (p0 - p_cr) R_p^2 (1 + nu) / (E r).
Plastic zone: elastic strains follow Hooke from the actual stresses with no plastic strain out
of plane (s_z is the intermediate principal stress, s_z = p0 + nu (s_r + s_t - 2 p0)); plastic
strains follow the flow rule eps_r^p + K_psi eps_t^p = 0. Compatibility gives
dU/dr + K_psi U / r = h(r) with h = (1+nu)/E [(1 - nu - nu K_psi) ds_r + (K_psi (1 - nu) - nu) ds_t],
ds = s - p0, integrated from U(R_p):

    U(r) = U(R_p) (R_p/r)^K_psi
           + (1+nu)/E { alpha (p_i + A) R^(1-K_p) [r^K_p - R_p^(K_p+K_psi) r^-K_psi] / (K_p + K_psi)
                        - (1 - 2 nu)(p0 + A) [r - R_p^(K_psi+1) r^-K_psi] },
    alpha = (1 - nu - nu K_psi) + K_p (K_psi (1 - nu) - nu)

(the small-strain solution of Carranza-Torres & Fairhurst 2000 for Mohr-Coulomb; with psi = phi
it is Salencon's associated solution). Functions below return code-convention values: stresses
compression-negative, radial displacement outward-positive (negative = towards the tunnel).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def unconfined_strength(c, phi):
    """s_c = 2 c cos phi / (1 - sin phi): the Mohr-Coulomb unconfined strength (phi in radians)."""
    return 2 * c * np.cos(phi) / (1 - np.sin(phi))


@dataclass(frozen=True)
class DeepTunnelMC:
    p0: float
    R: float
    E: float
    nu: float
    c: float
    phi: float
    psi: float
    p_i: float = 0.0

    def __post_init__(self):
        if not (0 < self.phi < np.pi / 2):
            raise ValueError("closed form needs 0 < phi < 90 degrees (phi = 0, Tresca, is not covered)")
        if not (0 <= self.psi <= self.phi):
            raise ValueError("closed form needs 0 <= psi <= phi")
        if self.p_i < 0 or self.p0 <= 0:
            raise ValueError("p0 > 0 and p_i >= 0 (compression-positive pressures)")

    @classmethod
    def released(cls, p0, R, E, nu, c, phi, psi, lam: float) -> "DeepTunnelMC":
        """The tunnel with a fraction lam of the excavation load released: p_i = (1 - lam) p0."""
        return cls(p0, R, E, nu, c, phi, psi, (1.0 - lam) * p0)

    # ------------------------------------------------------------------ constants
    @property
    def K_p(self):
        return (1 + np.sin(self.phi)) / (1 - np.sin(self.phi))

    @property
    def K_psi(self):
        return (1 + np.sin(self.psi)) / (1 - np.sin(self.psi))

    @property
    def s_c(self):
        return unconfined_strength(self.c, self.phi)

    @property
    def _A(self):
        return self.s_c / (self.K_p - 1)

    @property
    def critical_pressure(self) -> float:
        return (2 * self.p0 - self.s_c) / (1 + self.K_p)

    @property
    def plastic(self) -> bool:
        return self.p_i < self.critical_pressure

    @property
    def plastic_radius(self) -> float:
        """R_p (= R when the ground stays elastic)."""
        if not self.plastic:
            return self.R
        A = self._A
        return self.R * ((self.critical_pressure + A) / (self.p_i + A)) ** (1 / (self.K_p - 1))

    # ------------------------------------------------------------------ fields
    def stresses(self, r):
        """(s_rr, s_tt, s_zz) at radii r >= R, compression negative."""
        r = np.asarray(r, float)
        p0, Rp = self.p0, self.plastic_radius
        pb = self.critical_pressure if self.plastic else self.p_i
        sr = p0 - (p0 - pb) * (Rp / r) ** 2
        st = p0 + (p0 - pb) * (Rp / r) ** 2
        if self.plastic:
            inside = r < Rp
            A = self._A
            sr_p = (self.p_i + A) * (r / self.R) ** (self.K_p - 1) - A
            sr = np.where(inside, sr_p, sr)
            st = np.where(inside, self.K_p * sr_p + self.s_c, st)
        sz = p0 + self.nu * (sr + st - 2 * p0)
        return -sr, -st, -sz

    def displacement(self, r):
        """Radial displacement u_r at radii r >= R (outward positive: negative here)."""
        r = np.asarray(r, float)
        Rp, nu, E = self.plastic_radius, self.nu, self.E
        pb = self.critical_pressure if self.plastic else self.p_i
        U_el = (self.p0 - pb) * Rp ** 2 * (1 + nu) / (E * r)
        if not self.plastic:
            return -U_el
        Kp, Kq, A = self.K_p, self.K_psi, self._A
        alpha = (1 - nu - nu * Kq) + Kp * (Kq * (1 - nu) - nu)
        U_Rp = (self.p0 - pb) * Rp * (1 + nu) / E
        U_pl = U_Rp * (Rp / r) ** Kq + (1 + nu) / E * (
            alpha * (self.p_i + A) * self.R ** (1 - Kp) * (r ** Kp - Rp ** (Kp + Kq) * r ** -Kq) / (Kp + Kq)
            - (1 - 2 * nu) * (self.p0 + A) * (r - Rp ** (Kq + 1) * r ** -Kq))
        return -np.where(r < Rp, U_pl, U_el)

    def out_of_plane_is_intermediate(self, n: int = 200) -> bool:
        """Whether s_z stays between s_r and s_t in the plastic zone, as the solution assumes.
        (With full release it holds iff p0/s_c <= (1 - nu)/(1 - 2 nu) at the wall; otherwise s_z
        becomes the major stress near the wall and the true solution involves the MC edge.)"""
        r = np.linspace(self.R, self.plastic_radius, n)
        sr, st, sz = self.stresses(r)
        tol = 1e-12 * self.p0
        return bool(np.all((sz <= sr + tol) & (sz >= st - tol)))

    @property
    def wall_displacement(self) -> float:
        """u_r at the wall (outward positive, so negative: the tunnel converges)."""
        return float(self.displacement(self.R))
