"""The closed-form deep tunnel in Mohr-Coulomb ground (geoback.physics.plasticity.closed_form).

Known limits and the conditions the solution is built from, checked on the formulae:
* c -> infinity, or a support pressure above the critical one: elastic, u_R = (p0 - p_i) R (1+nu)/E;
* stresses and displacement continuous at the plastic radius;
* equilibrium d s_r/dr + (s_r - s_t)/r = 0 in both zones; the yield condition in the plastic zone,
  strictly inside outside it;
* kinematics: from the displacement field, total strains minus Hooke's elastic strains of the
  stresses give plastic strains obeying the flow rule eps_r^p + K_psi eps_t^p = 0, with the
  right sign, and none in the elastic zone.
"""
from __future__ import annotations

import numpy as np
import pytest

from geoback.physics.plasticity.closed_form import DeepTunnelMC

P0, R, E, NU, C, PHI = 1000.0, 1.0, 1.0e5, 0.4, 110.0, np.radians(30.0)


def tunnel(psi_deg=0.0, p_i=0.0, c=C, nu=NU):
    return DeepTunnelMC(P0, R, E, nu, c, PHI, np.radians(psi_deg), p_i)


def test_huge_cohesion_is_elastic():
    t = tunnel(c=1e9)
    assert not t.plastic and t.plastic_radius == R
    assert t.wall_displacement == pytest.approx(-P0 * R * (1 + NU) / E, rel=1e-14)
    r = np.array([1.0, 2.0, 7.5])
    assert np.allclose(t.displacement(r), -P0 * R ** 2 * (1 + NU) / (E * r), rtol=1e-14)
    sr, st, sz = t.stresses(r)
    assert np.allclose(sr, -P0 * (1 - (R / r) ** 2)) and np.allclose(st, -P0 * (1 + (R / r) ** 2))
    assert np.allclose(sz, -P0)


@pytest.mark.parametrize("psi_deg", [0.0, 30.0])
def test_support_pressure_above_critical_keeps_the_ground_elastic(psi_deg):
    t0 = tunnel(psi_deg)
    p_cr = t0.critical_pressure
    assert 0 < p_cr < P0
    for p_i in (p_cr, p_cr + 50.0):
        t = tunnel(psi_deg, p_i=p_i)
        assert not t.plastic and t.plastic_radius == R
        assert t.wall_displacement == pytest.approx(-(P0 - p_i) * R * (1 + NU) / E, rel=1e-12)
    # just below it a thin plastic zone appears and the displacement is continuous in p_i
    t = tunnel(psi_deg, p_i=p_cr * (1 - 1e-9))
    assert t.plastic and t.plastic_radius == pytest.approx(R, rel=1e-8)
    assert t.wall_displacement == pytest.approx(-(P0 - p_cr) * R * (1 + NU) / E, rel=1e-7)
    # and p0 below the unconfined strength threshold never yields even at full release
    weak = DeepTunnelMC(0.4 * t0.s_c, R, E, NU, C, PHI, 0.0)
    assert weak.critical_pressure < 0 and not weak.plastic


@pytest.mark.parametrize("psi_deg", [0.0, 10.0, 30.0])
def test_fields_are_continuous_at_the_plastic_radius(psi_deg):
    t = tunnel(psi_deg)
    Rp = t.plastic_radius
    assert 1.5 < Rp / R < 2.0
    eps = 1e-9 * Rp
    inner, outer = Rp - eps, Rp + eps
    for a, b in zip(t.stresses(inner), t.stresses(outer)):
        assert a == pytest.approx(b, rel=1e-7)
    assert t.displacement(inner) == pytest.approx(t.displacement(outer), rel=1e-7)
    assert -t.stresses(Rp + eps)[0] == pytest.approx(t.critical_pressure, rel=1e-7)


@pytest.mark.parametrize("psi_deg", [0.0, 30.0])
def test_equilibrium_and_yield(psi_deg):
    t = tunnel(psi_deg)
    Rp = t.plastic_radius
    r = np.concatenate([np.linspace(R, 0.999 * Rp, 200), np.linspace(1.001 * Rp, 10 * R, 200)])
    h = 1e-6
    sr, st, _ = t.stresses(r)
    dsr = (t.stresses(r + h)[0] - t.stresses(r - h)[0]) / (2 * h)
    assert np.abs(dsr + (sr - st) / r).max() <= 1e-6 * P0
    s, n = -sr, -st  # compression positive: s_t = K_p s_r + s_c in the plastic zone
    f = n - t.K_p * s - t.s_c
    plastic = r < Rp
    assert np.abs(f[plastic]).max() <= 1e-10 * P0
    assert np.all(f[~plastic] < 0)


@pytest.mark.parametrize("psi_deg", [0.0, 10.0, 30.0])
def test_displacement_obeys_hooke_and_the_flow_rule(psi_deg):
    t = tunnel(psi_deg)
    Rp = t.plastic_radius
    r = np.concatenate([np.linspace(1.001 * R, 0.999 * Rp, 300), np.linspace(1.001 * Rp, 5 * R, 100)])
    h = 1e-6
    u = t.displacement(r)
    e_r = (t.displacement(r + h) - t.displacement(r - h)) / (2 * h)
    e_t = u / r
    sr, st, sz = (s + P0 for s in t.stresses(r))  # changes from the initial stress (-P0)
    e_r_el = ((1 - NU ** 2) * sr - NU * (1 + NU) * st) / E  # plane strain, no plastic strain out of plane
    e_t_el = ((1 - NU ** 2) * st - NU * (1 + NU) * sr) / E
    assert np.allclose(sz, NU * (sr + st), atol=1e-9 * P0)
    p_r, p_t = e_r - e_r_el, e_t - e_t_el
    scale = abs(t.wall_displacement) / R
    assert np.abs(p_r + t.K_psi * p_t).max() <= 1e-6 * scale
    plastic = r < Rp
    assert np.all(p_t[plastic] <= 1e-9 * scale)  # hoop contraction, radial extension
    assert p_t[plastic].min() < -1e-2 * scale
    assert np.abs(p_r[~plastic]).max() <= 1e-6 * scale and np.abs(p_t[~plastic]).max() <= 1e-6 * scale


def test_out_of_plane_stress_assumption_is_checked():
    """s_z must stay intermediate: with nu = 0.4 it does for p0/s_c = 2.6, with nu = 0.3 it does not."""
    assert tunnel(nu=0.4).out_of_plane_is_intermediate()
    assert not tunnel(nu=0.3).out_of_plane_is_intermediate()


def test_dilation_increases_the_convergence_and_not_the_plastic_radius():
    t0, t10, t30 = tunnel(0.0), tunnel(10.0), tunnel(30.0)
    assert t0.plastic_radius == t10.plastic_radius == t30.plastic_radius
    assert abs(t0.wall_displacement) < abs(t10.wall_displacement) < abs(t30.wall_displacement)
    assert abs(t0.wall_displacement) > P0 * R * (1 + NU) / E  # more than elastic


def test_invalid_inputs():
    with pytest.raises(ValueError):
        DeepTunnelMC(P0, R, E, NU, C, 0.0, 0.0)
    with pytest.raises(ValueError):
        DeepTunnelMC(P0, R, E, NU, C, PHI, PHI + 0.1)
    with pytest.raises(ValueError):
        DeepTunnelMC(P0, R, E, NU, C, PHI, 0.0, -1.0)
