"""Single-point verification of the Mohr-Coulomb return mapping (geoback.physics.plasticity.mohr_coulomb).

* elastic states are left alone, with the elastic tangent;
* after a return the stress satisfies the yield conditions, and the plastic strain is a
  non-negative combination of the active flow directions (Kuhn-Tucker), associated or not;
* the main-plane return equals the closed form of de Souza Neto et al. (2008, ch. 8);
* associated flow: the return is the closest point in the energy norm (checked against a
  general-purpose constrained minimiser), tension cut-off included;
* the apex: hydrostatic tension beyond c cot(phi) returns to it;
* the consistent tangent and the derivatives with respect to material and history equal central
  finite differences of the update; the tangent is symmetric for psi = phi only;
* complex-safety: a complex step gives the real update in its real part.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import minimize, nnls

from geoback.physics.plasticity import mohr_coulomb as mc
from geoback.physics.plasticity.mohr_coulomb import Material

E, NU, C, PHI = 1.0e4, 0.3, 20.0, np.radians(30.0)


def random_stresses(n, seed, spread=60.0, mean=-40.0):
    rng = np.random.default_rng(seed)
    s = rng.normal(0.0, spread, (n, 4))
    s[:, :3] += mean + rng.normal(0.0, spread, (n, 1))
    return s


def principal_sorted(sigma_trial, sigma):
    """Principal values of trial and returned stress in the trial's order s1 >= s2 >= s3."""
    pt, _, _ = mc.principal(sigma_trial)
    ps, _, _ = mc.principal(sigma)
    order = np.argsort(-pt, axis=1)
    return np.take_along_axis(pt, order, 1), np.take_along_axis(ps, order, 1)


def flow_vectors(psi):
    s = np.sin(psi)
    return {"F1": (1 + s, 0, s - 1), "F2": (0, 1 + s, s - 1), "F3": (1 + s, s - 1, 0),
            "T1": (1, 0, 0), "T2": (0, 1, 0), "T3": (0, 0, 1)}


def plane_values(s, c, phi, t):
    sp, k = np.sin(phi), 2 * c * np.cos(phi)
    return {"F1": (s[0] - s[2]) + (s[0] + s[2]) * sp - k, "F2": (s[1] - s[2]) + (s[1] + s[2]) * sp - k,
            "F3": (s[0] - s[1]) + (s[0] + s[1]) * sp - k, "T1": s[0] - t, "T2": s[1] - t, "T3": s[2] - t}


# ---------------------------------------------------------------------------- elastic and yield
def test_elastic_states_are_unchanged_with_elastic_tangent():
    mat = Material(E, NU, C, PHI, PHI / 3)
    sigma = random_stresses(2000, 1, spread=5.0, mean=-200.0)
    f, _ = mc.yield_functions(sigma, mat)
    inside = f < 0
    assert inside.sum() > 1500
    out, mode = mc.return_map(sigma[inside], mat)
    assert np.all(mode == mc.ELASTIC)
    assert np.array_equal(out, sigma[inside])
    deps = np.zeros((inside.sum(), 3))
    C_alg = mc.consistent_tangent(sigma[inside], deps, mat)
    assert np.array_equal(C_alg, mc.elastic_matrix(mat.at(inside.sum())))


@pytest.mark.parametrize("psi_deg, tension", [(30.0, np.inf), (0.0, np.inf), (10.0, 5.0), (30.0, 0.0)])
def test_returned_stresses_satisfy_the_yield_conditions_and_kuhn_tucker(psi_deg, tension):
    psi = np.radians(psi_deg)
    mat = Material(E, NU, C, PHI, psi, tension)
    trial = random_stresses(3000, 2)
    sigma, mode = mc.return_map(trial, mat)
    f, ft = mc.yield_functions(sigma, mat)
    scale = np.abs(trial).max(axis=1) + C
    ok = mode != mc.APEX
    assert np.all(f[ok] <= 1e-10 * scale[ok])
    if np.isfinite(tension):
        assert np.all(ft <= 1e-10 * scale)
    assert len(np.unique(mode)) >= (4 if np.isfinite(tension) else 3)
    # plastic strain = D^-1 (trial - sigma) in principal space: a non-negative combination of the
    # flow directions of the active planes (and only those)
    lam, G = mc.lame(E, NU)
    Dp = lam * np.ones((3, 3)) + 2 * G * np.eye(3)
    pt, ps = principal_sorted(trial, sigma)
    N = flow_vectors(psi)
    checked = 0
    for k in np.flatnonzero((mode != mc.ELASTIC) & ok)[:400]:
        deps_p = np.linalg.solve(Dp, pt[k] - ps[k])
        values = plane_values(ps[k], C, PHI, tension)
        active = [name for name, v in values.items() if abs(v) <= 1e-9 * scale[k]]
        A = np.array([N[name] for name in active]).T
        coef, resid = nnls(A, deps_p)
        assert resid <= 1e-9 * np.linalg.norm(deps_p), (k, mode[k], active)
        checked += 1
    assert checked > 100


