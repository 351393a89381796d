"""Staged construction with a lining (geoback.physics.staged, geoback.physics.lining, geoback.case.construction).

- Convergence-confinement of a deep circular tunnel (uniform in-situ stress, elastic ground, a thick
  elastic ring installed after a release beta): wall displacement and lining thrust within 1 % of the
  closed form for several relative stiffnesses; with K0 != 1 thrust and bending moment against the
  exact bonded thick-ring solution (tests/lined_tunnel.py).
- beta = 1 without a lining equals the one-step model; a lining of vanishing stiffness too; an
  infinitely stiff lining installed before any release allows no movement; the condensed lining
  equals the assembled ground-and-lining matrix.
- Every sensitivity (ground, extensions, beta[stage], the lining's E and nu) against central
  differences; factorisations through a whole identification = distinct stiffness configurations.
"""
from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
import yaml

from conftest import CASES
from geoback.case.loading import LoadedCase, case_from_data
from geoback.physics.extensions import EXTENSIONS
from geoback.physics.elastic import ElasticSimulation
from geoback.physics.ground import Extension
from geoback.inference.identification import identify, prepare
from geoback.observation.readings import survey_blocks
from geoback.physics.factory import make_simulation
from geoback.physics.staged import StagedSimulation
from lined_tunnel import LinedTunnel, ccm, check_michell, support_stiffness

pytestmark = pytest.mark.quick  # the edit-test loop tier (`pytest -m quick`)

# ---------------------------------------------------------------------------- the deep tunnel
R, T, Z0, E_G, NU_G, NU_L, GAMMA = 1.0, 0.1, 40.0, 1e5, 0.3, 0.2, 20.0


def _uniform(f, value, ground, i, values):
    """The in-situ stress of the axis' depth all round the wall (a deep tunnel): sigma_v = -gamma z0."""
    f.release = f.release * ((1 - value) + value * Z0 / f.point_depth)


UNIFORM = {**EXTENSIONS, "uniform": Extension("uniform", False, "-", 0.0, _uniform, "uniform in-situ stress")}


def deep_case(El: float, beta: float, K0: float, install_first: bool = False) -> LoadedCase:
    stages = [{"name": "unsupported", "release": beta}, {"name": "lined", "install": "lining", "release": 1.0}]
    if install_first:
        stages = [{"name": "lined", "install": "lining", "release": 1.0}]
    data = {"name": "deep", "geometry": {"radius": R, "axis_depth": Z0, "width": 40.0, "depth": 80.0},
            "ground": {"unit_weight": GAMMA, "K0": K0, "layers": [{"name": "g", "top": 0.0, "E": E_G, "nu": NU_G}]},
            "mesh": {"size_tunnel": R / 16, "size_far": 4.0},
            "instruments": [{"name": "P", "kind": "points", "points": [[R, -Z0]], "sigma": 1e-3}],
            "construction": {"lining": {"thickness": T, "E": El, "nu": NU_L}, "stages": stages}}
    return LoadedCase(case_from_data(data), Path("deep.yaml"), {})


def wall_radial(sim, u_free):
    """Polar angle and radial displacement of the wall nodes, without the rigid translation of the
    hole: the free surface 40 R above and the fixed base 40 R below move it as a rigid body (mode 1),
    which an infinite medium does not (it strains nothing)."""
    fe = sim.fe
    u = fe.expand(u_free).reshape(-1, 2)
    wall = np.unique(fe.mesh.tunnel_edges)
    p = fe.nodes[wall] - np.array([0.0, -Z0])
    phi = np.arctan2(p[:, 1], p[:, 0])
    o = np.argsort(phi)
    shift = np.trapezoid(u[wall][o, 1], phi[o]) / np.pi
    return phi, ((u[wall] - [0.0, shift]) * p).sum(axis=1) / np.hypot(p[:, 0], p[:, 1])


def deep_run(El: float, beta: float, K0: float):
    loaded = deep_case(El, beta, K0)
    sim = make_simulation(loaded, extensions=UNIFORM)
    values = prepare(loaded, with_readings=False, simulation=sim, values={"uniform": 1.0}).values
    U = sim.stage_displacements(values)
    phi, ur = wall_radial(sim, U[-1])
    return sim, U, phi, ur, sim.lining_forces(values)


