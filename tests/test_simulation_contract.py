"""The contract every ``Simulation`` passes, run over the registry of implementations
(``geoback.physics.factory.IMPLEMENTATIONS``): each built from its shipped example case on a mesh
twice as coarse. A new physics registered there is checked here with no change to this file.

- the registry: the factory builds the registered class for its example case;
- names: every quantity is canonical, has a unit (that of ``limits.QUANTITIES`` for its stem), a range
  holding the case's value, and no null value (it is not an extension); every identified parameter
  resolves; every extension the simulation knows has a null value at which the readings are the
  baseline's;
- sensitivities: every quantity the case identifies (and, for linear physics, every quantity of the
  simulation) against central differences of ``replaying(values)``: for linear physics Richardson's
  with relative step 3e-4, within 1e-6 of the column's largest entry; for piecewise-smooth physics the
  step and tolerance of tests/test_plasticity_sensitivities.py (1e-5, norm-wise);
- a view on other instruments (``surveying``) reads the same model (against a simulation built on those
  instruments), shares the counters and factorisations (no new factorisation), and leaves the
  simulation's readings and sensitivities bitwise as they were;
- counters: a forward run is counted; a repeated predict at the same values costs no factorisation
  and no forward run; on linear ground, all moduli (the ground's and the linings') scaled together cost
  no factorisation (K = s K_ref);
- fields: displacement (N, 2) on the field's mesh, cell data one value per element, point data (N, 2)
  per stage, stage displacements (stages, free dofs), unknown stages refused.
"""
from __future__ import annotations

from types import SimpleNamespace

from pathlib import Path

import numpy as np
import pytest

from geoback.case.limits import QUANTITIES
from geoback.case.loading import load_case
from geoback.case.meshsize import refined_case
from geoback.observation.instruments import build_block
from geoback.physics.extensions import EXTENSIONS
from geoback.physics.factory import IMPLEMENTATIONS, implementation, make_simulation
from geoback.physics.simulation import is_instrument_term

pytestmark = pytest.mark.quick  # the edit-test loop tier (`pytest -m quick`): about 10 s in all

ROOT = Path(__file__).resolve().parents[1]
COARSER = 0.5  # refined_case factor: element sizes doubled


@pytest.fixture(scope="module", params=IMPLEMENTATIONS, ids=lambda impl: impl.name)
def built(request):
    """(implementation, loaded case, simulation) for every registered implementation."""
    impl = request.param
    loaded = load_case(ROOT / impl.example)
    loaded = loaded.with_case(refined_case(loaded.case, COARSER))
    return impl, loaded, make_simulation(loaded)


def fresh(loaded, sim, blocks=None):
    """Another simulation of the case on the same mesh (nothing factorised or remembered)."""
    return make_simulation(loaded, mesh=sim.mesh, blocks=blocks)


def identified(loaded, sim) -> list[str]:
    """The physical quantities the case identifies, canonical."""
    return [sim.canonical(p.name) for p in loaded.case.parameters if not is_instrument_term(p.name)]


def tunnel(g) -> tuple[tuple[float, float], float]:
    """Centre and half-width of the tunnel: the circular tunnel's axis and radius, or with openings the
    first opening's centroid and half its larger extent."""
    if not hasattr(g, "openings"):
        return (0.0, -g.axis_depth), g.radius
    from geoback.case.layout import polygon

    p = polygon(g.openings[0])
    minx, miny, maxx, maxy = p.bounds
    return (max(p.centroid.x, 0.0) if g.model == "half" else p.centroid.x, p.centroid.y), max(maxx - minx, maxy - miny) / 2


def other_blocks(loaded, sim) -> list:
    """Instruments the case does not have: surface points and a point beside the tunnel (both
    components), read at the first stage and at the last."""
    (cx, cy), r = tunnel(loaded.case.geometry)
    n = len(loaded.case.instruments)
    surface = build_block(SimpleNamespace(kind="points", name="contract-surface", components=["ux", "uy"], sigma=1.0,
                                          points=[[cx, 0.0], [cx + r, 0.0], [cx + 3 * r, 0.0]]), loaded, n)
    side = build_block(SimpleNamespace(kind="points", name="contract-side", components=["ux", "uy"], sigma=1.0,
                                       points=[[cx + 2 * r, cy]]), loaded, n + 1)
    return [surface.at(sim.stages[0]), side.at(sim.stages[-1])]