def test_main_plane_return_is_the_closed_form():
    psi = np.radians(10.0)
    mat = Material(E, NU, C, PHI, psi)
    # principal trial stresses well apart, moderately outside: returns to the face F1
    rng = np.random.default_rng(3)
    s1 = rng.uniform(-20, 0, 200)
    s2 = s1 - rng.uniform(60, 80, 200)
    s3 = s2 - rng.uniform(60, 80, 200)
    trial = np.column_stack([s1, s3, s2, np.zeros(200)])  # in-plane pair (s1, s3), szz = s2
    sigma, mode = mc.return_map(trial, mat)
    assert np.all(mode == 1)  # all outside, none near an edge
    lam, G = mc.lame(E, NU)
    K = lam + 2 * G / 3
    sphi, spsi = np.sin(PHI), np.sin(psi)
    f = (s1 - s3) + (s1 + s3) * sphi - 2 * C * np.cos(PHI)
    dgamma = f / (4 * G * (1 + sphi * spsi / 3) + 4 * K * sphi * spsi)
    expected = np.column_stack([
        s1 - (2 * G * (1 + spsi / 3) + 2 * K * spsi) * dgamma,
        s3 + (2 * G * (1 - spsi / 3) - 2 * K * spsi) * dgamma,
        s2 + (4 * G / 3 - 2 * K) * spsi * dgamma,
        np.zeros(200)])
    assert np.abs(sigma - expected).max() <= 1e-12 * np.abs(trial).max()


def test_associated_return_is_the_closest_point_in_the_energy_norm():
    """psi = phi: the return maps to the admissible point nearest in the D^-1 norm (convex set:
    Mohr-Coulomb and the tension cut-off), whatever face, edge or corner is active."""
    t = 10.0
    mat = Material(E, NU, C, PHI, PHI, t)
    trial = random_stresses(160, 4)
    sigma, mode = mc.return_map(trial, mat)
    assert {1, 2, 3, 4, 5}.issubset(set(mode.tolist()))
    lam, G = mc.lame(E, NU)
    Dinv = np.linalg.inv(lam * np.ones((3, 3)) + 2 * G * np.eye(3))
    sp, k = np.sin(PHI), 2 * C * np.cos(PHI)
    cons = [{"type": "ineq", "fun": (lambda x, i=i, j=j: (k - (x[i] - x[j]) - (x[i] + x[j]) * sp) / k)}
            for i in range(3) for j in range(3) if i != j]
    cons += [{"type": "ineq", "fun": (lambda x, i=i: (t - x[i]) / k)} for i in range(3)]
    pt, ps = principal_sorted(trial, sigma)
    worst = 0.0
    for q in np.flatnonzero(mode != mc.ELASTIC):
        start = np.minimum(ps[q], t) - 1.0
        res = minimize(lambda x: G * (x - pt[q]) @ Dinv @ (x - pt[q]), start, constraints=cons, method="SLSQP",
                       options=dict(ftol=1e-15, maxiter=500))
        worst = max(worst, np.abs(res.x - ps[q]).max() / (np.abs(pt[q]).max() + C))
    assert worst <= 1e-5  # the accuracy of SLSQP, not of the return mapping


@pytest.mark.parametrize("tension", [np.inf, 3.0])
def test_hydrostatic_tension_returns_to_the_apex(tension):
    mat = Material(E, NU, C, PHI, 0.0, tension)
    apex = min(C / np.tan(PHI), tension)
    trial = np.array([[100.0, 100.0, 100.0, 0.0], [80.0, 90.0, 95.0, 1.0]])
    sigma, mode = mc.return_map(trial, mat)
    assert np.allclose(sigma, [apex, apex, apex, 0.0], rtol=0, atol=1e-10 * apex)


# ---------------------------------------------------------------------------- derivatives
def _fd_states(psi, seed, n=4000):
    mat = Material(E, NU, C, PHI, psi, 8.0)
    sigma_n = random_stresses(n, seed, spread=40.0, mean=-60.0)
    f, ft = mc.yield_functions(sigma_n, mat)
    sigma_n = sigma_n[(f <= 0) & (ft <= 0)]  # start from admissible states
    rng = np.random.default_rng(seed + 100)
    deps = rng.normal(0.0, 4e-3, (len(sigma_n), 3))
    return mat, sigma_n, deps