def test_the_closed_form_is_consistent():
    assert check_michell() < 1e-8  # the displacement table used by the deviatoric mode
    for ratio in (0.1, 1.0, 10.0):  # with K0 = 1 the full solution is the CCM's two lines meeting
        El = ratio * E_G / (1 + NU_G) / support_stiffness(R, T, 1.0, NU_L)
        cf = LinedTunnel(R, T, E_G, NU_G, El, NU_L, -GAMMA * Z0, 1.0, 0.4)
        u, pl, N = ccm(R, T, E_G, NU_G, El, NU_L, GAMMA * Z0, 0.4)
        assert -cf.wall_displacement(0.3)[0] == pytest.approx(u, rel=1e-12)
        assert cf.lining_pressure() == pytest.approx(pl, rel=1e-12)
        assert cf.forces([10.0])[0][0] == pytest.approx(N, rel=1e-12)  # N = p_l R (equilibrium)


@pytest.mark.parametrize("ratio", [0.1, 1.0, 10.0], ids=lambda r: f"ks/kg={r:g}")
@pytest.mark.parametrize("beta", [0.3, 0.6])
def test_convergence_confinement_of_a_deep_tunnel(ratio, beta):
    """Ground reaction line meeting the thick ring's support line: wall displacement and thrust
    within 1 % (measured: 1.5e-3, its mean 2.5e-5, and 1.4e-3), for support-to-ground stiffness ratios 0.1 to 10."""
    El = ratio * E_G / (1 + NU_G) / support_stiffness(R, T, 1.0, NU_L)
    sim, U, phi, ur, forces = deep_run(El, beta, 1.0)
    u, pl, N = ccm(R, T, E_G, NU_G, El, NU_L, GAMMA * Z0, beta)
    assert np.max(np.abs(-ur / u - 1)) < 0.01
    assert -np.mean(ur) == pytest.approx(u, rel=1e-3)
    assert np.max(np.abs(forces.N[-1] / N - 1)) < 0.01
    assert forces.stages == ["lined"]
    # before the lining the unsupported wall took beta of the full release: p0 R / (2 G) beta
    _, ur1 = wall_radial(sim, U[0])
    assert np.max(np.abs(-ur1 / (beta * GAMMA * Z0 * R * (1 + NU_G) / E_G) - 1)) < 0.01


@pytest.mark.parametrize("ratio", [0.1, 10.0], ids=lambda r: f"ks/kg={r:g}")
def test_thrust_and_moment_with_K0_against_the_bonded_thick_ring(ratio):
    """K0 = 0.5: the deviatoric mode bends the ring. N within 1 % of its largest value and M within
    1 % of its largest value around the ring (measured: 5e-4 and 6e-3 at ks/kg = 0.1)."""
    El = ratio * E_G / (1 + NU_G) / support_stiffness(R, T, 1.0, NU_L)
    _, _, phi, ur, forces = deep_run(El, 0.4, 0.5)
    cf = LinedTunnel(R, T, E_G, NU_G, El, NU_L, -GAMMA * Z0, 0.5, 0.4)
    N, M = cf.forces(forces.angle)
    assert np.max(np.abs(forces.N[-1] - N)) < 0.01 * np.max(np.abs(N))
    assert np.max(np.abs(forces.M[-1] - M)) < 0.01 * np.max(np.abs(M))
    u_cf = cf.wall_displacement(phi)[0]
    assert np.max(np.abs(ur - u_cf)) < 0.01 * np.max(np.abs(u_cf))
    # moments: sagging (intrados in tension) where the ground pushes in the most
    assert np.sign(forces.M[-1][0]) == np.sign(M[0])


def test_infinitely_stiff_lining_installed_before_any_release_allows_no_movement():
    loaded = deep_case(1e6 * E_G, 1.0, 1.0, install_first=True)
    sim = make_simulation(loaded, extensions=UNIFORM)
    values = prepare(loaded, with_readings=False, simulation=sim, values={"uniform": 1.0}).values
    u = sim.stage_displacements(values)[-1]
    free = GAMMA * Z0 * R * (1 + NU_G) / E_G  # the unlined wall's movement
    assert np.max(np.abs(u)) < 1e-5 * free
    forces = sim.lining_forces(values)
    assert forces.N[-1] == pytest.approx(np.full_like(forces.N[-1], GAMMA * Z0 * R), rel=1e-3)  # carries it all


# ---------------------------------------------------------------------------- a shallow tunnel
def paper_data(construction: dict | None, parameters: list | None = None) -> dict:
    data = yaml.safe_load((CASES / "tunnel-paper.yaml").read_text())
    data["mesh"] = {"size_tunnel": 0.6, "size_far": 5.0}
    for ins in data["instruments"]:
        ins.pop("readings")
    data["instruments"].append({"name": "S", "kind": "points", "points": [[0.0, 0.0], [4.0, 0.0], [8.0, 0.0]],
                                "components": ["uy"], "sigma": 0.001})
    if construction is not None:
        data["construction"] = construction
    if parameters is not None:
        data["parameters"] = parameters
    return data