def test_the_factory_builds_the_registered_implementation(built):
    impl, loaded, sim = built
    assert implementation(loaded.case) is impl
    assert type(sim) is impl.load()
    assert sim.stages and sim.dofs == sim.fe.ndof and sim.survey.m > 0


def test_names_are_consistent(built):
    impl, loaded, sim = built
    q = sim.quantities()
    assert q
    for name, value in q.items():
        assert sim.canonical(name) == name, name
        stem = name.partition("[")[0]
        unit = sim.unit(name)
        assert isinstance(unit, str) and unit, name
        if stem in QUANTITIES:
            assert unit == QUANTITIES[stem][0], name
        assert sim.limits(name, q).contains(value), name
        assert sim.null_value(name, q) is None, name  # a case's own quantity is no extension
    for name in identified(loaded, sim):
        assert name is not None and name in q, name
    x0 = sim.predict(q).x
    for ext in EXTENSIONS.values():
        layer = f"[{sim.ground.layers[-1]}]" if ext.per_layer else ""
        name = sim.canonical(ext.base + layer)
        if name is None:  # not modelled by this physics (cross-anisotropy with yielding ground)
            continue
        null = sim.null_value(name, q)
        assert isinstance(null, float) and sim.unit(name) == ext.unit, name
        x = sim.predict({**q, name: null}).x
        assert np.abs(x - x0).max() <= 1e-9 * np.abs(x0).max(), name  # the baseline at the null value


def _columns(sim, values, names, h_rel, richardson):
    out = np.empty((sim.survey.m, len(names)))
    for j, name in enumerate(names):
        h = h_rel * abs(values[name])

        def x(step):
            return sim.predict({**values, name: values[name] + step}).x

        d1 = (x(h) - x(-h)) / (2 * h)
        out[:, j] = (4 * d1 - (x(2 * h) - x(-2 * h)) / (4 * h)) / 3 if richardson else d1
    return out


def test_sensitivities_match_central_differences(built):
    impl, loaded, sim = built
    values = sim.quantities()
    names = identified(loaded, sim)
    if not sim.piecewise_smooth:  # linear physics: every quantity (cheap)
        names = list(dict.fromkeys(names + list(values)))
    A = sim.predict(values, names, sensitivities=True).A
    fd_sim = sim.replaying(values)
    if sim.piecewise_smooth:  # the step and tolerance of tests/test_plasticity_sensitivities.py
        fd = _columns(fd_sim, values, names, 1e-5, richardson=False)
        for j, name in enumerate(names):
            assert np.linalg.norm(A[:, j]) > 0, name
            assert np.linalg.norm(fd[:, j] - A[:, j]) <= 1e-5 * np.linalg.norm(A[:, j]), name
    else:
        # Richardson-extrapolated central differences at a relative step of 1e-3: at 3e-4 round-off reached
        # 1.2e-6 of the column for a lining's nu in a section with openings (8e-8 at 3e-3), at 3e-3 the
        # truncation reached 2.8e-6 for nu = 0.49 (1 / (1 - 2 nu) is steep there); 1e-3 sits between
        fd = _columns(fd_sim, values, names, 1e-3, richardson=True)
        for j, name in enumerate(names):
            scale = np.abs(A[:, j]).max()
            assert scale > 0, name
            assert np.abs(fd[:, j] - A[:, j]).max() <= 1e-6 * scale, name


