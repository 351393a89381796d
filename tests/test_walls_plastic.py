"""Walls, props and anchors on Mohr-Coulomb ground (physics/excavation_plastic.py with the springs in the
engine, plasticity/incremental.py): ground that never yields is the elastic model, sensitivities included;
yielding ground's sensitivities against finite differences of the replayed schedule."""
from __future__ import annotations

import numpy as np
import pytest

from test_walls import geoback_cache, pit, simulation  # noqa: F401 - the fixture is used by every test


# ---------------------------------------------------------------------------- on mohr-coulomb ground
def _mc(c=15.0, phi=24.0, **kw):
    ins = [{"name": "I1", "kind": "inclinometer", "x": 10.4, "toe_depth": 24.0, "spacing": 2.0, "sigma": 1e-4,
            "readings": {"level2": [0.0] * 12, "dig3": [0.0] * 12}},
           {"name": "S1", "kind": "points", "points": [[12, 0], [16, 0], [24, 0]], "components": ["uy"],
            "sigma": 1e-3, "readings": {"dig3": [0.0] * 3}},
           {"name": "C1", "kind": "load_cell", "support": "P1", "sigma": 5.0, "readings": {"level2": [0.0],
                                                                                          "dig3": [0.0]}},
           {"name": "C2", "kind": "load_cell", "support": "P2", "sigma": 5.0, "readings": {"dig3": [0.0]}}]
    layers = [{"name": "soft", "top": 0.0, "E": 20000.0, "nu": 0.3, "model": "mohr-coulomb", "c": c, "phi": phi, "psi": 0.0},
              {"name": "stiff", "top": 10.0, "E": 80000.0, "nu": 0.3}]
    return pit(layers=layers, instruments=ins, **kw)


@pytest.mark.quick
@pytest.mark.parametrize("kind", ["props", "anchors"])
def test_mohr_coulomb_ground_that_never_yields_is_the_elastic_model(kind):
    """c' huge: the walls, props (or anchors), their preloads and the load cells read as on elastic ground,
    sensitivities included (the springs in the engine's residual, tangent and eqn (4))."""
    sim = simulation(_mc(c=1e9, props=kind == "props", anchors=kind == "anchors", preload=120.0))
    assert type(sim).__name__ == "YieldingExcavationSimulation"
    data = _mc(props=kind == "props", anchors=kind == "anchors", preload=120.0)
    data["ground"]["layers"][0] = {"name": "soft", "top": 0.0, "E": 20000.0, "nu": 0.3}
    elastic = simulation(data, mesh=sim.mesh)
    assert type(elastic).__name__ == "ExcavationSimulation"
    names = ["E[W]", "k[P1]", "preload[P1]", "k[P2]", "preload[P2]", "E[soft]", "K0"]
    v = sim.quantities()
    a = sim.predict(v, names, sensitivities=True)
    b = elastic.predict(elastic.quantities(), names, sensitivities=True)
    assert not sim.solution(v).yielded.any()
    assert np.abs(a.x - b.x).max() <= 1e-8 * np.abs(b.x).max()
    for j, name in enumerate(names):
        assert np.abs(a.A[:, j] - b.A[:, j]).max() <= 1e-7 * np.abs(b.A[:, j]).max(), name
    wa, wb = sim.wall_forces(v)["W"], elastic.wall_forces(elastic.quantities())["W"]
    assert np.abs(wa.M - wb.M).max() <= 1e-7 * np.abs(wb.M).max()


@pytest.mark.quick
def test_the_walls_forces_on_yielding_ground_come_from_the_elastoplastic_solution():
    sim = simulation(_mc(preload=120.0))
    v = sim.quantities()
    assert sim.solution(v).yielded.any()
    wf = sim.wall_forces(v)["W"]
    line = np.column_stack([np.full(len(wf.depths), 10.4), -wf.depths])
    ux = sim.stage_displacements_at(v, line, "dig3")[:, 0]
    assert np.abs(wf.ux[-1] - ux).max() <= 1e-12 + 1e-9 * np.abs(ux).max()


@pytest.mark.slow
def test_mohr_coulomb_sensitivities_with_props_against_central_differences():
    """Soft clay yielding behind the wall: the new values' DDM columns against finite differences of the
    replayed schedule on the base run's branch (test_excavation_plastic's procedure)."""
    from test_excavation_plastic import _check_sensitivities

    data = _mc(preload=120.0)
    data["construction"]["props"][1]["preload"] = 40.0
    sim = simulation(data)
    assert sim.solution(sim.quantities()).yielded.any()
    _check_sensitivities(sim, ["E[W]", "k[P1]", "preload[P1]", "k[P2]", "preload[P2]", "c[soft]", "phi[soft]"],
                         steps=(1e-4, 1e-5, 1e-6))


def test_condensed_engine_runs_equal_whole_factorisations_with_props():
    """The yielding pit with props and their preload, every engine run factorising only the region that may
    yield (plasticity/condensed.py, forced here: automatic from 10 k unknowns): readings and sensitivities as
    with whole factorisations; a second run keeps each stage's region (condensed anew, the springs and the
    wall not scaling with the ground's modulus)."""
    from dataclasses import replace

    from geoback.physics.solver import available_backends

    if "pardiso" not in available_backends():
        pytest.skip("condensation needs PARDISO")
    names = ["E[soft]", "K0", "c[soft]", "phi[soft]", "k[P1]", "preload[P1]"]
    data = _mc(preload=120.0)
    whole = simulation(data)
    cond = simulation(data, mesh=whole.mesh)
    whole.options = replace(whole.options, condense=False)
    cond.options = replace(cond.options, condense=True)
    v = whole.quantities()
    for values in (v, dict(v, **{"E[soft]": 1.05 * v["E[soft]"], "c[soft]": 0.97 * v["c[soft]"]})):
        before = cond.counters.condensations
        a = cond.predict(values, names, sensitivities=True)
        b = whole.predict(values, names, sensitivities=True)
        assert cond.solution(values).yielded.any()
        assert np.abs(a.x - b.x).max() <= 1e-9 * np.abs(b.x).max()
        for j, name in enumerate(names):
            assert np.abs(a.A[:, j] - b.A[:, j]).max() <= 1e-8 * np.abs(b.A[:, j]).max(), name
        assert cond.counters.condensations > before and whole.counters.condensations == 0
    assert cond.counters.factorised_unknowns / cond.counters.factorisations \
        < 0.7 * whole.counters.factorised_unknowns / whole.counters.factorisations