def _stable(sigma_n, deps, mat, sigma_pert):
    """Points whose active set does not change under the finite-difference perturbations."""
    base = mc.select(mc.trial_stress(sigma_n, deps, mat.at(len(sigma_n))), mat.at(len(sigma_n)))
    keep = base != mc.APEX
    for s_n, d_e, m in sigma_pert:
        keep &= mc.select(mc.trial_stress(s_n, d_e, m.at(len(s_n))), m.at(len(s_n))) == base
    return keep, base


@pytest.mark.parametrize("psi_deg", [30.0, 10.0, 0.0])
def test_consistent_tangent_equals_finite_differences(psi_deg):
    mat, sigma_n, deps = _fd_states(np.radians(psi_deg), 5)
    C_alg = mc.consistent_tangent(sigma_n, deps, mat)
    h = 1e-8
    pert = []
    fd = np.zeros_like(C_alg)
    for j in range(3):
        e = np.zeros(3)
        e[j] = h
        pert += [(sigma_n, deps + e, mat), (sigma_n, deps - e, mat)]
        fd[:, :, j] = (mc.update(sigma_n, deps + e, mat)[0] - mc.update(sigma_n, deps - e, mat)[0]) / (2 * h)
    keep, mode = _stable(sigma_n, deps, mat, pert)
    plastic = keep & (mode != mc.ELASTIC)
    assert plastic.sum() > 300 and len(set(mode[plastic].tolist())) >= 4
    lam, G = mc.lame(E, NU)
    # relative to the tangent, or to 1e-3 of the elastic stiffness where it vanishes (corners, apex)
    scale = np.maximum(np.abs(C_alg[keep]).max(axis=(1, 2)), 1e-3 * (lam + 2 * G))
    err = np.abs(fd - C_alg)[keep].max(axis=(1, 2)) / scale
    assert err.max() <= 1e-5  # central differences in double precision
    inplane = C_alg[plastic][:, [0, 1, 3], :]
    asym = np.abs(inplane - inplane.transpose(0, 2, 1)).max(axis=(1, 2)) / (lam + 2 * G)
    if psi_deg == 30.0:
        assert asym.max() <= 1e-10  # associated: symmetric algorithmic tangent
    else:
        assert np.median(asym) > 1e-3  # non-associated: not symmetric


@pytest.mark.parametrize("psi_deg", [30.0, 10.0, 0.0])
def test_tangent_by_hand_equals_the_complex_step(psi_deg):
    """The consistent tangent differentiated by hand (real inputs) is the complex-step derivative of the same
    return mapping (complex inputs take it) to rounding, on every active set the states reach."""
    mat, sigma_n, deps = _fd_states(np.radians(psi_deg), 9)
    n = len(sigma_n)
    mode = mc.select(mc.trial_stress(sigma_n, deps, mat.at(n)), mat.at(n))
    by_hand = mc.consistent_tangent(sigma_n, deps, mat, mode)
    stepped = mc.consistent_tangent(sigma_n.astype(complex), deps, mat, mode)
    plastic = mode != mc.ELASTIC
    assert plastic.sum() > 300 and len(set(mode[plastic].tolist())) >= 5
    lam, G = mc.lame(E, NU)
    assert np.abs(by_hand - stepped).max() <= 1e-12 * (lam + 2 * G)
    assert np.array_equal(by_hand[~plastic], mc.elastic_matrix(mat.at(n))[~plastic])
    # beyond the apex (no return with psi = 0): the stress is the apex whatever the strain
    apex = Material(E, NU, C, PHI, 0.0)
    trial = np.array([[80.0, 90.0, 95.0, 1.0]])
    assert mc.select(trial, apex.at(1))[0] == mc.APEX
    zero = np.zeros((1, 3))
    assert np.abs(mc.consistent_tangent(trial, zero, apex)).max() == 0.0
    assert np.abs(mc.consistent_tangent(trial.astype(complex), zero, apex)).max() == 0.0


@pytest.mark.parametrize("name, h", [("E", 1e-3), ("nu", 1e-7), ("c", 1e-6), ("phi", 1e-8), ("psi", 1e-8),
                                     ("tension", 1e-6), ("sigma_n", 1e-6)])
def test_derivatives_of_the_update_equal_finite_differences(name, h):
    mat, sigma_n, deps = _fd_states(np.radians(10.0), 6)
    n = len(sigma_n)
    if name == "sigma_n":
        d_sigma = np.random.default_rng(7).normal(0.0, 1.0, sigma_n.shape)
        exact = mc.directional_derivative(sigma_n, deps, mat, d_sigma_n=d_sigma)
        plus, minus = (sigma_n + h * d_sigma, deps, mat), (sigma_n - h * d_sigma, deps, mat)
    else:
        d_mat = Material(**{**{k: 0.0 for k in Material.names()}, name: 1.0})
        exact = mc.directional_derivative(sigma_n, deps, mat, d_mat=d_mat)
        plus, minus = (sigma_n, deps, mat.at(n).plus(d_mat.at(n), h)), (sigma_n, deps, mat.at(n).plus(d_mat.at(n), -h))
    fd = (mc.update(*plus)[0] - mc.update(*minus)[0]) / (2 * h)
    keep, mode = _stable(sigma_n, deps, mat, [plus, minus])
    assert (keep & (mode != mc.ELASTIC)).sum() > 300
    scale = np.abs(exact[keep]).max() + 1e-300
    assert np.abs(fd - exact)[keep].max() <= 1e-5 * scale


