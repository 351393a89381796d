"""PlasticSimulation (geoback.physics.plastic): a case with Mohr-Coulomb ground behind the Simulation interface,
on a real gmsh mesh with the real incremental solver (no mocks).

The case: a tunnel (R = 3 m, axis 15 m deep) in one mohr-coulomb layer under gravity, K0 = 0.9,
released in two stages (beta = 0.7, then 1) - a plastic zone at both stages (to 1.10 R and 1.56 R
at c = 50 kPa, phi = 30 deg, psi = 5 deg), so the second stage carries the history of the first.

Measured here (1.5 k free DOFs): DDM sensitivities of the readings against central differences of
step 1e-5 (the base run's schedule replayed, Newton tolerance 1e-13) agree to 1e-11..2e-9 relative
(E 1.0e-10, nu 1.5e-10, K0 2.0e-11, c 1.1e-11, phi 1.5e-10, psi 9.9e-10, beta[near] 2.1e-9,
beta[final] 4.5e-11); c = 1e9 kPa reproduces the linear-elastic staged model's readings to 2e-14
relative; readings with 5, 10, 20, 40 increments per unit of release differ from those with 80 by
3.0e-3, 2.2e-3, 8.8e-4, 3.1e-4 relative (the default is 10).
"""
from __future__ import annotations

import copy

import numpy as np
import pytest

from geoback.case.loading import LoadedCase, case_from_data
from geoback.errors import CaseError, ForwardFailure
from geoback.inference.estimate import Settings, fit
from geoback.inference.identification import prepare
from geoback.observation.instruments import build_survey
from geoback.physics.plastic import PROBE_TOL, PlasticSimulation
from geoback.physics.factory import make_simulation

pytestmark = pytest.mark.quick  # the edit-test loop tier (`pytest -m quick`)


def case_data(**layer) -> dict:
    ground = {"name": "marl", "top": 0.0, "E": "40 MPa", "nu": 0.3, "model": "mohr-coulomb", "c": 50.0,
              "phi": 30.0, "psi": 5.0}
    ground.update(layer)
    return dict(
        name="plastic-small",
        geometry=dict(radius=3.0, axis_depth=15.0, width=40.0, depth=40.0),
        ground=dict(unit_weight=20.0, K0=0.9, layers=[ground]),
        mesh=dict(size_tunnel=0.6, size_far=8.0),
        construction=dict(stages=[dict(name="near", release=0.7), dict(name="final", release=1.0)]),
        instruments=[
            dict(name="X1", kind="extensometer", start=[0.0, 0.0], end=[0.0, -11.8], spacing=2.0, stations=5,
                 sigma=0.0002),
            dict(name="I1", kind="inclinometer", x=4.5, toe_depth=30.0, spacing=3.0, stations=9, sigma=0.0002),
            dict(name="C1", kind="convergence", points=[[0.0, -12.0], [3.0, -15.0]], sigma=0.0005),
        ],
    )


def loaded_case(**layer) -> LoadedCase:
    return LoadedCase(case_from_data(case_data(**layer)), None, {})


@pytest.fixture(scope="module")
def sim():
    return make_simulation(loaded_case())


NAMES = ["E[marl]", "nu[marl]", "K0", "c[marl]", "phi[marl]", "psi[marl]", "beta[near]", "beta[final]"]


def test_chosen_for_mohr_coulomb_ground_and_names(sim):
    assert isinstance(sim, PlasticSimulation) and sim.stages == ["near", "final"]
    q = sim.quantities()
    assert q["c[marl]"] == 50.0 and q["phi[marl]"] == 30.0 and q["psi[marl]"] == 5.0 and q["beta[near]"] == 0.7
    assert sim.canonical("c") == "c[marl]" and sim.canonical("phi") == "phi[marl]" and sim.canonical("tension") is None
    assert sim.unit("phi[marl]") == "deg" and sim.unit("c[marl]") == "kPa" and sim.unit("E[marl]") == "kPa"
    assert sim.limits("psi[marl]", q).hi == 30.0  # psi at most phi
    assert sim.limits("phi[marl]", q).contains(30.0) and not sim.limits("phi[marl]", q).contains(70.0)


def test_plastic_zone_at_both_stages(sim):
    zone = sim.plastic_zone(sim.quantities())
    near, final = zone.stages
    assert near.yielded_points > 0 and final.yielded_points > near.yielded_points
    assert 1.05 < near.max_radius / 3.0 < final.max_radius / 3.0 < 2.0
    assert final.area > near.area > 0


def _replayed(sim: PlasticSimulation) -> PlasticSimulation:
    """The simulation replaying its last run's schedule with a tight Newton tolerance (finite differences)."""
    return sim.replaying(sim.quantities())


def test_sensitivities_against_central_differences(sim):
    values = sim.quantities()
    exact = sim.predict(values, NAMES, sensitivities=True).A
    fd = _replayed(sim)
    for j, name in enumerate(NAMES):
        h = 1e-5 * abs(values[name])
        up, down = dict(values), dict(values)
        up[name] += h
        down[name] -= h
        col = (fd.predict(up).x - fd.predict(down).x) / (2 * h)
        assert np.linalg.norm(exact[:, j]) > 0, name
        assert np.linalg.norm(col - exact[:, j]) <= 1e-5 * np.linalg.norm(exact[:, j]), name