def test_a_view_on_other_instruments_leaves_the_simulation_as_it_was(built):
    impl, loaded, _ = built
    sim = fresh(loaded, built[2])
    values = sim.quantities()
    names = identified(loaded, sim)
    sim.predict(values, names, sensitivities=True)  # loads met once are answered from their span after
    before = sim.predict(values, names, sensitivities=True)  # (to rounding): the state the view must keep
    survey = sim.survey
    blocks = other_blocks(loaded, sim)
    spent = sim.counters.snapshot()
    view = sim.surveying(blocks)
    assert view is not sim and type(view) is type(sim) and view.counters is sim.counters
    assert [b.name for b in view.survey.blocks] == [b.name for b in blocks]
    seen = view.predict(values, names, sensitivities=True)
    assert sim.counters.since(spent)["factorisations"] == 0  # the view reads with the factorisations made
    with sim.surveying(blocks) as again:  # a view is a context manager too
        np.testing.assert_array_equal(again.predict(values).x, seen.x)
    assert sim.survey is survey
    after = sim.predict(values, names, sensitivities=True)
    np.testing.assert_array_equal(after.x, before.x)
    np.testing.assert_array_equal(after.A, before.A)
    # the view reads the same model: a simulation built on those instruments
    other = fresh(loaded, sim, blocks)
    ref = other.predict(values, names, sensitivities=True)
    np.testing.assert_allclose(seen.x, ref.x, rtol=1e-9, atol=1e-12 * np.abs(ref.x).max())
    np.testing.assert_allclose(seen.A, ref.A, rtol=1e-8, atol=1e-10 * np.abs(ref.A).max())


def test_counters_increase_as_documented(built):
    impl, loaded, _ = built
    sim = fresh(loaded, built[2])
    values = sim.quantities()
    names = identified(loaded, sim)
    c0 = sim.counters.snapshot()
    sim.predict(values, names, sensitivities=True)
    first = sim.counters.since(c0)
    assert first["forward_runs"] == 1 and first["factorisations"] >= 1 and first["solves"] >= 1
    c1 = sim.counters.snapshot()
    sim.predict(values)
    sim.predict(values, names, sensitivities=True)
    again = sim.counters.since(c1)
    assert again["factorisations"] == 0 and again["forward_runs"] == 0
    if sim.piecewise_smooth:
        return
    moduli = {n: 1.1 * v for n, v in values.items() if n.startswith("E[")}  # the ground's and any lining's
    c2 = sim.counters.snapshot()
    sim.predict({**values, **moduli}, names, sensitivities=True)  # K = 1.1 K_ref: the same factorisation
    scaled = sim.counters.since(c2)
    assert scaled["factorisations"] == 0 and scaled["forward_runs"] == 1


def test_fields_have_the_shapes_of_their_mesh(built):
    impl, loaded, sim = built
    values = sim.quantities()
    f = sim.field(values)
    nodes, elements = len(f.mesh.nodes), len(f.mesh.triangles)
    assert f.displacement.shape == (nodes, 2)
    assert f.cell_data and all(np.shape(v) == (elements,) for v in f.cell_data.values())
    assert all(np.shape(v) == (nodes, 2) for v in f.point_data.values())
    if len(sim.stages) > 1:
        assert set(f.point_data) == {f"displacement[{s}]" for s in sim.stages}
        np.testing.assert_array_equal(f.point_data[f"displacement[{sim.stages[-1]}]"], f.displacement)
    U = sim.stage_displacements(values)
    assert U.shape == (len(sim.stages), sim.fe.nfree)
    (cx, cy), r = tunnel(loaded.case.geometry)
    pts = np.array([[cx, 0.0], [cx + 2 * r, cy]])
    for k, stage in enumerate(sim.stages):
        at = sim.stage_displacements_at(values, pts, stage)
        assert at.shape == (2, 2)
        Ix, Iy = sim.fe.interpolation(pts)
        np.testing.assert_array_equal(at, np.column_stack([Ix @ U[k], Iy @ U[k]]))
    np.testing.assert_array_equal(sim.displacements_at(values, pts), sim.stage_displacements_at(values, pts, sim.stages[-1]))
    with pytest.raises(ValueError):
        sim.stage_displacements_at(values, pts, "no-such-stage")