def test_derivatives_along_many_directions_at_once_equal_one_at_a_time():
    mat, sigma_n, deps = _fd_states(np.radians(10.0), 11)
    n = len(sigma_n)
    mode = mc.select(mc.trial_stress(sigma_n, deps, mat.at(n)), mat.at(n))
    rng = np.random.default_rng(12)
    d_sigma, d_deps = rng.normal(0.0, 1.0, (n, 4, 4)), rng.normal(0.0, 1e-3, (n, 3, 4))
    d_sigma[:, :, 3] = 0.0  # a direction of the material only
    d_deps[:, :, 3] = 0.0
    zero = {k: 0.0 for k in Material.names()}
    d_mats = [Material(**{**zero, "E": 1.0}), None, Material(**{**zero, "phi": 1.0, "c": 2.0}),
              Material(**{**zero, "psi": 1.0})]
    many = mc.directional_derivatives(sigma_n, deps, mat, d_sigma, d_deps, d_mats, mode)
    assert (mode != mc.ELASTIC).sum() > 300
    for j in range(4):
        one = mc.directional_derivative(sigma_n, deps, mat, d_sigma[:, :, j], d_deps[:, :, j], d_mats[j], mode)
        assert np.abs(many[:, :, j] - one).max() <= 1e-13 * np.abs(one).max(), j


def test_complex_step_keeps_the_real_update():
    mat, sigma_n, deps = _fd_states(np.radians(10.0), 8)
    real, mode = mc.update(sigma_n, deps, mat)
    cplx, mode_c = mc.update(sigma_n + 1e-20j * np.ones_like(sigma_n), deps, mat)
    assert np.array_equal(mode, mode_c)
    assert np.abs(cplx.real - real).max() <= 1e-13 * np.abs(real).max()


def test_sorted_principal_stresses_are_the_stable_sort_of_the_principal_ones():
    """The sort that places szz among the ordered in-plane pair gives what a stable descending argsort gives,
    ties included (szz equal to the major, all three equal), real and complex-step stresses alike."""
    rng = np.random.default_rng(0)
    sig = rng.standard_normal((5000, 4)) * 100
    major = 0.5 * (sig[:, 0] + sig[:, 1]) + np.hypot(0.5 * (sig[:, 0] - sig[:, 1]), sig[:, 3])
    sig[::7, 2] = major[::7]
    sig[::11, 1] = sig[::11, 2] = sig[::11, 0]
    sig[::11, 3] = 0.0
    for s in (sig, sig + 1e-30j * rng.standard_normal(sig.shape)):
        p = mc.principal(s)[0]
        order = np.argsort(-p.real, axis=1, kind="stable")
        got, got_order = mc._sorted_principal(s)[:2]
        assert np.array_equal(got_order, order)
        assert np.array_equal(got, np.take_along_axis(p, order, axis=1))


def test_mobilised_strength():
    """1 on the yield surface, the ratio of deviator to strength inside, inf where the mean stress leaves none."""
    mat = mc.Material(1e5, 0.3, 20.0, np.radians(30.0), 0.0)
    s3 = -100.0
    # on the surface: (s1 - s3) = 2c cos(phi) - (s1 + s3) sin(phi)  ->  s1 = (2c cos(phi) + s3 (1 - sin(phi))) / (1 + sin(phi))
    phi = np.radians(30.0)
    s1 = (2 * 20.0 * np.cos(phi) + s3 * (1 - np.sin(phi))) / (1 + np.sin(phi))
    sigma = np.array([[s1, s3, 0.5 * (s1 + s3), 0.0],      # at yield
                      [-60.0, -60.0, -60.0, 0.0],          # isotropic: nothing mobilised
                      [100.0, 90.0, 95.0, 0.0]])           # tension beyond the apex: no strength left
    rho = mc.mobilised(sigma, mat)
    assert rho[0] == pytest.approx(1.0, rel=1e-12)
    assert rho[1] == 0.0
    assert np.isinf(rho[2])
    inside = mc.mobilised(np.array([[0.5 * (s1 + s3) + 0.25 * (s1 - s3), 0.5 * (s1 + s3) - 0.25 * (s1 - s3),
                                     0.5 * (s1 + s3), 0.0]]), mat)
    assert inside[0] == pytest.approx(0.5, rel=1e-12)