def test_huge_cohesion_is_the_elastic_model(sim):
    values = dict(sim.quantities(), **{"c[marl]": 1e9})
    x = sim.predict(values).x
    run = sim.solution(values)
    assert not run.result.yielded.any()
    data = case_data()
    layer = data["ground"]["layers"][0]
    for f in ("model", "c", "phi", "psi"):
        layer.pop(f)
    elastic = make_simulation(LoadedCase(case_from_data(data), None, {}), mesh=sim.mesh)
    assert type(elastic).__name__ == "StagedSimulation"
    x_el = elastic.predict(elastic.quantities()).x
    assert np.linalg.norm(x - x_el) <= 1e-10 * np.linalg.norm(x_el)


def test_readings_do_not_depend_on_the_increments(sim):
    values = sim.quantities()
    fine = PlasticSimulation(sim.loaded, mesh=sim.mesh, increments=40)
    x10, x40 = sim.predict(values).x, fine.predict(values).x
    assert sum(len(stage) for stage in fine.options.schedule) == 40
    # elastic spans are one increment either way (exact: linear), the plastic ones are 4x finer
    assert fine.solution(values).result.counters.increments > 2 * sim.solution(values).result.counters.increments
    assert np.linalg.norm(x10 - x40) <= 5e-3 * np.linalg.norm(x40)


def test_residual_below_tolerance_at_every_increment_and_stage(sim):
    values = sim.quantities()
    run = sim.solution(values)
    res = run.result
    assert np.all(res.converged_residuals() <= res.tol)
    # the equilibrium of each stage's state, recomputed here from the stresses the run returned
    mat, sigma0, f, lam = sim._inputs(values)
    for k in range(len(sim.stages)):
        R = sim.ops.internal_force(res.sigma[k].reshape(-1, 4) - sigma0) - lam[k] * f
        assert np.linalg.norm(R) <= res.tol * np.linalg.norm(lam[k] * f)


def test_one_run_gives_readings_and_sensitivities_and_is_counted():
    sim = make_simulation(loaded_case())
    values = sim.quantities()
    sim.predict(values, NAMES[:4], sensitivities=True)
    c = sim.counters.snapshot()
    assert c["forward_runs"] == 1 and c["factorisations"] > 1 and c["solves"] >= c["factorisations"]
    sim.predict(values)  # readings at the point just evaluated: no new run
    sim.predict(values, NAMES[:2], sensitivities=True)
    assert sim.counters.forward_runs == 1
    # a trial point right after a sensitivity request: one run gives the sensitivities asked last too
    other = dict(values, **{"E[marl]": 41000.0})
    sim.predict(other)
    sim.predict(other, NAMES[:2], sensitivities=True)
    assert sim.counters.forward_runs == 2
    # a probe (an interval's check) is no trial point: its run differentiates nothing, and its Newton iterations
    # stop at PROBE_TOL: its readings are a fresh run's to that tolerance, and no closer than 1e-10 asks for
    probe = dict(values, **{"E[marl]": 39000.0})
    with sim.probing():
        x = sim.predict(probe).x
    assert sim.counters.forward_runs == 3 and sim._runs.run.names == () and sim._runs.run.probe
    fresh = make_simulation(loaded_case()).predict(probe).x
    scale = np.max(np.abs(fresh))
    assert 1e-12 * scale < np.max(np.abs(fresh - x)) <= 10 * PROBE_TOL * scale
    # outside a probe the probe's run is not reused: a run to the full tolerance is made
    again = sim.predict(probe).x
    assert sim.counters.forward_runs == 4 and not sim._runs.run.probe
    assert np.max(np.abs(fresh - again)) <= 1e-8 * scale


def test_another_survey_on_a_shallow_copy(sim):
    """Nothing survey-dependent is cached: a copy with another survey reads the same run."""
    values = sim.quantities()
    x = sim.predict(values).x
    runs = sim.counters.forward_runs
    blocks = [b for b in sim.survey.blocks if b.name == "I1"]
    other = copy.copy(sim)
    other.survey = build_survey(blocks, sim.fe)
    assert np.allclose(other.predict(values).x, x[sim.survey.rows("I1")], rtol=1e-12, atol=0)
    assert sim.counters.forward_runs == runs


def test_in_situ_stress_beyond_the_strength():
    with pytest.raises(CaseError, match="K0"):  # refused with the case
        case_from_data(dict(case_data(c=2.0), ground=dict(unit_weight=20.0, K0=0.25, layers=[
            case_data(c=2.0)["ground"]["layers"][0]])))
    sim = make_simulation(loaded_case())
    with pytest.raises(ForwardFailure, match="strength"):  # or met during a fit
        sim.predict(dict(sim.quantities(), **{"K0": 0.25, "c[marl]": 2.0}))
    with pytest.raises(ForwardFailure, match="dilation"):
        sim.predict(dict(sim.quantities(), **{"psi[marl]": 31.0}))