STAGED = {"lining": {"thickness": 0.3, "E": "20 GPa", "nu": 0.2},
          "stages": [{"name": "advance", "release": 0.4}, {"name": "lined", "install": "lining", "release": 1.0}]}


def loaded_of(data) -> LoadedCase:
    return LoadedCase(case_from_data(data), CASES / "x.yaml", {})


def staged_analysis(data, **kw):
    loaded = loaded_of(data)
    from geoback.case.loading import stage_names

    blocks, _ = survey_blocks(loaded, stage_names(loaded.case), read=False)
    sim = make_simulation(loaded, blocks=blocks)
    return prepare(loaded, with_readings=False, simulation=sim, **kw)


def test_full_release_without_lining_equals_the_one_step_model():
    one = prepare(loaded_of(paper_data(None)), with_readings=False)
    staged = prepare(loaded_of(paper_data({"stages": [{"name": "excavation", "release": 1.0}]})), with_readings=False)
    assert isinstance(staged.simulation, StagedSimulation) and isinstance(one.simulation, ElasticSimulation)
    p = one.parameters.initial
    a, b = one.predict(p, sensitivities=True), staged.predict(p, sensitivities=True)
    np.testing.assert_allclose(b.x, a.x, rtol=1e-13, atol=1e-16)
    np.testing.assert_allclose(b.A, a.A, rtol=1e-12, atol=1e-14 * np.abs(a.A).max())


def test_several_releases_without_lining_add_up_to_the_one_step_model():
    stages = {"stages": [{"name": "a", "release": 0.25}, {"name": "b", "release": 0.7}, {"name": "c", "release": 1.0}]}
    staged = staged_analysis(paper_data(stages))
    one = prepare(loaded_of(paper_data(None)), with_readings=False)
    x1 = one.predict(one.parameters.initial).x
    x = staged.predict(staged.parameters.initial).x
    rows = np.array([lab.stage for lab in staged.simulation.survey.labels])
    m = len(x1)
    for stage, beta in (("a", 0.25), ("b", 0.7), ("c", 1.0)):
        np.testing.assert_allclose(x[rows == stage], beta * x1[:m], rtol=1e-12)


def test_lining_of_vanishing_stiffness_equals_the_one_step_model():
    soft = copy.deepcopy(STAGED)
    soft["lining"]["E"] = 1e-6  # kPa
    staged = staged_analysis(paper_data(soft))
    one = prepare(loaded_of(paper_data(None)), with_readings=False)
    x1 = one.predict(one.parameters.initial).x
    x = staged.predict(staged.parameters.initial).x
    rows = np.array([lab.stage for lab in staged.simulation.survey.labels])
    np.testing.assert_allclose(x[rows == "lined"], x1, rtol=1e-9, atol=1e-10 * np.abs(x1).max())
    np.testing.assert_allclose(x[rows == "advance"], 0.4 * x1, rtol=1e-12)


def test_condensed_lining_equals_the_assembled_matrix():
    """(K_g + U S U^t) from the condensation against the ground and ring matrices assembled
    together and solved directly."""
    a = staged_analysis(paper_data(STAGED))
    sim = a.simulation
    values = a.values
    w1 = sim._w1(sim._solution(values))
    ring, fe = sim.ring, sim.fe
    st = sim.ground.state(sim._ground_values(values))
    Kg = fe.matrix(st.coeffs)
    Kg = Kg + sp.triu(Kg, 1).T
    Kr = ring.fe.matrix(ring.coefficients(values).real)
    Kr = (Kr + sp.triu(Kr, 1).T).tocsr()
    n, ni = fe.nfree, len(ring.i)
    index = np.empty(ring.fe.nfree, np.int64)  # ring free dof -> position in the joint system
    index[ring.o] = ring.wall_dofs
    index[ring.i] = n + np.arange(ni)
    C = Kr.tocoo()
    K = sp.block_diag([Kg, sp.csr_matrix((ni, ni))]) + sp.csr_matrix((C.data, (index[C.row], index[C.col])), shape=(n + ni,) * 2)
    f = np.concatenate([fe.load(st.sigma_v, st.sigma_h), np.zeros(ni)])
    u = spla.spsolve(K.tocsc(), f)
    np.testing.assert_allclose(w1, u[:n], rtol=1e-8, atol=1e-10 * np.abs(u).max())
    inner = sim.ring.ring_displacement(u[ring.wall_dofs])
    np.testing.assert_allclose(inner[ring.fe.free[ring.i]], u[n:], rtol=1e-8, atol=1e-10 * np.abs(u).max())