def test_a_trial_point_without_solution_is_a_rejected_step():
    """Gauss-Newton from far away steps to phi below the (fixed) dilation angle, where the model has
    no solution: the step is rejected and halved, and the fit still reaches the truth."""
    loaded = loaded_case(psi=20.0, phi=24.0)
    analysis = prepare(loaded, with_readings=False)
    x = analysis.simulation.predict(analysis.values).x
    from geoback.case.loading import Parameter

    a = prepare(loaded, with_readings=False, simulation=analysis.simulation,
                parameters=[Parameter(name="phi", initial=40.0, bounds=(10.0, 45.0))])
    from geoback.inference.misfit import Data, Misfit

    misfit = Misfit(a.simulation, Data.build(a.simulation.survey.blocks, x), a.parameters, a.base_values)
    res = fit(misfit, Settings(max_iterations=30), method="gn")
    assert any(not np.isfinite(h.J) and not h.accepted for h in res.history)
    assert res.status == "converged" and res.p[0] == pytest.approx(24.0, abs=0.05)


def test_forecasts_on_yielding_ground_are_the_model_at_the_estimate():
    """A plastic case with forecasts (a settlement line and points at the last stage, an instrument read
    at the first): the forecasts read through another survey (Simulation.surveying) equal the forward
    model at the identified values at those points, their sensitivities equal central differences of it,
    and the simulation reads its own instruments as before."""
    from geoback.worth.forecast import forecast

    data = case_data()
    data["parameters"] = [dict(name="E", initial="30 MPa", bounds=["1 MPa", "1 GPa"]),
                          dict(name="c", initial=70.0, bounds=[5.0, 500.0])]
    data["forecasts"] = [
        dict(name="trough", kind="line", start=[0.0, 0.0], end=[20.0, 0.0], points=5, component="uy", stage="final"),
        dict(name="P", kind="points", points=[[4.0, -10.0]], components=["ux", "uy"], stage="final"),
        dict(name="X1-near", kind="instrument", instrument="X1", stage="near"),
    ]
    data["design"] = dict(forecasts=["trough"], candidates=[
        dict(name="S2", kind="points", points=[[6.0, 0.0]], components=["uy"], sigma=0.0005,
             vary={"points": [[[6.0, 0.0]], [[30.0, 0.0]]]})])
    loaded = LoadedCase(case_from_data(data), None, {})
    analysis = prepare(loaded, with_readings=False)
    sim = analysis.simulation
    truth = dict(analysis.values, **{"E[marl]": 40000.0, "c[marl]": 50.0})
    x_true = sim.predict(truth).x
    a = analysis.with_readings(x_true)
    from geoback.inference.identification import identify

    res = identify(a, profile="none")
    assert res.status == "converged" and res.fit.p == pytest.approx([40000.0, 50.0], rel=1e-4)
    before = a.predict(res.fit.p, sensitivities=True)
    fc = forecast(a, res, draws=0)
    after = a.predict(res.fit.p, sensitivities=True)
    np.testing.assert_array_equal(before.x, after.x)  # the simulation's own survey is back
    np.testing.assert_array_equal(before.A, after.A)
    assert fc.counts["forward_runs"] == 0  # the forecasts read the fit's last run

    values = a.values_at(res.fit.p)
    fresh = make_simulation(loaded, mesh=sim.mesh)
    line = np.column_stack([np.linspace(0.0, 20.0, 5), np.zeros(5)])
    expected_trough = fresh.stage_displacements_at(values, line, "final")[:, 1]
    np.testing.assert_allclose(fc.value[fc.rows("trough")], expected_trough, rtol=1e-9, atol=1e-12)
    expected_p = fresh.stage_displacements_at(values, np.array([[4.0, -10.0]]), "final")[0]
    np.testing.assert_allclose(fc.value[fc.rows("P")], expected_p, rtol=1e-9, atol=1e-12)
    from geoback.observation.instruments import case_blocks

    x1_near = make_simulation(loaded, mesh=sim.mesh, blocks=[b.at("near") for b in case_blocks(loaded)
                                                             if b.name == "X1"]).predict(values).x
    np.testing.assert_allclose(fc.value[fc.rows("X1-near")], x1_near, rtol=1e-9, atol=1e-12)

    # geoback design on yielding ground: candidates read through another survey, no new run
    from geoback.worth.design import design

    d = design(a, res)
    assert d.counts["forward_runs"] == 0 and len(d.names) == 2
    assert np.all(np.isfinite(d.after)) and d.best == d.names[0]  # a point near the trough beats one far out

    # the band's sensitivities: exact DDM columns against central differences of the trough
    fd = fresh.replaying(values)
    for j, name in enumerate(res.parameters.names):
        h = 1e-5 * abs(values[name])
        up, down = dict(values), dict(values)
        up[name] += h
        down[name] -= h
        col = (fd.stage_displacements_at(up, line, "final")[:, 1]
               - fd.stage_displacements_at(down, line, "final")[:, 1]) / (2 * h)
        exact = fc.sensitivity[fc.rows("trough"), j]
        assert np.linalg.norm(col - exact) <= 1e-5 * np.linalg.norm(exact), name