SENSITIVITY_PARAMETERS = [
    {"name": "E", "initial": 9000.0}, {"name": "K0", "initial": 0.8}, {"name": "nu", "initial": 0.3},
    {"name": "beta[advance]", "initial": 0.45}, {"name": "E[lining]", "initial": 1.5e7},
    {"name": "nu[lining]", "initial": 0.25}, {"name": "Egrad[clay]", "initial": 150.0},
    {"name": "n[clay]", "initial": 1.2}, {"name": "m[clay]", "initial": 0.9}, {"name": "K0grad", "initial": 0.02},
    {"name": "beta", "initial": 0.9}]


@pytest.mark.parametrize("mode", ["condensed", "direct"])
def test_sensitivities_through_the_stages_match_central_differences(mode):
    """Both ways of solving the lined configuration: condensed onto the wall while the ground's
    factorisation is reused, assembled and factorised once the ground keeps changing."""
    a = staged_analysis(paper_data(STAGED, SENSITIVITY_PARAMETERS))
    p = a.parameters.initial.copy()
    if mode == "direct":
        a.predict(p * np.where(np.array(a.parameters.names) == "nu[clay]", 0.9, 1.0))  # another ground
        x_direct = a.predict(p).x
    A = a.predict(p, sensitivities=True).A
    assert (a.simulation._sol.direct is not None) == (mode == "direct")
    if mode == "direct":
        fresh = staged_analysis(paper_data(STAGED, SENSITIVITY_PARAMETERS))
        np.testing.assert_allclose(x_direct, fresh.predict(p).x, rtol=1e-9, atol=1e-12)  # = condensed
    for j, name in enumerate(a.parameters.names):
        h = 1e-2 * abs(p[j])
        up, down = p.copy(), p.copy()
        up[j] += h
        down[j] -= h
        up2, down2 = p.copy(), p.copy()
        up2[j] += 2 * h
        down2[j] -= 2 * h
        # fourth-order central difference: truncation (h/p)^4 ~ 1e-8, round-off ~ 1e-13 / 1e-2
        fd = (8 * (a.predict(up).x - a.predict(down).x) - (a.predict(up2).x - a.predict(down2).x)) / (12 * h)
        err = np.linalg.norm(fd - A[:, j]) / np.linalg.norm(A[:, j])
        assert err < 1e-6, (name, err)


def test_lining_sensitivities_without_an_unlined_stage():
    first = {"lining": STAGED["lining"], "stages": [{"name": "lined", "install": "lining", "release": 1.0}]}
    a = staged_analysis(paper_data(first, [{"name": "E", "initial": 9000.0}, {"name": "E[lining]", "initial": 2e6}]))
    p = a.parameters.initial.copy()
    A = a.predict(p, sensitivities=True).A
    for j in range(2):
        h = 1e-3 * p[j]
        up, down = p.copy(), p.copy()
        up[j] += h
        down[j] -= h
        fd = (a.predict(up).x - a.predict(down).x) / (2 * h)
        assert np.linalg.norm(fd - A[:, j]) < 1e-5 * np.linalg.norm(A[:, j])


def test_one_factorisation_per_configuration_through_an_identification():
    """(E, K0, beta) from readings at two stages: the ground's factorisation and the lined
    configuration's (its condensation onto the wall) are made once and reused to the end."""
    params = [{"name": "E", "initial": 5000.0, "bounds": [100, 1e6]}, {"name": "K0", "initial": 0.6},
              {"name": "beta[advance]", "initial": 0.6, "bounds": [0.05, 1.0]}]
    data = paper_data(STAGED, params)
    truth = {"E[clay]": 10000.0, "K0": 1.0, "beta[advance]": 0.35}
    gen = staged_analysis(data)
    x = gen.simulation.predict({**gen.values, **truth}).x
    a = staged_analysis(data).with_readings(x)  # a fresh simulation: every instrument at both stages
    sim = a.simulation
    res = identify(a)
    assert res.fit.status == "converged"
    for name, v in truth.items():
        assert res[name].value == pytest.approx(v, rel=1e-6)
    assert res.counts["factorisations"] == 2 == len(sim.plan.configurations)
    assert res.counts["solves"] <= sim.ring.n_wall_dofs + 4  # the wall flexibility, then the loads only
